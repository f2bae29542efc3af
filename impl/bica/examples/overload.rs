//! Runs a small robot on the real scheduler thread, injects a 120 ms overload into one
//! component through remote access, and prints the miss warning (through `tracing`) and
//! the statistics report.

use std::time::Duration;

use bica::prelude::*;

const MS: u64 = 1_000_000;

/// A camera at about 33 Hz; its period is a multiple of the planner's, which steps it.
#[derive(Default)]
struct Camera {
    frames: u64,
}
impl Component for Camera {
    fn step(&mut self, _: &mut StepContext<'_>) -> Result<(), BicaError> {
        self.frames += 1;
        Ok(())
    }
}

/// A 100 Hz planner whose next step can be made to overrun on request.
#[derive(Default)]
struct Planner {
    overload_ms: u64,
}
impl Component for Planner {
    fn step(&mut self, ctx: &mut StepContext<'_>) -> Result<(), BicaError> {
        ctx.step::<Camera>()?;
        if self.overload_ms > 0 {
            std::thread::sleep(Duration::from_millis(std::mem::take(&mut self.overload_ms)));
        }
        Ok(())
    }
}

/// A 100 Hz motion controller, the victim of the overload.
#[derive(Default)]
struct Motion;
impl Component for Motion {
    fn step(&mut self, _: &mut StepContext<'_>) -> Result<(), BicaError> {
        Ok(())
    }
}

fn main() -> Result<(), BicaError> {
    tracing_subscriber::fmt().with_target(false).init();
    let config = RuntimeConfig { report_interval_ns: 1_000 * MS, ..RuntimeConfig::default() };
    let driver = Driver::spawn(config, |runtime| {
        runtime.register(Camera::default(), 30 * MS)?;
        runtime.register(Planner::default(), 10 * MS)?;
        runtime.register(Motion, 10 * MS)?;
        runtime.activate::<Planner>()?;
        runtime.activate::<Motion>()
    })?;
    let remote = driver.remote();
    std::thread::sleep(Duration::from_millis(500));
    println!("injecting a 120 ms overload into the planner");
    remote.call::<Planner, _>(|planner| planner.overload_ms = 120)?;
    std::thread::sleep(Duration::from_millis(1_200));
    let report = remote.submit(|control| control.statistics())?.wait()?;
    println!("{report}");
    driver.stop()
}
