//! The convergence model on small configurations: every property holds, and the unique state counts are pinned so
//! that a change to the state space (in the model or in the replica) is noticed and looked at before the number
//! is updated.

use model::convergence::{ConvergenceConfig, NetworkKind, check_convergence};
use model::{CheckOptions, CheckReport};

fn check(replicas: usize, ops: usize, network: NetworkKind) -> CheckReport {
    let config = ConvergenceConfig { replicas, ops, network, ..ConvergenceConfig::default() };
    let report = check_convergence(&config, &CheckOptions::default());
    let failures: Vec<_> = report.failures().collect();
    assert!(failures.is_empty(), "{}", report.to_text());
    assert!(report.complete);
    report
}

#[test]
fn three_replicas_two_ops_without_duplication_converge_and_match_the_spec() {
    assert_eq!(check(3, 2, NetworkKind::UnorderedNonduplicating).unique_states, 8_449);
}

#[test]
fn duplicated_deltas_change_nothing() {
    assert_eq!(check(2, 2, NetworkKind::UnorderedDuplicating).unique_states, 1_233);
}

#[test]
fn anti_entropy_recovers_any_loss() {
    assert_eq!(check(2, 2, NetworkKind::Lossy).unique_states, 2_055);
}

#[test]
fn every_property_is_reported() {
    let report = check(2, 2, NetworkKind::UnorderedNonduplicating);
    assert_eq!(report.properties.len(), model::convergence::property_count(&ConvergenceConfig::default()));
}
