//! `cortex check`: the Stateright model checks of the real implementation (see the `model` crate).
//!
//! `convergence` checks the DSR replica, `agents` the agent protocol's core between agents with faults,
//! `scheduler` the BICA scheduler core, `mutants` plants each known bug and
//! checks that a model kills it (only in a build with the `mutants` feature, so a normal build cannot plant bugs).
//! Text output by default, the full report with `--json`; a progress line on standard error while checking. Exit
//! code 1 when a property fails, or (for `mutants`) when a mutant survives.

use std::net::{SocketAddr, TcpListener};
use std::time::Duration;

use anyhow::{Context, Result, bail};
use clap::{Args, Subcommand};
use model::convergence::{ConvergenceConfig, NetworkKind};
use model::scheduler::{SchedulerModelConfig, TopLevelSpec};
use model::{CheckOptions, CheckReport, Search};
use stateright::{Checker, Model};

/// Arguments of `cortex check`.
#[derive(Debug, Args)]
pub struct CheckArgs {
    /// Which model.
    #[command(subcommand)]
    what: CheckCommand,
}

#[derive(Debug, Subcommand)]
enum CheckCommand {
    /// CRDT convergence of the real DSR replica under any delivery order, duplication or loss.
    Convergence(ConvergenceArgs),
    /// The real agent protocol core between N agents: loss, duplication, reordering, crashes and restarts, cuts.
    Agents(AgentsArgs),
    /// Graceful degradation of the real BICA scheduler core on a virtual clock.
    Scheduler(SchedulerArgs),
    /// Plant every known bug and check that the models kill it (needs a build with `--features mutants`).
    Mutants(MutantsArgs),
}

/// Options shared by the checks.
#[derive(Debug, Args)]
struct CommonArgs {
    /// Print the whole report as JSON.
    #[arg(long)]
    json: bool,
    /// Checker threads.
    #[arg(long, default_value_t = 2)]
    threads: usize,
    /// Breadth-first search (shortest counterexamples) instead of depth-first.
    #[arg(long)]
    bfs: bool,
    /// Stop after this many seconds (the report then says the search is incomplete).
    #[arg(long)]
    timeout_s: Option<u64>,
    /// Serve Stateright's web Explorer on this address (e.g. 127.0.0.1:3000) instead of checking.
    #[arg(long, value_name = "ADDR")]
    explore: Option<SocketAddr>,
}

impl CommonArgs {
    fn options(&self) -> CheckOptions {
        CheckOptions {
            search: if self.bfs { Search::Bfs } else { Search::Dfs },
            threads: self.threads,
            timeout: self.timeout_s.map(Duration::from_secs),
            progress: true,
        }
    }
}

#[derive(Debug, Args)]
struct ConvergenceArgs {
    /// Number of replicas.
    #[arg(long, default_value_t = 3)]
    replicas: usize,
    /// Total operation budget, shared by all replicas.
    #[arg(long, default_value_t = 3)]
    ops: usize,
    /// unordered-duplicating, unordered-nonduplicating or lossy.
    #[arg(long, default_value = "unordered-nonduplicating", value_parser = parse_network)]
    network: NetworkKind,
    /// Clock advances (each moves one replica's physical clock ahead just before one of its operations), shared
    /// by all replicas.
    #[arg(long, default_value_t = 1)]
    ticks: usize,
    /// Anti-entropy announces (a replica's applied operations to one peer, answered with deltas or a
    /// snapshot), shared by all replicas.
    #[arg(long, default_value_t = 0)]
    syncs: usize,
    /// Deltas each replica keeps for anti-entropy (with loss or announces); older gaps get a snapshot.
    #[arg(long, default_value_t = 1)]
    history: usize,
    /// Writes of at least this many attribute payload bytes fold the retained writes they overwrite (0: every
    /// write; 8: the RT edge's writes fold and the 4 B `level` writes are kept apart).
    #[arg(long, default_value_t = 0)]
    fold_min_bytes: usize,
    #[command(flatten)]
    common: CommonArgs,
}

fn parse_network(text: &str) -> Result<NetworkKind, String> {
    text.parse()
}

#[derive(Debug, Args)]
struct AgentsArgs {
    /// Number of agents.
    #[arg(long, default_value_t = 2)]
    agents: usize,
    /// Local writes, shared by all agents.
    #[arg(long, default_value_t = 2)]
    writes: usize,
    /// Messages the network may lose.
    #[arg(long, default_value_t = 1)]
    losses: usize,
    /// Messages the network may deliver twice.
    #[arg(long, default_value_t = 0)]
    duplicates: usize,
    /// Crashes (each may be followed by a restart as a new life).
    #[arg(long, default_value_t = 1)]
    crashes: usize,
    /// Network cuts (each may heal).
    #[arg(long, default_value_t = 1)]
    cuts: usize,
    /// Timer ticks, shared by all agents.
    #[arg(long, default_value_t = 4)]
    ticks: usize,
    /// Stops of a joining agent's process (SIGSTOP; each resumed later than the join wait).
    #[arg(long, default_value_t = 0)]
    stops: usize,
    /// Agents per announce group: with fewer than --agents, each agent announces every ⌈agents / group⌉
    /// periods once it has heard its peers.
    #[arg(long, default_value_t = agent::config::DEFAULT_ANNOUNCE_GROUP)]
    announce_group: u32,
    /// Announce intervals of silence after which an agent forgets a peer (running agents: 4; the model's 1 lets
    /// its few ticks reach a forgetting; 0: never).
    #[arg(long, default_value_t = 1)]
    peer_forget_intervals: u64,
    /// The agents name no graph (`cortex agent` without `--graph-id`): a first life that starts alone makes an
    /// unnamed graph of its own, which must move once the agents hear each other. Without it every agent names
    /// the one graph.
    #[arg(long)]
    unnamed: bool,
    #[command(flatten)]
    common: CommonArgs,
}

#[derive(Debug, Args)]
struct SchedulerArgs {
    /// Top-level components: the first three are two parents sharing a dependency and an independent logger;
    /// more are independent workers.
    #[arg(long, default_value_t = 3)]
    components: usize,
    /// Virtual-time horizon, ns of the model's clock.
    #[arg(long)]
    horizon_ns: Option<u64>,
    /// Overrunning runs allowed per path.
    #[arg(long)]
    overruns: Option<u8>,
    /// Activations/removals the checker may inject per path.
    #[arg(long)]
    list_changes: Option<u8>,
    #[command(flatten)]
    common: CommonArgs,
}

#[derive(Debug, Args)]
struct MutantsArgs {
    /// Print the results as JSON.
    #[arg(long)]
    json: bool,
    /// Check only the mutants whose name contains this text (`dsr::`, `bica::`, `agent::`, or a whole name such as
    /// `agent::AnnounceTimerLost`); repeat for several. Without it, every mutant.
    #[arg(long, value_name = "TEXT")]
    only: Vec<String>,
}

/// Runs `cortex check`.
pub fn run(args: CheckArgs) -> Result<()> {
    match args.what {
        CheckCommand::Convergence(args) => {
            if args.replicas < 2 || args.replicas > 5 {
                bail!("--replicas must be between 2 and 5 (got {})", args.replicas);
            }
            if args.ops + args.ticks + args.syncs > 12 {
                bail!(
                    "--ops, --ticks and --syncs add up to at most 12 (the state space grows exponentially with them)"
                );
            }
            let config = ConvergenceConfig {
                replicas: args.replicas,
                ops: args.ops,
                ticks: args.ticks,
                syncs: args.syncs,
                history: args.history,
                fold_min_payload_bytes: args.fold_min_bytes,
                network: args.network,
                ..Default::default()
            };
            if let Some(address) = args.common.explore {
                return explore(model::convergence::model(&config), address);
            }
            finish(model::check_convergence(&config, &args.common.options()), args.common.json)
        }
        CheckCommand::Agents(args) => {
            if args.agents < 2 || args.agents > 4 {
                bail!("--agents must be between 2 and 4 (got {})", args.agents);
            }
            let config = model::AgentsConfig {
                agents: args.agents,
                budgets: model::agents::Budgets {
                    writes: args.writes,
                    losses: args.losses,
                    duplicates: args.duplicates,
                    crashes: args.crashes,
                    cuts: args.cuts,
                    ticks: args.ticks,
                    stops: args.stops,
                },
                announce_group: args.announce_group,
                peer_forget_intervals: args.peer_forget_intervals,
                unnamed: args.unnamed,
                ..Default::default()
            };
            if let Some(address) = args.common.explore {
                return explore(model::agents::AgentsModel::new(config), address);
            }
            finish(model::check_agents(&config, &args.common.options()), args.common.json)
        }
        CheckCommand::Scheduler(args) => {
            let config = scheduler_config(&args)?;
            if let Some(address) = args.common.explore {
                return explore(model::SchedulerModel::new(config).map_err(anyhow::Error::msg)?, address);
            }
            finish(model::check_scheduler(config, &args.common.options()), args.common.json)
        }
        CheckCommand::Mutants(args) => mutants(args.json, &args.only),
    }
}

fn scheduler_config(args: &SchedulerArgs) -> Result<SchedulerModelConfig> {
    let mut config = SchedulerModelConfig::default();
    if args.components == 0 || args.components > 15 {
        bail!("--components must be between 1 and 15 (got {})", args.components);
    }
    config.components.truncate(args.components);
    for index in config.components.len()..args.components {
        config.components.push(TopLevelSpec {
            name: format!("worker{index}"),
            period_ns: 20,
            nominal_ns: 1,
            calls_dependency: false,
        });
    }
    if let Some(horizon) = args.horizon_ns {
        config.horizon_ns = horizon;
    }
    if let Some(overruns) = args.overruns {
        config.max_overruns = overruns;
    }
    if let Some(changes) = args.list_changes {
        config.max_list_changes = changes;
    }
    config.validate().map_err(anyhow::Error::msg).context("invalid scheduler model configuration")?;
    Ok(config)
}

fn finish(report: CheckReport, json: bool) -> Result<()> {
    if json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print!("{}", report.to_text());
    }
    let failed: Vec<&str> = report.failures().map(|p| p.name.as_str()).collect();
    if !failed.is_empty() {
        bail!("{} propert{} failed: {}", failed.len(), if failed.len() == 1 { "y" } else { "ies" }, failed.join("; "));
    }
    if !report.complete {
        bail!("the search did not finish (timeout): the verdicts cover only the states explored");
    }
    Ok(())
}

/// Serves Stateright's Explorer until the process is interrupted.
fn explore<M>(model: M, address: SocketAddr) -> Result<()>
where
    M: Model + Send + Sync + 'static,
    M::State: Clone + std::fmt::Debug + std::hash::Hash + PartialEq + Send + Sync + 'static,
    M::Action: Clone + std::fmt::Debug + PartialEq + Send + Sync + 'static,
{
    // Stateright's server panics if it cannot bind; check first so the user gets an error, not a panic.
    drop(TcpListener::bind(address).with_context(|| format!("cannot listen on {address}"))?);
    let checker = model.checker().threads(1).serve(address);
    eprintln!("Stateright Explorer on http://{address}/ (Ctrl-C to stop)");
    loop {
        std::thread::park_timeout(Duration::from_secs(3600));
        let _ = checker.unique_state_count();
    }
}

#[cfg(feature = "mutants")]
fn mutants(json: bool, only: &[String]) -> Result<()> {
    let wanted = |name: &str| only.is_empty() || only.iter().any(|text| name.contains(text.as_str()));
    if !model::mutants::mutant_names().iter().any(|name| wanted(name)) {
        bail!(
            "no mutant's name contains {}; the mutants are: {}",
            only.join(" or "),
            model::mutants::mutant_names().join(", ")
        );
    }
    let results = model::mutants::check_mutants(false, &wanted);
    if json {
        println!("{}", serde_json::to_string_pretty(&results)?);
    } else {
        for result in &results {
            let verdict = if result.killed { "killed" } else { "SURVIVED" };
            println!(
                "{:<44} {verdict:<9} {} states, {:.2} s",
                result.mutant, result.report.unique_states, result.report.seconds
            );
            for property in &result.killed_by {
                println!("    violated: {property}");
            }
            if let Some(path) = &result.counterexample {
                for (index, action) in path.actions.iter().enumerate() {
                    println!("    {:>3}. {action}", index + 1);
                }
            }
        }
    }
    let survivors: Vec<&str> = results.iter().filter(|r| !r.killed).map(|r| r.mutant.as_str()).collect();
    if !survivors.is_empty() {
        bail!("{} mutant(s) survived: {}", survivors.len(), survivors.join(", "));
    }
    Ok(())
}

#[cfg(not(feature = "mutants"))]
fn mutants(_json: bool, _only: &[String]) -> Result<()> {
    bail!(
        "this build cannot plant mutants (they exist only behind the `mutants` feature); run \
         `cargo run --release -p harness --features mutants -- check mutants`"
    )
}
