//! The `cortex` command: one binary for the project's tools, so that every experiment, check and report is run
//! the same way. This file only parses the command line and hands each subcommand to its module in
//! [`commands`]; errors come back as `anyhow` chains and are printed as one line on standard error with exit
//! code 1 (clap's own usage errors exit with 2).

use std::process::ExitCode;

use clap::{Parser, Subcommand};

mod commands;
mod memory;

/// Tools for the DSR_d working memory: CORTEX graphs now; model checks, agents, benchmarks, replays and reports
/// as they arrive.
#[derive(Debug, Parser)]
#[command(name = "cortex", version, about)]
struct Cli {
    /// What to do.
    #[command(subcommand)]
    command: Command,
}

/// The subcommands. Each lives in its own module under `commands/`.
#[derive(Debug, Subcommand)]
enum Command {
    /// Inspect and convert CORTEX JSON graphs.
    Graph(commands::graph::GraphArgs),
    /// Model-check the real implementation (convergence, scheduler, mutants).
    Check(commands::check::CheckArgs),
    /// Replay a ROS 2 MCAP log into the graph through a bridge agent.
    Replay(commands::replay::ReplayArgs),
    /// Check the bundled datasets against their manifest.
    Datasets(commands::datasets::DatasetsArgs),
    /// Run one DSR_d agent over RTPS until interrupted.
    Agent(commands::agent::AgentArgs),
    /// Measure agents: round-trip time and graph join.
    Bench(commands::bench::BenchArgs),
    /// Live bridges between the graph and other middleware: `bridge ros2 --config FILE.toml`.
    Bridge(commands::bridge::BridgeArgs),
    /// DDS Security: `security init DIR` makes a test PKI (CA, identities, governance, permissions).
    Security(commands::security::SecurityArgs),
    /// Serve a web inspector of the live graph and the BICA debug primitives.
    Inspect(commands::inspect::InspectArgs),
    /// Run an experiment set and write a report (results.json, figures, report.md).
    Report(commands::report::ReportArgs),
    /// A Jepsen-style fault campaign on agent processes in network namespaces (needs root).
    Chaos(commands::chaos::ChaosArgs),
    /// An agent process of a chaos campaign (started by `cortex chaos`).
    #[command(hide = true)]
    ChaosAgent(commands::chaos::serve::ChaosAgentArgs),
    /// A receiver process of a measured run (started by `cortex report`).
    #[command(hide = true)]
    MeasureReceiver(commands::receiver::ReceiverArgs),
}

/// The log filter without `RUST_LOG`: warnings, except `rustdds`'s report (at ERROR) that a NACK of a large sample
/// names more than 256 missing fragments and is cut to 256, which it is by design (the rest are asked for in the next
/// round); a reader repairing a camera frame after a partition printed it ~100,000 times in 40 s.
const DEFAULT_LOG: &str = "warn,rustdds::structure::sequence_number=off";

/// Sends log records to standard error, filtered by `RUST_LOG` (default [`DEFAULT_LOG`]): this program's `tracing` events and,
/// through the `log` bridge, the `log` records of `rustdds`. Standard output stays for results (JSON status lines,
/// reports), so a reader of those never sees a log line.
fn init_logging() {
    use std::io::IsTerminal;
    use tracing_subscriber::filter::{EnvFilter, LevelFilter};
    let filter = match std::env::var("RUST_LOG") {
        Ok(directives) => EnvFilter::builder().with_default_directive(LevelFilter::WARN.into()).parse_lossy(directives),
        Err(_) => EnvFilter::new(DEFAULT_LOG),
    };
    // `try_init` also installs the `log` bridge (the `tracing-log` feature). It fails only if a subscriber is
    // already set, which nothing here does.
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_ansi(std::io::stderr().is_terminal())
        .try_init();
}

fn main() -> ExitCode {
    if !memory::keep_freed_memory() {
        eprintln!("note: the allocator keeps its defaults: frame-sized buffers are mapped afresh (see memory.rs)");
    }
    init_logging();
    let cli = Cli::parse();
    let outcome = match cli.command {
        Command::Graph(args) => commands::graph::run(args),
        Command::Check(args) => commands::check::run(args),
        Command::Replay(args) => commands::replay::run(args),
        Command::Datasets(args) => commands::datasets::run(args),
        Command::Agent(args) => commands::agent::run(args),
        Command::Bench(args) => commands::bench::run(args),
        Command::Bridge(args) => commands::bridge::run(args),
        Command::Inspect(args) => commands::inspect::run(args),
        Command::Security(args) => commands::security::run(args),
        Command::Report(args) => commands::report::run(args),
        Command::MeasureReceiver(args) => commands::receiver::run(args),
        Command::ChaosAgent(args) => commands::chaos::serve::run(args),
        Command::Chaos(args) => match commands::chaos::run(args) {
            Ok(true) => Ok(()),
            Ok(false) => return ExitCode::from(commands::chaos::EXIT_VIOLATION),
            Err(error) => Err(error),
        },
    };
    match outcome {
        Ok(()) => ExitCode::SUCCESS,
        Err(error) => {
            eprintln!("error: {error:#}");
            ExitCode::FAILURE
        }
    }
}
