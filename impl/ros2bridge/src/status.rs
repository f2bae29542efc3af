//! What the bridge reports: per input topic ([`crate::inbound::InCounters`]) and per output topic ([`OutCounters`])
//! counters, the replay bridge's own counts, and latency summaries of the live path ([`Latencies`]), as one
//! serializable [`BridgeStatus`] that the `cortex bridge ros2` command prints as a JSON status line.

use std::collections::BTreeMap;

use serde::Serialize;

use crate::inbound::InCounters;

/// How many latency samples a [`Latencies`] keeps (the most recent ones).
pub const LATENCY_SAMPLES: usize = 8192;

/// What happened on one output topic.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize)]
pub struct OutCounters {
    /// The ROS 2 topic.
    pub topic: String,
    /// `tf`, `tf_static`, `image` or `laser`.
    pub kind: &'static str,
    /// The node read (none for TF).
    pub node: Option<String>,
    /// Messages written to DDS.
    pub published: u64,
    /// Messages that could not be built (a malformed node) or written (a DDS error).
    pub errors: u64,
    /// The last such error.
    pub last_error: Option<String>,
}

/// A bounded ring of latency samples, µs, with percentiles.
#[derive(Debug, Clone, Default)]
pub struct Latencies {
    samples_us: Vec<u64>,
    next: usize,
    count: u64,
}

/// Percentiles of a [`Latencies`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct LatencySummary {
    /// Samples recorded since the start (the percentiles are over the last [`LATENCY_SAMPLES`]).
    pub count: u64,
    /// Median, µs.
    pub p50_us: u64,
    /// 99th percentile, µs.
    pub p99_us: u64,
    /// Largest of the kept samples, µs.
    pub max_us: u64,
}

impl Latencies {
    /// Records one sample.
    pub fn record(&mut self, latency_us: u64) {
        if self.samples_us.len() < LATENCY_SAMPLES {
            self.samples_us.push(latency_us);
        } else {
            self.samples_us[self.next] = latency_us;
        }
        self.next = (self.next + 1) % LATENCY_SAMPLES;
        self.count += 1;
    }

    /// Nearest-rank percentiles of the kept samples (all zero when there are none).
    pub fn summary(&self) -> LatencySummary {
        let mut sorted = self.samples_us.clone();
        sorted.sort_unstable();
        let rank = |p: f64| -> u64 {
            if sorted.is_empty() {
                return 0;
            }
            let index = ((p * sorted.len() as f64).ceil() as usize).clamp(1, sorted.len()) - 1;
            sorted[index]
        };
        LatencySummary { count: self.count, p50_us: rank(0.5), p99_us: rank(0.99), max_us: rank(1.0) }
    }
}

/// Latencies of one input topic, each from the header stamp of the sample (the publisher's clock; same host).
#[derive(Debug, Clone, Default, Serialize)]
pub struct InLatency {
    /// The ROS 2 topic.
    pub topic: String,
    /// Stamp → the sample taken from the rustdds reader (the raw DDS delivery).
    pub taken: LatencySummary,
    /// Stamp → the sample's deltas written into the graph and published to the other agents.
    pub in_graph: LatencySummary,
}

/// The bridge's status line.
#[derive(Debug, Clone, Default, Serialize)]
pub struct BridgeStatus {
    /// Per input topic.
    pub inputs: Vec<InCounters>,
    /// Per output topic.
    pub outputs: Vec<OutCounters>,
    /// Messages the replay bridge decoded and wrote, by type.
    pub decoded: BTreeMap<String, u64>,
    /// TF transforms refused (a cycle, or a frame its own parent).
    pub tf_refused: u64,
    /// Deltas the In direction produced.
    pub deltas: u64,
    /// RT edges skipped by the Out direction because their attributes are not a valid pose.
    pub bad_rt_edges: u64,
    /// Latencies of the input topics (only samples whose header stamp is at most a minute old count).
    pub latency_in: Vec<InLatency>,
    /// Graph change signal → message written to DDS, µs, over all output topics.
    pub latency_out: LatencySummary,
    /// Times the DDS side was rebuilt because `rustdds`'s threads had ended (see [`crate::Ros2Bridge`]).
    pub rebuilds: u64,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentiles_are_nearest_rank_over_the_kept_samples() {
        let mut latencies = Latencies::default();
        assert_eq!(latencies.summary(), LatencySummary::default());
        for us in 1..=100 {
            latencies.record(us);
        }
        assert_eq!(latencies.summary(), LatencySummary { count: 100, p50_us: 50, p99_us: 99, max_us: 100 });
        for _ in 0..LATENCY_SAMPLES {
            latencies.record(7);
        }
        let summary = latencies.summary();
        assert_eq!((summary.count, summary.p50_us, summary.max_us), (100 + LATENCY_SAMPLES as u64, 7, 7));
    }
}
