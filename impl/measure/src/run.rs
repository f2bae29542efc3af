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
use bytes::Bytes;
use dsr::{Replica, ReplicaId};
use transport::fault::FaultPlan;
use transport::inproc::Bus;
use transport::rtps::{RtpsConfig, RtpsTransport};
use transport::{Channel, Clock, Transport};

use crate::clock::MonoClock;
use crate::receiving::{PROBE, Received, ReceiverOutcome, Receiving};
use crate::source::{SourceSide, publish_all, samples, summarise};
use crate::usage::{loopback_tx_bytes, thread_cpu_ns};
use crate::workload::Workload;

pub use crate::results::{AgentCost, Bandwidth, RunResult};
pub use crate::spec::{Link, RunConfig};

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
    let topic_prefix = format!("measure{}_{}_{}", std::process::id(), config.agents, crate::clock::run_number());
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
    use transport::fault::FaultConfig;

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
