//! Stateright models that check the implementation's own code.
//!
//! - [`convergence`]: replicas hold real [`dsr::Replica`] values and exchange real encoded deltas and snapshots
//!   over Stateright's networks, with checker-chosen operations, clock advances and anti-entropy; on every state the
//!   properties compare every replica with the others, with a fresh replica joining its deltas, with a late joiner
//!   installing its snapshot and with an independent reference specification ([`spec`]), and check its change
//!   events.
//! - [`agents`]: N real agent protocol cores ([`agent::core::AgentCore`]) exchange real encoded messages over a
//!   network that loses, duplicates and reorders, with ticks, crashes and restarts, and cuts that heal; the
//!   properties are unique lives, bounded buffers, and convergence to the specification once the faults stop.
//! - [`scheduler`]: the real [`bica`] scheduler core runs on a virtual clock with step durations chosen by the
//!   checker; the properties are the graceful-degradation guarantees of the BICA runtime.
//! - `mutants` (with the `mutants` feature): plants each known bug in the implementation and checks that a model
//!   kills it.
//! - [`report`]: runs a checker and reports states, timing and each property's verdict with its counterexample.

pub mod agents;
pub mod convergence;
#[cfg(feature = "mutants")]
pub mod mutants;
pub mod report;
pub mod scheduler;
pub mod spec;

pub use agents::{AgentsConfig, check_agents};
pub use convergence::{ConvergenceConfig, NetworkKind, check_convergence};
pub use report::{CheckOptions, CheckReport, CounterExample, PropertyResult, Search, run_check};
pub use scheduler::{SchedulerModel, SchedulerModelConfig, check_scheduler};
