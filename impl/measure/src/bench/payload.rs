//! Payloads from one writer to N receiver processes on this host, by every [`PayloadPath`] in one run, beside the
//! machine's own limit (issue 20; `cortex bench payload` and the report's "Same-host payloads against the
//! machine's limit"):
//!
//! - **agents over a link** (`agents.rs`): an agent in this process writes the attribute `cam_rgb` of a node; one
//!   agent per receiver process (`bench payload-receiver`, [`receiver`]) over the same [`agent::Link`] stamps the
//!   change signal of each value in its replica;
//! - **the shared-memory transport alone** (`lanes.rs`): the agents' `transport::shm::ShmTransport` from this
//!   process to one per receiver process, no agent on either side: between the two, it says whether the agents'
//!   distance to raw iceoryx2 is in their transport or in the agent;
//! - **raw iceoryx2** (`raw.rs`): `transport::shm::limit` — a sample into a loaned chunk, each receiver process
//!   stamps it in place, no agent, no envelope, no copy out;
//! - **memcpy**: one copy of the size in this process.
//!
//! **Latency** is one way ([`crate::results::PAYLOAD_PATHS_LATENCY`]): the writer stamps each sample just before
//! it writes it, each receiver stamps its delivery, both on the wall clock of this host, and the difference is the
//! latency of that delivery. For each number of receivers and each path the receivers are started once and every
//! size goes through them in turn: probes (each receiver answers one, so discovery and the join are done),
//! `warmup` unmeasured samples, then `count` samples at `rate_hz`, the last of which every receiver answers before
//! the window closes. **CPU** per receiver process and **loopback bytes** are read at the window's edges (the
//! receivers' `/proc/PID/task/*/schedstat`; the loopback counters in a fresh network namespace, [`Counting`]), so
//! they cover the samples of that size and the receivers' answers to the last. A delivery that never comes is
//! counted as missing, never waited for beyond a timeout. [`table`] writes the result as text or Markdown, with the
//! issue's targets beside it.

mod agents;
mod lanes;
mod numbering;
mod raw;
pub mod table;

use std::io::{BufRead as _, BufReader};
use std::path::Path;
use std::time::{Duration, Instant};

use anyhow::Context as _;
use hdrhistogram::Histogram;
use serde::{Deserialize, Serialize};

use super::helper::Helper;
use super::{Counting, growth, loadavg};
use crate::latency::{self, Percentiles};
use crate::netns::LoopbackCounters;
use crate::restart::with_restarts;
use crate::results::{PayloadCell, PayloadPathsResult};
use crate::spec::{PayloadPath, PayloadPathsExperiment};
use crate::usage::process_cpu_ns_of;

/// How long the loopback must stay quiet after a session that used it ([`settle`]).
const QUIET: Duration = Duration::from_millis(1_500);
/// The longest wait for that quiet.
const SETTLE_LIMIT: Duration = Duration::from_secs(10);
/// How long the receivers have to report after the run.
const REPORT_TIMEOUT: Duration = Duration::from_secs(30);

/// What an agent receiver process prints when it stops (one JSON line).
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct ReceiverReport {
    /// The receiver's index.
    pub index: u32,
    /// `[sample number, delivery stamp ns]` of every measured sample it got.
    pub delivered: Vec<[u64; 2]>,
}

/// Every cell of `experiment`, starting `program` (the `cortex` binary) for the receiver processes; `domain` is the
/// DDS domain of agents over RTPS. `progress` is called with a label after each cell.
///
/// # Errors
/// An experiment that makes no cell ([`PayloadPathsExperiment::validate`]), a transport or agent that cannot
/// start, or receivers that do not all answer a probe within 30 s at any of
/// [`MAX_STARTS`](crate::restart::MAX_STARTS) starts.
pub fn run(
    experiment: &PayloadPathsExperiment,
    domain: u16,
    counting: &Counting,
    program: &Path,
    progress: &mut dyn FnMut(&str),
) -> anyhow::Result<PayloadPathsResult> {
    experiment.validate()?;
    let mut cells = Vec::new();
    if experiment.paths.contains(&PayloadPath::Memcpy) {
        for &size in &experiment.sizes {
            cells.push(memcpy_cell(size, experiment.count));
            progress(&format!("payload paths: memcpy {size} B"));
        }
    }
    for &receivers in &experiment.receivers {
        for &path in experiment.paths.iter().filter(|p| p.has_receivers()) {
            let before = counting.counters()?;
            let label = format!("{} to {receivers} receivers", path.label());
            let unanswered = |error: &anyhow::Error| error.is::<numbering::ProbesUnanswered>();
            let mut reported = 0;
            let session = with_restarts(&label, unanswered, |start| {
                let mut once = new_cells(&mut reported, &mut *progress);
                let progress: &mut dyn FnMut(&str) = &mut once;
                match path {
                    PayloadPath::Iceoryx2 => raw::session(experiment, receivers, counting, program, progress),
                    PayloadPath::Transport => lanes::session(experiment, receivers, start, counting, program, progress),
                    PayloadPath::Agents(link) => {
                        let session = agents::Session { link, receivers, domain, start };
                        agents::session(experiment, &session, counting, program, progress)
                    }
                    PayloadPath::Memcpy => Ok(Vec::new()),
                }
            });
            let (mut session, starts) = session.with_context(|| label.clone())?;
            session.iter_mut().for_each(|cell| cell.session_starts = starts);
            cells.extend(session);
            if growth(counting.counters()?, before).is_some_and(|g| g.tx_bytes > 0) {
                settle(counting)?;
            }
        }
    }
    let netns = *counting == Counting::Socket;
    Ok(PayloadPathsResult::new(experiment.clone(), netns, loadavg(), cells))
}

/// The receiver process of `path` (the helper of `bench payload-receiver`): receiver `index` on the services of
/// `prefix` (raw iceoryx2), or an agent of the graph on `domain` and topic prefix `prefix` over the path's link.
/// Returns an agent receiver's report once the writer says stop; raw iceoryx2 receivers answer each sample as it
/// comes and report nothing.
///
/// # Errors
/// `memcpy`, which has no receivers; a transport or agent that cannot start; a writer silent for 60 s.
pub fn receiver(path: PayloadPath, domain: u16, prefix: &str, index: u32) -> anyhow::Result<Option<ReceiverReport>> {
    match path {
        PayloadPath::Memcpy => anyhow::bail!("memcpy has no receiver processes"),
        PayloadPath::Iceoryx2 => {
            raw::receive(prefix, index)?;
            Ok(None)
        }
        PayloadPath::Transport => Ok(Some(lanes::receive(prefix, index)?)),
        PayloadPath::Agents(link) => Ok(Some(agents::receive(link, domain, prefix, index)?)),
    }
}

/// `progress` for one start of a session: a start measures every size again, so it reports only the cells beyond
/// those an earlier start of the same session reported (`reported`, updated), and a restarted session's cells are
/// counted once.
fn new_cells<'a>(reported: &'a mut usize, progress: &'a mut dyn FnMut(&str)) -> impl FnMut(&str) + 'a {
    let mut finished = 0;
    move |label| {
        finished += 1;
        if finished > *reported {
            *reported = finished;
            progress(label);
        }
    }
}

fn memcpy_cell(size_bytes: usize, count: u32) -> PayloadCell {
    let mut histogram = latency::histogram();
    for ns in transport::shm::limit::memcpy_ns(size_bytes, count as usize) {
        histogram.saturating_record(ns.max(1));
    }
    PayloadCell {
        path: PayloadPath::Memcpy,
        size_bytes,
        receivers: 0,
        expected: u64::from(count),
        latency: Percentiles::of(&histogram),
        cpu_ns_per_sample: None,
        loopback_bytes_per_sample: None,
        to_iceoryx2: None,
        session_starts: 1,
    }
}

/// After a session that used the network: waits until the loopback has been quiet for [`QUIET`] (at most
/// [`SETTLE_LIMIT`]), so that what its processes send as they leave — multicast group reports repeated for a second
/// or more, a participant's last announcements — is not counted in the next session's windows.
fn settle(counting: &Counting) -> anyhow::Result<()> {
    let limit = Instant::now() + SETTLE_LIMIT;
    let mut last = counting.counters()?;
    let mut quiet_since = Instant::now();
    while Instant::now() < limit && quiet_since.elapsed() < QUIET {
        std::thread::sleep(Duration::from_millis(100));
        let now = counting.counters()?;
        if growth(now, last).is_some_and(|g| g.tx_bytes > 0) {
            quiet_since = Instant::now();
        }
        last = now;
    }
    Ok(())
}

/// Calls `write(i)` for `i` in `0..count`, the calls `1 / rate_hz` apart from the first.
fn paced(count: u32, rate_hz: f64, mut write: impl FnMut(u32) -> anyhow::Result<()>) -> anyhow::Result<()> {
    let period = Duration::from_secs_f64(1.0 / rate_hz);
    let mut due = Instant::now();
    for i in 0..count {
        std::thread::sleep(due.saturating_duration_since(Instant::now()));
        write(i)?;
        due += period;
    }
    Ok(())
}

/// The receivers' CPU time and the loopback counters at one edge of a measured window.
#[derive(Clone, Debug)]
struct Mark {
    counters: Option<LoopbackCounters>,
    cpu_ns: Vec<Option<u64>>,
}

impl Mark {
    /// Now, for the receiver processes `pids`.
    fn now(counting: &Counting, pids: &[u32]) -> anyhow::Result<Mark> {
        Ok(Mark { counters: counting.counters()?, cpu_ns: pids.iter().map(|&pid| process_cpu_ns_of(pid)).collect() })
    }

    /// Mean CPU ns of a receiver per sample, and loopback bytes per sample, from `self` to `end`.
    fn costs(&self, end: &Mark, samples: u64) -> (Option<f64>, Option<f64>) {
        let spent: Vec<u64> =
            self.cpu_ns.iter().zip(&end.cpu_ns).filter_map(|(&a, &b)| Some(b?.saturating_sub(a?))).collect();
        let per_sample = |total: f64, n: usize| total / n as f64 / samples.max(1) as f64;
        let cpu = (!spent.is_empty()).then(|| per_sample(spent.iter().sum::<u64>() as f64, spent.len()));
        let loopback = growth(end.counters, self.counters).map(|g| g.tx_bytes as f64 / samples.max(1) as f64);
        (cpu, loopback)
    }
}

/// One size's measured window: its edges and the latency of every delivery.
struct Window {
    size_bytes: usize,
    samples: u32,
    start: Mark,
    end: Mark,
    latencies: Histogram<u64>,
}

impl Window {
    fn cell(&self, path: PayloadPath, receivers: u32) -> PayloadCell {
        let (cpu, loopback) = self.start.costs(&self.end, u64::from(self.samples));
        PayloadCell {
            path,
            size_bytes: self.size_bytes,
            receivers,
            expected: u64::from(self.samples) * u64::from(receivers),
            latency: Percentiles::of(&self.latencies),
            cpu_ns_per_sample: cpu,
            loopback_bytes_per_sample: loopback,
            to_iceoryx2: None,
            session_starts: 1,
        }
    }
}

/// Starts `receivers` helper processes of `program` with the command lines `args(index)`.
fn spawn_receivers(
    program: &Path,
    receivers: u32,
    args: impl Fn(u32) -> Vec<String>,
) -> anyhow::Result<(Vec<Helper>, Vec<u32>)> {
    let helpers = (0..receivers).map(|i| Helper::spawn(program, &args(i))).collect::<anyhow::Result<Vec<_>>>()?;
    let pids = helpers.iter().map(Helper::pid).collect();
    Ok((helpers, pids))
}

/// Each helper's one-line [`ReceiverReport`], as many as come within [`REPORT_TIMEOUT`] (the deliveries of a
/// receiver without one count as missing). The helpers are killed afterwards if still running.
fn collect_reports(helpers: Vec<Helper>) -> Vec<ReceiverReport> {
    let (sender, reports) = std::sync::mpsc::channel();
    let mut helpers = helpers;
    for helper in &mut helpers {
        let Some(stdout) = helper.take_stdout() else { continue };
        let sender = sender.clone();
        std::thread::spawn(move || {
            let line = BufReader::new(stdout).lines().next();
            let report = line.and_then(Result::ok).and_then(|line| serde_json::from_str::<ReceiverReport>(&line).ok());
            let _ = sender.send(report);
        });
    }
    drop(sender);
    let deadline = Instant::now() + REPORT_TIMEOUT;
    let mut got = Vec::new();
    while let Ok(report) = reports.recv_timeout(deadline.saturating_duration_since(Instant::now())) {
        got.extend(report);
    }
    got
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_restarted_session_reports_each_cell_once() {
        let mut seen = Vec::new();
        let mut progress = |label: &str| seen.push(label.to_owned());
        let mut reported = 0;
        // The first start measures two sizes, then its receivers stop answering; the second measures all three.
        for labels in [&["16 B", "1 MiB"][..], &["16 B", "1 MiB", "4 MiB"][..]] {
            let mut start = new_cells(&mut reported, &mut progress);
            labels.iter().for_each(|label| start(label));
        }
        assert_eq!(seen, ["16 B", "1 MiB", "4 MiB"]);
    }

    #[test]
    fn costs_are_per_sample_and_receiver_and_skip_unreadable_receivers() {
        let start = Mark { counters: None, cpu_ns: vec![Some(100), Some(1_000), None] };
        let end = Mark { counters: None, cpu_ns: vec![Some(1_100), Some(3_000), Some(5)] };
        // Receivers 0 and 1 spent 1,000 and 2,000 ns over 10 samples: a mean of 150 ns per sample.
        assert_eq!(start.costs(&end, 10), (Some(150.0), None));
        let blind = Mark { counters: None, cpu_ns: vec![None] };
        assert_eq!(blind.costs(&blind, 10), (None, None));
    }

    #[test]
    fn pacing_calls_every_sample_once_in_order_and_stops_at_an_error() {
        let mut seen = Vec::new();
        paced(4, 1e6, |i| {
            seen.push(i);
            Ok(())
        })
        .unwrap();
        assert_eq!(seen, [0, 1, 2, 3]);
        let error = paced(4, 1e6, |i| if i == 2 { anyhow::bail!("refused") } else { Ok(()) }).unwrap_err();
        assert!(error.to_string().contains("refused"));
    }

    #[test]
    fn a_memcpy_cell_has_every_sample_and_no_receivers() {
        let cell = memcpy_cell(1024, 5);
        assert_eq!((cell.receivers, cell.expected, cell.latency.count), (0, 5, 5));
        assert!(cell.cpu_ns_per_sample.is_none() && cell.loopback_bytes_per_sample.is_none());
    }

    #[test]
    fn memcpy_has_no_receiver_process() {
        assert!(receiver(PayloadPath::Memcpy, 0, "p", 0).is_err());
    }
}
