//! Checks the real BICA scheduler with the Stateright scheduler model: the default small configuration
//! satisfies every graceful-degradation property (with its state count pinned), the model really reaches
//! overruns, misses, deactivations and reactivations, transitions are deterministic, and, with the `mutants`
//! feature, each planted scheduler bug is killed by the property expected to catch it, with a counterexample.

use model::scheduler::{Check, SchedulerAction, SchedulerModel, SchedulerModelConfig, SchedulerState, check_scheduler};
use model::{CheckOptions, CheckReport, Search};
use stateright::{Checker, Model};

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
    assert_eq!(report.unique_states, 58_607);
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
        let explanation = format!("VIOLATION: [{}]", case.expected_property);
        assert!(path.last_state.contains(&explanation), "{name}: the last state explains the violation");
        eprintln!("{}", report.to_text());
    }

    #[test]
    fn catch_up_burst_is_killed_by_skipped_release_accounting() {
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

    #[test]
    fn finish_unmatched_is_killed_by_illegal_calls_refused() {
        assert_killed("scheduler-finish-unmatched");
    }
}

#[test]
fn breadth_first_search_visits_the_same_states() {
    let report = check_scheduler(SchedulerModelConfig::default(), &options(Search::Bfs));
    assert_all_hold(&report);
    assert_eq!(report.unique_states, 58_607);
}

#[test]
fn identical_action_sequences_give_identical_states_and_traces() {
    // Random walks (a fixed linear congruential sequence picks the actions), each replayed on a second,
    // freshly built model: every transition must give the same state, trace and findings both times.
    let config = SchedulerModelConfig { check_determinism: false, ..SchedulerModelConfig::default() };
    let first = SchedulerModel::new(config.clone()).expect("valid configuration");
    let second = SchedulerModel::new(config).expect("valid configuration");
    let mut seed: u64 = 0x5eed;
    let mut transitions = 0;
    for _walk in 0..200 {
        let mut state = first.initial_state();
        let mut replayed = second.initial_state();
        assert_eq!(state, replayed);
        loop {
            let mut actions = Vec::new();
            first.actions(&state, &mut actions);
            let Some(next) = pick(&first, &state, &actions, &mut seed) else { break };
            let (action, next) = next;
            let again = second.apply(&replayed, action).expect("the action applies on the replay too");
            assert_eq!(next, again, "{}", first.format_action(&action));
            assert_eq!(next.last_events(), again.last_events());
            assert_eq!(next.findings(), again.findings());
            assert!(next.findings().is_empty(), "{:?}", next.findings());
            state = next;
            replayed = again;
            transitions += 1;
        }
    }
    assert!(transitions > 1_000, "the walks are long enough to matter ({transitions} transitions)");
}

/// Picks an applicable action pseudo-randomly and applies it.
fn pick(
    model: &SchedulerModel,
    state: &SchedulerState,
    actions: &[SchedulerAction],
    seed: &mut u64,
) -> Option<(SchedulerAction, SchedulerState)> {
    let mut candidates: Vec<(SchedulerAction, SchedulerState)> =
        actions.iter().filter_map(|&a| model.apply(state, a).map(|s| (a, s))).collect();
    if candidates.is_empty() {
        return None;
    }
    *seed = seed.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1_442_695_040_888_963_407);
    let index = (*seed >> 33) as usize % candidates.len();
    Some(candidates.swap_remove(index))
}

#[test]
fn invalid_configurations_are_rejected() {
    let overloaded = SchedulerModelConfig { miss_tolerance_ns: 3, ..SchedulerModelConfig::default() };
    assert!(overloaded.validate().unwrap_err().contains("tolerance"));
    let mut too_slow = SchedulerModelConfig::default();
    too_slow.components[2].nominal_ns = 7;
    assert!(too_slow.validate().unwrap_err().contains("nominal load"));
    let no_overrun = SchedulerModelConfig { overrun_ns: 2, ..SchedulerModelConfig::default() };
    assert!(no_overrun.validate().is_err());
    assert!(SchedulerModel::new(SchedulerModelConfig::default()).is_ok());
    // One round for the logger is both parents' steps with the dependency: 2 × (1 + 1).
    assert_eq!(SchedulerModelConfig::default().round_ns(2), 4);
}

/// Release-mode figures for the report: `cargo test --release -p model --test scheduler_model -- --ignored
/// --nocapture`. Times the bare checker (the shared runner polls its reporter once a second).
#[test]
#[ignore = "measurement, run in release mode"]
fn measure_default_configuration() {
    let model = SchedulerModel::new(SchedulerModelConfig::default()).expect("valid configuration");
    let started = std::time::Instant::now();
    let checker = model.checker().threads(2).spawn_dfs().join();
    let seconds = started.elapsed().as_secs_f64();
    let explored = checker.state_count();
    eprintln!(
        "default scheduler model: {explored} states explored, {} unique, depth {}, {seconds:.3} s, {:.0} states/s",
        checker.unique_state_count(),
        checker.max_depth(),
        explored as f64 / seconds
    );
    assert_eq!(checker.unique_state_count(), 58_607);
}
