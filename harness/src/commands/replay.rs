//! `cortex replay`: replay a robot log into the graph through a bridge agent and check that every agent ends with the
//! same graph.
//!
//! The log — an MCAP file (ROS 2 `cdr` or ROS 1 `ros1` messages), a ROS 1 bag (v2.0) or a rosbag2 directory (sqlite3
//! or MCAP storage), detected from its content — is read with `replay::log` (damage is an error that says where, or,
//! with `--recover`, the end of what is replayed); messages of types the bridge has no decoder for are decoded from
//! the definitions the log carries (`--opaque` carries them as raw bytes instead); messages are paced at the recorded timing divided by `--rate` (or as
//! fast as possible with `--rate max`) and looped `--loop` times; the bridge writes them into its replica and its
//! deltas go to the other agents. With `--transport inproc` the agents are replicas in this process joined by the
//! seeded in-memory delivery of `replay::inproc`. With `--transport rtps` the bridge is an agent in this process
//! and the others are `cortex agent` processes on the DDS engine, plain or running the BICA roles given with
//! `--roles` (see [`super::replay_rtps`]). The summary gives messages by type, unknown and skipped ones, bytes,
//! deltas, throughput and whether the final digests are equal (exit code 1 if they are not); over RTPS also each
//! agent's graph and the time from the end of the replay until every agent had the bridge's digest.
//!
//! With `--out DIR` an in-process run is also recorded as `DIR/run.mcap` (`measure::record`), for Foxglove: every
//! delta the bridge published (its encoded bytes, at its publication time on the run's clock), the latency of each
//! delta at each in-process receiver, each delta's convergence window, published bytes per 100 ms and the run's
//! summary.

use std::cell::Cell;
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{Context as _, anyhow, bail};
use clap::{Args, ValueEnum};
use dsr::{Replica, ReplicaId};
use measure::record::{self, RecordingSink, RunRecorder, RunSummary};
use measure::{MonoClock, PayloadClass, Percentiles, Provenance};
use replay::inproc::{self, InProcNetwork};
use replay::log::{Log, ReadOptions};
use replay::{Bridge, BridgeOptions, BridgeStats, Pacer, Rate};
use serde::{Deserialize, Serialize};
use transport::fault::FaultConfig;

/// How the agents are connected.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Transport {
    /// Replicas in this process, seeded in-memory delivery.
    Inproc,
    /// The bridge agent in this process, the other agents as `cortex agent` processes over RTPS.
    Rtps,
}

/// Arguments of `cortex replay`. Options not given come from `--config FILE.toml` if it sets them, else from the
/// defaults shown.
#[derive(Debug, Args)]
pub struct ReplayArgs {
    /// A log: an MCAP file (`cdr` or `ros1` messages), a ROS 1 bag (v2.0) or a rosbag2 directory (sqlite3 or mcap
    /// storage), detected from its content; may come from `--config` instead.
    file: Option<PathBuf>,
    /// A replay configuration (TOML): any of `log`, `agents`, `transport`, `rate`, `loops`, `topics`, `roles`,
    /// `faults`, `seed`, `window`, `domain`, `settle_ms`; relative paths against the parent of the file's
    /// directory (the repository root for files in `experiments/`). Command-line options win.
    #[arg(long)]
    config: Option<PathBuf>,
    /// Number of agents, the bridge included (1 to 64) [default: 3].
    #[arg(long)]
    agents: Option<u32>,
    /// How the agents are connected [default: inproc].
    #[arg(long, value_enum)]
    transport: Option<Transport>,
    /// Speed: a factor on the recorded timing (2 plays twice as fast) or `max` [default: 1].
    #[arg(long)]
    rate: Option<Rate>,
    /// Play the log this many times [default: 1].
    #[arg(long = "loop")]
    loops: Option<u32>,
    /// Only these topics (comma-separated).
    #[arg(long, value_delimiter = ',')]
    topics: Option<Vec<String>>,
    /// Replay what is readable before damage in the file instead of failing.
    #[arg(long)]
    recover: bool,
    /// Carry messages of types the bridge has no decoder for as opaque byte attributes, instead of decoding them
    /// from the definitions the log carries (or skipping them when it carries none).
    #[arg(long)]
    opaque: bool,
    /// Seed of the in-process delivery order [default: 1].
    #[arg(long)]
    seed: Option<u64>,
    /// Deltas in flight in the in-process delivery before one is delivered (reordering depth) [default: 64].
    #[arg(long)]
    window: Option<usize>,
    /// DDS domain id (`--transport rtps`) [default: 0].
    #[arg(long)]
    domain: Option<u16>,
    /// BICA roles of agents 2, 3, ... (`--transport rtps`), comma-separated, each `ROLE[:NODE]`: e.g.
    /// `camera-detector:cam0,laser-detector:scan`. The other agents are plain.
    #[arg(long, value_delimiter = ',')]
    roles: Option<Vec<super::replay_rtps::RoleSpec>>,
    /// Faults injected into what every agent process receives (`--transport rtps`; the agents' anti-entropy
    /// repairs them), e.g. `loss=0.1,duplicate=0.05,reorder=0.2,reorder-ms=10,delay-ms=0-2`.
    #[arg(long)]
    faults: Option<FaultConfig>,
    /// How long to wait for the agent processes to be ready, and after the replay for equal digests (ms)
    /// [default: 30000].
    #[arg(long)]
    settle_ms: Option<u64>,
    /// Print stable, machine-readable JSON instead of text.
    #[arg(long)]
    json: bool,
    /// Also record the run as `DIR/run.mcap` (created): the deltas as published, per-delta latencies and
    /// convergence windows, bandwidth and the summary, for Foxglove.
    #[arg(long, value_name = "DIR")]
    out: Option<PathBuf>,
}

/// A replay configuration file (`--config`): every field optional, unknown fields refused.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct ReplayFile {
    log: Option<PathBuf>,
    agents: Option<u32>,
    transport: Option<String>,
    rate: Option<String>,
    loops: Option<u32>,
    topics: Option<Vec<String>>,
    roles: Option<Vec<String>>,
    faults: Option<String>,
    seed: Option<u64>,
    window: Option<usize>,
    domain: Option<u16>,
    settle_ms: Option<u64>,
}

/// The replay as it runs: the command line over the configuration file over the defaults.
#[derive(Debug)]
struct Resolved {
    file: PathBuf,
    agents: u32,
    transport: Transport,
    rate: Rate,
    loops: u32,
    topics: Option<Vec<String>>,
    recover: bool,
    opaque: bool,
    seed: u64,
    window: usize,
    domain: u16,
    roles: Vec<super::replay_rtps::RoleSpec>,
    faults: Option<FaultConfig>,
    settle_ms: u64,
    json: bool,
    out: Option<PathBuf>,
}

/// Reads `--config` (if any) and merges it under the command line.
fn resolve(args: ReplayArgs) -> anyhow::Result<Resolved> {
    let (file, root) = match &args.config {
        Some(path) => {
            let text = std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
            let file: ReplayFile = toml::from_str(&text)
                .with_context(|| format!("{} is not a valid replay configuration", path.display()))?;
            (file, measure::experiment::ExperimentFile::root_of(path))
        }
        None => (ReplayFile::default(), PathBuf::from(".")),
    };
    let at = |field: &str| format!("{} field `{field}`", args.config.as_deref().unwrap_or(Path::new("")).display());
    let transport = match (args.transport, file.transport.as_deref()) {
        (Some(t), _) => t,
        (None, Some(name)) => Transport::from_str(name, true)
            .map_err(|_| anyhow!("{}: {name:?} is not inproc or rtps", at("transport")))?,
        (None, None) => Transport::Inproc,
    };
    let rate = match (args.rate, file.rate) {
        (Some(rate), _) => rate,
        (None, Some(text)) => text.parse().map_err(|e| anyhow!("{}: {e}", at("rate")))?,
        (None, None) => Rate::Factor(1.0),
    };
    let roles = match (args.roles, file.roles) {
        (Some(roles), _) => roles,
        (None, Some(names)) => names
            .iter()
            .map(|name| name.parse().map_err(|e: String| anyhow!("{}: {e}", at("roles"))))
            .collect::<anyhow::Result<_>>()?,
        (None, None) => Vec::new(),
    };
    let faults = match (args.faults, file.faults) {
        (Some(faults), _) => Some(faults),
        (None, Some(text)) => Some(text.parse().map_err(|e| anyhow!("{}: {e}", at("faults")))?),
        (None, None) => None,
    };
    let log = match (args.file, file.log) {
        (Some(path), _) => path,
        (None, Some(path)) => root.join(path),
        (None, None) => {
            bail!("no log to replay: give a log (FILE.mcap, FILE.bag, a rosbag2 directory), or `log` in --config")
        }
    };
    Ok(Resolved {
        file: log,
        agents: args.agents.or(file.agents).unwrap_or(3),
        transport,
        rate,
        loops: args.loops.or(file.loops).unwrap_or(1),
        topics: args.topics.or(file.topics),
        recover: args.recover,
        opaque: args.opaque,
        seed: args.seed.or(file.seed).unwrap_or(1),
        window: args.window.or(file.window).unwrap_or(64),
        domain: args.domain.or(file.domain).unwrap_or(0),
        roles,
        // `none` on the command line turns off the file's faults.
        faults: faults.filter(|f| *f != FaultConfig::default()),
        settle_ms: args.settle_ms.or(file.settle_ms).unwrap_or(30_000),
        json: args.json,
        out: args.out,
    })
}

/// What a replay did.
#[derive(Debug, Serialize)]
struct Summary {
    file: String,
    /// The log's container (`mcap`, `ros1 bag`, `rosbag2 sqlite3`, `rosbag2 mcap`).
    container: &'static str,
    transport: &'static str,
    agents: u32,
    rate: String,
    loops: u32,
    file_bytes: u64,
    damage: Option<String>,
    unread_bytes: u64,
    messages: u64,
    payload_bytes: u64,
    /// Seconds spent reading the log (mapping, decompressing, indexing, sorting) before the replay.
    read_seconds: f64,
    /// Payload MB per second of reading and replaying together.
    read_megabytes_per_second: f64,
    seconds: f64,
    messages_per_second: f64,
    megabytes_per_second: f64,
    bridge: BridgeStats,
    deltas: u64,
    delta_bytes: u64,
    deliveries: u64,
    digests: Vec<String>,
    digests_equal: bool,
    /// Faults injected into what the agent processes receive (`--faults`), as a specification.
    #[serde(skip_serializing_if = "Option::is_none")]
    faults: Option<String>,
    /// Over RTPS: each agent's graph at the end, the bridge first.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    agent_reports: Vec<measure::roles::AgentRow>,
    /// Over RTPS: milliseconds from the quiesce (every writer stopped) until every agent had the bridge's digest.
    #[serde(skip_serializing_if = "Option::is_none")]
    converged_ms: Option<f64>,
    /// Over RTPS: milliseconds from the end of the replay to the quiesce (the roles' statistics fetched meanwhile).
    #[serde(skip_serializing_if = "Option::is_none")]
    quiesced_after_ms: Option<f64>,
    /// What `--out` recorded (in-process runs).
    recording: Option<Recording>,
}

/// What `--out` recorded.
#[derive(Debug, Serialize)]
struct Recording {
    path: String,
    messages: BTreeMap<&'static str, u64>,
    /// Latencies at the in-process receivers (not recorded over RTPS).
    #[serde(skip_serializing_if = "Option::is_none")]
    latency: Option<Percentiles>,
    /// Convergence windows (not recorded over RTPS).
    #[serde(skip_serializing_if = "Option::is_none")]
    convergence: Option<Percentiles>,
}

/// Runs `cortex replay`.
///
/// # Errors
/// A file that cannot be read (or is damaged, without `--recover`), bad arguments, the RTPS transport, a delta a
/// receiver refuses, or final digests that differ.
pub fn run(args: ReplayArgs) -> anyhow::Result<()> {
    let args = resolve(args)?;
    if !(1..=64).contains(&args.agents) {
        bail!("--agents must be between 1 and 64, not {}", args.agents);
    }
    if args.transport == Transport::Inproc && !args.roles.is_empty() {
        bail!("--roles needs --transport rtps (the roles run in agent processes)");
    }
    if args.transport == Transport::Inproc && args.faults.is_some() {
        bail!(
            "--faults needs --transport rtps: the in-process replay has no anti-entropy to repair them (its delivery \
             already reorders with --window); the agent processes of an RTPS replay do"
        );
    }
    let options = ReadOptions { recover: args.recover, ..ReadOptions::default() };
    let reading = Instant::now();
    let log = Log::open(&args.file, options).context("cannot replay")?;
    let read_seconds = reading.elapsed().as_secs_f64();
    if let Some(damage) = &log.damage {
        eprintln!(
            "warning: {}: {damage}; replaying the {} messages read before it ({} bytes unread)",
            log.file,
            log.messages.len(),
            log.unread_bytes
        );
    }
    if args.transport == Transport::Rtps {
        return run_rtps(&args, &log, read_seconds);
    }
    let dictionary = replay::bridge::dictionary().context("bridge dictionary")?;
    let mut replica = Replica::with_dictionary(ReplicaId(1), dictionary.clone());
    let mut network = InProcNetwork::new(args.agents - 1, 2, &dictionary, args.seed, args.window);
    let mut bridge = Bridge::new(BridgeOptions { topics: args.topics.clone(), opaque: args.opaque });
    let clock = MonoClock::start();
    let pacer = Pacer::new(&log.messages, args.rate, args.loops, move || clock.now_ns());
    // The recording labels each delta with the payload class of the message it came from, set here as the message
    // is taken from the pacer, just before the bridge ingests it and publishes its deltas.
    let class = Cell::new(PayloadClass::Small);
    let paced = pacer.inspect(|item| class.set(PayloadClass::of_schema(item.message.channel.type_name())));
    let wait = |due_ns: u64| clock.sleep_until(due_ns);
    let started = Instant::now();
    let (driven, live) = match &args.out {
        None => (inproc::drive(paced, &mut bridge, &mut replica, &mut network, wait).context("replay")?, None),
        Some(dir) => {
            std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
            let path = dir.join("run.mcap");
            let mut provenance = Provenance::current();
            provenance.seeds.insert("delivery".to_owned(), args.seed);
            let mut metadata = record::provenance_metadata(&provenance);
            metadata.insert("run".to_owned(), format!("cortex replay {}", args.file.display()));
            metadata.insert("agents".to_owned(), args.agents.to_string());
            metadata.insert("delivery".to_owned(), format!("in process, seed {}, window {}", args.seed, args.window));
            metadata.insert("loops".to_owned(), args.loops.to_string());
            let recorder = RunRecorder::create(&path, metadata)?;
            let mut sink = RecordingSink::new(&mut network, recorder, BRIDGE_DICTIONARY, clock, &class)?;
            let driven = inproc::drive(paced, &mut bridge, &mut replica, &mut sink, wait).context("replay")?;
            (driven, Some((path, sink.finish())))
        }
    };
    let seconds = started.elapsed().as_secs_f64();
    let (digests, digests_equal) = inproc::digests(&replica, &network);
    let stats = network.stats();
    let digest_strings: Vec<String> = digests.iter().map(ToString::to_string).collect();
    let recording = match live {
        None => None,
        Some((path, (mut recorder, live))) => {
            let latency = live.latency.overall();
            let convergence = Percentiles::of(&live.convergence);
            let summary = RunSummary {
                run: args.file.file_name().map_or_else(|| log.file.clone(), |n| n.to_string_lossy().into_owned()),
                transport: "inproc".to_owned(),
                agents: args.agents,
                seed: args.seed,
                writes: live.writes,
                published_bytes: live.published_bytes,
                latency,
                latency_by_class: live.latency.by_class().into_iter().map(|(c, p)| (c.name().to_owned(), p)).collect(),
                convergence,
                writes_not_everywhere: live.writes_not_everywhere,
                end_convergence_ns: digests_equal.then(|| live.last_apply_ns.saturating_sub(live.last_publish_ns)),
                digests_equal,
                digests: digest_strings.clone(),
                writes_recorded: live.writes,
            };
            recorder.summary(clock.now_ns(), &summary)?;
            let messages = record::finish_file(recorder).with_context(|| format!("cannot write {}", path.display()))?;
            Some(Recording {
                path: path.display().to_string(),
                messages,
                latency: Some(latency),
                convergence: Some(convergence),
            })
        }
    };
    let summary = Summary {
        delta_bytes: stats.encoded_bytes,
        deliveries: stats.deliveries,
        digests: digest_strings,
        digests_equal,
        recording,
        ..summary(&args, &log, "inproc", &driven, [read_seconds, seconds], bridge.stats().clone())
    };
    finish(&args, &summary)
}

/// The part of a summary both transports fill alike; what differs (bytes, deliveries, digests, agents,
/// recording) is set by the caller. `[read_seconds, seconds]`: reading the log, and replaying it.
fn summary(
    args: &Resolved,
    log: &Log,
    transport: &'static str,
    drive: &inproc::DriveStats,
    [read_seconds, seconds]: [f64; 2],
    bridge: BridgeStats,
) -> Summary {
    Summary {
        file: args.file.display().to_string(),
        container: log.container.name(),
        transport,
        agents: args.agents,
        rate: rate_text(args.rate),
        loops: args.loops,
        file_bytes: log.file_bytes,
        damage: log.damage.as_ref().map(ToString::to_string),
        unread_bytes: log.unread_bytes,
        messages: drive.messages,
        payload_bytes: drive.bytes,
        read_seconds,
        read_megabytes_per_second: drive.bytes as f64 / 1e6 / (read_seconds + seconds).max(1e-9),
        seconds,
        messages_per_second: drive.messages as f64 / seconds.max(1e-9),
        megabytes_per_second: drive.bytes as f64 / 1e6 / seconds.max(1e-9),
        bridge,
        deltas: drive.deltas,
        delta_bytes: 0,
        deliveries: 0,
        digests: Vec::new(),
        digests_equal: false,
        faults: None,
        agent_reports: Vec::new(),
        converged_ms: None,
        quiesced_after_ms: None,
        recording: None,
    }
}

fn rate_text(rate: Rate) -> String {
    match rate {
        Rate::Max => "max".to_owned(),
        Rate::Factor(factor) => factor.to_string(),
    }
}

/// Prints the summary; an error if the digests differ.
fn finish(args: &Resolved, summary: &Summary) -> anyhow::Result<()> {
    if args.json {
        println!("{}", serde_json::to_string_pretty(summary)?);
    } else {
        print!("{}", text(summary));
    }
    if !summary.digests_equal {
        bail!("the agents' final digests differ: {}", summary.digests.join(" "));
    }
    Ok(())
}

fn run_rtps(args: &Resolved, log: &Log, read_seconds: f64) -> anyhow::Result<()> {
    let config = super::replay_rtps::RtpsReplay {
        agents: args.agents,
        domain: args.domain,
        roles: args.roles.clone(),
        faults: args.faults,
        settle: Duration::from_millis(args.settle_ms),
        record: match &args.out {
            Some(dir) => {
                std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
                Some(dir.join("run.mcap"))
            }
            None => None,
        },
    };
    let options = BridgeOptions { topics: args.topics.clone(), opaque: args.opaque };
    let outcome = super::replay_rtps::replay(log, options, args.rate, args.loops, &config)?;
    let summary = Summary {
        delta_bytes: outcome.bridge_bytes,
        deliveries: outcome.agents.iter().skip(1).map(|a| a.samples_received).sum(),
        digests: outcome.agents.iter().map(|a| a.digest.clone()).collect(),
        digests_equal: outcome.digests_equal,
        faults: args.faults.map(|f| f.to_spec()),
        agent_reports: outcome.agents.clone(),
        converged_ms: outcome.converged_ms,
        quiesced_after_ms: Some(outcome.quiesced_after_ms),
        recording: outcome.recorded.map(|(path, messages)| Recording {
            path: path.display().to_string(),
            messages,
            latency: None,
            convergence: None,
        }),
        ..summary(
            args,
            log,
            "rtps",
            &outcome.played.drive,
            [read_seconds, outcome.seconds],
            outcome.played.bridge.clone(),
        )
    };
    finish(args, &summary)
}

fn text(s: &Summary) -> String {
    let mut out = String::new();
    let _ = writeln!(
        out,
        "replay {} ({}, {} bytes) over {} with {} agents, rate {}, {} loop(s)",
        s.file, s.container, s.file_bytes, s.transport, s.agents, s.rate, s.loops
    );
    if let Some(faults) = &s.faults {
        let _ = writeln!(out, "  faults        {faults} (on what each agent process receives)");
    }
    if let Some(damage) = &s.damage {
        let _ = writeln!(out, "  damage        {damage} ({} bytes unread)", s.unread_bytes);
    }
    let _ = writeln!(
        out,
        "  messages      {} in {:.3} s: {:.0} messages/s, {:.1} MB/s of payload ({} bytes)",
        s.messages, s.seconds, s.messages_per_second, s.megabytes_per_second, s.payload_bytes
    );
    let _ = writeln!(
        out,
        "  read          in {:.3} s before the replay: {:.1} MB/s of payload read and replayed",
        s.read_seconds, s.read_megabytes_per_second
    );
    let table = |out: &mut String, title: &str, rows: &BTreeMap<String, u64>| {
        for (name, count) in rows {
            let _ = writeln!(out, "  {title:<13} {count:>8}  {name}");
        }
    };
    table(&mut out, "decoded", &s.bridge.decoded);
    table(&mut out, "described", &s.bridge.described);
    table(&mut out, "unknown", &s.bridge.unknown);
    let b = &s.bridge;
    let _ = writeln!(
        out,
        "  carried       {} opaque, {} filtered out, {} TF transforms refused",
        b.opaque, b.filtered, b.tf_refused
    );
    table(&mut out, "errors", &b.errors);
    for error in &b.first_errors {
        let _ = writeln!(out, "    {error}");
    }
    let _ = if s.transport == "rtps" {
        // Over RTPS the bridge agent's counters: its deltas, and its announces and re-sends meanwhile.
        writeln!(
            out,
            "  deltas        {} ({} bytes the bridge agent published during the replay), {} samples received by the others",
            s.deltas, s.delta_bytes, s.deliveries
        )
    } else {
        writeln!(out, "  deltas        {} ({} bytes encoded), {} deliveries", s.deltas, s.delta_bytes, s.deliveries)
    };
    for a in &s.agent_reports {
        let _ = writeln!(
            out,
            "  agent {:<3}     {:<15} {:>6} nodes  digest {}  {} samples received, {} sent",
            a.id, a.role, a.nodes, a.digest, a.samples_received, a.samples_sent
        );
        for c in &a.components {
            let _ = writeln!(
                out,
                "      {:>6.1} of {:>6.1} Hz {:>6} runs {:>5} misses {:>5} skipped  lateness p99 {:>7.2} ms  step p99 \
                 {:>6.2} ms  {}",
                c.achieved_hz,
                c.nominal_hz,
                c.runs,
                c.misses,
                c.skipped_releases,
                c.lateness_p99_ms,
                c.wall_p99_ms,
                c.name
            );
        }
        if let Some(error) = &a.components_error {
            let _ = writeln!(out, "      BICA statistics unavailable: {error}");
        }
    }
    if let Some(ms) = s.converged_ms {
        let _ = writeln!(
            out,
            "  converged     every agent had the bridge's digest {ms:.1} ms after the writers stopped (status every \
             100 ms; the roles were quiesced {:.1} ms after the replay ended, their statistics fetched meanwhile)",
            s.quiesced_after_ms.unwrap_or(0.0)
        );
    }
    let verdict = if s.digests_equal { "equal" } else { "DIFFER" };
    let _ = writeln!(out, "  digests       {verdict}: {}", s.digests.join(" "));
    if let Some(r) = &s.recording {
        let count = |topic: &str| r.messages.get(topic).copied().unwrap_or(0);
        match r.latency {
            Some(latency) => {
                let _ = writeln!(
                    out,
                    "  recorded      {}: {} deltas, {} latencies (p50 {:.3} ms, p99 {:.3} ms), {} convergence windows",
                    r.path,
                    count(record::DELTA_TOPIC),
                    count(record::Metric::Latency.topic()),
                    latency.p50_ns as f64 / 1e6,
                    latency.p99_ns as f64 / 1e6,
                    count(record::Metric::Convergence.topic())
                );
            }
            None => {
                let _ = writeln!(
                    out,
                    "  recorded      {}: {} deltas as the bridge published them, {} bandwidth windows",
                    r.path,
                    count(record::DELTA_TOPIC),
                    count(record::Metric::Bandwidth.topic())
                );
            }
        }
    }
    out
}

/// How a replica gets the dictionary the recorded deltas need.
const BRIDGE_DICTIONARY: &str = "replay::bridge::dictionary()";
