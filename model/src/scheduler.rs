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

use std::sync::Arc;

use bica::core::{ComponentId, Decision, SchedulerCore};

use state::{Reference, ns};
use stateright::{Model, Property};

use crate::report::{CheckOptions, CheckReport, run_check};

mod audit;
mod checks;
mod config;
mod driver;
#[cfg(feature = "mutants")]
mod mutants;
mod probes;
mod state;

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
