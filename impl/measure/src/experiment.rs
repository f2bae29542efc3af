//! Experiment files and the runner of an experiment set.
//!
//! An experiment file (TOML, in `experiments/`) names a `quick` and a `full` [`ExperimentSet`]: the logs to replay
//! (each with its rate and loops), the numbers of agents and the seeds of the replay sweep, a payload-size sweep of
//! synthetic writes, fault-injection variants, and the partition experiment. Relative paths are resolved against
//! the repository root, the parent of the directory that holds the file (`experiments/..`).
//!
//! [`run_set`] runs a set in process and returns [`Results`]: every measurement with its provenance, ready to be
//! written as JSON and rendered by [`crate::report`].

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::Context as _;
use replay::Rate;
use serde::{Deserialize, Serialize};
use transport::fault::FaultConfig;

use crate::partition::{self, PartitionConfig, PartitionResult};
use crate::provenance::{DatasetChecksum, Provenance};
use crate::roles::{self, RolesExperiment, RolesResult};
use crate::run::{self, Link, RunConfig, RunResult};
use crate::timeline::{self, TimelineExperiment, TimelineResult};
use crate::workload::{self, Workload};

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

fn link(name: &str, domain_id: u16) -> anyhow::Result<Link> {
    match name {
        "inproc" => Ok(Link::InProc),
        "rtps" => Ok(Link::Rtps { domain_id }),
        "rtps-processes" => Ok(Link::Processes { domain_id }),
        other => anyhow::bail!("unknown transport {other:?} (inproc, rtps or rtps-processes)"),
    }
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
        let ms = |v: f64| (v.max(0.0) * 1e6) as u64;
        let config = FaultConfig {
            duplicate: self.duplicate,
            reorder: self.reorder,
            reorder_ns: ms(self.reorder_ms),
            delay_ns: (ms(self.delay_ms[0]), ms(self.delay_ms[1]).max(ms(self.delay_ms[0]))),
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
}

impl ExperimentSet {
    /// Number of runs, for progress bars.
    pub fn steps(&self) -> u64 {
        (self.logs.len() * self.agents.len() * self.seeds.len() * self.transports.len()
            + self.payload.sizes.len()
            + self.faults.variants.len() * self.faults.transports.len()
            + self.partition.repetitions as usize * self.partition.transports.len()
            + usize::from(self.timeline.is_some())
            + usize::from(self.roles.is_some())) as u64
    }
}

/// A run of one fault variant.
#[derive(Clone, Debug, Serialize)]
pub struct FaultRun {
    /// The variant's label.
    pub label: String,
    /// The run.
    pub run: RunResult,
}

/// Everything a set measured. (`timeline` was added to schema version 1 without a bump: a new field, absent when
/// the set has no timeline.)
#[derive(Clone, Debug, Serialize)]
pub struct Results {
    /// How it was obtained.
    pub provenance: Provenance,
    /// The experiment file's name.
    pub experiment: String,
    /// `quick` or `full`.
    pub mode: String,
    /// The set as run.
    pub set: ExperimentSet,
    /// Replay sweep: one run per log, number of agents and seed.
    pub replay: Vec<RunResult>,
    /// Payload sweep: one run per size.
    pub payload: Vec<RunResult>,
    /// Fault variants.
    pub faults: Vec<FaultRun>,
    /// Partition runs.
    pub partition: Vec<PartitionResult>,
    /// The scheduler timeline, if the set has one.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub timeline: Option<TimelineResult>,
    /// The detector roles' replay over RTPS, if the set has one (added to schema version 1 like `timeline`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub roles: Option<RolesResult>,
    /// Wall-clock seconds of the whole set.
    pub seconds: f64,
}

fn rate(text: &str) -> anyhow::Result<Rate> {
    text.parse::<Rate>().map_err(|e| anyhow::anyhow!(e))
}

fn plan(root: &Path, spec: &LogSpec) -> anyhow::Result<Workload> {
    workload::from_log(&root.join(&spec.path), rate(&spec.rate)?, spec.loops)
}

/// Runs `set` (relative paths against `root`), calling `progress` with a label after each run. Runs over
/// `rtps-processes` start `receiver_program` (the `cortex` binary) for every receiver.
///
/// # Errors
/// A log that cannot be read, an invalid rate, an unknown transport, `rtps-processes` without a receiver program,
/// or a run that fails.
pub fn run_set(
    set: &ExperimentSet,
    root: &Path,
    experiment: &str,
    mode: &str,
    receiver_program: Option<&Path>,
    progress: &mut dyn FnMut(&str),
) -> anyhow::Result<Results> {
    let started = Instant::now();
    let mut provenance = Provenance::current();
    let mut seen = BTreeMap::new();
    for spec in set.logs.iter().chain([&set.faults.log]) {
        if seen.insert(spec.path.clone(), ()).is_none() {
            let checksum = DatasetChecksum::of(&root.join(&spec.path))
                .with_context(|| format!("cannot read {}", spec.path.display()))?;
            provenance.datasets.push(checksum);
        }
    }
    for path in set.timeline.as_ref().map(|t| &t.log).into_iter().chain(set.roles.as_ref().map(|r| &r.log.path)) {
        if seen.insert(path.clone(), ()).is_none() {
            let checksum =
                DatasetChecksum::of(&root.join(path)).with_context(|| format!("cannot read {}", path.display()))?;
            provenance.datasets.push(checksum);
        }
    }
    for (i, seed) in set.seeds.iter().enumerate() {
        provenance.seeds.insert(format!("replay[{i}]"), *seed);
    }
    provenance.seeds.insert("payload".into(), 1);
    provenance.seeds.insert("faults".into(), 1);
    provenance.seeds.insert("partition_first_of_1_to_repetitions".into(), 1);

    let links = set.transports.iter().map(|t| link(t, set.rtps_domain)).collect::<anyhow::Result<Vec<_>>>()?;
    let fault_links =
        set.faults.transports.iter().map(|t| link(t, set.rtps_domain)).collect::<anyhow::Result<Vec<_>>>()?;
    let payload_link = link(&set.payload.transport, set.rtps_domain)?;
    let base = RunConfig { receiver_program: receiver_program.map(Path::to_path_buf), ..RunConfig::default() };
    let mut replay = Vec::new();
    for spec in &set.logs {
        let workload = plan(root, spec)?;
        for &link in &links {
            for &agents in &set.agents {
                for &seed in &set.seeds {
                    let result = run::run(&workload, &RunConfig { agents, seed, link, ..base.clone() })
                        .with_context(|| format!("{} with {agents} agents over {}", workload.name, link.name()))?;
                    progress(&format!("{} {} N={agents} seed {seed}", workload.name, link.name()));
                    replay.push(result);
                }
            }
        }
    }
    let mut payload = Vec::new();
    for &size in &set.payload.sizes {
        let workload = workload::synthetic(size, set.payload.rate_hz, set.payload.count, 1)?;
        let config = RunConfig { agents: set.payload.agents, seed: 1, link: payload_link, ..base.clone() };
        payload.push(run::run(&workload, &config).with_context(|| format!("payload {size} B"))?);
        progress(&format!("payload {size} B"));
    }
    let mut faults = Vec::new();
    let workload = plan(root, &set.faults.log)?;
    for &link in &fault_links {
        for variant in &set.faults.variants {
            let injected = variant.config();
            let config = RunConfig { agents: set.faults.agents, seed: 1, link, faults: injected, ..base.clone() };
            let run = run::run(&workload, &config)
                .with_context(|| format!("faults {} over {}", variant.label, link.name()))?;
            faults.push(FaultRun { label: variant.label.clone(), run });
            progress(&format!("faults {} ({})", variant.label, link.name()));
        }
    }
    let mut partitions = Vec::new();
    for name in &set.partition.transports {
        let link = link(name, set.rtps_domain)?;
        for seed in 1..=u64::from(set.partition.repetitions) {
            let config = PartitionConfig {
                agents: set.partition.agents,
                partition: Duration::from_millis(set.partition.partition_ms),
                rate_hz: set.partition.rate_hz,
                announce_period: Duration::from_millis(set.partition.announce_ms),
                seed,
                link,
                ..PartitionConfig::default()
            };
            partitions
                .push(partition::run(&config).with_context(|| format!("partition over {} seed {seed}", link.name()))?);
            progress(&format!("partition {} seed {seed}", link.name()));
        }
    }
    let timeline = match &set.timeline {
        Some(experiment) => {
            let result = timeline::run(experiment, root).context("scheduler timeline")?;
            progress("scheduler timeline");
            Some(result)
        }
        None => None,
    };
    let roles = match &set.roles {
        Some(experiment) => {
            let program = receiver_program.context("the roles replay needs the cortex binary to start agents")?;
            let result = roles::run(experiment, root, program, set.rtps_domain).context("detector roles replay")?;
            progress("detector roles over RTPS");
            Some(result)
        }
        None => None,
    };
    Ok(Results {
        provenance,
        experiment: experiment.to_owned(),
        mode: mode.to_owned(),
        set: set.clone(),
        replay,
        payload,
        faults,
        partition: partitions,
        timeline,
        roles,
        seconds: started.elapsed().as_secs_f64(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_bundled_paper_file_parses_and_its_paths_exist() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../experiments/paper.toml");
        let file = ExperimentFile::load(&path).unwrap();
        let root = ExperimentFile::root_of(&path);
        for set in [&file.quick, &file.full] {
            for spec in set.logs.iter().chain([&set.faults.log]) {
                assert!(root.join(&spec.path).is_file(), "{}", spec.path.display());
                rate(&spec.rate).unwrap();
            }
            assert!(set.faults.variants.iter().any(|v| v.config().is_none()), "a variant without faults");
            assert!(set.steps() > 0);
            let timeline = set.timeline.as_ref().expect("the paper's sets measure the scheduler timeline");
            timeline.validate().unwrap();
            assert!(root.join(&timeline.log).is_file(), "{}", timeline.log.display());
        }
    }

    #[test]
    fn unknown_fields_are_refused() {
        let error = toml::from_str::<LogSpec>("path = \"a\"\nrate = \"1\"\nspeed = 2\n").unwrap_err();
        assert!(error.to_string().contains("speed"), "{error}");
        let timeline = "log = \"a\"\nperiod_ms = 50\nduration_ms = 3000\noverload_from_ms = 1000\n\
                        overload_until_ms = 2000\noverload_period_ms = 100\noverload_busy_ms = 120\nbusy_ms = 1\n";
        let error = toml::from_str::<TimelineExperiment>(timeline).unwrap_err();
        assert!(error.to_string().contains("busy_ms"), "{error}");
    }
}
