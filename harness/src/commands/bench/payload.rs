//! `cortex bench payload` and its hidden receiver helper `cortex bench payload-receiver`: payloads from one writer
//! to N receiver processes by every path (`measure::spec::PayloadPath`: agents over each `cortex agent
//! --transport`, raw iceoryx2, memcpy), in one run (`measure::bench::payload`).
//!
//! The agent paths are `agent::Link::ALL`: a transport added there (the hybrid's `auto`) is a `--paths` value
//! and part of the default run with no change here.

use std::path::PathBuf;

use anyhow::{Context as _, Result};
use clap::Args;
use measure::bench::Counting;
use measure::bench::payload::{self, table};
use measure::netns::NetnsSetup;
use measure::spec::{PayloadPath, PayloadPathsExperiment};

use super::{NetnsMode, enter_netns, this_program};

/// `--paths`: one of [`PayloadPath::all`] by its name.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PathArg(pub PayloadPath);

crate::commands::value_enum_by_name!(PathArg, PayloadPath::all());

fn default_paths() -> Vec<PathArg> {
    PayloadPathsExperiment::default().paths.into_iter().map(PathArg).collect()
}

fn default_sizes() -> Vec<usize> {
    PayloadPathsExperiment::default().sizes
}

fn default_receivers() -> Vec<u32> {
    PayloadPathsExperiment::default().receivers
}

/// Arguments of `cortex bench payload`.
#[derive(Debug, Args)]
pub struct PayloadArgs {
    /// Payload sizes in bytes (at least 8).
    #[arg(long, value_delimiter = ',', default_values_t = default_sizes())]
    pub sizes: Vec<usize>,
    /// Numbers of receiver processes.
    #[arg(long, value_delimiter = ',', default_values_t = default_receivers())]
    pub receivers: Vec<u32>,
    /// The paths, in the order the table shows them.
    #[arg(long, value_enum, value_delimiter = ',', default_values_t = default_paths())]
    pub paths: Vec<PathArg>,
    /// Measured samples per size, receivers and path (after the warm-up samples).
    #[arg(long, default_value_t = PayloadPathsExperiment::default().count)]
    pub count: u32,
    /// Unmeasured samples of each size before the measured ones. Steady state for a large frame takes enough to
    /// fill a receiver's 64 MiB anti-entropy history (e.g. 20 for 4 MiB, 40 to be safe); before it, received frames
    /// land in heap pages never touched before, or leased frames leave the writer shared-memory chunks never touched.
    #[arg(long, default_value_t = PayloadPathsExperiment::default().warmup)]
    pub warmup: u32,
    /// Warm each size up to steady state, up to this many samples: a size whose frames fill a receiver's 64 MiB
    /// anti-entropy history within it gets the samples that fill it (190 for 360,960 B) when they are more than
    /// `--warmup`. 0: `--warmup` for every size.
    #[arg(long, default_value_t = PayloadPathsExperiment::default().steady_max)]
    pub steady_max: u32,
    /// Samples per second.
    #[arg(long, default_value_t = PayloadPathsExperiment::default().rate_hz)]
    pub rate_hz: f64,
    /// DDS domain id of the agents over RTPS.
    #[arg(long, default_value_t = 0)]
    pub domain: u16,
    /// Run in a fresh network namespace (multicast on `lo`) to count loopback bytes.
    #[arg(long, value_enum, default_value_t = NetnsMode::Auto)]
    pub netns: NetnsMode,
    /// Also write the result as one JSON object to this file.
    #[arg(long)]
    pub json: Option<PathBuf>,
}

/// Arguments of the payload receiver helper.
#[derive(Debug, Args)]
pub struct PayloadReceiverArgs {
    /// The path.
    #[arg(long, value_enum)]
    pub path: PathArg,
    /// DDS domain id.
    #[arg(long)]
    pub domain: u16,
    /// Topic prefix (agents) or service prefix (iceoryx2, the shared-memory transport).
    #[arg(long)]
    pub prefix: String,
    /// This receiver's index.
    #[arg(long)]
    pub index: u32,
}

/// Runs `cortex bench payload`: checks the arguments, enters a fresh network namespace when it can, measures and
/// prints the table (and writes `--json`).
pub(super) fn run(args: PayloadArgs) -> Result<()> {
    let experiment = PayloadPathsExperiment {
        sizes: args.sizes,
        receivers: args.receivers,
        paths: args.paths.iter().map(|p| p.0).collect(),
        count: args.count,
        rate_hz: args.rate_hz,
        warmup: args.warmup,
        steady_max: args.steady_max,
    };
    experiment.validate()?;
    let Some(counting) = enter_netns(args.netns, NetnsSetup { multicast: true })? else { return Ok(()) };
    if let Counting::EstimateOnly(why) = &counting {
        eprintln!("note: loopback bytes not counted ({why})");
    }
    let result = payload::run(&experiment, args.domain, &counting, &this_program()?, &mut |done| eprintln!("{done}"))?;
    print!("{}", table::text(&result));
    if let Some(path) = &args.json {
        let json = serde_json::to_string_pretty(&result)?;
        std::fs::write(path, json).with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(())
}

/// Runs the receiver helper: an agent receiver prints its report as one JSON line when told to stop.
pub(super) fn receiver(args: PayloadReceiverArgs) -> Result<()> {
    if let Some(report) = payload::receiver(args.path.0, args.domain, &args.prefix, args.index)? {
        println!("{}", serde_json::to_string(&report)?);
    }
    Ok(())
}
