//! # Measurements of DSR_d runs
//!
//! The numbers behind `cortex report`: how long an update takes from the source agent's write to its application
//! at every receiving agent, how long until every replica reflects a write and until all digests are equal, how
//! many bytes the transport put on the wire, and what the receivers cost in CPU — with the provenance (commit,
//! compiler, machine, seeds, dataset checksums) needed to read them later.
//!
//! - [`clock`] — one monotonic clock for the whole run ([`clock::MonoClock`]), so a send time and a receive time
//!   on different threads are comparable (one host, one clock).
//! - [`latency`] — HDR histograms per payload class ([`latency::PayloadClass`]) and their percentiles.
//! - [`run`] — the in-process experiment: a planned sequence of encoded deltas (a replayed log or synthetic
//!   writes) published through a [`transport::Transport`] (the in-process bus, optionally behind the seeded fault
//!   injector) to N-1 receiver replicas on their own threads; per-write latencies, convergence windows, bytes.
//! - [`process`] — runs whose receivers are separate processes, each with its own RTPS participant: the body of a
//!   receiver process ([`process::receiver_main`]) and the source side that starts, probes and collects them.
//! - [`workload`] — the planned writes: a bundled ROS 2 log through the `replay` bridge, or synthetic byte
//!   attributes of a chosen size at a chosen rate.
//! - [`partition`] — agents (`agent::Agent`, with anti-entropy) on the in-process bus: the time to reconverge
//!   after a partition heals.
//! - [`timeline`] — the scheduler timeline of a detector (the `camera-detector` role of `perception`) on the real
//!   BICA runtime and clock, under an overload injected by another component of the same scheduler.
//! - [`experiment`] — experiment files (TOML) and the runner of a set of experiments.
//! - [`figures`] — line charts as SVG and PNG with an embedded font (no system font libraries).
//! - [`netns`] — exact wire bytes: re-run a measurement in a fresh network namespace and read its loopback
//!   counters ([`netns::LoopbackCounters`]) at phase boundaries; says why when a namespace cannot be made.
//! - [`provenance`] — commit, rustc, machine (cores, memory, CPU model from `/proc`), dataset checksums.
//!
//! - [`roles`] — detector roles in `cortex agent` processes during a replay over RTPS: their BICA statistics
//!   and the convergence of the graph, by running `cortex replay --transport rtps --roles ... --json`.
//! - [`report`] — `results.json`, the figures and `report.md` of an experiment set.
//! - [`record`] — runs as MCAP files that Foxglove opens: metrics on JSON-schema channels, the graph deltas as
//!   published.
//!
//! Results serialise to JSON with [`SCHEMA_VERSION`]; a change that renames or removes a field bumps it.

pub mod clock;
pub mod experiment;
pub mod figures;
pub mod lanes;
pub mod latency;
pub mod netns;
pub mod partition;
pub mod process;
pub mod provenance;
pub mod record;
pub mod report;
pub mod roles;
pub mod run;
pub mod timeline;
pub mod workload;

/// Version of the JSON result schema written by `cortex report` (`results.json`). 2: a run's `source_cpu_ns` and
/// `receiver_cpu_ns` are gone, `agent_costs` (CPU and memory per agent, the source first) holds them.
pub const SCHEMA_VERSION: u32 = 2;

pub use clock::MonoClock;
pub use latency::{LatencyRecorder, PayloadClass, Percentiles};
pub use provenance::Provenance;
pub use run::{AgentCost, Link, RunConfig, RunResult};
pub use workload::{PlannedWrite, Workload};
