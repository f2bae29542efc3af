//! `cortex agent`: runs one DSR_d agent process over RTPS until interrupted, so that agents can be started by
//! hand, by scripts and by the multi-process tests. It can start from a CORTEX JSON graph, insert some nodes of
//! its own (a scripted writer for tests), print its status as JSON lines, and write the graph as CORTEX JSON when
//! it stops (Ctrl-C or `--run-for-ms`).

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use agent::{Agent, AgentConfig, AgentId};
use anyhow::{Context, Result, bail};
use clap::Args;
use dsr::{NewNode, attrs};
use transport::SystemClock;
use transport::rtps::{RtpsConfig, RtpsTransport};

/// Arguments of `cortex agent`.
#[derive(Debug, Args)]
pub struct AgentArgs {
    /// Agent id (0..4096), unique among the running agents.
    #[arg(long)]
    pub id: u32,
    /// Start from this CORTEX JSON graph if no running agent answers.
    #[arg(long)]
    pub seed_json: Option<PathBuf>,
    /// DDS domain id.
    #[arg(long, default_value_t = 0)]
    pub domain: u16,
    /// Topic name prefix (several graphs can share a domain).
    #[arg(long, default_value = "dsr")]
    pub topic_prefix: String,
    /// Write the graph as CORTEX JSON here when stopping.
    #[arg(long)]
    pub dump_json: Option<PathBuf>,
    /// Print the status as one JSON object per line, every `--status-ms`.
    #[arg(long)]
    pub json_status: bool,
    /// Period of status lines.
    #[arg(long, default_value_t = 250)]
    pub status_ms: u64,
    /// How long to wait for a running agent's graph before starting alone.
    #[arg(long, default_value_t = 2000)]
    pub join_wait_ms: u64,
    /// Once ready, insert this many nodes named `a<ID>_<i>` (a scripted writer).
    #[arg(long, default_value_t = 0)]
    pub insert_nodes: u32,
    /// Stop by itself after this long (otherwise run until Ctrl-C).
    #[arg(long)]
    pub run_for_ms: Option<u64>,
}

/// Runs `cortex agent`.
pub fn run(args: AgentArgs) -> Result<()> {
    if args.id >= AgentId::LIMIT {
        bail!("--id {} is out of range (0..{})", args.id, AgentId::LIMIT);
    }
    let mut config = AgentConfig::new(AgentId(args.id));
    config.join_wait = Duration::from_millis(args.join_wait_ms);
    if let Some(path) = &args.seed_json {
        let bytes = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
        config.seed = Some(dsr::json::parse_bytes(&bytes).with_context(|| format!("parsing {}", path.display()))?);
    }
    let rtps = RtpsConfig { domain_id: args.domain, topic_prefix: args.topic_prefix.clone(), ..RtpsConfig::default() };
    let transport = RtpsTransport::new(rtps).context("joining the DDS domain")?;
    let agent = Agent::start(config, transport, Arc::new(SystemClock))?;

    let stop = Arc::new(AtomicBool::new(false));
    {
        let stop = Arc::clone(&stop);
        ctrlc::set_handler(move || stop.store(true, Ordering::SeqCst)).context("installing the Ctrl-C handler")?;
    }
    let started = Instant::now();
    let deadline = args.run_for_ms.map(|ms| started + Duration::from_millis(ms));
    let mut written = false;
    let mut next_status = Instant::now();
    while !stop.load(Ordering::SeqCst) && deadline.is_none_or(|d| Instant::now() < d) {
        if !written && agent.is_ready() {
            written = true;
            for i in 0..args.insert_nodes {
                let name = format!("a{}_{i}", args.id);
                let node = NewNode::new("object", &name).with_attr("pos_x", i as f32);
                let id = agent.insert_node(node).with_context(|| format!("inserting {name}"))?;
                agent.set_attr(id, attrs::POS_Y, args.id as f32)?;
            }
        }
        if args.json_status && Instant::now() >= next_status {
            next_status = Instant::now() + Duration::from_millis(args.status_ms);
            println!("{}", status_json(&agent, started));
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    agent.shutdown();
    if args.json_status {
        println!("{}", status_json(&agent, started));
    }
    if let Some(path) = &args.dump_json {
        let json = agent
            .read(dsr::json::export)
            .context("the agent never got a graph, nothing to dump")?
            .context("exporting the graph")?;
        std::fs::write(path, json).with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(())
}

fn status_json<T: transport::Transport>(agent: &Agent<T>, started: Instant) -> serde_json::Value {
    let status = agent.status();
    serde_json::json!({
        "id": status.id.0,
        "ready": status.ready,
        "replica": status.replica.map(|r| r.0),
        "nodes": status.nodes,
        "edges": status.edges,
        "digest": agent.digest().map(|d| d.to_string()),
        "peers": status.peers.iter().map(|p| p.0).collect::<Vec<_>>(),
        "rejected": status.rejected,
        "collision": status.collision,
        "uptime_ms": started.elapsed().as_millis() as u64,
        "samples_sent": status.transport.samples_sent,
        "wire_bytes_sent": status.transport.wire_bytes_sent,
    })
}
