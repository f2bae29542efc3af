//! The audit of one transition: the verdicts it collects, and the properties stated over the trace events the
//! core recorded, the driver calls and request the model made, and the per-component summary of earlier trace
//! events ([`Seen`]). Nothing here reads the core's own bookkeeping: the grid a run must serve, the gap a
//! reactivation must report and the rate limiter's verdict all follow from past trace events.

use bica::core::{ComponentCounters, ComponentId};
use bica::trace::{Caller, MissEvent, TraceEvent};

use super::SchedulerModel;
use super::checks::{Check, Fact};
use super::state::{SchedulerState, ns};
use super::summary::Seen;

/// A driver call the core accepted, which its trace must record as made (component, caller, time).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum DriverCall {
    /// `begin_step` (its work ran, or its gate was closed).
    Begin {
        /// The stepped component.
        component: ComponentId,
        /// Who stepped it.
        caller: Caller,
        /// The driver's time of the call.
        at_ns: u64,
    },
    /// `finish_step`.
    Finish {
        /// The finished component.
        component: ComponentId,
        /// The driver's time of the call.
        at_ns: u64,
    },
}

/// A remote request the driver served (the core accepted it).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) struct Request {
    /// The top-level component.
    pub(super) component: ComponentId,
    /// Activation (or deactivation).
    pub(super) activate: bool,
    /// When it was served.
    pub(super) at_ns: u64,
}

/// Verdicts collected while auditing one transition, and what the driver did in it.
pub(super) struct Audit<'a> {
    pub(super) model: &'a SchedulerModel,
    pub(super) violated: u16,
    pub(super) observed: u16,
    pub(super) findings: Vec<String>,
    /// The driver's accepted step calls, in order.
    pub(super) calls: Vec<DriverCall>,
    /// The remote request served, if any.
    pub(super) request: Option<Request>,
}

/// A `StepStarted` event.
#[derive(Clone, Copy, Debug)]
struct Run {
    component: ComponentId,
    caller: Caller,
    at_ns: u64,
    release_ns: u64,
    lateness_ns: u64,
    skipped_periods: u64,
}

/// What the walk over one transition's trace carries from one event to the next.
struct Walk {
    /// Steps started and not finished, outermost first.
    stack: Vec<ComponentId>,
    /// Time of the last start or finish.
    last_time_ns: u64,
    /// Index of the next driver call the trace must record.
    next_call: usize,
    /// A miss event waiting for the start of its run.
    pending_miss: Option<MissEvent>,
    /// A reactivation signal waiting for the start of its run.
    pending_gap: Option<(ComponentId, u64)>,
    /// The shared dependency ran in this transition's step.
    dependency_ran: bool,
    /// The served request's event was seen.
    request_seen: bool,
}

impl<'a> Audit<'a> {
    /// An empty audit for a transition of `model`.
    pub(super) fn new(model: &'a SchedulerModel) -> Self {
        Audit { model, violated: 0, observed: 0, findings: Vec::new(), calls: Vec::new(), request: None }
    }
}

impl Audit<'_> {
    pub(super) fn fail(&mut self, check: Check, finding: String) {
        self.violated |= check.bit();
        self.findings.push(format!("[{}] {finding}", check.name()));
    }

    pub(super) fn observe(&mut self, fact: Fact) {
        self.observed |= fact.bit();
    }

    pub(super) fn name(&self, id: ComponentId) -> String {
        self.model.names.get(id.0 as usize).cloned().unwrap_or_else(|| format!("#{}", id.0))
    }

    fn caller_name(&self, caller: Caller) -> String {
        match caller {
            Caller::TopLevel => "the scheduler".to_owned(),
            Caller::Nested { parent } => self.name(parent),
        }
    }

    /// Walks the transition's trace, checking each event against the driver's calls and request and the
    /// summaries of earlier events, and updating the summaries in `next`.
    pub(super) fn events(&mut self, previous: &SchedulerState, next: &mut SchedulerState, events: &[TraceEvent]) {
        let mut walk = Walk {
            stack: Vec::new(),
            last_time_ns: previous.now_ns,
            next_call: 0,
            pending_miss: None,
            pending_gap: None,
            dependency_ran: false,
            request_seen: false,
        };
        for event in events {
            match *event {
                TraceEvent::Miss(miss) => {
                    if walk.pending_miss.replace(miss).is_some() {
                        self.fail(Check::MissExactness, "two misses raised for one run".to_owned());
                    }
                }
                TraceEvent::Reactivated { component, gap_ns, .. } => {
                    if walk.pending_gap.replace((component, gap_ns)).is_some() {
                        self.fail(Check::ReactivationSignalled, "two reactivations signalled for one run".to_owned());
                    }
                }
                TraceEvent::StepStarted { component, caller, at_ns, release_ns, lateness_ns, skipped_periods } => {
                    let run = Run { component, caller, at_ns, release_ns, lateness_ns, skipped_periods };
                    self.started(previous, next, &mut walk, run);
                }
                TraceEvent::StepFinished { component, at_ns } => self.finished(&mut walk, component, at_ns),
                TraceEvent::GatedSkip { component, caller, at_ns, next_release_ns } => {
                    self.gated(next, &mut walk, component, caller, at_ns, next_release_ns);
                }
                TraceEvent::Activated { component, at_ns } => self.list_event(next, &mut walk, component, at_ns, true),
                TraceEvent::Deactivated { component, at_ns } => {
                    self.list_event(next, &mut walk, component, at_ns, false);
                }
            }
        }
        self.end_of_trace(previous, next, &walk);
    }

    /// The trace records the driver's next call exactly as made.
    fn recorded(&mut self, walk: &mut Walk, traced: DriverCall) {
        let made = self.calls.get(walk.next_call).copied();
        walk.next_call += 1;
        if made != Some(traced) {
            self.fail(
                Check::CallsAccepted,
                format!("the trace records {traced:?}, but the driver's call was {made:?}"),
            );
        }
    }

    /// The reactivation limit (k periods) and the period of component `index`.
    fn limits(&self, index: usize) -> (u64, u64) {
        let config = &self.model.config;
        let period = config.period_ns(index);
        (period.saturating_mul(config.reactivation_gap_periods), period)
    }

    /// A `StepStarted` event: nesting, quiet shutdown, the grid, timeliness, the miss and the reactivation signal.
    fn started(&mut self, previous: &SchedulerState, next: &mut SchedulerState, walk: &mut Walk, run: Run) {
        let index = run.component.0 as usize;
        let top_level = index < self.model.config.components.len();
        self.recorded(walk, DriverCall::Begin { component: run.component, caller: run.caller, at_ns: run.at_ns });
        self.nesting(walk, &run);
        if run.caller == Caller::TopLevel && top_level && !next.seen[index].active {
            self.fail(
                Check::QuietShutdown,
                format!(
                    "{} stepped by the scheduler at {} after it was deactivated",
                    self.name(run.component),
                    ns(run.at_ns)
                ),
            );
        }
        let (limit, period) = self.limits(index);
        let seen = &mut next.seen[index];
        seen.called(run.at_ns, limit, period);
        let pending = seen.pending_ns(period).unwrap_or(run.at_ns);
        let seen = seen.clone();
        if !top_level && run.caller != Caller::TopLevel {
            self.dependency_run(walk, &run, pending);
        }
        let skipped = self.grid(&seen, &run, pending, period);
        let lateness = run.at_ns.saturating_sub(pending);
        if top_level && run.caller == Caller::TopLevel {
            self.timeliness(previous, &run, pending, lateness, skipped);
        }
        let miss = walk.pending_miss.take();
        self.miss(&seen, &run, miss, (pending, lateness, skipped));
        let gap = walk.pending_gap.take();
        self.reactivation(&seen, &run, gap);
        let seen = &mut next.seen[index];
        if let Some(miss) = miss {
            seen.missed(miss.actual_ns, miss.warn);
        }
        seen.ran(run.at_ns, run.release_ns);
    }

    /// No overlap: time never goes back, a top-level step starts only when nothing runs, a nested one only
    /// inside its parent, and no component inside itself.
    fn nesting(&mut self, walk: &mut Walk, run: &Run) {
        let name = self.name(run.component);
        if run.at_ns < walk.last_time_ns {
            self.fail(Check::NoOverlap, format!("{name} starts at {} after {}", ns(run.at_ns), ns(walk.last_time_ns)));
        }
        walk.last_time_ns = run.at_ns;
        match run.caller {
            Caller::TopLevel if !walk.stack.is_empty() => {
                let running = self.name(walk.stack[walk.stack.len() - 1]);
                self.fail(Check::NoOverlap, format!("top-level {name} starts while {running} runs"));
            }
            Caller::Nested { parent } if walk.stack.last() != Some(&parent) => self.fail(
                Check::NoOverlap,
                format!("{name} called by {} which is not the running step", self.name(parent)),
            ),
            _ => {}
        }
        if walk.stack.contains(&run.component) {
            self.fail(Check::NoOverlap, format!("{name} starts inside its own step"));
        }
        if matches!(run.caller, Caller::Nested { .. }) {
            self.observe(Fact::NestedStep);
        }
        walk.stack.push(run.component);
    }

    /// The shared dependency runs at most once per step, and only when one of its releases is pending.
    fn dependency_run(&mut self, walk: &mut Walk, run: &Run, pending: u64) {
        let name = self.name(run.component);
        if walk.dependency_ran {
            self.fail(
                Check::SharedDependencyOncePerPeriod,
                format!("{name} runs twice in one step at {}", ns(run.at_ns)),
            );
        }
        walk.dependency_ran = true;
        if run.at_ns < pending {
            self.fail(
                Check::SharedDependencyOncePerPeriod,
                format!(
                    "{name} runs at {} for {}, but it already ran in this period (its next release on the trace's \
                     grid is {})",
                    ns(run.at_ns),
                    self.caller_name(run.caller),
                    ns(pending)
                ),
            );
        }
    }

    /// The run against its grid: never before its release, never a release an earlier run served or dropped,
    /// at least a period after the last run's release (rate limit); the oldest pending release, lateness =
    /// start − release, and skipped = the grid points that passed unrun (accounting). Returns that number.
    fn grid(&mut self, seen: &Seen, run: &Run, pending: u64, period: u64) -> u64 {
        let name = self.name(run.component);
        let Some(grid) = seen.grid else { return 0 };
        let rushed = run.at_ns < run.release_ns || run.release_ns < pending;
        let too_soon = seen.last_release_ns.filter(|&last| run.release_ns < last.saturating_add(period));
        if rushed || too_soon.is_some() {
            self.fail(
                Check::RateLimit,
                format!(
                    "{name} runs at {} serving release {}; the oldest release no run served or dropped is {}, and \
                     its last run served {} (period {})",
                    ns(run.at_ns),
                    ns(run.release_ns),
                    ns(pending),
                    seen.last_release_ns.map_or("-".to_owned(), ns),
                    ns(period)
                ),
            );
        }
        let lateness = run.at_ns.saturating_sub(pending);
        let skipped = grid.points_between(pending, run.at_ns, period);
        let on_grid = grid.contains(run.release_ns, period);
        if run.release_ns != pending || !on_grid || run.lateness_ns != lateness || run.skipped_periods != skipped {
            let expected = if run.at_ns < pending {
                format!("no release is pending before {}", ns(pending))
            } else {
                format!("release {}, lateness {}, {skipped} grid points passed unrun", ns(pending), ns(lateness))
            };
            self.fail(
                Check::SkippedReleasesCounted,
                format!(
                    "{name} at {}: reports release {}, lateness {}, skipped {}; the trace's grid says {expected}",
                    ns(run.at_ns),
                    ns(run.release_ns),
                    ns(run.lateness_ns),
                    run.skipped_periods,
                ),
            );
        }
        if run.skipped_periods > 0 {
            self.observe(Fact::SkippedRelease);
        }
        skipped
    }

    /// Lateness bound and recovery, for a run the scheduler started: `lateness` is measured from the oldest
    /// pending release of the trace's grid to the driver's start.
    fn timeliness(&mut self, previous: &SchedulerState, run: &Run, release: u64, lateness: u64, skipped: u64) {
        let config = &self.model.config;
        let index = run.component.0 as usize;
        let round = config.round_ns(index);
        let period = config.period_ns(index);
        let name = self.name(run.component);
        let bound = previous.overrun_excess_ns + round;
        if lateness > bound {
            self.fail(
                Check::LatenessBound,
                format!(
                    "{name} starts {} late at {}, more than the overruns so far ({}) plus one round ({})",
                    ns(lateness),
                    ns(run.at_ns),
                    ns(previous.overrun_excess_ns),
                    ns(round)
                ),
            );
        }
        if lateness > round {
            self.observe(Fact::LateBeyondRound);
        }
        let Some(end) = previous.overload_end_ns.filter(|&end| release >= end + period) else { return };
        self.observe(Fact::RunAfterOverload);
        if lateness > round || skipped > 0 || run.skipped_periods > 0 {
            self.fail(
                Check::Recovery,
                format!(
                    "{name} released at {} (a period after the overload ended at {}) starts {} late with {} \
                     skipped; one round is {}",
                    ns(release),
                    ns(end),
                    ns(lateness),
                    skipped.max(run.skipped_periods),
                    ns(round)
                ),
            );
        }
    }

    /// Miss exactness: a miss event precedes the run exactly when its lateness exceeds the tolerance, and
    /// carries the run's release, start, lateness and skipped periods; its warning obeys the rate limit.
    fn miss(&mut self, seen: &Seen, run: &Run, miss: Option<MissEvent>, expected: (u64, u64, u64)) {
        let (release, lateness, skipped) = expected;
        let tolerance = self.model.config.miss_tolerance_ns;
        let name = self.name(run.component);
        let late = lateness > tolerance;
        if lateness > 0 && !late {
            self.observe(Fact::LateWithinTolerance);
        }
        let Some(miss) = miss else {
            if late {
                self.fail(
                    Check::MissExactness,
                    format!(
                        "no miss raised for {name} starting at {}: lateness {} > tolerance {}",
                        ns(run.at_ns),
                        ns(lateness),
                        ns(tolerance)
                    ),
                );
            }
            return;
        };
        self.observe(Fact::Miss);
        if !late {
            self.fail(
                Check::MissExactness,
                format!("miss raised for {name} at lateness {} ≤ tolerance {}", ns(lateness), ns(tolerance)),
            );
        }
        let carried = (miss.component, miss.expected_ns, miss.actual_ns, miss.lateness_ns, miss.skipped_periods);
        if carried != (run.component, release, run.at_ns, lateness, skipped) {
            self.fail(
                Check::MissExactness,
                format!(
                    "miss event {miss:?} does not match the run of {name} at {} (release {}, lateness {}, skipped {})",
                    ns(run.at_ns),
                    ns(release),
                    ns(lateness),
                    skipped
                ),
            );
        }
        self.warning(seen, &miss);
    }

    /// The rate limiter over the trace's warnings: a miss warns iff no warning of its component was given in the
    /// last interval, and a warning reports the misses since the previous one.
    fn warning(&mut self, seen: &Seen, miss: &MissEvent) {
        let interval = self.model.config.warning_interval_ns;
        let warn = seen.last_warning_ns.is_none_or(|last| miss.actual_ns.saturating_sub(last) >= interval);
        let suppressed = if warn { seen.misses_since_warning } else { 0 };
        if !miss.warn {
            self.observe(Fact::SuppressedWarning);
        }
        if (miss.warn, miss.suppressed_since_last_warning) != (warn, suppressed) {
            self.fail(
                Check::CountersNeverLost,
                format!(
                    "miss of {} at {}: warn {} with {} suppressed; the trace's last warning was at {} with {} \
                     misses since, so warn {warn} with {suppressed} suppressed",
                    self.name(miss.component),
                    ns(miss.actual_ns),
                    miss.warn,
                    miss.suppressed_since_last_warning,
                    seen.last_warning_ns.map_or("-".to_owned(), ns),
                    seen.misses_since_warning
                ),
            );
        }
    }

    /// The reactivation signal: present exactly when the trace owes a gap (the component came back more than
    /// k periods after it was last stepped or deactivated), for this component, with that gap.
    fn reactivation(&mut self, seen: &Seen, run: &Run, signalled: Option<(ComponentId, u64)>) {
        if signalled.is_some() {
            self.observe(Fact::Reactivation);
        }
        let expected = seen.owed_gap_ns;
        if signalled.is_some_and(|(component, _)| component != run.component) || signalled.map(|s| s.1) != expected {
            let config = &self.model.config;
            self.fail(
                Check::ReactivationSignalled,
                format!(
                    "{} runs at {}: signalled gap {:?}, but the trace shows a gap of {:?} (k = {} periods of {})",
                    self.name(run.component),
                    ns(run.at_ns),
                    signalled.map(|s| ns(s.1)),
                    expected.map(ns),
                    config.reactivation_gap_periods,
                    ns(config.period_ns(run.component.0 as usize))
                ),
            );
        }
    }

    /// A `StepFinished` event: the innermost running step ends, at the driver's time.
    fn finished(&mut self, walk: &mut Walk, component: ComponentId, at_ns: u64) {
        self.recorded(walk, DriverCall::Finish { component, at_ns });
        if at_ns < walk.last_time_ns {
            self.fail(Check::NoOverlap, format!("{} finishes before it started", self.name(component)));
        }
        walk.last_time_ns = at_ns;
        match walk.stack.pop() {
            Some(running) if running == component => {}
            other => self.fail(
                Check::NoOverlap,
                format!("{} finishes while {:?} is the innermost step", self.name(component), other),
            ),
        }
    }

    /// A `GatedSkip` event: only the shared dependency may be gated, exactly when no release of its grid is
    /// pending, and the gate names that release; no miss or reactivation goes with it.
    fn gated(
        &mut self,
        next: &mut SchedulerState,
        walk: &mut Walk,
        component: ComponentId,
        caller: Caller,
        at_ns: u64,
        next_release_ns: u64,
    ) {
        self.recorded(walk, DriverCall::Begin { component, caller, at_ns });
        let index = component.0 as usize;
        let name = self.name(component);
        let (limit, period) = self.limits(index);
        let seen = &mut next.seen[index];
        seen.called(at_ns, limit, period);
        let pending = seen.pending_ns(period).unwrap_or(at_ns);
        if index == self.model.config.components.len() {
            self.observe(Fact::DependencyGatedSkip);
            if at_ns >= pending || next_release_ns != pending {
                self.fail(
                    Check::SharedDependencyOncePerPeriod,
                    format!(
                        "{name} gated at {} for {} (gate says next release {}), but the trace's grid has release {} \
                         pending",
                        ns(at_ns),
                        self.caller_name(caller),
                        ns(next_release_ns),
                        ns(pending)
                    ),
                );
            }
        } else {
            self.fail(Check::CallsAccepted, format!("top-level {name} gated at {}", ns(at_ns)));
        }
        if walk.pending_miss.take().is_some() {
            self.fail(Check::MissExactness, format!("miss raised for the gated call of {name}"));
        }
        if walk.pending_gap.take().is_some() {
            self.fail(Check::ReactivationSignalled, format!("reactivation signalled for the gated call of {name}"));
        }
    }

    /// An `Activated` or `Deactivated` event: only as the effect of the request the driver served, for a
    /// component whose list membership it changes.
    fn list_event(
        &mut self,
        next: &mut SchedulerState,
        walk: &mut Walk,
        component: ComponentId,
        at_ns: u64,
        activate: bool,
    ) {
        let index = component.0 as usize;
        let name = self.name(component);
        let expected = Some(Request { component, activate, at_ns });
        if self.request != expected || walk.request_seen || next.seen[index].active == activate {
            let what = if activate { "activated" } else { "deactivated" };
            self.fail(
                Check::CallsAccepted,
                format!(
                    "{name} {what} at {}, but the driver served {:?} (it was active: {})",
                    ns(at_ns),
                    self.request,
                    next.seen[index].active
                ),
            );
        }
        walk.request_seen = true;
        let (limit, period) = self.limits(index);
        let seen = &mut next.seen[index];
        if activate {
            seen.activated(at_ns, limit, period);
        } else {
            seen.deactivated(at_ns);
        }
    }

    /// After the last event: nothing is left running, no miss or signal is left without its run, every driver
    /// call is in the trace, and a served request that changes the active list shows there (a deactivation at
    /// once, for quiet shutdown).
    fn end_of_trace(&mut self, previous: &SchedulerState, next: &SchedulerState, walk: &Walk) {
        if let Some(component) = walk.stack.last() {
            self.fail(Check::NoCancellation, format!("{} started but never finished", self.name(*component)));
        }
        if !next.core.running().is_empty() {
            self.fail(
                Check::NoCancellation,
                format!("steps {:?} still running between iterations", next.core.running()),
            );
        }
        if walk.pending_miss.is_some() {
            self.fail(Check::MissExactness, "a miss raised without a run".to_owned());
        }
        if let Some((component, gap)) = walk.pending_gap {
            self.fail(
                Check::ReactivationSignalled,
                format!("{} told of a {} gap without a run", self.name(component), ns(gap)),
            );
        }
        if let Some(missing) = self.calls.get(walk.next_call).copied() {
            self.fail(Check::CallsAccepted, format!("the driver's call {missing:?} is not in the trace"));
        }
        let Some(request) = self.request else { return };
        let was_active = previous.seen[request.component.0 as usize].active;
        if walk.request_seen || was_active == request.activate {
            return;
        }
        let name = self.name(request.component);
        if request.activate {
            self.fail(
                Check::CallsAccepted,
                format!("{name} activated at {} but no Activated event", ns(request.at_ns)),
            );
        } else {
            self.fail(
                Check::QuietShutdown,
                format!(
                    "{name} deactivated at {} but it stays in the active list (no Deactivated event)",
                    ns(request.at_ns)
                ),
            );
        }
    }

    /// Counters change by exactly what the transition's trace shows; the trace dropped nothing.
    pub(super) fn counters(&mut self, next: &SchedulerState, before: &[ComponentCounters], events: &[TraceEvent]) {
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
