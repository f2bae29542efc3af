//! The source side of a run, shared by in-process runs ([`crate::run`]) and runs with receiver processes
//! ([`crate::process`]): the samples of a workload, their publication at their due times, and the summary of a run
//! from the source's stamps and the receivers' outcomes.

use bytes::{BufMut as _, Bytes, BytesMut};
use transport::{Channel, Transport};

use crate::clock::MonoClock;
use crate::latency::{self, LatencyRecorder, Percentiles};
use crate::receiving::{NOT_APPLIED, ReceiverOutcome};
use crate::results::{AgentCost, Bandwidth, RunResult, TimelineWrite, WriteTimeline};
use crate::spec::RunConfig;
use crate::usage::{peak_rss_bytes, thread_cpu_ns};
use crate::workload::Workload;

/// Samples of a workload: the write's index (8 bytes, little-endian) before its encoded delta. Built before the
/// clock matters, so publishing is all the source does while measured. Eight bytes keep the delta's large vectors
/// where its encoding placed them, aligned, so receivers read them in place.
pub(crate) fn samples(workload: &Workload) -> Vec<Bytes> {
    workload
        .writes
        .iter()
        .enumerate()
        .map(|(seq, w)| {
            let mut sample = BytesMut::with_capacity(8 + w.delta.len());
            sample.put_u64_le(seq as u64);
            sample.put_slice(&w.delta);
            sample.freeze()
        })
        .collect()
}

/// Publishes `samples` at their due times from `start`; returns the publish stamps (as many as were published)
/// and the source thread's CPU time, or the transport's error with the stamps so far.
pub(crate) fn publish_all(
    source: &dyn Transport,
    workload: &Workload,
    samples: Vec<Bytes>,
    clock: MonoClock,
    start: u64,
) -> (Vec<u64>, Option<u64>, Option<transport::TransportError>) {
    let cpu_before = thread_cpu_ns();
    let mut sent_at = Vec::with_capacity(samples.len());
    let mut publish_error = None;
    for (write, sample) in workload.writes.iter().zip(samples) {
        clock.sleep_until(start + write.due_ns);
        sent_at.push(clock.now_ns());
        if let Err(error) = source.publish(Channel::Updates, sample) {
            publish_error = Some(error);
            break;
        }
    }
    let source_cpu_ns = cpu_before.zip(thread_cpu_ns()).map(|(a, b)| b.saturating_sub(a));
    (sent_at, source_cpu_ns, publish_error)
}

/// What the source side of a run measured, for [`summarise`].
pub(crate) struct SourceSide {
    pub start: u64,
    pub sent_at: Vec<u64>,
    pub sample_bytes: u64,
    pub source_cpu_ns: Option<u64>,
    /// The source's wire bytes during the publishing span.
    pub source_wire: u64,
    pub loopback: Option<u64>,
}

/// Latencies, convergence windows, bandwidth and costs of a run from the source's stamps and the receivers'.
pub(crate) fn summarise(
    workload: &Workload,
    config: &RunConfig,
    source: SourceSide,
    outcomes: Vec<ReceiverOutcome>,
) -> RunResult {
    let SourceSide { start, sent_at, sample_bytes, source_cpu_ns, source_wire, loopback } = source;
    let last_publish = sent_at.last().copied().unwrap_or(start);
    let mut latency = LatencyRecorder::new();
    let mut windows = latency::histogram();
    let mut not_everywhere = 0;
    let mut timeline = WriteTimeline::new(config.agents - 1);
    for (seq, &sent) in sent_at.iter().enumerate() {
        let class = workload.writes[seq].class;
        let write = TimelineWrite { class, bytes: 8 + workload.writes[seq].delta.len() as u64, publish_ns: sent };
        let applied = |o: &ReceiverOutcome| o.applied_at.get(seq).copied().filter(|&at| at != NOT_APPLIED);
        timeline.push(write, outcomes.iter().map(applied));
        let mut window = 0;
        let mut everywhere = true;
        for outcome in &outcomes {
            match outcome.applied_at.get(seq).copied().unwrap_or(NOT_APPLIED) {
                NOT_APPLIED => everywhere = false,
                at => {
                    let ns = at.saturating_sub(sent);
                    latency.record(class, ns);
                    window = window.max(ns);
                }
            }
        }
        if everywhere {
            windows.saturating_record(window.max(1));
        } else {
            not_everywhere += 1;
        }
    }
    let digests_equal = outcomes.iter().all(|o| o.digest == workload.final_digest);
    let last_apply = outcomes
        .iter()
        .flat_map(|o| o.applied_at.iter().copied().filter(|&t| t != NOT_APPLIED))
        .max()
        .unwrap_or(last_publish);
    let span_s = (last_publish.saturating_sub(start) as f64 / 1e9).max(1e-3);
    let received: Vec<u64> =
        outcomes.iter().map(|o| o.stats.payload_bytes_received.saturating_sub(o.probe_bytes)).collect();
    let wire_sent = source_wire + outcomes.iter().map(|o| o.stats.wire_bytes_sent).sum::<u64>();
    let bandwidth = Bandwidth {
        source_wire_bytes: source_wire,
        wire_bytes_per_second: wire_sent as f64 / span_s,
        received_bytes_per_second: received.iter().sum::<u64>() as f64 / span_s,
        received_bytes: received,
        loopback_tx_bytes: loopback,
        loopback_tx_bytes_per_second: loopback.map(|b| b as f64 / span_s),
        dropped_full: outcomes.iter().map(|o| o.stats.dropped_full).sum(),
        injected_drops: outcomes.iter().map(|o| o.stats.dropped_injected).sum(),
        injected_duplicates: outcomes.iter().map(|o| o.stats.duplicated_injected).sum(),
    };
    let process_peak_rss_bytes = peak_rss_bytes();
    let mut agent_costs =
        vec![AgentCost { agent: 1, kind: "thread", cpu_ns: source_cpu_ns, peak_rss_bytes: process_peak_rss_bytes }];
    agent_costs.extend(outcomes.iter().map(|o| {
        let mut cost = o.cost.clone();
        cost.peak_rss_bytes = cost.peak_rss_bytes.or(process_peak_rss_bytes);
        cost
    }));
    RunResult {
        workload: workload.name.clone(),
        transport: format!("{}{}", config.link.name(), if config.faults.is_some() { "+faults" } else { "" }),
        agents: config.agents,
        seed: config.seed,
        writes: sent_at.len() as u64,
        sample_bytes,
        publish_seconds: last_publish.saturating_sub(start) as f64 / 1e9,
        latency: latency.overall(),
        latency_by_class: latency.by_class().into_iter().collect(),
        latency_cdf: latency.cdf(50),
        convergence: Percentiles::of(&windows),
        convergence_cdf: latency::cdf(&windows, 50),
        writes_not_everywhere: not_everywhere,
        end_convergence_ns: digests_equal.then(|| last_apply.saturating_sub(last_publish)),
        digests_equal,
        refused: outcomes.iter().map(|o| o.refused).sum(),
        bandwidth,
        process_peak_rss_bytes,
        agent_costs,
        start_attempts: 1,
        latency_histogram: latency.histogram().clone(),
        convergence_histogram: windows,
        timeline,
    }
}
