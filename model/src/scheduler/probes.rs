//! The illegal-call probes: on copies of the core, the driver calls the core must refuse, between steps and
//! during a step; each must return an error, never panic, and leave the core as it was.

use bica::BicaError;
use bica::core::{ComponentId, Decision, SchedulerCore};
use bica::trace::{Caller, TraceEvent};

use super::audit::Audit;
use super::checks::{Check, Fact};

impl Audit<'_> {
    /// Tries an illegal driver call on a copy of `core`: it must be refused, record nothing in the copy's trace,
    /// and leave the copy as it was (the last is the one check not over the trace: a refusal leaves no trace).
    fn try_illegal(
        &mut self,
        core: &SchedulerCore,
        what: &str,
        call: impl FnOnce(&mut SchedulerCore) -> Result<(), BicaError>,
    ) {
        let mut probe = core.clone();
        let result = call(&mut probe);
        let traced: Vec<TraceEvent> = probe.trace().events().skip(core.trace().events().len()).copied().collect();
        let verdict = match result {
            Ok(()) if traced.is_empty() => "accepted".to_owned(),
            Ok(()) => format!("accepted, and the trace records {traced:?}"),
            Err(_) if !traced.is_empty() => format!("refused, but the trace records {traced:?}"),
            Err(_) if probe != *core => "refused, but it changed the core".to_owned(),
            Err(_) => return,
        };
        self.fail(Check::IllegalCallsRefused, format!("{what}: {verdict}"));
    }

    /// The illegal calls a driver could make between two iterations of its loop (no step running at `now`).
    pub(super) fn illegal_between_steps(&mut self, core: &SchedulerCore, now: u64) {
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
    pub(super) fn illegal_during_step(&mut self, core: &SchedulerCore, running: ComponentId, now: u64) {
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
}
