//! `cortex replay`: replay a robot log into the graph through a bridge agent and check that every agent ends with the
//! same graph.
//!
//! The log — an MCAP file (ROS 2 `cdr` or ROS 1 `ros1` messages), a ROS 1 bag (v2.0) or a rosbag2 directory (sqlite3
//! or MCAP storage), detected from its content — is read with `replay::log` (damage is an error that says where, or,
//! with `--recover`, the end of what is replayed); messages of types the bridge has no decoder for are decoded from
//! the definitions the log carries (`--opaque` carries them as raw bytes instead); messages are paced at the
//! recorded timing divided by `--rate` (or as fast as possible with `--rate max`) and looped `--loop` times; the
//! bridge writes them into its replica and its deltas go to the other agents. With `--transport inproc` the agents
//! are replicas in this process joined by the seeded in-memory delivery of `replay::inproc`. With `--transport
//! rtps` the bridge is an agent in this process and the others are `cortex agent` processes on the DDS engine,
//! plain or running the BICA roles given with `--roles` (the runner [`measure::replay_rtps`]). The summary gives
//! messages by type, unknown and skipped ones, bytes, deltas, throughput and whether the final digests are equal
//! (exit code 1 if they are not); over RTPS also each agent's graph, the roles' BICA statistics and the time from
//! the quiesce (every writer stopped) until every agent had the bridge's digest.
//!
//! With `--out DIR` an in-process run is also recorded as `DIR/run.mcap` (`measure::record`), for Foxglove: every
//! delta the bridge published (its encoded bytes, at its publication time on the run's clock), the latency of each
//! delta at each in-process receiver, each delta's convergence window, published bytes per 100 ms and the run's
//! summary (over RTPS: the deltas the bridge published and the bytes per 100 ms).
//!
//! The arguments are resolved in `config`, the two transports run in `inproc` and `rtps`, and `summary` prints
//! what either did.

mod config;
mod inproc;
mod rtps;
mod summary;

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context as _, bail};
use clap::{Args, ValueEnum};
use measure::replay_rtps::RoleSpec;
use replay::Rate;
use replay::log::{Log, ReadOptions};
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
    roles: Option<Vec<RoleSpec>>,
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

/// Runs `cortex replay`.
///
/// # Errors
/// A file that cannot be read (or is damaged, without `--recover`), bad arguments, the RTPS transport, a delta a
/// receiver refuses, or final digests that differ.
pub fn run(args: ReplayArgs) -> anyhow::Result<()> {
    let args = config::resolve(args)?;
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
    match args.transport {
        Transport::Rtps => rtps::run(&args, &log, read_seconds),
        Transport::Inproc => inproc::run(&args, &log, read_seconds),
    }
}
