//! Shared test fixtures: a scripted `Worker` component that spends virtual time, and trace
//! checkers for the scheduler's degradation properties.
#![allow(dead_code, missing_docs)]

use bica::prelude::*;

pub type StepFn = fn(&mut StepContext<'_>) -> Result<Stepped, BicaError>;

/// A component that steps its dependencies, then spends `duration_ns` of virtual time
/// (plus `extra_ns` on run number `run_index` of the pair in `overrun`).
pub struct Worker<const N: usize> {
    pub clock: VirtualClock,
    pub duration_ns: u64,
    pub overrun: Option<(u64, u64)>,
    pub deps: Vec<StepFn>,
    pub runs: u64,
    pub reactivation_gaps_ns: Vec<u64>,
}

impl<const N: usize> Worker<N> {
    pub fn new(clock: &VirtualClock, duration_ns: u64) -> Self {
        Self {
            clock: clock.clone(),
            duration_ns,
            overrun: None,
            deps: Vec::new(),
            runs: 0,
            reactivation_gaps_ns: Vec::new(),
        }
    }
}

impl<const N: usize> Component for Worker<N> {
    fn step(&mut self, ctx: &mut StepContext<'_>) -> Result<(), BicaError> {
        for dep in &self.deps {
            dep(ctx)?;
        }
        let extra = match self.overrun {
            Some((run, extra)) if run == self.runs => extra,
            _ => 0,
        };
        self.clock.advance_ns(self.duration_ns + extra);
        self.runs += 1;
        Ok(())
    }

    fn on_reactivated(&mut self, gap_ns: u64) {
        self.reactivation_gaps_ns.push(gap_ns);
    }
}

fn step_it<T: Component>(ctx: &mut StepContext<'_>) -> Result<Stepped, BicaError> {
    ctx.step::<T>()
}

pub const MAX_WORKERS: usize = 8;

/// Description of one worker for `add_worker`.
#[derive(Debug, Clone)]
pub struct WorkerSpec {
    pub period_ns: u64,
    pub duration_ns: u64,
    pub overrun: Option<(u64, u64)>,
    pub deps: Vec<usize>,
}

macro_rules! by_index {
    ($index:expr, $n:ident => $body:expr) => {
        match $index {
            0 => {
                const $n: usize = 0;
                $body
            }
            1 => {
                const $n: usize = 1;
                $body
            }
            2 => {
                const $n: usize = 2;
                $body
            }
            3 => {
                const $n: usize = 3;
                $body
            }
            4 => {
                const $n: usize = 4;
                $body
            }
            5 => {
                const $n: usize = 5;
                $body
            }
            6 => {
                const $n: usize = 6;
                $body
            }
            7 => {
                const $n: usize = 7;
                $body
            }
            other => panic!("test fixture supports {MAX_WORKERS} workers, got index {other}"),
        }
    };
}

/// The step function of worker `index`, for use as a dependency.
pub fn step_worker(index: usize) -> StepFn {
    by_index!(index, I => step_it::<Worker<I>>)
}

/// Registers worker `index` (registration order must follow the index).
pub fn add_worker(runtime: &mut Runtime<VirtualClock>, index: usize, spec: &WorkerSpec) -> ComponentId {
    let clock = runtime.clock().clone();
    by_index!(index, I => {
        let mut worker = Worker::<I>::new(&clock, spec.duration_ns);
        worker.overrun = spec.overrun;
        worker.deps = spec.deps.iter().map(|&d| step_worker(d)).collect();
        runtime.register(worker, spec.period_ns).unwrap().id()
    })
}

pub fn activate_worker(runtime: &mut Runtime<VirtualClock>, index: usize) {
    by_index!(index, I => runtime.activate::<Worker<I>>().unwrap())
}

pub fn deactivate_worker(runtime: &mut Runtime<VirtualClock>, index: usize) {
    by_index!(index, I => runtime.deactivate::<Worker<I>>().unwrap())
}

pub fn worker_runs(runtime: &Runtime<VirtualClock>, index: usize) -> u64 {
    by_index!(index, I => runtime.registry().get::<Worker<I>>().unwrap().runs)
}

pub fn worker_reactivations(runtime: &Runtime<VirtualClock>, index: usize) -> Vec<u64> {
    by_index!(index, I => runtime.registry().get::<Worker<I>>().unwrap().reactivation_gaps_ns.clone())
}

/// A runtime with a big trace and a virtual clock at 0.
pub fn virtual_runtime(scheduler: SchedulerConfig) -> Runtime<VirtualClock> {
    let config = RuntimeConfig {
        scheduler: SchedulerConfig { trace_capacity: 1 << 20, ..scheduler },
        report_interval_ns: 0,
        ..RuntimeConfig::default()
    };
    Runtime::new(config, VirtualClock::new(0))
}

/// One run of gated work reconstructed from the trace.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Run {
    pub component: ComponentId,
    pub caller: Caller,
    pub started_ns: u64,
    pub finished_ns: u64,
    pub release_ns: u64,
    pub lateness_ns: u64,
    pub skipped_periods: u64,
}

/// Checks nesting (no overlap, nothing cancelled, nested calls come from the innermost
/// running step, time never goes back) and returns the runs in start order.
pub fn runs_checking_nesting(trace: &[TraceEvent]) -> Vec<Run> {
    let mut stack: Vec<usize> = Vec::new();
    let mut runs: Vec<Run> = Vec::new();
    let mut last_time = 0;
    for event in trace {
        match *event {
            TraceEvent::StepStarted { component, caller, at_ns, release_ns, lateness_ns, skipped_periods } => {
                assert!(at_ns >= last_time, "time went back at {event:?}");
                last_time = at_ns;
                match caller {
                    Caller::TopLevel => assert!(stack.is_empty(), "top-level step {event:?} overlaps {stack:?}"),
                    Caller::Nested { parent } => {
                        let top = stack.last().map(|&i| runs[i].component);
                        assert_eq!(top, Some(parent), "nested step {event:?} not called by the running step");
                    }
                }
                assert!(!stack.iter().any(|&i| runs[i].component == component), "{component:?} overlaps itself");
                stack.push(runs.len());
                runs.push(Run {
                    component,
                    caller,
                    started_ns: at_ns,
                    finished_ns: 0,
                    release_ns,
                    lateness_ns,
                    skipped_periods,
                });
            }
            TraceEvent::StepFinished { component, at_ns } => {
                assert!(at_ns >= last_time);
                last_time = at_ns;
                let index = stack.pop().expect("finish without start");
                assert_eq!(runs[index].component, component, "finish does not match innermost start");
                runs[index].finished_ns = at_ns;
            }
            _ => {}
        }
    }
    assert!(stack.is_empty(), "steps started but never finished (cancelled): {stack:?}");
    runs
}

/// Checks that each component's runs serve strictly later releases on its grid, never
/// before the release and never twice per period.
pub fn check_rate_limit(runs: &[Run], period_of: impl Fn(ComponentId) -> u64) {
    let mut previous: std::collections::HashMap<ComponentId, Run> = std::collections::HashMap::new();
    for run in runs {
        assert!(run.release_ns <= run.started_ns, "run before its release: {run:?}");
        assert_eq!(run.lateness_ns, run.started_ns - run.release_ns);
        let period = period_of(run.component);
        assert_eq!(run.skipped_periods, run.lateness_ns / period, "skipped periods miscounted: {run:?}");
        if let Some(prev) = previous.get(&run.component) {
            assert!(
                run.release_ns >= prev.release_ns + period * (prev.skipped_periods + 1),
                "{run:?} serves a release already served by {prev:?}"
            );
            assert!(run.started_ns >= prev.release_ns + period, "{run:?} runs twice in the period of {prev:?}");
        }
        previous.insert(run.component, *run);
    }
}
