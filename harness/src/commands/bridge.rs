//! `cortex bridge ros2 --config FILE.toml`: a live bridge between a ROS 2 domain and the graph
//! (`ros2bridge::Ros2Bridge`). The graph side is an agent started as `cortex agent` starts one, on the file's DSR
//! domain and prefix; it waits for its graph (or starts one alone), then the bridge reads the file's ROS 2 topics
//! into it and publishes its RT edges, images and laser scans to ROS 2. With `--json-status` it prints one JSON line
//! every `--status-ms` (the bridge's counters and latencies, and the agent's status line), and a last one when it
//! stops (Ctrl-C, `--run-for-ms`, or standard input closed with `--control-stdin`); `--dump-json` writes the graph
//! as CORTEX JSON at the end.

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail};
use clap::{Args, Subcommand};
use ros2bridge::{BridgeConfig, BridgeStatus, Ros2Bridge};
use serde::Serialize;
use transport::rtps::RtpsConfig;

use super::agent::{dump_graph, life_file, start_rtps_agent};

/// `cortex bridge`.
#[derive(Debug, Args)]
pub struct BridgeArgs {
    /// Which bridge.
    #[command(subcommand)]
    pub command: BridgeCommand,
}

/// The bridges.
#[derive(Debug, Subcommand)]
pub enum BridgeCommand {
    /// ROS 2 topics into the graph and the graph's TF, images and laser scans out to ROS 2, live on RTPS.
    Ros2(Ros2Args),
}

/// `cortex bridge ros2`.
#[derive(Debug, Args)]
pub struct Ros2Args {
    /// The bridge file (TOML; README, "ROS 2 bridge").
    #[arg(long)]
    pub config: PathBuf,
    /// Print a JSON status line every `--status-ms`, and one at the end.
    #[arg(long)]
    pub json_status: bool,
    /// Period of the status lines, ms.
    #[arg(long, default_value_t = 1000)]
    pub status_ms: u64,
    /// Stop after this many ms.
    #[arg(long)]
    pub run_for_ms: Option<u64>,
    /// Stop when standard input closes.
    #[arg(long)]
    pub control_stdin: bool,
    /// How long the agent looks for a graph to join before starting one alone, ms.
    #[arg(long, default_value_t = 2000)]
    pub join_wait_ms: u64,
    /// A CORTEX JSON graph to start from when no agent answers.
    #[arg(long)]
    pub seed_json: Option<PathBuf>,
    /// Write the graph as CORTEX JSON here when stopping.
    #[arg(long)]
    pub dump_json: Option<PathBuf>,
    /// Where the agent records its incarnation (as `cortex agent --state-dir`; `none` for no record).
    #[arg(long)]
    pub state_dir: Option<String>,
}

/// One status line.
#[derive(Debug, Serialize)]
struct StatusOut {
    bridge: BridgeStatus,
    agent: agent::StatusLine,
}

/// Runs `cortex bridge`.
pub fn run(args: BridgeArgs) -> Result<()> {
    match args.command {
        BridgeCommand::Ros2(args) => run_ros2(args),
    }
}

fn run_ros2(args: Ros2Args) -> Result<()> {
    let config = BridgeConfig::load(&args.config)?;
    let agent = start_rtps_agent(
        config.agent_id,
        None,
        args.join_wait_ms,
        args.seed_json.as_deref(),
        RtpsConfig { domain_id: config.dsr_domain, topic_prefix: config.dsr_prefix.clone(), ..RtpsConfig::default() },
        None,
        life_file(args.state_dir.as_deref(), config.dsr_domain, &config.dsr_prefix, config.agent_id),
    )?;
    if !agent.wait_ready(Duration::from_millis(args.join_wait_ms) + Duration::from_secs(10)) {
        bail!("agent {} got no graph in time to start the bridge", config.agent_id);
    }
    let bridge = Ros2Bridge::start(&config, Arc::clone(&agent))?;
    let stop = Arc::new(AtomicBool::new(false));
    {
        let stop = Arc::clone(&stop);
        ctrlc::set_handler(move || stop.store(true, Ordering::SeqCst)).context("installing the Ctrl-C handler")?;
    }
    if args.control_stdin {
        let stop = Arc::clone(&stop);
        std::thread::spawn(move || {
            for line in std::io::stdin().lines() {
                if line.is_err() {
                    break;
                }
            }
            stop.store(true, Ordering::SeqCst);
        });
    }
    let started = Instant::now();
    let deadline = args.run_for_ms.map(|ms| started + Duration::from_millis(ms));
    let status = |bridge: &Ros2Bridge| -> Result<String> {
        let line =
            StatusOut { bridge: bridge.status(), agent: agent.status_line(started.elapsed().as_millis() as u64) };
        serde_json::to_string(&line).context("writing the status line")
    };
    let mut next_status = Instant::now();
    while !stop.load(Ordering::SeqCst) && deadline.is_none_or(|d| Instant::now() < d) {
        if args.json_status && Instant::now() >= next_status {
            next_status = Instant::now() + Duration::from_millis(args.status_ms);
            println!("{}", status(&bridge)?);
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    let last = status(&bridge)?;
    bridge.stop();
    if args.json_status {
        println!("{last}");
    }
    agent.shutdown();
    if let Some(path) = &args.dump_json {
        dump_graph(&agent, path)?;
    }
    Ok(())
}
