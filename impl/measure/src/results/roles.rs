//! What the detector roles' replay over RTPS measured ([`crate::roles`]); `cortex replay --json` prints these
//! types too.

use serde::{Deserialize, Serialize};

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
