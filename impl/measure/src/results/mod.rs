//! What the runners measured: plain result types, serialised into `results.json`, read by the report, the figures
//! and the MCAP recordings. Data with small accessors and nothing else: no module here runs, draws or writes
//! anything, and none uses a runner or a consumer.

mod partition;
mod payload_paths;
mod roles;
mod run;
mod scaling;
mod timeline;

use serde::Serialize;

pub use partition::PartitionResult;
pub use payload_paths::{PAYLOAD_PATHS_LATENCY, PathRatios, PayloadCell, PayloadPathsResult};
pub use roles::{AgentRow, ComponentRow, RolesResult};
pub use run::{AgentCost, Bandwidth, MAX_TIMELINE_WRITES, RunResult, TimelineWrite, WriteTimeline};
pub use scaling::{CONTROL_KINDS, DATA_KINDS, KindTraffic, REPAIR_KINDS, ScalingRates, ScalingResult, ScalingRow};
pub use timeline::{PhaseSummary, StepRecord, Timeline, TimelineResult};

use crate::provenance::Provenance;
use crate::spec::ExperimentSet;

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
    /// Control traffic against the number of agents, if the set has a `scaling` section (added to schema version 2
    /// without a bump: a new field, absent when the set has none).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub scaling: Option<ScalingResult>,
    /// Payloads to receiver processes by every path beside the machine's limit, if the set has a `payload_paths`
    /// section (added to schema version 2 without a bump, like `scaling`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub payload_paths: Option<PayloadPathsResult>,
    /// Wall-clock seconds of the whole set.
    pub seconds: f64,
}
