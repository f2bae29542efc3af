//! The scheduler model's actions and states: what the checker does next, and a state (the real core, the
//! virtual time, the per-component summary the properties need, the budgets, the verdicts of the transition
//! that led here) with its identity and its display in counterexamples.

use std::fmt;
use std::hash::{Hash, Hasher};
use std::sync::Arc;

use bica::core::{ComponentId, SchedulerCore};
use bica::trace::{Caller, TraceEvent};

use super::checks::{Check, Fact};
use super::summary::Seen;

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

/// A state of the model: the real scheduler core, the virtual time, the trace's summary of each component, the
/// budgets, and the
/// verdicts of the transition that led here.
#[derive(Clone)]
pub struct SchedulerState {
    pub(super) core: SchedulerCore,
    pub(super) now_ns: u64,
    /// What the trace has shown of each registered component (indexed by component id).
    pub(super) seen: Vec<Seen>,
    pub(super) overruns: u8,
    pub(super) overrun_excess_ns: u64,
    pub(super) overload_end_ns: Option<u64>,
    pub(super) list_changes: u8,
    pub(super) violated: u16,
    pub(super) observed: u16,
    // Display only: not part of the state's identity (see `Hash`/`PartialEq`).
    pub(super) last_events: Vec<TraceEvent>,
    pub(super) findings: Vec<String>,
    pub(super) names: Arc<[String]>,
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
            self.seen.as_slice(),
            (self.overruns, self.overrun_excess_ns, self.overload_end_ns, self.list_changes),
            (self.violated, self.observed),
        )
    }
}

/// The fields that make a state's identity (everything but the display-only ones).
type Identity<'a> = (&'a SchedulerCore, u64, &'a [Seen], (u8, u64, Option<u64>, u8), (u16, u16));

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
pub(super) fn ns(time: u64) -> String {
    format!("{time}ns")
}

pub(super) fn describe_event(names: &[String], event: &TraceEvent) -> String {
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
        for (index, seen) in self.seen.iter().enumerate() {
            let id = ComponentId(index as u32);
            let counters = self.core.counters(id).unwrap_or_default();
            // The period comes from the core's registration, for display only.
            let pending = self.core.period_ns(id).ok().and_then(|period| seen.pending_ns(period));
            writeln!(
                f,
                "{}: pending release (per trace) {}, runs {}, gated {}, skipped {}, misses {}, warnings {}, reactivations {}{}",
                self.names.get(index).map_or("?", String::as_str),
                pending.map_or("-".to_owned(), ns),
                counters.runs,
                counters.gated_skips,
                counters.skipped_releases,
                counters.misses,
                counters.warnings,
                counters.reactivations,
                if seen.active { "" } else { " (inactive)" }
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
