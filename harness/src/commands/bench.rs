//! `cortex bench`: measurements of agents over RTPS on this host, as separate processes. `rtt` ping-pongs one
//! attribute between two agent processes and, in the same run, raw byte samples between two processes over the
//! same `rustdds` transport with no agent on top (the transport's limit); `join` times a new agent process
//! receiving and rebuilding a graph of N nodes; `fanout` (hidden, for issues 5 and 7) sends large samples from one
//! writer to N reader processes and counts the bytes on the wire against N, with multicast on and off; `payload`
//! (`bench/payload.rs`) sends payloads of several sizes from one writer to N receiver processes by every path —
//! agents over each transport, raw iceoryx2, memcpy — in one run (issue 20). The helper processes are this binary's
//! hidden `bench echo`, `bench join-child`, `bench fanout-reader` and `bench payload-receiver` subcommands.
//!
//! The measurements are `measure::bench` functions that return their figures; this command parses arguments,
//! decides where the measurement runs, and prints. `rtt` and `fanout` re-run themselves in a fresh network
//! namespace when they can (`--netns auto`, the default: root, `unshare` and `ip` present), so the namespace's
//! loopback counters count exactly their traffic — IP, UDP and RTPS, acknowledgements, heartbeats and discovery —
//! read at phase boundaries (discovery, then steady state). Otherwise they print the transport's estimate only and
//! say why. Figures are measurements, never test assertions.

mod payload;
mod print;

use std::path::PathBuf;
use std::process::Stdio;

use anyhow::{Context, Result, bail};
use clap::{Args, Subcommand, ValueEnum};
use measure::bench::fanout::{FanoutConfig, FanoutResult};
use measure::bench::rtt::RttConfig;
use measure::bench::{Counting, fanout, join, rtt};
use measure::netns::{self, NetnsSetup};
use measure::spec::ScalingExperiment;
use transport::rtps::Multicast;

use super::agent::UpdatesArg;

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
    /// Anti-entropy and data traffic against the number of agents, in the seeded simulator (no network).
    Scaling(ScalingArgs),
    /// Payloads of 16 B to 4 MiB from one writer to N receiver processes by every path (agents over RTPS, agents
    /// over shared memory, raw iceoryx2, memcpy) in one run: one-way latency, CPU per receiver, loopback bytes, and
    /// each agent figure over raw iceoryx2's.
    Payload(payload::PayloadArgs),
    /// Helper process: one receiver of `bench payload`.
    #[command(hide = true)]
    PayloadReceiver(payload::PayloadReceiverArgs),
}

/// Arguments of `cortex bench scaling`.
#[derive(Debug, Args)]
pub struct ScalingArgs {
    /// Numbers of agents, one run each.
    #[arg(long, value_delimiter = ',', default_values_t = [8, 32, 128])]
    pub agents: Vec<u32>,
    /// Agents that write.
    #[arg(long, default_value_t = 4)]
    pub writers: u32,
    /// Writes per second, all writers together.
    #[arg(long, default_value_t = 100.0)]
    pub rate: f64,
    /// Measured window, ms of simulated time.
    #[arg(long, default_value_t = 10_000)]
    pub window_ms: u64,
    /// Base announce period, ms.
    #[arg(long, default_value_t = 500)]
    pub announce_ms: u64,
    /// Agents whose announces fit in one period (0: every agent announces every period).
    #[arg(long, value_delimiter = ',', default_values_t = [agent::config::DEFAULT_ANNOUNCE_GROUP])]
    pub announce_group: Vec<u32>,
    /// Seed of the agents' nonces and the written values.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Print the result as one JSON object.
    #[arg(long)]
    pub json: bool,
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
    /// `auto`, `on` or `off`.
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
    /// Also through agents protected by DDS Security (a fresh test PKI, submessages encrypted with AES-GCM),
    /// beside the unprotected ones in the same run.
    #[arg(long)]
    pub security: bool,
    /// Also measure two agents over same-host shared memory (iceoryx2, `transport::shm`) in the same run: threaded,
    /// and "app-driven" (the pinging agent driven by the bench's own thread, `Agent::pump_wait`).
    #[arg(long)]
    pub shm: bool,
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
    /// Also join with DDS Security (a fresh test PKI, submessages encrypted), after the unprotected join.
    #[arg(long)]
    pub security: bool,
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
    /// DDS Security credentials.
    #[arg(long)]
    pub security: Option<PathBuf>,
    /// Over same-host shared memory instead of RTPS.
    #[arg(long)]
    pub shm: bool,
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
    /// DDS Security credentials.
    #[arg(long)]
    pub security: Option<PathBuf>,
}

/// Runs `cortex bench`.
pub fn run(args: BenchArgs) -> Result<()> {
    match args.what {
        BenchCommand::Rtt(args) => run_rtt(args),
        BenchCommand::Join(args) => run_join(args),
        BenchCommand::Echo(args) => {
            let security = args.security.as_deref();
            let (multicast, updates) = (args.multicast.into(), args.updates.into());
            rtt::echo(args.domain, &args.prefix, args.raw, multicast, updates, security, args.shm)
        }
        BenchCommand::JoinChild(args) => {
            let report = join::child(args.domain, &args.prefix, args.nodes, args.security.as_deref())?;
            println!("{}", serde_json::to_string(&report)?);
            Ok(())
        }
        BenchCommand::Fanout(args) => run_fanout(args),
        BenchCommand::FanoutReader(args) => fanout::reader(args.domain, &args.prefix, args.multicast.into()),
        BenchCommand::Scaling(args) => run_scaling(args),
        BenchCommand::Payload(args) => payload::run(args),
        BenchCommand::PayloadReceiver(args) => payload::receiver(args),
    }
}

/// One run per announce group, side by side (`--announce-group 0,8`: without and with the bound).
fn run_scaling(args: ScalingArgs) -> Result<()> {
    let mut results = Vec::new();
    for &announce_group in &args.announce_group {
        let experiment = ScalingExperiment {
            agents: args.agents.clone(),
            writers: args.writers,
            write_rate_hz: args.rate,
            window_ms: args.window_ms,
            announce_ms: args.announce_ms,
            announce_group,
            seed: args.seed,
        };
        results.push(measure::scaling::run(&experiment, &mut |done| eprintln!("{done}"))?);
    }
    if args.json {
        println!("{}", serde_json::to_string(&results)?);
    } else {
        for result in &results {
            print::scaling(result);
        }
    }
    Ok(())
}

/// This binary: the benchmarks start it for their helper processes.
fn this_program() -> Result<PathBuf> {
    std::env::current_exe().context("finding the cortex binary")
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

fn run_rtt(args: RttArgs) -> Result<()> {
    if args.rate <= 0.0 || args.count == 0 || args.updates.is_empty() {
        bail!("--rate and --count must be positive, and --updates must name at least one delivery");
    }
    let setup = NetnsSetup { multicast: args.multicast != MulticastArg::Off };
    let Some(counting) = enter_netns(args.netns, setup)? else { return Ok(()) };
    let config = RttConfig {
        payload_bytes: args.payload,
        rate_hz: args.rate,
        count: args.count,
        domain_id: args.domain,
        multicast: args.multicast.into(),
        updates: args.updates.iter().map(|&u| u.into()).collect(),
        security: if args.security { Some(super::security::bench_credentials()?) } else { None },
        shm: args.shm,
    };
    let result = rtt::run(&config, &counting, &this_program()?)?;
    if args.json {
        println!("{}", serde_json::to_string(&result)?);
    } else {
        print::rtt(&result, &counting);
    }
    Ok(())
}

fn run_join(args: JoinArgs) -> Result<()> {
    let result = join::run(args.nodes, args.domain, &this_program()?, None)?;
    let secured = if args.security {
        let credentials = super::security::bench_credentials()?;
        Some(join::run(args.nodes, args.domain, &this_program()?, Some(&credentials)).context("the protected join")?)
    } else {
        None
    };
    if args.json {
        let json = match &secured {
            None => serde_json::to_value(&result)?,
            Some(secured) => serde_json::json!({ "unprotected": result, "protected": secured }),
        };
        println!("{json}");
    } else {
        print::join(&result);
        if let Some(secured) = &secured {
            println!("with DDS Security (submessages encrypted):");
            print::join(secured);
            print::join_ratio(&result, secured);
        }
    }
    Ok(())
}

fn run_fanout(args: FanoutArgs) -> Result<()> {
    if args.rate <= 0.0 || args.frames == 0 || args.readers.is_empty() || args.readers.contains(&0) {
        bail!("--rate, --frames and every --readers count must be positive");
    }
    if args.payload < 8 {
        bail!("--payload must be at least 8 bytes (a sequence number)");
    }
    if args.readers.iter().any(|&n| n > fanout::MAX_READERS) {
        bail!("--readers: at most {} reader processes", fanout::MAX_READERS);
    }
    let config = FanoutConfig {
        readers: args.readers.clone(),
        payload_bytes: args.payload,
        rate_hz: args.rate,
        frames: args.frames,
        multicast: args.multicast.iter().map(|&m| m.into()).collect(),
        domain_id: args.domain,
    };
    let program = this_program()?;
    let (result, counting) = if netns::inside().is_some() {
        (fanout::run(&config, &Counting::Socket, &program)?, Counting::Socket)
    } else if args.netns == NetnsMode::Off {
        let counting = Counting::EstimateOnly("--netns off".into());
        (fanout::run(&config, &counting, &program)?, counting)
    } else {
        match netns::probe(NetnsSetup { multicast: true }) {
            Ok(()) => (fanout_in_namespaces(&args, &config)?, Counting::Socket),
            Err(error) if args.netns == NetnsMode::Require => {
                return Err(error).context("--netns require: cannot run in a fresh network namespace");
            }
            Err(error) => {
                eprintln!("note: no fresh network namespace ({error}); socket-level bytes not measured");
                let counting = Counting::EstimateOnly(error.to_string());
                (fanout::run(&config, &counting, &program)?, counting)
            }
        }
    };
    if result.skipped_multicast_on {
        eprintln!("note: skipping --multicast on: this host's loopback is not multicast-capable");
    }
    if args.json {
        println!("{}", serde_json::to_string(&result)?);
    } else {
        print::fanout(&result, &counting);
    }
    Ok(())
}

/// Every run of `args`, one fresh network namespace per multicast setting (`lo` multicast-capable unless `off`,
/// as on a host whose loopback has no multicast), each a child process of this binary reporting its
/// [`FanoutResult`] as JSON.
fn fanout_in_namespaces(args: &FanoutArgs, config: &FanoutConfig) -> Result<FanoutResult> {
    let mut all = FanoutResult {
        payload: config.payload_bytes,
        rate_hz: config.rate_hz,
        frames: config.frames,
        netns: true,
        runs: Vec::new(),
        skipped_multicast_on: false,
    };
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
        let child: FanoutResult =
            serde_json::from_slice(&output.stdout).context("the fan-out's report from its namespace")?;
        all.runs.extend(child.runs);
    }
    Ok(all)
}
