//! `cortex replay`'s settings: the command line over a configuration file (`--config FILE.toml`) over the
//! defaults.

use std::path::{Path, PathBuf};

use anyhow::{Context as _, anyhow, bail};
use clap::ValueEnum as _;
use measure::replay_rtps::RoleSpec;
use replay::Rate;
use serde::Deserialize;
use transport::fault::FaultConfig;

use super::{ReplayArgs, Transport};

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
pub(super) struct Resolved {
    pub(super) file: PathBuf,
    pub(super) agents: u32,
    pub(super) transport: Transport,
    pub(super) rate: Rate,
    pub(super) loops: u32,
    pub(super) topics: Option<Vec<String>>,
    pub(super) recover: bool,
    pub(super) opaque: bool,
    pub(super) seed: u64,
    pub(super) window: usize,
    pub(super) domain: u16,
    pub(super) roles: Vec<RoleSpec>,
    pub(super) faults: Option<FaultConfig>,
    pub(super) settle_ms: u64,
    pub(super) json: bool,
    pub(super) out: Option<PathBuf>,
}

/// Reads `--config` (if any) and merges it under the command line.
pub(super) fn resolve(args: ReplayArgs) -> anyhow::Result<Resolved> {
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
