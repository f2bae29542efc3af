//! The audit of one transition: the verdicts it collects, and the properties checked on the trace events the
//! core recorded.

use bica::core::{ComponentCounters, ComponentId};
use bica::trace::{Caller, MissEvent, TraceEvent};

use super::SchedulerModel;
use super::checks::{Check, Fact};
use super::state::{SchedulerState, ns};

/// Verdicts collected while auditing one transition.
pub(super) struct Audit<'a> {
    pub(super) model: &'a SchedulerModel,
    pub(super) violated: u16,
    pub(super) observed: u16,
    pub(super) findings: Vec<String>,
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

    /// Audits the transition's trace against the reference, updating the reference as it goes.
    pub(super) fn events(&mut self, previous: &SchedulerState, next: &mut SchedulerState, events: &[TraceEvent]) {
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

fn caller_name(audit: &Audit<'_>, caller: Caller) -> String {
    match caller {
        Caller::TopLevel => "the scheduler".to_owned(),
        Caller::Nested { parent } => audit.name(parent),
    }
}
