//! Property tests of the degradation guarantees, over random component sets, periods,
//! step durations (including overruns), cascades and run-time list changes, all under the
//! virtual clock so every run is deterministic.

mod common;

use std::collections::{HashMap, HashSet};

use bica::prelude::*;
use common::*;
use proptest::prelude::*;

const US: u64 = 1_000;

#[derive(Debug, Clone)]
struct Scenario {
    workers: Vec<WorkerSpec>,
    initially_active: Vec<bool>,
    /// (time, worker, activate?) applied between steps.
    list_changes: Vec<(u64, usize, bool)>,
    tolerance_ns: u64,
    end_ns: u64,
}

fn worker_strategy(index: usize, count: usize, with_deps: bool) -> impl Strategy<Value = WorkerSpec> {
    let later: Vec<usize> = (index + 1..count).collect();
    let deps = if with_deps && !later.is_empty() {
        proptest::sample::subsequence(later.clone(), 0..=later.len().min(2)).boxed()
    } else {
        Just(Vec::new()).boxed()
    };
    (1u64..=20, 0u64..=3000, deps, proptest::option::of((0u64..5, 1u64..=50_000))).prop_map(
        move |(period_ms, duration_us, deps, overrun)| WorkerSpec {
            period_ns: period_ms * 1_000 * US,
            duration_ns: duration_us * US,
            overrun: overrun.map(|(run, extra_us)| (run, extra_us * US)),
            deps,
        },
    )
}

fn scenario_strategy() -> impl Strategy<Value = Scenario> {
    (1usize..=6).prop_flat_map(|count| {
        let workers: Vec<_> = (0..count).map(|i| worker_strategy(i, count, true)).collect();
        (
            workers,
            proptest::collection::vec(any::<bool>(), count),
            proptest::collection::vec((0u64..300_000, 0..count, any::<bool>()), 0..6),
            0u64..5_000,
        )
            .prop_map(|(workers, initially_active, mut changes, tolerance_us)| {
                changes.sort_by_key(|c| c.0);
                Scenario {
                    workers,
                    initially_active,
                    list_changes: changes.into_iter().map(|(t, w, a)| (t * US, w, a)).collect(),
                    tolerance_ns: tolerance_us * US,
                    end_ns: 300_000 * US,
                }
            })
    })
}

fn run_scenario(scenario: &Scenario) -> (Runtime<VirtualClock>, Vec<TraceEvent>) {
    let config = SchedulerConfig { miss_tolerance_ns: scenario.tolerance_ns, ..SchedulerConfig::default() };
    let mut runtime = virtual_runtime(config);
    for (index, spec) in scenario.workers.iter().enumerate() {
        add_worker(&mut runtime, index, spec);
    }
    for (index, &active) in scenario.initially_active.iter().enumerate() {
        if active {
            activate_worker(&mut runtime, index);
        }
    }
    for &(at_ns, index, activate) in &scenario.list_changes {
        runtime.run_until(at_ns).unwrap();
        if activate {
            activate_worker(&mut runtime, index);
        } else {
            deactivate_worker(&mut runtime, index);
        }
    }
    runtime.run_until(scenario.end_ns).unwrap();
    let trace = runtime.drain_trace();
    assert_eq!(runtime.core().trace().dropped(), 0, "trace ring too small for the test");
    (runtime, trace)
}

/// Top-level only, constant durations, at most one overrun: for the lateness bounds.
fn flat_strategy(
    max_total_duration_fraction: Option<u64>,
) -> impl Strategy<Value = (Vec<WorkerSpec>, usize, u64, u64)> {
    (1usize..=6).prop_flat_map(move |count| {
        let workers: Vec<_> = (0..count).map(|i| worker_strategy(i, count, false)).collect();
        (workers, 0..count, 0u64..5, 1u64..=80_000).prop_map(move |(mut workers, slow, run, extra_us)| {
            for worker in &mut workers {
                worker.overrun = None;
            }
            if let Some(fraction) = max_total_duration_fraction {
                // Keep a round well inside the shortest period, so the nominal load fits.
                let min_period = workers.iter().map(|w| w.period_ns).min().unwrap();
                let budget = min_period / fraction / workers.len() as u64;
                for worker in &mut workers {
                    worker.duration_ns = worker.duration_ns.min(budget);
                }
            }
            workers[slow].overrun = Some((run, extra_us * US));
            (workers, slow, run, extra_us * US)
        })
    })
}

fn run_flat(workers: &[WorkerSpec], end_ns: u64) -> Vec<TraceEvent> {
    let mut runtime = virtual_runtime(SchedulerConfig::default());
    for (index, spec) in workers.iter().enumerate() {
        add_worker(&mut runtime, index, spec);
        activate_worker(&mut runtime, index);
    }
    runtime.run_until(end_ns).unwrap();
    runtime.drain_trace()
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 200, ..ProptestConfig::default() })]

    #[test]
    fn no_step_overlaps_another_or_itself_and_no_started_step_is_cancelled(scenario in scenario_strategy()) {
        let (_, trace) = run_scenario(&scenario);
        runs_checking_nesting(&trace);
    }

    #[test]
    fn gated_work_never_runs_more_often_than_its_period_allows(scenario in scenario_strategy()) {
        let (runtime, trace) = run_scenario(&scenario);
        let runs = runs_checking_nesting(&trace);
        check_rate_limit(&runs, |id| runtime.core().period_ns(id).unwrap());
        for (index, _) in scenario.workers.iter().enumerate() {
            let id = ComponentId(index as u32);
            let counted = runs.iter().filter(|r| r.component == id).count() as u64;
            prop_assert_eq!(runtime.core().counters(id).unwrap().runs, counted);
        }
    }

    #[test]
    fn deactivated_components_are_never_stepped_by_the_scheduler(scenario in scenario_strategy()) {
        let (_, trace) = run_scenario(&scenario);
        let mut active: HashSet<ComponentId> = HashSet::new();
        for event in &trace {
            match *event {
                TraceEvent::Activated { component, .. } => { active.insert(component); }
                TraceEvent::Deactivated { component, .. } => { active.remove(&component); }
                TraceEvent::StepStarted { component, caller: Caller::TopLevel, .. } => {
                    prop_assert!(active.contains(&component), "{:?} stepped while inactive", component);
                }
                _ => {}
            }
        }
    }

    #[test]
    fn miss_is_raised_exactly_when_lateness_exceeds_the_tolerance(scenario in scenario_strategy()) {
        let (runtime, trace) = run_scenario(&scenario);
        let mut misses: HashMap<ComponentId, u64> = HashMap::new();
        for (position, event) in trace.iter().enumerate() {
            if let TraceEvent::StepStarted { component, at_ns, release_ns, lateness_ns, skipped_periods, .. } = *event {
                let previous = position.checked_sub(1).map(|p| trace[p]);
                let late = lateness_ns > scenario.tolerance_ns;
                match previous {
                    Some(TraceEvent::Miss(miss)) => {
                        prop_assert!(late, "miss raised at lateness {} <= tolerance {}", lateness_ns, scenario.tolerance_ns);
                        prop_assert_eq!((miss.component, miss.expected_ns, miss.actual_ns), (component, release_ns, at_ns));
                        prop_assert_eq!((miss.lateness_ns, miss.skipped_periods), (lateness_ns, skipped_periods));
                        *misses.entry(component).or_default() += 1;
                    }
                    _ => prop_assert!(!late, "no miss raised at lateness {} > tolerance {}", lateness_ns, scenario.tolerance_ns),
                }
            }
        }
        for (index, _) in scenario.workers.iter().enumerate() {
            let id = ComponentId(index as u32);
            prop_assert_eq!(runtime.core().counters(id).unwrap().misses, misses.get(&id).copied().unwrap_or(0));
        }
    }

    #[test]
    fn one_overrun_delays_every_component_by_at_most_the_overrun_plus_one_round(
        (workers, _slow, _run, overrun_ns) in flat_strategy(None)
    ) {
        let round_ns: u64 = workers.iter().map(|w| w.duration_ns).sum();
        let runs = runs_checking_nesting(&run_flat(&workers, 300_000 * US));
        for run in runs {
            prop_assert!(run.lateness_ns <= overrun_ns + round_ns, "{:?} later than {} + {}", run, overrun_ns, round_ns);
        }
    }

    #[test]
    fn nominal_rates_return_within_one_period_after_the_overload_ends(
        (workers, slow, slow_run, _overrun_ns) in flat_strategy(Some(2))
    ) {
        let round_ns: u64 = workers.iter().map(|w| w.duration_ns).sum();
        let runs = runs_checking_nesting(&run_flat(&workers, 300_000 * US));
        let slow_id = ComponentId(slow as u32);
        let overload_end_ns = runs.iter().filter(|r| r.component == slow_id).nth(slow_run as usize).unwrap().finished_ns;
        for (index, worker) in workers.iter().enumerate() {
            let id = ComponentId(index as u32);
            let settled: Vec<&Run> =
                runs.iter().filter(|r| r.component == id && r.release_ns >= overload_end_ns + worker.period_ns).collect();
            for run in &settled {
                prop_assert_eq!(run.skipped_periods, 0);
                prop_assert!(run.lateness_ns <= round_ns, "{:?} late after the overload", run);
            }
            for pair in settled.windows(2) {
                prop_assert_eq!(pair[1].release_ns - pair[0].release_ns, worker.period_ns, "release dropped at nominal load");
            }
        }
    }

    #[test]
    fn scheduler_core_state_is_deterministic_for_identical_inputs(scenario in scenario_strategy()) {
        let (first, first_trace) = run_scenario(&scenario);
        let (second, second_trace) = run_scenario(&scenario);
        prop_assert_eq!(first_trace, second_trace);
        prop_assert_eq!(first.core(), second.core());
    }
}
