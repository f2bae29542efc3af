//! The scheduler core: a pure, deterministic state machine. It reads no clock, spawns no
//! thread and does no I/O. Drivers feed it events ("it is now t", "this step finished at t")
//! and it answers with decisions ("step component X", "sleep until t") and records them
//! in a bounded [`TraceBuffer`]. The same code runs under the real thread driver, under a
//! virtual clock in tests, and inside the model checker.
//!
//! # Release policy: phase-preserving
//!
//! A component with period `T` is released at `r0 + k·T`, where `r0` is the time it was
//! (re)activated. Its gated work runs at most once per release: a run at time `t` serves
//! the oldest pending release `r` (lateness `t - r`), and every other release `≤ t` is
//! dropped and counted as a skipped period; the next release is the first `r0 + k·T > t`.
//! There is never a catch-up burst after an overrun, and the phase never drifts, so rates
//! return to nominal right after an overload. A component that is stepped again after a
//! gap of more than `reactivation_gap_periods` periods is told so and its grid restarts at
//! that time (being idle is not a miss).
//!
//! # Rounds
//!
//! The scheduler scans the active list in order; each scan is a round in which every due
//! component is stepped at most once. When a round ends, a new one begins if anything is
//! due, otherwise the driver sleeps until the earliest release. So after one step overruns
//! by X, no other component waits more than X plus one round.
//!
//! ```
//! use bica::core::{Decision, Gate, SchedulerConfig, SchedulerCore};
//! use bica::trace::Caller;
//!
//! let mut core = SchedulerCore::new(SchedulerConfig::default());
//! let sensor = core.register(10_000_000).unwrap(); // 100 Hz
//! core.activate(sensor, 0).unwrap();
//! assert_eq!(core.next_decision(0).unwrap(), Decision::Step(sensor));
//! let Gate::Run(info) = core.begin_step(sensor, 0, Caller::TopLevel).unwrap() else { panic!() };
//! assert_eq!(info.lateness_ns, 0);
//! core.finish_step(sensor, 1_000).unwrap();
//! assert_eq!(core.next_decision(1_000).unwrap(), Decision::SleepUntil(10_000_000));
//! ```

use serde::{Deserialize, Serialize};

pub use crate::component_id::ComponentId;
use crate::error::BicaError;
use crate::trace::{Caller, MissEvent, TraceBuffer, TraceEvent};

/// A deliberately planted scheduler bug, for checking that tests and the model catch it.
#[cfg(feature = "mutants")]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum SchedulerMutant {
    /// After an overrun, run one step per missed release back to back (catch-up burst).
    CatchUpBurst,
    /// A dependency stepped by a second parent in the same period runs its work again.
    SharedDependencyTwice,
    /// The miss check is off by one: lateness of exactly `tolerance + 1` is not reported.
    MissOffByOne,
    /// A deactivated component is stepped once more before it leaves the list.
    RemovedSteppedOnceMore,
    /// `finish_step` does not check that the component is the innermost running step: a finish of a step that
    /// is not running is accepted, pops whatever runs (if anything) and is traced as finished.
    FinishUnmatched,
}

/// Tunables of the scheduler core.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct SchedulerConfig {
    /// A miss is raised exactly when a run's lateness exceeds this.
    pub miss_tolerance_ns: u64,
    /// A component stepped again after more than this many periods is told it was re-activated.
    pub reactivation_gap_periods: u64,
    /// At most one miss warning per component per this interval (counters are never limited).
    pub warning_interval_ns: u64,
    /// Capacity of the trace ring (0 disables the trace).
    pub trace_capacity: usize,
    /// Deepest cascade allowed (a guard against runaway recursion).
    pub max_cascade_depth: usize,
    /// The planted bug, if any (feature `mutants` only).
    #[cfg(feature = "mutants")]
    pub mutant: Option<SchedulerMutant>,
}

impl Default for SchedulerConfig {
    fn default() -> Self {
        Self {
            miss_tolerance_ns: 1_000_000,
            reactivation_gap_periods: 10,
            warning_interval_ns: 1_000_000_000,
            trace_capacity: 4096,
            max_cascade_depth: 64,
            #[cfg(feature = "mutants")]
            mutant: None,
        }
    }
}

/// What the driver should do next.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Decision {
    /// Step this top-level component now (call [`SchedulerCore::begin_step`] with [`Caller::TopLevel`]).
    Step(ComponentId),
    /// Nothing is due: sleep until this time (or until a request arrives).
    SleepUntil(u64),
    /// The active list is empty: wait for a request.
    Idle,
}

/// Details of a run the gate allowed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct RunInfo {
    /// Release served by this run.
    pub release_ns: u64,
    /// Start time minus release.
    pub lateness_ns: u64,
    /// Releases dropped before this run.
    pub skipped_periods: u64,
    /// The miss raised by this run, if its lateness exceeds the tolerance.
    pub miss: Option<MissEvent>,
    /// Set when the component runs again after a long gap: how long the gap was.
    pub reactivated_after_gap_ns: Option<u64>,
}

/// Answer of the frequency gate for one step call.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Gate {
    /// The gated work runs now; call [`SchedulerCore::finish_step`] when it ends.
    Run(RunInfo),
    /// Not time yet: the work does not run (nothing to finish).
    NotDue {
        /// When the gate opens next.
        next_release_ns: u64,
    },
}

/// Counters per component. They are never rate-limited or dropped.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize)]
pub struct ComponentCounters {
    /// Runs of the gated work.
    pub runs: u64,
    /// Step calls whose gate was closed.
    pub gated_skips: u64,
    /// Releases dropped because a run came too late to serve them.
    pub skipped_releases: u64,
    /// Deadline misses.
    pub misses: u64,
    /// Miss warnings that were allowed through the rate limiter.
    pub warnings: u64,
    /// Re-activations after a long gap.
    pub reactivations: u64,
}

#[derive(Debug, Clone, PartialEq, Eq, Hash)]
struct ComponentState {
    period_ns: u64,
    /// Next release; `None` until the component is first activated or stepped.
    next_release_ns: Option<u64>,
    in_active_list: bool,
    /// Last time it was stepped (run or gated skip) or left the active list.
    last_seen_ns: Option<u64>,
    reactivation_pending_gap_ns: Option<u64>,
    last_warning_ns: Option<u64>,
    misses_since_warning: u64,
    counters: ComponentCounters,
    #[cfg(feature = "mutants")]
    pending_removal: bool,
}

/// The pure scheduler state machine. `Clone + Eq + Hash` so a model checker can store it.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct SchedulerCore {
    config: SchedulerConfig,
    components: Vec<ComponentState>,
    active: Vec<ComponentId>,
    /// Position in `active` of the next candidate of the current round.
    cursor: usize,
    /// Cascade of steps in progress, outermost first.
    running: Vec<ComponentId>,
    decided: Option<ComponentId>,
    last_now_ns: u64,
    rounds: u64,
    trace: TraceBuffer,
}

impl SchedulerCore {
    /// Creates an empty scheduler.
    pub fn new(config: SchedulerConfig) -> Self {
        let trace = TraceBuffer::with_capacity(config.trace_capacity);
        Self {
            config,
            components: Vec::new(),
            active: Vec::new(),
            cursor: 0,
            running: Vec::new(),
            decided: None,
            last_now_ns: 0,
            rounds: 0,
            trace,
        }
    }

    /// The configuration in force.
    pub fn config(&self) -> &SchedulerConfig {
        &self.config
    }

    /// Registers a component with its period and returns its id. It is not active yet.
    pub fn register(&mut self, period_ns: u64) -> Result<ComponentId, BicaError> {
        let id = ComponentId(u32::try_from(self.components.len()).map_err(|_| BicaError::UnknownComponent {
            component: "too many components (more than u32::MAX)".to_owned(),
        })?);
        if period_ns == 0 {
            return Err(BicaError::InvalidPeriod { component: format!("{id:?}") });
        }
        self.components.push(ComponentState {
            period_ns,
            next_release_ns: None,
            in_active_list: false,
            last_seen_ns: None,
            reactivation_pending_gap_ns: None,
            last_warning_ns: None,
            misses_since_warning: 0,
            counters: ComponentCounters::default(),
            #[cfg(feature = "mutants")]
            pending_removal: false,
        });
        Ok(id)
    }

    /// Number of registered components.
    pub fn component_count(&self) -> usize {
        self.components.len()
    }

    /// Period of a component.
    pub fn period_ns(&self, id: ComponentId) -> Result<u64, BicaError> {
        Ok(self.state(id)?.period_ns)
    }

    /// Counters of a component.
    pub fn counters(&self, id: ComponentId) -> Result<ComponentCounters, BicaError> {
        Ok(self.state(id)?.counters)
    }

    /// The active (top-level) list in stepping order.
    pub fn active(&self) -> &[ComponentId] {
        &self.active
    }

    /// Whether `id` is in the active list.
    pub fn is_active(&self, id: ComponentId) -> bool {
        self.active.contains(&id)
    }

    /// Steps currently in progress, outermost first (empty between steps).
    pub fn running(&self) -> &[ComponentId] {
        &self.running
    }

    /// Rounds completed so far.
    pub fn rounds(&self) -> u64 {
        self.rounds
    }

    /// The trace ring.
    pub fn trace(&self) -> &TraceBuffer {
        &self.trace
    }

    /// Removes and returns the held trace events.
    pub fn drain_trace(&mut self) -> Vec<TraceEvent> {
        self.trace.drain()
    }

    fn state(&self, id: ComponentId) -> Result<&ComponentState, BicaError> {
        self.components.get(id.index()).ok_or_else(|| unknown(id))
    }

    fn observe_time(&mut self, now_ns: u64) -> Result<(), BicaError> {
        if now_ns < self.last_now_ns {
            return Err(BicaError::TimeWentBackwards { now_ns, last_ns: self.last_now_ns });
        }
        self.last_now_ns = now_ns;
        Ok(())
    }

    fn refuse_during_step(&self) -> Result<(), BicaError> {
        match self.running.last() {
            Some(&running) => Err(BicaError::ChangeDuringStep { running }),
            None => Ok(()),
        }
    }

    /// Appends `id` to the end of the active list. Its release grid restarts at `now_ns`
    /// (or at its pending release, if that is later);
    /// if it was inactive for more than `reactivation_gap_periods` periods, its next run
    /// reports the gap. Activating an active component does nothing.
    pub fn activate(&mut self, id: ComponentId, now_ns: u64) -> Result<(), BicaError> {
        self.state(id)?;
        self.refuse_during_step()?;
        self.observe_time(now_ns)?;
        let gap_limit = self.gap_limit_ns(id);
        let state = &mut self.components[id.index()];
        #[cfg(feature = "mutants")]
        {
            state.pending_removal = false;
        }
        if state.in_active_list {
            return Ok(());
        }
        state.in_active_list = true;
        if let Some(seen) = state.last_seen_ns {
            let gap = now_ns - seen.min(now_ns);
            if gap > gap_limit {
                state.reactivation_pending_gap_ns = Some(gap);
            }
        }
        // Restart the grid at `now_ns`, unless the old grid's next release is still ahead:
        // keeping it then stops a quick deactivate/activate from running twice in a period.
        state.next_release_ns = Some(state.next_release_ns.map_or(now_ns, |release| release.max(now_ns)));
        self.active.push(id);
        self.trace.push(TraceEvent::Activated { component: id, at_ns: now_ns });
        Ok(())
    }

    /// Removes `id` from the active list: it is simply no longer stepped (no hook runs).
    /// Deactivating an inactive component does nothing.
    pub fn deactivate(&mut self, id: ComponentId, now_ns: u64) -> Result<(), BicaError> {
        self.state(id)?;
        self.refuse_during_step()?;
        self.observe_time(now_ns)?;
        let Some(position) = self.active.iter().position(|&a| a == id) else {
            return Ok(());
        };
        #[cfg(feature = "mutants")]
        if self.config.mutant == Some(SchedulerMutant::RemovedSteppedOnceMore) {
            // Planted bug: the removal waits for one more step of the component.
            self.components[id.index()].pending_removal = true;
            return Ok(());
        }
        self.remove_from_active(position, now_ns);
        Ok(())
    }

    fn remove_from_active(&mut self, position: usize, now_ns: u64) {
        let id = self.active.remove(position);
        if position < self.cursor {
            self.cursor -= 1;
        }
        if self.decided == Some(id) {
            self.decided = None;
        }
        let state = &mut self.components[id.index()];
        state.in_active_list = false;
        state.last_seen_ns = Some(now_ns);
        self.trace.push(TraceEvent::Deactivated { component: id, at_ns: now_ns });
    }

    fn gap_limit_ns(&self, id: ComponentId) -> u64 {
        self.components[id.index()].period_ns.saturating_mul(self.config.reactivation_gap_periods)
    }

    fn is_due(&self, id: ComponentId, now_ns: u64) -> bool {
        self.components[id.index()].next_release_ns.is_none_or(|release| release <= now_ns)
    }

    /// Decides what to do at `now_ns`: the next due component of the round, or how long to sleep.
    pub fn next_decision(&mut self, now_ns: u64) -> Result<Decision, BicaError> {
        if let Some(&running) = self.running.last() {
            return Err(BicaError::StepOverlap { component: running, running });
        }
        self.observe_time(now_ns)?;
        if self.active.is_empty() {
            self.decided = None;
            return Ok(Decision::Idle);
        }
        // At most two scans: the rest of this round, then (if anything is due) a new round.
        for _ in 0..2 {
            while self.cursor < self.active.len() {
                let id = self.active[self.cursor];
                if self.is_due(id, now_ns) {
                    self.decided = Some(id);
                    return Ok(Decision::Step(id));
                }
                self.cursor += 1;
            }
            self.cursor = 0;
            self.rounds += 1;
            if !self.active.iter().any(|&id| self.is_due(id, now_ns)) {
                break;
            }
        }
        self.decided = None;
        let earliest = self
            .active
            .iter()
            .filter_map(|&id| self.components[id.index()].next_release_ns)
            .min()
            .expect("invariant: every active component has a release grid");
        assert!(earliest > now_ns, "invariant: nothing is due when the scheduler sleeps");
        Ok(Decision::SleepUntil(earliest))
    }

    /// Asks the frequency gate of `id` whether its work runs at `now_ns`. A top-level
    /// caller must be the component [`next_decision`](Self::next_decision) chose; a nested
    /// caller must be the innermost running step. On [`Gate::Run`] the step is in progress
    /// until [`finish_step`](Self::finish_step).
    pub fn begin_step(&mut self, id: ComponentId, now_ns: u64, caller: Caller) -> Result<Gate, BicaError> {
        self.state(id)?;
        match caller {
            Caller::TopLevel => {
                if let Some(&running) = self.running.last() {
                    return Err(BicaError::StepOverlap { component: id, running });
                }
                if self.decided != Some(id) {
                    return Err(BicaError::NotDecided { component: id, decided: self.decided });
                }
            }
            Caller::Nested { parent } => {
                if self.running.last() != Some(&parent) {
                    return Err(BicaError::FinishMismatch { component: parent, running: self.running.last().copied() });
                }
            }
        }
        if self.running.contains(&id) || self.running.len() >= self.config.max_cascade_depth {
            let path = self.running.iter().chain(std::iter::once(&id)).map(|c| format!("{}", c.0)).collect::<Vec<_>>();
            return Err(BicaError::CascadeCycle { component: format!("{id:?}"), path: path.join(" -> ") });
        }
        self.observe_time(now_ns)?;
        if caller == Caller::TopLevel {
            self.decided = None;
        }
        let gap_limit = self.gap_limit_ns(id);
        let tolerance = self.config.miss_tolerance_ns;
        let warning_interval = self.config.warning_interval_ns;
        #[cfg(feature = "mutants")]
        let mutant = self.config.mutant;
        let state = &mut self.components[id.index()];

        // A dependency that was not stepped for a long time starts afresh: report the gap
        // and restart its grid, so idleness is not mistaken for lateness.
        if !state.in_active_list
            && let Some(seen) = state.last_seen_ns
        {
            let gap = now_ns - seen.min(now_ns);
            if gap > gap_limit {
                state.reactivation_pending_gap_ns = Some(gap);
                state.next_release_ns = Some(state.next_release_ns.map_or(now_ns, |release| release.max(now_ns)));
            }
        }
        state.last_seen_ns = Some(now_ns);
        let release = *state.next_release_ns.get_or_insert(now_ns);
        if now_ns < release {
            #[cfg(feature = "mutants")]
            if mutant == Some(SchedulerMutant::SharedDependencyTwice)
                && matches!(caller, Caller::Nested { .. })
                && state.counters.runs > 0
            {
                // Planted bug: the gate is ignored for nested calls, so a dependency
                // shared by two parents runs twice in one period.
                let previous = release - state.period_ns.min(release);
                return Ok(self.start_run(id, now_ns, caller, previous, 0, None));
            }
            state.counters.gated_skips += 1;
            self.trace.push(TraceEvent::GatedSkip { component: id, caller, at_ns: now_ns, next_release_ns: release });
            return Ok(Gate::NotDue { next_release_ns: release });
        }
        let lateness = now_ns - release;
        let skipped = lateness / state.period_ns;
        let next_release = release.saturating_add(skipped.saturating_add(1).saturating_mul(state.period_ns));
        #[cfg(feature = "mutants")]
        let next_release = if mutant == Some(SchedulerMutant::CatchUpBurst) {
            // Planted bug: advance one period only, so late runs follow back to back.
            release.saturating_add(state.period_ns)
        } else {
            next_release
        };
        #[cfg(feature = "mutants")]
        let skipped = if mutant == Some(SchedulerMutant::CatchUpBurst) { 0 } else { skipped };
        state.next_release_ns = Some(next_release);
        state.counters.skipped_releases += skipped;

        let miss_threshold = tolerance;
        #[cfg(feature = "mutants")]
        let miss_threshold =
            if mutant == Some(SchedulerMutant::MissOffByOne) { tolerance.saturating_add(1) } else { miss_threshold };
        let miss = if lateness > miss_threshold {
            state.counters.misses += 1;
            let warn = state.last_warning_ns.is_none_or(|last| now_ns.saturating_sub(last) >= warning_interval);
            let suppressed = state.misses_since_warning;
            if warn {
                state.counters.warnings += 1;
                state.last_warning_ns = Some(now_ns);
                state.misses_since_warning = 0;
            } else {
                state.misses_since_warning += 1;
            }
            Some(MissEvent {
                component: id,
                expected_ns: release,
                actual_ns: now_ns,
                lateness_ns: lateness,
                skipped_periods: skipped,
                warn,
                suppressed_since_last_warning: if warn { suppressed } else { 0 },
            })
        } else {
            None
        };
        Ok(self.start_run(id, now_ns, caller, release, skipped, miss))
    }

    fn start_run(
        &mut self,
        id: ComponentId,
        now_ns: u64,
        caller: Caller,
        release_ns: u64,
        skipped_periods: u64,
        miss: Option<MissEvent>,
    ) -> Gate {
        let state = &mut self.components[id.index()];
        state.counters.runs += 1;
        let reactivated = state.reactivation_pending_gap_ns.take();
        if reactivated.is_some() {
            state.counters.reactivations += 1;
        }
        let lateness_ns = now_ns - release_ns;
        self.running.push(id);
        if let Some(gap_ns) = reactivated {
            self.trace.push(TraceEvent::Reactivated { component: id, at_ns: now_ns, gap_ns });
        }
        if let Some(miss) = miss {
            self.trace.push(TraceEvent::Miss(miss));
        }
        self.trace.push(TraceEvent::StepStarted {
            component: id,
            caller,
            at_ns: now_ns,
            release_ns,
            lateness_ns,
            skipped_periods,
        });
        Gate::Run(RunInfo { release_ns, lateness_ns, skipped_periods, miss, reactivated_after_gap_ns: reactivated })
    }

    /// Reports that the innermost running step, `id`, finished at `now_ns`.
    pub fn finish_step(&mut self, id: ComponentId, now_ns: u64) -> Result<(), BicaError> {
        #[cfg(feature = "mutants")]
        let unchecked = self.config.mutant == Some(SchedulerMutant::FinishUnmatched);
        #[cfg(not(feature = "mutants"))]
        let unchecked = false;
        if self.running.last() != Some(&id) && !unchecked {
            return Err(BicaError::FinishMismatch { component: id, running: self.running.last().copied() });
        }
        self.observe_time(now_ns)?;
        self.running.pop();
        self.trace.push(TraceEvent::StepFinished { component: id, at_ns: now_ns });
        if self.running.is_empty() && self.active.get(self.cursor) == Some(&id) {
            // The top-level step of this round's candidate is done: move on.
            self.cursor += 1;
            #[cfg(feature = "mutants")]
            if self.components[id.index()].pending_removal {
                self.components[id.index()].pending_removal = false;
                self.remove_from_active(self.cursor - 1, now_ns);
            }
        }
        Ok(())
    }
}

fn unknown(id: ComponentId) -> BicaError {
    BicaError::UnknownComponent { component: format!("{id:?}") }
}
