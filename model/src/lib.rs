//! Stateright models that check the implementation's own code.
//!
//! - [`convergence`]: replicas hold real [`dsr::Replica`] values and exchange real deltas over Stateright's
//!   networks; the properties compare every replica with each other and with an independent reference
//!   specification ([`spec`]).
//! - [`scheduler`]: the real [`bica`] scheduler core runs on a virtual clock with step durations chosen by the
//!   checker; the properties are the graceful-degradation guarantees of the BICA runtime.
//! - [`mutants`]: with the `mutants` feature, plants each known bug and checks that some property fails.

pub mod report;
pub mod scheduler;

pub use report::{CheckOptions, CheckReport, CounterExample, PropertyResult, Search, run_check};
pub mod convergence;
pub mod spec;
pub use scheduler::{SchedulerModel, SchedulerModelConfig, check_scheduler};
