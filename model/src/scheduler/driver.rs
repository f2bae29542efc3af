//! The transition of the scheduler model: one iteration of the runtime's driver loop (run the decided step with
//! its cascade, sleep to the decided release, or serve a remote request) driven through the real core, and the
//! list changes the checker may inject. The driver records every call the core accepted and every request it
//! served, for the audit to find in the trace.

use bica::core::{ComponentCounters, ComponentId, Decision, Gate};
use bica::trace::Caller;

use super::SchedulerModel;
use super::audit::{Audit, DriverCall, Request};
use super::checks::{Check, Fact};
use super::state::{OverrunIn, SchedulerAction, SchedulerState, ns};

impl SchedulerModel {
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
        let mut audit = Audit::new(self);
        audit.illegal_between_steps(&state.core, state.now_ns);
        next.now_ns = self.serve_request_time(state, action, &mut audit);
        match action {
            SchedulerAction::Activate { component, .. } => self.serve_request(&mut next, &mut audit, component, true),
            SchedulerAction::Deactivate { component, .. } => {
                self.serve_request(&mut next, &mut audit, component, false)
            }
            SchedulerAction::Sleep { until_ns, .. } => self.sleep(&mut next, &mut audit, until_ns),
            SchedulerAction::Step { component, overrun, .. } => {
                next.now_ns = self.run_step(&mut next, &mut audit, component, overrun)?;
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

    /// Serves a remote activation (or deactivation) request of top-level `component` at the current time; the
    /// audit then looks for its effect in the trace.
    fn serve_request(&self, next: &mut SchedulerState, audit: &mut Audit<'_>, component: usize, activate: bool) {
        next.list_changes += 1;
        let id = ComponentId(component as u32);
        let now = next.now_ns;
        let (call, result) = if activate {
            ("activate", next.core.activate(id, now))
        } else {
            audit.observe(Fact::Deactivation);
            ("deactivate", next.core.deactivate(id, now))
        };
        match result {
            Ok(()) => audit.request = Some(Request { component: id, activate, at_ns: now }),
            Err(error) => {
                audit.fail(Check::CallsAccepted, format!("{call}({}) refused: {error}", self.names[component]))
            }
        }
    }

    /// The driver sleeps until `until_ns`: the core must still decide so, and (by the trace's grids) no active
    /// component may be due now or have a release before the wake-up.
    fn sleep(&self, next: &mut SchedulerState, audit: &mut Audit<'_>, until_ns: u64) {
        let now = next.now_ns;
        match next.core.next_decision(now) {
            Ok(Decision::SleepUntil(wake)) if wake == until_ns => {}
            other => audit.fail(
                Check::Determinism,
                format!("the decision at {} changed from sleep until {} to {other:?}", ns(now), ns(until_ns)),
            ),
        }
        let pending: Vec<(usize, u64)> = (0..self.config.components.len())
            .filter(|&i| next.seen[i].active)
            .filter_map(|i| next.seen[i].pending_ns(self.config.period_ns(i)).map(|release| (i, release)))
            .collect();
        let due: Vec<&str> =
            pending.iter().filter(|&&(_, release)| release <= now).map(|&(i, _)| self.names[i].as_str()).collect();
        if !due.is_empty() {
            audit.fail(Check::LatenessBound, format!("the scheduler sleeps at {} while {due:?} are due", ns(now)));
        }
        if let Some(earliest) = pending.iter().map(|&(_, release)| release).min()
            && earliest < until_ns
        {
            audit.fail(
                Check::LatenessBound,
                format!("the scheduler sleeps until {} past a release at {}", ns(until_ns), ns(earliest)),
            );
        }
        next.now_ns = until_ns.max(now);
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
        let begun = next.core.begin_step(id, now, Caller::TopLevel);
        if begun.is_ok() {
            audit.calls.push(DriverCall::Begin { component: id, caller: Caller::TopLevel, at_ns: now });
        }
        match begun {
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
            let caller = Caller::Nested { parent: id };
            let begun = next.core.begin_step(dependency, time, caller);
            if begun.is_ok() {
                audit.calls.push(DriverCall::Begin { component: dependency, caller, at_ns: time });
            }
            match begun {
                Ok(Gate::Run(_)) => {
                    let duration = if overrun == Some(OverrunIn::Dependency) {
                        self.overran(next, time, self.config.dependency.nominal_ns)
                    } else {
                        self.config.dependency.nominal_ns
                    };
                    time += duration;
                    match next.core.finish_step(dependency, time) {
                        Ok(()) => audit.calls.push(DriverCall::Finish { component: dependency, at_ns: time }),
                        Err(error) => {
                            audit.fail(Check::CallsAccepted, format!("finish_step(dependency) refused: {error}"))
                        }
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
        match next.core.finish_step(id, time) {
            Ok(()) => audit.calls.push(DriverCall::Finish { component: id, at_ns: time }),
            Err(error) => {
                audit.fail(Check::CallsAccepted, format!("finish_step({name}) at {} refused: {error}", ns(time)))
            }
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

    /// The list changes (remote activation and deactivation requests) the checker may inject at `at_ns`.
    pub(super) fn list_changes(&self, state: &SchedulerState, at_ns: u64, actions: &mut Vec<SchedulerAction>) {
        if state.list_changes >= self.config.max_list_changes {
            return;
        }
        for (component, seen) in state.seen.iter().enumerate().take(self.config.components.len()) {
            actions.push(if seen.active {
                SchedulerAction::Deactivate { at_ns, component }
            } else {
                SchedulerAction::Activate { at_ns, component }
            });
        }
    }
}
