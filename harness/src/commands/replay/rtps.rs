//! `cortex replay --transport rtps`: the log played by a bridge agent in this process into `cortex agent`
//! processes over RTPS, plain or running the BICA roles of `--roles`. The replay is the runner
//! [`measure::replay_rtps::run`]; this module turns the arguments into its settings and its outcome into the
//! summary.

use std::time::Duration;

use anyhow::Context as _;
use measure::replay_rtps::{self, RtpsReplay};
use replay::BridgeOptions;
use replay::log::Log;

use super::config::Resolved;
use super::summary::{Recording, Summary, finish, summary};

/// Runs the RTPS replay of `log` (read in `read_seconds`) and prints its summary.
///
/// # Errors
/// The runner fails (see [`measure::replay_rtps::run`]), `--out` cannot be created, or the final digests differ.
pub(super) fn run(args: &Resolved, log: &Log, read_seconds: f64) -> anyhow::Result<()> {
    let settings = RtpsReplay {
        agents: args.agents,
        domain: args.domain,
        roles: args.roles.clone(),
        faults: args.faults,
        bridge: BridgeOptions { topics: args.topics.clone(), opaque: args.opaque },
        rate: args.rate,
        loops: args.loops,
        settle: Duration::from_millis(args.settle_ms),
        record: match &args.out {
            Some(dir) => {
                std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
                Some(dir.join("run.mcap"))
            }
            None => None,
        },
        program: std::env::current_exe().context("cannot find the cortex binary")?,
        quiet_agents: false,
    };
    let outcome = replay_rtps::run(log, &settings)?;
    let summary = Summary {
        delta_bytes: outcome.bridge_bytes,
        deliveries: outcome.agents.iter().skip(1).map(|a| a.samples_received).sum(),
        digests: outcome.agents.iter().map(|a| a.digest.clone()).collect(),
        digests_equal: outcome.digests_equal,
        faults: args.faults.map(|f| f.to_spec()),
        agent_reports: outcome.agents.clone(),
        converged_ms: outcome.converged_ms,
        quiesced_after_ms: Some(outcome.quiesced_after_ms),
        recording: outcome.recorded.map(|(path, messages)| Recording {
            path: path.display().to_string(),
            messages,
            latency: None,
            convergence: None,
        }),
        ..summary(
            args,
            log,
            "rtps",
            &outcome.played.drive,
            [read_seconds, outcome.seconds],
            outcome.played.bridge.clone(),
        )
    };
    finish(args, &summary)
}
