//! Expected-trace tests for hand-written scenarios under the virtual clock: a cascade, a
//! shared dependency, an overrun, a removal and re-activation, and bad input.

mod common;

use bica::prelude::*;
use common::*;

const MS: u64 = 1_000_000;

fn spec(period_ns: u64, duration_ns: u64, deps: Vec<usize>) -> WorkerSpec {
    WorkerSpec { period_ns, duration_ns, overrun: None, deps }
}

fn started(component: ComponentId, caller: Caller, at_ns: u64, release_ns: u64) -> TraceEvent {
    TraceEvent::StepStarted {
        component,
        caller,
        at_ns,
        release_ns,
        lateness_ns: at_ns - release_ns,
        skipped_periods: 0,
    }
}

fn finished(component: ComponentId, at_ns: u64) -> TraceEvent {
    TraceEvent::StepFinished { component, at_ns }
}

#[test]
fn cascade_steps_dependencies_inside_the_parent_step_in_declared_order() {
    let mut runtime = virtual_runtime(SchedulerConfig::default());
    let parent = add_worker(&mut runtime, 0, &spec(10 * MS, MS, vec![1, 2]));
    let vision = add_worker(&mut runtime, 1, &spec(10 * MS, 2 * MS, vec![]));
    let walk = add_worker(&mut runtime, 2, &spec(10 * MS, 3 * MS, vec![]));
    activate_worker(&mut runtime, 0);
    runtime.run_until(5 * MS).unwrap();
    let nested = Caller::Nested { parent };
    assert_eq!(
        runtime.drain_trace(),
        vec![
            TraceEvent::Activated { component: parent, at_ns: 0 },
            started(parent, Caller::TopLevel, 0, 0),
            started(vision, nested, 0, 0),
            finished(vision, 2 * MS),
            // A dependency's grid starts at its first call.
            started(walk, nested, 2 * MS, 2 * MS),
            finished(walk, 5 * MS),
            finished(parent, 6 * MS),
        ]
    );
}

#[test]
fn shared_dependency_runs_its_gated_work_once_per_period() {
    let mut runtime = virtual_runtime(SchedulerConfig { miss_tolerance_ns: 5 * MS, ..SchedulerConfig::default() });
    let first = add_worker(&mut runtime, 0, &spec(10 * MS, MS, vec![2]));
    let second = add_worker(&mut runtime, 1, &spec(10 * MS, MS, vec![2]));
    let shared = add_worker(&mut runtime, 2, &spec(10 * MS, MS, vec![]));
    activate_worker(&mut runtime, 0);
    activate_worker(&mut runtime, 1);
    runtime.drain_trace();
    runtime.run_until(5 * MS).unwrap();
    assert_eq!(
        runtime.drain_trace(),
        vec![
            started(first, Caller::TopLevel, 0, 0),
            started(shared, Caller::Nested { parent: first }, 0, 0),
            finished(shared, MS),
            finished(first, 2 * MS),
            started(second, Caller::TopLevel, 2 * MS, 0),
            TraceEvent::GatedSkip {
                component: shared,
                caller: Caller::Nested { parent: second },
                at_ns: 2 * MS,
                next_release_ns: 10 * MS,
            },
            finished(second, 3 * MS),
        ]
    );
    runtime.run_until(100 * MS).unwrap();
    assert_eq!(worker_runs(&runtime, 2), 10, "one run per 10 ms period over 100 ms");
    assert_eq!(runtime.core().counters(shared).unwrap().gated_skips, 10);
}

#[test]
fn overrun_skips_missed_releases_without_a_catch_up_burst_and_reports_the_miss() {
    let mut runtime = virtual_runtime(SchedulerConfig { miss_tolerance_ns: MS, ..SchedulerConfig::default() });
    // Worker 0 overruns on its first run: 35 ms instead of 1 ms.
    let slow = add_worker(
        &mut runtime,
        0,
        &WorkerSpec { period_ns: 10 * MS, duration_ns: MS, overrun: Some((0, 34 * MS)), deps: vec![] },
    );
    let victim = add_worker(&mut runtime, 1, &spec(10 * MS, MS, vec![]));
    activate_worker(&mut runtime, 0);
    activate_worker(&mut runtime, 1);
    runtime.drain_trace();
    runtime.run_until(60 * MS).unwrap();
    let trace = runtime.drain_trace();
    let expected_miss = |component, expected_ns, actual_ns, skipped_periods, warn| {
        TraceEvent::Miss(MissEvent {
            component,
            expected_ns,
            actual_ns,
            lateness_ns: actual_ns - expected_ns,
            skipped_periods,
            warn,
            suppressed_since_last_warning: 0,
        })
    };
    let started_late = |component, at_ns, release_ns, skipped_periods| TraceEvent::StepStarted {
        component,
        caller: Caller::TopLevel,
        at_ns,
        release_ns,
        lateness_ns: at_ns - release_ns,
        skipped_periods,
    };
    assert_eq!(
        trace,
        vec![
            started(slow, Caller::TopLevel, 0, 0),
            finished(slow, 35 * MS),
            // The victim's release at 0 is served at 35 ms: 3 periods dropped, one miss.
            expected_miss(victim, 0, 35 * MS, 3, true),
            started_late(victim, 35 * MS, 0, 3),
            finished(victim, 36 * MS),
            // A new round: the slow one serves its release at 10 ms once, not three times.
            expected_miss(slow, 10 * MS, 36 * MS, 2, true),
            started_late(slow, 36 * MS, 10 * MS, 2),
            finished(slow, 37 * MS),
            // Back on the original phase (r0 + k*T) right after the overload.
            started(slow, Caller::TopLevel, 40 * MS, 40 * MS),
            finished(slow, 41 * MS),
            started(victim, Caller::TopLevel, 41 * MS, 40 * MS),
            finished(victim, 42 * MS),
            started(slow, Caller::TopLevel, 50 * MS, 50 * MS),
            finished(slow, 51 * MS),
            started(victim, Caller::TopLevel, 51 * MS, 50 * MS),
            finished(victim, 52 * MS),
        ]
    );
    let counters = runtime.core().counters(victim).unwrap();
    assert_eq!((counters.misses, counters.skipped_releases), (1, 3));
}

#[test]
fn removed_component_simply_stops_and_short_gap_is_not_a_reactivation() {
    let mut runtime = virtual_runtime(SchedulerConfig::default());
    add_worker(&mut runtime, 0, &spec(10 * MS, MS, vec![]));
    let removed = add_worker(&mut runtime, 1, &spec(10 * MS, MS, vec![]));
    activate_worker(&mut runtime, 0);
    activate_worker(&mut runtime, 1);
    runtime.run_until(15 * MS).unwrap();
    assert_eq!(worker_runs(&runtime, 1), 2);
    deactivate_worker(&mut runtime, 1);
    runtime.run_until(65 * MS).unwrap();
    assert_eq!(worker_runs(&runtime, 1), 2, "a removed component is not stepped");
    assert!(runtime.drain_trace().iter().all(
        |e| !matches!(e, TraceEvent::StepStarted { component, at_ns, .. } if *component == removed && *at_ns >= 15 * MS)
    ));
    // 50 ms = 5 periods < 10: back without a reactivation notice, on a fresh grid, no miss.
    activate_worker(&mut runtime, 1);
    runtime.run_until(100 * MS).unwrap();
    assert_eq!(worker_runs(&runtime, 1), 6, "runs at 65, 75, 85, 95 ms");
    assert!(worker_reactivations(&runtime, 1).is_empty());
    assert_eq!(runtime.core().counters(removed).unwrap().misses, 0);
}

#[test]
fn component_reactivated_after_more_than_ten_periods_is_told_the_gap() {
    let mut runtime = virtual_runtime(SchedulerConfig::default());
    add_worker(&mut runtime, 0, &spec(10 * MS, MS, vec![]));
    let returning = add_worker(&mut runtime, 1, &spec(10 * MS, MS, vec![]));
    activate_worker(&mut runtime, 0);
    activate_worker(&mut runtime, 1);
    runtime.run_until(5 * MS).unwrap();
    deactivate_worker(&mut runtime, 1); // at 5 ms
    runtime.run_until(200 * MS).unwrap();
    activate_worker(&mut runtime, 1);
    runtime.drain_trace();
    runtime.run_until(205 * MS).unwrap();
    assert_eq!(worker_reactivations(&runtime, 1), vec![195 * MS]);
    let trace = runtime.drain_trace();
    assert!(
        trace.contains(&TraceEvent::Reactivated { component: returning, at_ns: 201 * MS, gap_ns: 195 * MS }),
        "{trace:?}"
    );
    assert_eq!(runtime.core().counters(returning).unwrap().misses, 0, "being inactive is not a miss");
}

#[test]
fn dependency_not_stepped_for_long_is_reactivated_with_a_fresh_grid() {
    let mut runtime = virtual_runtime(SchedulerConfig::default());
    add_worker(&mut runtime, 0, &spec(10 * MS, MS, vec![1]));
    let dependency = add_worker(&mut runtime, 1, &spec(10 * MS, MS, vec![]));
    activate_worker(&mut runtime, 0);
    runtime.run_until(5 * MS).unwrap();
    deactivate_worker(&mut runtime, 0);
    runtime.run_until(300 * MS).unwrap();
    activate_worker(&mut runtime, 0);
    runtime.run_until(305 * MS).unwrap();
    assert_eq!(worker_reactivations(&runtime, 1), vec![300 * MS]);
    let counters = runtime.core().counters(dependency).unwrap();
    assert_eq!((counters.misses, counters.skipped_releases, counters.reactivations), (0, 0, 1));
}

#[test]
fn quick_deactivate_and_activate_does_not_run_twice_in_one_period() {
    let mut runtime = virtual_runtime(SchedulerConfig::default());
    add_worker(&mut runtime, 0, &spec(10 * MS, MS, vec![]));
    activate_worker(&mut runtime, 0);
    runtime.run_until(2 * MS).unwrap();
    deactivate_worker(&mut runtime, 0);
    activate_worker(&mut runtime, 0);
    runtime.run_until(9 * MS).unwrap();
    assert_eq!(worker_runs(&runtime, 0), 1);
    runtime.run_until(11 * MS).unwrap();
    assert_eq!(worker_runs(&runtime, 0), 2);
}

struct CycleA;
struct CycleB;
impl Component for CycleA {
    fn step(&mut self, ctx: &mut StepContext<'_>) -> Result<(), BicaError> {
        ctx.step::<CycleB>()?;
        Ok(())
    }
}
impl Component for CycleB {
    fn step(&mut self, ctx: &mut StepContext<'_>) -> Result<(), BicaError> {
        ctx.step::<CycleA>()?;
        Ok(())
    }
}

#[test]
fn cascade_cycle_is_an_error_naming_the_path_and_the_scheduler_keeps_running() {
    let mut runtime = virtual_runtime(SchedulerConfig::default());
    runtime.register(CycleA, 10 * MS).unwrap();
    runtime.register(CycleB, 10 * MS).unwrap();
    runtime.activate::<CycleA>().unwrap();
    let outcome = runtime.run_once().unwrap();
    let RunOutcome::Stepped { result: Err(BicaError::CascadeCycle { component, path }), .. } = outcome else {
        panic!("expected a cascade cycle, got {outcome:?}");
    };
    assert!(component.ends_with("CycleA"), "{component}");
    assert!(path.contains("CycleA -> ") && path.contains("CycleB -> ") && path.ends_with("CycleA"), "{path}");
    assert_eq!(runtime.step_failures(), 1);
    assert!(runtime.core().running().is_empty());
    // Both are back in their slots and stepping goes on.
    assert!(runtime.registry().get::<CycleA>().is_ok() && runtime.registry().get::<CycleB>().is_ok());
    runtime.clock().advance_ns(10 * MS);
    assert!(matches!(runtime.run_once().unwrap(), RunOutcome::Stepped { .. }));
}

struct StepsUnregistered;
impl Component for StepsUnregistered {
    fn step(&mut self, ctx: &mut StepContext<'_>) -> Result<(), BicaError> {
        ctx.step::<CycleA>()?;
        Ok(())
    }
}

#[test]
fn stepping_an_unregistered_component_is_an_error() {
    let mut runtime = virtual_runtime(SchedulerConfig::default());
    runtime.register(StepsUnregistered, MS).unwrap();
    runtime.activate::<StepsUnregistered>().unwrap();
    let outcome = runtime.run_once().unwrap();
    assert!(
        matches!(outcome, RunOutcome::Stepped { result: Err(BicaError::UnknownComponent { .. }), .. }),
        "{outcome:?}"
    );
    assert!(matches!(runtime.activate::<CycleA>(), Err(BicaError::UnknownComponent { .. })));
}

#[test]
fn registering_a_type_twice_or_with_zero_period_is_an_error() {
    let mut runtime = virtual_runtime(SchedulerConfig::default());
    runtime.register(CycleA, MS).unwrap();
    assert!(matches!(runtime.register(CycleA, MS), Err(BicaError::AlreadyRegistered { .. })));
    assert!(matches!(runtime.register(CycleB, 0), Err(BicaError::InvalidPeriod { .. })));
    assert_eq!(runtime.registry().len(), 1);
}

#[test]
fn scheduler_sleeps_until_the_next_release_instead_of_polling() {
    let mut runtime = virtual_runtime(SchedulerConfig::default());
    add_worker(&mut runtime, 0, &spec(10 * MS, MS, vec![]));
    add_worker(&mut runtime, 1, &spec(4 * MS, MS, vec![]));
    activate_worker(&mut runtime, 0);
    activate_worker(&mut runtime, 1);
    assert!(matches!(runtime.run_once().unwrap(), RunOutcome::Stepped { .. }));
    assert!(matches!(runtime.run_once().unwrap(), RunOutcome::Stepped { .. }));
    assert_eq!(runtime.run_once().unwrap(), RunOutcome::SleepUntil(4 * MS));
    let mut idle = virtual_runtime(SchedulerConfig::default());
    assert_eq!(idle.run_once().unwrap(), RunOutcome::Idle);
}

#[test]
fn core_refuses_overlapping_undecided_and_mismatched_steps() {
    let mut core = SchedulerCore::new(SchedulerConfig::default());
    let a = core.register(10).unwrap();
    let b = core.register(10).unwrap();
    core.activate(a, 0).unwrap();
    core.activate(b, 0).unwrap();
    assert!(matches!(core.begin_step(b, 0, Caller::TopLevel), Err(BicaError::NotDecided { .. })));
    assert_eq!(core.next_decision(0).unwrap(), Decision::Step(a));
    assert!(matches!(core.begin_step(a, 0, Caller::TopLevel).unwrap(), Gate::Run(_)));
    assert!(matches!(core.next_decision(0), Err(BicaError::StepOverlap { .. })));
    assert!(matches!(core.begin_step(b, 0, Caller::TopLevel), Err(BicaError::StepOverlap { .. })));
    assert!(matches!(core.finish_step(b, 1), Err(BicaError::FinishMismatch { .. })));
    assert!(matches!(core.deactivate(b, 1), Err(BicaError::ChangeDuringStep { .. })));
    assert!(matches!(core.begin_step(a, 1, Caller::Nested { parent: a }), Err(BicaError::CascadeCycle { .. })));
    core.finish_step(a, 2).unwrap();
    assert!(matches!(core.next_decision(1), Err(BicaError::TimeWentBackwards { .. })));
    assert!(matches!(core.begin_step(ComponentId(9), 2, Caller::TopLevel), Err(BicaError::UnknownComponent { .. })));
}

#[test]
fn miss_warnings_are_rate_limited_but_every_miss_is_counted() {
    let config = SchedulerConfig { miss_tolerance_ns: 0, warning_interval_ns: 100 * MS, ..SchedulerConfig::default() };
    let mut runtime = virtual_runtime(config);
    // Worker 0 takes 3 ms every 10 ms, so worker 1 is 3 ms late every period.
    add_worker(&mut runtime, 0, &spec(10 * MS, 3 * MS, vec![]));
    let late = add_worker(&mut runtime, 1, &spec(10 * MS, MS, vec![]));
    activate_worker(&mut runtime, 0);
    activate_worker(&mut runtime, 1);
    runtime.run_until(1000 * MS).unwrap();
    let counters = runtime.core().counters(late).unwrap();
    assert_eq!(counters.misses, 100);
    assert_eq!(counters.warnings, 10, "one warning per 100 ms");
    let trace = runtime.drain_trace();
    let warned: Vec<MissEvent> = trace
        .iter()
        .filter_map(|e| match e {
            TraceEvent::Miss(m) if m.warn => Some(*m),
            _ => None,
        })
        .collect();
    assert_eq!(warned[1].suppressed_since_last_warning, 9);
}

#[test]
fn statistics_report_achieved_frequency_and_step_times() {
    let mut runtime = virtual_runtime(SchedulerConfig::default());
    add_worker(&mut runtime, 0, &spec(10 * MS, 2 * MS, vec![]));
    activate_worker(&mut runtime, 0);
    runtime.run_until(1000 * MS).unwrap();
    let report = runtime.statistics();
    let worker = &report.components[0];
    assert_eq!(worker.counters.runs, 100);
    assert!((worker.achieved_hz - 100.0).abs() < 1e-6, "{}", worker.achieved_hz);
    assert_eq!((worker.wall.p50_ns, worker.wall.max_ns), (2 * MS, 2 * MS));
    assert_eq!(worker.cpu.p99_ns, 2 * MS, "the virtual clock's CPU time follows its wall time");
    assert!(report.to_string().contains("Worker<0>"));
}

#[test]
fn identical_inputs_give_identical_traces() {
    let run = || {
        let mut runtime = virtual_runtime(SchedulerConfig::default());
        add_worker(
            &mut runtime,
            0,
            &WorkerSpec { period_ns: 7 * MS, duration_ns: 2 * MS, overrun: Some((3, 20 * MS)), deps: vec![2] },
        );
        add_worker(&mut runtime, 1, &spec(5 * MS, MS, vec![2]));
        add_worker(&mut runtime, 2, &spec(3 * MS, MS, vec![]));
        activate_worker(&mut runtime, 0);
        activate_worker(&mut runtime, 1);
        runtime.run_until(500 * MS).unwrap();
        (runtime.drain_trace(), runtime.core().clone())
    };
    assert_eq!(run(), run());
}
