//! One module per `cortex` subcommand; each has an `Args` type for clap and a `run` function that returns an
//! `anyhow::Result`. Later subcommands (`check`, `agent`, `bench`, `replay`, `report`, `inspect`) go beside
//! `graph`.

pub mod agent;
pub mod bench;
pub mod bridge;
pub mod chaos;
pub mod check;
pub mod datasets;
pub mod graph;
pub mod inspect;
pub mod receiver;
pub mod replay;
pub mod report;
pub mod security;
