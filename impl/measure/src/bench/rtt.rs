//! Round-trip time of one attribute between two agent processes, beside raw `rustdds` ping-pong between two
//! processes over the same transport (the transport's limit), for each delivery of updates asked for. Both loops
//! are `ping_pong`: a ping waits for its pong (or 1 s), then for its slot; the first [`WARMUP`] are not measured.

use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

use agent::{Agent, AgentConfig, AgentId};
use anyhow::{Context as _, bail, ensure};
use dsr::{Change, Element, NewNode, NodeId, attrs};
use hdrhistogram::Histogram;
use serde::Serialize;
use transport::rtps::{Multicast, UpdateDelivery};
use transport::shm::{ShmSettings, ShmTransport};
use transport::{Channel, Clock as _, EndpointId, SystemClock, Transport};

use super::helper::{self, Helper};
use super::{Counting, Credentials, growth, payload_of, rtps, rtps_secured, seq_of};
use crate::netns::LoopbackCounters;

/// Pings sent before the measured ones.
pub const WARMUP: u32 = 100;
const PING: &str = "bench_ping";
const PONG: &str = "bench_pong";
/// How long the echoing side waits for a ping before it exits.
const ECHO_SILENCE: Duration = Duration::from_secs(60);
/// How long a ping waits for its pong before it counts as lost.
const PONG_TIMEOUT: Duration = Duration::from_secs(1);

/// What to measure.
#[derive(Clone, Debug)]
pub struct RttConfig {
    /// Attribute payload in bytes (at least 8: a sequence number).
    pub payload_bytes: usize,
    /// Pings per second (closed loop).
    pub rate_hz: f64,
    /// Pings measured, after [`WARMUP`].
    pub count: u32,
    /// DDS domain id.
    pub domain_id: u16,
    /// Multicast for same-host readers.
    pub multicast: Multicast,
    /// Deliveries of updates to compare, each measured raw and through agents, in this order.
    pub updates: Vec<UpdateDelivery>,
    /// Also through agents protected by DDS Security with these credentials, beside the unprotected agents.
    pub security: Option<Credentials>,
    /// Also measure two agents over same-host shared memory (`transport::shm::ShmTransport`) in the same run,
    /// threaded and with the pinging agent driven by the bench's thread.
    pub shm: bool,
}

/// What `cortex bench rtt --json` prints.
#[derive(Debug, Serialize)]
pub struct RttResult {
    /// Attribute payload in bytes.
    pub payload: usize,
    /// Pings per second.
    pub rate_hz: f64,
    /// Pings measured per loop.
    pub count: u32,
    /// Whether the transports used multicast.
    pub multicast: bool,
    /// Two agents over same-host shared memory, same loop (with `RttConfig::shm`).
    pub shm_agent: Option<RttFigures>,
    /// The same, with the pinging agent driven by the bench's own thread ([`Agent::pump_wait`]) instead of
    /// threads of its own: its pongs are handled on the thread that writes the pings, as in the raw loop.
    pub shm_agent_driven: Option<RttFigures>,
    /// Raw samples over the same shared-memory transport, same loop (with `RttConfig::shm`): its limit.
    pub shm_raw: Option<RttFigures>,
    /// Whether the run was in a fresh network namespace (socket-level bytes measured).
    pub netns: bool,
    /// One entry per delivery of updates.
    pub runs: Vec<RttRun>,
}

/// One delivery setting's raw and agent ping-pong.
#[derive(Debug, Serialize)]
pub struct RttRun {
    /// `reliable` or `best-effort`.
    pub updates: &'static str,
    /// Through agents.
    pub agent: RttFigures,
    /// Raw samples.
    pub raw: RttFigures,
    /// Agent p50 over raw p50.
    pub p50_ratio: f64,
    /// Through agents protected by DDS Security (with `--security`).
    pub secured: Option<RttFigures>,
    /// Protected agent p50 over unprotected agent p50.
    pub secured_p50_ratio: Option<f64>,
    /// Protected agent p99 over unprotected agent p99.
    pub secured_p99_ratio: Option<f64>,
}

/// Figures of one ping-pong loop.
#[derive(Debug, Serialize)]
pub struct RttFigures {
    /// Round trips measured.
    pub count: u64,
    /// Pings without a pong within 1 s.
    pub lost: u64,
    /// Round-trip percentiles, µs.
    pub p50_us: u64,
    /// 90th percentile, µs.
    pub p90_us: u64,
    /// 99th percentile, µs.
    pub p99_us: u64,
    /// Largest round trip, µs.
    pub max_us: u64,
    /// Payload bytes the pinging side's transport sent per ping (the agent's envelope included).
    pub envelope_bytes_per_update: f64,
    /// The transport's estimate of wire bytes per ping.
    pub wire_bytes_per_update: f64,
    /// Socket-level bytes, when measured in a fresh network namespace.
    pub socket: Option<SocketFigures>,
    /// Agents: gap requests of the pinging agent during the measured loop (each a repair it asked for at once).
    pub gap_requests: Option<u64>,
}

/// Socket-level bytes of one measurement, from the namespace's loopback counters.
#[derive(Debug, Serialize)]
pub struct SocketFigures {
    /// Discovery (and, for agents, the join) until the first echo came back.
    pub discovery: LoopbackCounters,
    /// The measured loop: every update both ways, their acknowledgements and heartbeats, periodic discovery.
    pub steady: LoopbackCounters,
    /// Updates in the steady state (pings sent plus pongs received).
    pub updates: u64,
    /// Steady-state loopback bytes per update.
    pub bytes_per_update: f64,
    /// Steady-state loopback packets per update.
    pub packets_per_update: f64,
}

impl SocketFigures {
    fn new(discovery: LoopbackCounters, steady: LoopbackCounters, updates: u64) -> SocketFigures {
        SocketFigures {
            discovery,
            steady,
            updates,
            bytes_per_update: steady.tx_bytes as f64 / updates.max(1) as f64,
            packets_per_update: steady.tx_packets as f64 / updates.max(1) as f64,
        }
    }

    /// From the counters at the start, after discovery, and after the steady state.
    fn of(
        start: Option<LoopbackCounters>,
        discovered: Option<LoopbackCounters>,
        end: Option<LoopbackCounters>,
        updates: u64,
    ) -> Option<SocketFigures> {
        Some(SocketFigures::new(growth(discovered, start)?, growth(end, discovered)?, updates))
    }
}

/// What one ping-pong loop observed, beside its histogram of round trips in µs.
#[derive(Debug)]
struct LoopCounts {
    pings: u64,
    pongs: u64,
    lost: u64,
    histogram_us: Histogram<u64>,
}

/// The closed loop both ping-pongs share: `WARMUP + count` pings `period` apart; `ping(seq)` sends one,
/// `pong(seq, deadline)` waits until `deadline` for its answer and says when it was seen (`None`: not in time). An
/// agent's pong is seen in a change callback, on the thread that joined it, as a raw pong is on the thread that
/// takes it from the transport.
fn ping_pong(
    count: u32,
    period: Duration,
    mut ping: impl FnMut(u64) -> anyhow::Result<()>,
    mut pong: impl FnMut(u64, Instant) -> Option<Instant>,
) -> anyhow::Result<LoopCounts> {
    let mut counts = LoopCounts { pings: 0, pongs: 0, lost: 0, histogram_us: Histogram::new(3)? };
    let mut next = Instant::now();
    for seq in 0..u64::from(WARMUP + count) {
        let sent = Instant::now();
        ping(seq)?;
        counts.pings += 1;
        let seen = pong(seq, sent + PONG_TIMEOUT);
        counts.pongs += u64::from(seen.is_some());
        if seq >= u64::from(WARMUP) {
            match seen {
                Some(seen) => counts.histogram_us.record(seen.saturating_duration_since(sent).as_micros() as u64)?,
                None => counts.lost += 1,
            }
        }
        next += period;
        std::thread::sleep(next.saturating_duration_since(Instant::now()));
    }
    Ok(counts)
}

/// The figures of a loop whose pinging side sent `payload_bytes` and an estimated `wire_bytes` meanwhile.
fn figures(counts: &LoopCounts, payload_bytes: u64, wire_bytes: u64, socket: Option<SocketFigures>) -> RttFigures {
    let h = &counts.histogram_us;
    RttFigures {
        count: h.len(),
        lost: counts.lost,
        p50_us: h.value_at_quantile(0.5),
        p90_us: h.value_at_quantile(0.9),
        p99_us: h.value_at_quantile(0.99),
        max_us: h.max(),
        envelope_bytes_per_update: payload_bytes as f64 / counts.pings.max(1) as f64,
        wire_bytes_per_update: wire_bytes as f64 / counts.pings.max(1) as f64,
        socket,
        gap_requests: None,
    }
}

/// Runs both ping-pongs for every delivery of `config`, starting `program` for the echoing side.
///
/// # Errors
/// A rate, count or delivery list that makes no run, a transport or agent that cannot start, or an echo that does
/// not answer within 30 s.
pub fn run(config: &RttConfig, counting: &Counting, program: &Path) -> anyhow::Result<RttResult> {
    ensure!(config.rate_hz > 0.0 && config.count > 0, "the rate and the count must be positive");
    ensure!(!config.updates.is_empty(), "name at least one delivery of updates");
    let period = Duration::from_secs_f64(1.0 / config.rate_hz);
    let mut runs = Vec::new();
    for &updates in &config.updates {
        let raw = raw(config, updates, period, counting, program, false)
            .with_context(|| format!("raw rustdds ping-pong, {} updates", updates.name()))?;
        let agent = through_agents(config, updates, period, counting, program, Via::Rtps)
            .with_context(|| format!("agent ping-pong, {} updates", updates.name()))?;
        let secured = match &config.security {
            Some(credentials) => Some(
                through_agents(config, updates, period, counting, program, Via::Secured(credentials))
                    .with_context(|| format!("agent ping-pong with DDS Security, {} updates", updates.name()))?,
            ),
            None => None,
        };
        let ratio = |a: u64, b: u64| a as f64 / b.max(1) as f64;
        runs.push(RttRun {
            updates: updates.name(),
            p50_ratio: ratio(agent.p50_us, raw.p50_us),
            secured_p50_ratio: secured.as_ref().map(|s| ratio(s.p50_us, agent.p50_us)),
            secured_p99_ratio: secured.as_ref().map(|s| ratio(s.p99_us, agent.p99_us)),
            secured,
            agent,
            raw,
        });
    }
    let (shm_agent, shm_agent_driven, shm_raw) = if config.shm {
        let raw = raw(config, UpdateDelivery::Reliable, period, counting, program, true)
            .context("raw ping-pong over shared memory")?;
        let agent = through_agents(config, UpdateDelivery::Reliable, period, counting, program, Via::Shm)
            .context("agent ping-pong over shared memory")?;
        let driven = through_agents(config, UpdateDelivery::Reliable, period, counting, program, Via::ShmDriven)
            .context("agent ping-pong over shared memory, the pinging agent driven by the bench's thread")?;
        (Some(agent), Some(driven), Some(raw))
    } else {
        (None, None, None)
    };
    Ok(RttResult {
        shm_agent,
        shm_agent_driven,
        shm_raw,
        payload: config.payload_bytes,
        rate_hz: config.rate_hz,
        count: config.count,
        multicast: config.multicast.resolve(),
        netns: crate::netns::inside().is_some(),
        runs,
    })
}

/// Raw samples between two processes, each the other's transport endpoint: over RTPS with `updates`, or over
/// same-host shared memory with `shm` (then `updates` only names the loop).
fn raw(
    config: &RttConfig,
    updates: UpdateDelivery,
    period: Duration,
    counting: &Counting,
    program: &Path,
    shm: bool,
) -> anyhow::Result<RttFigures> {
    let prefix =
        format!("rawrtt{}{}{}", std::process::id(), updates.name().replace('-', ""), if shm { "shm" } else { "" });
    let start = counting.counters()?;
    let transport: Arc<dyn Transport> = if shm {
        Arc::new(shm_transport(&prefix, 1)?)
    } else {
        Arc::new(rtps(config.domain_id, &prefix, config.multicast, updates)?)
    };
    let args = helper::echo_args(config.domain_id, &prefix, true, config.multicast, updates, None, shm);
    let _helper = Helper::spawn(program, &args)?;
    // Discovery: probe until an echo comes back.
    let deadline = Instant::now() + Duration::from_secs(30);
    loop {
        if Instant::now() > deadline {
            bail!("the echo process was not discovered within 30 s");
        }
        transport.publish(Channel::Updates, payload_of(u64::MAX, config.payload_bytes))?;
        if transport.recv_timeout(Duration::from_millis(100)).is_some() {
            break;
        }
    }
    while transport.recv_timeout(Duration::from_millis(200)).is_some() {}
    let discovered = counting.counters()?;
    let before = transport.stats();
    let counts = ping_pong(
        config.count,
        period,
        |seq| Ok(transport.publish(Channel::Updates, payload_of(seq, config.payload_bytes))?),
        |seq, deadline| {
            while let Some(sample) = transport.recv_timeout(deadline.saturating_duration_since(Instant::now())) {
                if seq_of(&sample.bytes) == Some(seq) {
                    return Some(Instant::now());
                }
            }
            None
        },
    )?;
    let end = counting.counters()?;
    let after = transport.stats();
    let socket = SocketFigures::of(start, discovered, end, counts.pings + counts.pongs);
    Ok(figures(
        &counts,
        after.payload_bytes_sent - before.payload_bytes_sent,
        after.wire_bytes_sent - before.wire_bytes_sent,
        socket,
    ))
}

fn bench_config(id: u32, join_wait: Duration) -> AgentConfig {
    let mut config = AgentConfig::new(AgentId(id));
    config.join_wait = join_wait;
    config
}

/// How the two agents of a ping-pong reach each other.
#[derive(Clone, Copy)]
enum Via<'a> {
    /// RTPS, unprotected.
    Rtps,
    /// RTPS with DDS Security, with these credentials.
    Secured(&'a Credentials),
    /// Same-host shared memory.
    Shm,
    /// Same-host shared memory, the pinging agent driven by the bench's thread ([`Agent::pump_wait`]).
    ShmDriven,
}

/// The pongs the pinging agent's change callback reports (sequence number, when seen), and how to wait for them.
struct Pongs {
    seen: std::sync::mpsc::Receiver<(u64, Instant)>,
    /// Whether the bench's thread drives the agent: then it handles the samples itself while it waits.
    driven: bool,
}

impl Pongs {
    /// The next pong reported before `until`.
    fn next(&self, agent: &Agent<Arc<dyn Transport>>, until: Instant) -> Option<(u64, Instant)> {
        if !self.driven {
            return self.seen.recv_timeout(until.saturating_duration_since(Instant::now())).ok();
        }
        loop {
            if let Ok(pong) = self.seen.try_recv() {
                return Some(pong);
            }
            let left = until.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return None;
            }
            agent.pump_wait(left);
        }
    }
}

/// Waits (up to 10 s) until `agent` has its graph, driving it meanwhile if the bench's thread drives it.
fn wait_ready(agent: &Agent<Arc<dyn Transport>>, driven: bool) -> anyhow::Result<()> {
    let deadline = Instant::now() + Duration::from_secs(10);
    while driven && !agent.is_ready() && Instant::now() < deadline {
        agent.pump_wait(deadline.saturating_duration_since(Instant::now()));
    }
    ensure!(agent.wait_ready(deadline.saturating_duration_since(Instant::now())), "the pinging agent did not start");
    Ok(())
}

fn through_agents(
    config: &RttConfig,
    updates: UpdateDelivery,
    period: Duration,
    counting: &Counting,
    program: &Path,
    via: Via<'_>,
) -> anyhow::Result<RttFigures> {
    let name = match via {
        Via::Rtps => "",
        Via::Secured(_) => "sec",
        Via::Shm => "shm",
        Via::ShmDriven => "shmdriven",
    };
    let prefix = format!("agentrtt{}{}{name}", std::process::id(), updates.name().replace('-', ""));
    let start = counting.counters()?;
    let transport: Arc<dyn Transport> = match via {
        Via::Shm | Via::ShmDriven => Arc::new(shm_transport(&prefix, 1)?),
        Via::Rtps => Arc::new(rtps(config.domain_id, &prefix, config.multicast, updates)?),
        Via::Secured(credentials) => Arc::new(rtps_secured(
            config.domain_id,
            &prefix,
            config.multicast,
            updates,
            Some(credentials.this.as_path()),
        )?),
    };
    let driven = matches!(via, Via::ShmDriven);
    let (config_1, clock) = (bench_config(1, Duration::from_millis(300)), Arc::new(SystemClock));
    let agent = Arc::new(if driven {
        Agent::new(config_1, transport, clock)?
    } else {
        Agent::start(config_1, transport, clock)?
    });
    wait_ready(&agent, driven)?;
    let ping = agent.insert_node(NewNode::new("object", PING))?;
    let pong = agent.insert_node(NewNode::new("object", PONG))?;
    let (pongs, seen) = std::sync::mpsc::channel::<(u64, Instant)>();
    let seen = Pongs { seen, driven };
    let weak = Arc::downgrade(&agent);
    let callback = agent.on_change(move |signal| {
        let at = Instant::now();
        let Some(agent) = weak.upgrade().filter(|_| is_pong(&signal.change, pong)) else { return };
        if let Some(seq) = agent.attr(pong, attrs::CAM_RGB).and_then(|b| seq_of(&b)) {
            let _ = pongs.send((seq, at));
        }
    });
    let security = match via {
        Via::Secured(credentials) => Some(credentials.helper.as_path()),
        Via::Rtps | Via::Shm | Via::ShmDriven => None,
    };
    let shm = matches!(via, Via::Shm | Via::ShmDriven);
    let args = helper::echo_args(config.domain_id, &prefix, false, config.multicast, updates, security, shm);
    let _helper = Helper::spawn(program, &args)?;
    // The echo agent joins, then echoes; wait for the echo of a probe.
    let deadline = Instant::now() + Duration::from_secs(30);
    'probe: loop {
        if Instant::now() > deadline {
            bail!("the echo agent did not answer within 30 s");
        }
        agent.set_attr(ping, attrs::CAM_RGB, payload_of(u64::MAX, config.payload_bytes))?;
        if seen.next(&agent, Instant::now() + Duration::from_millis(200)).is_some() {
            break 'probe;
        }
    }
    // Late echoes of the probes: wait for 200 ms without one.
    while seen.next(&agent, Instant::now() + Duration::from_millis(200)).is_some() {}
    let discovered = counting.counters()?;
    let before = agent.status();
    let counts = ping_pong(
        config.count,
        period,
        |seq| Ok(agent.set_attr(ping, attrs::CAM_RGB, payload_of(seq, config.payload_bytes))?),
        |seq, deadline| {
            while let Some((got, at)) = seen.next(&agent, deadline) {
                if got == seq {
                    return Some(at);
                }
            }
            None
        },
    )?;
    agent.remove_on_change(callback);
    let end = counting.counters()?;
    let after = agent.status();
    let socket = SocketFigures::of(start, discovered, end, counts.pings + counts.pongs);
    let mut figures = figures(
        &counts,
        after.transport.payload_bytes_sent - before.transport.payload_bytes_sent,
        after.transport.wire_bytes_sent - before.transport.wire_bytes_sent,
        socket,
    );
    figures.gap_requests = Some(after.gap_requests - before.gap_requests);
    Ok(figures)
}

/// The shared-memory transport of the agent ping-pong's side `side` (1 pings, 2 echoes), on services of `prefix`.
fn shm_transport(prefix: &str, side: u128) -> anyhow::Result<ShmTransport> {
    let endpoint = EndpointId((u128::from(std::process::id()) << 8) | side);
    ShmTransport::open(&format!("cortex/bench/{prefix}"), endpoint, &ShmSettings::default())
        .context("opening shared memory")
}

fn is_pong(change: &Change, pong: NodeId) -> bool {
    matches!(change, Change::AttrUpdated { element: Element::Node(id), name } if *id == pong && name.as_str() == "cam_rgb")
}

/// The echoing side (the helper process of `bench echo`): echoes raw samples, or runs an agent that copies every
/// remote ping into the pong node. Returns after 60 s without a ping.
///
/// # Errors
/// The transport or agent cannot start, or the agent gets no graph with ping and pong nodes within 30 s.
/// With `security`, it joins with DDS Security's credentials in that directory; with `shm`, over same-host shared
/// memory instead of RTPS.
pub fn echo(
    domain: u16,
    prefix: &str,
    raw: bool,
    multicast: Multicast,
    updates: UpdateDelivery,
    security: Option<&Path>,
    shm: bool,
) -> anyhow::Result<()> {
    let transport: Arc<dyn Transport> = if shm {
        Arc::new(shm_transport(prefix, 2)?)
    } else {
        Arc::new(rtps_secured(domain, prefix, multicast, updates, security)?)
    };
    if raw {
        while let Some(sample) = transport.recv_timeout(Duration::from_secs(60)) {
            transport.publish(sample.channel, sample.bytes)?;
        }
        return Ok(());
    }
    let agent = Arc::new(Agent::start(bench_config(2, Duration::from_secs(30)), transport, Arc::new(SystemClock))?);
    if !agent.wait_ready(Duration::from_secs(30)) {
        bail!("the echo agent got no graph");
    }
    let find = |name: &str| agent.node_by_name(name).map(|n| n.id);
    let (Some(ping), Some(pong)) = (find(PING), find(PONG)) else { bail!("the graph has no ping/pong nodes") };
    // Echoed in a change callback, on the thread that joined the ping; this thread only watches for silence and
    // failures (a wake-up of its own per ping would compete with the echo for the CPU).
    let heard_ns = Arc::new(AtomicU64::new(SystemClock.now_ns()));
    let (failed, failure) = std::sync::mpsc::sync_channel::<String>(1);
    let (weak, heard) = (Arc::downgrade(&agent), Arc::clone(&heard_ns));
    agent.on_change(move |signal| {
        let is_ping = matches!(&signal.change, Change::AttrUpdated { element: Element::Node(id), name }
            if *id == ping && name.as_str() == "cam_rgb");
        let Some(agent) = weak.upgrade().filter(|_| is_ping && !signal.local) else { return };
        heard.store(SystemClock.now_ns(), Ordering::Relaxed);
        if let Some(value) = agent.attr(ping, attrs::CAM_RGB)
            && let Err(error) = agent.set_attr(pong, attrs::CAM_RGB, value)
        {
            let _ = failed.try_send(error.to_string());
        }
    });
    while SystemClock.now_ns().saturating_sub(heard_ns.load(Ordering::Relaxed)) < ECHO_SILENCE.as_nanos() as u64 {
        if let Ok(error) = failure.recv_timeout(Duration::from_secs(1)) {
            bail!("echoing a ping: {error}");
        }
    }
    agent.shutdown();
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_loop_measures_answered_pings_after_the_warmup_and_counts_the_lost() {
        let mut sent = Vec::new();
        let counts = ping_pong(
            10,
            Duration::ZERO,
            |seq| {
                sent.push(seq);
                Ok(())
            },
            // A pong seen 2 ms after its ping (the deadline is the ping's send time and the timeout).
            |seq, deadline| (seq % 5 != 0).then(|| deadline - PONG_TIMEOUT + Duration::from_millis(2)),
        )
        .unwrap();
        assert_eq!(sent, (0..u64::from(WARMUP) + 10).collect::<Vec<_>>());
        assert_eq!(counts.pings, u64::from(WARMUP) + 10);
        // Every fifth ping goes unanswered: 22 of 110, 2 of them among the 10 measured (100 and 105).
        assert_eq!(counts.pongs, 110 - 22);
        assert_eq!(counts.lost, 2);
        assert_eq!(counts.histogram_us.len(), 8);
        assert_eq!(
            (counts.histogram_us.min(), counts.histogram_us.max()),
            (2000, 2000),
            "timed to when the pong was seen"
        );
        let f = figures(&counts, 1100, 2200, None);
        assert_eq!((f.count, f.lost, f.envelope_bytes_per_update, f.wire_bytes_per_update), (8, 2, 10.0, 20.0));
    }

    #[test]
    fn a_failed_ping_stops_the_loop() {
        let result = ping_pong(
            5,
            Duration::ZERO,
            |seq| if seq == 3 { bail!("refused") } else { Ok(()) },
            |_, _| Some(Instant::now()),
        );
        assert!(result.unwrap_err().to_string().contains("refused"));
    }
}
