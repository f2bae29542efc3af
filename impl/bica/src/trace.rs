//! The scheduler's decisions as a bounded trace of events, so tests and the model checker
//! can check degradation properties on what actually happened instead of on internals.

use std::collections::VecDeque;

use serde::{Deserialize, Serialize};

use crate::component_id::ComponentId;

/// Who asked for a step: the scheduler (top-level) or another component (cascade).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum Caller {
    /// The scheduler stepped a component of the active list.
    TopLevel,
    /// A component stepped one of its dependencies or driven components.
    Nested {
        /// The component whose step asked for this one.
        parent: ComponentId,
    },
}

/// A deadline miss: the gated work started later than the tolerance allows.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct MissEvent {
    /// The late component.
    pub component: ComponentId,
    /// The release the run served (when it should have started).
    pub expected_ns: u64,
    /// When it actually started.
    pub actual_ns: u64,
    /// `actual_ns - expected_ns`.
    pub lateness_ns: u64,
    /// Releases that passed without their own run and were dropped (never caught up).
    pub skipped_periods: u64,
    /// Whether a warning should be logged now (warnings are rate-limited, counters are not).
    pub warn: bool,
    /// Misses of this component not warned about since the previous warning.
    pub suppressed_since_last_warning: u64,
}

/// One observable decision of the scheduler.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum TraceEvent {
    /// Gated work of `component` started.
    StepStarted {
        /// Component that runs.
        component: ComponentId,
        /// Who stepped it.
        caller: Caller,
        /// Start time.
        at_ns: u64,
        /// Release served by this run.
        release_ns: u64,
        /// `at_ns - release_ns`.
        lateness_ns: u64,
        /// Releases dropped before this one.
        skipped_periods: u64,
    },
    /// Gated work of `component` finished.
    StepFinished {
        /// Component that finished.
        component: ComponentId,
        /// Finish time.
        at_ns: u64,
    },
    /// `component` was stepped but its gate was closed: its work did not run.
    GatedSkip {
        /// Component that was stepped.
        component: ComponentId,
        /// Who stepped it.
        caller: Caller,
        /// Time of the call.
        at_ns: u64,
        /// When its gate opens next.
        next_release_ns: u64,
    },
    /// A deadline miss.
    Miss(MissEvent),
    /// `component` joined the active (top-level) list.
    Activated {
        /// The component.
        component: ComponentId,
        /// When.
        at_ns: u64,
    },
    /// `component` left the active list.
    Deactivated {
        /// The component.
        component: ComponentId,
        /// When.
        at_ns: u64,
    },
    /// `component` runs again after a gap longer than the configured number of periods.
    Reactivated {
        /// The component.
        component: ComponentId,
        /// When.
        at_ns: u64,
        /// How long it was not stepped.
        gap_ns: u64,
    },
}

/// A ring of the most recent trace events. When full, the oldest event is dropped and
/// counted in [`TraceBuffer::dropped`]; capacity 0 disables tracing.
#[derive(Debug, Clone, PartialEq, Eq, Hash, Default)]
pub struct TraceBuffer {
    events: VecDeque<TraceEvent>,
    capacity: usize,
    dropped: u64,
}

impl TraceBuffer {
    /// Creates a ring holding at most `capacity` events.
    pub fn with_capacity(capacity: usize) -> Self {
        Self { events: VecDeque::with_capacity(capacity.min(1 << 16)), capacity, dropped: 0 }
    }

    /// Appends an event, dropping the oldest one if full.
    pub fn push(&mut self, event: TraceEvent) {
        if self.capacity == 0 {
            self.dropped += 1;
            return;
        }
        if self.events.len() == self.capacity {
            self.events.pop_front();
            self.dropped += 1;
        }
        self.events.push_back(event);
    }

    /// Events currently held, oldest first.
    pub fn events(&self) -> impl ExactSizeIterator<Item = &TraceEvent> {
        self.events.iter()
    }

    /// Removes and returns all held events, oldest first.
    pub fn drain(&mut self) -> Vec<TraceEvent> {
        self.events.drain(..).collect()
    }

    /// Number of events dropped because the ring was full or disabled.
    pub fn dropped(&self) -> u64 {
        self.dropped
    }
}
