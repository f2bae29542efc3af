//! With the `mutants` feature: every planted bug, in the replica, the scheduler and the agent protocol, is killed by some `always`
//! property with a non-empty counterexample, and the configuration that kills it, with the switch built in and no bug
//! planted, satisfies every `always` property (the baseline: the property that kills a mutant holds without it).
#![cfg(feature = "mutants")]

#[test]
fn every_mutant_is_killed_with_a_counterexample() {
    let results = model::mutants::check_all_mutants(false);
    assert_eq!(results.len(), 32);
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

/// The baseline of every kill: each mutant's configuration of the convergence and agents models, with the mutation
/// switch built in and nothing planted, breaks no `always` property. (The scheduler's mutants all use the default
/// scheduler configuration, which `tests/scheduler_model.rs` checks in this build too.)
#[test]
fn every_mutant_configuration_without_its_mutant_breaks_no_always_property() {
    use std::collections::HashSet;
    let options = model::report::CheckOptions::default();
    let mut convergence = HashSet::new();
    for (_, config) in model::mutants::dsr_mutant_configs() {
        let config = model::convergence::ConvergenceConfig { mutant: None, planted: None, ..config };
        if convergence.insert(config.clone()) {
            let report = model::check_convergence(&config, &options);
            assert!(always_holds(&report), "{config:?}:\n{}", report.to_text());
        }
    }
    let mut agents = HashSet::new();
    for (_, config, _) in model::mutants::agent_mutant_configs() {
        let config = model::agents::AgentsConfig { mutant: None, planted: None, ..config };
        if agents.insert(config.clone()) {
            let report = model::agents::check_agents(&config, &options);
            assert!(always_holds(&report), "{config:?}:\n{}", report.to_text());
        }
    }
    assert!(convergence.len() >= 8 && agents.len() >= 6, "{} and {} configurations", convergence.len(), agents.len());
}

fn always_holds(report: &model::CheckReport) -> bool {
    report.failures().all(|p| p.expectation == "sometimes")
}
