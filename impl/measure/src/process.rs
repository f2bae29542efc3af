//! Runs whose receivers are separate processes ([`Link::Processes`](crate::run::Link::Processes)): the source is
//! this process, every receiver is a process of its own with its own replica and its own RTPS participant
//! (`transport::rtps`), all on this host over loopback UDP. Latencies stay comparable because every process reads
//! the same `CLOCK_MONOTONIC` from the run's origin ([`MonoClock::with_origin`]).
//!
//! A receiver process is any executable that, given `measure-receiver --spec JSON`, calls [`receiver_main`] and
//! prints its [`ReceiverReport`] as one JSON line on standard output (`cortex measure-receiver` does). The run:
//!
//! 1. the source starts the N−1 receiver processes ([`RunConfig::receiver_program`]);
//! 2. it publishes probes on `Updates` until every receiver has answered one on `Sync` (RTPS discovery; a
//!    reliable volatile reader matched late would miss the first writes). If some receiver has not answered
//!    within [`RunConfig::probe_window`] ([`PROBE_WINDOW`](crate::spec::PROBE_WINDOW) by default), every
//!    receiver is stopped and the run starts again with new processes, a new participant and new topics
//!    ([`crate::restart`]); the result counts the starts ([`RunResult::start_attempts`]);
//! 3. it publishes the workload at its due times; a receiver stamps each write when decoded and applied, and exits
//!    with its report once it has applied every write;
//! 4. the source waits for the receivers to exit, at most [`RunConfig::settle_timeout`] after the last write; then
//!    it publishes a stop on `Sync`, and a receiver still running reports what it has and exits. One that does not
//!    within 5 s more is killed and the run fails.
//!
//! A receiver also gives up by itself if the source falls silent (no probe within 60 s, or nothing for
//! `settle_ms` after the last sample it saw), so no orphan outlives a killed source for long.

use std::io::Read as _;
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::sync::Arc;
use std::time::Duration;

use anyhow::{Context as _, bail};
use bytes::Bytes;
use dsr::{Digest, Replica, ReplicaId};
use serde::{Deserialize, Serialize};
use transport::fault::{FaultConfig, FaultPlan};
use transport::rtps::{RtpsConfig, RtpsTransport};
use transport::{Channel, Clock, Transport, TransportStats};

use crate::clock::MonoClock;
use crate::receiving::{PROBE, Received, ReceiverOutcome, Receiving};
use crate::restart::with_restarts;
use crate::results::{AgentCost, RunResult};
use crate::source::{self, SourceSide};
use crate::spec::RunConfig;
use crate::usage::{loopback_tx_bytes, peak_rss_bytes, process_cpu_ns};
use crate::workload::Workload;

/// First 8 bytes of a receiver's answer to a probe on `Sync`; the receiver's replica id follows (4 bytes, LE).
const PROBE_ANSWER: u64 = u64::MAX - 1;
/// The 8 bytes the source publishes on `Sync` when receivers still running must report and exit.
const STOP: u64 = u64::MAX - 2;
/// How long a receiver waits for its first probe before giving up.
const FIRST_PROBE_WAIT: Duration = Duration::from_secs(60);

/// A start of a run's receivers in which some did not answer the source's probes within [`RunConfig::probe_window`].
#[derive(Debug, thiserror::Error)]
#[error(
    "{answered} of {started} receiver processes answered the source's probes within {window:?} (not heard from: \
     replicas {silent:?})"
)]
struct ProbesUnanswered {
    /// Receivers that answered.
    answered: usize,
    /// Receivers started.
    started: usize,
    /// How long the source probed.
    window: Duration,
    /// Replica ids of the receivers not heard from.
    silent: Vec<u32>,
}

/// What a receiver process is told (`--spec`, JSON).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReceiverSpec {
    /// DDS domain id.
    pub domain_id: u16,
    /// Topic prefix of the run.
    pub topic_prefix: String,
    /// The receiver's replica id (2 and up; 1 is the source).
    pub replica: u32,
    /// Writes in the workload.
    pub writes: usize,
    /// The run clock's origin (`CLOCK_MONOTONIC`, ns).
    pub origin_ns: u64,
    /// Seed of the fault injector.
    pub seed: u64,
    /// Faults on what this receiver receives.
    pub faults: Option<FaultConfig>,
    /// Capacity of the receiver's inbox.
    pub inbox_capacity: usize,
    /// Give up after this long without a sample, once the first probe has arrived.
    pub settle_ms: u64,
}

/// What a receiver process prints when it stops (one JSON line).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ReceiverReport {
    /// The receiver's replica id.
    pub replica: u32,
    /// Apply time of every write on the run's clock (`u64::MAX`: never applied).
    pub applied_at: Vec<u64>,
    /// Samples it could not decode or apply.
    pub refused: u64,
    /// Bytes of probes and run control received (not part of the workload).
    pub probe_bytes: u64,
    /// Its transport's counters.
    pub stats: TransportStats,
    /// CPU time of the whole process from its first probe until it stopped, ns (`getrusage`).
    pub cpu_ns: Option<u64>,
    /// Peak resident memory of the process, bytes (`VmHWM`).
    pub peak_rss_bytes: Option<u64>,
    /// BLAKE3 digest of its final visible graph.
    pub digest: [u8; 32],
    /// Why it stopped: `complete`, `stopped` (the source's stop), `silent` (the source fell silent).
    pub ended: String,
}

/// The body of a receiver process: joins the run's RTPS topics, answers probes, applies the writes and returns
/// its report once it has every write, or is told to stop, or the source falls silent.
///
/// # Errors
/// The DDS domain cannot be joined, or the bridge dictionary cannot be built.
pub fn receiver_main(spec: &ReceiverSpec) -> anyhow::Result<ReceiverReport> {
    let clock = MonoClock::with_origin(spec.origin_ns);
    let rtps = RtpsTransport::new(RtpsConfig {
        domain_id: spec.domain_id,
        topic_prefix: spec.topic_prefix.clone(),
        inbox_capacity: spec.inbox_capacity.clamp(1, 1 << 16),
        ..RtpsConfig::default()
    })
    .context("cannot create an RTPS participant")?;
    let transport: Box<dyn Transport> = match spec.faults {
        Some(faults) => {
            let plan = FaultPlan::new(spec.seed.wrapping_add(u64::from(spec.replica)), faults);
            Box::new(plan.wrap(rtps, Arc::new(clock) as Arc<dyn Clock>))
        }
        None => Box::new(rtps),
    };
    let dictionary = replay::bridge::dictionary().context("bridge dictionary")?;
    let mut receiving = Receiving::new(Replica::with_dictionary(ReplicaId(spec.replica), dictionary), spec.writes);
    let mut answer = PROBE_ANSWER.to_le_bytes().to_vec();
    answer.extend_from_slice(&spec.replica.to_le_bytes());
    let answer = Bytes::from(answer);
    let silence = Duration::from_millis(spec.settle_ms.max(1)).as_nanos() as u64;
    let mut cpu_start = None;
    let mut last_heard = clock.now_ns();
    let ended = loop {
        if receiving.all_applied() {
            break "complete";
        }
        let limit = if cpu_start.is_none() { FIRST_PROBE_WAIT.as_nanos() as u64 } else { silence };
        if clock.now_ns().saturating_sub(last_heard) > limit {
            break "silent";
        }
        let Some(sample) = transport.recv_timeout(Duration::from_millis(2)) else { continue };
        last_heard = clock.now_ns();
        match sample.channel {
            Channel::Updates => {
                if receiving.on_sample(&sample.bytes, || clock.now_ns()) == Received::Probe {
                    cpu_start = cpu_start.or_else(process_cpu_ns);
                    // A lost answer is answered again at the next probe.
                    let _ = transport.publish(Channel::Sync, answer.clone());
                }
            }
            _ => {
                // Run control (the stop, other receivers' probe answers): not part of the workload's bytes.
                receiving.probe_bytes += sample.bytes.len() as u64;
                if sample.channel == Channel::Sync && sample.bytes.as_ref() == STOP.to_le_bytes() {
                    break "stopped";
                }
            }
        }
    };
    let cpu_ns = cpu_start.zip(process_cpu_ns()).map(|(a, b)| b.saturating_sub(a));
    Ok(ReceiverReport {
        replica: spec.replica,
        digest: receiving.replica.digest().0,
        applied_at: receiving.applied_at,
        refused: receiving.refused,
        probe_bytes: receiving.probe_bytes,
        stats: transport.stats(),
        cpu_ns,
        peak_rss_bytes: peak_rss_bytes(),
        ended: ended.to_owned(),
    })
}

/// A started receiver process: its standard output and error are read on threads so a large report never blocks.
struct Receiver {
    replica: u32,
    child: Child,
    stdout: std::thread::JoinHandle<Vec<u8>>,
    stderr: std::thread::JoinHandle<Vec<u8>>,
}

fn spawn(program: &Path, spec: &ReceiverSpec) -> anyhow::Result<Receiver> {
    let mut child = Command::new(program)
        .arg("measure-receiver")
        .arg("--spec")
        .arg(serde_json::to_string(spec)?)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .with_context(|| format!("cannot start the receiver process {}", program.display()))?;
    let mut out = child.stdout.take().context("receiver stdout")?;
    let mut err = child.stderr.take().context("receiver stderr")?;
    let stdout = std::thread::spawn(move || {
        let mut bytes = Vec::new();
        let _ = out.read_to_end(&mut bytes);
        bytes
    });
    let stderr = std::thread::spawn(move || {
        let mut bytes = Vec::new();
        let _ = err.read_to_end(&mut bytes);
        bytes
    });
    Ok(Receiver { replica: spec.replica, child, stdout, stderr })
}

impl Receiver {
    fn exited(&mut self) -> bool {
        matches!(self.child.try_wait(), Ok(Some(_)))
    }

    /// Waits for the process and parses its report.
    fn report(mut self) -> anyhow::Result<ReceiverReport> {
        let status = self.child.wait().context("waiting for a receiver process")?;
        let out = self.stdout.join().unwrap_or_default();
        let err = self.stderr.join().unwrap_or_default();
        let tail = |bytes: &[u8]| {
            let text = String::from_utf8_lossy(bytes);
            let lines: Vec<&str> = text.lines().collect();
            lines[lines.len().saturating_sub(5)..].join("\n")
        };
        if !status.success() {
            bail!("receiver process {} ended with {status}: {}", self.replica, tail(&err));
        }
        let text = String::from_utf8_lossy(&out);
        let line = text.lines().rev().find(|l| !l.trim().is_empty()).unwrap_or_default();
        serde_json::from_str(line)
            .with_context(|| format!("receiver process {} printed no report; stderr: {}", self.replica, tail(&err)))
    }
}

fn kill_all(receivers: &mut [Receiver]) {
    for r in receivers {
        let _ = r.child.kill();
        let _ = r.child.wait();
    }
}

/// The source side of a [`Link::Processes`](crate::run::Link::Processes) run (see the module documentation):
/// starts the receivers again ([`with_restarts`]) while some do not answer the probes.
pub(crate) fn run(workload: &Workload, config: &RunConfig, domain_id: u16) -> anyhow::Result<RunResult> {
    let program = config
        .receiver_program
        .as_deref()
        .context("a run with receiver processes needs the receiver program (RunConfig::receiver_program)")?;
    let what = format!("{} with {} agents over rtps-processes", workload.name, config.agents);
    let unanswered = |error: &anyhow::Error| error.is::<ProbesUnanswered>();
    let (mut result, starts) = with_restarts(&what, unanswered, |_| start(workload, config, domain_id, program))?;
    result.start_attempts = starts;
    Ok(result)
}

/// One start of a run's receivers: the run itself if they all answer the probes.
fn start(workload: &Workload, config: &RunConfig, domain_id: u16, program: &Path) -> anyhow::Result<RunResult> {
    let clock = MonoClock::start();
    let topic_prefix = format!("measurep{}_{}_{}", std::process::id(), config.agents, crate::clock::run_number());
    let source = RtpsTransport::new(RtpsConfig {
        domain_id,
        topic_prefix: topic_prefix.clone(),
        inbox_capacity: config.inbox_capacity.clamp(1, 1 << 16),
        ..RtpsConfig::default()
    })
    .context("cannot create the source's RTPS participant")?;
    let mut receivers = Vec::new();
    for i in 0..config.agents - 1 {
        let spec = ReceiverSpec {
            domain_id,
            topic_prefix: topic_prefix.clone(),
            replica: 2 + i,
            writes: workload.writes.len(),
            origin_ns: clock.origin_ns(),
            seed: config.seed,
            faults: config.faults,
            inbox_capacity: config.inbox_capacity,
            settle_ms: config.settle_timeout.as_millis() as u64 + 5_000,
        };
        match spawn(program, &spec) {
            Ok(receiver) => receivers.push(receiver),
            Err(error) => {
                kill_all(&mut receivers);
                return Err(error);
            }
        }
    }
    let result = measure(workload, config, &source, &mut receivers, clock);
    if result.is_err() {
        kill_all(&mut receivers);
    }
    let source_side = result?;
    let mut outcomes = Vec::new();
    for receiver in receivers {
        let report = receiver.report()?;
        outcomes.push(ReceiverOutcome {
            applied_at: report.applied_at,
            refused: report.refused,
            stats: report.stats,
            digest: Digest(report.digest),
            probe_bytes: report.probe_bytes,
            cost: AgentCost {
                agent: report.replica,
                kind: "process",
                cpu_ns: report.cpu_ns,
                peak_rss_bytes: report.peak_rss_bytes,
            },
        });
    }
    Ok(source::summarise(workload, config, source_side, outcomes))
}

/// Probes, publishes and waits for the receivers to exit (or stops them).
fn measure(
    workload: &Workload,
    config: &RunConfig,
    source: &RtpsTransport,
    receivers: &mut [Receiver],
    clock: MonoClock,
) -> anyhow::Result<SourceSide> {
    let samples = source::samples(workload);
    let sample_bytes = samples.iter().map(|s| s.len() as u64).sum();
    let mut heard = std::collections::BTreeSet::new();
    let probe_deadline = clock.now_ns() + config.probe_window.as_nanos() as u64;
    while heard.len() < receivers.len() {
        if clock.now_ns() > probe_deadline {
            let silent = receivers.iter().map(|r| r.replica).filter(|r| !heard.contains(r)).collect();
            let (answered, started, window) = (heard.len(), receivers.len(), config.probe_window);
            return Err(ProbesUnanswered { answered, started, window, silent }.into());
        }
        if let Some(r) = receivers.iter_mut().find_map(|r| r.exited().then_some(r.replica)) {
            bail!("receiver process {r} exited before the run started");
        }
        source.publish(Channel::Updates, Bytes::copy_from_slice(&PROBE.to_le_bytes())).context("probe")?;
        let until = clock.now_ns() + 20_000_000;
        while clock.now_ns() < until {
            let Some(sample) = source.recv_timeout(Duration::from_millis(2)) else { continue };
            if let Some((head, rest)) = sample.bytes.split_first_chunk::<8>()
                && u64::from_le_bytes(*head) == PROBE_ANSWER
                && let Some(id) = rest.first_chunk::<4>()
            {
                heard.insert(u32::from_le_bytes(*id));
            }
        }
    }
    std::thread::sleep(Duration::from_millis(20));
    let source_before = source.stats();
    let lo_before = loopback_tx_bytes();
    let start = clock.now_ns();
    let (sent_at, source_cpu_ns, publish_error) = source::publish_all(source, workload, samples, clock, start);
    if let Some(error) = publish_error {
        return Err(error).context("the source's transport refused a write");
    }
    // Drain the answers to late probes while waiting, so the source's inbox never fills.
    let deadline = clock.now_ns() + config.settle_timeout.as_nanos() as u64;
    while !receivers.iter_mut().all(Receiver::exited) && clock.now_ns() < deadline {
        let _ = source.recv_timeout(Duration::from_millis(1));
    }
    let lo_after = loopback_tx_bytes();
    if !receivers.iter_mut().all(Receiver::exited) {
        let give_up = clock.now_ns() + 5_000_000_000;
        while !receivers.iter_mut().all(Receiver::exited) {
            if clock.now_ns() > give_up {
                bail!("receiver processes did not stop within 5 s of the source's stop");
            }
            source.publish(Channel::Sync, Bytes::copy_from_slice(&STOP.to_le_bytes())).context("stop")?;
            std::thread::sleep(Duration::from_millis(50));
        }
    }
    let source_wire = source.stats().wire_bytes_sent - source_before.wire_bytes_sent;
    Ok(SourceSide {
        start,
        sent_at,
        sample_bytes,
        source_cpu_ns,
        source_wire,
        loopback: lo_before.zip(lo_after).map(|(a, b)| b.saturating_sub(a)),
    })
}
