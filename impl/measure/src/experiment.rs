//! The runner of an experiment set: every run a set asks for, in order, with the provenance of the whole.
//!
//! [`run_set`] runs a set ([`crate::spec::ExperimentSet`], read from an experiment file) and returns
//! [`Results`]: every measurement with its provenance, ready to be written as JSON and rendered by
//! [`crate::report`].

use std::collections::BTreeMap;
use std::path::Path;
use std::time::{Duration, Instant};

use anyhow::Context as _;
use replay::Rate;

use crate::bench::{self, Counting};
use crate::provenance::{DatasetChecksum, Provenance};
use crate::results::{FaultRun, PartitionResult, Results, RunResult};
use crate::spec::{Link, LogSpec, PartitionConfig, RunConfig};
use crate::workload::{self, Workload};
use crate::{partition, roles, run, scaling, timeline};

pub use crate::spec::{ExperimentFile, ExperimentSet};

fn link(name: &str, domain_id: u16) -> anyhow::Result<Link> {
    match name {
        "inproc" => Ok(Link::InProc),
        "rtps" => Ok(Link::Rtps { domain_id }),
        "rtps-processes" => Ok(Link::Processes { domain_id }),
        other => anyhow::bail!("unknown transport {other:?} (inproc, rtps or rtps-processes)"),
    }
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
    // Every transport name is checked before the first run, so a typo does not cost a sweep.
    let names = set.transports.iter().chain(&set.faults.transports).chain(&set.partition.transports);
    for name in names.chain([&set.payload.transport]) {
        link(name, set.rtps_domain)?;
    }
    if let Some(experiment) = &set.payload_paths {
        experiment.validate()?;
    }
    let provenance = provenance_of(set, root)?;
    let base = RunConfig { receiver_program: receiver_program.map(Path::to_path_buf), ..RunConfig::default() };
    let replay = replay_sweep(set, root, &base, progress)?;
    let payload = payload_sweep(set, &base, progress)?;
    let faults = fault_variants(set, root, &base, progress)?;
    let partition = partitions(set, progress)?;
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
    let scaling = match &set.scaling {
        Some(experiment) => Some(scaling::run(experiment, progress).context("control traffic against agents")?),
        None => None,
    };
    let payload_paths = match &set.payload_paths {
        Some(experiment) => {
            let program = receiver_program.context("the payload paths need the cortex binary for their receivers")?;
            let counting = match crate::netns::inside() {
                Some(_) => Counting::Socket,
                None => Counting::EstimateOnly("not in a fresh network namespace".into()),
            };
            let result = bench::payload::run(experiment, set.rtps_domain, &counting, program, progress)
                .context("payload paths")?;
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
        partition,
        timeline,
        roles,
        scaling,
        payload_paths,
        seconds: started.elapsed().as_secs_f64(),
    })
}

/// The provenance of a run of `set` started now: the checksum of every dataset it reads (each once) and its seeds.
fn provenance_of(set: &ExperimentSet, root: &Path) -> anyhow::Result<Provenance> {
    let mut provenance = Provenance::current();
    let mut seen = BTreeMap::new();
    let logs = set.logs.iter().chain([&set.faults.log]).map(|spec| &spec.path);
    let optional = set.timeline.as_ref().map(|t| &t.log).into_iter().chain(set.roles.as_ref().map(|r| &r.log.path));
    for path in logs.chain(optional) {
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
    Ok(provenance)
}

/// One run per log, transport, number of agents and seed.
fn replay_sweep(
    set: &ExperimentSet,
    root: &Path,
    base: &RunConfig,
    progress: &mut dyn FnMut(&str),
) -> anyhow::Result<Vec<RunResult>> {
    let links = set.transports.iter().map(|t| link(t, set.rtps_domain)).collect::<anyhow::Result<Vec<_>>>()?;
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
    Ok(replay)
}

/// One run of synthetic writes per payload size.
fn payload_sweep(
    set: &ExperimentSet,
    base: &RunConfig,
    progress: &mut dyn FnMut(&str),
) -> anyhow::Result<Vec<RunResult>> {
    let payload_link = link(&set.payload.transport, set.rtps_domain)?;
    let mut payload = Vec::new();
    for &size in &set.payload.sizes {
        let workload = workload::synthetic(size, set.payload.rate_hz, set.payload.count, 1)?;
        let config = RunConfig { agents: set.payload.agents, seed: 1, link: payload_link, ..base.clone() };
        payload.push(run::run(&workload, &config).with_context(|| format!("payload {size} B"))?);
        progress(&format!("payload {size} B"));
    }
    Ok(payload)
}

/// One run of the fault experiment's log per transport and variant.
fn fault_variants(
    set: &ExperimentSet,
    root: &Path,
    base: &RunConfig,
    progress: &mut dyn FnMut(&str),
) -> anyhow::Result<Vec<FaultRun>> {
    let fault_links =
        set.faults.transports.iter().map(|t| link(t, set.rtps_domain)).collect::<anyhow::Result<Vec<_>>>()?;
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
    Ok(faults)
}

/// The partition runs: seeds 1 to `repetitions` per transport.
fn partitions(set: &ExperimentSet, progress: &mut dyn FnMut(&str)) -> anyhow::Result<Vec<PartitionResult>> {
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
    Ok(partitions)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::spec::TimelineExperiment;

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
