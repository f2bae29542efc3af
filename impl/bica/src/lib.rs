//! BICA runtime: components with frequencies, a single-threaded cascade scheduler that
//! degrades gracefully, statistics, debug primitives and finite-state machines.
//!
//! A component does one thing. Its inputs (modulations) and results are ordinary methods
//! of its type; [`Component::step`] runs one iteration. In the cascade, a component steps
//! the components it reads *before* reading their results and sets the modulations of the
//! components it drives *before* stepping them. Each component has a period; its frequency
//! gate runs its work at most once per period on a phase-preserving grid, so a dependency
//! shared by several parents runs once per period and an overrun never causes a burst of
//! catch-up steps (see [`core`] for the policy).
//!
//! The scheduler core ([`core::SchedulerCore`]) is a pure state machine: no clock reads,
//! no threads, no I/O. [`Runtime`] runs it with an injected [`Clock`]; [`Driver`] puts it
//! on a thread with the real monotonic clock.
//!
//! ```
//! use bica::prelude::*;
//!
//! /// Reads the (simulated) ball position.
//! #[derive(Default)]
//! struct Vision { ball_x_m: f64 }
//! impl Vision {
//!     fn ball_x_m(&self) -> f64 { self.ball_x_m }
//! }
//! impl Component for Vision {
//!     fn step(&mut self, _ctx: &mut StepContext<'_>) -> Result<(), BicaError> {
//!         self.ball_x_m += 0.5;
//!         Ok(())
//!     }
//! }
//!
//! /// Walks at the speed it is modulated with.
//! #[derive(Default)]
//! struct Walk { speed_m_per_s: f64, steps: u32 }
//! impl Walk {
//!     fn set_speed_m_per_s(&mut self, speed: f64) { self.speed_m_per_s = speed; }
//! }
//! impl Component for Walk {
//!     fn step(&mut self, _ctx: &mut StepContext<'_>) -> Result<(), BicaError> {
//!         self.steps += 1;
//!         Ok(())
//!     }
//! }
//!
//! /// The behaviour: takes information from Vision, drives Walk.
//! struct GoToBall;
//! impl Component for GoToBall {
//!     fn step(&mut self, ctx: &mut StepContext<'_>) -> Result<(), BicaError> {
//!         ctx.step::<Vision>()?;                        // step what we read first...
//!         let ball_x_m = ctx.get::<Vision>()?.ball_x_m(); // ...then read its result,
//!         ctx.get_mut::<Walk>()?.set_speed_m_per_s(ball_x_m.min(1.0)); // modulate...
//!         ctx.step::<Walk>()?;                          // ...then step what we drive.
//!         Ok(())
//!     }
//! }
//!
//! let clock = VirtualClock::new(0);
//! let mut runtime = Runtime::new(RuntimeConfig::default(), clock.clone());
//! runtime.register(Vision::default(), 10_000_000).unwrap(); // 100 Hz
//! runtime.register(Walk::default(), 10_000_000).unwrap();
//! runtime.register(GoToBall, 10_000_000).unwrap();
//! runtime.activate::<GoToBall>().unwrap();
//! runtime.run_until(95_000_000).unwrap(); // releases at 0, 10, ..., 90 ms
//! let walk = runtime.registry().get::<Walk>().unwrap();
//! assert_eq!(walk.steps, 10);
//! assert_eq!(walk.speed_m_per_s, 1.0);
//! ```

pub mod clock;
pub mod component;
pub mod component_id;
pub mod core;
pub mod debug;
pub mod debug_primitives;
pub mod error;
pub mod fsm;
pub mod remote;
pub mod runtime;
pub mod service;
pub mod stats;
pub mod trace;

pub use crate::clock::{Clock, MonotonicClock, VirtualClock};
pub use crate::component::{Component, Handle, Registry, StepContext, Stepped};
pub use crate::error::BicaError;
pub use crate::runtime::{Driver, RunOutcome, Runtime, RuntimeConfig};

/// The names most programs need.
pub mod prelude {
    pub use crate::clock::{Clock, MonotonicClock, VirtualClock};
    pub use crate::component::{Component, Handle, Registry, StepContext, Stepped};
    pub use crate::component_id::ComponentId;
    pub use crate::core::{Decision, Gate, SchedulerConfig, SchedulerCore};
    pub use crate::debug::DebugCollector;
    pub use crate::debug_primitives::Debuggable;
    pub use crate::error::BicaError;
    pub use crate::fsm::Fsm;
    pub use crate::remote::RemoteHandle;
    pub use crate::runtime::{Driver, RunOutcome, Runtime, RuntimeConfig};
    pub use crate::trace::{Caller, MissEvent, TraceEvent};
}
