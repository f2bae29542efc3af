//! With the `mutants` feature: every planted bug, in the replica, the scheduler and the agent protocol, is killed by some `always`
//! property with a non-empty counterexample.
#![cfg(feature = "mutants")]

#[test]
fn every_mutant_is_killed_with_a_counterexample() {
    let results = model::mutants::check_all_mutants(false);
    assert_eq!(results.len(), 31);
    for result in &results {
        assert!(result.killed, "{} survived:\n{}", result.mutant, result.report.to_text());
        let path = result.counterexample.as_ref().expect("a killed mutant has a counterexample");
        assert!(!path.actions.is_empty(), "{}: empty counterexample", result.mutant);
    }
}

#[test]
fn the_winner_and_name_holder_rules_are_killed_by_the_specification() {
    use dsr::DsrMutant;
    let rules = [DsrMutant::TieBreakByArrival, DsrMutant::WinnerLowestRank, DsrMutant::NameHeldByLatest];
    for (mutant, config) in model::mutants::dsr_mutant_configs().into_iter().filter(|(m, _)| rules.contains(m)) {
        let report = model::check_convergence(&config, &model::mutants::mutant_options(false));
        let failed: Vec<&str> = report.failures().map(|p| p.name.as_str()).collect();
        assert!(failed.contains(&model::convergence::properties::SPEC_EVERY), "{mutant:?} failed only {failed:?}");
    }
}
