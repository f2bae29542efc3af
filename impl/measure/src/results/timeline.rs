//! What the scheduler timeline of a detector measured ([`crate::timeline`]).

use bica::core::ComponentCounters;
use serde::Serialize;

use crate::spec::TimelineExperiment;

/// One top-level step of the detector. Times are nanoseconds after the start of the run.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub struct StepRecord {
    /// The release the step served.
    pub release_ns: u64,
    /// When its gated work started.
    pub start_ns: u64,
    /// When it finished.
    pub finish_ns: u64,
    /// `start_ns - release_ns`.
    pub lateness_ns: u64,
    /// Releases dropped before this one (never run later).
    pub skipped_releases: u64,
    /// Whether the scheduler raised a miss event for it.
    pub miss: bool,
}

/// The detector's steps in one phase of the run: steps that started in `[from_ns, until_ns)`.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct PhaseSummary {
    /// `before`, `during` or `after` the overload.
    pub name: String,
    /// Start of the phase, ns after the start of the run.
    pub from_ns: u64,
    /// End of the phase (excluded).
    pub until_ns: u64,
    /// Steps that started in it.
    pub steps: u64,
    /// `steps` over the phase's length.
    pub frequency_hz: f64,
    /// Largest lateness.
    pub lateness_max_ns: u64,
    /// Mean lateness.
    pub lateness_mean_ns: u64,
    /// Steps with a miss event.
    pub misses: u64,
    /// Releases skipped by these steps.
    pub skipped_releases: u64,
    /// Mean wall time of a step (start to finish).
    pub step_mean_ns: u64,
}

/// What `measure::timeline::derive` computes from the trace.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Timeline {
    /// Every top-level step of the detector, in order.
    pub steps: Vec<StepRecord>,
    /// Achieved frequency `(t_ns, hz)`: steps started in `(t - window, t]` over the window, every
    /// `measure::timeline::FREQUENCY_SAMPLE_MS` from one window after the start to the end of the run.
    pub frequency: Vec<(u64, f64)>,
    /// Before, during and after the overload window.
    pub phases: Vec<PhaseSummary>,
    /// Largest lateness of any step.
    pub lateness_max_ns: u64,
    /// Steps with a miss event.
    pub misses: u64,
    /// Skipped releases, all steps.
    pub skipped_releases: u64,
    /// Top-level steps of every component in the trace.
    pub top_level_steps: u64,
    /// Top-level steps (of any component) that started before the previous one finished, or while another step was
    /// in progress. The scheduler promises 0.
    pub overlaps: u64,
}

/// A measured timeline with what produced it.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct TimelineResult {
    /// The experiment as run.
    pub experiment: TimelineExperiment,
    /// The clock the runtime read (`bica::clock::MonotonicClock` for a measurement).
    pub clock: String,
    /// Type name of the detector component.
    pub detector: String,
    /// Type name of the overloading component.
    pub overload_component: String,
    /// Frames in the camera log.
    pub log_frames: u64,
    /// Frames the log camera wrote into the graph.
    pub frames_written: u64,
    /// Steps of the overloading component that busy-waited.
    pub overload_busy_steps: u64,
    /// The detector's counters kept by the scheduler core (runs, skipped releases, misses); they must agree with the
    /// timeline derived from the trace.
    pub counters: ComponentCounters,
    /// Steps (of any component) whose `step` returned an error.
    pub step_failures: u64,
    /// Trace events lost because the ring was full (0, or the timeline is incomplete).
    pub trace_dropped: u64,
    /// The derived timeline.
    pub timeline: Timeline,
}

impl TimelineResult {
    /// Whether the trace-derived counts equal the scheduler core's counters.
    pub fn counters_agree(&self) -> bool {
        let t = &self.timeline;
        self.counters.runs == t.steps.len() as u64
            && self.counters.misses == t.misses
            && self.counters.skipped_releases == t.skipped_releases
    }
}
