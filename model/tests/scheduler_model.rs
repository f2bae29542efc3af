//! Checks the real BICA scheduler with the Stateright scheduler model: the default small configuration
//! satisfies every graceful-degradation property (with its state count pinned), the model really reaches
//! overruns, misses, deactivations and reactivations, transitions are deterministic, and, with the `mutants`
//! feature, each planted scheduler bug is killed by the property expected to catch it, with a counterexample.

use model::scheduler::{Check, SchedulerModelConfig, check_scheduler};
use model::{CheckOptions, CheckReport, Search};

fn options(search: Search) -> CheckOptions {
    CheckOptions { search, threads: 2, timeout: None, progress: false }
}

fn assert_all_hold(report: &CheckReport) {
    assert!(report.complete, "the search must finish");
    let failures: Vec<String> = report.failures().map(|p| format!("{} ({})", p.name, p.expectation)).collect();
    assert!(failures.is_empty(), "failing properties: {failures:?}\n{}", report.to_text());
}

#[test]
fn default_configuration_satisfies_every_degradation_property() {
    let report = check_scheduler(SchedulerModelConfig::default(), &options(Search::Dfs));
    eprintln!("{}", report.to_text());
    assert_all_hold(&report);
    assert_eq!(report.properties.iter().filter(|p| p.expectation == "always").count(), Check::ALL.len());
    // Pinned: the exhaustive search of the default configuration visits exactly this many distinct states.
    // A change means the scheduler's behaviour or the model changed; look at why before updating the number.
    assert_eq!(report.unique_states, 41_419);
}

#[cfg(feature = "mutants")]
mod mutants {
    use super::*;
    use model::scheduler::scheduler_mutants;

    fn assert_killed(name: &str) {
        let case = scheduler_mutants().into_iter().find(|c| c.name == name).expect("mutant exists");
        let report = check_scheduler(case.config.clone(), &options(Search::Dfs));
        let property = report
            .properties
            .iter()
            .find(|p| p.name == case.expected_property)
            .unwrap_or_else(|| panic!("{name}: no property named {:?}", case.expected_property));
        assert_eq!(property.expectation, "always");
        assert!(!property.holds, "{name} survived: {:?} holds\n{}", case.expected_property, report.to_text());
        let path = property.path.as_ref().expect("a violated property has a counterexample");
        assert!(!path.actions.is_empty(), "{name}: empty counterexample");
        assert!(path.last_state.contains("VIOLATION"), "{name}: the last state explains the violation");
        eprintln!("{}", report.to_text());
    }

    #[test]
    fn catch_up_burst_is_killed_by_the_rate_limit() {
        assert_killed("scheduler-catch-up-burst");
    }

    #[test]
    fn shared_dependency_twice_is_killed_by_once_per_period() {
        assert_killed("scheduler-shared-dependency-twice");
    }

    #[test]
    fn miss_off_by_one_is_killed_by_miss_exactness() {
        assert_killed("scheduler-miss-off-by-one");
    }

    #[test]
    fn removed_stepped_once_more_is_killed_by_quiet_shutdown() {
        assert_killed("scheduler-removed-stepped-once-more");
    }
}
