//! The mutant check: plants each known bug in the real implementation and checks that a model kills it, with a
//! readable counterexample (the shortest: each check breadth-first on one thread; the checks run side by side, one
//! per core).
//!
//! Only with the `mutants` feature, which enables the switches in `dsr` and `bica`; a normal build cannot plant
//! anything.

use std::sync::Mutex;

use agent::mutants::ProtocolMutant;
use dsr::DsrMutant;
use serde::Serialize;

use crate::agents::{AgentsConfig, Budgets, check_agents};
use crate::convergence::{ConvergenceConfig, NetworkKind, check_convergence};
use crate::report::{CheckOptions, CheckReport, CounterExample, Search};
use crate::scheduler::{check_scheduler, scheduler_mutants};

/// What happened to one mutant.
#[derive(Clone, Debug, Serialize)]
pub struct MutantResult {
    /// The planted bug.
    pub mutant: String,
    /// The model that ran it.
    pub model: String,
    /// Whether some `always` property failed.
    pub killed: bool,
    /// The properties that failed.
    pub killed_by: Vec<String>,
    /// The counterexample of the first failed property.
    pub counterexample: Option<CounterExample>,
    /// The whole check.
    pub report: CheckReport,
}

impl MutantResult {
    fn from_report(mutant: String, report: CheckReport) -> Self {
        let failures: Vec<_> = report.failures().filter(|p| p.expectation != "sometimes").cloned().collect();
        MutantResult {
            mutant,
            model: report.model.clone(),
            killed: !failures.is_empty(),
            killed_by: failures.iter().map(|p| p.name.clone()).collect(),
            counterexample: failures.first().and_then(|p| p.path.clone()),
            report,
        }
    }
}

/// The smallest convergence configuration whose network can expose each replica mutant.
pub fn dsr_mutant_configs() -> Vec<(DsrMutant, ConvergenceConfig)> {
    // No clock advance unless a mutant needs one (the default's one advance multiplies the states by four).
    let config =
        |replicas, ops, network| ConvergenceConfig { replicas, ops, network, ticks: 0, ..ConvergenceConfig::default() };
    let nondup = NetworkKind::UnorderedNonduplicating;
    DsrMutant::ALL
        .into_iter()
        .map(|mutant| {
            let base = match mutant {
                // A re-delivered delta is what re-adds a superseded value.
                DsrMutant::JoinNotIdempotent => config(2, 2, NetworkKind::UnorderedDuplicating),
                // Only loss makes anti-entropy matter.
                DsrMutant::AntiEntropySkipsLastDelta => config(2, 1, NetworkKind::Lossy),
                DsrMutant::RemoveLosesContext | DsrMutant::DeleteKeepsIncidentEdges => config(2, 1, nondup),
                DsrMutant::TieBreakByArrival | DsrMutant::EdgeToDeletedNodeVisible => config(2, 2, nondup),
                // Two concurrent writes of one attribute; two concurrent inserts of one name. Deterministic: only
                // the specification can tell.
                DsrMutant::WinnerLowestRank | DsrMutant::NameHeldByLatest => config(2, 2, nondup),
                // A delete that hides an edge; a snapshot of a state with a tombstone; a node inserted with an
                // attribute (its second dot).
                DsrMutant::IncidentEdgeEventsMissing
                | DsrMutant::InstallDropsTombstones
                | DsrMutant::CodecDotOffset => config(2, 1, nondup),
                // An attribute write on an inserted node that arrives before the node.
                DsrMutant::EarlyAttrDropped => config(2, 2, nondup),
                // An overwrite that reaches one replica without the write it removed; that replica's snapshot
                // (no history at all) answers a third one's announce.
                DsrMutant::SnapshotAppliedFromContext => {
                    ConvergenceConfig { syncs: 1, history: 0, ..config(3, 2, nondup) }
                }
                // Three operations of one replica, the first arriving after the third; two concurrent inserts of
                // one name, then the holder deleted.
                DsrMutant::ContextCompactionSkipsGap | DsrMutant::NameKeptByDeletedHolder => config(2, 3, nondup),
                // A clock advanced to a stamp, then another operation at the same physical time.
                DsrMutant::StampTiesPhysicalClock => ConvergenceConfig { ticks: 1, ..config(2, 2, nondup) },
                // An announce answered with a snapshot (no history at all), then an operation.
                DsrMutant::SnapshotJoinKeepsClock => ConvergenceConfig { syncs: 1, history: 0, ..config(2, 2, nondup) },
                // Two lost deltas, an announce answered from a history of one.
                DsrMutant::HistoryOffByOne => {
                    ConvergenceConfig { syncs: 1, history: 1, ..config(2, 2, NetworkKind::Lossy) }
                }
                // Two writes of one seed attribute lost, the second folding in the first; an announce answered from
                // a history of two.
                DsrMutant::FoldDropsContext => {
                    ConvergenceConfig { syncs: 1, history: 2, ..config(2, 2, NetworkKind::Lossy) }
                }
            };
            (mutant, base.with_mutant(mutant))
        })
        .collect()
}

/// Options for mutant runs: breadth-first on one thread, so each counterexample is a shortest one.
pub fn mutant_options(progress: bool) -> CheckOptions {
    CheckOptions { search: Search::Bfs, threads: 1, timeout: None, progress }
}

fn dsr_name(mutant: DsrMutant) -> String {
    format!("dsr::{mutant:?}")
}

fn bica_name(case: &str) -> String {
    format!("bica::{case}")
}

fn agent_name(mutant: ProtocolMutant) -> String {
    format!("agent::{mutant:?}")
}

/// Which mutants to check: given a mutant's name (`dsr::…`, `bica::…`, `agent::…`), whether to check it.
pub type Wanted<'a> = &'a dyn Fn(&str) -> bool;

/// Runs the replica mutants `wanted` accepts through the convergence model.
pub fn check_dsr_mutants(progress: bool, wanted: Wanted<'_>) -> Vec<MutantResult> {
    run_side_by_side(dsr_jobs(progress, wanted))
}

fn dsr_jobs(progress: bool, wanted: Wanted<'_>) -> Vec<Job> {
    dsr_mutant_configs()
        .into_iter()
        .filter(|(mutant, _)| wanted(&dsr_name(*mutant)))
        .map(|(mutant, config)| -> Job {
            Box::new(move || {
                let report = check_convergence(&config, &mutant_options(progress));
                MutantResult::from_report(dsr_name(mutant), report)
            })
        })
        .collect()
}

/// Runs the scheduler mutants `wanted` accepts through the scheduler model.
pub fn check_scheduler_mutants(progress: bool, wanted: Wanted<'_>) -> Vec<MutantResult> {
    run_side_by_side(scheduler_jobs(progress, wanted))
}

fn scheduler_jobs(progress: bool, wanted: Wanted<'_>) -> Vec<Job> {
    scheduler_mutants()
        .into_iter()
        .filter(|case| wanted(&bica_name(case.name)))
        .map(|case| -> Job {
            Box::new(move || {
                let report = check_scheduler(case.config, &mutant_options(progress));
                let mut result = MutantResult::from_report(bica_name(case.name), report);
                // Report the property the mutant is meant to break first, when it is among the failures.
                if let Some(expected) = result.report.failures().find(|p| p.name == case.expected_property) {
                    result.counterexample = expected.path.clone();
                }
                result
            })
        })
        .collect()
}

/// The smallest agents configuration whose faults can expose each protocol mutant, and the property meant to
/// kill it.
pub fn agent_mutant_configs() -> Vec<(ProtocolMutant, AgentsConfig, &'static str)> {
    use crate::agents::properties as p;
    let none = Budgets { ticks: 3, ..Budgets::default() };
    let with = |budgets: Budgets| AgentsConfig { agents: 2, budgets, ..AgentsConfig::default() };
    ProtocolMutant::ALL
        .into_iter()
        .map(|mutant| {
            let (config, property) = match mutant {
                // A lost delta, then a later one of the same writer.
                ProtocolMutant::NoGapRequest => (with(Budgets { writes: 2, losses: 1, ..none }), p::GAP_ASKED),
                // A restart whose new life joins a graph that shows nothing of the first life.
                ProtocolMutant::IncarnationForgotten => {
                    (with(Budgets { crashes: 1, ticks: 5, ..none }), p::UNIQUE_LIVES)
                }
                // A write that reaches a joiner before its graph does.
                ProtocolMutant::DropEarlyDelta => (with(Budgets { writes: 1, ..none }), p::EARLY_KEPT),
                // A lost write and a lost quiet announce: only a periodic announce would repair them.
                ProtocolMutant::AnnounceTimerLost => {
                    (with(Budgets { writes: 1, losses: 2, ticks: 4, ..none }), p::SETTLES)
                }
                // A lost graph request.
                ProtocolMutant::JoinRequestOnce => (with(Budgets { losses: 1, ..none }), p::JOINER_SERVED),
                // A lost answer to a missing-request.
                ProtocolMutant::PendingAskNeverExpires => {
                    (with(Budgets { writes: 2, losses: 2, ticks: 4, ..none }), p::SETTLES)
                }
                // A joiner stopped before its peer's answer came.
                ProtocolMutant::JoinWaitCountsAbsence => (with(Budgets { stops: 1, ..none }), p::JOINER_SERVED),
                // Agents naming no graph, the joiner starting alone before the first agent's first tick: two
                // unnamed graphs, one of which must move.
                ProtocolMutant::UnnamedGraphNeverMoves => {
                    (AgentsConfig { unnamed: true, ..with(Budgets { ticks: 5, ..none }) }, p::SETTLES)
                }
            };
            (mutant, config.with_mutant(mutant), property)
        })
        .collect()
}

/// Runs the protocol mutants `wanted` accepts through the agents model.
pub fn check_agent_mutants(progress: bool, wanted: Wanted<'_>) -> Vec<MutantResult> {
    run_side_by_side(agent_jobs(progress, wanted))
}

fn agent_jobs(progress: bool, wanted: Wanted<'_>) -> Vec<Job> {
    agent_mutant_configs()
        .into_iter()
        .filter(|(mutant, _, _)| wanted(&agent_name(*mutant)))
        .map(|(mutant, config, property)| -> Job {
            Box::new(move || {
                let report = check_agents(&config, &mutant_options(progress));
                let mut result = MutantResult::from_report(agent_name(mutant), report);
                if let Some(expected) = result.report.failures().find(|p| p.name == property) {
                    result.counterexample = expected.path.clone();
                }
                result
            })
        })
        .collect()
}

/// Runs every mutant of the three models.
pub fn check_all_mutants(progress: bool) -> Vec<MutantResult> {
    check_mutants(progress, &|_| true)
}

/// Runs the mutants of the three models that `wanted` accepts, in the order of [`mutant_names`]: side by side, one
/// check per core (each check is still breadth-first on one thread, so its counterexample is a shortest one).
pub fn check_mutants(progress: bool, wanted: Wanted<'_>) -> Vec<MutantResult> {
    let mut jobs = dsr_jobs(progress, wanted);
    jobs.extend(scheduler_jobs(progress, wanted));
    jobs.extend(agent_jobs(progress, wanted));
    run_side_by_side(jobs)
}

/// One mutant's check, ready to run on any thread.
type Job = Box<dyn FnOnce() -> MutantResult + Send>;

/// Runs `jobs` on as many threads as the machine has cores (at most one per job) and returns their results in the
/// jobs' order. The checks share nothing: each replica or agent carries the mutant planted in it.
fn run_side_by_side(jobs: Vec<Job>) -> Vec<MutantResult> {
    let count = jobs.len();
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get()).min(count);
    let queue = Mutex::new(jobs.into_iter().enumerate());
    let done = Mutex::new(Vec::with_capacity(count));
    std::thread::scope(|scope| {
        for _ in 0..threads {
            scope.spawn(|| {
                loop {
                    // The guard is dropped before the job runs, so the other threads take the next ones meanwhile.
                    let next = queue.lock().unwrap_or_else(|p| p.into_inner()).next();
                    let Some((index, job)) = next else { break };
                    let result = job();
                    done.lock().unwrap_or_else(|p| p.into_inner()).push((index, result));
                }
            });
        }
    });
    let mut done = done.into_inner().unwrap_or_else(|p| p.into_inner());
    done.sort_by_key(|(index, _)| *index);
    done.into_iter().map(|(_, result)| result).collect()
}

/// The name of every mutant, as [`MutantResult::mutant`] gives it: `dsr::…`, `bica::…`, `agent::…`.
pub fn mutant_names() -> Vec<String> {
    let dsr = dsr_mutant_configs().into_iter().map(|(mutant, _)| dsr_name(mutant));
    let bica = scheduler_mutants().into_iter().map(|case| bica_name(case.name));
    let agent = agent_mutant_configs().into_iter().map(|(mutant, _, _)| agent_name(mutant));
    dsr.chain(bica).chain(agent).collect()
}
