//! The agents model on small configurations: every `always` property holds (unique lives, bounded buffers,
//! invariants, gap requests, early deltas kept, settling to the specification once the faults stop, joiners
//! served), and the unique state counts are pinned so that a change to the state space (in the model or in the
//! agent core) is noticed and looked at before the number is updated. The `sometimes` witnesses need larger budgets
//! (`cortex check agents` with its defaults reaches every one).

use model::agents::{AgentsConfig, Budgets, check_agents};
use model::{CheckOptions, CheckReport};

fn check(config: AgentsConfig) -> CheckReport {
    let report = check_agents(&config, &CheckOptions::default());
    let failures: Vec<_> = report.failures().filter(|p| p.expectation != "sometimes").collect();
    assert!(failures.is_empty(), "{}", report.to_text());
    assert!(report.complete);
    report
}

fn config(agents: usize, budgets: Budgets) -> AgentsConfig {
    AgentsConfig { agents, budgets, ..Default::default() }
}

/// One write, three ticks, no faults.
fn quiet() -> Budgets {
    Budgets { writes: 1, ticks: 3, ..Budgets::default() }
}

#[test]
fn a_crash_a_cut_a_loss_and_a_duplicate_all_settle_to_the_specification() {
    let config = config(2, Budgets { losses: 1, duplicates: 1, crashes: 1, cuts: 1, ..quiet() });
    assert_eq!(check(config).unique_states, 25_842);
}

#[test]
fn lost_writes_are_repaired() {
    assert_eq!(check(config(2, Budgets { writes: 2, losses: 1, ..quiet() })).unique_states, 7_580);
}

#[test]
fn three_agents_join_one_graph() {
    assert_eq!(check(config(3, quiet())).unique_states, 5_326);
}

#[test]
fn a_group_of_one_stretches_the_announce_period_and_a_lost_write_is_still_repaired() {
    // Three agents in announce groups of one: each announces every 3 periods once it has heard both peers.
    let every_period = config(3, Budgets { losses: 1, ..quiet() });
    let stretched = AgentsConfig { announce_group: 1, ..every_period.clone() };
    let (stretched, every_period) = (check(stretched).unique_states, check(every_period).unique_states);
    assert_ne!(stretched, every_period, "the group of one must change when the agents announce");
    assert_eq!(stretched, 17_843);
}

#[test]
fn an_agent_forgets_a_silent_peer_and_the_agents_still_settle() {
    // Two agents in announce groups of one, so a forgetting halves the forgetting agent's announce interval;
    // a peer is forgotten after one interval of silence (the model's default; running agents wait four).
    let config = AgentsConfig { announce_group: 1, ..config(2, Budgets { ticks: 4, ..quiet() }) };
    let report = check(config);
    let forgotten = report.properties.iter().find(|p| p.name == model::agents::properties::W_FORGOTTEN).unwrap();
    assert!(forgotten.holds, "no path forgets a peer: {}", report.to_text());
    assert_eq!(report.unique_states, 1_206);
}

#[test]
fn a_joiner_stopped_while_it_joins_takes_the_peers_graph_when_it_resumes() {
    // The joiner's process is stopped for twice its join wait and resumed; its first act is a tick that late. The
    // time it could not listen does not count against its wait, so it asks again and joins the ready peer's graph
    // (planted, `JoinWaitCountsAbsence` starts it alone: the mutant check kills it). With a loss (its request, or
    // the answer that waits for it while it is stopped) and a crash (of the stopped process, too) beside it.
    let report = check(config(2, Budgets { stops: 1, crashes: 1, losses: 1, ..quiet() }));
    let joined = report.properties.iter().find(|p| p.name == model::agents::properties::W_STOPPED_JOINED).unwrap();
    assert!(joined.holds, "no path resumes a stopped joiner into a peer's graph: {}", report.to_text());
    assert_eq!(report.unique_states, 57_032);
}

#[test]
fn agents_that_name_no_graph_end_in_one_graph_after_a_cut_and_after_a_restart() {
    // Unnamed, a joiner that starts alone (before the first agent's first tick, or under a cut) makes a graph of
    // its own, and a restarted agent starts again in the unnamed graph it recorded; settling now requires one
    // graph, so an unnamed graph that never moved would fail it (planted, `UnnamedGraphNeverMoves`: the mutant
    // check kills it).
    let unnamed = |budgets| AgentsConfig { unnamed: true, ..config(2, budgets) };
    let cut = check(unnamed(Budgets { ticks: 6, cuts: 1, ..quiet() }));
    let moved = cut.properties.iter().find(|p| p.name == model::agents::properties::W_MOVED).unwrap();
    assert!(moved.holds, "no path moves an unnamed graph: {}", cut.to_text());
    assert_eq!(cut.unique_states, 58_809);
    assert_eq!(check(unnamed(Budgets { ticks: 5, crashes: 1, ..quiet() })).unique_states, 47_323);
}
