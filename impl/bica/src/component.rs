//! The component model: a component does one thing; its inputs (modulations) and results
//! are ordinary methods of its type, and [`Component::step`] runs one iteration of its
//! gated work. Components live in a [`Registry`] (one instance per type) and reach each
//! other through the [`StepContext`] passed to `step`, which lets the cascade read
//! naturally: step the components you read *before* reading them, set the modulations of
//! the components you drive *before* stepping them.
//!
//! A component being stepped is taken out of its slot for the duration of its step, so a
//! cascade cycle (A steps B steps A) or a read of a busy component is an error, not a
//! `RefCell` panic.

use std::any::{Any, TypeId};
use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hasher};
use std::marker::PhantomData;

use crate::clock::Clock;
use crate::component_id::ComponentId;
use crate::core::{Gate, SchedulerCore};
use crate::debug_primitives::Debuggable;
use crate::error::BicaError;
use crate::stats::Statistics;
use crate::trace::Caller;

/// One component of the cascade. Implement `step`; everything else has a default.
pub trait Component: Any {
    /// Runs one iteration of the component's work. Called only when its frequency gate
    /// is open (at most once per period). Step dependencies through `ctx` before reading them.
    fn step(&mut self, ctx: &mut StepContext<'_>) -> Result<(), BicaError>;

    /// Called just before the first step after the component was not stepped for more
    /// than the configured number of periods (default 10), e.g. to restart an FSM.
    fn on_reactivated(&mut self, _gap_ns: u64) {}

    /// Components that can draw debug primitives return themselves here.
    fn as_debuggable(&self) -> Option<&dyn Debuggable> {
        None
    }
}

/// A typed, copyable reference to a registered component (faster than a type lookup).
#[derive(Debug)]
pub struct Handle<T> {
    id: ComponentId,
    marker: PhantomData<fn() -> T>,
}

impl<T> Clone for Handle<T> {
    fn clone(&self) -> Self {
        *self
    }
}
impl<T> Copy for Handle<T> {}

impl<T> Handle<T> {
    /// The untyped id.
    pub fn id(self) -> ComponentId {
        self.id
    }
}

/// Hasher for `TypeId` keys: a `TypeId` is already a good hash, so fold its bits instead of
/// running SipHash on the hot path.
#[derive(Default)]
struct TypeIdHasher(u64);

impl Hasher for TypeIdHasher {
    fn finish(&self) -> u64 {
        self.0
    }
    fn write(&mut self, bytes: &[u8]) {
        for chunk in bytes.chunks(8) {
            let mut word = [0u8; 8];
            word[..chunk.len()].copy_from_slice(chunk);
            self.0 = self.0.rotate_left(5) ^ u64::from_le_bytes(word);
        }
    }
    fn write_u64(&mut self, value: u64) {
        self.0 = self.0.rotate_left(5) ^ value;
    }
}

struct Slot {
    name: &'static str,
    /// `None` while the component is stepping (taken out).
    component: Option<Box<dyn Component>>,
}

/// The component instances, one per type, indexed like the scheduler's ids.
#[derive(Default)]
pub struct Registry {
    slots: Vec<Slot>,
    by_type: HashMap<TypeId, ComponentId, BuildHasherDefault<TypeIdHasher>>,
}

impl std::fmt::Debug for Registry {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_list().entries(self.slots.iter().map(|s| s.name)).finish()
    }
}

impl Registry {
    /// Adds a component under the id the scheduler core gave it.
    pub(crate) fn insert<T: Component>(&mut self, id: ComponentId, component: T) -> Result<Handle<T>, BicaError> {
        let name = std::any::type_name::<T>();
        if self.by_type.contains_key(&TypeId::of::<T>()) {
            return Err(BicaError::AlreadyRegistered { component: name.to_owned() });
        }
        assert_eq!(id.0 as usize, self.slots.len(), "invariant: registry ids follow the core's ids");
        self.slots.push(Slot { name, component: Some(Box::new(component)) });
        self.by_type.insert(TypeId::of::<T>(), id);
        Ok(Handle { id, marker: PhantomData })
    }

    /// Whether type `T` is registered (so `insert` would fail).
    pub fn contains<T: Component>(&self) -> bool {
        self.by_type.contains_key(&TypeId::of::<T>())
    }

    /// The handle of component type `T`.
    pub fn handle<T: Component>(&self) -> Result<Handle<T>, BicaError> {
        match self.by_type.get(&TypeId::of::<T>()) {
            Some(&id) => Ok(Handle { id, marker: PhantomData }),
            None => Err(BicaError::UnknownComponent { component: std::any::type_name::<T>().to_owned() }),
        }
    }

    /// Type name of a component.
    pub fn name(&self, id: ComponentId) -> Result<&'static str, BicaError> {
        self.slots.get(id.0 as usize).map(|s| s.name).ok_or_else(|| unknown_id(id))
    }

    /// Number of registered components.
    pub fn len(&self) -> usize {
        self.slots.len()
    }

    /// Whether nothing is registered.
    pub fn is_empty(&self) -> bool {
        self.slots.is_empty()
    }

    /// Reads component `T` (fails if it is stepping right now).
    pub fn get<T: Component>(&self) -> Result<&T, BicaError> {
        self.get_by_handle(self.handle::<T>()?)
    }

    /// Mutably reaches component `T`, e.g. to set a modulation (fails if it is stepping).
    pub fn get_mut<T: Component>(&mut self) -> Result<&mut T, BicaError> {
        let handle = self.handle::<T>()?;
        self.get_mut_by_handle(handle)
    }

    /// Reads a component through its handle.
    pub fn get_by_handle<T: Component>(&self, handle: Handle<T>) -> Result<&T, BicaError> {
        let component = self.dyn_ref(handle.id)?;
        let any: &dyn Any = component;
        Ok(any.downcast_ref::<T>().expect("invariant: a handle's type matches its slot"))
    }

    /// Mutably reaches a component through its handle.
    pub fn get_mut_by_handle<T: Component>(&mut self, handle: Handle<T>) -> Result<&mut T, BicaError> {
        let component = self.dyn_mut(handle.id)?;
        let any: &mut dyn Any = component;
        Ok(any.downcast_mut::<T>().expect("invariant: a handle's type matches its slot"))
    }

    /// The component behind `id` as a trait object (fails if it is stepping).
    pub fn dyn_ref(&self, id: ComponentId) -> Result<&dyn Component, BicaError> {
        let slot = self.slots.get(id.0 as usize).ok_or_else(|| unknown_id(id))?;
        slot.component.as_deref().ok_or_else(|| busy(slot.name))
    }

    fn dyn_mut(&mut self, id: ComponentId) -> Result<&mut (dyn Component + 'static), BicaError> {
        let slot = self.slots.get_mut(id.0 as usize).ok_or_else(|| unknown_id(id))?;
        let name = slot.name;
        slot.component.as_deref_mut().ok_or_else(|| busy(name))
    }

    fn take(&mut self, id: ComponentId) -> Box<dyn Component> {
        self.slots[id.0 as usize].component.take().expect("invariant: the core never runs a component twice at once")
    }

    fn put_back(&mut self, id: ComponentId, component: Box<dyn Component>) {
        let slot = &mut self.slots[id.0 as usize].component;
        assert!(slot.is_none(), "invariant: a stepping component's slot stays empty");
        *slot = Some(component);
    }
}

fn unknown_id(id: ComponentId) -> BicaError {
    BicaError::UnknownComponent { component: format!("{id:?}") }
}

fn busy(name: &str) -> BicaError {
    BicaError::CascadeCycle {
        component: name.to_owned(),
        path: "it was read or stepped while its own step is running".to_owned(),
    }
}

/// A change of the active list requested during a step, applied after the top-level step.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ListChange {
    /// Append to the active list.
    Activate(ComponentId),
    /// Remove from the active list.
    Deactivate(ComponentId),
}

/// What `step` receives: access to the other components and to time.
pub struct StepContext<'a> {
    pub(crate) registry: &'a mut Registry,
    pub(crate) core: &'a mut SchedulerCore,
    pub(crate) stats: &'a mut Statistics,
    pub(crate) clock: &'a dyn Clock,
    pub(crate) current: ComponentId,
    pub(crate) step_started_ns: u64,
    pub(crate) list_changes: &'a mut Vec<ListChange>,
}

/// Whether a [`StepContext::step`] call ran the dependency's gated work.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Stepped {
    /// Its work ran now.
    Ran,
    /// Its gate was closed (it already ran this period); its results are from that run.
    NotDue,
}

impl StepContext<'_> {
    /// Steps component `T` as part of the cascade: its gated work runs if due.
    pub fn step<T: Component>(&mut self) -> Result<Stepped, BicaError> {
        let handle = self.registry.handle::<T>()?;
        self.step_id(handle.id)
    }

    /// Steps a component through its handle (skips the type lookup).
    pub fn step_handle<T: Component>(&mut self, handle: Handle<T>) -> Result<Stepped, BicaError> {
        self.step_id(handle.id)
    }

    /// Steps a component by id.
    pub fn step_id(&mut self, id: ComponentId) -> Result<Stepped, BicaError> {
        let now_ns = self.clock.now_ns();
        let gate =
            self.core.begin_step(id, now_ns, Caller::Nested { parent: self.current }).map_err(|error| match error {
                BicaError::CascadeCycle { path, .. } => BicaError::CascadeCycle {
                    component: self.registry.name(id).unwrap_or("?").to_owned(),
                    path: self.describe_path(&path),
                },
                other => other,
            })?;
        match gate {
            Gate::NotDue { .. } => Ok(Stepped::NotDue),
            Gate::Run(info) => {
                let parent = std::mem::replace(&mut self.current, id);
                let parent_started = std::mem::replace(&mut self.step_started_ns, now_ns);
                let result = run_one(self, id, now_ns, &info);
                self.current = parent;
                self.step_started_ns = parent_started;
                result.map(|()| Stepped::Ran)
            }
        }
    }

    fn describe_path(&self, ids: &str) -> String {
        ids.split(" -> ")
            .map(|n| n.parse::<u32>().ok().and_then(|n| self.registry.name(ComponentId(n)).ok()).unwrap_or("?"))
            .collect::<Vec<_>>()
            .join(" -> ")
    }

    /// Reads component `T` (step it first if you need fresh results).
    pub fn get<T: Component>(&self) -> Result<&T, BicaError> {
        self.registry.get::<T>()
    }

    /// Mutably reaches component `T`, e.g. to set its modulation before stepping it.
    pub fn get_mut<T: Component>(&mut self) -> Result<&mut T, BicaError> {
        self.registry.get_mut::<T>()
    }

    /// Reads a component through its handle.
    pub fn get_handle<T: Component>(&self, handle: Handle<T>) -> Result<&T, BicaError> {
        self.registry.get_by_handle(handle)
    }

    /// Mutably reaches a component through its handle.
    pub fn get_mut_handle<T: Component>(&mut self, handle: Handle<T>) -> Result<&mut T, BicaError> {
        self.registry.get_mut_by_handle(handle)
    }

    /// The registry, for generic code (e.g. the debug collector).
    pub fn registry(&self) -> &Registry {
        self.registry
    }

    /// Current time from the injected clock.
    pub fn now_ns(&self) -> u64 {
        self.clock.now_ns()
    }

    /// When the current component's step started.
    pub fn step_started_ns(&self) -> u64 {
        self.step_started_ns
    }

    /// The component whose step this is.
    pub fn current(&self) -> ComponentId {
        self.current
    }

    /// Asks for `T` to join the active list after the current top-level step.
    pub fn activate<T: Component>(&mut self) -> Result<(), BicaError> {
        let id = self.registry.handle::<T>()?.id;
        self.list_changes.push(ListChange::Activate(id));
        Ok(())
    }

    /// Asks for `T` to leave the active list after the current top-level step.
    pub fn deactivate<T: Component>(&mut self) -> Result<(), BicaError> {
        let id = self.registry.handle::<T>()?.id;
        self.list_changes.push(ListChange::Deactivate(id));
        Ok(())
    }
}

/// Runs the gated work of `id`, whose gate the core has just opened: takes it out of its
/// slot, steps it, puts it back, tells the core it finished and records statistics.
pub(crate) fn run_one(
    ctx: &mut StepContext<'_>,
    id: ComponentId,
    started_ns: u64,
    info: &crate::core::RunInfo,
) -> Result<(), BicaError> {
    let mut component = ctx.registry.take(id);
    if let Some(gap_ns) = info.reactivated_after_gap_ns {
        component.on_reactivated(gap_ns);
    }
    let cpu_start_ns = ctx.stats.should_time_cpu(id, started_ns).then(|| ctx.clock.thread_cpu_ns());
    let result = component.step(ctx);
    let finished_ns = ctx.clock.now_ns();
    let cpu_ns = cpu_start_ns.map(|start| ctx.clock.thread_cpu_ns().saturating_sub(start));
    ctx.registry.put_back(id, component);
    ctx.core.finish_step(id, finished_ns).expect("invariant: the finished step is the innermost running one");
    ctx.stats.record_run(id, started_ns, finished_ns, cpu_ns, info);
    if let Some(miss) = info.miss
        && miss.warn
    {
        tracing::warn!(
            component = ctx.registry.name(id).unwrap_or("?"),
            expected_ns = miss.expected_ns,
            actual_ns = miss.actual_ns,
            lateness_ns = miss.lateness_ns,
            skipped_periods = miss.skipped_periods,
            suppressed_warnings = miss.suppressed_since_last_warning,
            "component missed its release"
        );
    }
    result
}
