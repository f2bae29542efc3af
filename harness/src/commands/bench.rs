//! `cortex bench`: measurements of agents over RTPS on this host, as separate processes. `rtt` ping-pongs one
//! attribute between two agent processes and, in the same run, raw byte samples between two processes over the
//! same `rustdds` transport with no agent on top (the transport's limit); `join` times a new agent process
//! receiving and rebuilding a graph of N nodes. The helper processes are this binary's hidden `bench echo` and
//! `bench join-child` subcommands. Figures are measurements, never test assertions.

use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Stdio};
use std::sync::Arc;
use std::time::{Duration, Instant};

use agent::{Agent, AgentConfig, AgentId};
use anyhow::{Context, Result, bail};
use bytes::Bytes;
use clap::{Args, Subcommand};
use dsr::{Change, Element, NewNode, NodeId, Replica, Value, attrs};
use hdrhistogram::Histogram;
use transport::rtps::{RtpsConfig, RtpsTransport};
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
    /// Print one JSON object.
    #[arg(long)]
    pub json: bool,
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
    }
}

const WARMUP: u32 = 100;
const PING: &str = "bench_ping";
const PONG: &str = "bench_pong";

fn rtps(domain: u16, prefix: &str) -> Result<RtpsTransport> {
    RtpsTransport::new(RtpsConfig { domain_id: domain, topic_prefix: prefix.into(), ..RtpsConfig::default() })
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
}

fn figures(histogram: &Histogram<u64>, lost: u64, payload: u64, wire: u64, updates: u64) -> RttFigures {
    RttFigures {
        count: histogram.len(),
        lost,
        p50_us: histogram.value_at_quantile(0.5),
        p90_us: histogram.value_at_quantile(0.9),
        p99_us: histogram.value_at_quantile(0.99),
        max_us: histogram.max(),
        envelope_bytes_per_update: payload as f64 / updates.max(1) as f64,
        wire_bytes_per_update: wire as f64 / updates.max(1) as f64,
    }
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
    if args.rate <= 0.0 || args.count == 0 {
        bail!("--rate and --count must be positive");
    }
    let period = Duration::from_secs_f64(1.0 / args.rate);
    let raw = rtt_raw(&args, period).context("raw rustdds ping-pong")?;
    let agent = rtt_agent(&args, period).context("agent ping-pong")?;
    let ratio = agent.p50_us as f64 / raw.p50_us.max(1) as f64;
    if args.json {
        let out = serde_json::json!({
            "payload": args.payload, "rate_hz": args.rate, "count": args.count,
            "agent": agent, "raw_rustdds": raw, "p50_ratio": ratio,
        });
        println!("{out}");
    } else {
        println!("RTT, {} B payload, {} Hz, {} pings, two processes on loopback", args.payload, args.rate, args.count);
        println!(
            "{:<12} {:>8} {:>8} {:>8} {:>8} {:>6} {:>14} {:>14}",
            "", "p50 us", "p90 us", "p99 us", "max us", "lost", "envelope B/upd", "wire B/upd"
        );
        for (name, f) in [("agent", &agent), ("raw rustdds", &raw)] {
            println!(
                "{name:<12} {:>8} {:>8} {:>8} {:>8} {:>6} {:>14.1} {:>14.1}",
                f.p50_us, f.p90_us, f.p99_us, f.max_us, f.lost, f.envelope_bytes_per_update, f.wire_bytes_per_update
            );
        }
        println!("agent p50 / raw p50 = {ratio:.2}");
    }
    Ok(())
}

fn rtt_raw(args: &RttArgs, period: Duration) -> Result<RttFigures> {
    let prefix = format!("rawrtt{}", std::process::id());
    let transport = rtps(args.domain, &prefix)?;
    let _helper = Helper::spawn(&[
        "bench".into(),
        "echo".into(),
        "--domain".into(),
        args.domain.to_string(),
        "--prefix".into(),
        prefix,
        "--raw".into(),
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
    let mut histogram = Histogram::<u64>::new(3)?;
    let mut lost = 0;
    let before = transport.stats();
    let mut next = Instant::now();
    for seq in 0..u64::from(WARMUP + args.count) {
        let sent = Instant::now();
        transport.publish(Channel::Updates, payload_of(seq, args.payload))?;
        let reply_deadline = sent + Duration::from_secs(1);
        let mut got = false;
        while let Some(sample) = transport.recv_timeout(reply_deadline.saturating_duration_since(Instant::now())) {
            if seq_of(&sample.bytes) == Some(seq) {
                got = true;
                break;
            }
        }
        if seq >= u64::from(WARMUP) {
            if got {
                histogram.record(sent.elapsed().as_micros() as u64)?;
            } else {
                lost += 1;
            }
        }
        next += period;
        std::thread::sleep(next.saturating_duration_since(Instant::now()));
    }
    let after = transport.stats();
    let updates = u64::from(WARMUP + args.count);
    Ok(figures(
        &histogram,
        lost,
        after.payload_bytes_sent - before.payload_bytes_sent,
        after.wire_bytes_sent - before.wire_bytes_sent,
        updates,
    ))
}

fn bench_config(id: u32, join_wait: Duration) -> AgentConfig {
    let mut config = AgentConfig::new(AgentId(id));
    config.join_wait = join_wait;
    config
}

fn rtt_agent(args: &RttArgs, period: Duration) -> Result<RttFigures> {
    let prefix = format!("agentrtt{}", std::process::id());
    let agent =
        Agent::start(bench_config(1, Duration::from_millis(300)), rtps(args.domain, &prefix)?, Arc::new(SystemClock))?;
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
    let mut histogram = Histogram::<u64>::new(3)?;
    let mut lost = 0;
    let before = agent.status().transport;
    let mut next = Instant::now();
    for seq in 0..u64::from(WARMUP + args.count) {
        let sent = Instant::now();
        agent.set_attr(ping, attrs::CAM_RGB, payload_of(seq, args.payload))?;
        let reply_deadline = sent + Duration::from_secs(1);
        let mut got = false;
        while let Ok(signal) = signals.recv_deadline(reply_deadline) {
            if is_pong(&signal.change, pong) && agent.attr(pong, attrs::CAM_RGB).and_then(|b| seq_of(&b)) == Some(seq) {
                got = true;
                break;
            }
        }
        if seq >= u64::from(WARMUP) {
            if got {
                histogram.record(sent.elapsed().as_micros() as u64)?;
            } else {
                lost += 1;
            }
        }
        next += period;
        std::thread::sleep(next.saturating_duration_since(Instant::now()));
    }
    let after = agent.status().transport;
    let updates = u64::from(WARMUP + args.count);
    Ok(figures(
        &histogram,
        lost,
        after.payload_bytes_sent - before.payload_bytes_sent,
        after.wire_bytes_sent - before.wire_bytes_sent,
        updates,
    ))
}

fn is_pong(change: &Change, pong: NodeId) -> bool {
    matches!(change, Change::AttrUpdated { element: Element::Node(id), name } if *id == pong && name.as_str() == "cam_rgb")
}

fn echo(args: EchoArgs) -> Result<()> {
    let transport = rtps(args.domain, &args.prefix)?;
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
    let agent =
        Agent::start(bench_config(1, Duration::from_millis(300)), rtps(args.domain, &prefix)?, Arc::new(SystemClock))?;
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
    let transport = rtps(args.domain, &args.prefix)?;
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
