//! The convergence model on small configurations: every property holds, and the unique state counts are pinned so
//! that a change to the state space (in the model or in the replica) is noticed and looked at before the number
//! is updated. The counts are deterministic: the checker visits every reachable state whatever the thread timing.

use model::convergence::{ConvergenceConfig, NetworkKind, check_convergence};
use model::{CheckOptions, CheckReport};

fn check(config: ConvergenceConfig) -> CheckReport {
    let report = check_convergence(&config, &CheckOptions::default());
    let failures: Vec<_> = report.failures().collect();
    assert!(failures.is_empty(), "{}", report.to_text());
    assert!(report.complete);
    report
}

/// A configuration without clock advances.
fn config(replicas: usize, ops: usize, network: NetworkKind) -> ConvergenceConfig {
    ConvergenceConfig { replicas, ops, network, ticks: 0, ..ConvergenceConfig::default() }
}

/// The default `cortex check convergence`. Its states include every state of 3 replicas x 3 operations without a
/// clock advance (835,425 unique), since the one advance is optional. Not run again in the test command's
/// `--features mutants` pass, which plants no mutant here and would only repeat it.
#[test]
#[cfg(not(feature = "mutants"))]
fn three_replicas_three_ops_one_clock_advance_the_default_check_converge_and_match_the_spec_in_every_state() {
    let report = check(ConvergenceConfig::default());
    assert_eq!(report.configuration["replicas"], 3);
    assert_eq!(report.configuration["ops"], 3);
    assert_eq!(report.configuration["ticks"], 1);
    assert_eq!(report.unique_states, 3_333_153);
}

#[test]
fn three_replicas_two_ops_without_duplication_converge_and_match_the_spec() {
    assert_eq!(check(config(3, 2, NetworkKind::UnorderedNonduplicating)).unique_states, 8_449);
}

#[test]
fn duplicated_and_truncated_deltas_change_nothing() {
    assert_eq!(check(config(2, 2, NetworkKind::UnorderedDuplicating)).unique_states, 1_233);
    assert_eq!(check(config(2, 3, NetworkKind::UnorderedDuplicating)).unique_states, 55_125);
}

#[test]
fn anti_entropy_recovers_any_loss() {
    assert_eq!(check(config(2, 2, NetworkKind::Lossy)).unique_states, 2_055);
}

#[test]
fn announces_at_any_time_with_a_history_of_one_repair_loss() {
    let announces = ConvergenceConfig { syncs: 2, history: 1, ..config(2, 2, NetworkKind::Lossy) };
    assert_eq!(check(announces).unique_states, 144_101);
}

/// The same with the replica's default fold threshold (1 KiB), above every write of the model, so no write folds:
/// the history's path without folding keeps every property. With a history of one operation, folding and not
/// folding reach the same states, hence the same count.
#[test]
fn announces_repair_loss_with_the_default_fold_threshold_where_no_write_folds() {
    let fold_min_payload_bytes = dsr::LogLimits::default().fold_min_payload_bytes;
    let unfolded =
        ConvergenceConfig { syncs: 2, history: 1, fold_min_payload_bytes, ..config(2, 2, NetworkKind::Lossy) };
    assert_eq!(check(unfolded).unique_states, 144_101);
}

#[test]
fn snapshots_answer_when_there_is_no_history() {
    let snapshots = ConvergenceConfig { syncs: 1, history: 0, ..config(3, 2, NetworkKind::UnorderedNonduplicating) };
    assert_eq!(check(snapshots).unique_states, 248_626);
}

#[test]
fn skewed_clocks_decide_the_winners_and_stamps_still_follow_causality() {
    let skewed = ConvergenceConfig { ticks: 1, ..config(2, 3, NetworkKind::UnorderedNonduplicating) };
    assert_eq!(check(skewed).unique_states, 117_373);
}

#[test]
fn everything_at_once_on_a_duplicating_network() {
    // A clock advance, an announce with a history of one, and truncated copies of every delta.
    let all = ConvergenceConfig { ticks: 1, syncs: 1, history: 1, ..config(2, 2, NetworkKind::UnorderedDuplicating) };
    assert_eq!(check(all).unique_states, 76_669);
}

#[test]
fn every_property_is_reported() {
    let report = check(config(2, 2, NetworkKind::UnorderedNonduplicating));
    assert_eq!(report.properties.len(), model::convergence::property_count(&ConvergenceConfig::default()));
}
