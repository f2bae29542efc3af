//! Stateright model of the real BICA scheduler under overload: the checker drives the real
//! [`bica::core::SchedulerCore`] on a virtual clock, chooses every step's duration (nominal or overrun) and
//! may deactivate and reactivate components, and checks the graceful-degradation guarantees of the BICA
//! runtime on the trace events the core records in each transition.
//!
//! # The system
//!
//! K top-level components (the default has three: two parents that share one dependency, and one independent
//! component) are registered in the real core and activated at time 0; the shared dependency is registered
//! too but is never in the active list: a parent's step calls it through
//! `begin_step(dependency, now, Caller::Nested { parent })` before doing its own work, exactly as a BICA
//! component steps what it reads first. One model transition is one iteration of the driver loop of
//! `bica::runtime` (`run_once` and `run_forever`'s wait): ask [`SchedulerCore::next_decision`], then either run
//! the decided top-level step (with its cascade) to its end or sleep to the decided release; or serve a remote
//! request (an activation or deactivation), between iterations or halfway through a sleep, which the runtime's
//! wait on its request queue cuts short.
//!
//! Every transition also tries the driver calls the core must refuse, on copies of the core, between steps (finish
//! a step that is not running, start one the scheduler did not decide, a nested step without its parent, an
//! unknown component) and during a step (decide, start another top-level step, change the active list, step the
//! running component inside itself, finish one that is not running): each must return an error, never panic, and
//! leave the core as it was.
//!
//! # How properties are checked
//!
//! Each transition drains the core's trace and audits it against a small reference of the documented
//! policy (next release on the phase-preserving grid, last time seen, pending reactivation gap, rate-limiter
//! state; all of these mirror what the correct core keeps, so they do not enlarge the state space). The audit
//! records, in the new state, one bit per violated property (and a human-readable finding), and one bit per
//! interesting fact observed (an overrun, a miss, ...). The `always` properties test those bits, so a
//! counterexample ends exactly at the transition that broke the property; the `sometimes` properties show the
//! model really reaches overruns, misses, deactivations and reactivations, and the preconditions of the `always`
//! ones that a step need not meet (a run a period after an overload ended, for recovery; a late run within the
//! tolerance; a run later than one round; a nested step; a request during a sleep; an illegal call during a step). The events and findings of the
//! last transition are kept for display only: they take no part in the state's identity.

use std::fmt;
use std::hash::{Hash, Hasher};
use std::sync::Arc;

use bica::BicaError;
use bica::core::{ComponentCounters, ComponentId, Decision, Gate, SchedulerConfig, SchedulerCore};
use bica::trace::{Caller, MissEvent, TraceEvent};
use serde::{Deserialize, Serialize};
use stateright::{Model, Property};

use crate::report::{CheckOptions, CheckReport, run_check};

#[cfg(feature = "mutants")]
use bica::core::SchedulerMutant;

/// One top-level component of the model.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct TopLevelSpec {
    /// Name used in counterexamples.
    pub name: String,
    /// Period (its releases are `r0 + k·period`).
    pub period_ns: u64,
    /// Duration of its own work at nominal load (the dependency's run, if any, comes on top).
    pub nominal_ns: u64,
    /// Whether its step calls the shared dependency (as `Caller::Nested`) before its own work.
    pub calls_dependency: bool,
}

/// The dependency shared by the parents.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct DependencySpec {
    /// Name used in counterexamples.
    pub name: String,
    /// Period of its frequency gate.
    pub period_ns: u64,
    /// Duration of its work at nominal load.
    pub nominal_ns: u64,
}

/// Configuration of the scheduler model. Times are nanoseconds of the virtual clock.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct SchedulerModelConfig {
    /// The top-level components, in activation (and so stepping) order.
    pub components: Vec<TopLevelSpec>,
    /// The shared dependency.
    pub dependency: DependencySpec,
    /// Duration of an overrunning run (of a component's own work or of the dependency).
    pub overrun_ns: u64,
    /// How many runs in one path may overrun.
    pub max_overruns: u8,
    /// The core's miss tolerance: a miss is raised exactly when lateness exceeds it.
    pub miss_tolerance_ns: u64,
    /// The core's `reactivation_gap_periods` (k): a gap of more than k periods is signalled.
    pub reactivation_gap_periods: u64,
    /// The core's warning interval (at most one miss warning per component per interval).
    pub warning_interval_ns: u64,
    /// No transition starts at or after this virtual time (keeps the state space finite).
    pub horizon_ns: u64,
    /// How many activations/deactivations the checker may inject in one path.
    pub max_list_changes: u8,
    /// Run every transition twice and compare (the determinism property).
    pub check_determinism: bool,
    /// The planted scheduler bug, if any.
    #[cfg(feature = "mutants")]
    #[serde(serialize_with = "serialize_mutant", skip_deserializing)]
    pub mutant: Option<SchedulerMutant>,
}

#[cfg(feature = "mutants")]
fn serialize_mutant<S: serde::Serializer>(mutant: &Option<SchedulerMutant>, serializer: S) -> Result<S::Ok, S::Error> {
    match mutant {
        Some(mutant) => serializer.serialize_some(&format!("{mutant:?}")),
        None => serializer.serialize_none(),
    }
}

impl Default for SchedulerModelConfig {
    /// Time is counted in nanoseconds of the core's clock but the numbers are kept small (the model is
    /// scale-free; small numbers keep counterexamples readable and let a lateness of exactly tolerance + 1 ns
    /// occur). Two parents ("planner", "controller", period 10 ns) share a dependency ("perception", period
    /// 10 ns) and an independent "logger" has period 20 ns; nominal work takes 1 ns (2 ns for the logger); an
    /// overrunning run takes 12 ns (longer than a period, so releases are skipped); the tolerance is 4 ns (one
    /// round, so nominal load never misses); two overruns (so one component can miss twice within the 20 ns
    /// warning interval) and two list changes per path; k = 1 period; horizon 40 ns.
    fn default() -> Self {
        let top = |name: &str, period_ns: u64, nominal_ns: u64, calls_dependency: bool| TopLevelSpec {
            name: name.to_owned(),
            period_ns,
            nominal_ns,
            calls_dependency,
        };
        SchedulerModelConfig {
            components: vec![top("planner", 10, 1, true), top("controller", 10, 1, true), top("logger", 20, 2, false)],
            dependency: DependencySpec { name: "perception".to_owned(), period_ns: 10, nominal_ns: 1 },
            overrun_ns: 12,
            max_overruns: 2,
            miss_tolerance_ns: 4,
            reactivation_gap_periods: 1,
            warning_interval_ns: 20,
            horizon_ns: 40,
            max_list_changes: 2,
            check_determinism: true,
            #[cfg(feature = "mutants")]
            mutant: None,
        }
    }
}

impl SchedulerModelConfig {
    /// Number of registered components: the top-level ones and the dependency (the last id).
    pub fn registered(&self) -> usize {
        self.components.len() + 1
    }

    /// Id of the shared dependency in the core.
    pub fn dependency_id(&self) -> ComponentId {
        ComponentId(self.components.len() as u32)
    }

    /// Duration of one nominal top-level step of component `index`, its dependency's run included.
    pub fn nominal_step_ns(&self, index: usize) -> u64 {
        let spec = &self.components[index];
        spec.nominal_ns + if spec.calls_dependency { self.dependency.nominal_ns } else { 0 }
    }

    /// "One scheduler round" for top-level component `index`: the sum of the nominal step durations of the
    /// other top-level components (each parent's step including a run of the dependency). In a round every
    /// due component is stepped at most once, so at nominal load this is the longest a released component
    /// waits for the others.
    pub fn round_ns(&self, index: usize) -> u64 {
        (0..self.components.len()).filter(|&other| other != index).map(|other| self.nominal_step_ns(other)).sum()
    }

    /// Period of a registered component (top-level index, or the dependency's id).
    pub fn period_ns(&self, index: usize) -> u64 {
        self.components.get(index).map_or(self.dependency.period_ns, |spec| spec.period_ns)
    }

    /// Name of a registered component.
    pub fn name(&self, index: usize) -> &str {
        self.components.get(index).map_or(self.dependency.name.as_str(), |spec| spec.name.as_str())
    }

    /// Checks that the configuration is one the degradation guarantees are stated for: at least one
    /// component, non-zero periods, a nominal load that fits in the shortest period, a tolerance of at least
    /// one round (so nominal load raises no miss) and an overrun longer than every nominal duration.
    pub fn validate(&self) -> Result<(), String> {
        if self.components.is_empty() || self.components.len() > 15 {
            return Err("the model needs between 1 and 15 top-level components".to_owned());
        }
        if self.components.iter().any(|c| c.period_ns == 0) || self.dependency.period_ns == 0 {
            return Err("periods must be positive".to_owned());
        }
        let load: u64 = (0..self.components.len()).map(|i| self.nominal_step_ns(i)).sum();
        let shortest = self.components.iter().map(|c| c.period_ns).chain([self.dependency.period_ns]).min();
        if shortest.is_some_and(|shortest| load > shortest) {
            return Err(format!("nominal load per round ({load} ns) exceeds the shortest period"));
        }
        if let Some(index) = (0..self.components.len()).find(|&i| self.round_ns(i) > self.miss_tolerance_ns) {
            return Err(format!(
                "the tolerance ({} ns) is shorter than one round for {} ({} ns): nominal load would miss",
                self.miss_tolerance_ns,
                self.name(index),
                self.round_ns(index)
            ));
        }
        let longest_nominal =
            self.components.iter().map(|c| c.nominal_ns).chain([self.dependency.nominal_ns]).max().unwrap_or(0);
        if self.overrun_ns <= longest_nominal {
            return Err("the overrun must be longer than every nominal duration".to_owned());
        }
        Ok(())
    }

    fn scheduler_config(&self) -> SchedulerConfig {
        SchedulerConfig {
            miss_tolerance_ns: self.miss_tolerance_ns,
            reactivation_gap_periods: self.reactivation_gap_periods,
            warning_interval_ns: self.warning_interval_ns,
            trace_capacity: 64,
            #[cfg(feature = "mutants")]
            mutant: self.mutant,
            ..SchedulerConfig::default()
        }
    }
}

/// The properties of the model: `always` ones are violated by a transition, `sometimes` ones are facts a
/// transition may exhibit.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Check {
    /// A step starts only when no top-level step runs, a nested step only inside its parent, and no
    /// component runs inside itself; time never goes back.
    NoOverlap,
    /// Every started step finishes (within its transition); nothing is left running between iterations.
    NoCancellation,
    /// Every driver call the policy allows is accepted by the core, and the decided top-level component's
    /// gate is open.
    CallsAccepted,
    /// A run never starts before its release, never serves a release that an earlier run served or dropped:
    /// two runs of a component never fall in one period of its grid.
    RateLimit,
    /// Runs serve the phase-preserving grid: the oldest pending release, lateness = start − release, and
    /// skipped = lateness / period releases dropped (never caught up).
    SkippedReleasesCounted,
    /// A nested call runs the shared dependency's work iff one of its releases is pending: a second parent's
    /// call in the same period is a gated skip.
    SharedDependencyOncePerPeriod,
    /// A top-level run's lateness is at most X + one round, X being the total overrun so far; the scheduler
    /// never sleeps while a component is due.
    LatenessBound,
    /// A top-level run released one period or more after the last overrun ended is on time again: lateness
    /// at most one round (≤ tolerance) and no skipped release.
    Recovery,
    /// A miss is raised exactly when a run's lateness exceeds the tolerance, carrying its release, start,
    /// lateness and skipped periods.
    MissExactness,
    /// Miss warnings are rate-limited (one per interval, reporting how many were suppressed) while counters
    /// count every run, skip, miss and reactivation; no trace event is dropped.
    CountersNeverLost,
    /// A deactivated component is never stepped by the scheduler again until it is activated.
    QuietShutdown,
    /// A component stepped again after a gap of more than k periods is told so, with the gap; otherwise not.
    ReactivationSignalled,
    /// Running a transition twice from the same state gives the same state and trace.
    Determinism,
    /// Every illegal driver call (finishing a step that is not running, starting a step the scheduler did not
    /// decide or while another runs, deciding or changing the list during a step, stepping a component inside
    /// itself, an unknown component) is refused with an error and leaves the core as it was.
    IllegalCallsRefused,
}

impl Check {
    /// Every `always` property, in report order.
    pub const ALL: [Check; 14] = [
        Check::NoOverlap,
        Check::NoCancellation,
        Check::CallsAccepted,
        Check::RateLimit,
        Check::SkippedReleasesCounted,
        Check::SharedDependencyOncePerPeriod,
        Check::LatenessBound,
        Check::Recovery,
        Check::MissExactness,
        Check::CountersNeverLost,
        Check::QuietShutdown,
        Check::ReactivationSignalled,
        Check::Determinism,
        Check::IllegalCallsRefused,
    ];

    /// The property's name in reports.
    pub const fn name(self) -> &'static str {
        match self {
            Check::NoOverlap => "no step overlaps another or itself",
            Check::NoCancellation => "no started step is cancelled",
            Check::CallsAccepted => "the core accepts every driver call",
            Check::RateLimit => "gated work never runs more often than its period allows",
            Check::SkippedReleasesCounted => "skipped releases are counted, never caught up (phase-preserving grid)",
            Check::SharedDependencyOncePerPeriod => "shared dependency runs once per period",
            Check::LatenessBound => "lateness after overruns of X is at most X plus one round",
            Check::Recovery => "on time again one period after the last overrun",
            Check::MissExactness => "a miss is raised exactly when lateness exceeds the tolerance",
            Check::CountersNeverLost => "warnings rate-limited, counters never lost",
            Check::QuietShutdown => "a removed component is never stepped again (quiet shutdown)",
            Check::ReactivationSignalled => "reactivation after a gap of more than k periods is signalled",
            Check::Determinism => "identical inputs give identical traces and states",
            Check::IllegalCallsRefused => "illegal driver calls are refused with an error and change nothing",
        }
    }

    const fn bit(self) -> u16 {
        1 << self as u16
    }
}

/// Facts the `sometimes` properties look for, so a model that never reaches them is caught.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Fact {
    /// A run overran.
    Overrun,
    /// A release was dropped (skipped periods > 0).
    SkippedRelease,
    /// A miss was raised.
    Miss,
    /// A miss warning was suppressed by the rate limiter.
    SuppressedWarning,
    /// A second parent's call of the shared dependency was a gated skip.
    DependencyGatedSkip,
    /// A component was deactivated.
    Deactivation,
    /// A reactivation after a long gap was signalled.
    Reactivation,
    /// A top-level run released a period or more after an overload ended (the precondition of `Recovery`).
    RunAfterOverload,
    /// A top-level run later than one round (the overrun term of `LatenessBound` at work).
    LateBeyondRound,
    /// A run late but within the tolerance, so no miss (the other side of `MissExactness`).
    LateWithinTolerance,
    /// A nested step ran inside its parent (the nested case of `NoOverlap`).
    NestedStep,
    /// A remote request (an activation or deactivation) woke the driver during a sleep.
    RequestDuringSleep,
    /// An illegal driver call was tried while a step was running (the in-step case of `IllegalCallsRefused`).
    IllegalCallDuringStep,
}

impl Fact {
    /// Every fact, in report order.
    pub const ALL: [Fact; 13] = [
        Fact::Overrun,
        Fact::SkippedRelease,
        Fact::Miss,
        Fact::SuppressedWarning,
        Fact::DependencyGatedSkip,
        Fact::Deactivation,
        Fact::Reactivation,
        Fact::RunAfterOverload,
        Fact::LateBeyondRound,
        Fact::LateWithinTolerance,
        Fact::NestedStep,
        Fact::RequestDuringSleep,
        Fact::IllegalCallDuringStep,
    ];

    /// The property's name in reports.
    pub const fn name(self) -> &'static str {
        match self {
            Fact::Overrun => "a step overruns",
            Fact::SkippedRelease => "a release is skipped",
            Fact::Miss => "a miss is raised",
            Fact::SuppressedWarning => "a miss warning is suppressed by the rate limiter",
            Fact::DependencyGatedSkip => "a second call of the shared dependency in a period is gated",
            Fact::Deactivation => "a component is deactivated",
            Fact::Reactivation => "a reactivation after a long gap is signalled",
            Fact::RunAfterOverload => "a run is released a period after an overload ended",
            Fact::LateBeyondRound => "a run is later than one round",
            Fact::LateWithinTolerance => "a run is late within the tolerance",
            Fact::NestedStep => "a nested step runs inside its parent",
            Fact::RequestDuringSleep => "a remote request wakes the driver during a sleep",
            Fact::IllegalCallDuringStep => "an illegal driver call is tried during a step",
        }
    }

    const fn bit(self) -> u16 {
        1 << self as u16
    }
}

/// Which run of a step overruns.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum OverrunIn {
    /// The top-level component's own work.
    Own,
    /// The shared dependency's run inside the step.
    Dependency,
}

/// What the checker does next.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum SchedulerAction {
    /// Run the top-level step the scheduler decides (component index), with the chosen overrun, if any.
    Step {
        /// Time the step starts.
        at_ns: u64,
        /// Top-level component index.
        component: usize,
        /// Which run overruns, if any.
        overrun: Option<OverrunIn>,
    },
    /// Nothing is due: sleep until the scheduler's wake-up time.
    Sleep {
        /// Time the driver goes to sleep.
        from_ns: u64,
        /// Time it wakes.
        until_ns: u64,
    },
    /// Activate an inactive top-level component.
    Activate {
        /// Time of the request.
        at_ns: u64,
        /// Top-level component index.
        component: usize,
    },
    /// Deactivate an active top-level component.
    Deactivate {
        /// Time of the request.
        at_ns: u64,
        /// Top-level component index.
        component: usize,
    },
}

/// What the reference keeps for one registered component; each field mirrors what the correct core keeps.
#[derive(Clone, Debug, PartialEq, Eq, Hash, Default)]
struct Reference {
    /// Oldest release not yet served or dropped.
    next_release_ns: Option<u64>,
    /// Last time it was stepped (run or gated skip) or deactivated.
    last_seen_ns: Option<u64>,
    /// Gap to report on its next run.
    pending_gap_ns: Option<u64>,
    /// In the active list (top-level components only).
    active: bool,
    /// Last miss warning.
    last_warning_ns: Option<u64>,
    /// Misses not warned about since the last warning.
    suppressed: u64,
}

/// A state of the model: the real scheduler core, the virtual time, the reference, the budgets, and the
/// verdicts of the transition that led here.
#[derive(Clone)]
pub struct SchedulerState {
    core: SchedulerCore,
    now_ns: u64,
    reference: Vec<Reference>,
    overruns: u8,
    overrun_excess_ns: u64,
    overload_end_ns: Option<u64>,
    list_changes: u8,
    violated: u16,
    observed: u16,
    // Display only: not part of the state's identity (see `Hash`/`PartialEq`).
    last_events: Vec<TraceEvent>,
    findings: Vec<String>,
    names: Arc<[String]>,
}

impl SchedulerState {
    /// The real scheduler core.
    pub fn core(&self) -> &SchedulerCore {
        &self.core
    }

    /// Virtual time.
    pub fn now_ns(&self) -> u64 {
        self.now_ns
    }

    /// Trace events of the transition that led here.
    pub fn last_events(&self) -> &[TraceEvent] {
        &self.last_events
    }

    /// Why each violated property failed in the transition that led here.
    pub fn findings(&self) -> &[String] {
        &self.findings
    }

    /// Whether the transition that led here violated `check`.
    pub fn violates(&self, check: Check) -> bool {
        self.violated & check.bit() != 0
    }

    /// Whether the transition that led here exhibited `fact`.
    pub fn observed(&self, fact: Fact) -> bool {
        self.observed & fact.bit() != 0
    }

    fn identity(&self) -> Identity<'_> {
        (
            &self.core,
            self.now_ns,
            self.reference.as_slice(),
            (self.overruns, self.overrun_excess_ns, self.overload_end_ns, self.list_changes),
            (self.violated, self.observed),
        )
    }
}

/// The fields that make a state's identity (everything but the display-only ones).
type Identity<'a> = (&'a SchedulerCore, u64, &'a [Reference], (u8, u64, Option<u64>, u8), (u16, u16));

impl PartialEq for SchedulerState {
    fn eq(&self, other: &Self) -> bool {
        self.identity() == other.identity()
    }
}

impl Eq for SchedulerState {}

impl Hash for SchedulerState {
    fn hash<H: Hasher>(&self, state: &mut H) {
        self.identity().hash(state);
    }
}

/// Formats a time of the virtual clock.
fn ns(time: u64) -> String {
    format!("{time}ns")
}

fn describe_event(names: &[String], event: &TraceEvent) -> String {
    let name = |id: ComponentId| names.get(id.0 as usize).cloned().unwrap_or_else(|| format!("#{}", id.0));
    let caller = |caller: Caller| match caller {
        Caller::TopLevel => "top-level".to_owned(),
        Caller::Nested { parent } => format!("called by {}", name(parent)),
    };
    match *event {
        TraceEvent::StepStarted { component, caller: c, at_ns, release_ns, lateness_ns, skipped_periods } => format!(
            "{} started at {} ({}), release {}, lateness {}, skipped {}",
            name(component),
            ns(at_ns),
            caller(c),
            ns(release_ns),
            ns(lateness_ns),
            skipped_periods
        ),
        TraceEvent::StepFinished { component, at_ns } => format!("{} finished at {}", name(component), ns(at_ns)),
        TraceEvent::GatedSkip { component, caller: c, at_ns, next_release_ns } => {
            format!("{} gated at {} ({}), next release {}", name(component), ns(at_ns), caller(c), ns(next_release_ns))
        }
        TraceEvent::Miss(miss) => format!(
            "MISS {}: expected {}, actual {}, lateness {}, skipped {}, warn {}, suppressed {}",
            name(miss.component),
            ns(miss.expected_ns),
            ns(miss.actual_ns),
            ns(miss.lateness_ns),
            miss.skipped_periods,
            miss.warn,
            miss.suppressed_since_last_warning
        ),
        TraceEvent::Activated { component, at_ns } => format!("{} activated at {}", name(component), ns(at_ns)),
        TraceEvent::Deactivated { component, at_ns } => format!("{} deactivated at {}", name(component), ns(at_ns)),
        TraceEvent::Reactivated { component, at_ns, gap_ns } => {
            format!("{} told at {} it was reactivated after {}", name(component), ns(at_ns), ns(gap_ns))
        }
    }
}

impl fmt::Debug for SchedulerState {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "time {}, overruns {} (+{} in total), overload ended at {}, list changes {}",
            ns(self.now_ns),
            self.overruns,
            ns(self.overrun_excess_ns),
            self.overload_end_ns.map_or("-".to_owned(), ns),
            self.list_changes
        )?;
        writeln!(f, "active list {:?}, rounds {}", self.core.active(), self.core.rounds())?;
        for (index, reference) in self.reference.iter().enumerate() {
            let counters = self.core.counters(ComponentId(index as u32)).unwrap_or_default();
            writeln!(
                f,
                "{}: next release {}, runs {}, gated {}, skipped {}, misses {}, warnings {}, reactivations {}{}",
                self.names.get(index).map_or("?", String::as_str),
                reference.next_release_ns.map_or("-".to_owned(), ns),
                counters.runs,
                counters.gated_skips,
                counters.skipped_releases,
                counters.misses,
                counters.warnings,
                counters.reactivations,
                if reference.active { "" } else { " (inactive)" }
            )?;
        }
        writeln!(f, "trace of the last transition:")?;
        for event in &self.last_events {
            writeln!(f, "  {}", describe_event(&self.names, event))?;
        }
        for finding in &self.findings {
            writeln!(f, "VIOLATION: {finding}")?;
        }
        Ok(())
    }
}

/// The model: the configuration and the component names.
#[derive(Clone, Debug)]
pub struct SchedulerModel {
    config: SchedulerModelConfig,
    names: Arc<[String]>,
}

impl SchedulerModel {
    /// A model of `config` (see [`SchedulerModelConfig::validate`]).
    pub fn new(config: SchedulerModelConfig) -> Result<Self, String> {
        config.validate()?;
        let names = (0..config.registered()).map(|i| config.name(i).to_owned()).collect();
        Ok(SchedulerModel { config, names })
    }

    /// The configuration.
    pub fn config(&self) -> &SchedulerModelConfig {
        &self.config
    }

    /// The state at time 0: every top-level component registered and activated in order, the dependency
    /// registered only.
    pub fn initial_state(&self) -> SchedulerState {
        let mut core = SchedulerCore::new(self.config.scheduler_config());
        for index in 0..self.config.registered() {
            core.register(self.config.period_ns(index)).expect("validated periods are positive");
        }
        let mut reference = vec![Reference::default(); self.config.registered()];
        for (index, entry) in reference.iter_mut().enumerate().take(self.config.components.len()) {
            core.activate(ComponentId(index as u32), 0).expect("activation at time 0 is accepted");
            entry.active = true;
            entry.next_release_ns = Some(0);
        }
        let events = core.drain_trace();
        SchedulerState {
            core,
            now_ns: 0,
            reference,
            overruns: 0,
            overrun_excess_ns: 0,
            overload_end_ns: None,
            list_changes: 0,
            violated: 0,
            observed: 0,
            last_events: events,
            findings: Vec::new(),
            names: Arc::clone(&self.names),
        }
    }

    /// Applies `action` to `state` once (without the determinism check). `None` if the action does not apply
    /// (an overrun chosen for a dependency whose gate is closed).
    pub fn apply(&self, state: &SchedulerState, action: SchedulerAction) -> Option<SchedulerState> {
        let mut next = state.clone();
        next.violated = 0;
        next.observed = 0;
        next.last_events.clear();
        next.findings.clear();
        let before: Vec<ComponentCounters> = (0..self.config.registered())
            .map(|i| next.core.counters(ComponentId(i as u32)).unwrap_or_default())
            .collect();
        let mut audit = Audit { model: self, violated: 0, observed: 0, findings: Vec::new() };
        audit.illegal_between_steps(&state.core, state.now_ns);
        let now = self.serve_request_time(state, action, &mut audit);
        next.now_ns = now;
        match action {
            SchedulerAction::Activate { component, .. } => {
                next.list_changes += 1;
                if let Err(error) = next.core.activate(ComponentId(component as u32), now) {
                    audit.fail(Check::CallsAccepted, format!("activate({}) refused: {error}", self.names[component]));
                }
                let limit = self.config.period_ns(component).saturating_mul(self.config.reactivation_gap_periods);
                let reference = &mut next.reference[component];
                if !reference.active {
                    reference.active = true;
                    if let Some(seen) = reference.last_seen_ns
                        && now - seen.min(now) > limit
                    {
                        reference.pending_gap_ns = Some(now - seen.min(now));
                    }
                    reference.next_release_ns = Some(reference.next_release_ns.map_or(now, |r| r.max(now)));
                }
            }
            SchedulerAction::Deactivate { component, .. } => {
                next.list_changes += 1;
                audit.observe(Fact::Deactivation);
                if let Err(error) = next.core.deactivate(ComponentId(component as u32), now) {
                    audit.fail(Check::CallsAccepted, format!("deactivate({}) refused: {error}", self.names[component]));
                }
                let reference = &mut next.reference[component];
                if reference.active {
                    reference.active = false;
                    reference.last_seen_ns = Some(now);
                }
            }
            SchedulerAction::Sleep { until_ns, .. } => {
                match next.core.next_decision(now) {
                    Ok(Decision::SleepUntil(wake)) if wake == until_ns => {}
                    other => audit.fail(
                        Check::Determinism,
                        format!("the decision at {} changed from sleep until {} to {other:?}", ns(now), ns(until_ns)),
                    ),
                }
                let due: Vec<usize> = (0..self.config.components.len())
                    .filter(|&i| {
                        next.reference[i].active && next.reference[i].next_release_ns.is_some_and(|r| r <= now)
                    })
                    .collect();
                if !due.is_empty() {
                    let names: Vec<&str> = due.iter().map(|&i| self.names[i].as_str()).collect();
                    audit.fail(
                        Check::LatenessBound,
                        format!("the scheduler sleeps at {} while {names:?} are due", ns(now)),
                    );
                }
                let earliest = (0..self.config.components.len())
                    .filter(|&i| next.reference[i].active)
                    .filter_map(|i| next.reference[i].next_release_ns)
                    .min();
                if earliest.is_some_and(|earliest| earliest < until_ns) {
                    audit.fail(
                        Check::LatenessBound,
                        format!(
                            "the scheduler sleeps until {} past a release at {}",
                            ns(until_ns),
                            ns(earliest.unwrap_or(0))
                        ),
                    );
                }
                next.now_ns = until_ns.max(now);
            }
            SchedulerAction::Step { component, overrun, .. } => {
                let end = self.run_step(&mut next, &mut audit, component, overrun)?;
                next.now_ns = end;
            }
        }
        let events = next.core.drain_trace();
        audit.events(state, &mut next, &events);
        audit.counters(&next, &before, &events);
        next.violated = audit.violated;
        next.observed = audit.observed;
        next.findings = audit.findings;
        next.last_events = events;
        Some(next)
    }

    /// The time an action happens: now, or, for a remote request that arrives while the driver sleeps, the
    /// request's arrival (the runtime's loop wakes on its request queue and serves it at once).
    fn serve_request_time(&self, state: &SchedulerState, action: SchedulerAction, audit: &mut Audit<'_>) -> u64 {
        let at_ns = match action {
            SchedulerAction::Activate { at_ns, .. } | SchedulerAction::Deactivate { at_ns, .. } => at_ns,
            _ => return state.now_ns,
        };
        if at_ns > state.now_ns {
            audit.observe(Fact::RequestDuringSleep);
        }
        at_ns
    }

    /// Drives one top-level step (and its cascade) through the real core; returns its end time.
    fn run_step(
        &self,
        next: &mut SchedulerState,
        audit: &mut Audit<'_>,
        component: usize,
        overrun: Option<OverrunIn>,
    ) -> Option<u64> {
        let now = next.now_ns;
        let id = ComponentId(component as u32);
        let name = &self.names[component];
        match next.core.next_decision(now) {
            Ok(Decision::Step(decided)) if decided == id => {}
            other => {
                audit.fail(Check::Determinism, format!("the decision at {} changed from {name} to {other:?}", ns(now)));
                return Some(now);
            }
        }
        match next.core.begin_step(id, now, Caller::TopLevel) {
            Ok(Gate::Run(_)) => audit.illegal_during_step(&next.core, id, now),
            Ok(Gate::NotDue { next_release_ns }) => {
                audit.fail(
                    Check::CallsAccepted,
                    format!("{name} was decided at {} but its gate is closed until {}", ns(now), ns(next_release_ns)),
                );
                return Some(now);
            }
            Err(error) => {
                audit.fail(Check::CallsAccepted, format!("begin_step({name}) at {} refused: {error}", ns(now)));
                return Some(now);
            }
        }
        if overrun.is_some() {
            audit.observe(Fact::Overrun);
        }
        let spec = &self.config.components[component];
        let mut time = now;
        if spec.calls_dependency {
            let dependency = self.config.dependency_id();
            match next.core.begin_step(dependency, time, Caller::Nested { parent: id }) {
                Ok(Gate::Run(_)) => {
                    let duration = if overrun == Some(OverrunIn::Dependency) {
                        self.overran(next, time, self.config.dependency.nominal_ns)
                    } else {
                        self.config.dependency.nominal_ns
                    };
                    time += duration;
                    if let Err(error) = next.core.finish_step(dependency, time) {
                        audit.fail(Check::CallsAccepted, format!("finish_step(dependency) refused: {error}"));
                    }
                }
                Ok(Gate::NotDue { .. }) if overrun == Some(OverrunIn::Dependency) => return None,
                Ok(Gate::NotDue { .. }) => {}
                Err(error) => audit.fail(Check::CallsAccepted, format!("nested begin_step refused: {error}")),
            }
        }
        let duration =
            if overrun == Some(OverrunIn::Own) { self.overran(next, time, spec.nominal_ns) } else { spec.nominal_ns };
        time += duration;
        if let Err(error) = next.core.finish_step(id, time) {
            audit.fail(Check::CallsAccepted, format!("finish_step({name}) at {} refused: {error}", ns(time)));
        }
        Some(time)
    }

    /// Records an overrun of a run starting at `start` with nominal duration `nominal`; returns its duration.
    fn overran(&self, next: &mut SchedulerState, start: u64, nominal: u64) -> u64 {
        next.overruns += 1;
        next.overrun_excess_ns += self.config.overrun_ns - nominal;
        next.overload_end_ns = Some(start + self.config.overrun_ns);
        self.config.overrun_ns
    }

    /// The property list (`always` then `sometimes`).
    fn property_list() -> Vec<Property<Self>> {
        macro_rules! always {
            ($check:expr) => {
                Property::always($check.name(), |_: &SchedulerModel, s: &SchedulerState| !s.violates($check))
            };
        }
        macro_rules! sometimes {
            ($fact:expr) => {
                Property::sometimes($fact.name(), |_: &SchedulerModel, s: &SchedulerState| s.observed($fact))
            };
        }
        vec![
            always!(Check::NoOverlap),
            always!(Check::NoCancellation),
            always!(Check::CallsAccepted),
            always!(Check::RateLimit),
            always!(Check::SkippedReleasesCounted),
            always!(Check::SharedDependencyOncePerPeriod),
            always!(Check::LatenessBound),
            always!(Check::Recovery),
            always!(Check::MissExactness),
            always!(Check::CountersNeverLost),
            always!(Check::QuietShutdown),
            always!(Check::ReactivationSignalled),
            always!(Check::Determinism),
            always!(Check::IllegalCallsRefused),
            sometimes!(Fact::Overrun),
            sometimes!(Fact::SkippedRelease),
            sometimes!(Fact::Miss),
            sometimes!(Fact::SuppressedWarning),
            sometimes!(Fact::DependencyGatedSkip),
            sometimes!(Fact::Deactivation),
            sometimes!(Fact::Reactivation),
            sometimes!(Fact::RunAfterOverload),
            sometimes!(Fact::LateBeyondRound),
            sometimes!(Fact::LateWithinTolerance),
            sometimes!(Fact::NestedStep),
            sometimes!(Fact::RequestDuringSleep),
            sometimes!(Fact::IllegalCallDuringStep),
        ]
    }
}

/// Verdicts collected while auditing one transition.
struct Audit<'a> {
    model: &'a SchedulerModel,
    violated: u16,
    observed: u16,
    findings: Vec<String>,
}

impl Audit<'_> {
    fn fail(&mut self, check: Check, finding: String) {
        self.violated |= check.bit();
        self.findings.push(format!("[{}] {finding}", check.name()));
    }

    fn observe(&mut self, fact: Fact) {
        self.observed |= fact.bit();
    }

    /// Tries an illegal driver call on a copy of `core`: it must be refused, and the copy left as it was.
    fn try_illegal(
        &mut self,
        core: &SchedulerCore,
        what: &str,
        call: impl FnOnce(&mut SchedulerCore) -> Result<(), BicaError>,
    ) {
        let mut probe = core.clone();
        let verdict = match call(&mut probe) {
            Ok(()) => "accepted",
            Err(_) if probe != *core => "refused, but it changed the core",
            Err(_) => return,
        };
        self.fail(Check::IllegalCallsRefused, format!("{what}: {verdict}"));
    }

    /// The illegal calls a driver could make between two iterations of its loop (no step running at `now`).
    fn illegal_between_steps(&mut self, core: &SchedulerCore, now: u64) {
        let config = &self.model.config;
        let first = ComponentId(0);
        let unknown = ComponentId(config.registered() as u32);
        let dependency = config.dependency_id();
        self.try_illegal(core, "finish_step with no step running", |c| c.finish_step(first, now));
        self.try_illegal(core, "begin_step of an unknown component", |c| {
            c.begin_step(unknown, now, Caller::TopLevel).map(drop)
        });
        self.try_illegal(core, "a nested begin_step whose parent is not running", |c| {
            c.begin_step(dependency, now, Caller::Nested { parent: first }).map(drop)
        });
        // A top-level step the scheduler did not decide (after a decision, so the cursor is where it would be).
        let mut decided = core.clone();
        let chosen = match decided.next_decision(now) {
            Ok(Decision::Step(id)) => Some(id),
            _ => None,
        };
        let other = (0..config.components.len() as u32).map(ComponentId).find(|&id| Some(id) != chosen);
        if let Some(other) = other {
            self.try_illegal(&decided, "a top-level begin_step the scheduler did not decide", |c| {
                c.begin_step(other, now, Caller::TopLevel).map(drop)
            });
        }
    }

    /// The illegal calls a driver could make while the top-level step of `running` runs, at `now`.
    fn illegal_during_step(&mut self, core: &SchedulerCore, running: ComponentId, now: u64) {
        self.observe(Fact::IllegalCallDuringStep);
        let dependency = self.model.config.dependency_id();
        self.try_illegal(core, "next_decision during a step", |c| c.next_decision(now).map(drop));
        self.try_illegal(core, "a second top-level begin_step during a step", |c| {
            c.begin_step(running, now, Caller::TopLevel).map(drop)
        });
        self.try_illegal(core, "activate during a step", |c| c.activate(running, now));
        self.try_illegal(core, "deactivate during a step", |c| c.deactivate(running, now));
        self.try_illegal(core, "a step of the running component inside itself", |c| {
            c.begin_step(running, now, Caller::Nested { parent: running }).map(drop)
        });
        self.try_illegal(core, "finish_step of a component that is not running", |c| c.finish_step(dependency, now));
    }

    fn name(&self, id: ComponentId) -> String {
        self.model.names.get(id.0 as usize).cloned().unwrap_or_else(|| format!("#{}", id.0))
    }

    /// Audits the transition's trace against the reference, updating the reference as it goes.
    fn events(&mut self, previous: &SchedulerState, next: &mut SchedulerState, events: &[TraceEvent]) {
        let config = &self.model.config;
        let top_level = config.components.len();
        let tolerance = config.miss_tolerance_ns;
        let mut stack: Vec<(ComponentId, u64)> = Vec::new();
        let mut last_time = previous.now_ns;
        let mut pending_miss: Option<MissEvent> = None;
        let mut pending_gap: Option<(ComponentId, u64)> = None;
        let mut dependency_ran_in_step = false;
        for event in events {
            match *event {
                TraceEvent::Miss(miss) => {
                    if pending_miss.replace(miss).is_some() {
                        self.fail(Check::MissExactness, "two misses raised for one run".to_owned());
                    }
                }
                TraceEvent::Reactivated { component, gap_ns, .. } => {
                    pending_gap = Some((component, gap_ns));
                }
                TraceEvent::StepStarted { component, caller, at_ns, release_ns, lateness_ns, skipped_periods } => {
                    let name = self.name(component);
                    let index = component.0 as usize;
                    let period = config.period_ns(index);
                    // Overlap.
                    if at_ns < last_time {
                        self.fail(Check::NoOverlap, format!("{name} starts at {} after {}", ns(at_ns), ns(last_time)));
                    }
                    last_time = at_ns;
                    match caller {
                        Caller::TopLevel if !stack.is_empty() => self.fail(
                            Check::NoOverlap,
                            format!("top-level {name} starts while {} runs", self.name(stack[stack.len() - 1].0)),
                        ),
                        Caller::Nested { parent } if stack.last().map(|s| s.0) != Some(parent) => self.fail(
                            Check::NoOverlap,
                            format!("{name} called by {} which is not the running step", self.name(parent)),
                        ),
                        _ => {}
                    }
                    if stack.iter().any(|s| s.0 == component) {
                        self.fail(Check::NoOverlap, format!("{name} starts inside its own step"));
                    }
                    if matches!(caller, Caller::Nested { .. }) {
                        self.observe(Fact::NestedStep);
                    }
                    stack.push((component, at_ns));
                    // Quiet shutdown.
                    if caller == Caller::TopLevel && index < top_level && !next.reference[index].active {
                        self.fail(
                            Check::QuietShutdown,
                            format!("{name} stepped by the scheduler at {} after it was deactivated", ns(at_ns)),
                        );
                    }
                    // The reference's view of this call.
                    let expected_release = self.reference_call(next, index, at_ns);
                    if caller != Caller::TopLevel && index == top_level {
                        if dependency_ran_in_step {
                            self.fail(
                                Check::SharedDependencyOncePerPeriod,
                                format!("{name} runs twice in one step at {}", ns(at_ns)),
                            );
                        }
                        dependency_ran_in_step = true;
                        if at_ns < expected_release {
                            self.fail(
                                Check::SharedDependencyOncePerPeriod,
                                format!(
                                    "{name} runs at {} for {}, but it already ran in this period (next release {})",
                                    ns(at_ns),
                                    caller_name(self, caller),
                                    ns(expected_release)
                                ),
                            );
                        }
                    }
                    // Rate limit: never before the release, never a release already served or dropped.
                    if at_ns < release_ns || release_ns < expected_release {
                        self.fail(
                            Check::RateLimit,
                            format!(
                                "{name} runs at {} serving release {}, but its next release on the grid is {} \
                                 (an earlier run already served or dropped that period)",
                                ns(at_ns),
                                ns(release_ns),
                                ns(expected_release)
                            ),
                        );
                    }
                    // Accounting: the oldest pending release, lateness, skipped periods.
                    let lateness = at_ns.saturating_sub(expected_release);
                    let skipped = lateness / period;
                    if release_ns != expected_release || lateness_ns != lateness || skipped_periods != skipped {
                        self.fail(
                            Check::SkippedReleasesCounted,
                            format!(
                                "{name} at {}: reports release {}, lateness {}, skipped {}; the grid says release {}, \
                                 lateness {}, skipped {skipped}",
                                ns(at_ns),
                                ns(release_ns),
                                ns(lateness_ns),
                                skipped_periods,
                                ns(expected_release),
                                ns(lateness)
                            ),
                        );
                    }
                    if skipped_periods > 0 {
                        self.observe(Fact::SkippedRelease);
                    }
                    next.reference[index].next_release_ns =
                        Some(expected_release + skipped.saturating_add(1).saturating_mul(period));
                    // Lateness bound and recovery, for runs the scheduler itself started.
                    if caller == Caller::TopLevel && index < top_level {
                        let round = config.round_ns(index);
                        let bound = previous.overrun_excess_ns + round;
                        if lateness_ns > bound {
                            self.fail(
                                Check::LatenessBound,
                                format!(
                                    "{name} starts {} late at {}, more than the overruns so far ({}) plus one round ({})",
                                    ns(lateness_ns),
                                    ns(at_ns),
                                    ns(previous.overrun_excess_ns),
                                    ns(round)
                                ),
                            );
                        }
                        if lateness_ns > round {
                            self.observe(Fact::LateBeyondRound);
                        }
                        let after_overload = previous.overload_end_ns.is_some_and(|end| release_ns >= end + period);
                        if after_overload {
                            self.observe(Fact::RunAfterOverload);
                        }
                        if let Some(end) = previous.overload_end_ns
                            && after_overload
                            && (lateness_ns > round || skipped_periods > 0)
                        {
                            self.fail(
                                Check::Recovery,
                                format!(
                                    "{name} released at {} (a period after the overload ended at {}) starts {} late \
                                     with {} skipped; one round is {}",
                                    ns(release_ns),
                                    ns(end),
                                    ns(lateness_ns),
                                    skipped_periods,
                                    ns(round)
                                ),
                            );
                        }
                    }
                    // Miss exactness, both directions, with the run's values.
                    let late = lateness_ns > tolerance;
                    if lateness_ns > 0 && !late {
                        self.observe(Fact::LateWithinTolerance);
                    }
                    match pending_miss.take() {
                        Some(miss) => {
                            self.observe(Fact::Miss);
                            if !late {
                                self.fail(
                                    Check::MissExactness,
                                    format!(
                                        "miss raised for {name} at lateness {} ≤ tolerance {}",
                                        ns(lateness_ns),
                                        ns(tolerance)
                                    ),
                                );
                            }
                            if (
                                miss.component,
                                miss.expected_ns,
                                miss.actual_ns,
                                miss.lateness_ns,
                                miss.skipped_periods,
                            ) != (component, release_ns, at_ns, lateness_ns, skipped_periods)
                            {
                                self.fail(
                                    Check::MissExactness,
                                    format!("miss event {miss:?} does not match the run of {name} at {}", ns(at_ns)),
                                );
                            }
                            self.warning(next, index, &miss);
                        }
                        None if late => self.fail(
                            Check::MissExactness,
                            format!(
                                "no miss raised for {name} starting at {}: lateness {} > tolerance {}",
                                ns(at_ns),
                                ns(lateness_ns),
                                ns(tolerance)
                            ),
                        ),
                        None => {}
                    }
                    // Reactivation signal.
                    let expected_gap = next.reference[index].pending_gap_ns.take();
                    let signalled = pending_gap.take();
                    if signalled.is_some() {
                        self.observe(Fact::Reactivation);
                    }
                    if signalled.map(|s| s.0).is_some_and(|c| c != component) || signalled.map(|s| s.1) != expected_gap
                    {
                        self.fail(
                            Check::ReactivationSignalled,
                            format!(
                                "{name} runs at {}: signalled gap {:?}, expected gap {:?} (k = {} periods of {})",
                                ns(at_ns),
                                signalled.map(|s| ns(s.1)),
                                expected_gap.map(ns),
                                config.reactivation_gap_periods,
                                ns(period)
                            ),
                        );
                    }
                }
                TraceEvent::StepFinished { component, at_ns } => {
                    if at_ns < last_time {
                        self.fail(Check::NoOverlap, format!("{} finishes before it started", self.name(component)));
                    }
                    last_time = at_ns;
                    match stack.pop() {
                        Some((running, _)) if running == component => {}
                        other => self.fail(
                            Check::NoOverlap,
                            format!("{} finishes while {:?} is the innermost step", self.name(component), other),
                        ),
                    }
                }
                TraceEvent::GatedSkip { component, caller, at_ns, next_release_ns } => {
                    let index = component.0 as usize;
                    let name = self.name(component);
                    let expected_release = self.reference_call(next, index, at_ns);
                    if index == top_level {
                        self.observe(Fact::DependencyGatedSkip);
                        if at_ns >= expected_release || next_release_ns != expected_release {
                            self.fail(
                                Check::SharedDependencyOncePerPeriod,
                                format!(
                                    "{name} gated at {} for {} (gate says next release {}), but release {} is pending",
                                    ns(at_ns),
                                    caller_name(self, caller),
                                    ns(next_release_ns),
                                    ns(expected_release)
                                ),
                            );
                        }
                    } else {
                        self.fail(Check::CallsAccepted, format!("top-level {name} gated at {}", ns(at_ns)));
                    }
                    if pending_miss.take().is_some() {
                        self.fail(Check::MissExactness, format!("miss raised for the gated call of {name}"));
                    }
                }
                TraceEvent::Activated { .. } | TraceEvent::Deactivated { .. } => {}
            }
        }
        if let Some((component, _)) = stack.last() {
            self.fail(Check::NoCancellation, format!("{} started but never finished", self.name(*component)));
        }
        if !next.core.running().is_empty() {
            self.fail(
                Check::NoCancellation,
                format!("steps {:?} still running between iterations", next.core.running()),
            );
        }
        if pending_miss.is_some() {
            self.fail(Check::MissExactness, "a miss raised without a run".to_owned());
        }
        if let Some((component, gap)) = pending_gap {
            self.fail(
                Check::ReactivationSignalled,
                format!("{} told of a {} gap without a run", self.name(component), ns(gap)),
            );
        }
    }

    /// The reference's handling of a step call of `index` at `at_ns` (run or gated skip): a dependency seen
    /// after a long gap restarts its grid and owes a reactivation signal. Returns the release pending.
    fn reference_call(&mut self, next: &mut SchedulerState, index: usize, at_ns: u64) -> u64 {
        let config = &self.model.config;
        let limit = config.period_ns(index).saturating_mul(config.reactivation_gap_periods);
        let reference = &mut next.reference[index];
        if !reference.active
            && let Some(seen) = reference.last_seen_ns
            && at_ns - seen.min(at_ns) > limit
        {
            reference.pending_gap_ns = Some(at_ns - seen.min(at_ns));
            reference.next_release_ns = Some(reference.next_release_ns.map_or(at_ns, |r| r.max(at_ns)));
        }
        reference.last_seen_ns = Some(at_ns);
        *reference.next_release_ns.get_or_insert(at_ns)
    }

    /// The rate limiter: a warning at most once per interval, reporting the misses suppressed since the last.
    fn warning(&mut self, next: &mut SchedulerState, index: usize, miss: &MissEvent) {
        let interval = self.model.config.warning_interval_ns;
        let reference = &mut next.reference[index];
        let warn = reference.last_warning_ns.is_none_or(|last| miss.actual_ns.saturating_sub(last) >= interval);
        let suppressed = if warn { reference.suppressed } else { 0 };
        if warn {
            reference.last_warning_ns = Some(miss.actual_ns);
            reference.suppressed = 0;
        } else {
            reference.suppressed += 1;
            self.observe(Fact::SuppressedWarning);
        }
        if (miss.warn, miss.suppressed_since_last_warning) != (warn, suppressed) {
            let name = self.name(miss.component);
            self.fail(
                Check::CountersNeverLost,
                format!(
                    "miss of {name} at {}: warn {} with {} suppressed, expected warn {warn} with {suppressed} suppressed",
                    ns(miss.actual_ns),
                    miss.warn,
                    miss.suppressed_since_last_warning
                ),
            );
        }
    }

    /// Counters change by exactly what the transition's trace shows; the trace dropped nothing.
    fn counters(&mut self, next: &SchedulerState, before: &[ComponentCounters], events: &[TraceEvent]) {
        if next.core.trace().dropped() > 0 {
            self.fail(Check::CountersNeverLost, format!("{} trace events dropped", next.core.trace().dropped()));
        }
        for (index, before) in before.iter().enumerate() {
            let id = ComponentId(index as u32);
            let mut expected = *before;
            for event in events {
                match *event {
                    TraceEvent::StepStarted { component, skipped_periods, .. } if component == id => {
                        expected.runs += 1;
                        expected.skipped_releases += skipped_periods;
                    }
                    TraceEvent::GatedSkip { component, .. } if component == id => expected.gated_skips += 1,
                    TraceEvent::Miss(miss) if miss.component == id => {
                        expected.misses += 1;
                        expected.warnings += u64::from(miss.warn);
                    }
                    TraceEvent::Reactivated { component, .. } if component == id => expected.reactivations += 1,
                    _ => {}
                }
            }
            let actual = next.core.counters(id).unwrap_or_default();
            if actual != expected {
                self.fail(
                    Check::CountersNeverLost,
                    format!("counters of {}: {actual:?}, but the trace accounts for {expected:?}", self.name(id)),
                );
            }
        }
    }
}

fn caller_name(audit: &Audit<'_>, caller: Caller) -> String {
    match caller {
        Caller::TopLevel => "the scheduler".to_owned(),
        Caller::Nested { parent } => audit.name(parent),
    }
}

impl SchedulerModel {
    /// The list changes (remote activation and deactivation requests) the checker may inject at `at_ns`.
    fn list_changes(&self, state: &SchedulerState, at_ns: u64, actions: &mut Vec<SchedulerAction>) {
        if state.list_changes >= self.config.max_list_changes {
            return;
        }
        for (component, reference) in state.reference.iter().enumerate().take(self.config.components.len()) {
            actions.push(if reference.active {
                SchedulerAction::Deactivate { at_ns, component }
            } else {
                SchedulerAction::Activate { at_ns, component }
            });
        }
    }
}

impl Model for SchedulerModel {
    type State = SchedulerState;
    type Action = SchedulerAction;

    fn init_states(&self) -> Vec<SchedulerState> {
        vec![self.initial_state()]
    }

    fn actions(&self, state: &SchedulerState, actions: &mut Vec<SchedulerAction>) {
        let now = state.now_ns;
        // A path ends at the horizon, and at its first violation: the counterexample then ends exactly where a
        // property first broke (Stateright keeps the last violating path it meets, which would otherwise be
        // an arbitrary extension of it).
        if now >= self.config.horizon_ns || state.violated != 0 {
            return;
        }
        // What the driver loop would do next (on a copy: deciding moves the round cursor).
        let mut core = state.core.clone();
        match core.next_decision(now) {
            Ok(Decision::Step(id)) => {
                let component = id.0 as usize;
                actions.push(SchedulerAction::Step { at_ns: now, component, overrun: None });
                if state.overruns < self.config.max_overruns {
                    actions.push(SchedulerAction::Step { at_ns: now, component, overrun: Some(OverrunIn::Own) });
                    if self.config.components.get(component).is_some_and(|c| c.calls_dependency) {
                        actions.push(SchedulerAction::Step {
                            at_ns: now,
                            component,
                            overrun: Some(OverrunIn::Dependency),
                        });
                    }
                }
            }
            Ok(Decision::SleepUntil(until_ns)) => {
                actions.push(SchedulerAction::Sleep { from_ns: now, until_ns });
                // A remote request arriving halfway through the sleep wakes the driver, which serves it then.
                let halfway = now + (until_ns - now) / 2;
                if halfway > now {
                    self.list_changes(state, halfway, actions);
                }
            }
            Ok(Decision::Idle) | Err(_) => {}
        }
        self.list_changes(state, now, actions);
    }

    fn next_state(&self, state: &SchedulerState, action: SchedulerAction) -> Option<SchedulerState> {
        let mut next = self.apply(state, action)?;
        if self.config.check_determinism {
            let again = self.apply(state, action);
            let same = again.as_ref().is_some_and(|again| {
                *again == next && again.last_events == next.last_events && again.findings == next.findings
            });
            if !same {
                next.violated |= Check::Determinism.bit();
                next.findings.push(format!(
                    "[{}] the same action from the same state gave a different result",
                    Check::Determinism.name()
                ));
            }
        }
        Some(next)
    }

    fn properties(&self) -> Vec<Property<Self>> {
        Self::property_list()
    }

    fn format_action(&self, action: &SchedulerAction) -> String {
        match *action {
            SchedulerAction::Step { at_ns, component, overrun } => {
                let spec = &self.config.components[component];
                let dependency = if spec.calls_dependency {
                    format!(
                        ", {} {}",
                        self.config.dependency.name,
                        if overrun == Some(OverrunIn::Dependency) { "OVERRUNS" } else { "nominal (if due)" }
                    )
                } else {
                    String::new()
                };
                format!(
                    "at {}: step {} ({}{dependency})",
                    ns(at_ns),
                    spec.name,
                    if overrun == Some(OverrunIn::Own) {
                        format!("OVERRUNS to {}", ns(self.config.overrun_ns))
                    } else {
                        format!("nominal {}", ns(spec.nominal_ns))
                    }
                )
            }
            SchedulerAction::Sleep { from_ns, until_ns } => format!("at {}: sleep until {}", ns(from_ns), ns(until_ns)),
            SchedulerAction::Activate { at_ns, component } => {
                format!("at {}: activate {}", ns(at_ns), self.config.components[component].name)
            }
            SchedulerAction::Deactivate { at_ns, component } => {
                format!("at {}: deactivate {}", ns(at_ns), self.config.components[component].name)
            }
        }
    }
}

/// Checks the scheduler model of `config` and reports every property (model name "scheduler").
///
/// # Panics
///
/// If `config` is invalid (see [`SchedulerModelConfig::validate`]).
pub fn check_scheduler(config: SchedulerModelConfig, options: &CheckOptions) -> CheckReport {
    let configuration = serde_json::to_value(&config).expect("the configuration serializes");
    let model =
        SchedulerModel::new(config).unwrap_or_else(|error| panic!("invalid scheduler model configuration: {error}"));
    run_check(model, "scheduler", configuration, options)
}

/// One planted scheduler bug: its name, a configuration with it planted, and the property expected to catch it.
#[cfg(feature = "mutants")]
#[derive(Clone, Debug)]
pub struct SchedulerMutantCase {
    /// The mutant's name.
    pub name: &'static str,
    /// The model configuration with the mutant planted.
    pub config: SchedulerModelConfig,
    /// The `always` property expected to fail.
    pub expected_property: &'static str,
}

/// The five scheduler mutants of `bica`, each planted in the default configuration.
#[cfg(feature = "mutants")]
pub fn scheduler_mutants() -> Vec<SchedulerMutantCase> {
    let case = |name, mutant, check: Check| SchedulerMutantCase {
        name,
        config: SchedulerModelConfig { mutant: Some(mutant), ..SchedulerModelConfig::default() },
        expected_property: check.name(),
    };
    vec![
        case("scheduler-catch-up-burst", SchedulerMutant::CatchUpBurst, Check::SkippedReleasesCounted),
        case(
            "scheduler-shared-dependency-twice",
            SchedulerMutant::SharedDependencyTwice,
            Check::SharedDependencyOncePerPeriod,
        ),
        case("scheduler-miss-off-by-one", SchedulerMutant::MissOffByOne, Check::MissExactness),
        case("scheduler-removed-stepped-once-more", SchedulerMutant::RemovedSteppedOnceMore, Check::QuietShutdown),
        case("scheduler-finish-unmatched", SchedulerMutant::FinishUnmatched, Check::IllegalCallsRefused),
    ]
}
