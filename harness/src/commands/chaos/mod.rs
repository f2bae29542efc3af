//! `cortex chaos`: a Jepsen-style fault campaign on real agent processes. K agents (default 4), each a separate
//! `cortex chaos-agent` process in its own network namespace, joined by a bridge, so that to RTPS they are
//! separate hosts; writers running (node and edge inserts and deletes, attribute writes and removals, camera
//! frames); a seeded schedule of faults (random and one-way loss and partitions as `nftables` rules, `SIGSTOP` and
//! `SIGCONT`, `SIGKILL` and restart with and without a reachable peer, a late joiner); after each fault, heal and
//! measure the time until every agent shows the same graph; at the end, check the whole recorded history against
//! the reference specification.
//!
//! Modules: [`schedule`] (the seeded faults), [`net`] (namespaces and rules), [`procs`] (agent processes),
//! [`protocol`] (the lines between the campaign and its agents), [`workload`] (what an agent writes), [`serve`]
//! (the agent process), [`campaign`] (running one campaign), [`record`] (what it records), [`check`] (the verdict), [`output`] (files and figure).
//!
//! Exit code: 0 when every campaign passed, 3 when one found a violation (listed, and in `verdict.json`), 1 when a
//! campaign could not run (not root, `ip` or `nft` missing, a process that cannot start).

pub mod campaign;
pub mod check;
pub mod net;
pub mod output;
pub mod procs;
pub mod protocol;
pub mod record;
pub mod schedule;
pub mod serve;
pub mod workload;

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use anyhow::{Context, Result, bail};
use clap::Args;

use campaign::Campaign;
use output::{CampaignReport, Summary};
use record::CampaignConfig;
use schedule::{Fault, Schedule};

/// Exit code of a campaign that found a violation.
pub const EXIT_VIOLATION: u8 = 3;

/// Arguments of `cortex chaos`.
#[derive(Debug, Args)]
pub struct ChaosArgs {
    /// Seed of the fault schedule and of the writers' draws.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Run this many campaigns, seeds `seed`, `seed + 1`, ...
    #[arg(long, default_value_t = 1)]
    pub runs: u64,
    /// Agent processes (at least 3; the last joins late).
    #[arg(long, default_value_t = 4)]
    pub agents: usize,
    /// Rounds of faults (one of each kind per round, in a seeded order).
    #[arg(long, default_value_t = 1)]
    pub rounds: usize,
    /// How long each fault is on.
    #[arg(long, default_value_t = 3000)]
    pub fault_ms: u64,
    /// Writes per second per agent while the writers run.
    #[arg(long, default_value_t = 10.0)]
    pub write_hz: f64,
    /// Bytes of a camera frame (default: 640×480 mono).
    #[arg(long, default_value_t = 307_200)]
    pub image_bytes: usize,
    /// How long to wait for convergence after a heal before the campaign fails.
    #[arg(long, default_value_t = 60_000)]
    pub settle_ms: u64,
    /// How long a new agent life waits for a running agent's graph before starting alone.
    #[arg(long, default_value_t = 1500)]
    pub join_wait_ms: u64,
    /// DDS domain (the namespaces are the campaign's own, so any free domain works).
    #[arg(long, default_value_t = 42)]
    pub domain: u16,
    /// Output directory: one `seed-N/` per campaign (history.jsonl, verdict.json, timeline.svg/png, agent logs),
    /// and summary.json/summary.md.
    #[arg(long, default_value = "chaos-out")]
    pub out: PathBuf,
    /// Run every agent with DDS Security (a fresh test PKI per campaign, one identity per slot, submessages
    /// encrypted): the same faults and checks on a secured graph.
    #[arg(long)]
    pub security: bool,
    /// Run every agent in one network namespace, so that they are on one host to each other and move their samples
    /// through shared memory (the default transport's lanes; without this flag each agent is its own host and its
    /// lanes carry nothing). The schedule then has the process faults only (pause, kill+restart, late join): the
    /// network faults filter by namespace. Not with `--security` (shared memory would bypass it).
    #[arg(long, conflicts_with = "security")]
    pub same_host: bool,
    /// Give the agents no graph id (as `cortex agent` runs without `--graph-id`): a life that starts alone makes an
    /// unnamed graph of its own, and the lives that hear each other must end in one graph (an unnamed graph moves
    /// to a smaller id it hears). Without this flag every agent runs with the campaign's `--graph-id`. Not with
    /// `--security`: a secured deployment names its graph (README, "Graph identity").
    #[arg(long, conflicts_with = "security")]
    pub unnamed: bool,
    /// The fault kinds to draw from (default: every kind, or with `--same-host` the process faults), e.g.
    /// `--faults "stop at start,late join"`; the last agent starts only in a `late join` or a `late join alone` (one
    /// of them per campaign, whichever the seeded order of the first round puts first).
    #[arg(long, value_delimiter = ',')]
    pub faults: Vec<String>,
    /// Plant this protocol bug in every agent (an `agent::mutants::ProtocolMutant` name, e.g.
    /// `IncarnationForgotten`), to check that the campaign catches it. Only in a build with the `mutants` feature.
    #[cfg(feature = "mutants")]
    #[arg(long)]
    pub plant: Option<String>,
}

/// Runs `cortex chaos`; `Ok(false)` when a campaign found a violation.
pub fn run(args: ChaosArgs) -> Result<bool> {
    if args.agents < 3 {
        bail!("--agents {} is too few: a campaign needs at least 3 (the last joins late)", args.agents);
    }
    if args.agents > 200 || args.write_hz <= 0.0 || args.fault_ms < 500 {
        bail!("--agents must be at most 200, --write-hz positive and --fault-ms at least 500");
    }
    fault_kinds(&args)?;
    #[cfg(feature = "mutants")]
    if let Some(name) = &args.plant {
        serve::protocol_mutant(name)?;
    }
    net::preflight()?;
    let program = std::env::current_exe().context("finding the cortex binary")?;
    let interrupted = Arc::new(AtomicBool::new(false));
    {
        let interrupted = Arc::clone(&interrupted);
        ctrlc::set_handler(move || interrupted.store(true, Ordering::SeqCst))
            .context("installing the Ctrl-C handler")?;
    }
    std::fs::create_dir_all(&args.out).with_context(|| format!("creating {}", args.out.display()))?;
    let mut reports = Vec::new();
    for seed in args.seed..args.seed + args.runs {
        let report = run_one(&args, seed, &program, &interrupted)?;
        println!(
            "seed {seed}: {} — {} writes checked, {} episodes{}",
            if report.passed { "converged, nothing lost" } else { "FAILED" },
            report.verdict.writes,
            report.episodes.len(),
            report
                .episodes
                .iter()
                .map(|e| match e.heal_to_converge_ms {
                    Some(ms) => format!("; {} {ms:.0} ms", e.kind),
                    None => format!("; {} NOT CONVERGED", e.kind),
                })
                .collect::<String>()
        );
        for violation in &report.verdict.violations {
            println!("  violation: {violation}");
        }
        reports.push(report);
    }
    let summary = Summary::of(&reports);
    std::fs::write(args.out.join("summary.json"), serde_json::to_string_pretty(&summary)?)?;
    let markdown = summary.markdown();
    std::fs::write(args.out.join("summary.md"), &markdown)?;
    println!("\n{markdown}");
    Ok(summary.failed.is_empty())
}

/// The fault kinds of `--faults`, checked against the kinds the campaign can run; every one (every process fault
/// with `--same-host`) when none is given.
fn fault_kinds(args: &ChaosArgs) -> Result<Vec<&'static str>> {
    let possible: &[&'static str] = if args.same_host { &Fault::PROCESS_KINDS } else { &Fault::KINDS };
    if args.faults.is_empty() {
        return Ok(possible.to_vec());
    }
    args.faults
        .iter()
        .map(|name| {
            let name = name.trim();
            possible.iter().copied().find(|kind| *kind == name).ok_or_else(|| {
                anyhow::anyhow!(
                    "--faults: {name:?} is not a fault kind{} (one of: {})",
                    if args.same_host { " of --same-host" } else { "" },
                    possible.join(", ")
                )
            })
        })
        .collect()
}

fn run_one(
    args: &ChaosArgs,
    seed: u64,
    program: &std::path::Path,
    interrupted: &Arc<AtomicBool>,
) -> Result<CampaignReport> {
    let config = CampaignConfig {
        seed,
        agents: args.agents,
        rounds: args.rounds,
        fault_ms: args.fault_ms,
        write_hz: args.write_hz,
        image_bytes: args.image_bytes,
        settle_ms: args.settle_ms,
        join_wait_ms: args.join_wait_ms,
        domain: args.domain,
        security: args.security,
        same_host: args.same_host,
        unnamed: args.unnamed,
        #[cfg(feature = "mutants")]
        plant: args.plant.clone(),
    };
    let schedule = Schedule::generate(seed, args.agents, args.rounds, args.fault_ms, &fault_kinds(args)?);
    let dir = args.out.join(format!("seed-{seed}"));
    let tag = format!("cx{}", std::process::id());
    let mut provenance = measure::provenance::Provenance::current();
    provenance.seeds.insert("chaos".into(), seed);
    let campaign = Campaign::new(config.clone(), program.to_owned(), dir.clone(), &tag, Arc::clone(interrupted))?;
    let recorded = campaign.run(&schedule)?;
    let mut verdict = check::check(&recorded.writes, &recorded.killed_replicas, &recorded.finals);
    if !config.security {
        check::check_joins(&recorded.lives, &mut verdict);
    }
    let report = CampaignReport::new(config, &recorded, verdict, provenance);
    report.write(&dir, &recorded)?;
    Ok(report)
}
