//! `cortex inspect`: joins the graph as an agent over RTPS and serves the web inspector (graph, RT tree, 2-D
//! world and BICA debug views; edits with `--allow-edit`). Loopback by default; everything the page needs is
//! inside the binary. `--demo` also runs the camera-detector role on the bundled EuRoC frames in this process, so
//! the Debug view has a runtime to show; `--debug-agent N` shows instead the runtime of agent N (a
//! `cortex agent --role` process), called over the network.

use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use agent::AgentId;
use anyhow::{Context, Result, bail};
use clap::Args;
use inspector::debug::{DebugSource, RemoteDebug};
use inspector::feed::GraphFeed;
use inspector::{Inspector, InspectorConfig};
use transport::rtps::RtpsConfig;

/// Arguments of `cortex inspect`.
#[derive(Debug, Args)]
pub struct InspectArgs {
    /// The graph to inspect (1 to 16 hex digits; see `cortex agent --graph-id`). Without it, the graph of the first
    /// agent that answers.
    #[arg(long)]
    pub graph_id: Option<agent::GraphId>,
    /// Join with DDS Security, with the credentials in this directory (see `cortex agent --security`). When their
    /// permissions let the participant publish requests alone (a reader of `cortex security init --readers`, such
    /// as `inspector`), the inspector is read-only by itself, as with `--read-only`.
    #[arg(long)]
    pub security: Option<PathBuf>,
    /// Follow the graph without changing it: the inspector's agent publishes nothing but requests for the graph,
    /// never starts alone (it waits for an agent of the graph to answer), the page cannot edit, and no remote calls
    /// go out (no `--debug-agent`).
    #[arg(long, conflicts_with_all = ["allow_edit", "demo", "seed_json", "debug_agent"])]
    pub read_only: bool,
    /// DDS domain id.
    #[arg(long, default_value_t = 0)]
    pub domain: u16,
    /// Topic name prefix (several graphs can share a domain).
    #[arg(long, default_value = "dsr")]
    pub topic_prefix: String,
    /// Where to serve the page.
    #[arg(long, default_value = "127.0.0.1:8080")]
    pub listen: SocketAddr,
    /// Let the page edit the graph (attributes, nodes, edges) through the agent API.
    #[arg(long)]
    pub allow_edit: bool,
    /// The inspector's agent id (0..4096), unique among the running agents.
    #[arg(long, default_value_t = 4000)]
    pub id: u32,
    /// Start from this CORTEX JSON graph if no running agent answers.
    #[arg(long)]
    pub seed_json: Option<PathBuf>,
    /// How long to wait for a running agent's graph before starting alone (or from the seed).
    #[arg(long, default_value_t = 2000)]
    pub join_wait_ms: u64,
    /// Run the camera-detector role on the bundled EuRoC frames in this process (Debug view), mirroring the
    /// frames into the graph as node `demo_cam0`.
    #[arg(long, conflicts_with = "debug_agent")]
    pub demo: bool,
    /// Show in the Debug view the BICA runtime of this agent (a `cortex agent --role` process), through remote
    /// calls.
    #[arg(long)]
    pub debug_agent: Option<u32>,
    /// Stop by itself after this long (otherwise run until Ctrl-C).
    #[arg(long)]
    pub run_for_ms: Option<u64>,
}

/// Runs `cortex inspect`.
pub fn run(args: InspectArgs) -> Result<()> {
    if args.id >= AgentId::LIMIT {
        bail!("--id {} is out of range (0..{})", args.id, AgentId::LIMIT);
    }
    if !args.listen.ip().is_loopback() {
        eprintln!(
            "warning: serving the inspector on {} (not loopback): anyone who can reach it sees the graph",
            args.listen
        );
    }
    let security = super::agent::security_files(args.security.as_deref())?;
    let reader = !super::agent::credentials_write(args.security.as_deref(), &args.topic_prefix)?;
    if reader && (args.allow_edit || args.demo || args.seed_json.is_some() || args.debug_agent.is_some()) {
        bail!(
            "--security {}: these credentials let this participant publish requests alone, so the inspector is \
             read-only: --allow-edit, --demo, --seed-json and --debug-agent need a writer's credentials",
            args.security.as_deref().map(|p| p.display().to_string()).unwrap_or_default()
        );
    }
    let read_only = args.read_only || reader;
    if reader && !args.read_only {
        eprintln!("inspect: the credentials are a reader's (they publish requests alone): joining read-only");
    }
    let agent = super::agent::start_rtps_agent(
        args.id,
        args.graph_id,
        args.join_wait_ms,
        args.seed_json.as_deref(),
        RtpsConfig {
            domain_id: args.domain,
            topic_prefix: args.topic_prefix.clone(),
            security,
            read_only,
            ..RtpsConfig::default()
        },
        None,
        super::agent::life_file(None, args.domain, &args.topic_prefix, args.id),
    )?;
    let feed: Arc<dyn GraphFeed> = agent.clone();
    let mut demo = None;
    let mut debug: Option<Arc<dyn DebugSource>> = None;
    if args.demo {
        if !agent.wait_ready(Duration::from_millis(args.join_wait_ms) + Duration::from_secs(5)) {
            bail!("the agent did not get a graph in time for --demo");
        }
        let (running, source) = inspector::demo::Demo::start(Some(Arc::clone(&feed)))?;
        demo = Some(running);
        debug = Some(Arc::new(source));
    }
    if let Some(target) = args.debug_agent {
        if target >= AgentId::LIMIT || target == args.id {
            bail!("--debug-agent {target} must be another agent's id (0..{}, not {})", AgentId::LIMIT, args.id);
        }
        debug = Some(Arc::new(RemoteDebug::new(Arc::clone(&agent), AgentId(target))));
    }
    let title = format!("cortex inspect · domain {} · {}", args.domain, args.topic_prefix);
    let inspector =
        Inspector::start(feed, debug, InspectorConfig { listen: args.listen, allow_edit: args.allow_edit, title })?;
    println!(
        "inspector on http://{} ({})",
        inspector.addr(),
        if read_only {
            "read-only participant"
        } else if args.allow_edit {
            "edits allowed"
        } else {
            "read-only"
        }
    );

    let stop = Arc::new(AtomicBool::new(false));
    {
        let stop = Arc::clone(&stop);
        ctrlc::set_handler(move || stop.store(true, Ordering::SeqCst)).context("installing the Ctrl-C handler")?;
    }
    let deadline = args.run_for_ms.map(|ms| Instant::now() + Duration::from_millis(ms));
    while !stop.load(Ordering::SeqCst) && deadline.is_none_or(|d| Instant::now() < d) {
        std::thread::sleep(Duration::from_millis(50));
    }
    drop(inspector);
    drop(demo);
    agent.shutdown();
    Ok(())
}
