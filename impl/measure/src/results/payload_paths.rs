//! What `cortex bench payload` and the report's "Same-host payloads against the machine's limit" measured.

use serde::Serialize;

use crate::latency::Percentiles;
use crate::spec::{PayloadPath, PayloadPathsExperiment};

/// How the latencies of [`PayloadCell`] are taken, as tables state it.
pub const PAYLOAD_PATHS_LATENCY: &str = "one way: from the writer's stamp just before it writes (an agent's \
    set_attr, the transport's publish, iceoryx2's loan) to each receiver's stamp when the value is in its replica \
    (agents: a change callback, on the thread that joined it) or the sample is in its hands (the transport, \
    iceoryx2), both on this host's wall clock; memcpy: the copy alone";

/// Every cell of one run: the experiment, where it ran, and a cell per size, receivers and path.
#[derive(Clone, Debug, Serialize)]
pub struct PayloadPathsResult {
    /// What was asked for.
    pub experiment: PayloadPathsExperiment,
    /// Whether the loopback bytes were counted in a fresh network namespace (only this run's traffic).
    pub netns: bool,
    /// [`PAYLOAD_PATHS_LATENCY`].
    pub latency: String,
    /// The machine's load average when the run ended.
    pub loadavg: String,
    /// One cell per size, receivers and path (`memcpy`: per size, with 0 receivers), by size, then receivers, then
    /// the experiment's order of paths.
    pub cells: Vec<PayloadCell>,
}

/// One size to one number of receivers by one path.
#[derive(Clone, Debug, Serialize)]
pub struct PayloadCell {
    /// The path.
    pub path: PayloadPath,
    /// Bytes of the payload (for agents, of the attribute's value).
    pub size_bytes: usize,
    /// Receiver processes (0 for `memcpy`).
    pub receivers: u32,
    /// Deliveries expected: samples × receivers (samples for `memcpy`).
    pub expected: u64,
    /// One-way latencies of the deliveries that came ([`PAYLOAD_PATHS_LATENCY`]); `count` is how many came.
    pub latency: Percentiles,
    /// CPU time of a receiver process per sample, ns: each receiver's user + system time over the measured window
    /// (all its threads, `/proc/PID/task/*/schedstat`) over the samples, mean over the receivers.
    pub cpu_ns_per_sample: Option<f64>,
    /// Loopback bytes per sample over the measured window (every process of the run; `None` outside a fresh
    /// network namespace, where other traffic would count too).
    pub loopback_bytes_per_sample: Option<f64>,
    /// This cell's figures over raw iceoryx2's for the same size and receivers, when both were measured.
    pub to_iceoryx2: Option<PathRatios>,
    /// How many times this cell's receivers were started: 1, or more when some did not answer the probes and its
    /// session started again with new processes (at most [`crate::restart::MAX_STARTS`]). In
    /// `results.json` only when above 1.
    #[serde(skip_serializing_if = "super::run::is_first")]
    pub session_starts: u32,
}

/// A cell's figures over another's.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct PathRatios {
    /// p50 over p50.
    pub p50: f64,
    /// p99 over p99.
    pub p99: f64,
    /// Largest over largest.
    pub max: f64,
    /// CPU per sample over CPU per sample, when both were measured.
    pub cpu: Option<f64>,
}

impl PathRatios {
    /// `cell`'s figures over `limit`'s; `None` when either has no delivery.
    pub fn of(cell: &PayloadCell, limit: &PayloadCell) -> Option<PathRatios> {
        let (a, b) = (&cell.latency, &limit.latency);
        if a.count == 0 || b.count == 0 {
            return None;
        }
        let over = |x: u64, y: u64| x as f64 / y.max(1) as f64;
        let cpu = match (cell.cpu_ns_per_sample, limit.cpu_ns_per_sample) {
            (Some(x), Some(y)) if y > 0.0 => Some(x / y),
            _ => None,
        };
        Some(PathRatios {
            p50: over(a.p50_ns, b.p50_ns),
            p99: over(a.p99_ns, b.p99_ns),
            max: over(a.max_ns, b.max_ns),
            cpu,
        })
    }
}

impl PayloadPathsResult {
    /// The result of `cells`: put in table order, each agent and transport cell given its ratios to raw iceoryx2's of the same
    /// size and receivers.
    pub fn new(experiment: PayloadPathsExperiment, netns: bool, loadavg: String, mut cells: Vec<PayloadCell>) -> Self {
        let order = |path: PayloadPath| experiment.paths.iter().position(|&p| p == path).unwrap_or(usize::MAX);
        cells.sort_by_key(|c| (c.size_bytes, c.receivers, order(c.path)));
        let limits: Vec<PayloadCell> = cells.iter().filter(|c| c.path == PayloadPath::Iceoryx2).cloned().collect();
        for cell in cells.iter_mut().filter(|c| matches!(c.path, PayloadPath::Agents(_) | PayloadPath::Transport)) {
            let limit = limits.iter().find(|l| l.size_bytes == cell.size_bytes && l.receivers == cell.receivers);
            cell.to_iceoryx2 = limit.and_then(|limit| PathRatios::of(cell, limit));
        }
        PayloadPathsResult { experiment, netns, latency: PAYLOAD_PATHS_LATENCY.into(), loadavg, cells }
    }

    /// The cell of `path` for `size_bytes` to `receivers`, if measured.
    pub fn cell(&self, path: PayloadPath, size_bytes: usize, receivers: u32) -> Option<&PayloadCell> {
        self.cells.iter().find(|c| c.path == path && c.size_bytes == size_bytes && c.receivers == receivers)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cell(path: PayloadPath, size_bytes: usize, receivers: u32, p50_ns: u64) -> PayloadCell {
        PayloadCell {
            path,
            size_bytes,
            receivers,
            expected: 10,
            latency: Percentiles {
                count: 10,
                p50_ns,
                p99_ns: 2 * p50_ns,
                max_ns: 3 * p50_ns,
                ..Percentiles::default()
            },
            cpu_ns_per_sample: Some(p50_ns as f64),
            loopback_bytes_per_sample: Some(0.0),
            to_iceoryx2: None,
            session_starts: 1,
        }
    }

    #[test]
    fn agent_cells_get_their_ratios_to_raw_iceoryx2_of_the_same_size_and_receivers_in_table_order() {
        let shm = PayloadPath::Agents(agent::Link::Shm);
        let experiment = PayloadPathsExperiment {
            paths: vec![PayloadPath::Memcpy, PayloadPath::Iceoryx2, shm],
            ..PayloadPathsExperiment::default()
        };
        let cells = vec![
            cell(shm, 16, 2, 300),
            cell(PayloadPath::Iceoryx2, 16, 2, 100),
            cell(shm, 16, 1, 50),
            cell(PayloadPath::Memcpy, 16, 0, 1),
            cell(PayloadPath::Iceoryx2, 16, 1, 25),
            cell(shm, 1024, 1, 10),
        ];
        let result = PayloadPathsResult::new(experiment, true, "0.1".into(), cells);
        let order: Vec<(usize, u32, &str)> =
            result.cells.iter().map(|c| (c.size_bytes, c.receivers, c.path.name())).collect();
        assert_eq!(
            order,
            [
                (16, 0, "memcpy"),
                (16, 1, "iceoryx2"),
                (16, 1, "shm"),
                (16, 2, "iceoryx2"),
                (16, 2, "shm"),
                (1024, 1, "shm")
            ]
        );
        let ratios = result.cell(shm, 16, 2).and_then(|c| c.to_iceoryx2).expect("ratios");
        assert_eq!((ratios.p50, ratios.p99, ratios.max, ratios.cpu), (3.0, 3.0, 3.0, Some(3.0)));
        assert_eq!(result.cell(shm, 16, 1).and_then(|c| c.to_iceoryx2).map(|r| r.p50), Some(2.0));
        assert!(result.cell(shm, 1024, 1).expect("cell").to_iceoryx2.is_none(), "no limit measured for it");
        assert!(result.cell(PayloadPath::Iceoryx2, 16, 1).expect("cell").to_iceoryx2.is_none());
    }
}
