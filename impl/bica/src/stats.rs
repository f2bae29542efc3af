//! Per-component statistics: achieved frequency, wall time and thread CPU time per step
//! (mean, max, percentiles), misses and skipped releases. Percentiles come from a bounded
//! ring of the most recent samples ([`SAMPLE_RING_CAPACITY`] per component), so memory
//! stays fixed however long the robot runs; count, mean and max cover every step.

use std::collections::VecDeque;
use std::fmt;

use serde::{Deserialize, Serialize};

use crate::component_id::ComponentId;
use crate::core::{ComponentCounters, RunInfo, SchedulerCore};

/// Recent samples kept per component for percentiles.
pub const SAMPLE_RING_CAPACITY: usize = 1024;

/// Summary of a duration series in nanoseconds.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct DurationSummary {
    /// Samples ever recorded.
    pub count: u64,
    /// Mean of all samples.
    pub mean_ns: f64,
    /// Largest sample ever.
    pub max_ns: u64,
    /// Median of the recent ring.
    pub p50_ns: u64,
    /// 90th percentile of the recent ring.
    pub p90_ns: u64,
    /// 99th percentile of the recent ring.
    pub p99_ns: u64,
}

#[derive(Debug, Clone, Default)]
struct Series {
    count: u64,
    sum_ns: u128,
    max_ns: u64,
    recent: VecDeque<u64>,
}

impl Series {
    fn record(&mut self, sample_ns: u64) {
        self.count += 1;
        self.sum_ns += u128::from(sample_ns);
        self.max_ns = self.max_ns.max(sample_ns);
        if self.recent.len() == SAMPLE_RING_CAPACITY {
            self.recent.pop_front();
        }
        self.recent.push_back(sample_ns);
    }

    fn summary(&self) -> DurationSummary {
        if self.count == 0 {
            return DurationSummary::default();
        }
        let mut sorted: Vec<u64> = self.recent.iter().copied().collect();
        sorted.sort_unstable();
        let pick = |q: f64| {
            // Nearest-rank percentile.
            let rank = ((q * sorted.len() as f64).ceil() as usize).clamp(1, sorted.len());
            sorted[rank - 1]
        };
        DurationSummary {
            count: self.count,
            mean_ns: self.sum_ns as f64 / self.count as f64,
            max_ns: self.max_ns,
            p50_ns: pick(0.50),
            p90_ns: pick(0.90),
            p99_ns: pick(0.99),
        }
    }
}

#[derive(Debug, Clone, Default)]
struct ComponentSeries {
    wall: Series,
    cpu: Series,
    lateness: Series,
    first_run_ns: Option<u64>,
    last_run_ns: u64,
    last_cpu_timed_ns: Option<u64>,
}

/// Statistics collector, fed by the runtime after every run.
#[derive(Debug, Clone)]
pub struct Statistics {
    per_component: Vec<ComponentSeries>,
    cpu_time_enabled: bool,
    cpu_time_min_interval_ns: u64,
}

impl Statistics {
    /// Creates a collector; with `cpu_time_enabled`, a component's thread CPU time is measured on a run when at
    /// least `cpu_time_min_interval_ns` has passed since its last measured run (0: every run).
    pub fn new(cpu_time_enabled: bool, cpu_time_min_interval_ns: u64) -> Self {
        Self { per_component: Vec::new(), cpu_time_enabled, cpu_time_min_interval_ns }
    }

    /// Whether thread CPU time is measured at all.
    pub fn cpu_time_enabled(&self) -> bool {
        self.cpu_time_enabled
    }

    /// Whether the run of `id` starting at `now_ns` should have its CPU time measured.
    pub fn should_time_cpu(&self, id: ComponentId, now_ns: u64) -> bool {
        if !self.cpu_time_enabled {
            return false;
        }
        let last = self.per_component.get(id.0 as usize).and_then(|series| series.last_cpu_timed_ns);
        last.is_none_or(|last| now_ns.saturating_sub(last) >= self.cpu_time_min_interval_ns)
    }

    /// Records one run of `id`.
    pub fn record_run(
        &mut self,
        id: ComponentId,
        started_ns: u64,
        finished_ns: u64,
        cpu_ns: Option<u64>,
        info: &RunInfo,
    ) {
        let index = id.0 as usize;
        if self.per_component.len() <= index {
            self.per_component.resize_with(index + 1, ComponentSeries::default);
        }
        let series = &mut self.per_component[index];
        series.wall.record(finished_ns.saturating_sub(started_ns));
        if let Some(cpu_ns) = cpu_ns {
            series.cpu.record(cpu_ns);
            series.last_cpu_timed_ns = Some(started_ns);
        }
        series.lateness.record(info.lateness_ns);
        series.first_run_ns.get_or_insert(started_ns);
        series.last_run_ns = started_ns;
    }

    /// Builds a report of every registered component, named by `name_of` (the registry's type names).
    pub fn report(
        &self,
        name_of: impl Fn(ComponentId) -> Option<&'static str>,
        core: &SchedulerCore,
        now_ns: u64,
    ) -> StatisticsReport {
        let components = (0..core.component_count())
            .map(|index| {
                let id = ComponentId(u32::try_from(index).expect("invariant: ids fit in u32"));
                let series = self.per_component.get(index).cloned().unwrap_or_default();
                let counters = core.counters(id).expect("invariant: index is registered");
                let achieved_hz = match series.first_run_ns {
                    Some(first) if counters.runs > 1 && series.last_run_ns > first => {
                        (counters.runs - 1) as f64 * 1e9 / (series.last_run_ns - first) as f64
                    }
                    _ => 0.0,
                };
                let period_ns = core.period_ns(id).expect("invariant: index is registered");
                ComponentReport {
                    name: name_of(id).unwrap_or("?").to_owned(),
                    active: core.is_active(id),
                    nominal_hz: 1e9 / period_ns as f64,
                    achieved_hz,
                    counters,
                    wall: series.wall.summary(),
                    cpu: series.cpu.summary(),
                    lateness: series.lateness.summary(),
                }
            })
            .collect();
        StatisticsReport { at_ns: now_ns, components }
    }
}

/// Statistics of one component.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ComponentReport {
    /// Type name.
    pub name: String,
    /// Whether it is in the active list.
    pub active: bool,
    /// 1 / period.
    pub nominal_hz: f64,
    /// Runs per second between its first and last run.
    pub achieved_hz: f64,
    /// Runs, skips, misses.
    pub counters: ComponentCounters,
    /// Wall time per run.
    pub wall: DurationSummary,
    /// Thread CPU time per run (empty if not measured).
    pub cpu: DurationSummary,
    /// Lateness of each run against its release.
    pub lateness: DurationSummary,
}

/// Statistics of all components at one time.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StatisticsReport {
    /// When the report was made.
    pub at_ns: u64,
    /// One entry per registered component, in id order.
    pub components: Vec<ComponentReport>,
}

impl fmt::Display for StatisticsReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(f, "statistics at {:.3} s", self.at_ns as f64 / 1e9)?;
        writeln!(
            f,
            "{:<28} {:>9} {:>9} {:>7} {:>7} {:>7} {:>10} {:>10} {:>10} {:>10}",
            "component",
            "nom Hz",
            "got Hz",
            "runs",
            "misses",
            "skipped",
            "wall mean",
            "wall p99",
            "wall max",
            "cpu mean"
        )?;
        for c in &self.components {
            let short = c.name.rsplit("::").next().unwrap_or(&c.name);
            writeln!(
                f,
                "{:<28} {:>9.1} {:>9.1} {:>7} {:>7} {:>7} {:>8.1}us {:>8.1}us {:>8.1}us {:>8.1}us",
                short,
                c.nominal_hz,
                c.achieved_hz,
                c.counters.runs,
                c.counters.misses,
                c.counters.skipped_releases,
                c.wall.mean_ns / 1e3,
                c.wall.p99_ns as f64 / 1e3,
                c.wall.max_ns as f64 / 1e3,
                c.cpu.mean_ns / 1e3,
            )?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentiles_use_nearest_rank_over_recent_samples() {
        let mut series = Series::default();
        for sample in 1..=100 {
            series.record(sample);
        }
        let summary = series.summary();
        assert_eq!((summary.p50_ns, summary.p90_ns, summary.p99_ns, summary.max_ns), (50, 90, 99, 100));
        assert!((summary.mean_ns - 50.5).abs() < 1e-9);
    }

    #[test]
    fn sample_ring_is_bounded_but_count_and_max_cover_everything() {
        let mut series = Series::default();
        series.record(1_000_000);
        for _ in 0..(SAMPLE_RING_CAPACITY * 2) {
            series.record(1);
        }
        assert_eq!(series.recent.len(), SAMPLE_RING_CAPACITY);
        let summary = series.summary();
        assert_eq!(summary.count, 2 * SAMPLE_RING_CAPACITY as u64 + 1);
        assert_eq!(summary.max_ns, 1_000_000);
        assert_eq!(summary.p99_ns, 1);
    }
}
