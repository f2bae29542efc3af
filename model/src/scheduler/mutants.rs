//! The five scheduler mutants of `bica`, each planted in the default configuration with the property expected
//! to kill it.

use bica::core::SchedulerMutant;

use super::checks::Check;
use super::config::SchedulerModelConfig;

/// One planted scheduler bug: its name, a configuration with it planted, and the property expected to catch it.
#[derive(Clone, Debug)]
pub struct SchedulerMutantCase {
    /// The mutant's name.
    pub name: &'static str,
    /// The model configuration with the mutant planted.
    pub config: SchedulerModelConfig,
    /// The `always` property expected to fail.
    pub expected_property: &'static str,
}

/// The five scheduler mutants of `bica`, each planted in the default configuration.
pub fn scheduler_mutants() -> Vec<SchedulerMutantCase> {
    let case = |name, mutant, check: Check| SchedulerMutantCase {
        name,
        config: SchedulerModelConfig { mutant: Some(mutant), ..SchedulerModelConfig::default() },
        expected_property: check.name(),
    };
    vec![
        case("scheduler-catch-up-burst", SchedulerMutant::CatchUpBurst, Check::SkippedReleasesCounted),
        case(
            "scheduler-shared-dependency-twice",
            SchedulerMutant::SharedDependencyTwice,
            Check::SharedDependencyOncePerPeriod,
        ),
        case("scheduler-miss-off-by-one", SchedulerMutant::MissOffByOne, Check::MissExactness),
        case("scheduler-removed-stepped-once-more", SchedulerMutant::RemovedSteppedOnceMore, Check::QuietShutdown),
        case("scheduler-finish-unmatched", SchedulerMutant::FinishUnmatched, Check::IllegalCallsRefused),
    ]
}
