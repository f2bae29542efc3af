//! What to run: the experiment file (TOML, in `experiments/`) and the configurations the runners take. Plain data
//! with its parsing and validation; nothing here runs anything.
//!
//! An experiment file names a `quick` and a `full` [`ExperimentSet`]: the logs to replay (each with its rate and
//! loops), the numbers of agents and the seeds of the replay sweep, a payload-size sweep of synthetic writes,
//! fault-injection variants, the partition experiment, and the optional scheduler timeline, detector roles, control
//! traffic and payload paths (`paths.rs`: [`PayloadPathsExperiment`], also what `cortex bench payload` takes).
//! Relative paths are resolved against the repository root, the parent of the directory that holds the file
//! (`experiments/..`). [`RunConfig`] and [`PartitionConfig`] are what one run of [`crate::run`] or
//! [`crate::partition`] takes.

use std::path::{Path, PathBuf};
use std::time::Duration;

use anyhow::Context as _;
use bica::core::SchedulerConfig;
use serde::{Deserialize, Serialize};
use transport::fault::FaultConfig;

mod paths;
pub use paths::{
    MAX_PAYLOAD_PATH_BYTES, MAX_PAYLOAD_PATH_COUNT, MAX_PAYLOAD_PATH_RECEIVERS, PayloadPath, PayloadPathsExperiment,
};

/// An experiment file.
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct ExperimentFile {
    /// Short name, used in the report's title.
    pub name: String,
    /// What the experiments are for.
    pub description: String,
    /// The default set: at most 5 minutes on 2 cores.
    pub quick: ExperimentSet,
    /// The whole sweep (`--full`).
    pub full: ExperimentSet,
}

impl ExperimentFile {
    /// Reads and parses `path`.
    ///
    /// # Errors
    /// The file cannot be read or is not a valid experiment file (the message says where).
    pub fn load(path: &Path) -> anyhow::Result<ExperimentFile> {
        let text = std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
        toml::from_str(&text).with_context(|| format!("{} is not a valid experiment file", path.display()))
    }

    /// The repository root its relative paths are resolved against: the parent of the file's directory.
    pub fn root_of(path: &Path) -> PathBuf {
        let dir = path.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new("."));
        dir.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new(".")).to_path_buf()
    }
}

/// One log of the replay sweep.
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct LogSpec {
    /// Path of the MCAP file.
    pub path: PathBuf,
    /// A factor on the recorded timing, or `max`.
    pub rate: String,
    /// Passes over the log.
    #[serde(default = "one")]
    pub loops: u32,
}

fn one() -> u32 {
    1
}

fn inproc_only() -> Vec<String> {
    vec!["inproc".to_owned()]
}

fn default_domain() -> u16 {
    71
}

fn inproc() -> String {
    "inproc".to_owned()
}

/// Synthetic writes of growing size.
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct PayloadSweep {
    /// Sizes of the byte attribute written, in bytes.
    pub sizes: Vec<usize>,
    /// Writes per second.
    pub rate_hz: f64,
    /// Writes per size.
    pub count: usize,
    /// Agents, the source included.
    pub agents: u32,
    /// Transport of the sweep: `inproc`, `rtps` or `rtps-processes`.
    #[serde(default = "inproc")]
    pub transport: String,
}

/// One fault-injection variant (applied to what every receiver receives).
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct FaultSpec {
    /// Label in figures and tables.
    pub label: String,
    /// Uniform delay of every sample, milliseconds `[min, max]`.
    #[serde(default)]
    pub delay_ms: [f64; 2],
    /// Probability of an extra delay of up to `reorder_ms`.
    #[serde(default)]
    pub reorder: f64,
    /// Largest extra delay, milliseconds.
    #[serde(default)]
    pub reorder_ms: f64,
    /// Probability of a duplicate.
    #[serde(default)]
    pub duplicate: f64,
}

impl FaultSpec {
    /// The fault injector's configuration (no loss: the replay runner has no anti-entropy).
    pub fn config(&self) -> Option<FaultConfig> {
        let ns_from_ms = |v: f64| (v.max(0.0) * 1e6) as u64;
        let config = FaultConfig {
            duplicate: self.duplicate,
            reorder: self.reorder,
            reorder_ns: ns_from_ms(self.reorder_ms),
            delay_ns: (ns_from_ms(self.delay_ms[0]), ns_from_ms(self.delay_ms[1]).max(ns_from_ms(self.delay_ms[0]))),
            ..FaultConfig::default()
        };
        (config != FaultConfig::default()).then_some(config)
    }
}

/// Convergence with and without faults.
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct FaultExperiment {
    /// The log replayed.
    pub log: LogSpec,
    /// Agents, the source included.
    pub agents: u32,
    /// Transports the variants run over (each variant on each): `inproc`, `rtps`, `rtps-processes`. The injector
    /// sits on each receiver's receiving side, in the receiver's own process for `rtps-processes`.
    #[serde(default = "inproc_only")]
    pub transports: Vec<String>,
    /// The variants (one without faults is expected, for comparison).
    pub variants: Vec<FaultSpec>,
}

/// Reconvergence after a healed partition.
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct PartitionExperiment {
    /// Agents; the last is isolated.
    pub agents: u32,
    /// Length of the partition, milliseconds.
    pub partition_ms: u64,
    /// Writes per second on each side.
    pub rate_hz: f64,
    /// The agents' anti-entropy announce period, milliseconds.
    pub announce_ms: u64,
    /// Runs (seeds 1, 2, ...) per transport.
    pub repetitions: u32,
    /// Transports of the agents (all in this process): `inproc` and/or `rtps`.
    #[serde(default = "inproc_only")]
    pub transports: Vec<String>,
}

/// A set of experiments.
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct ExperimentSet {
    /// Logs replayed for every number of agents and seed.
    pub logs: Vec<LogSpec>,
    /// Numbers of agents, the source included.
    pub agents: Vec<u32>,
    /// Seeds (one run per seed: the repetitions).
    pub seeds: Vec<u64>,
    /// Transports of the replay sweep: `inproc` (the in-process bus), `rtps` (one rustdds participant per agent,
    /// all in this process, over loopback) and/or `rtps-processes` (every receiver a process of its own with its
    /// own participant; the source is the `cortex` process).
    #[serde(default = "inproc_only")]
    pub transports: Vec<String>,
    /// DDS domain id of the RTPS runs.
    #[serde(default = "default_domain")]
    pub rtps_domain: u16,
    /// Latency against payload size.
    pub payload: PayloadSweep,
    /// Convergence with and without faults.
    pub faults: FaultExperiment,
    /// Reconvergence after a partition.
    pub partition: PartitionExperiment,
    /// The scheduler timeline of a detector under an injected overload ([`crate::timeline`]); optional.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub timeline: Option<TimelineExperiment>,
    /// Detector roles in agent processes during a replay over RTPS ([`crate::roles`]); optional.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub roles: Option<RolesExperiment>,
    /// Control traffic against the number of agents in the seeded simulator ([`crate::scaling`]); optional.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scaling: Option<ScalingExperiment>,
    /// Payloads from one writer to receiver processes by every path, beside the machine's limit
    /// ([`crate::bench::payload`]); optional.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub payload_paths: Option<PayloadPathsExperiment>,
}

impl ExperimentSet {
    /// Number of runs, for progress bars.
    pub fn steps(&self) -> u64 {
        (self.logs.len() * self.agents.len() * self.seeds.len() * self.transports.len()
            + self.payload.sizes.len()
            + self.faults.variants.len() * self.faults.transports.len()
            + self.partition.repetitions as usize * self.partition.transports.len()
            + usize::from(self.timeline.is_some())
            + usize::from(self.roles.is_some())
            + self.scaling.as_ref().map_or(0, |s| s.agents.len())
            + self.payload_paths.as_ref().map_or(0, PayloadPathsExperiment::cells)) as u64
    }
}

/// Longest scheduler timeline accepted, ms (the records of every step are kept).
pub const MAX_TIMELINE_DURATION_MS: u64 = 60_000;

fn default_window_ms() -> u64 {
    250
}

fn default_miss_tolerance_us() -> u64 {
    SchedulerConfig::default().miss_tolerance_ns / 1_000
}

/// The experiment: an optional `timeline` section of an experiment set.
#[derive(Clone, Debug, PartialEq, Eq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct TimelineExperiment {
    /// The camera log whose images feed the detector (replayed on its recorded timing, looping).
    pub log: PathBuf,
    /// Period of the detector (and of its reader, labeller and the log camera), ms.
    pub period_ms: u64,
    /// Length of the run, ms.
    pub duration_ms: u64,
    /// Start of the overload window, ms after the start of the run.
    pub overload_from_ms: u64,
    /// End of the overload window (excluded), ms after the start of the run.
    pub overload_until_ms: u64,
    /// Period of the overloading component, ms.
    pub overload_period_ms: u64,
    /// Busy time of each of its steps that starts inside the window, ms.
    pub overload_busy_ms: u64,
    /// Width of the sliding window of the achieved frequency, ms.
    #[serde(default = "default_window_ms")]
    pub window_ms: u64,
    /// A step is a miss when its lateness exceeds this, µs (the scheduler's `miss_tolerance_ns`).
    #[serde(default = "default_miss_tolerance_us")]
    pub miss_tolerance_us: u64,
}

impl TimelineExperiment {
    /// Checks that the numbers make a run.
    ///
    /// # Errors
    /// A zero period or window, a window outside the run, a run longer than [`MAX_TIMELINE_DURATION_MS`].
    pub fn validate(&self) -> anyhow::Result<()> {
        anyhow::ensure!(self.period_ms > 0, "timeline: period_ms must be positive");
        anyhow::ensure!(self.overload_period_ms > 0, "timeline: overload_period_ms must be positive");
        anyhow::ensure!(self.window_ms > 0, "timeline: window_ms must be positive");
        anyhow::ensure!(
            self.duration_ms > 0 && self.duration_ms <= MAX_TIMELINE_DURATION_MS,
            "timeline: duration_ms must be in 1..={MAX_TIMELINE_DURATION_MS}, not {}",
            self.duration_ms
        );
        anyhow::ensure!(
            self.overload_from_ms < self.overload_until_ms && self.overload_until_ms <= self.duration_ms,
            "timeline: the overload window {}..{} ms must be non-empty and inside the run (0..{} ms)",
            self.overload_from_ms,
            self.overload_until_ms,
            self.duration_ms
        );
        Ok(())
    }
}

/// The `roles` section of an experiment set.
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct RolesExperiment {
    /// The log the bridge plays.
    pub log: LogSpec,
    /// Agents, the bridge included.
    pub agents: u32,
    /// Roles of agents 2, 3, ... (`ROLE[:NODE]`, as `cortex replay --roles`); the rest are plain agents.
    pub roles: Vec<String>,
    /// Faults injected into what every agent process receives (`cortex replay --faults`), if any.
    #[serde(default)]
    pub faults: Option<String>,
}

fn default_announce_group() -> u32 {
    agent::config::DEFAULT_ANNOUNCE_GROUP
}

/// Most agents in one run of the control-traffic simulation.
pub const MAX_SCALING_AGENTS: u32 = 1_024;
/// Longest measured window of the control-traffic simulation, ms of simulated time.
pub const MAX_SCALING_WINDOW_MS: u64 = 600_000;

/// The `scaling` section of an experiment set: control traffic (announces, missing-requests, repairs) beside the
/// data traffic, against the number of agents, in the seeded simulator ([`crate::scaling`]).
#[derive(Clone, Debug, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct ScalingExperiment {
    /// Numbers of agents, one run each.
    pub agents: Vec<u32>,
    /// Agents that write (the first ones; fewer if a run has fewer agents).
    pub writers: u32,
    /// Writes per second, all writers together (one float attribute each).
    pub write_rate_hz: f64,
    /// The measured window, ms of simulated time, after every agent has joined.
    pub window_ms: u64,
    /// The agents' base announce period, ms (`AgentConfig::announce_period`).
    pub announce_ms: u64,
    /// Agents whose announces fit in one period (`AgentConfig::announce_group`; 0: every agent announces every
    /// period, as before the group bound).
    #[serde(default = "default_announce_group")]
    pub announce_group: u32,
    /// Seed of the agents' nonces and of the writers' values.
    pub seed: u64,
}

impl ScalingExperiment {
    /// Checks the numbers.
    ///
    /// # Errors
    /// No run, fewer than 2 or more than [`MAX_SCALING_AGENTS`] agents in a run, no writer, a rate that is not
    /// positive and finite, an empty window or one over [`MAX_SCALING_WINDOW_MS`], a zero announce period.
    pub fn validate(&self) -> anyhow::Result<()> {
        anyhow::ensure!(!self.agents.is_empty(), "scaling: `agents` lists no run");
        if let Some(n) = self.agents.iter().find(|&&n| !(2..=MAX_SCALING_AGENTS).contains(&n)) {
            anyhow::bail!("scaling: {n} agents (2 to {MAX_SCALING_AGENTS})");
        }
        anyhow::ensure!(self.writers >= 1, "scaling: `writers` is 0");
        anyhow::ensure!(
            self.write_rate_hz.is_finite() && self.write_rate_hz > 0.0,
            "scaling: `write_rate_hz` {} is not a positive rate",
            self.write_rate_hz
        );
        anyhow::ensure!(
            (1..=MAX_SCALING_WINDOW_MS).contains(&self.window_ms),
            "scaling: `window_ms` {} (1 to {MAX_SCALING_WINDOW_MS})",
            self.window_ms
        );
        anyhow::ensure!(self.announce_ms >= 1, "scaling: `announce_ms` is 0");
        Ok(())
    }
}

/// How long the source of a [`Link::Processes`] run probes, by default, before it gives up on a start of the
/// run's receivers ([`RunConfig::probe_window`]).
pub const PROBE_WINDOW: Duration = Duration::from_secs(30);

/// How an experiment runs.
#[derive(Clone, Debug)]
pub struct RunConfig {
    /// Agents, the source included (2 or more).
    pub agents: u32,
    /// How the endpoints are connected.
    pub link: Link,
    /// Seed of the fault injector.
    pub seed: u64,
    /// Faults applied to what each receiver receives (`None`: the bus alone).
    pub faults: Option<FaultConfig>,
    /// Capacity of each receiver's inbox (a full inbox drops, and the drop is counted). The in-process bus
    /// allocates and touches every slot when a receiver attaches (about 80 bytes each); RTPS inboxes are capped at
    /// 2^16. The default, 2^16, is 5 MB a receiver and holds every write of the longest bundled log's run (16,818).
    pub inbox_capacity: usize,
    /// How long to wait, after the last write, for every receiver to apply everything.
    pub settle_timeout: Duration,
    /// The program that runs a receiver process ([`Link::Processes`]): an executable taking
    /// `measure-receiver --spec JSON` and calling `measure::process::receiver_main`, e.g. the `cortex` binary.
    pub receiver_program: Option<std::path::PathBuf>,
    /// How long the source of a [`Link::Processes`] run probes for its receivers before it starts them again
    /// ([`PROBE_WINDOW`] by default; see `measure::process`).
    pub probe_window: Duration,
}

impl Default for RunConfig {
    fn default() -> Self {
        RunConfig {
            agents: 3,
            link: Link::InProc,
            seed: 1,
            faults: None,
            inbox_capacity: 1 << 16,
            settle_timeout: Duration::from_secs(20),
            receiver_program: None,
            probe_window: PROBE_WINDOW,
        }
    }
}

/// How a partition experiment runs.
#[derive(Clone, Debug)]
pub struct PartitionConfig {
    /// Agents (2 or more); the last one is isolated.
    pub agents: u32,
    /// How long the partition lasts.
    pub partition: Duration,
    /// Writes per second on each side during the partition.
    pub rate_hz: f64,
    /// The agents' anti-entropy announce period.
    pub announce_period: Duration,
    /// Seed of the fault injector.
    pub seed: u64,
    /// Background faults besides the partition (none by default).
    pub faults: FaultConfig,
    /// Give up waiting for equal digests after this long.
    pub timeout: Duration,
    /// How the agents are connected: [`Link::InProc`] or [`Link::Rtps`] (agents in this process either way).
    pub link: Link,
}

impl Default for PartitionConfig {
    fn default() -> Self {
        PartitionConfig {
            agents: 3,
            partition: Duration::from_millis(500),
            rate_hz: 100.0,
            announce_period: Duration::from_millis(100),
            seed: 1,
            faults: FaultConfig::default(),
            timeout: Duration::from_secs(10),
            link: Link::InProc,
        }
    }
}

/// How the endpoints of a run are connected.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Link {
    /// The in-process bus (`transport::inproc`): one copy handed to every inbox, no network.
    #[default]
    InProc,
    /// One RTPS participant (`transport::rtps`, rustdds) per endpoint, all in this process, over loopback UDP.
    Rtps {
        /// DDS domain id (each run also takes topics of its own).
        domain_id: u16,
    },
    /// Every receiver a separate process with its own RTPS participant (see [`crate::process`]), over loopback UDP;
    /// the source is this process. Needs [`RunConfig::receiver_program`].
    Processes {
        /// DDS domain id (each run also takes topics of its own).
        domain_id: u16,
    },
}

impl Link {
    /// `inproc` or `rtps`.
    pub fn name(self) -> &'static str {
        match self {
            Link::InProc => "inproc",
            Link::Rtps { .. } => "rtps",
            Link::Processes { .. } => "rtps-processes",
        }
    }
}
