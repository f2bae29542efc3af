//! # Measurements of DSR_d runs
//!
//! The numbers behind `cortex report`: how long an update takes from the source agent's write to its application
//! at every receiving agent, how long until every replica reflects a write and until all digests are equal, how
//! many bytes the transport put on the wire, and what the receivers cost in CPU — with the provenance (commit,
//! compiler, machine, seeds, dataset checksums) needed to read them later.
//!
//! The crate has three layers, and every `use crate::…` points down:
//!
//! 1. **Plain data** — [`spec`] (what to run: the experiment file, the runners' configurations, [`Link`]) and
//!    [`results`] (what was measured: [`RunResult`], [`results::WriteTimeline`],
//!    [`results::Results`], …), beside the leaf helpers [`units`] (the one place durations and bytes become
//!    display numbers), [`clock`], [`latency`], [`provenance`] and [`restart`] (starting receivers again).
//! 2. **Runners** that produce results: [`run`] (in-process runs, their source side in `source` and receiving
//!    side in `receiving`, shared with [`process`]: receivers as separate processes), [`partition`],
//!    [`replay_rtps`] (a log replayed over RTPS into `cortex agent` processes, its bridge agent playing the log
//!    with [`bridge_agent`]) and [`roles`] over it, [`timeline`], [`scaling`] (control traffic against the number
//!    of agents, in the seeded simulator), with [`workload`] (the planned writes), [`netns`] and [`usage`] (what
//!    the OS says a run cost), and [`experiment`], which runs a whole set.
//! 3. **Consumers** of results: [`report`] (`results.json`, the figures and `report.md`, one file per section),
//!    [`figures`] and [`lanes`] (SVG and PNG with an embedded font), and [`record`] (runs as MCAP files that
//!    Foxglove opens).
//!
//! Results serialise to JSON with [`SCHEMA_VERSION`]; a change that renames or removes a field bumps it.

pub mod bench;
pub mod bridge_agent;
pub mod clock;
pub mod experiment;
pub mod figures;
pub mod lanes;
pub mod latency;
pub mod netns;
pub mod partition;
pub mod process;
pub mod provenance;
mod receiving;
pub mod record;
pub mod replay_rtps;
pub mod report;
pub mod restart;
pub mod results;
pub mod roles;
pub mod run;
pub mod scaling;
mod source;
pub mod spec;
pub mod timeline;
pub mod units;
pub mod usage;
pub mod workload;

/// Version of the JSON result schema written by `cortex report` (`results.json`). 2: a run's `source_cpu_ns` and
/// `receiver_cpu_ns` are gone, `agent_costs` (CPU and memory per agent, the source first) holds them.
pub const SCHEMA_VERSION: u32 = 2;

pub use clock::MonoClock;
pub use latency::{LatencyRecorder, PayloadClass, Percentiles};
pub use provenance::Provenance;
pub use results::{AgentCost, RunResult};
pub use spec::{Link, RunConfig};
pub use workload::{PlannedWrite, Workload};
