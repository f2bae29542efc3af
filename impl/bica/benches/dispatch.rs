//! Dispatch overhead of the scheduler per step, side by side with a hand-written loop
//! calling the same work directly (the limit): a chain of N trivial components stepped
//! through the cascade, and M top-level components at mixed rates.
// `criterion_group!` generates an undocumented public function.
#![allow(missing_docs)]

use std::hint::black_box;

use bica::prelude::*;
use criterion::{Criterion, criterion_group, criterion_main};

type StepFn = fn(&mut StepContext<'_>) -> Result<Stepped, BicaError>;

/// Trivial work: bump a counter.
struct Trivial<const N: usize> {
    count: u64,
    next: Option<StepFn>,
}

impl<const N: usize> Trivial<N> {
    #[inline(never)]
    fn work(&mut self) {
        self.count = black_box(self.count.wrapping_add(1));
    }
}

impl<const N: usize> Component for Trivial<N> {
    fn step(&mut self, ctx: &mut StepContext<'_>) -> Result<(), BicaError> {
        if let Some(next) = self.next {
            next(ctx)?;
        }
        self.work();
        Ok(())
    }
}

fn step_it<T: Component>(ctx: &mut StepContext<'_>) -> Result<Stepped, BicaError> {
    ctx.step::<T>()
}

const CHAIN: usize = 8;

fn lean(cpu_time_enabled: bool, trace_capacity: usize) -> RuntimeConfig {
    RuntimeConfig {
        scheduler: SchedulerConfig { trace_capacity, ..SchedulerConfig::default() },
        cpu_time_enabled,
        report_interval_ns: 0,
        ..RuntimeConfig::default()
    }
}

macro_rules! register_chain {
    ($runtime:expr, $period:expr, [$($n:literal),*], $last:literal) => {{
        $( $runtime.register(Trivial::<$n> { count: 0, next: Some(step_it::<Trivial<{ $n + 1 }>>) }, $period).unwrap(); )*
        $runtime.register(Trivial::<$last> { count: 0, next: None }, $period).unwrap();
        $runtime.activate::<Trivial<0>>().unwrap();
    }};
}

fn chain_runtime(config: RuntimeConfig) -> Runtime<MonotonicClock> {
    let mut runtime = Runtime::new(config, MonotonicClock::new());
    // Period 1 ns with the real clock: every component is due at every round.
    register_chain!(runtime, 1, [0, 1, 2, 3, 4, 5, 6], 7);
    runtime
}

fn bench_chain(c: &mut Criterion) {
    let mut group = c.benchmark_group(format!("chain_of_{CHAIN}"));
    for (label, config) in [("scheduler_lean", lean(false, 0)), ("scheduler_default", lean(true, 4096))] {
        let mut runtime = chain_runtime(config);
        group.bench_function(label, |b| {
            b.iter(|| {
                let outcome = runtime.run_once().unwrap();
                debug_assert!(matches!(outcome, RunOutcome::Stepped { .. }));
                black_box(outcome);
            })
        });
    }
    let mut c0 = Trivial::<0> { count: 0, next: None };
    let mut c1 = Trivial::<1> { count: 0, next: None };
    let mut c2 = Trivial::<2> { count: 0, next: None };
    let mut c3 = Trivial::<3> { count: 0, next: None };
    let mut c4 = Trivial::<4> { count: 0, next: None };
    let mut c5 = Trivial::<5> { count: 0, next: None };
    let mut c6 = Trivial::<6> { count: 0, next: None };
    let mut c7 = Trivial::<7> { count: 0, next: None };
    group.bench_function("hand_written_loop", |b| {
        b.iter(|| {
            // Same order as the cascade: the deepest dependency's work first.
            c7.work();
            c6.work();
            c5.work();
            c4.work();
            c3.work();
            c2.work();
            c1.work();
            c0.work();
        })
    });
    group.finish();
}

const MIXED: usize = 16;

fn bench_mixed_rates(c: &mut Criterion) {
    // 16 top-level components at periods of 1, 2, 4 and 8 ticks; one tick = 1 ms of
    // virtual time. One iteration = one tick = 7.5 steps on average.
    const TICK_NS: u64 = 1_000_000;
    let mut group = c.benchmark_group(format!("mixed_rates_{MIXED}"));
    let clock = VirtualClock::new(0);
    let mut runtime = Runtime::new(lean(false, 0), clock.clone());
    macro_rules! reg {
        ($($n:literal),*) => {$(
            runtime.register(Trivial::<$n> { count: 0, next: None }, TICK_NS << ($n % 4)).unwrap();
            runtime.activate::<Trivial<$n>>().unwrap();
        )*};
    }
    reg!(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
    group.bench_function("scheduler_lean", |b| {
        b.iter(|| {
            while let RunOutcome::Stepped { .. } = runtime.run_once().unwrap() {}
            clock.advance_ns(TICK_NS);
        })
    });
    let mut work: Vec<Box<dyn FnMut()>> = Vec::new();
    macro_rules! hand {
        ($($n:literal),*) => {$({
            let mut c = Trivial::<$n> { count: 0, next: None };
            work.push(Box::new(move || c.work()));
        })*};
    }
    hand!(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
    let mut tick: u64 = 0;
    group.bench_function("hand_written_loop", |b| {
        b.iter(|| {
            for (index, work) in work.iter_mut().enumerate() {
                if tick.is_multiple_of(1 << (index % 4)) {
                    work();
                }
            }
            tick = black_box(tick + 1);
        })
    });
    group.finish();
}

criterion_group!(benches, bench_chain, bench_mixed_rates);
criterion_main!(benches);
