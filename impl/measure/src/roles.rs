//! Detector roles during a replay over RTPS: a log played by a bridge agent into `cortex agent` processes running
//! BICA roles (camera detector, laser detector, attention), optionally with faults injected where they receive.
//! It runs `cortex replay --transport rtps --roles ... --json` (the `cortex` binary given to
//! [`crate::experiment::run_set`]) and keeps what the replay reports: every role's BICA statistics (frequency
//! achieved, misses, skipped releases, lateness and step time, fetched by a remote call over the same DDS engine
//! just before the roles are quiesced), each agent's graph, and the time from the quiesce — when every writer has
//! stopped — until every agent had the bridge's digest (sampled from status lines every 100 ms, so that is its
//! resolution). The statistics calls come between the end of the replay and the quiesce; with injected loss a lost
//! call waits out its 1 s timeout, which is why the window is counted from the quiesce.

use std::path::Path;
use std::process::Command;

use anyhow::Context as _;

use crate::results::RolesResult;
use crate::spec::RolesExperiment;

pub use crate::results::{AgentRow, ComponentRow};

/// Runs the roles replay with `program` (the `cortex` binary) on DDS domain `domain`.
///
/// # Errors
/// The program cannot start, the replay fails (its standard error is quoted), or its output is not a summary.
pub fn run(experiment: &RolesExperiment, root: &Path, program: &Path, domain: u16) -> anyhow::Result<RolesResult> {
    let log = root.join(&experiment.log.path);
    let mut command = Command::new(program);
    command
        .arg("replay")
        .arg(&log)
        .args(["--transport", "rtps", "--json", "--domain", &domain.to_string()])
        .args(["--agents", &experiment.agents.to_string(), "--rate", &experiment.log.rate])
        .args(["--loop", &experiment.log.loops.to_string()]);
    if !experiment.roles.is_empty() {
        command.args(["--roles", &experiment.roles.join(",")]);
    }
    if let Some(faults) = &experiment.faults {
        command.args(["--faults", faults]);
    }
    let output = command.output().with_context(|| format!("cannot start {}", program.display()))?;
    if !output.status.success() {
        let stderr = String::from_utf8_lossy(&output.stderr);
        let tail: Vec<&str> = stderr.lines().rev().take(5).collect();
        anyhow::bail!(
            "the roles replay failed ({}): {}",
            output.status,
            tail.into_iter().rev().collect::<Vec<_>>().join("\n")
        );
    }
    serde_json::from_slice(&output.stdout).context("the roles replay printed no summary")
}
