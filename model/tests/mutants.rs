//! With the `mutants` feature: every planted bug, in the replica, the scheduler and the agent protocol, is killed by some `always`
//! property with a non-empty counterexample.
#![cfg(feature = "mutants")]

#[test]
fn every_mutant_is_killed_with_a_counterexample() {
    let results = model::mutants::check_all_mutants(false);
    assert_eq!(results.len(), 26);
    for result in &results {
        assert!(result.killed, "{} survived:\n{}", result.mutant, result.report.to_text());
        let path = result.counterexample.as_ref().expect("a killed mutant has a counterexample");
        assert!(!path.actions.is_empty(), "{}: empty counterexample", result.mutant);
    }
}
