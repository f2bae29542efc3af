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
use dsr::{Delta, Digest, Replica, ReplicaId};
use hdrhistogram::Histogram;
use serde::Serialize;
use transport::fault::{FaultConfig, FaultPlan};
use transport::inproc::Bus;
use transport::rtps::{RtpsConfig, RtpsTransport};
use transport::{Channel, Clock, Transport, TransportStats};

use crate::clock::MonoClock;
use crate::latency::{self, LatencyRecorder, PayloadClass, Percentiles};
use crate::record::{TimelineWrite, WriteTimeline};
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
    /// Every receiver a separate process with its own RTPS participant (see [`crate::process`]), over loopback UDP;
    /// the source is this process. Needs [`RunConfig::receiver_program`].
    Processes {
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
            Link::Processes { .. } => "rtps-processes",
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
    /// The program that runs a receiver process ([`Link::Processes`]): an executable taking
    /// `measure-receiver --spec JSON` and calling [`crate::process::receiver_main`], e.g. the `cortex` binary.
    pub receiver_program: Option<std::path::PathBuf>,
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
            receiver_program: None,
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

/// What one receiver (thread or process) reports at the end of a run.
#[derive(Clone, Debug)]
pub(crate) struct ReceiverOutcome {
    /// Apply time of every write on the run's clock, [`NOT_APPLIED`] if never applied.
    pub applied_at: Vec<u64>,
    /// Samples that could not be decoded or applied.
    pub refused: u64,
    /// The receiver's transport counters.
    pub stats: TransportStats,
    /// The receiver's final graph digest.
    pub digest: Digest,
    /// Bytes of probes received (not part of the workload).
    pub probe_bytes: u64,
    /// CPU and memory of the receiver.
    pub cost: AgentCost,
}

/// A number distinguishing runs of this process (topic names of RTPS runs).
pub(crate) fn clock_id() -> u64 {
    static NEXT: AtomicU64 = AtomicU64::new(0);
    NEXT.fetch_add(1, Ordering::Relaxed)
}

/// CPU time of the calling thread in nanoseconds, from `/proc/thread-self/schedstat` (Linux).
pub fn thread_cpu_ns() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/thread-self/schedstat").ok()?;
    text.split_whitespace().next()?.parse().ok()
}

/// CPU time of every thread of this process (user + system) in nanoseconds, from `getrusage`.
#[allow(unsafe_code)]
pub fn process_cpu_ns() -> Option<u64> {
    // SAFETY: an all-zero rusage is a valid value of this plain C struct.
    let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
    // SAFETY: `usage` is a valid, writable rusage; RUSAGE_SELF is always supported.
    if unsafe { libc::getrusage(libc::RUSAGE_SELF, &mut usage) } != 0 {
        return None;
    }
    let ns = |t: libc::timeval| (t.tv_sec as u64) * 1_000_000_000 + (t.tv_usec as u64) * 1_000;
    Some(ns(usage.ru_utime) + ns(usage.ru_stime))
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

/// Apply time of a write never applied.
pub(crate) const NOT_APPLIED: u64 = u64::MAX;
/// Sequence number of the probes sent until every receiver hears the source (RTPS discovery).
pub(crate) const PROBE: u64 = u64::MAX;

/// What a sample was to a receiver.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Received {
    /// A discovery probe.
    Probe,
    /// A write applied for the first time.
    Applied,
    /// A write applied before (a duplicate).
    Again,
    /// Bytes that are not a write of this run, or a delta the replica refused.
    Refused,
}

/// The receiving side of a run, shared by receiver threads and receiver processes: decodes a sample's sequence
/// number and delta, applies it, and stamps the first application of every write.
pub(crate) struct Receiving {
    pub replica: Replica,
    pub applied_at: Vec<u64>,
    pub applied: u64,
    pub refused: u64,
    pub probe_bytes: u64,
}

impl Receiving {
    pub fn new(replica: Replica, writes: usize) -> Self {
        Receiving { replica, applied_at: vec![NOT_APPLIED; writes], applied: 0, refused: 0, probe_bytes: 0 }
    }

    /// Handles one sample; `now` is read after the delta is applied.
    pub fn on_sample(&mut self, bytes: &[u8], now: impl FnOnce() -> u64) -> Received {
        let Some((header, body)) = bytes.split_first_chunk::<8>() else {
            self.refused += 1;
            return Received::Refused;
        };
        let seq = u64::from_le_bytes(*header);
        if seq == PROBE {
            self.probe_bytes += bytes.len() as u64;
            return Received::Probe;
        }
        let ok = Delta::decode(body).ok().and_then(|delta| self.replica.apply(&delta).ok()).is_some();
        let now = now();
        match usize::try_from(seq).ok().and_then(|seq| self.applied_at.get_mut(seq)) {
            Some(slot) if ok => {
                if *slot == NOT_APPLIED {
                    *slot = now;
                    self.applied += 1;
                    Received::Applied
                } else {
                    Received::Again
                }
            }
            _ => {
                self.refused += 1;
                Received::Refused
            }
        }
    }

    pub fn all_applied(&self) -> bool {
        self.applied == self.applied_at.len() as u64
    }
}

fn receive(
    transport: Box<dyn Transport>,
    replica: Replica,
    writes: usize,
    clock: MonoClock,
    applied: Arc<AtomicU64>,
    probes: Arc<AtomicU64>,
    stop: Arc<AtomicBool>,
) -> ReceiverOutcome {
    let cpu_start = thread_cpu_ns();
    let mut receiving = Receiving::new(replica, writes);
    while !stop.load(Ordering::Acquire) {
        let Some(sample) = transport.recv_timeout(Duration::from_millis(2)) else { continue };
        match receiving.on_sample(&sample.bytes, || clock.now_ns()) {
            Received::Probe => {
                probes.fetch_add(1, Ordering::Release);
            }
            Received::Applied => {
                applied.fetch_add(1, Ordering::Release);
            }
            Received::Again | Received::Refused => {}
        }
    }
    let cpu_ns = cpu_start.zip(thread_cpu_ns()).map(|(a, b)| b.saturating_sub(a));
    let agent = receiving.replica.id().0;
    ReceiverOutcome {
        digest: receiving.replica.digest(),
        applied_at: receiving.applied_at,
        refused: receiving.refused,
        stats: transport.stats(),
        probe_bytes: receiving.probe_bytes,
        cost: AgentCost { agent, kind: "thread", cpu_ns, peak_rss_bytes: None },
    }
}

/// Samples of a workload: the write's index (8 bytes, little-endian) before its encoded delta. Built before the
/// clock matters, so publishing is all the source does while measured.
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
        latency_histogram: latency.histogram().clone(),
        convergence_histogram: windows,
        timeline,
    }
}

/// Runs `workload` from one source to `config.agents - 1` receivers and measures it: receivers on threads of this
/// process ([`Link::InProc`], [`Link::Rtps`]) or receiver processes ([`Link::Processes`], see [`crate::process`]).
///
/// # Errors
/// Fewer than 2 agents, a thread or process that cannot be started, or a publication the transport refuses.
pub fn run(workload: &Workload, config: &RunConfig) -> anyhow::Result<RunResult> {
    anyhow::ensure!(config.agents >= 2, "a run needs at least 2 agents, not {}", config.agents);
    if let Link::Processes { domain_id } = config.link {
        return crate::process::run(workload, config, domain_id);
    }
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
            Link::Rtps { domain_id } | Link::Processes { domain_id } => {
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
    let samples = samples(workload);
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
    let start = clock.now_ns();
    let (sent_at, source_cpu_ns, publish_error) = publish_all(source.as_ref(), workload, samples, clock, start);
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
    let source_wire = source.stats().wire_bytes_sent - source_before.wire_bytes_sent;
    let side = SourceSide {
        start,
        sent_at,
        sample_bytes,
        source_cpu_ns,
        source_wire,
        loopback: lo_before.zip(lo_after).map(|(a, b)| b.saturating_sub(a)),
    };
    Ok(summarise(workload, config, side, outcomes))
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
