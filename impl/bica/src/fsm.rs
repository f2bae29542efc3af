//! Finite-state-machine components written as plain data: states list the components they
//! require (stepped before the state's code) and the components they modulate (stepped
//! after it), plus transitions checked in declaration order (first true wins) that can use
//! a per-state stopwatch. The current state is readable from outside. Each machine is its
//! own component type `Fsm<S, D>`, so pick a distinct state enum `S` (or data type `D`)
//! per machine.
//!
//! One step: (1) step the current state's required components; (2) take the first
//! transition whose condition holds (at most one per step; the stopwatch restarts and the
//! new state's required components are stepped); (3) run the state's action; (4) step the
//! components it modulates. After a long gap (re-activation) the machine restarts from
//! its initial state.

use std::fmt::Debug;

use crate::component::{Component, StepContext, Stepped};
use crate::error::BicaError;

type StepFn = fn(&mut StepContext<'_>) -> Result<Stepped, BicaError>;
type Action<D> = Box<dyn FnMut(&mut D, &mut StepContext<'_>) -> Result<(), BicaError>>;
type Condition<D> = Box<dyn Fn(&D, &StepContext<'_>, u64) -> bool>;

fn step_component<T: Component>(ctx: &mut StepContext<'_>) -> Result<Stepped, BicaError> {
    ctx.step::<T>()
}

/// Declaration of one state.
pub struct StateSpec<S, D> {
    state: S,
    requires: Vec<(StepFn, &'static str)>,
    modulates: Vec<(StepFn, &'static str)>,
    action: Option<Action<D>>,
    transitions: Vec<(S, Condition<D>)>,
}

impl<S: Copy + Eq + Debug + 'static, D: 'static> StateSpec<S, D> {
    fn new(state: S) -> Self {
        Self { state, requires: Vec::new(), modulates: Vec::new(), action: None, transitions: Vec::new() }
    }

    /// `T` is stepped before this state's transitions and action.
    pub fn requires<T: Component>(mut self) -> Self {
        self.requires.push((step_component::<T>, std::any::type_name::<T>()));
        self
    }

    /// `T` is stepped after this state's action (which sets its modulation).
    pub fn modulates<T: Component>(mut self) -> Self {
        self.modulates.push((step_component::<T>, std::any::type_name::<T>()));
        self
    }

    /// The state's code, run every step while in this state.
    pub fn action(
        mut self,
        action: impl FnMut(&mut D, &mut StepContext<'_>) -> Result<(), BicaError> + 'static,
    ) -> Self {
        self.action = Some(Box::new(action));
        self
    }

    /// A transition to `to` when `condition(data, ctx, time_in_state_ns)` holds. Earlier
    /// declarations have priority.
    pub fn transition(mut self, to: S, condition: impl Fn(&D, &StepContext<'_>, u64) -> bool + 'static) -> Self {
        self.transitions.push((to, Box::new(condition)));
        self
    }

    /// A transition to `to` once the machine has been in this state for `after_ns`.
    pub fn after_ns(self, after_ns: u64, to: S) -> Self {
        self.transition(to, move |_, _, in_state_ns| in_state_ns >= after_ns)
    }
}

/// Builder of an [`Fsm`].
pub struct FsmBuilder<S, D> {
    name: String,
    initial: S,
    data: D,
    states: Vec<StateSpec<S, D>>,
}

impl<S: Copy + Eq + Debug + 'static, D: 'static> FsmBuilder<S, D> {
    /// Declares a state.
    pub fn state(mut self, state: S, declare: impl FnOnce(StateSpec<S, D>) -> StateSpec<S, D>) -> Self {
        self.states.push(declare(StateSpec::new(state)));
        self
    }

    /// Checks the declaration: unique states, a declared initial state, declared targets.
    pub fn build(self) -> Result<Fsm<S, D>, BicaError> {
        let invalid = |reason: String| BicaError::InvalidFsm { fsm: self.name.clone(), reason };
        for (index, spec) in self.states.iter().enumerate() {
            if self.states[..index].iter().any(|other| other.state == spec.state) {
                return Err(invalid(format!("state {:?} is declared twice", spec.state)));
            }
            for (to, _) in &spec.transitions {
                if !self.states.iter().any(|other| other.state == *to) {
                    return Err(invalid(format!("state {:?} has a transition to undeclared state {to:?}", spec.state)));
                }
            }
        }
        let Some(initial_index) = self.states.iter().position(|spec| spec.state == self.initial) else {
            return Err(invalid(format!("initial state {:?} is not declared", self.initial)));
        };
        Ok(Fsm {
            name: self.name,
            states: self.states,
            initial_index,
            current_index: initial_index,
            entered_ns: None,
            transitions_taken: 0,
            data: self.data,
        })
    }
}

/// A component written as a finite-state machine.
///
/// ```
/// use bica::prelude::*;
///
/// #[derive(Debug, Clone, Copy, PartialEq, Eq)]
/// enum Kick { Wait, Swing }
///
/// let fsm = Fsm::builder("kick", Kick::Wait, 0u32)
///     .state(Kick::Wait, |s| s.after_ns(20, Kick::Swing))
///     .state(Kick::Swing, |s| s.action(|swings, _| { *swings += 1; Ok(()) }).after_ns(10, Kick::Wait))
///     .build()
///     .unwrap();
/// let mut runtime = Runtime::new(RuntimeConfig::default(), VirtualClock::new(0));
/// runtime.register(fsm, 10).unwrap();
/// runtime.activate::<Fsm<Kick, u32>>().unwrap();
/// runtime.run_until(25).unwrap(); // steps at 0, 10, 20: the third one switches to Swing
/// let fsm = runtime.registry().get::<Fsm<Kick, u32>>().unwrap();
/// assert_eq!(fsm.current_state(), Kick::Swing);
/// assert_eq!(*fsm.data(), 1);
/// ```
pub struct Fsm<S, D> {
    name: String,
    states: Vec<StateSpec<S, D>>,
    initial_index: usize,
    current_index: usize,
    entered_ns: Option<u64>,
    transitions_taken: u64,
    data: D,
}

impl<S: Debug, D> Debug for Fsm<S, D> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Fsm")
            .field("name", &self.name)
            .field("state", &self.states[self.current_index].state)
            .field("transitions_taken", &self.transitions_taken)
            .finish_non_exhaustive()
    }
}

impl<S: Copy + Eq + Debug + 'static, D: 'static> Fsm<S, D> {
    /// Starts declaring a machine named `name` starting in `initial` with user data `data`.
    pub fn builder(name: impl Into<String>, initial: S, data: D) -> FsmBuilder<S, D> {
        FsmBuilder { name: name.into(), initial, data, states: Vec::new() }
    }

    /// The machine's name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The current state.
    pub fn current_state(&self) -> S {
        self.states[self.current_index].state
    }

    /// When the current state was entered (`None` before the first step).
    pub fn entered_ns(&self) -> Option<u64> {
        self.entered_ns
    }

    /// Transitions taken so far.
    pub fn transitions_taken(&self) -> u64 {
        self.transitions_taken
    }

    /// The user data.
    pub fn data(&self) -> &D {
        &self.data
    }

    /// The user data, mutably (e.g. to set a modulation of the machine).
    pub fn data_mut(&mut self) -> &mut D {
        &mut self.data
    }

    /// Names of the components the current state requires and modulates.
    pub fn current_dependencies(&self) -> (Vec<&'static str>, Vec<&'static str>) {
        let spec = &self.states[self.current_index];
        (spec.requires.iter().map(|r| r.1).collect(), spec.modulates.iter().map(|m| m.1).collect())
    }

    fn step_required(&self, ctx: &mut StepContext<'_>) -> Result<(), BicaError> {
        for (step, _) in &self.states[self.current_index].requires {
            step(ctx)?;
        }
        Ok(())
    }
}

impl<S: Copy + Eq + Debug + 'static, D: 'static> Component for Fsm<S, D> {
    fn step(&mut self, ctx: &mut StepContext<'_>) -> Result<(), BicaError> {
        let now_ns = ctx.step_started_ns();
        let entered_ns = *self.entered_ns.get_or_insert(now_ns);
        self.step_required(ctx)?;
        let in_state_ns = now_ns.saturating_sub(entered_ns);
        let spec = &self.states[self.current_index];
        let next = spec.transitions.iter().find(|(_, condition)| condition(&self.data, ctx, in_state_ns)).map(|t| t.0);
        if let Some(next) = next {
            self.current_index = self
                .states
                .iter()
                .position(|spec| spec.state == next)
                .expect("invariant: build() checked every transition target is declared");
            self.entered_ns = Some(now_ns);
            self.transitions_taken += 1;
            self.step_required(ctx)?;
        }
        let spec = &mut self.states[self.current_index];
        if let Some(action) = spec.action.as_mut() {
            action(&mut self.data, ctx)?;
        }
        for (step, _) in &spec.modulates {
            step(ctx)?;
        }
        Ok(())
    }

    fn on_reactivated(&mut self, _gap_ns: u64) {
        self.current_index = self.initial_index;
        self.entered_ns = None;
    }
}
