//! The transition of the scheduler model: one iteration of the runtime's driver loop (run the decided step with
//! its cascade, sleep to the decided release, or serve a remote request) driven through the real core, and the
//! list changes the checker may inject.

use bica::core::{ComponentCounters, ComponentId, Decision, Gate};
use bica::trace::Caller;

use super::SchedulerModel;
use super::audit::Audit;
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

    /// The list changes (remote activation and deactivation requests) the checker may inject at `at_ns`.
    pub(super) fn list_changes(&self, state: &SchedulerState, at_ns: u64, actions: &mut Vec<SchedulerAction>) {
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
