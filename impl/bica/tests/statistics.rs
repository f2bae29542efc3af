//! Statistics under the virtual clock: which runs have their thread CPU time measured.

use bica::prelude::*;

/// Does nothing; only its statistics matter.
#[derive(Default)]
struct Fast;
impl Component for Fast {
    fn step(&mut self, _ctx: &mut StepContext<'_>) -> Result<(), BicaError> {
        Ok(())
    }
}

/// Does nothing at a slower rate.
#[derive(Default)]
struct Slow;
impl Component for Slow {
    fn step(&mut self, _ctx: &mut StepContext<'_>) -> Result<(), BicaError> {
        Ok(())
    }
}

#[test]
fn cpu_time_is_measured_every_run_up_to_1_khz_and_once_a_millisecond_above() {
    let clock = VirtualClock::new(0);
    let mut runtime = Runtime::new(RuntimeConfig::default(), clock);
    runtime.register(Fast, 100_000).unwrap(); // 10 kHz
    runtime.register(Slow, 10_000_000).unwrap(); // 100 Hz
    runtime.activate::<Fast>().unwrap();
    runtime.activate::<Slow>().unwrap();
    runtime.run_until(100_000_000 - 1).unwrap(); // 100 ms
    let report = runtime.statistics();
    let fast = report.components.iter().find(|c| c.name.contains("Fast")).unwrap();
    let slow = report.components.iter().find(|c| c.name.contains("Slow")).unwrap();
    assert_eq!(fast.counters.runs, 1000);
    assert_eq!(fast.cpu.count, 100, "one measured run per millisecond");
    assert_eq!(fast.wall.count, 1000, "wall time on every run");
    assert_eq!(slow.counters.runs, 10);
    assert_eq!(slow.cpu.count, 10, "every run of a component at up to 1 kHz");
}

#[test]
fn cpu_time_can_be_measured_on_every_run_or_not_at_all() {
    for (interval_ns, enabled, expected) in [(0, true, 1000), (1_000_000, false, 0)] {
        let config =
            RuntimeConfig { cpu_time_min_interval_ns: interval_ns, cpu_time_enabled: enabled, ..Default::default() };
        let mut runtime = Runtime::new(config, VirtualClock::new(0));
        runtime.register(Fast, 100_000).unwrap();
        runtime.activate::<Fast>().unwrap();
        runtime.run_until(100_000_000 - 1).unwrap();
        let report = runtime.statistics();
        assert_eq!(report.components[0].cpu.count, expected);
    }
}
