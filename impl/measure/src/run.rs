//! The in-process experiment: one source endpoint publishes a [`Workload`]'s deltas at their due times through a
//! [`transport::Transport`] — the in-process bus, optionally behind the seeded fault injector — to N-1 receivers,
//! each on its own thread with its own replica. Every time is read from one [`MonoClock`].
//!
//! A sample is the encoded delta behind an 8-byte little-endian sequence number (the write's index in the
//! workload), so receivers can say which write they applied; the bytes counted include those 8. A receiver stamps
//! a write when its delta has been decoded and applied to its replica. From these stamps:
//!
//! - **latency** of a write at a receiver = apply stamp − publish stamp, per payload class;
//! - **convergence window** of a write = the largest of its latencies over the receivers (the time until every
//!   replica reflects it), for writes that reached every receiver;
//! - **end convergence** = the last apply stamp at any receiver − the last publish stamp, provided every receiver
//!   then has the source's digest (checked after the receivers stop).
//!
//! This runner has no anti-entropy, so fault plans for it should not lose samples (delay, reordering and
//! duplication only); recovery from loss and partitions is measured with real agents in [`crate::partition`].

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::Duration;

use anyhow::Context as _;
use bytes::{BufMut as _, Bytes, BytesMut};
use dsr::{Delta, Replica, ReplicaId};
use hdrhistogram::Histogram;
use serde::Serialize;
use transport::fault::{FaultConfig, FaultPlan};
use transport::inproc::Bus;
use transport::rtps::{RtpsConfig, RtpsTransport};
use transport::{Channel, Clock, Transport, TransportStats};

use crate::clock::MonoClock;
use crate::latency::{self, LatencyRecorder, PayloadClass, Percentiles};
use crate::workload::Workload;

/// How the endpoints of a run are connected.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Link {
    /// The in-process bus (`transport::inproc`): one copy handed to every inbox, no network.
    #[default]
    InProc,
    /// One RTPS participant (`transport::rtps`, rustdds) per endpoint, all in this process, over loopback UDP.
    Rtps {
        /// DDS domain id (each run also takes topics of its own).
        domain_id: u16,
    },
}

impl Link {
    /// `inproc` or `rtps`.
    pub fn name(self) -> &'static str {
        match self {
            Link::InProc => "inproc",
            Link::Rtps { .. } => "rtps",
        }
    }
}

/// How an experiment runs.
#[derive(Clone, Debug)]
pub struct RunConfig {
    /// Agents, the source included (2 or more).
    pub agents: u32,
    /// How the endpoints are connected.
    pub link: Link,
    /// Seed of the fault injector.
    pub seed: u64,
    /// Faults applied to what each receiver receives (`None`: the bus alone).
    pub faults: Option<FaultConfig>,
    /// Capacity of each receiver's inbox (a full inbox drops, and the drop is counted).
    pub inbox_capacity: usize,
    /// How long to wait, after the last write, for every receiver to apply everything.
    pub settle_timeout: Duration,
}

impl Default for RunConfig {
    fn default() -> Self {
        RunConfig {
            agents: 3,
            link: Link::InProc,
            seed: 1,
            faults: None,
            inbox_capacity: 1 << 20,
            settle_timeout: Duration::from_secs(20),
        }
    }
}

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
    /// CPU time of the source thread while publishing, nanoseconds (`/proc/thread-self/schedstat`).
    pub source_cpu_ns: Option<u64>,
    /// CPU time of each receiver thread, nanoseconds.
    pub receiver_cpu_ns: Vec<Option<u64>>,
    /// Peak resident memory of the whole process so far (`VmHWM`), bytes: the agents share the process.
    pub process_peak_rss_bytes: Option<u64>,
    /// Every latency, for merging runs (not serialised; the percentiles and CDF points are).
    #[serde(skip)]
    pub latency_histogram: Histogram<u64>,
    /// Every per-write convergence window, for merging runs (not serialised).
    #[serde(skip)]
    pub convergence_histogram: Histogram<u64>,
}

struct ReceiverOutcome {
    applied_at: Vec<u64>,
    refused: u64,
    stats: TransportStats,
    cpu_ns: Option<u64>,
    replica: Replica,
    probe_bytes: u64,
}

/// A number distinguishing runs of this process (topic names of RTPS runs).
fn clock_id() -> u64 {
    static NEXT: AtomicU64 = AtomicU64::new(0);
    NEXT.fetch_add(1, Ordering::Relaxed)
}

/// CPU time of the calling thread in nanoseconds, from `/proc/thread-self/schedstat` (Linux).
pub fn thread_cpu_ns() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/thread-self/schedstat").ok()?;
    text.split_whitespace().next()?.parse().ok()
}

/// Transmitted bytes of the loopback interface of this process's network namespace (Linux; see
/// [`crate::netns::LoopbackCounters`], which reads `/proc/self/net/dev` because `/sys/class/net` shows the
/// namespace that mounted `/sys`).
pub fn loopback_tx_bytes() -> Option<u64> {
    crate::netns::LoopbackCounters::read().ok().map(|counters| counters.tx_bytes)
}

/// Peak resident memory of this process in bytes (`VmHWM` in `/proc/self/status`).
pub fn peak_rss_bytes() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = text.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024)
}

const NOT_APPLIED: u64 = u64::MAX;
/// Sequence number of the probes sent until every receiver hears the source (RTPS discovery).
const PROBE: u64 = u64::MAX;

fn receive(
    transport: Box<dyn Transport>,
    mut replica: Replica,
    writes: usize,
    clock: MonoClock,
    applied: Arc<AtomicU64>,
    probes: Arc<AtomicU64>,
    stop: Arc<AtomicBool>,
) -> ReceiverOutcome {
    let cpu_start = thread_cpu_ns();
    let mut applied_at = vec![NOT_APPLIED; writes];
    let mut refused = 0;
    let mut probe_bytes = 0;
    while !stop.load(Ordering::Acquire) {
        let Some(sample) = transport.recv_timeout(Duration::from_millis(2)) else { continue };
        let Some((header, body)) = sample.bytes.split_first_chunk::<8>() else {
            refused += 1;
            continue;
        };
        let seq = u64::from_le_bytes(*header);
        if seq == PROBE {
            probe_bytes += sample.bytes.len() as u64;
            probes.fetch_add(1, Ordering::Release);
            continue;
        }
        let seq = seq as usize;
        let ok = Delta::decode(body).ok().and_then(|delta| replica.apply(&delta).ok()).is_some();
        let now = clock.now_ns();
        match applied_at.get_mut(seq) {
            Some(slot) if ok => {
                if *slot == NOT_APPLIED {
                    *slot = now;
                    applied.fetch_add(1, Ordering::Release);
                }
            }
            _ => refused += 1,
        }
    }
    let cpu_ns = cpu_start.zip(thread_cpu_ns()).map(|(a, b)| b.saturating_sub(a));
    ReceiverOutcome { applied_at, refused, stats: transport.stats(), cpu_ns, replica, probe_bytes }
}

/// Runs `workload` from one source to `config.agents - 1` receivers over the in-process bus and measures it.
///
/// # Errors
/// Fewer than 2 agents, a thread that cannot be started, or a publication the transport refuses.
pub fn run(workload: &Workload, config: &RunConfig) -> anyhow::Result<RunResult> {
    anyhow::ensure!(config.agents >= 2, "a run needs at least 2 agents, not {}", config.agents);
    let clock = MonoClock::start();
    let bus = Bus::new();
    let plan = config.faults.map(|faults| FaultPlan::new(config.seed, faults));
    let topic_prefix = format!("measure{}_{}_{}", std::process::id(), config.agents, clock_id());
    let endpoint = |bus: &Bus| -> anyhow::Result<Box<dyn Transport>> {
        fn wrap<T: Transport + 'static>(plan: &Option<FaultPlan>, inner: T, clock: MonoClock) -> Box<dyn Transport> {
            match plan {
                Some(plan) => Box::new(plan.wrap(inner, Arc::new(clock) as Arc<dyn Clock>)),
                None => Box::new(inner),
            }
        }
        Ok(match config.link {
            Link::InProc => wrap(&plan, bus.attach(config.inbox_capacity), clock),
            Link::Rtps { domain_id } => {
                let rtps = RtpsTransport::new(RtpsConfig {
                    domain_id,
                    topic_prefix: topic_prefix.clone(),
                    inbox_capacity: config.inbox_capacity.min(1 << 16),
                    ..RtpsConfig::default()
                })
                .context("cannot create an RTPS participant")?;
                wrap(&plan, rtps, clock)
            }
        })
    };
    let source = endpoint(&bus)?;
    let n = workload.writes.len();
    let stop = Arc::new(AtomicBool::new(false));
    let mut counters = Vec::new();
    let mut probe_counters = Vec::new();
    let mut threads = Vec::new();
    for i in 0..config.agents - 1 {
        let transport = endpoint(&bus)?;
        let replica = Replica::with_dictionary(ReplicaId(2 + i), workload.dictionary.clone());
        let applied = Arc::new(AtomicU64::new(0));
        counters.push(Arc::clone(&applied));
        let probes = Arc::new(AtomicU64::new(0));
        probe_counters.push(Arc::clone(&probes));
        let stop = Arc::clone(&stop);
        let handle = std::thread::Builder::new()
            .name(format!("receiver-{}", i + 2))
            .spawn(move || receive(transport, replica, n, clock, applied, probes, stop))
            .context("cannot start a receiver thread")?;
        threads.push(handle);
    }
    // Samples are built before the clock matters: publishing is all the source does while measured.
    let samples: Vec<Bytes> = workload
        .writes
        .iter()
        .enumerate()
        .map(|(seq, w)| {
            let mut sample = BytesMut::with_capacity(8 + w.delta.len());
            sample.put_u64_le(seq as u64);
            sample.put_slice(&w.delta);
            sample.freeze()
        })
        .collect();
    let sample_bytes = samples.iter().map(|s| s.len() as u64).sum();
    // Probes until every receiver hears the source: RTPS discovery takes a while, and a reliable volatile reader
    // matched late would miss the first writes.
    let heard = || probe_counters.iter().all(|c| c.load(Ordering::Acquire) > 0);
    let probe_deadline = clock.now_ns() + 30_000_000_000;
    while !heard() {
        if clock.now_ns() > probe_deadline {
            stop.store(true, Ordering::Release);
            anyhow::bail!("the receivers did not hear the source within 30 s ({})", config.link.name());
        }
        source.publish(Channel::Updates, Bytes::copy_from_slice(&PROBE.to_le_bytes())).context("probe")?;
        std::thread::sleep(Duration::from_millis(20));
    }
    std::thread::sleep(Duration::from_millis(20));
    let source_before = source.stats();
    let lo_before = loopback_tx_bytes();
    let cpu_before = thread_cpu_ns();
    let start = clock.now_ns();
    let mut sent_at = Vec::with_capacity(n);
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
    let last_publish = sent_at.last().copied().unwrap_or(start);
    let deadline = clock.now_ns() + config.settle_timeout.as_nanos() as u64;
    while counters.iter().any(|c| c.load(Ordering::Acquire) < sent_at.len() as u64) && clock.now_ns() < deadline {
        std::thread::sleep(Duration::from_micros(200));
    }
    stop.store(true, Ordering::Release);
    let mut outcomes = Vec::new();
    for handle in threads {
        outcomes.push(handle.join().map_err(|_| anyhow::anyhow!("a receiver thread panicked"))?);
    }
    let lo_after = loopback_tx_bytes();
    if let Some(error) = publish_error {
        return Err(error).context("the source's transport refused a write");
    }

    let mut latency = LatencyRecorder::new();
    let mut windows = latency::histogram();
    let mut not_everywhere = 0;
    for (seq, &sent) in sent_at.iter().enumerate() {
        let class = workload.writes[seq].class;
        let mut window = 0;
        let mut everywhere = true;
        for outcome in &outcomes {
            match outcome.applied_at[seq] {
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
    let digests_equal = outcomes.iter().all(|o| o.replica.digest() == workload.final_digest);
    let last_apply = outcomes
        .iter()
        .flat_map(|o| o.applied_at.iter().copied().filter(|&t| t != NOT_APPLIED))
        .max()
        .unwrap_or(last_publish);
    let span_s = (last_publish.saturating_sub(start) as f64 / 1e9).max(1e-3);
    let source_stats = source.stats();
    let source_wire = source_stats.wire_bytes_sent - source_before.wire_bytes_sent;
    let received: Vec<u64> =
        outcomes.iter().map(|o| o.stats.payload_bytes_received.saturating_sub(o.probe_bytes)).collect();
    let wire_sent = source_wire + outcomes.iter().map(|o| o.stats.wire_bytes_sent).sum::<u64>();
    let loopback = lo_before.zip(lo_after).map(|(a, b)| b.saturating_sub(a));
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
    Ok(RunResult {
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
        source_cpu_ns,
        receiver_cpu_ns: outcomes.iter().map(|o| o.cpu_ns).collect(),
        process_peak_rss_bytes: peak_rss_bytes(),
        latency_histogram: latency.histogram().clone(),
        convergence_histogram: windows,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::workload::synthetic;

    #[test]
    fn every_receiver_applies_every_write_and_ends_equal() {
        let workload = synthetic(2000, 1000.0, 50, 3).unwrap();
        let result = run(&workload, &RunConfig { agents: 4, ..RunConfig::default() }).unwrap();
        assert_eq!(result.writes, 51);
        assert_eq!(result.latency.count, 51 * 3);
        assert_eq!(result.convergence.count, 51);
        assert_eq!(result.writes_not_everywhere, 0);
        assert!(result.digests_equal && result.end_convergence_ns.is_some());
        assert_eq!(result.refused, 0);
        assert_eq!(result.bandwidth.source_wire_bytes, result.sample_bytes);
        assert_eq!(result.bandwidth.received_bytes, vec![result.sample_bytes; 3]);
        assert!(result.convergence.max_ns <= result.latency.max_ns);
    }

    #[test]
    fn rtps_participants_in_one_process_deliver_every_write() {
        let workload = synthetic(100_000, 200.0, 20, 9).unwrap();
        let config = RunConfig { agents: 3, link: Link::Rtps { domain_id: 71 }, ..RunConfig::default() };
        let result = run(&workload, &config).unwrap();
        assert_eq!(result.transport, "rtps");
        assert_eq!(result.writes_not_everywhere, 0, "{result:?}");
        assert!(result.digests_equal);
        // The RTPS layer's estimate adds headers to every sample.
        assert!(result.bandwidth.source_wire_bytes > result.sample_bytes);
        assert_eq!(result.bandwidth.received_bytes, vec![result.sample_bytes; 2]);
    }

    #[test]
    fn reordering_and_duplication_still_converge() {
        let workload = synthetic(100, 2000.0, 100, 5).unwrap();
        let faults = FaultConfig {
            duplicate: 0.1,
            reorder: 0.3,
            reorder_ns: 3_000_000,
            delay_ns: (0, 1_000_000),
            ..FaultConfig::default()
        };
        let result = run(&workload, &RunConfig { agents: 3, faults: Some(faults), ..RunConfig::default() }).unwrap();
        assert_eq!(result.transport, "inproc+faults");
        assert_eq!(result.writes_not_everywhere, 0);
        assert!(result.digests_equal);
        assert!(result.bandwidth.injected_duplicates > 0);
    }

    #[test]
    fn loss_without_anti_entropy_is_reported_not_hidden() {
        let workload = synthetic(100, 5000.0, 200, 5).unwrap();
        let faults = FaultConfig { loss: 0.2, ..FaultConfig::default() };
        let config = RunConfig {
            agents: 2,
            faults: Some(faults),
            settle_timeout: Duration::from_millis(200),
            ..RunConfig::default()
        };
        let result = run(&workload, &config).unwrap();
        assert!(result.writes_not_everywhere > 0);
        assert!(result.bandwidth.injected_drops > 0);
        assert_eq!(result.convergence.count + result.writes_not_everywhere, result.writes);
    }
}
