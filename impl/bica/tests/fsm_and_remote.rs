//! FSM components (required before, modulated after, priorities, stopwatch, restart) and
//! remote access through the request queue, on a virtual runtime and on the real driver.

use std::time::Duration;

use bica::prelude::*;

const MS: u64 = 1_000_000;

/// Records the order components ran in, shared through a component.
#[derive(Default)]
struct Log {
    entries: Vec<&'static str>,
}
impl Component for Log {
    fn step(&mut self, _: &mut StepContext<'_>) -> Result<(), BicaError> {
        Ok(())
    }
}

#[derive(Default)]
struct Sensor {
    value: u32,
}
impl Component for Sensor {
    fn step(&mut self, ctx: &mut StepContext<'_>) -> Result<(), BicaError> {
        self.value += 1;
        ctx.get_mut::<Log>()?.entries.push("sensor");
        Ok(())
    }
}

#[derive(Default)]
struct Actuator {
    command: u32,
}
impl Component for Actuator {
    fn step(&mut self, ctx: &mut StepContext<'_>) -> Result<(), BicaError> {
        ctx.get_mut::<Log>()?.entries.push("actuator");
        Ok(())
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Mode {
    Idle,
    Track,
    Rest,
}

fn tracker() -> Fsm<Mode, u32> {
    Fsm::builder("tracker", Mode::Idle, 0u32)
        .state(Mode::Idle, |s| {
            s.requires::<Sensor>()
                // Declared first, so it wins over the timed transition below.
                .transition(Mode::Rest, |_, ctx, _| ctx.get::<Sensor>().map(|s| s.value >= 100).unwrap_or(false))
                .after_ns(20 * MS, Mode::Track)
        })
        .state(Mode::Track, |s| {
            s.requires::<Sensor>()
                .modulates::<Actuator>()
                .action(|tracked, ctx| {
                    ctx.get_mut::<Log>()?.entries.push("track-action");
                    let value = ctx.get::<Sensor>()?.value;
                    ctx.get_mut::<Actuator>()?.command = value;
                    *tracked += 1;
                    Ok(())
                })
                .after_ns(30 * MS, Mode::Idle)
        })
        .state(Mode::Rest, |s| s)
        .build()
        .unwrap()
}

fn fsm_runtime() -> Runtime<VirtualClock> {
    let mut runtime =
        Runtime::new(RuntimeConfig { report_interval_ns: 0, ..RuntimeConfig::default() }, VirtualClock::new(0));
    runtime.register(Log::default(), MS).unwrap();
    runtime.register(Sensor::default(), 10 * MS).unwrap();
    runtime.register(Actuator::default(), 10 * MS).unwrap();
    runtime.register(tracker(), 10 * MS).unwrap();
    runtime.activate::<Fsm<Mode, u32>>().unwrap();
    runtime
}

#[test]
fn fsm_steps_required_components_before_its_action_and_modulated_ones_after() {
    let mut runtime = fsm_runtime();
    runtime.run_until(25 * MS).unwrap(); // steps at 0, 10, 20: the third one enters Track
    let fsm = runtime.registry().get::<Fsm<Mode, u32>>().unwrap();
    assert_eq!(fsm.current_state(), Mode::Track);
    assert_eq!(fsm.entered_ns(), Some(20 * MS));
    assert_eq!(
        runtime.registry().get::<Log>().unwrap().entries,
        vec!["sensor", "sensor", "sensor", "track-action", "actuator"]
    );
    assert_eq!(runtime.registry().get::<Actuator>().unwrap().command, 3);
}

#[test]
fn fsm_timed_transition_uses_the_per_state_stopwatch() {
    let mut runtime = fsm_runtime();
    runtime.run_until(45 * MS).unwrap();
    assert_eq!(runtime.registry().get::<Fsm<Mode, u32>>().unwrap().current_state(), Mode::Track);
    runtime.run_until(55 * MS).unwrap(); // 50 ms: 30 ms in Track
    let fsm = runtime.registry().get::<Fsm<Mode, u32>>().unwrap();
    assert_eq!(fsm.current_state(), Mode::Idle);
    assert_eq!((fsm.transitions_taken(), *fsm.data()), (2, 3));
}

#[test]
fn fsm_earlier_transition_has_priority() {
    let mut runtime = fsm_runtime();
    runtime.registry_mut().get_mut::<Sensor>().unwrap().value = 200;
    runtime.run_until(35 * MS).unwrap();
    assert_eq!(runtime.registry().get::<Fsm<Mode, u32>>().unwrap().current_state(), Mode::Rest);
}

#[test]
fn fsm_restarts_from_its_initial_state_after_reactivation() {
    let mut runtime = fsm_runtime();
    runtime.run_until(25 * MS).unwrap();
    runtime.deactivate::<Fsm<Mode, u32>>().unwrap();
    runtime.run_until(500 * MS).unwrap();
    runtime.activate::<Fsm<Mode, u32>>().unwrap();
    runtime.run_until(505 * MS).unwrap();
    let fsm = runtime.registry().get::<Fsm<Mode, u32>>().unwrap();
    assert_eq!((fsm.current_state(), fsm.entered_ns()), (Mode::Idle, Some(500 * MS)));
}

#[test]
fn fsm_declaration_errors_are_reported() {
    let undeclared_target =
        Fsm::builder("bad", Mode::Idle, ()).state(Mode::Idle, |s| s.after_ns(1, Mode::Rest)).build();
    assert!(matches!(undeclared_target, Err(BicaError::InvalidFsm { .. })));
    let missing_initial = Fsm::builder("bad", Mode::Idle, ()).state(Mode::Rest, |s| s).build();
    assert!(matches!(missing_initial, Err(BicaError::InvalidFsm { .. })));
    let duplicate = Fsm::builder("bad", Mode::Idle, ()).state(Mode::Idle, |s| s).state(Mode::Idle, |s| s).build();
    assert!(matches!(duplicate, Err(BicaError::InvalidFsm { .. })));
}

#[test]
fn remote_requests_are_served_between_steps_on_the_scheduler_thread() {
    let mut runtime = fsm_runtime();
    let remote = runtime.remote();
    let set = remote.submit(|control| control.get_mut::<Actuator>().map(|a| a.command = 42)).unwrap();
    let read = remote.submit(|control| control.get::<Actuator>().map(|a| a.command)).unwrap();
    assert!(set.try_take().is_none(), "nothing runs before the scheduler serves the queue");
    runtime.run_once().unwrap();
    assert_eq!(set.wait().unwrap(), Ok(()));
    assert_eq!(read.wait().unwrap(), Ok(42));
    let activate_log =
        remote.submit(|control| control.get::<Sensor>().map(|s| s.value).and(control.activate::<Log>())).unwrap();
    runtime.run_once().unwrap();
    assert_eq!(activate_log.wait().unwrap(), Ok(()));
    assert!(runtime.core().active().len() == 2);
}

#[test]
fn full_request_queue_is_an_error_not_a_block() {
    let config = RuntimeConfig { request_queue_capacity: 2, ..RuntimeConfig::default() };
    let runtime = Runtime::new(config, VirtualClock::new(0));
    let remote = runtime.remote();
    remote.submit(|_| ()).unwrap();
    remote.submit(|_| ()).unwrap();
    assert_eq!(remote.submit(|_| ()).unwrap_err(), BicaError::QueueFull { capacity: 2 });
    drop(runtime);
    assert_eq!(remote.submit(|_| ()).unwrap_err(), BicaError::SchedulerStopped);
}

#[derive(Default)]
struct Counter {
    steps: u64,
    target: i64,
}
impl Component for Counter {
    fn step(&mut self, _: &mut StepContext<'_>) -> Result<(), BicaError> {
        self.steps += 1;
        Ok(())
    }
}

#[test]
fn driver_thread_serves_remote_calls_and_stops_on_request() {
    let driver = Driver::spawn(RuntimeConfig::default(), |runtime| {
        runtime.register(Counter::default(), MS)?;
        runtime.activate::<Counter>()
    })
    .unwrap();
    let remote = driver.remote();
    remote.call::<Counter, _>(|c| c.target = -7).unwrap();
    assert_eq!(remote.call::<Counter, _>(|c| c.target).unwrap(), -7);
    // Wait (bounded) until the thread has stepped at least twice; no speed is asserted.
    let mut steps = 0;
    for _ in 0..2000 {
        steps = remote.call::<Counter, _>(|c| c.steps).unwrap();
        if steps >= 2 {
            break;
        }
        std::thread::sleep(Duration::from_millis(1));
    }
    assert!(steps >= 2);
    assert!(matches!(remote.call::<Sensor, _>(|s| s.value), Err(BicaError::UnknownComponent { .. })));
    driver.stop().unwrap();
    assert_eq!(remote.call::<Counter, _>(|c| c.steps).unwrap_err(), BicaError::SchedulerStopped);
}

#[test]
fn driver_reports_a_failing_build() {
    let result = Driver::spawn(RuntimeConfig::default(), |runtime| runtime.activate::<Counter>());
    assert!(matches!(result, Err(BicaError::UnknownComponent { .. })));
}
