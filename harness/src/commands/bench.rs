//! `cortex bench`: measurements of agents over RTPS on this host, as separate processes. `rtt` ping-pongs one
//! attribute between two agent processes and, in the same run, raw byte samples between two processes over the
//! same `rustdds` transport with no agent on top (the transport's limit); `join` times a new agent process
//! receiving and rebuilding a graph of N nodes; `fanout` (hidden, for issues 5 and 7) sends large samples from one
//! writer to N reader processes and counts the bytes on the wire against N, with multicast on and off. The helper
//! processes are this binary's hidden `bench echo`, `bench join-child` and `bench fanout-reader` subcommands.
//!
//! `rtt` and `fanout` re-run themselves in a fresh network namespace when they can (`--netns auto`, the default:
//! root, `unshare` and `ip` present), so the namespace's loopback counters count exactly their traffic — IP, UDP
//! and RTPS, acknowledgements, heartbeats and discovery — read at phase boundaries (discovery, then steady
//! state). Otherwise they print the transport's estimate only and say why. Figures are measurements, never test
//! assertions.

use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Stdio};
use std::sync::Arc;
use std::time::{Duration, Instant};

use agent::{Agent, AgentConfig, AgentId};
use anyhow::{Context, Result, bail};
use bytes::Bytes;
use clap::{Args, Subcommand, ValueEnum};
use dsr::{Change, Element, NewNode, NodeId, Replica, Value, attrs};
use hdrhistogram::Histogram;
use measure::netns::{self, LoopbackCounters, NetnsSetup};
use transport::rtps::{Multicast, RtpsConfig, RtpsTransport, estimated_wire_bytes};

use super::agent::UpdatesArg;
use transport::{Channel, Clock, SystemClock, Transport};

/// Arguments of `cortex bench`.
#[derive(Debug, Args)]
pub struct BenchArgs {
    /// Which measurement.
    #[command(subcommand)]
    pub what: BenchCommand,
}

/// The measurements.
#[derive(Debug, Subcommand)]
pub enum BenchCommand {
    /// Round-trip time of one attribute between two agent processes, beside raw rustdds ping-pong.
    Rtt(RttArgs),
    /// Time for a new agent process to receive and rebuild a graph of N nodes.
    Join(JoinArgs),
    /// Helper process: echoes pings (agent or raw mode).
    #[command(hide = true)]
    Echo(EchoArgs),
    /// Helper process: joins and reports the time to the graph.
    #[command(hide = true)]
    JoinChild(JoinChildArgs),
    /// Bytes on the wire of one writer of large samples to N reader processes, multicast on and off.
    #[command(hide = true)]
    Fanout(FanoutArgs),
    /// Helper process: counts the fan-out's samples and reports the count.
    #[command(hide = true)]
    FanoutReader(FanoutReaderArgs),
}

/// Where a measurement runs, and so how its wire bytes are counted.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum NetnsMode {
    /// In a fresh network namespace when one can be made (exact socket-level bytes), else here with estimates.
    Auto,
    /// In a fresh network namespace, or fail.
    Require,
    /// Here, with the transport's estimates only.
    Off,
}

/// `--multicast`: the transport's [`Multicast`] setting.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum MulticastArg {
    /// Multicast when the loopback interface is multicast-capable.
    Auto,
    /// Same-host readers share one multicast datagram.
    On,
    /// One unicast copy per same-host reader (rustdds's default).
    Off,
}

impl From<MulticastArg> for Multicast {
    fn from(arg: MulticastArg) -> Multicast {
        match arg {
            MulticastArg::Auto => Multicast::Auto,
            MulticastArg::On => Multicast::On,
            MulticastArg::Off => Multicast::Off,
        }
    }
}

impl MulticastArg {
    fn name(self) -> &'static str {
        match self {
            MulticastArg::Auto => "auto",
            MulticastArg::On => "on",
            MulticastArg::Off => "off",
        }
    }
}

/// Arguments of `cortex bench rtt`.
#[derive(Debug, Args)]
pub struct RttArgs {
    /// Attribute payload in bytes (at least 8: a sequence number).
    #[arg(long, default_value_t = 8)]
    pub payload: usize,
    /// Pings per second (closed loop: a ping waits for its pong, then for its slot).
    #[arg(long, default_value_t = 1000.0)]
    pub rate: f64,
    /// Pings measured (after 100 warm-up pings).
    #[arg(long, default_value_t = 2000)]
    pub count: u32,
    /// DDS domain id.
    #[arg(long, default_value_t = 0)]
    pub domain: u16,
    /// Run in a fresh network namespace to count socket-level bytes.
    #[arg(long, value_enum, default_value_t = NetnsMode::Auto)]
    pub netns: NetnsMode,
    /// Multicast for same-host readers (in a namespace, `lo` is made multicast-capable unless `off`).
    #[arg(long, value_enum, default_value_t = MulticastArg::Auto)]
    pub multicast: MulticastArg,
    /// Deliveries of updates to compare, each measured raw and through agents, in this order.
    #[arg(long, value_enum, value_delimiter = ',', default_value = "reliable,best-effort")]
    pub updates: Vec<UpdatesArg>,
    /// Print one JSON object.
    #[arg(long)]
    pub json: bool,
}

/// Arguments of `cortex bench fanout`.
#[derive(Debug, Args)]
pub struct FanoutArgs {
    /// Numbers of reader processes, one run each.
    #[arg(long, value_delimiter = ',', default_value = "1,2,4,8")]
    pub readers: Vec<u32>,
    /// Sample size in bytes (default: a 752x480 mono8 frame).
    #[arg(long, default_value_t = 360_960)]
    pub payload: usize,
    /// Samples per second.
    #[arg(long, default_value_t = 20.0)]
    pub rate: f64,
    /// Samples per run.
    #[arg(long, default_value_t = 60)]
    pub frames: u32,
    /// Multicast settings to compare, one run per setting and reader count.
    #[arg(long, value_enum, value_delimiter = ',', default_value = "on,off")]
    pub multicast: Vec<MulticastArg>,
    /// DDS domain id.
    #[arg(long, default_value_t = 0)]
    pub domain: u16,
    /// Run in a fresh network namespace (with multicast on `lo`) to count socket-level bytes.
    #[arg(long, value_enum, default_value_t = NetnsMode::Auto)]
    pub netns: NetnsMode,
    /// Print one JSON object.
    #[arg(long)]
    pub json: bool,
}

/// Arguments of the fan-out reader helper.
#[derive(Debug, Args)]
pub struct FanoutReaderArgs {
    /// DDS domain id.
    #[arg(long)]
    pub domain: u16,
    /// Topic prefix.
    #[arg(long)]
    pub prefix: String,
    /// Multicast setting.
    #[arg(long, value_enum)]
    pub multicast: MulticastArg,
}

/// Arguments of `cortex bench join`.
#[derive(Debug, Args)]
pub struct JoinArgs {
    /// Nodes in the graph (a tree, 6 attributes and one RT edge per node).
    #[arg(long, default_value_t = 10_000)]
    pub nodes: u32,
    /// DDS domain id.
    #[arg(long, default_value_t = 0)]
    pub domain: u16,
    /// Print one JSON object.
    #[arg(long)]
    pub json: bool,
}

/// Arguments of the echo helper.
#[derive(Debug, Args)]
pub struct EchoArgs {
    /// DDS domain id.
    #[arg(long)]
    pub domain: u16,
    /// Topic prefix.
    #[arg(long)]
    pub prefix: String,
    /// Echo raw samples instead of running an agent.
    #[arg(long)]
    pub raw: bool,
    /// Multicast setting.
    #[arg(long, value_enum, default_value_t = MulticastArg::Auto)]
    pub multicast: MulticastArg,
    /// Delivery of updates.
    #[arg(long, value_enum, default_value_t = UpdatesArg::Reliable)]
    pub updates: UpdatesArg,
}

/// Arguments of the join helper.
#[derive(Debug, Args)]
pub struct JoinChildArgs {
    /// DDS domain id.
    #[arg(long)]
    pub domain: u16,
    /// Topic prefix.
    #[arg(long)]
    pub prefix: String,
    /// Nodes expected.
    #[arg(long)]
    pub nodes: usize,
}

/// Runs `cortex bench`.
pub fn run(args: BenchArgs) -> Result<()> {
    match args.what {
        BenchCommand::Rtt(args) => rtt(args),
        BenchCommand::Join(args) => join(args),
        BenchCommand::Echo(args) => echo(args),
        BenchCommand::JoinChild(args) => join_child(args),
        BenchCommand::Fanout(args) => fanout(args),
        BenchCommand::FanoutReader(args) => fanout_reader(args),
    }
}

/// Where this measurement counts bytes.
enum Counting {
    /// This process runs in a fresh network namespace: its loopback counters are the measurement's traffic.
    Socket,
    /// Estimates only, and why.
    EstimateOnly(String),
}

/// Either runs this command again in a fresh network namespace and returns `None` (the child did the work), or
/// says how this process counts bytes.
fn enter_netns(mode: NetnsMode, setup: NetnsSetup) -> Result<Option<Counting>> {
    if netns::inside().is_some() {
        return Ok(Some(Counting::Socket));
    }
    if mode == NetnsMode::Off {
        return Ok(Some(Counting::EstimateOnly("--netns off".into())));
    }
    match netns::reexec_in_fresh_netns(setup) {
        Ok(status) if status.success() => Ok(None),
        Ok(status) => bail!("the measurement in a fresh network namespace failed ({status})"),
        Err(error) if mode == NetnsMode::Require => {
            Err(error).context("--netns require: cannot run in a fresh network namespace")
        }
        Err(error) => {
            eprintln!("note: no fresh network namespace ({error}); socket-level bytes not measured, estimates only");
            Ok(Some(Counting::EstimateOnly(error.to_string())))
        }
    }
}

/// The loopback counters now, when this process counts socket-level bytes.
fn counters(counting: &Counting) -> Result<Option<LoopbackCounters>> {
    match counting {
        Counting::Socket => Ok(Some(LoopbackCounters::read()?)),
        Counting::EstimateOnly(_) => Ok(None),
    }
}

fn growth(later: Option<LoopbackCounters>, earlier: Option<LoopbackCounters>) -> Option<LoopbackCounters> {
    Some(later?.since(&earlier?))
}

const WARMUP: u32 = 100;
const PING: &str = "bench_ping";
const PONG: &str = "bench_pong";

fn rtps(domain: u16, prefix: &str, multicast: MulticastArg) -> Result<RtpsTransport> {
    rtps_with(domain, prefix, multicast, UpdatesArg::Reliable)
}

fn rtps_with(domain: u16, prefix: &str, multicast: MulticastArg, updates: UpdatesArg) -> Result<RtpsTransport> {
    RtpsTransport::new(RtpsConfig {
        domain_id: domain,
        topic_prefix: prefix.into(),
        multicast: multicast.into(),
        updates: updates.into(),
        ..RtpsConfig::default()
    })
    .context("joining the DDS domain")
}

/// A helper process of this binary, killed when dropped.
struct Helper(Child);

impl Helper {
    fn spawn(args: &[String]) -> Result<Helper> {
        let exe = std::env::current_exe().context("finding the cortex binary")?;
        let child = Command::new(exe)
            .args(args)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .context("starting a helper process")?;
        Ok(Helper(child))
    }
}

impl Drop for Helper {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Socket-level bytes of one measurement, from the namespace's loopback counters.
#[derive(Debug, serde::Serialize)]
struct SocketFigures {
    /// Discovery (and, for agents, the join) until the first echo came back.
    discovery: LoopbackCounters,
    /// The measured loop: every update both ways, their acknowledgements and heartbeats, periodic discovery.
    steady: LoopbackCounters,
    /// Updates in the steady state (pings sent plus pongs received).
    updates: u64,
    bytes_per_update: f64,
    packets_per_update: f64,
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
}

/// Figures of one ping-pong run.
#[derive(Debug, serde::Serialize)]
struct RttFigures {
    count: u64,
    lost: u64,
    p50_us: u64,
    p90_us: u64,
    p99_us: u64,
    max_us: u64,
    envelope_bytes_per_update: f64,
    wire_bytes_per_update: f64,
    /// Socket-level bytes, when measured in a fresh network namespace.
    socket: Option<SocketFigures>,
    /// Agents: gap requests of the pinging agent during the measured loop (each a repair it asked for at once).
    gap_requests: Option<u64>,
}

/// What one ping-pong loop observed, beside its histogram.
struct LoopCounts {
    pings: u64,
    pongs: u64,
    lost: u64,
    payload_bytes: u64,
    estimated_wire_bytes: u64,
}

impl LoopCounts {
    /// Counts the answer to ping `seq` sent at `sent` (`got`: it came in time); past the warm-up, its round trip
    /// goes into `histogram`, or it counts as lost.
    fn answered(&mut self, seq: u64, got: bool, sent: Instant, histogram: &mut Histogram<u64>) -> Result<()> {
        self.pongs += u64::from(got);
        if seq >= u64::from(WARMUP) {
            if got {
                histogram.record(sent.elapsed().as_micros() as u64)?;
            } else {
                self.lost += 1;
            }
        }
        Ok(())
    }
}

fn figures(histogram: &Histogram<u64>, counts: &LoopCounts, socket: Option<SocketFigures>) -> RttFigures {
    RttFigures {
        count: histogram.len(),
        lost: counts.lost,
        p50_us: histogram.value_at_quantile(0.5),
        p90_us: histogram.value_at_quantile(0.9),
        p99_us: histogram.value_at_quantile(0.99),
        max_us: histogram.max(),
        envelope_bytes_per_update: counts.payload_bytes as f64 / counts.pings.max(1) as f64,
        wire_bytes_per_update: counts.estimated_wire_bytes as f64 / counts.pings.max(1) as f64,
        socket,
        gap_requests: None,
    }
}

/// Socket figures from the counters at the start, after discovery, and after the steady state.
fn socket_figures(
    start: Option<LoopbackCounters>,
    discovered: Option<LoopbackCounters>,
    end: Option<LoopbackCounters>,
    updates: u64,
) -> Option<SocketFigures> {
    Some(SocketFigures::new(growth(discovered, start)?, growth(end, discovered)?, updates))
}

fn payload_of(seq: u64, size: usize) -> Bytes {
    let mut bytes = vec![0u8; size.max(8)];
    bytes[..8].copy_from_slice(&seq.to_le_bytes());
    Bytes::from(bytes)
}

fn seq_of(bytes: &[u8]) -> Option<u64> {
    Some(u64::from_le_bytes(bytes.get(..8)?.try_into().ok()?))
}

fn rtt(args: RttArgs) -> Result<()> {
    if args.rate <= 0.0 || args.count == 0 || args.updates.is_empty() {
        bail!("--rate and --count must be positive, and --updates must name at least one delivery");
    }
    let setup = NetnsSetup { multicast: args.multicast != MulticastArg::Off };
    let Some(counting) = enter_netns(args.netns, setup)? else { return Ok(()) };
    let period = Duration::from_secs_f64(1.0 / args.rate);
    let mut runs = Vec::new();
    for &updates in &args.updates {
        let raw = rtt_raw(&args, updates, period, &counting)
            .with_context(|| format!("raw rustdds ping-pong, {} updates", updates.name()))?;
        let agent = rtt_agent(&args, updates, period, &counting)
            .with_context(|| format!("agent ping-pong, {} updates", updates.name()))?;
        runs.push(RttRun {
            updates: updates.name(),
            p50_ratio: agent.p50_us as f64 / raw.p50_us.max(1) as f64,
            agent,
            raw,
        });
    }
    let multicast = Multicast::from(args.multicast).resolve();
    if args.json {
        let out = serde_json::json!({
            "payload": args.payload, "rate_hz": args.rate, "count": args.count,
            "multicast": multicast, "netns": netns::inside().is_some(), "runs": runs,
        });
        println!("{out}");
        return Ok(());
    }
    let place = match &counting {
        Counting::Socket => "in a fresh network namespace",
        Counting::EstimateOnly(_) => "on this host's loopback",
    };
    println!(
        "RTT, {} B payload, {} Hz, {} pings, two processes {place}, multicast {}",
        args.payload,
        args.rate,
        args.count,
        if multicast { "on" } else { "off" }
    );
    println!(
        "{:<26} {:>7} {:>7} {:>7} {:>7} {:>5} {:>8} {:>14} {:>12} {:>12} {:>9}",
        "",
        "p50 us",
        "p90 us",
        "p99 us",
        "max us",
        "lost",
        "repairs",
        "envelope B/upd",
        "est. wire B",
        "socket B/upd",
        "pkts/upd"
    );
    for run in &runs {
        for (who, f) in [("agent", &run.agent), ("raw rustdds", &run.raw)] {
            let (socket_bytes, packets) = match &f.socket {
                Some(s) => (format!("{:.1}", s.bytes_per_update), format!("{:.2}", s.packets_per_update)),
                None => ("-".into(), "-".into()),
            };
            let repairs = f.gap_requests.map_or("-".into(), |n| n.to_string());
            let name = format!("{who}, {}", run.updates);
            println!(
                "{name:<26} {:>7} {:>7} {:>7} {:>7} {:>5} {repairs:>8} {:>14.1} {:>12.1} {socket_bytes:>12} {packets:>9}",
                f.p50_us, f.p90_us, f.p99_us, f.max_us, f.lost, f.envelope_bytes_per_update, f.wire_bytes_per_update
            );
        }
    }
    for run in &runs {
        println!("{} updates: agent p50 / raw p50 = {:.2}", run.updates, run.p50_ratio);
    }
    match &counting {
        Counting::Socket => {
            for run in &runs {
                for (who, f) in [("agent (discovery + join)", &run.agent), ("raw rustdds (discovery)", &run.raw)] {
                    if let Some(s) = &f.socket {
                        println!(
                            "{who}, {}: {} B in {} packets before the first echo; steady state {} B in {} packets \
                             ({} B multicast) for {} updates (pings + pongs)",
                            run.updates,
                            s.discovery.tx_bytes,
                            s.discovery.tx_packets,
                            s.steady.tx_bytes,
                            s.steady.tx_packets,
                            s.steady.tx_multicast_bytes,
                            s.updates
                        );
                    }
                }
            }
            println!(
                "socket B/upd: loopback tx bytes (IPv4 + UDP + RTPS, acknowledgements, heartbeats, periodic discovery, \
                 anti-entropy) in the steady state / updates both ways; est. wire B: the transport's estimate for one \
                 sample; repairs: the pinging agent's gap requests"
            );
        }
        Counting::EstimateOnly(why) => println!("socket-level bytes not measured ({why}); est. wire B is an estimate"),
    }
    Ok(())
}

/// One delivery setting's raw and agent ping-pong.
#[derive(Debug, serde::Serialize)]
struct RttRun {
    updates: &'static str,
    agent: RttFigures,
    raw: RttFigures,
    p50_ratio: f64,
}

fn rtt_raw(args: &RttArgs, updates: UpdatesArg, period: Duration, counting: &Counting) -> Result<RttFigures> {
    let prefix = format!("rawrtt{}{}", std::process::id(), updates.name().replace('-', ""));
    let start = counters(counting)?;
    let transport = rtps_with(args.domain, &prefix, args.multicast, updates)?;
    let _helper = Helper::spawn(&[
        "bench".into(),
        "echo".into(),
        "--domain".into(),
        args.domain.to_string(),
        "--prefix".into(),
        prefix,
        "--raw".into(),
        "--multicast".into(),
        args.multicast.name().into(),
        "--updates".into(),
        updates.name().into(),
    ])?;
    // Discovery: probe until an echo comes back.
    let deadline = Instant::now() + Duration::from_secs(30);
    loop {
        if Instant::now() > deadline {
            bail!("the echo process was not discovered within 30 s");
        }
        transport.publish(Channel::Updates, payload_of(u64::MAX, args.payload))?;
        if transport.recv_timeout(Duration::from_millis(100)).is_some() {
            break;
        }
    }
    while transport.recv_timeout(Duration::from_millis(200)).is_some() {}
    let discovered = counters(counting)?;
    let mut histogram = Histogram::<u64>::new(3)?;
    let mut counts = LoopCounts { pings: 0, pongs: 0, lost: 0, payload_bytes: 0, estimated_wire_bytes: 0 };
    let before = transport.stats();
    let mut next = Instant::now();
    for seq in 0..u64::from(WARMUP + args.count) {
        let sent = Instant::now();
        transport.publish(Channel::Updates, payload_of(seq, args.payload))?;
        counts.pings += 1;
        let reply_deadline = sent + Duration::from_secs(1);
        let mut got = false;
        while let Some(sample) = transport.recv_timeout(reply_deadline.saturating_duration_since(Instant::now())) {
            if seq_of(&sample.bytes) == Some(seq) {
                got = true;
                break;
            }
        }
        counts.answered(seq, got, sent, &mut histogram)?;
        next += period;
        std::thread::sleep(next.saturating_duration_since(Instant::now()));
    }
    let end = counters(counting)?;
    let after = transport.stats();
    counts.payload_bytes = after.payload_bytes_sent - before.payload_bytes_sent;
    counts.estimated_wire_bytes = after.wire_bytes_sent - before.wire_bytes_sent;
    let socket = socket_figures(start, discovered, end, counts.pings + counts.pongs);
    Ok(figures(&histogram, &counts, socket))
}

fn bench_config(id: u32, join_wait: Duration) -> AgentConfig {
    let mut config = AgentConfig::new(AgentId(id));
    config.join_wait = join_wait;
    config
}

fn rtt_agent(args: &RttArgs, updates: UpdatesArg, period: Duration, counting: &Counting) -> Result<RttFigures> {
    let prefix = format!("agentrtt{}{}", std::process::id(), updates.name().replace('-', ""));
    let start = counters(counting)?;
    let agent = Agent::start(
        bench_config(1, Duration::from_millis(300)),
        rtps_with(args.domain, &prefix, args.multicast, updates)?,
        Arc::new(SystemClock),
    )?;
    if !agent.wait_ready(Duration::from_secs(10)) {
        bail!("the pinging agent did not start");
    }
    let ping = agent.insert_node(NewNode::new("object", PING))?;
    let pong = agent.insert_node(NewNode::new("object", PONG))?;
    let signals = agent.subscribe(100_000);
    let _helper = Helper::spawn(&[
        "bench".into(),
        "echo".into(),
        "--domain".into(),
        args.domain.to_string(),
        "--prefix".into(),
        prefix,
        "--multicast".into(),
        args.multicast.name().into(),
        "--updates".into(),
        updates.name().into(),
    ])?;
    // The echo agent joins, then echoes; wait for the echo of a probe.
    let deadline = Instant::now() + Duration::from_secs(30);
    'probe: loop {
        if Instant::now() > deadline {
            bail!("the echo agent did not answer within 30 s");
        }
        agent.set_attr(ping, attrs::CAM_RGB, payload_of(u64::MAX, args.payload))?;
        let until = Instant::now() + Duration::from_millis(200);
        while let Ok(signal) = signals.recv_deadline(until) {
            if is_pong(&signal.change, pong) {
                break 'probe;
            }
        }
    }
    std::thread::sleep(Duration::from_millis(200));
    while signals.try_recv().is_ok() {}
    let discovered = counters(counting)?;
    let mut histogram = Histogram::<u64>::new(3)?;
    let mut counts = LoopCounts { pings: 0, pongs: 0, lost: 0, payload_bytes: 0, estimated_wire_bytes: 0 };
    let before = agent.status();
    let mut next = Instant::now();
    for seq in 0..u64::from(WARMUP + args.count) {
        let sent = Instant::now();
        agent.set_attr(ping, attrs::CAM_RGB, payload_of(seq, args.payload))?;
        counts.pings += 1;
        let reply_deadline = sent + Duration::from_secs(1);
        let mut got = false;
        while let Ok(signal) = signals.recv_deadline(reply_deadline) {
            if is_pong(&signal.change, pong) && agent.attr(pong, attrs::CAM_RGB).and_then(|b| seq_of(&b)) == Some(seq) {
                got = true;
                break;
            }
        }
        counts.answered(seq, got, sent, &mut histogram)?;
        next += period;
        std::thread::sleep(next.saturating_duration_since(Instant::now()));
    }
    let end = counters(counting)?;
    let after = agent.status();
    counts.payload_bytes = after.transport.payload_bytes_sent - before.transport.payload_bytes_sent;
    counts.estimated_wire_bytes = after.transport.wire_bytes_sent - before.transport.wire_bytes_sent;
    let socket = socket_figures(start, discovered, end, counts.pings + counts.pongs);
    let mut figures = figures(&histogram, &counts, socket);
    figures.gap_requests = Some(after.gap_requests - before.gap_requests);
    Ok(figures)
}

fn is_pong(change: &Change, pong: NodeId) -> bool {
    matches!(change, Change::AttrUpdated { element: Element::Node(id), name } if *id == pong && name.as_str() == "cam_rgb")
}

fn echo(args: EchoArgs) -> Result<()> {
    let transport = rtps_with(args.domain, &args.prefix, args.multicast, args.updates)?;
    if args.raw {
        loop {
            if let Some(sample) = transport.recv_timeout(Duration::from_secs(60)) {
                transport.publish(sample.channel, sample.bytes)?;
            } else {
                return Ok(());
            }
        }
    }
    let agent = Agent::start(bench_config(2, Duration::from_secs(30)), transport, Arc::new(SystemClock))?;
    let signals = agent.subscribe(100_000);
    if !agent.wait_ready(Duration::from_secs(30)) {
        bail!("the echo agent got no graph");
    }
    let find = |name: &str| agent.node_by_name(name).map(|n| n.id);
    let (Some(ping), Some(pong)) = (find(PING), find(PONG)) else { bail!("the graph has no ping/pong nodes") };
    loop {
        let Ok(signal) = signals.recv_timeout(Duration::from_secs(60)) else { return Ok(()) };
        if let Change::AttrUpdated { element: Element::Node(id), name } = &signal.change
            && *id == ping
            && name.as_str() == "cam_rgb"
            && !signal.local
            && let Some(value) = agent.attr(ping, attrs::CAM_RGB)
        {
            agent.set_attr(pong, attrs::CAM_RGB, value)?;
        }
    }
}

/// Builds the join benchmark's graph: a tree with 6 attributes and one RT edge per node.
fn build_tree<T: Transport>(agent: &Agent<T>, nodes: u32) -> Result<()> {
    let mut ids: Vec<NodeId> = Vec::with_capacity(nodes as usize);
    for i in 0..nodes {
        let parent = if i == 0 { None } else { Some(ids[((i - 1) / 4) as usize]) };
        let node = NewNode::new(if i == 0 { "world" } else { "object" }, &format!("n{i}"))
            .with_attr("pos_x", i as f32)
            .with_attr("pos_y", -(i as f32))
            .with_attr("level", if i == 0 { 0 } else { 1 + (i as f64).log(4.0) as i32 })
            .with_attr("parent", parent.map_or(0, |p| p.0))
            .with_attr("color", Value::String("SteelBlue".into()))
            .with_attr("width", 100);
        let id = agent.insert_node(node)?;
        if let Some(parent) = parent {
            agent.insert_edge(
                parent,
                id,
                "RT",
                vec![
                    ("rt_translation".into(), vec![100.0f32, 0.0, 0.0].into()),
                    ("rt_rotation_euler_xyz".into(), vec![0.0f32, 0.0, 0.1].into()),
                ],
            )?;
        }
        ids.push(id);
    }
    Ok(())
}

fn join(args: JoinArgs) -> Result<()> {
    let prefix = format!("join{}", std::process::id());
    let agent = Agent::start(
        bench_config(1, Duration::from_millis(300)),
        rtps(args.domain, &prefix, MulticastArg::Auto)?,
        Arc::new(SystemClock),
    )?;
    if !agent.wait_ready(Duration::from_secs(10)) {
        bail!("the first agent did not start");
    }
    build_tree(&agent, args.nodes)?;
    // In-process: snapshot encode (timed inside the agent's lock, so a wait for the lock is not counted), decode
    // and join into an empty replica (the rebuild alone).
    let (bytes, encoded) = agent
        .read(|replica| {
            let started = Instant::now();
            (replica.encode_snapshot(), started.elapsed())
        })
        .context("no graph")?;
    let started = Instant::now();
    let mut fresh = Replica::new(dsr::ReplicaId(9999));
    fresh.apply(&dsr::Delta::decode(&bytes)?)?;
    let rebuilt = encoded + started.elapsed();
    // A new agent process joins; both processes read the system clock, so their times compare.
    let spawned_at_ns = SystemClock.now_ns();
    let mut helper = Helper::spawn(&[
        "bench".into(),
        "join-child".into(),
        "--domain".into(),
        args.domain.to_string(),
        "--prefix".into(),
        prefix,
        "--nodes".into(),
        args.nodes.to_string(),
    ])?;
    let stdout = helper.0.stdout.take().context("helper stdout")?;
    let line = BufReader::new(stdout).lines().next().context("the joining process printed nothing")??;
    let child: JoinChildReport = serde_json::from_str(&line).context("the joining process's report")?;
    let server = agent.status();
    let breakdown =
        JoinBreakdown::new(spawned_at_ns, &child, server.last_answer.as_ref(), agent.transport().discovery());
    let out = serde_json::json!({
        "nodes": args.nodes,
        "snapshot_bytes": bytes.len(),
        "snapshot_encode_ms": encoded.as_secs_f64() * 1e3,
        "snapshot_encode_decode_join_ms": rebuilt.as_secs_f64() * 1e3,
        "process": child,
        "breakdown": breakdown,
        "loadavg": loadavg(),
    });
    if args.json {
        println!("{out}");
    } else {
        println!("join of a {}-node graph (tree, 6 attributes + 1 RT edge per node)", args.nodes);
        println!(
            "  in process: snapshot {} bytes; encode {:.1} ms; encode+decode+join {:.1} ms",
            bytes.len(),
            encoded.as_secs_f64() * 1e3,
            rebuilt.as_secs_f64() * 1e3
        );
        println!(
            "  new agent process: {} of {} nodes, {} graph request(s)",
            child.nodes, args.nodes, child.join_requests
        );
        breakdown.print();
        println!("  load average: {}", loadavg());
    }
    Ok(())
}

/// The load average of this machine (`/proc/loadavg`), printed beside every figure.
fn loadavg() -> String {
    std::fs::read_to_string("/proc/loadavg").map_or_else(|_| "unknown".into(), |s| s.trim().to_owned())
}

/// What the joining process reports: its own steps and discovery, in ns since the Unix epoch.
#[derive(Debug, serde::Serialize, serde::Deserialize)]
struct JoinChildReport {
    /// Visible nodes once ready.
    nodes: usize,
    /// Whether all nodes arrived.
    complete: bool,
    /// `main` of the helper ran (the binary was loaded).
    main_ns: u64,
    /// The RTPS participant, topics, readers and writers exist.
    participant_ns: u64,
    /// The first remote participant was discovered.
    peer_discovered_ns: Option<u64>,
    /// The helper's sync writer matched a remote reader (its graph request can be heard).
    sync_writer_matched_ns: Option<u64>,
    /// The helper's sync reader matched a remote writer (the answer can reach it).
    sync_reader_matched_ns: Option<u64>,
    /// Graph requests published.
    join_requests: u32,
    /// The first and the last graph request published.
    first_request_ns: Option<u64>,
    last_request_ns: Option<u64>,
    /// The answer reached the agent.
    answer_received_ns: Option<u64>,
    /// The snapshot was decoded.
    decoded_ns: Option<u64>,
    /// The replica was built: the agent became ready.
    ready_ns: Option<u64>,
    /// `wait_ready` returned in the helper's main thread.
    ready_seen_ns: u64,
}

/// The join, step by step, in ms since the parent spawned the joining process (`at_ms`) and as durations.
#[derive(Debug, serde::Serialize)]
struct JoinBreakdown {
    /// Milestones since the spawn, in order: name and ms (absent when not reached or not known).
    at_ms: Vec<(&'static str, Option<f64>)>,
    /// Spawn → ready: what a user waits for.
    total_ms: Option<f64>,
    /// Participant created → the sync channel matched both ways (rustdds discovery).
    discovery_ms: Option<f64>,
    /// The answered request reached the server → the joiner was ready (encode, transfer, decode, join).
    request_to_ready_ms: Option<f64>,
    /// Server: request received → encoded snapshot ready.
    server_encode_ms: Option<f64>,
    /// Whether the server took the snapshot from its cache.
    server_snapshot_cached: Option<bool>,
    /// Server: snapshot ready → publish returned.
    server_publish_ms: Option<f64>,
    /// Snapshot ready at the server → answer taken from the joiner's inbox.
    transfer_ms: Option<f64>,
    /// Joiner: answer received → snapshot decoded.
    decode_ms: Option<f64>,
    /// Joiner: decoded → replica built and ready.
    join_ms: Option<f64>,
}

impl JoinBreakdown {
    fn new(
        spawned_ns: u64,
        child: &JoinChildReport,
        answer: Option<&agent::AnswerTiming>,
        server_discovery: transport::rtps::DiscoveryTimes,
    ) -> JoinBreakdown {
        let ms = |from: u64, to: u64| (to as f64 - from as f64) / 1e6;
        let since = |t: Option<u64>| t.map(|t| ms(spawned_ns, t));
        let between = |a: Option<u64>, b: Option<u64>| Some(ms(a?, b?));
        let sync_matched = match (child.sync_writer_matched_ns, child.sync_reader_matched_ns) {
            (Some(w), Some(r)) => Some(w.max(r)),
            _ => None,
        };
        let sync = Channel::Sync.index();
        JoinBreakdown {
            at_ms: vec![
                ("main", since(Some(child.main_ns))),
                ("participant created", since(Some(child.participant_ns))),
                ("first graph request", since(child.first_request_ns)),
                ("peer discovered", since(child.peer_discovered_ns)),
                ("server: sync writer matched joiner", since(server_discovery.writer_matched_ns[sync])),
                ("joiner: sync writer matched", since(child.sync_writer_matched_ns)),
                ("joiner: sync reader matched", since(child.sync_reader_matched_ns)),
                ("last graph request", since(child.last_request_ns)),
                ("server: request received", since(answer.map(|a| a.request_received_ns))),
                ("server: snapshot encoded", since(answer.map(|a| a.snapshot_ready_ns))),
                ("server: answer published", since(answer.map(|a| a.published_ns))),
                ("joiner: answer received", since(child.answer_received_ns)),
                ("joiner: decoded", since(child.decoded_ns)),
                ("joiner: ready", since(child.ready_ns)),
                ("joiner: ready seen by wait_ready", since(Some(child.ready_seen_ns))),
            ],
            total_ms: since(child.ready_ns),
            discovery_ms: between(Some(child.participant_ns), sync_matched),
            request_to_ready_ms: between(answer.map(|a| a.request_received_ns), child.ready_ns),
            server_encode_ms: answer.map(|a| ms(a.request_received_ns, a.snapshot_ready_ns)),
            server_snapshot_cached: answer.map(|a| a.from_cache),
            server_publish_ms: answer.map(|a| ms(a.snapshot_ready_ns, a.published_ns)),
            transfer_ms: between(answer.map(|a| a.snapshot_ready_ns), child.answer_received_ns),
            decode_ms: between(child.answer_received_ns, child.decoded_ns),
            join_ms: between(child.decoded_ns, child.ready_ns),
        }
    }

    fn print(&self) {
        let show = |v: Option<f64>| v.map_or_else(|| "-".to_owned(), |v| format!("{v:.1} ms"));
        println!("  timeline, from spawning the joining process:");
        for (name, at) in &self.at_ms {
            println!("    {name:<38} {:>10}", show(*at));
        }
        println!("  total (spawn → ready)                  {:>10}", show(self.total_ms));
        println!("  discovery (participant → sync matched) {:>10}", show(self.discovery_ms));
        println!("  request received → ready               {:>10}", show(self.request_to_ready_ms));
        let cached = match self.server_snapshot_cached {
            Some(true) => " (cached)",
            Some(false) => " (encoded)",
            None => "",
        };
        println!("    server snapshot{cached:<11}            {:>10}", show(self.server_encode_ms));
        println!("    server publish                       {:>10}", show(self.server_publish_ms));
        println!("    transfer (encoded → received)        {:>10}", show(self.transfer_ms));
        println!("    decode                               {:>10}", show(self.decode_ms));
        println!("    join                                 {:>10}", show(self.join_ms));
    }
}

fn join_child(args: JoinChildArgs) -> Result<()> {
    let main_ns = SystemClock.now_ns();
    let transport = rtps(args.domain, &args.prefix, MulticastArg::Auto)?;
    let participant_ns = transport.discovery().created_ns;
    let agent = Agent::start(bench_config(2, Duration::from_secs(60)), transport, Arc::new(SystemClock))?;
    if !agent.wait_ready(Duration::from_secs(60)) {
        bail!("no graph within 60 s");
    }
    let ready_seen_ns = SystemClock.now_ns();
    let status = agent.status();
    let discovery = agent.transport().discovery();
    let sync = Channel::Sync.index();
    let report = JoinChildReport {
        nodes: status.nodes,
        complete: status.nodes == args.nodes,
        main_ns,
        participant_ns,
        peer_discovered_ns: discovery.first_participant_ns,
        sync_writer_matched_ns: discovery.writer_matched_ns[sync],
        sync_reader_matched_ns: discovery.reader_matched_ns[sync],
        join_requests: status.join.requests,
        first_request_ns: status.join.first_request_ns,
        last_request_ns: status.join.last_request_ns,
        answer_received_ns: status.join.answer_received_ns,
        decoded_ns: status.join.decoded_ns,
        ready_ns: status.join.ready_ns,
        ready_seen_ns,
    };
    println!("{}", serde_json::to_string(&report)?);
    Ok(())
}

/// Figures of one fan-out run: one writer, `readers` reader processes.
#[derive(Debug, serde::Serialize, serde::Deserialize)]
struct FanoutFigures {
    readers: u32,
    /// The multicast setting asked for, and whether the writer's participant uses multicast.
    multicast_setting: String,
    multicast: bool,
    frames: u32,
    payload_bytes: usize,
    /// Fewest frames any reader received.
    delivered_min: u64,
    /// The transport's estimate for one copy of one frame.
    estimated_wire_bytes_per_frame: usize,
    /// Discovery of every reader, until each answered a probe.
    discovery: Option<LoopbackCounters>,
    /// From the first frame until every reader reported its count.
    steady: Option<LoopbackCounters>,
    /// Steady-state loopback tx bytes per frame sent, and that over the payload (≈ copies on the wire).
    bytes_per_frame: Option<f64>,
    copies_per_frame: Option<f64>,
    /// `bytes_per_frame` times the frame rate.
    megabytes_per_second: Option<f64>,
}

const PROBE: &[u8] = b"fanout-probe";
const READY: &[u8] = b"fanout-ready";
const DONE: &[u8] = b"fanout-done";

fn fanout(args: FanoutArgs) -> Result<()> {
    if args.rate <= 0.0 || args.frames == 0 || args.readers.is_empty() || args.readers.contains(&0) {
        bail!("--rate, --frames and every --readers count must be positive");
    }
    if args.payload < 8 {
        bail!("--payload must be at least 8 bytes (a sequence number)");
    }
    if args.readers.iter().any(|&n| n > 32) {
        bail!("--readers: at most 32 reader processes");
    }
    let (runs, counting) = if netns::inside().is_some() {
        (fanout_runs(&args, &Counting::Socket)?, Counting::Socket)
    } else if args.netns == NetnsMode::Off {
        let counting = Counting::EstimateOnly("--netns off".into());
        (fanout_runs(&args, &counting)?, counting)
    } else {
        match netns::probe(NetnsSetup { multicast: true }) {
            Ok(()) => (fanout_in_namespaces(&args)?, Counting::Socket),
            Err(error) if args.netns == NetnsMode::Require => {
                return Err(error).context("--netns require: cannot run in a fresh network namespace");
            }
            Err(error) => {
                eprintln!("note: no fresh network namespace ({error}); socket-level bytes not measured");
                let counting = Counting::EstimateOnly(error.to_string());
                (fanout_runs(&args, &counting)?, counting)
            }
        }
    };
    if args.json {
        let out = serde_json::json!({
            "payload": args.payload, "rate_hz": args.rate, "frames": args.frames,
            "netns": matches!(counting, Counting::Socket), "runs": runs,
        });
        println!("{out}");
        return Ok(());
    }
    for (index, run) in runs.iter().enumerate() {
        print_fanout_row(run, index == 0, args.rate, &counting);
    }
    match &counting {
        Counting::EstimateOnly(why) => println!("socket-level bytes not measured ({why})"),
        Counting::Socket => println!(
            "bytes: loopback tx (IPv4 + UDP + RTPS, acknowledgements, heartbeats) from the first frame until every \
             reader reported its count, per frame sent; copies = bytes per frame / payload; mcast = share of those \
             bytes sent to a multicast group. Each multicast setting ran in its own namespace (`lo` multicast-capable \
             unless `off`)."
        ),
    }
    Ok(())
}

/// Every run of `args` in this process.
fn fanout_runs(args: &FanoutArgs, counting: &Counting) -> Result<Vec<FanoutFigures>> {
    let mut runs = Vec::new();
    for &setting in &args.multicast {
        // Outside a namespace of our own, multicast on a host whose loopback cannot carry it would leave through
        // the other multicast-capable interfaces: not for a benchmark's traffic.
        if setting == MulticastArg::On
            && matches!(counting, Counting::EstimateOnly(_))
            && !transport::rtps::loopback_multicast_capable()
        {
            eprintln!("note: skipping --multicast on: this host's loopback is not multicast-capable");
            continue;
        }
        for &readers in &args.readers {
            runs.push(
                fanout_once(args, readers, setting, counting)
                    .with_context(|| format!("fan-out to {readers} readers, multicast {}", setting.name()))?,
            );
        }
    }
    Ok(runs)
}

/// Every run of `args`, one fresh network namespace per multicast setting (`lo` multicast-capable unless `off`,
/// as on a host whose loopback has no multicast), each a child process of this binary reporting JSON.
fn fanout_in_namespaces(args: &FanoutArgs) -> Result<Vec<FanoutFigures>> {
    let mut runs = Vec::new();
    for &setting in &args.multicast {
        let readers: Vec<String> = args.readers.iter().map(u32::to_string).collect();
        let child_args: Vec<std::ffi::OsString> = [
            "bench",
            "fanout",
            "--json",
            "--netns",
            "require",
            "--multicast",
            setting.name(),
            "--readers",
            &readers.join(","),
            "--payload",
            &args.payload.to_string(),
            "--rate",
            &args.rate.to_string(),
            "--frames",
            &args.frames.to_string(),
            "--domain",
            &args.domain.to_string(),
        ]
        .iter()
        .map(Into::into)
        .collect();
        let output =
            netns::this_executable_in_fresh_netns(NetnsSetup { multicast: setting != MulticastArg::Off }, &child_args)?
                .stdin(Stdio::null())
                .stderr(Stdio::inherit())
                .output()
                .context("starting the fan-out in a fresh network namespace")?;
        if !output.status.success() {
            bail!("the fan-out with multicast {} failed in its namespace ({})", setting.name(), output.status);
        }
        let report: serde_json::Value =
            serde_json::from_slice(&output.stdout).context("the fan-out's report from its namespace")?;
        let child_runs: Vec<FanoutFigures> =
            serde_json::from_value(report["runs"].clone()).context("the fan-out's runs from its namespace")?;
        runs.extend(child_runs);
    }
    Ok(runs)
}

fn print_fanout_row(run: &FanoutFigures, header: bool, rate: f64, counting: &Counting) {
    if header {
        let place = match counting {
            Counting::Socket => "in a fresh network namespace",
            Counting::EstimateOnly(_) => "on this host's loopback",
        };
        println!(
            "fan-out: one writer of {} B samples at {rate} Hz, {} samples, to N reader processes {place}",
            run.payload_bytes, run.frames
        );
        println!(
            "{:>9} {:>3} {:>10} {:>12} {:>14} {:>8} {:>7} {:>9} {:>12}",
            "multicast", "N", "delivered", "discovery B", "bytes/frame", "copies", "mcast", "MB/s", "est. B/frame"
        );
    }
    let fmt = |v: Option<f64>, digits: usize| v.map_or_else(|| "-".to_owned(), |v| format!("{v:.digits$}"));
    let mcast_share = run.steady.map(|s| s.tx_multicast_bytes as f64 / s.tx_bytes.max(1) as f64 * 100.0);
    println!(
        "{:>9} {:>3} {:>10} {:>12} {:>14} {:>8} {:>7} {:>9} {:>12}",
        format!("{}{}", run.multicast_setting, if run.multicast { "" } else { "*" }),
        run.readers,
        format!("{}/{}", run.delivered_min, run.frames),
        run.discovery.map_or_else(|| "-".to_owned(), |d| d.tx_bytes.to_string()),
        fmt(run.bytes_per_frame, 0),
        fmt(run.copies_per_frame, 2),
        mcast_share.map_or_else(|| "-".to_owned(), |v| format!("{v:.0}%")),
        fmt(run.megabytes_per_second, 2),
        run.estimated_wire_bytes_per_frame,
    );
}

fn fanout_once(args: &FanoutArgs, readers: u32, setting: MulticastArg, counting: &Counting) -> Result<FanoutFigures> {
    let prefix = format!("fanout{}m{}n{readers}", std::process::id(), setting.name());
    let start = counters(counting)?;
    let transport = rtps(args.domain, &prefix, setting)?;
    let mut helpers = Vec::new();
    for _ in 0..readers {
        helpers.push(Helper::spawn(&[
            "bench".into(),
            "fanout-reader".into(),
            "--domain".into(),
            args.domain.to_string(),
            "--prefix".into(),
            prefix.clone(),
            "--multicast".into(),
            setting.name().into(),
        ])?);
    }
    // Discovery: probe until every reader has answered one (its reader matched ours and ours matched its writer).
    let mut ready = std::collections::BTreeSet::new();
    let deadline = Instant::now() + Duration::from_secs(60);
    while ready.len() < readers as usize {
        if Instant::now() > deadline {
            bail!("{} of {readers} readers answered within 60 s", ready.len());
        }
        transport.publish(Channel::Calls, Bytes::from_static(PROBE))?;
        let until = Instant::now() + Duration::from_millis(100);
        while let Some(sample) = transport.recv_timeout(until.saturating_duration_since(Instant::now())) {
            if &sample.bytes[..] == READY {
                ready.insert(sample.origin);
            }
        }
    }
    // Every reader answered: the probes still in flight reach matched readers only; let them settle.
    while transport.recv_timeout(Duration::from_millis(300)).is_some() {}
    let discovered = counters(counting)?;
    let period = Duration::from_secs_f64(1.0 / args.rate);
    let mut next = Instant::now();
    for seq in 0..u64::from(args.frames) {
        transport.publish(Channel::Updates, payload_of(seq, args.payload))?;
        next += period;
        std::thread::sleep(next.saturating_duration_since(Instant::now()));
    }
    let mut done = Vec::with_capacity(DONE.len() + 8);
    done.extend_from_slice(DONE);
    done.extend_from_slice(&u64::from(args.frames).to_le_bytes());
    transport.publish(Channel::Calls, Bytes::from(done))?;
    let mut counts = std::collections::BTreeMap::new();
    let deadline = Instant::now() + Duration::from_secs(60);
    while counts.len() < readers as usize {
        if Instant::now() > deadline {
            bail!("{} of {readers} readers reported their counts within 60 s", counts.len());
        }
        if let Some(sample) = transport.recv_timeout(Duration::from_millis(100))
            && sample.channel == Channel::Calls
            && let Some(count) = sample.bytes.strip_prefix(DONE).and_then(seq_of)
        {
            counts.insert(sample.origin, count);
        }
    }
    let end = counters(counting)?;
    drop(helpers);
    let steady = growth(end, discovered);
    let bytes_per_frame = steady.map(|s| s.tx_bytes as f64 / f64::from(args.frames));
    Ok(FanoutFigures {
        readers,
        multicast_setting: setting.name().into(),
        multicast: transport.multicast(),
        frames: args.frames,
        payload_bytes: args.payload,
        delivered_min: counts.values().copied().min().unwrap_or(0),
        estimated_wire_bytes_per_frame: estimated_wire_bytes(args.payload, true),
        discovery: growth(discovered, start),
        steady,
        bytes_per_frame,
        copies_per_frame: bytes_per_frame.map(|b| b / args.payload as f64),
        megabytes_per_second: bytes_per_frame.map(|b| b * args.rate / 1e6),
    })
}

/// The fan-out reader: answers probes, counts frames, and reports the count when told the run is done and it has
/// them all (or 10 s later). Exits when the writer has been silent for 60 s.
fn fanout_reader(args: FanoutReaderArgs) -> Result<()> {
    let transport = rtps(args.domain, &args.prefix, args.multicast)?;
    let mut frames = 0u64;
    let mut expected: Option<(u64, Instant)> = None;
    let mut last_heard = Instant::now();
    loop {
        if let Some(sample) = transport.recv_timeout(Duration::from_millis(50)) {
            last_heard = Instant::now();
            match sample.channel {
                Channel::Updates => frames += 1,
                Channel::Calls if &sample.bytes[..] == PROBE => {
                    transport.publish(Channel::Calls, Bytes::from_static(READY))?;
                }
                Channel::Calls => {
                    if let Some(total) = sample.bytes.strip_prefix(DONE).and_then(seq_of) {
                        expected = Some((total, Instant::now()));
                    }
                }
                Channel::Sync => {}
            }
        } else if last_heard.elapsed() > Duration::from_secs(60) {
            return Ok(());
        }
        if let Some((total, since)) = expected
            && (frames >= total || since.elapsed() > Duration::from_secs(10))
        {
            let mut report = Vec::with_capacity(DONE.len() + 8);
            report.extend_from_slice(DONE);
            report.extend_from_slice(&frames.to_le_bytes());
            transport.publish(Channel::Calls, Bytes::from(report))?;
            expected = None;
        }
    }
}
