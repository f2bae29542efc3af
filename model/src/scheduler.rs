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
//! The properties are stated over the trace itself, never against a copy of the core's bookkeeping: each
//! transition drains the core's trace and walks it (module `audit`) next to what the model itself decided (the
//! driver calls it made, at its virtual times, with the durations it chose, and the request it served) and a
//! small per-component summary of earlier trace events (module `summary`: in the active list or not, the release
//! grid, the release of the last run, when it was last seen, the gap owed, the last miss warning and the misses
//! since). So a bug shared by the core and a reference cannot pass: what a run must serve is read off the grid the
//! trace defines, not computed the way the core computes it. Stated over the trace:
//!
//! - the trace records every driver call as made (component, caller, time), and each served request's
//!   `Activated`/`Deactivated` event at once; no other such event appears (`CallsAccepted`, `QuietShutdown`);
//! - no overlap: a step starts only when the previous top-level step has finished, a nested one only inside its
//!   parent, never inside itself; time never goes back; the trace ends with nothing running (`NoOverlap`,
//!   `NoCancellation`);
//! - the grid: the releases of a component are `r0 + k·T`, `r0` being the time of the `Activated` event that
//!   started the grid (or of its first call, for the dependency, which is never activated; or of a call after a
//!   gap of more than k periods), unless a release of the old grid was still ahead then (the old grid goes on).
//!   A run serves the oldest grid point no earlier run passed, never before it (`RateLimit`); its release is at
//!   least a period after the last run's release (`RateLimit`); its reported lateness is the driver's start time
//!   minus that release and its skipped count the number of grid points that passed unrun before its start
//!   (`SkippedReleasesCounted`); the dependency runs only when a release of its grid is pending, at most once a
//!   step, and is gated otherwise, the gate naming that release (`SharedDependencyOncePerPeriod`);
//! - a miss event precedes a run exactly when that lateness exceeds the tolerance, carrying the run's values
//!   (`MissExactness`); a miss warns exactly when no warning of its component appears in the trace in the last
//!   interval, reporting the misses since the last warning, and the counters move by what the trace shows
//!   (`CountersNeverLost`);
//! - after a `Deactivated` event, no top-level run of the component until an `Activated` event (`QuietShutdown`);
//! - a `Reactivated` event precedes a run exactly when the component came back (activation, or call of the
//!   dependency) more than k periods after its last step call or `Deactivated` event in the trace, reporting that
//!   time (`ReactivationSignalled`);
//! - with what the model chose: a top-level run's lateness is at most the overrun so far plus one round, and the
//!   driver never sleeps while an active component's grid has a release due (`LatenessBound`); a run released a
//!   period after the last overrun ended is on time (`Recovery`).
//!
//! Not over the trace alone: `Determinism` compares two runs of a transition (states, traces, findings);
//! `IllegalCallsRefused` is checked on each probe's result and on the trace it leaves in its copy of
//! the core (an accepted illegal finish shows there as a `StepFinished` of a step that is not running), but that a
//! refused call changed nothing hidden can only be seen by comparing the copy with the core (a refusal leaves no
//! trace); `CountersNeverLost` reads the core's
//! counters and dropped-event count to compare them with the trace; `NoCancellation` also asks the core that no
//! step is left running; and the decisions the driver follows (step or sleep) are the core's answers, as in the
//! runtime.
//!
//! The audit records, in the new state, one bit per violated property (and a human-readable finding), and one
//! bit per interesting fact observed (an overrun, a miss, ...). The `always` properties test those bits, so a
//! counterexample ends exactly at the transition that broke the property; the `sometimes` properties show the
//! model really reaches overruns, misses, deactivations and reactivations, and the preconditions of the `always`
//! ones that a step need not meet (a run a period after an overload ended, for recovery; a late run within the
//! tolerance; a run later than one round; a nested step; a request during a sleep; an illegal call during a
//! step). The events and findings of the last transition are kept for display only: they take no part in the
//! state's identity; the summaries do. They hold a little more than the core keeps (the grid's phase and the
//! first time not yet passed, rather than the next release; the last run's release), which costs 30 unique states
//! in the default configuration (58,607, against 58,577 with the former reference that mirrored the core's fields;
//! `model/tests/scheduler_model.rs` pins the count).

use std::sync::Arc;

use bica::core::{ComponentId, Decision, SchedulerCore};
use bica::trace::TraceEvent;
use stateright::{Model, Property};

use crate::report::{CheckOptions, CheckReport, run_check};
use state::ns;
use summary::Seen;

mod audit;
mod checks;
mod config;
mod driver;
#[cfg(feature = "mutants")]
mod mutants;
mod probes;
mod state;
mod summary;

pub use checks::{Check, Fact};
pub use config::{DependencySpec, SchedulerModelConfig, TopLevelSpec};
#[cfg(feature = "mutants")]
pub use mutants::{SchedulerMutantCase, scheduler_mutants};
pub use state::{OverrunIn, SchedulerAction, SchedulerState};

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
        for index in 0..self.config.components.len() {
            core.activate(ComponentId(index as u32), 0).expect("activation at time 0 is accepted");
        }
        let events = core.drain_trace();
        // The summaries start from the activations the trace shows.
        let mut seen = vec![Seen::default(); self.config.registered()];
        for event in &events {
            if let TraceEvent::Activated { component, at_ns } = *event {
                let index = component.0 as usize;
                let period = self.config.period_ns(index);
                seen[index].activated(at_ns, period.saturating_mul(self.config.reactivation_gap_periods), period);
            }
        }
        SchedulerState {
            core,
            now_ns: 0,
            seen,
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
        property_list()
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

/// The property list (`always` then `sometimes`).
fn property_list() -> Vec<Property<SchedulerModel>> {
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
