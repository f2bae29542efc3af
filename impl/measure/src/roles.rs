//! Detector roles during a replay over RTPS: a log played by a bridge agent into `cortex agent` processes running
//! BICA roles (camera detector, laser detector, attention), optionally with faults injected where they receive.
//! It runs `cortex replay --transport rtps --roles ... --json` (the `cortex` binary given to
//! [`crate::experiment::run_set`]) and keeps what the replay reports: every role's BICA statistics (frequency
//! achieved, misses, skipped releases, lateness and step time, fetched by a remote call over the same DDS engine
//! just before the roles are quiesced), each agent's graph, and the time from the quiesce — when every writer has
//! stopped — until every agent had the bridge's digest (sampled from status lines every 100 ms, so that is its
//! resolution). The statistics calls come between the end of the replay and the quiesce; with injected loss a lost
//! call waits out its 1 s timeout, which is why the window is counted from the quiesce.

use std::fmt::Write as _;
use std::path::Path;
use std::process::Command;

use anyhow::Context as _;
use serde::{Deserialize, Serialize};

use crate::experiment::LogSpec;

/// Heading of the report's section.
pub const SECTION: &str = "## Detector roles over RTPS";

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

/// One component's BICA statistics, as `cortex replay` reports them (it uses this type).
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
pub struct ComponentRow {
    /// Component type name.
    pub name: String,
    /// Nominal frequency.
    pub nominal_hz: f64,
    /// Frequency achieved.
    pub achieved_hz: f64,
    /// Steps run.
    pub runs: u64,
    /// Deadline misses.
    pub misses: u64,
    /// Releases skipped after overruns.
    pub skipped_releases: u64,
    /// 99th percentile of lateness, ms.
    pub lateness_p99_ms: f64,
    /// 99th percentile of the step's wall time, ms.
    pub wall_p99_ms: f64,
}

/// One agent at the end of the replay, as `cortex replay` reports it (it uses this type).
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
pub struct AgentRow {
    /// Agent id (1 is the bridge).
    pub id: u32,
    /// `bridge`, `plain` or the role.
    pub role: String,
    /// Nodes in its graph.
    pub nodes: u64,
    /// Its graph digest.
    pub digest: String,
    /// Samples it received.
    pub samples_received: u64,
    /// Samples it published.
    pub samples_sent: u64,
    /// A role's components, with their statistics just before the role was quiesced.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub components: Vec<ComponentRow>,
    /// Why the statistics are missing, if the remote call failed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub components_error: Option<String>,
}

/// What the roles replay measured.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
pub struct RolesResult {
    /// Messages the bridge played.
    pub messages: u64,
    /// Deltas the bridge wrote.
    pub deltas: u64,
    /// Seconds of the replay.
    pub seconds: f64,
    /// Faults injected, as a specification.
    #[serde(default)]
    pub faults: Option<String>,
    /// Milliseconds from the quiesce (every writer stopped) until every agent had the bridge's digest (100 ms
    /// resolution).
    #[serde(default)]
    pub converged_ms: Option<f64>,
    /// Milliseconds from the end of the replay to the quiesce (the roles' statistics fetched meanwhile).
    #[serde(default)]
    pub quiesced_after_ms: Option<f64>,
    /// Whether every agent ended with the bridge's digest.
    pub digests_equal: bool,
    /// Every agent, the bridge first.
    #[serde(rename(deserialize = "agent_reports"))]
    pub agents: Vec<AgentRow>,
}

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

/// A type name without its module paths: `perception::sensors::SensorReader<perception::sensors::Camera>` →
/// `SensorReader<Camera>`.
pub fn short_type_name(name: &str) -> String {
    let mut out = String::with_capacity(name.len());
    let mut token = String::new();
    let flush = |token: &mut String, out: &mut String| {
        out.push_str(token.rsplit("::").next().unwrap_or(token));
        token.clear();
    };
    for c in name.chars() {
        if c.is_alphanumeric() || c == '_' || c == ':' {
            token.push(c);
        } else {
            flush(&mut token, &mut out);
            out.push(c);
        }
    }
    flush(&mut token, &mut out);
    out
}

/// Appends the report's section (nothing to say beyond "not run" when the set has no `roles` section).
pub fn section(md: &mut String, experiment: Option<&RolesExperiment>, result: Option<&RolesResult>) {
    let _ = writeln!(md, "{SECTION}\n");
    let (Some(e), Some(r)) = (experiment, result) else {
        let _ = writeln!(md, "Not run: this experiment set has no `roles` section.\n");
        return;
    };
    let _ = writeln!(
        md,
        "`cortex replay {} --transport rtps --agents {} --roles {} --rate {}{}`: the bridge agent (this process) plays \
         the log into {} `cortex agent` processes over RTPS, each a real agent (envelope, anti-entropy) running its \
         BICA role on the real clock; {}. After the replay the bridge fetches every role's BICA statistics by a \
         remote call (`runtime.components`), tells the roles to stop writing, and waits until every agent shows its \
         digest: {} ({} messages, {} deltas in {:.2} s).\n",
        e.log.path.display(),
        e.agents,
        e.roles.join(","),
        e.log.rate,
        e.faults.as_ref().map_or_else(String::new, |f| format!(" --faults {f}")),
        e.agents - 1,
        r.faults.as_ref().map_or_else(
            || "no faults injected".to_owned(),
            |f| format!("faults injected into what each agent process receives: `{f}`")
        ),
        match (r.digests_equal, r.converged_ms) {
            (true, Some(ms)) => format!(
                "every digest equal {ms:.0} ms after the writers stopped (100 ms resolution; the roles were told to \
                 stop writing {:.0} ms after the replay ended, once their statistics were fetched)",
                r.quiesced_after_ms.unwrap_or(0.0)
            ),
            _ => "**the digests did not become equal** within the settle time".to_owned(),
        },
        r.messages,
        r.deltas,
        r.seconds
    );
    let _ = writeln!(
        md,
        "Lateness is measured against each component's own release grid. A component stepped by its parent in the \
         cascade (the camera reader and colour labeller under the blob detector; the stimuli and head under the \
         search/track behaviour) runs when its parent runs, so a phase offset of up to one parent period shows as \
         lateness and misses there; the top of each cascade shows the scheduler's own lateness.\n"
    );
    let _ = writeln!(
        md,
        "| agent | role | nodes | samples received | component | achieved / nominal Hz | runs | misses | skipped | lateness p99 ms | step p99 ms |\n|---:|---|---:|---:|---|---:|---:|---:|---:|---:|---:|"
    );
    for a in &r.agents {
        if a.components.is_empty() {
            let note =
                a.components_error.as_deref().map_or("—".to_owned(), |e| format!("statistics unavailable: {e}"));
            let _ =
                writeln!(md, "| {} | {} | {} | {} | {note} | | | | | | |", a.id, a.role, a.nodes, a.samples_received);
        }
        for c in &a.components {
            let _ = writeln!(
                md,
                "| {} | {} | {} | {} | `{}` | {:.1} / {:.1} | {} | {} | {} | {:.2} | {:.2} |",
                a.id,
                a.role,
                a.nodes,
                a.samples_received,
                short_type_name(&c.name),
                c.achieved_hz,
                c.nominal_hz,
                c.runs,
                c.misses,
                c.skipped_releases,
                c.lateness_p99_ms,
                c.wall_p99_ms
            );
        }
    }
    let _ = writeln!(md);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_replay_summary_parses_into_the_result_and_the_section_shows_it() {
        let json = r#"{"file":"x.mcap","transport":"rtps","agents":2,"messages":10,"deltas":12,"seconds":1.5,
            "digests_equal":true,"converged_ms":120.5,"faults":"loss=0.1",
            "agent_reports":[{"id":1,"role":"bridge","nodes":5,"digest":"ab","samples_received":3,"samples_sent":9},
              {"id":2,"role":"camera-detector","nodes":5,"digest":"ab","samples_received":12,"samples_sent":2,
               "components":[{"name":"perception::blobs::BlobDetector","nominal_hz":10.0,"achieved_hz":9.9,"runs":15,
                 "misses":1,"skipped_releases":0,"lateness_p99_ms":0.5,"wall_p99_ms":0.1}]}]}"#;
        let result: RolesResult = serde_json::from_str(json).unwrap();
        assert_eq!(result.agents.len(), 2);
        assert_eq!(result.agents[1].components[0].runs, 15);
        let experiment = RolesExperiment {
            log: LogSpec { path: "x.mcap".into(), rate: "1".into(), loops: 1 },
            agents: 2,
            roles: vec!["camera-detector".into()],
            faults: Some("loss=0.1".into()),
        };
        let mut md = String::new();
        section(&mut md, Some(&experiment), Some(&result));
        assert!(
            md.contains("| 2 | camera-detector | 5 | 12 | `BlobDetector` | 9.9 / 10.0 | 15 | 1 | 0 | 0.50 | 0.10 |"),
            "{md}"
        );
        assert!(md.contains("every digest equal 120 ms after the writers stopped"), "{md}");
        assert_eq!(
            short_type_name("bica::fsm::Fsm<perception::behaviour::SearchTrack, perception::behaviour::Data>"),
            "Fsm<SearchTrack, Data>"
        );
        assert_eq!(short_type_name("Plain"), "Plain");
        let mut md = String::new();
        section(&mut md, None, None);
        assert!(md.contains("Not run"));
    }
}
