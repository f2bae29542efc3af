//! With feature `mutants`, each planted scheduler bug must change observable behaviour in
//! the scenario built to expose it; the same scenario without the mutant is the control.
#![cfg(feature = "mutants")]

mod common;

use bica::core::SchedulerMutant;
use bica::prelude::*;
use common::*;

const MS: u64 = 1_000_000;

fn runtime_with(mutant: Option<SchedulerMutant>, tolerance_ns: u64) -> Runtime<VirtualClock> {
    virtual_runtime(SchedulerConfig { mutant, miss_tolerance_ns: tolerance_ns, ..SchedulerConfig::default() })
}

fn spec(period_ns: u64, duration_ns: u64, deps: Vec<usize>) -> WorkerSpec {
    WorkerSpec { period_ns, duration_ns, overrun: None, deps }
}

fn overrun_runs(mutant: Option<SchedulerMutant>) -> Vec<Run> {
    let mut runtime = runtime_with(mutant, MS);
    add_worker(
        &mut runtime,
        0,
        &WorkerSpec { period_ns: 10 * MS, duration_ns: MS, overrun: Some((0, 39 * MS)), deps: vec![] },
    );
    activate_worker(&mut runtime, 0);
    runtime.run_until(60 * MS).unwrap();
    runs_checking_nesting(&runtime.drain_trace())
}

#[test]
fn catch_up_burst_mutant_runs_back_to_back_after_an_overrun() {
    let control = overrun_runs(None);
    let mutant = overrun_runs(Some(SchedulerMutant::CatchUpBurst));
    // Control: 0 (overruns to 40 ms), then 40, 50 ms on the grid.
    assert_eq!(control.iter().map(|r| r.started_ns).collect::<Vec<_>>(), vec![0, 40 * MS, 50 * MS]);
    // Mutant: releases 10, 20, 30 ms are "caught up" back to back from 40 ms.
    assert!(mutant.len() > control.len());
    assert!(mutant.windows(2).any(|p| p[1].started_ns - p[0].started_ns < 10 * MS));
}

fn shared_runs(mutant: Option<SchedulerMutant>) -> u64 {
    let mut runtime = runtime_with(mutant, 10 * MS);
    add_worker(&mut runtime, 0, &spec(10 * MS, MS, vec![2]));
    add_worker(&mut runtime, 1, &spec(10 * MS, MS, vec![2]));
    add_worker(&mut runtime, 2, &spec(10 * MS, MS, vec![]));
    activate_worker(&mut runtime, 0);
    activate_worker(&mut runtime, 1);
    runtime.run_until(100 * MS).unwrap();
    worker_runs(&runtime, 2)
}

#[test]
fn shared_dependency_mutant_runs_the_dependency_twice_per_period() {
    assert_eq!(shared_runs(None), 10);
    assert_eq!(shared_runs(Some(SchedulerMutant::SharedDependencyTwice)), 20);
}

fn misses_at_tolerance_plus_one(mutant: Option<SchedulerMutant>) -> u64 {
    let tolerance_ns = MS;
    let mut runtime = runtime_with(mutant, tolerance_ns);
    // Worker 0 takes exactly tolerance + 1, so worker 1 starts tolerance + 1 late.
    add_worker(&mut runtime, 0, &spec(10 * MS, tolerance_ns + 1, vec![]));
    let late = add_worker(&mut runtime, 1, &spec(10 * MS, 0, vec![]));
    activate_worker(&mut runtime, 0);
    activate_worker(&mut runtime, 1);
    runtime.run_until(5 * MS).unwrap();
    runtime.core().counters(late).unwrap().misses
}

#[test]
fn miss_off_by_one_mutant_hides_the_miss_at_tolerance_plus_one() {
    assert_eq!(misses_at_tolerance_plus_one(None), 1);
    assert_eq!(misses_at_tolerance_plus_one(Some(SchedulerMutant::MissOffByOne)), 0);
}

fn runs_after_removal(mutant: Option<SchedulerMutant>) -> u64 {
    let mut runtime = runtime_with(mutant, MS);
    add_worker(&mut runtime, 0, &spec(10 * MS, MS, vec![]));
    activate_worker(&mut runtime, 0);
    runtime.run_until(5 * MS).unwrap();
    let before = worker_runs(&runtime, 0);
    deactivate_worker(&mut runtime, 0);
    runtime.run_until(100 * MS).unwrap();
    worker_runs(&runtime, 0) - before
}

#[test]
fn removed_stepped_once_more_mutant_steps_a_removed_component() {
    assert_eq!(runs_after_removal(None), 0);
    assert_eq!(runs_after_removal(Some(SchedulerMutant::RemovedSteppedOnceMore)), 1);
}

fn finish_with_nothing_running(mutant: Option<SchedulerMutant>) -> bool {
    let mut core = SchedulerCore::new(SchedulerConfig { mutant, ..SchedulerConfig::default() });
    let id = core.register(10 * MS).unwrap();
    core.activate(id, 0).unwrap();
    core.finish_step(id, 0).is_ok()
}

#[test]
fn finish_unmatched_mutant_accepts_finishing_a_step_that_is_not_running() {
    assert!(!finish_with_nothing_running(None));
    assert!(finish_with_nothing_running(Some(SchedulerMutant::FinishUnmatched)));
}
