//! The scheduler model's configuration: the top-level components, the shared dependency, the overrun and
//! list-change budgets, and the core's tunables; its validation, and the derived quantities the properties use
//! (one round, nominal step durations).

use bica::core::{ComponentId, SchedulerConfig};
use serde::{Deserialize, Serialize};

#[cfg(feature = "mutants")]
use bica::core::SchedulerMutant;

/// One top-level component of the model.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct TopLevelSpec {
    /// Name used in counterexamples.
    pub name: String,
    /// Period (its releases are `r0 + k·period`).
    pub period_ns: u64,
    /// Duration of its own work at nominal load (the dependency's run, if any, comes on top).
    pub nominal_ns: u64,
    /// Whether its step calls the shared dependency (as `Caller::Nested`) before its own work.
    pub calls_dependency: bool,
}

/// The dependency shared by the parents.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct DependencySpec {
    /// Name used in counterexamples.
    pub name: String,
    /// Period of its frequency gate.
    pub period_ns: u64,
    /// Duration of its work at nominal load.
    pub nominal_ns: u64,
}

/// Configuration of the scheduler model. Times are nanoseconds of the virtual clock.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct SchedulerModelConfig {
    /// The top-level components, in activation (and so stepping) order.
    pub components: Vec<TopLevelSpec>,
    /// The shared dependency.
    pub dependency: DependencySpec,
    /// Duration of an overrunning run (of a component's own work or of the dependency).
    pub overrun_ns: u64,
    /// How many runs in one path may overrun.
    pub max_overruns: u8,
    /// The core's miss tolerance: a miss is raised exactly when lateness exceeds it.
    pub miss_tolerance_ns: u64,
    /// The core's `reactivation_gap_periods` (k): a gap of more than k periods is signalled.
    pub reactivation_gap_periods: u64,
    /// The core's warning interval (at most one miss warning per component per interval).
    pub warning_interval_ns: u64,
    /// No transition starts at or after this virtual time (keeps the state space finite).
    pub horizon_ns: u64,
    /// How many activations/deactivations the checker may inject in one path.
    pub max_list_changes: u8,
    /// Run every transition twice and compare (the determinism property).
    pub check_determinism: bool,
    /// The planted scheduler bug, if any.
    #[cfg(feature = "mutants")]
    #[serde(serialize_with = "serialize_mutant", skip_deserializing)]
    pub mutant: Option<SchedulerMutant>,
}

#[cfg(feature = "mutants")]
fn serialize_mutant<S: serde::Serializer>(mutant: &Option<SchedulerMutant>, serializer: S) -> Result<S::Ok, S::Error> {
    match mutant {
        Some(mutant) => serializer.serialize_some(&format!("{mutant:?}")),
        None => serializer.serialize_none(),
    }
}

impl Default for SchedulerModelConfig {
    /// Time is counted in nanoseconds of the core's clock but the numbers are kept small (the model is
    /// scale-free; small numbers keep counterexamples readable and let a lateness of exactly tolerance + 1 ns
    /// occur). Two parents ("planner", "controller", period 10 ns) share a dependency ("perception", period
    /// 10 ns) and an independent "logger" has period 20 ns; nominal work takes 1 ns (2 ns for the logger); an
    /// overrunning run takes 12 ns (longer than a period, so releases are skipped); the tolerance is 4 ns (one
    /// round, so nominal load never misses); two overruns (so one component can miss twice within the 20 ns
    /// warning interval) and two list changes per path; k = 1 period; horizon 40 ns.
    fn default() -> Self {
        let top = |name: &str, period_ns: u64, nominal_ns: u64, calls_dependency: bool| TopLevelSpec {
            name: name.to_owned(),
            period_ns,
            nominal_ns,
            calls_dependency,
        };
        SchedulerModelConfig {
            components: vec![top("planner", 10, 1, true), top("controller", 10, 1, true), top("logger", 20, 2, false)],
            dependency: DependencySpec { name: "perception".to_owned(), period_ns: 10, nominal_ns: 1 },
            overrun_ns: 12,
            max_overruns: 2,
            miss_tolerance_ns: 4,
            reactivation_gap_periods: 1,
            warning_interval_ns: 20,
            horizon_ns: 40,
            max_list_changes: 2,
            check_determinism: true,
            #[cfg(feature = "mutants")]
            mutant: None,
        }
    }
}

impl SchedulerModelConfig {
    /// Number of registered components: the top-level ones and the dependency (the last id).
    pub fn registered(&self) -> usize {
        self.components.len() + 1
    }

    /// Id of the shared dependency in the core.
    pub fn dependency_id(&self) -> ComponentId {
        ComponentId(self.components.len() as u32)
    }

    /// Duration of one nominal top-level step of component `index`, its dependency's run included.
    pub fn nominal_step_ns(&self, index: usize) -> u64 {
        let spec = &self.components[index];
        spec.nominal_ns + if spec.calls_dependency { self.dependency.nominal_ns } else { 0 }
    }

    /// "One scheduler round" for top-level component `index`: the sum of the nominal step durations of the
    /// other top-level components (each parent's step including a run of the dependency). In a round every
    /// due component is stepped at most once, so at nominal load this is the longest a released component
    /// waits for the others.
    pub fn round_ns(&self, index: usize) -> u64 {
        (0..self.components.len()).filter(|&other| other != index).map(|other| self.nominal_step_ns(other)).sum()
    }

    /// Period of a registered component (top-level index, or the dependency's id).
    pub fn period_ns(&self, index: usize) -> u64 {
        self.components.get(index).map_or(self.dependency.period_ns, |spec| spec.period_ns)
    }

    /// Name of a registered component.
    pub fn name(&self, index: usize) -> &str {
        self.components.get(index).map_or(self.dependency.name.as_str(), |spec| spec.name.as_str())
    }

    /// Checks that the configuration is one the degradation guarantees are stated for: at least one
    /// component, non-zero periods, a nominal load that fits in the shortest period, a tolerance of at least
    /// one round (so nominal load raises no miss) and an overrun longer than every nominal duration.
    pub fn validate(&self) -> Result<(), String> {
        if self.components.is_empty() || self.components.len() > 15 {
            return Err("the model needs between 1 and 15 top-level components".to_owned());
        }
        if self.components.iter().any(|c| c.period_ns == 0) || self.dependency.period_ns == 0 {
            return Err("periods must be positive".to_owned());
        }
        let load: u64 = (0..self.components.len()).map(|i| self.nominal_step_ns(i)).sum();
        let shortest = self.components.iter().map(|c| c.period_ns).chain([self.dependency.period_ns]).min();
        if shortest.is_some_and(|shortest| load > shortest) {
            return Err(format!("nominal load per round ({load} ns) exceeds the shortest period"));
        }
        if let Some(index) = (0..self.components.len()).find(|&i| self.round_ns(i) > self.miss_tolerance_ns) {
            return Err(format!(
                "the tolerance ({} ns) is shorter than one round for {} ({} ns): nominal load would miss",
                self.miss_tolerance_ns,
                self.name(index),
                self.round_ns(index)
            ));
        }
        let longest_nominal =
            self.components.iter().map(|c| c.nominal_ns).chain([self.dependency.nominal_ns]).max().unwrap_or(0);
        if self.overrun_ns <= longest_nominal {
            return Err("the overrun must be longer than every nominal duration".to_owned());
        }
        Ok(())
    }

    pub(super) fn scheduler_config(&self) -> SchedulerConfig {
        SchedulerConfig {
            miss_tolerance_ns: self.miss_tolerance_ns,
            reactivation_gap_periods: self.reactivation_gap_periods,
            warning_interval_ns: self.warning_interval_ns,
            trace_capacity: 64,
            #[cfg(feature = "mutants")]
            mutant: self.mutant,
            ..SchedulerConfig::default()
        }
    }
}
