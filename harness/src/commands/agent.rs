//! `cortex agent`: runs one DSR_d agent process over RTPS until interrupted, so that agents can be started by
//! hand, by scripts and by the multi-process tests. It can start from a CORTEX JSON graph, insert some nodes of
//! its own (a scripted writer for tests), print its status as JSON lines, and write the graph as CORTEX JSON when
//! it stops (Ctrl-C or `--run-for-ms`).
//!
//! With `--role`, the process also runs a BICA runtime (real clock, its own thread) whose components work on the
//! agent's graph through `perception::agent_graph`: `camera-detector`, `laser-detector` and `attention` are the
//! trees of `perception::roles`; `fixture-camera` writes the bundled EuRoC frames into the `cam_rgb` of a camera
//! node (a stand-in for a sensor bridge). The runtime's named methods (`runtime.components`,
//! `runtime.debug_frame`, `runtime.set_debug`, `runtime.methods` and the role's own) are served to other agents
//! over the `Calls` channel.

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use agent::rtps::AgentTransport;
use agent::{Agent, AgentConfig, AgentId, Control, GraphId, Link};
use anyhow::{Context, Result, anyhow, bail};
use bica::clock::ns_from_ms;
use bica::prelude::*;
use bica::service::{Service, ServiceBuilder};
use clap::builder::PossibleValue;
use clap::{Args, ValueEnum};
use dsr::{NewNode, NodeId, attrs};
use measure::bridge_agent::play_log;
use perception::agent_graph::share_agent;
use perception::attention::{Scanner, StimulusKind};
use perception::blobs::{BlobConfig, BlobDetector};
use perception::graph::SharedGraph;
use perception::labelling::{ColourClass, LabelConfig, LabelTables};
use perception::obstacles::{LaserObstacleDetector, ObstacleConfig};
use perception::roles::Role;
use perception::sensors::{CameraReader, Image, LaserReader, write_image};
use transport::fault::FaultConfig;
use transport::rtps::{RtpsConfig, UpdateDelivery};

/// Arguments of `cortex agent`.
#[derive(Debug, Args)]
pub struct AgentArgs {
    /// Agent id (0..4096), unique among the running agents.
    #[arg(long)]
    pub id: u32,
    /// Start from this CORTEX JSON graph if no running agent answers.
    #[arg(long)]
    pub seed_json: Option<PathBuf>,
    /// The graph this agent belongs to (1 to 16 hex digits): it joins only this graph, refuses every other one on
    /// the domain and prefix, and creates it with this id if it starts alone. Without it, the agent takes the
    /// graph its previous life recorded in `--state-dir`, else the graph of the first agent that answers, else
    /// (starting alone) the one graph it heard agents of while it waited, else a new graph with a random id; such
    /// a graph is unnamed until it hears a named agent of it, and moves to a named graph, or an unnamed one with a
    /// smaller id, that it hears announced. The id is in `--json-status` (`graph`, `graph_named`).
    #[arg(long)]
    pub graph_id: Option<GraphId>,
    /// Join with DDS Security, with the credentials in this directory (`DIR/NAME` of `cortex security init`):
    /// authenticated, access-controlled and protected as its governance and permissions say. Checked before
    /// joining (files, CA signature, expiry).
    #[arg(long)]
    pub security: Option<PathBuf>,
    /// Follow the graph without changing it: the agent asks for the graph (on the requests channel alone, the one
    /// a reader of `cortex security init --readers` may publish on), never starts alone, answers nobody and refuses
    /// local writes (`--insert-nodes`, a role's writes). Needed with a reader's `--security` credentials.
    #[arg(long)]
    pub read_only: bool,
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
    /// Run this BICA role on the agent's graph and serve its runtime's methods to other agents.
    #[arg(long, value_enum)]
    pub role: Option<RoleArg>,
    /// The log the `bridge` role replays.
    #[arg(long, required_if_eq("role", "bridge"))]
    pub log: Option<PathBuf>,
    /// Replay rate of the `bridge` role: `max`, or a factor of the recorded timing (2 plays twice as fast).
    #[arg(long, default_value = "1")]
    pub rate: replay::Rate,
    /// How many times the `bridge` role plays its log.
    #[arg(long, default_value_t = 1)]
    pub loops: u32,
    /// The role's node: the camera (camera-detector, fixture-camera), the laser (laser-detector) or the head
    /// (attention).
    #[arg(long, default_value = "cam0")]
    pub sensor: String,
    /// Period of the role's components.
    #[arg(long, default_value_t = 100)]
    pub period_ms: u64,
    /// Take commands on standard input, one per line: `quiesce` stops the role's runtime (the agent keeps
    /// replicating, so its graph can settle); end of input stops the agent as Ctrl-C does. `cortex replay
    /// --transport rtps` drives its agent processes this way.
    #[arg(long)]
    pub control_stdin: bool,
    /// Inject faults into what this agent receives (seeded with its id), e.g. `loss=0.1,delay-ms=0-2`: keys
    /// `loss`, `duplicate`, `reorder`, `reorder-ms`, `delay-ms`, `max-held`.
    #[arg(long)]
    pub faults: Option<FaultConfig>,
    /// How this agent sends its updates: `reliable` (every peer acknowledges each), or `best-effort` (updates up
    /// to 1 KB unacknowledged, losses repaired by anti-entropy and gap requests; see `transport::rtps`). Agents of
    /// one graph may mix settings: each reads both.
    #[arg(long, value_enum, default_value_t = UpdatesArg::Reliable)]
    pub updates: UpdatesArg,
    /// What carries the samples: `auto` (RTPS, and same-host shared memory to the agents of this graph on this
    /// host and network namespace: `transport::hybrid`), `rtps` (DDS over UDP alone), or `shm` (shared memory
    /// alone: every agent of the graph on this host and started with `--transport shm`; no discovery). With
    /// `--security`, `auto` is RTPS alone: shared memory would bypass the protection.
    #[arg(long, value_enum, default_value_t = TransportArg(Link::Auto))]
    pub transport: TransportArg,
    /// Where this agent records each life's incarnation (`DIR/d<DOMAIN>-<PREFIX>-a<ID>.life`), so that a restarted
    /// agent never takes an earlier life's replica id, even when no peer is reachable. Default
    /// `$XDG_STATE_HOME/cortex`, else `~/.local/state/cortex`; `none` keeps no record (a life then draws its
    /// incarnation floor at random: see the `agent` crate's Identity section).
    #[arg(long)]
    pub state_dir: Option<String>,
}

/// The incarnation record of agent `id` of the graph (`domain`, `prefix`) under `state_dir` (see
/// [`AgentArgs::state_dir`]); `None` for `none`, or when no home directory is known.
pub fn life_file(state_dir: Option<&str>, domain: u16, prefix: &str, id: u32) -> Option<PathBuf> {
    let dir = match state_dir {
        Some("none") => return None,
        Some(dir) => PathBuf::from(dir),
        None => match (std::env::var_os("XDG_STATE_HOME"), std::env::var_os("HOME")) {
            (Some(state), _) if !state.is_empty() => PathBuf::from(state).join("cortex"),
            (_, Some(home)) if !home.is_empty() => PathBuf::from(home).join(".local/state/cortex"),
            _ => return None,
        },
    };
    Some(dir.join(format!("d{domain}-{prefix}-a{id}.life")))
}

/// `--transport`: what carries an agent's samples, one of [`Link::ALL`] by its name.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TransportArg(pub Link);

super::value_enum_by_name!(TransportArg, Link::ALL);

/// `--updates`: how the transport sends [`transport::Channel::Updates`] ([`UpdateDelivery`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum UpdatesArg {
    /// Reliable, like every channel (every reader acknowledges every sample).
    Reliable,
    /// Samples up to 1 KB best-effort; agents repair losses by anti-entropy and gap requests.
    BestEffort,
}

impl From<UpdatesArg> for UpdateDelivery {
    fn from(arg: UpdatesArg) -> UpdateDelivery {
        match arg {
            UpdatesArg::Reliable => UpdateDelivery::Reliable,
            UpdatesArg::BestEffort => UpdateDelivery::BEST_EFFORT_SMALL,
        }
    }
}

impl UpdatesArg {
    /// `reliable` or `best-effort`.
    pub fn name(self) -> &'static str {
        UpdateDelivery::from(self).name()
    }
}

/// `--role`: one of the roles an agent process can run ([`Role`]), by its name.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RoleArg(pub Role);

impl ValueEnum for RoleArg {
    fn value_variants<'a>() -> &'a [Self] {
        const ALL: [RoleArg; 5] = [
            RoleArg(Role::ALL[0]),
            RoleArg(Role::ALL[1]),
            RoleArg(Role::ALL[2]),
            RoleArg(Role::ALL[3]),
            RoleArg(Role::ALL[4]),
        ];
        &ALL
    }

    fn to_possible_value(&self) -> Option<PossibleValue> {
        Some(PossibleValue::new(self.0.name()).help(self.0.summary()))
    }
}

/// Starts an agent on RTPS with the real clock ([`agent::rtps::start`]): the way `cortex agent` and `cortex
/// inspect` join a graph, from `seed_json` if no running agent answers within `join_wait_ms`. With `faults`, what
/// the agent receives goes through the seeded fault injector (seeded with the agent id). `life_file` is where each
/// life records its incarnation ([`AgentConfig::life_file`]); `graph` the graph it belongs to
/// ([`AgentConfig::graph`]). With `rtps.read_only` the agent is read-only too ([`AgentConfig::read_only`]).
///
/// # Errors
/// An unreadable or invalid seed graph, or a DDS domain that cannot be joined.
pub fn start_rtps_agent(
    id: u32,
    graph: Option<GraphId>,
    join_wait_ms: u64,
    seed_json: Option<&std::path::Path>,
    rtps: RtpsConfig,
    faults: Option<FaultConfig>,
    life_file: Option<PathBuf>,
) -> Result<Arc<Agent<AgentTransport>>> {
    let mut config = agent_config(id, graph, join_wait_ms, seed_json, life_file)?;
    config.read_only = rtps.read_only;
    agent::rtps::start(config, rtps, faults).context("joining the DDS domain")
}

/// The configuration `cortex agent` gives its agent, whatever the transport: id, graph, join wait, seed graph,
/// life file.
///
/// # Errors
/// An id out of range, an unreadable or invalid seed graph.
fn agent_config(
    id: u32,
    graph: Option<GraphId>,
    join_wait_ms: u64,
    seed_json: Option<&std::path::Path>,
    life_file: Option<PathBuf>,
) -> Result<AgentConfig> {
    if id >= AgentId::LIMIT {
        bail!("--id {id} is out of range (0..{})", AgentId::LIMIT);
    }
    let mut config = AgentConfig::new(AgentId(id));
    config.join_wait = Duration::from_millis(join_wait_ms);
    config.life_file = life_file;
    config.graph = graph;
    if let Some(path) = seed_json {
        let bytes = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
        let reading = dsr::json::read(&bytes, dsr::json::Strictness::Lenient)
            .with_context(|| format!("parsing {}", path.display()))?;
        for warning in &reading.warnings {
            eprintln!("warning: {}: {warning}", path.display());
        }
        config.seed = Some(reading.graph);
    }
    Ok(config)
}

/// The transport's DDS Security settings for the credentials in `dir`, checked first
/// ([`super::security::check_credentials`]).
///
/// # Errors
/// Missing, unreadable, wrongly signed, expired or not yet valid credentials (the message names the file).
pub fn security_files(dir: Option<&std::path::Path>) -> Result<Option<transport::rtps::SecurityFiles>> {
    let Some(dir) = dir else { return Ok(None) };
    super::security::check_credentials(dir).context("--security")?;
    Ok(Some(transport::rtps::SecurityFiles { dir: dir.to_path_buf() }))
}

/// Whether the DDS Security credentials in `dir` (if any) let the participant write the graph with topic prefix
/// `topic_prefix`: `false` for a reader's, which publish requests alone
/// ([`super::security::may_write_graph`]).
///
/// # Errors
/// An unreadable permissions file.
pub fn credentials_write(dir: Option<&std::path::Path>, topic_prefix: &str) -> Result<bool> {
    match dir {
        None => Ok(true),
        Some(dir) => super::security::may_write_graph(dir, topic_prefix).context("--security"),
    }
}

/// Runs `cortex agent`.
pub fn run(args: AgentArgs) -> Result<()> {
    let life = life_file(args.state_dir.as_deref(), args.domain, &args.topic_prefix, args.id);
    let link = args.transport.0;
    if link == Link::Shm && args.security.is_some() {
        bail!("--security protects RTPS; it does not apply to --transport {link}");
    }
    let mut config = agent_config(args.id, args.graph_id, args.join_wait_ms, args.seed_json.as_deref(), life)?;
    let security = security_files(args.security.as_deref())?;
    if !args.read_only && !credentials_write(args.security.as_deref(), &args.topic_prefix)? {
        bail!(
            "--security {}: these credentials let this participant publish requests alone (a reader of `cortex \
             security init --readers`), so it cannot write the graph; start it with --read-only to follow the graph",
            args.security.as_deref().unwrap_or_else(|| std::path::Path::new("")).display()
        );
    }
    if args.read_only && (args.role.is_some() || args.seed_json.is_some()) {
        bail!("--read-only: an agent that cannot write runs no --role and starts from no --seed-json");
    }
    config.read_only = args.read_only;
    let rtps = RtpsConfig {
        domain_id: args.domain,
        topic_prefix: args.topic_prefix.clone(),
        updates: args.updates.into(),
        security,
        read_only: args.read_only,
        ..RtpsConfig::default()
    };
    let agent = link.start(config, rtps, args.faults).with_context(|| format!("starting the agent on {link}"))?;
    let stop = Arc::new(AtomicBool::new(false));
    let work = start_work(&args, &agent, &stop)?;
    {
        let stop = Arc::clone(&stop);
        ctrlc::set_handler(move || stop.store(true, Ordering::SeqCst)).context("installing the Ctrl-C handler")?;
    }
    let quiesce = Arc::new(AtomicBool::new(false));
    if args.control_stdin {
        read_control(Arc::clone(&stop), Arc::clone(&quiesce));
    }
    let started = Instant::now();
    let work = serve(&args, &agent, work, &stop, &quiesce, started)?;
    stop_work(&agent, work, &stop)?;
    agent.shutdown();
    if args.json_status {
        println!("{}", status_json(&agent, started));
    }
    if let Some(path) = &args.dump_json {
        dump_graph(&agent, path)?;
    }
    Ok(())
}

/// Writes the agent's graph as CORTEX JSON to `path` (`--dump-json`).
///
/// # Errors
/// The agent never got a graph, the export failed, or the file cannot be written.
pub fn dump_graph<T: transport::Transport + 'static>(agent: &Agent<T>, path: &std::path::Path) -> Result<()> {
    let json = agent
        .read(dsr::json::export)
        .context("the agent never got a graph, nothing to dump")?
        .context("exporting the graph")?;
    std::fs::write(path, json).with_context(|| format!("writing {}", path.display()))
}

/// What an agent process runs besides its agent: a role's BICA runtime, or the bridge's log player.
#[derive(Default)]
struct Work {
    /// The role's runtime, until it is quiesced.
    driver: Option<Driver>,
    /// The bridge role's player thread.
    player: Option<std::thread::JoinHandle<Result<replay::BridgeStats>>>,
}

/// Starts `--role`'s work once the agent has its graph: the bridge plays `--log` on a thread (until it ends or
/// `stop` is set); any other role runs its BICA tree, whose methods the agent serves to other agents.
fn start_work(args: &AgentArgs, agent: &Arc<Agent<AgentTransport>>, stop: &Arc<AtomicBool>) -> Result<Work> {
    let Some(RoleArg(role)) = args.role else { return Ok(Work::default()) };
    let join_wait = Duration::from_millis(args.join_wait_ms) + Duration::from_secs(10);
    if role == Role::Bridge {
        if !agent.wait_ready(join_wait) {
            bail!("agent {} got no graph in time to start the bridge", args.id);
        }
        let path = args
            .log
            .clone()
            .context("the bridge role needs --log LOG (an MCAP file, a ROS 1 bag or a rosbag2 directory)")?;
        let log = replay::Log::open(&path, replay::ReadOptions::default())
            .with_context(|| format!("cannot replay {}", path.display()))?;
        let (agent, stop, rate, loops) = (Arc::clone(agent), Arc::clone(stop), args.rate, args.loops);
        let player = std::thread::spawn(move || {
            let options = replay::BridgeOptions::default();
            play_log(&agent, &log, options, rate, loops, &stop, &mut |_| Ok(())).map(|p| p.bridge)
        });
        return Ok(Work { driver: None, player: Some(player) });
    }
    if !agent.wait_ready(join_wait) {
        bail!("agent {} got no graph in time to start role {role:?}", args.id);
    }
    let (driver, service) = start_role(role, agent, &args.sensor, args.period_ms)?;
    agent.serve_calls(Arc::new(service));
    Ok(Work { driver: Some(driver), player: None })
}

/// Reads `--control-stdin` commands ([`Control`]) on a thread: `quiesce` sets `quiesce`; the end of input sets
/// `stop`.
fn read_control(stop: Arc<AtomicBool>, quiesce: Arc<AtomicBool>) {
    std::thread::spawn(move || {
        for line in std::io::stdin().lines() {
            match line.as_deref().map(str::trim) {
                Ok("") => {}
                Ok(text) => match Control::parse(text) {
                    Some(Control::Quiesce) => quiesce.store(true, Ordering::SeqCst),
                    None => eprintln!("agent: unknown command on standard input: {text:?} (quiesce)"),
                },
                Err(_) => break,
            }
        }
        stop.store(true, Ordering::SeqCst);
    });
}

/// The longest [`serve`] sleeps between looks at the stop flag, readiness and quiescence.
const SERVE_POLL: Duration = Duration::from_millis(50);

/// Runs until `stop` is set or `--run-for-ms` has passed: inserts `--insert-nodes` nodes once ready, stops the
/// role's runtime when quiesced, prints status lines.
fn serve(
    args: &AgentArgs,
    agent: &Agent<AgentTransport>,
    mut work: Work,
    stop: &AtomicBool,
    quiesce: &AtomicBool,
    started: Instant,
) -> Result<Work> {
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
        if quiesce.load(Ordering::SeqCst)
            && let Some(driver) = work.driver.take()
        {
            agent.stop_serving_calls();
            driver.stop().context("stopping the role's runtime")?;
        }
        if args.json_status && Instant::now() >= next_status {
            next_status = Instant::now() + Duration::from_millis(args.status_ms);
            println!("{}", status_json(agent, started));
        }
        // Looks again when the next status line or the end is due, and at least every SERVE_POLL (for the stop
        // flag, readiness and quiescence): an idle agent's process wakes 20 times a second, not 100.
        let mut until = Instant::now() + SERVE_POLL;
        if args.json_status {
            until = until.min(next_status);
        }
        if let Some(end) = deadline {
            until = until.min(end);
        }
        std::thread::sleep(until.saturating_duration_since(Instant::now()));
    }
    Ok(work)
}

/// Stops what still runs: the role's runtime, or the bridge's player (its counters on standard error).
fn stop_work(agent: &Agent<AgentTransport>, work: Work, stop: &AtomicBool) -> Result<()> {
    if let Some(driver) = work.driver {
        agent.stop_serving_calls();
        driver.stop().context("stopping the role's runtime")?;
    }
    if let Some(player) = work.player {
        stop.store(true, Ordering::SeqCst);
        let stats = player.join().map_err(|_| anyhow!("the bridge thread panicked"))??;
        eprintln!(
            "bridge: {} messages bridged, {} unknown, {} filtered, {} errors",
            stats.messages,
            stats.unknown.values().sum::<u64>(),
            stats.filtered,
            stats.error_count()
        );
    }
    Ok(())
}

fn status_json<T: transport::Transport>(agent: &Agent<T>, started: Instant) -> String {
    let line = agent.status_line(started.elapsed().as_millis() as u64);
    serde_json::to_string(&line).unwrap_or_else(|error| format!("{{\"error\": \"status line: {error}\"}}"))
}

/// Starts `role`'s runtime on its own thread, over `agent`'s graph; returns it with its named methods.
fn start_role(
    role: Role,
    agent: &Arc<Agent<AgentTransport>>,
    sensor: &str,
    period_ms: u64,
) -> Result<(Driver, Service)> {
    if role == Role::Bridge {
        bail!("the bridge role runs no BICA tree (it is a log player)");
    }
    let frames = match role {
        Role::FixtureCamera => perception::fixtures::euroc_frames().context("reading the EuRoC fixtures")?,
        _ => Vec::new(),
    };
    let tables = LabelTables::new(LabelConfig {
        classes: vec![ColourClass { name: "bright".into(), min: [200; 3], max: [255; 3], display: [255, 255, 0] }],
    })
    .map_err(|e| anyhow!("colour tables: {e}"))?;
    let agent = Arc::clone(agent);
    let sensor = sensor.to_owned();
    let driver = Driver::spawn(RuntimeConfig::default(), move |runtime| {
        let graph = share_agent(agent);
        let failed = |message: String| BicaError::StepFailed { component: format!("role {role:?}"), message };
        let built = match role {
            Role::CameraDetector => {
                let blobs = BlobConfig { min_area_px: 200, ..BlobConfig::default() };
                perception::roles::camera_detector(runtime, graph, &sensor, tables, blobs, period_ms)
            }
            Role::LaserDetector => {
                perception::roles::laser_detector(runtime, graph, &sensor, ObstacleConfig::default(), period_ms)
            }
            Role::Attention => {
                perception::roles::attention(runtime, graph, &sensor, StimulusKind::Blob { class: 0 }, period_ms)
            }
            Role::FixtureCamera => {
                runtime.register(
                    FixtureCamera { graph, name: sensor, node: None, frames, written: 0 },
                    ns_from_ms(period_ms.max(1)),
                )?;
                return runtime.activate::<FixtureCamera>();
            }
            Role::Bridge => return Err(failed("the bridge role runs no BICA tree".into())),
        };
        built.map_err(|e| failed(e.to_string()))
    })
    .map_err(|e| anyhow!("starting role {role:?}: {e}"))?;
    let methods = ServiceBuilder::new();
    let methods = match role {
        Role::CameraDetector => methods
            .method("BlobDetector.blob_count", |d: &mut BlobDetector, (): ()| d.blobs().len() as u64)
            .method("CameraReader.readings", |r: &mut CameraReader, (): ()| r.readings()),
        Role::LaserDetector => methods
            .method("LaserObstacleDetector.cluster_count", |d: &mut LaserObstacleDetector, (): ()| {
                d.clusters().len() as u64
            })
            .method("LaserReader.readings", |r: &mut LaserReader, (): ()| r.readings()),
        Role::Attention => methods.method("Scanner.runs", |s: &mut Scanner, (): ()| s.runs()),
        Role::FixtureCamera => methods.method("FixtureCamera.written", |c: &mut FixtureCamera, (): ()| c.written),
        Role::Bridge => methods,
    };
    let service = methods.build(driver.remote());
    Ok((driver, service))
}

/// Writes the bundled frames into camera node `name` (inserted if missing), each 5 times in a row, so the
/// detector's tracks of a frame's blobs get confirmed before the next frame.
struct FixtureCamera {
    graph: SharedGraph,
    name: String,
    node: Option<NodeId>,
    frames: Vec<Image>,
    written: u64,
}

impl Component for FixtureCamera {
    fn step(&mut self, ctx: &mut StepContext<'_>) -> Result<(), BicaError> {
        let now = ctx.now_ns();
        let failed = |message: String| BicaError::StepFailed { component: "FixtureCamera".into(), message };
        let mut graph = self.graph.borrow_mut();
        let node = match self.node.or_else(|| graph.find_node(&self.name)) {
            Some(node) => node,
            None => graph.insert_node(now, NewNode::new("camera", &self.name)).map_err(|e| failed(e.to_string()))?,
        };
        self.node = Some(node);
        let Some(frame) = self.frames.get((self.written / 5) as usize % self.frames.len().max(1)) else {
            return Ok(());
        };
        write_image(&mut *graph, now, node, frame, now, self.written).map_err(|e| failed(e.to_string()))?;
        self.written += 1;
        Ok(())
    }
}
