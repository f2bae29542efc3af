//! What one run of [`crate::run`] measured: latencies, convergence, bytes, costs, and the per-write timeline.

use hdrhistogram::Histogram;
use serde::Serialize;

use crate::latency::{PayloadClass, Percentiles};

/// Writes whose per-write record a [`WriteTimeline`] keeps; later ones are counted, not kept.
pub const MAX_TIMELINE_WRITES: usize = 1 << 16;

/// Bytes counted by the transports during a run.
#[derive(Clone, Debug, Default, Serialize)]
pub struct Bandwidth {
    /// Bytes the source's transport put on the wire (its own accounting: payload plus headers).
    pub source_wire_bytes: u64,
    /// Bytes received by each receiver's transport.
    pub received_bytes: Vec<u64>,
    /// Wire bytes sent by every endpoint, per second of the run's publishing span.
    pub wire_bytes_per_second: f64,
    /// Bytes received by all receivers together, per second of the publishing span.
    pub received_bytes_per_second: f64,
    /// Growth of the loopback interface's transmitted bytes from the first publication until every receiver has
    /// everything (`lo` of this network namespace, from `/proc/self/net/dev`), if readable: the OS-level
    /// cross-check. Near zero for the in-process bus (other processes add to it); for RTPS it includes
    /// acknowledgements, heartbeats and discovery.
    pub loopback_tx_bytes: Option<u64>,
    /// `loopback_tx_bytes` per second of the publishing span.
    pub loopback_tx_bytes_per_second: Option<f64>,
    /// Samples dropped at full inboxes.
    pub dropped_full: u64,
    /// Samples dropped by the fault injector (loss, partitions).
    pub injected_drops: u64,
    /// Extra copies delivered by the fault injector.
    pub injected_duplicates: u64,
}

/// CPU and memory of one agent of a run.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct AgentCost {
    /// Replica id of the agent (1 is the source).
    pub agent: u32,
    /// `thread` (an agent on a thread of this process) or `process` (a receiver process of its own).
    pub kind: &'static str,
    /// CPU time spent receiving, nanoseconds: the receiver thread alone (`/proc/thread-self/schedstat`), or every
    /// thread of a receiver process, its RTPS threads included (`getrusage`), from its first received sample until
    /// it stops; for the source, its publishing thread while publishing.
    pub cpu_ns: Option<u64>,
    /// Peak resident memory, bytes (`VmHWM`): the agent's own process, or — for agents on threads — the shared
    /// process, so the same figure for all of them.
    pub peak_rss_bytes: Option<u64>,
}

/// What one run measured.
#[derive(Clone, Debug, Serialize)]
pub struct RunResult {
    /// The workload's name.
    pub workload: String,
    /// `inproc` or `rtps`, with `+faults` when the fault injector is in the way.
    pub transport: String,
    /// Agents, the source included.
    pub agents: u32,
    /// Seed of the fault injector.
    pub seed: u64,
    /// Writes published.
    pub writes: u64,
    /// Sum of the published samples' sizes.
    pub sample_bytes: u64,
    /// Seconds from the first to the last publication.
    pub publish_seconds: f64,
    /// Latency of every (write, receiver) pair.
    pub latency: Percentiles,
    /// Latency per payload class.
    pub latency_by_class: Vec<(PayloadClass, Percentiles)>,
    /// Points `(ns, fraction)` of the latency distribution, for figures.
    pub latency_cdf: Vec<(u64, f64)>,
    /// Per-write convergence windows (writes that reached every receiver).
    pub convergence: Percentiles,
    /// Points `(ns, fraction)` of the convergence-window distribution.
    pub convergence_cdf: Vec<(u64, f64)>,
    /// Writes that some receiver never applied.
    pub writes_not_everywhere: u64,
    /// Nanoseconds from the last publication to the last application anywhere, when every receiver ended with the
    /// source's digest; `None` if some did not.
    pub end_convergence_ns: Option<u64>,
    /// Whether every receiver ended with the source's digest.
    pub digests_equal: bool,
    /// Samples a receiver could not decode or apply.
    pub refused: u64,
    /// Bytes counted by the transports.
    pub bandwidth: Bandwidth,
    /// Peak resident memory of this process so far (`VmHWM`), bytes: all agents of in-process runs, the source
    /// of `rtps-processes` runs.
    pub process_peak_rss_bytes: Option<u64>,
    /// CPU and memory per agent, the source first (schema 2: replaces `source_cpu_ns` and `receiver_cpu_ns`).
    pub agent_costs: Vec<AgentCost>,
    /// How many times the run's receivers were started: 1, or for `rtps-processes` more when some receiver did
    /// not answer the source's probes and the run started again with new processes (at most
    /// [`crate::restart::MAX_STARTS`]). In `results.json` only when above 1.
    #[serde(skip_serializing_if = "is_first")]
    pub start_attempts: u32,
    /// Every latency, for merging runs (not serialised; the percentiles and CDF points are).
    #[serde(skip)]
    pub latency_histogram: Histogram<u64>,
    /// Every per-write convergence window, for merging runs (not serialised).
    #[serde(skip)]
    pub convergence_histogram: Histogram<u64>,
    /// Publication and application times of the first writes, for the run's MCAP recording (not serialised).
    #[serde(skip)]
    pub timeline: WriteTimeline,
}

/// Whether a run's receivers were started once ([`RunResult::start_attempts`], [`super::PayloadCell::session_starts`]).
pub(super) fn is_first(attempts: &u32) -> bool {
    *attempts <= 1
}

/// Publication and application times of a run's first writes (at most [`MAX_TIMELINE_WRITES`]), kept in a
/// [`RunResult`] so the run can be recorded after it ends.
#[derive(Clone, Debug, Default)]
pub struct WriteTimeline {
    receivers: u32,
    writes: Vec<TimelineWrite>,
    /// `writes.len() × receivers` application times, write-major; `u64::MAX` where never applied.
    applied_ns: Vec<u64>,
    not_kept: u64,
}

/// One write of a [`WriteTimeline`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TimelineWrite {
    /// Payload class of the message it came from.
    pub class: PayloadClass,
    /// Bytes of the published sample.
    pub bytes: u64,
    /// Publication at the source, ns on the run's clock.
    pub publish_ns: u64,
}

impl WriteTimeline {
    /// An empty timeline of a run with `receivers` receivers.
    pub fn new(receivers: u32) -> Self {
        WriteTimeline { receivers, ..WriteTimeline::default() }
    }

    /// Adds the next write with its application time at each receiver (`None`: never applied), in receiver order.
    /// Past [`MAX_TIMELINE_WRITES`] the write is only counted.
    pub fn push(&mut self, write: TimelineWrite, applied_ns: impl IntoIterator<Item = Option<u64>>) {
        if self.writes.len() >= MAX_TIMELINE_WRITES {
            self.not_kept += 1;
            return;
        }
        let before = self.applied_ns.len();
        self.applied_ns.extend(applied_ns.into_iter().map(|t| t.unwrap_or(u64::MAX)));
        assert_eq!(self.applied_ns.len() - before, self.receivers as usize, "one time per receiver");
        self.writes.push(write);
    }

    /// Receivers of the run.
    pub fn receivers(&self) -> u32 {
        self.receivers
    }

    /// The writes kept, in publication order.
    pub fn writes(&self) -> &[TimelineWrite] {
        &self.writes
    }

    /// When write `seq` was applied at receiver `receiver` (0-based), if it was.
    pub fn applied_ns(&self, seq: usize, receiver: usize) -> Option<u64> {
        let at = self.applied_ns[seq * self.receivers as usize + receiver];
        (at != u64::MAX).then_some(at)
    }

    /// Writes published but not kept.
    pub fn not_kept(&self) -> u64 {
        self.not_kept
    }
}
