//! `cortex measure-receiver` (hidden): the body of a receiver process of a measured run whose agents are separate
//! processes (`measure::process`). `cortex report` and `measure::run` start it; it prints one JSON report line.

use anyhow::Context as _;
use clap::Args;

/// Arguments of `cortex measure-receiver`.
#[derive(Debug, Args)]
pub struct ReceiverArgs {
    /// The receiver's specification, JSON (`measure::process::ReceiverSpec`).
    #[arg(long)]
    spec: String,
}

/// Runs one receiver process until it has every write, is stopped, or the source falls silent.
///
/// # Errors
/// A specification that is not valid JSON of the expected shape, or a DDS domain that cannot be joined.
pub fn run(args: ReceiverArgs) -> anyhow::Result<()> {
    let spec: measure::process::ReceiverSpec =
        serde_json::from_str(&args.spec).context("--spec is not a receiver specification")?;
    let report = measure::process::receiver_main(&spec)?;
    println!("{}", serde_json::to_string(&report)?);
    Ok(())
}
