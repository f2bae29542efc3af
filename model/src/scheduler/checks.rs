//! The properties of the scheduler model, as bits a transition sets: [`Check`] (the `always` properties, one
//! bit per violated property) and [`Fact`] (what the `sometimes` properties look for). The parent module
//! turns them into the property list.

/// The properties of the model: `always` ones are violated by a transition, `sometimes` ones are facts a
/// transition may exhibit.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Check {
    /// A step starts only when no top-level step runs, a nested step only inside its parent, and no
    /// component runs inside itself; time never goes back.
    NoOverlap,
    /// Every started step finishes (within its transition); nothing is left running between iterations.
    NoCancellation,
    /// Every driver call the policy allows is accepted by the core, the trace records each accepted step call
    /// as the driver made it and each served request's list event, and the decided top-level component's gate
    /// is open.
    CallsAccepted,
    /// A run never starts before its release, never serves a release that an earlier run served or dropped
    /// (a grid point at or before the last run's start), and serves a release at least one period after the
    /// last run's: two runs of a component never fall in one period of its grid.
    RateLimit,
    /// Runs serve the phase-preserving grid `r0 + k·T` the trace defines (`r0` from the activation that started
    /// it): the oldest pending release, lateness = the driver's start − release, and skipped = the grid points
    /// that passed unrun (dropped, never caught up).
    SkippedReleasesCounted,
    /// A nested call runs the shared dependency's work iff one of its releases is pending: a second parent's
    /// call in the same period is a gated skip.
    SharedDependencyOncePerPeriod,
    /// A top-level run's lateness is at most X + one round, X being the total overrun so far; the scheduler
    /// never sleeps while a component is due.
    LatenessBound,
    /// A top-level run released one period or more after the last overrun ended is on time again: lateness
    /// at most one round (≤ tolerance) and no skipped release.
    Recovery,
    /// A miss is raised exactly when a run's lateness exceeds the tolerance, carrying its release, start,
    /// lateness and skipped periods.
    MissExactness,
    /// Miss warnings are rate-limited (one per interval, reporting how many were suppressed) while counters
    /// count every run, skip, miss and reactivation; no trace event is dropped.
    CountersNeverLost,
    /// A served deactivation shows in the trace at once, and the component is never stepped by the scheduler
    /// again until the trace shows its activation.
    QuietShutdown,
    /// A component that comes back more than k periods after the trace last saw it (stepped or deactivated)
    /// is told so at its next run, with that gap; otherwise not.
    ReactivationSignalled,
    /// Running a transition twice from the same state gives the same state and trace.
    Determinism,
    /// Every illegal driver call (finishing a step that is not running, starting a step the scheduler did not
    /// decide or while another runs, deciding or changing the list during a step, stepping a component inside
    /// itself, an unknown component) is refused with an error and leaves the core as it was.
    IllegalCallsRefused,
}

impl Check {
    /// Every `always` property, in report order.
    pub const ALL: [Check; 14] = [
        Check::NoOverlap,
        Check::NoCancellation,
        Check::CallsAccepted,
        Check::RateLimit,
        Check::SkippedReleasesCounted,
        Check::SharedDependencyOncePerPeriod,
        Check::LatenessBound,
        Check::Recovery,
        Check::MissExactness,
        Check::CountersNeverLost,
        Check::QuietShutdown,
        Check::ReactivationSignalled,
        Check::Determinism,
        Check::IllegalCallsRefused,
    ];

    /// The property's name in reports.
    pub const fn name(self) -> &'static str {
        match self {
            Check::NoOverlap => "no step overlaps another or itself",
            Check::NoCancellation => "no started step is cancelled",
            Check::CallsAccepted => "the core accepts every driver call",
            Check::RateLimit => "gated work never runs more often than its period allows",
            Check::SkippedReleasesCounted => "skipped releases are counted, never caught up (phase-preserving grid)",
            Check::SharedDependencyOncePerPeriod => "shared dependency runs once per period",
            Check::LatenessBound => "lateness after overruns of X is at most X plus one round",
            Check::Recovery => "on time again one period after the last overrun",
            Check::MissExactness => "a miss is raised exactly when lateness exceeds the tolerance",
            Check::CountersNeverLost => "warnings rate-limited, counters never lost",
            Check::QuietShutdown => "a removed component is never stepped again (quiet shutdown)",
            Check::ReactivationSignalled => "reactivation after a gap of more than k periods is signalled",
            Check::Determinism => "identical inputs give identical traces and states",
            Check::IllegalCallsRefused => "illegal driver calls are refused with an error and change nothing",
        }
    }

    pub(super) const fn bit(self) -> u16 {
        1 << self as u16
    }
}

/// Facts the `sometimes` properties look for, so a model that never reaches them is caught.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Fact {
    /// A run overran.
    Overrun,
    /// A release was dropped (skipped periods > 0).
    SkippedRelease,
    /// A miss was raised.
    Miss,
    /// A miss warning was suppressed by the rate limiter.
    SuppressedWarning,
    /// A second parent's call of the shared dependency was a gated skip.
    DependencyGatedSkip,
    /// A component was deactivated.
    Deactivation,
    /// A reactivation after a long gap was signalled.
    Reactivation,
    /// A top-level run released a period or more after an overload ended (the precondition of `Recovery`).
    RunAfterOverload,
    /// A top-level run later than one round (the overrun term of `LatenessBound` at work).
    LateBeyondRound,
    /// A run late but within the tolerance, so no miss (the other side of `MissExactness`).
    LateWithinTolerance,
    /// A nested step ran inside its parent (the nested case of `NoOverlap`).
    NestedStep,
    /// A remote request (an activation or deactivation) woke the driver during a sleep.
    RequestDuringSleep,
    /// An illegal driver call was tried while a step was running (the in-step case of `IllegalCallsRefused`).
    IllegalCallDuringStep,
}

impl Fact {
    /// Every fact, in report order.
    pub const ALL: [Fact; 13] = [
        Fact::Overrun,
        Fact::SkippedRelease,
        Fact::Miss,
        Fact::SuppressedWarning,
        Fact::DependencyGatedSkip,
        Fact::Deactivation,
        Fact::Reactivation,
        Fact::RunAfterOverload,
        Fact::LateBeyondRound,
        Fact::LateWithinTolerance,
        Fact::NestedStep,
        Fact::RequestDuringSleep,
        Fact::IllegalCallDuringStep,
    ];

    /// The property's name in reports.
    pub const fn name(self) -> &'static str {
        match self {
            Fact::Overrun => "a step overruns",
            Fact::SkippedRelease => "a release is skipped",
            Fact::Miss => "a miss is raised",
            Fact::SuppressedWarning => "a miss warning is suppressed by the rate limiter",
            Fact::DependencyGatedSkip => "a second call of the shared dependency in a period is gated",
            Fact::Deactivation => "a component is deactivated",
            Fact::Reactivation => "a reactivation after a long gap is signalled",
            Fact::RunAfterOverload => "a run is released a period after an overload ended",
            Fact::LateBeyondRound => "a run is later than one round",
            Fact::LateWithinTolerance => "a run is late within the tolerance",
            Fact::NestedStep => "a nested step runs inside its parent",
            Fact::RequestDuringSleep => "a remote request wakes the driver during a sleep",
            Fact::IllegalCallDuringStep => "an illegal driver call is tried during a step",
        }
    }

    pub(super) const fn bit(self) -> u16 {
        1 << self as u16
    }
}
