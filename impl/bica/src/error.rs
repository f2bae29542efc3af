//! Errors of the BICA runtime. Bad input (an unknown component, a cascade cycle, a
//! full request queue) is reported through [`BicaError`] instead of a panic, so a
//! robot keeps running when one component is misused.

use crate::component_id::ComponentId;

/// Everything that can go wrong when registering, stepping or reaching a component.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum BicaError {
    /// A component type or id was asked for but never registered.
    #[error("unknown component `{component}`: it was never registered")]
    UnknownComponent {
        /// Type name or id of the component that was asked for.
        component: String,
    },
    /// A second instance of a component type was registered.
    #[error("component `{component}` is already registered (one instance per type)")]
    AlreadyRegistered {
        /// Type name of the component.
        component: String,
    },
    /// A component was registered with a period of zero.
    #[error("component `{component}` has an invalid period of 0 ns; periods must be at least 1 ns")]
    InvalidPeriod {
        /// Type name of the component.
        component: String,
    },
    /// A component asked (directly or through others) to step or read a component that is
    /// already stepping higher up the cascade, e.g. A steps B steps A.
    #[error("cascade cycle: `{component}` is already stepping (cascade path: {path})")]
    CascadeCycle {
        /// The component that was asked for while busy.
        component: String,
        /// The cascade from the top-level step down to the repeated component.
        path: String,
    },
    /// A top-level step was started while another step was still running.
    #[error("cannot start top-level step of {component:?}: step of {running:?} is still running")]
    StepOverlap {
        /// Component whose start was refused.
        component: ComponentId,
        /// Component still running.
        running: ComponentId,
    },
    /// A top-level step was started for a component the scheduler did not choose.
    #[error("top-level step of {component:?} was not decided by the scheduler (decided: {decided:?})")]
    NotDecided {
        /// Component whose start was refused.
        component: ComponentId,
        /// What the scheduler decided, if anything.
        decided: Option<ComponentId>,
    },
    /// `finish_step` did not match the innermost running step.
    #[error("finish of {component:?} does not match the running step {running:?}")]
    FinishMismatch {
        /// Component that was reported finished.
        component: ComponentId,
        /// Innermost running component, if any.
        running: Option<ComponentId>,
    },
    /// The active list cannot change while a step is running (changes are applied between steps).
    #[error("cannot change the active list while {running:?} is stepping")]
    ChangeDuringStep {
        /// Component currently running.
        running: ComponentId,
    },
    /// The time given to the scheduler went backwards.
    #[error("time went backwards: {now_ns} ns is before the last seen {last_ns} ns")]
    TimeWentBackwards {
        /// Time that was given.
        now_ns: u64,
        /// Latest time seen before.
        last_ns: u64,
    },
    /// A component's own step reported a failure.
    #[error("step of `{component}` failed: {message}")]
    StepFailed {
        /// Type name of the failing component.
        component: String,
        /// What the component said.
        message: String,
    },
    /// The remote request queue is full; the caller should retry later.
    #[error("remote request queue is full ({capacity} requests)")]
    QueueFull {
        /// Capacity of the queue.
        capacity: usize,
    },
    /// The scheduler thread has stopped and can no longer serve requests.
    #[error("scheduler thread has stopped")]
    SchedulerStopped,
    /// A finite-state machine was declared inconsistently.
    #[error("invalid fsm `{fsm}`: {reason}")]
    InvalidFsm {
        /// Name of the machine.
        fsm: String,
        /// What is wrong.
        reason: String,
    },
    /// A debug primitive was rejected (e.g. image bytes do not match its size).
    #[error("invalid debug primitive: {reason}")]
    InvalidPrimitive {
        /// What is wrong.
        reason: String,
    },
}

impl BicaError {
    /// Builds a [`BicaError::StepFailed`] for component type `T`; handy inside `step`.
    pub fn step_failed<T: ?Sized>(message: impl Into<String>) -> Self {
        Self::StepFailed { component: std::any::type_name::<T>().to_owned(), message: message.into() }
    }
}
