//! The agent paths: an agent in this process writes `cam_rgb` of the node `payload_source`; each receiver process
//! runs an agent over the same [`Link`], stamps every change signal of that attribute in its replica, and answers
//! the samples that ask for it by writing the sample's number into `cam_rgb` of its own node `payload_rx<I>`.
//!
//! A sample's value starts with its number (little-endian, [`crate::bench::payload_of`]) and two flags in the top
//! bits: [`PROBE`] (not measured: probes and warm-up samples) and [`ANSWER`] (the receivers answer it). [`STOP`]
//! tells the receivers to report and exit.

use std::path::Path;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use agent::rtps::AgentTransport;
use agent::{Agent, AgentConfig, AgentId, Link};
use anyhow::{Context as _, bail};
use dsr::{Change, Element, NewNode, NodeId, attrs};
use transport::rtps::RtpsConfig;
use transport::{Clock as _, SystemClock};

use super::{Counting, Mark, ReceiverReport, Window, collect_reports, paced, spawn_receivers};
use crate::bench::{helper, payload_of, seq_of};
use crate::latency;
use crate::results::PayloadCell;
use crate::spec::{PayloadPath, PayloadPathsExperiment};

const SOURCE: &str = "payload_source";
/// A sample that is not measured (a probe or a warm-up sample).
const PROBE: u64 = 1 << 62;
/// A sample every receiver answers.
const ANSWER: u64 = 1 << 63;
/// The sample number, below the flags.
const NUMBER: u64 = PROBE - 1;
/// The value that tells receivers to report and exit.
const STOP: u64 = u64::MAX;
/// Probes of one size go out this far apart until every receiver has answered one.
const PROBE_INTERVAL: Duration = Duration::from_millis(200);
/// How long the receivers have to answer the first probe (discovery and join included).
const FIRST_ANSWER_TIMEOUT: Duration = Duration::from_secs(60);
/// How long the receivers have to answer the last sample of a size before its window closes anyway.
const LAST_ANSWER_TIMEOUT: Duration = Duration::from_secs(20);
/// A receiver that hears nothing from the writer for this long gives up.
const WRITER_SILENT: Duration = Duration::from_secs(60);

fn receiver_node(index: u32) -> String {
    format!("payload_rx{index}")
}

fn config(id: u32, join_wait: Duration) -> AgentConfig {
    let mut config = AgentConfig::new(AgentId(id));
    config.join_wait = join_wait;
    config
}

fn rtps(domain: u16, prefix: &str) -> RtpsConfig {
    RtpsConfig { domain_id: domain, topic_prefix: prefix.into(), ..RtpsConfig::default() }
}

/// The writer of a session and what it has written.
struct Writer {
    agent: Arc<Agent<AgentTransport>>,
    source: NodeId,
    receivers: u32,
    next: u64,
}

impl Writer {
    /// Writes a sample of `size` bytes numbered with the next number and `flags`; returns the number and when the
    /// write began.
    fn write(&mut self, size: usize, flags: u64) -> anyhow::Result<(u64, u64)> {
        let number = self.next;
        self.next += 1;
        let value = payload_of(number | flags, size);
        let at = SystemClock.now_ns();
        self.agent.set_attr(self.source, attrs::CAM_RGB, value)?;
        Ok((number, at))
    }

    /// Whether every receiver has answered a sample numbered `at_least` or later.
    fn answered(&self, at_least: u64) -> bool {
        (0..self.receivers).all(|i| {
            let node = self.agent.node_by_name(&receiver_node(i));
            let answer = node.and_then(|n| self.agent.attr(n.id, attrs::CAM_RGB)).and_then(|b| seq_of(&b));
            answer.is_some_and(|n| n >= at_least)
        })
    }

    /// Waits up to `timeout` for every receiver to answer `at_least` or later; says whether they did.
    fn wait_answers(&self, at_least: u64, timeout: Duration) -> bool {
        let deadline = Instant::now() + timeout;
        while Instant::now() < deadline {
            if self.answered(at_least) {
                return true;
            }
            std::thread::sleep(Duration::from_millis(2));
        }
        self.answered(at_least)
    }

    /// Probes of `size` bytes until every receiver has answered one.
    fn probe(&mut self, size: usize) -> anyhow::Result<()> {
        let first = self.next;
        let deadline = Instant::now() + FIRST_ANSWER_TIMEOUT;
        loop {
            self.write(size, PROBE | ANSWER)?;
            if self.wait_answers(first, PROBE_INTERVAL) {
                return Ok(());
            }
            if Instant::now() > deadline {
                bail!("the receivers did not all answer a probe of {size} B within 60 s");
            }
        }
    }
}

/// Every size of `experiment` from an agent here to agents in `receivers` processes of `program`, over `link`.
pub(super) fn session(
    experiment: &PayloadPathsExperiment,
    link: Link,
    receivers: u32,
    domain: u16,
    counting: &Counting,
    program: &Path,
    progress: &mut dyn FnMut(&str),
) -> anyhow::Result<Vec<PayloadCell>> {
    let path = PayloadPath::Agents(link);
    let prefix = format!("payload{}{}n{receivers}", std::process::id(), link.name());
    let agent = link.start(config(1, Duration::from_millis(300)), rtps(domain, &prefix), None)?;
    if !agent.wait_ready(Duration::from_secs(10)) {
        bail!("the writing agent did not start");
    }
    let source = agent.insert_node(NewNode::new("object", SOURCE))?;
    let mut writer = Writer { agent, source, receivers, next: 0 };
    let (helpers, pids) =
        spawn_receivers(program, receivers, |i| helper::payload_receiver_args(link.name(), domain, &prefix, i))?;
    let mut windows = Vec::new();
    for &size in &experiment.sizes {
        writer.probe(size)?;
        paced(experiment.warmup_for(size), experiment.rate_hz, |_| writer.write(size, PROBE).map(drop))?;
        let start = Mark::now(counting, &pids)?;
        let mut written = Vec::with_capacity(experiment.count as usize);
        paced(experiment.count, experiment.rate_hz, |i| {
            let flags = if i + 1 == experiment.count { ANSWER } else { 0 };
            written.push(writer.write(size, flags)?);
            Ok(())
        })?;
        let last = written.last().map_or(0, |&(number, _)| number);
        // A receiver that misses the last sample leaves the window open for the timeout; its misses show as
        // deliveries missing from the cell.
        writer.wait_answers(last, LAST_ANSWER_TIMEOUT);
        let end = Mark::now(counting, &pids)?;
        windows.push((
            written,
            Window { size_bytes: size, samples: experiment.count, start, end, latencies: latency::histogram() },
        ));
        progress(&format!("payload paths: agents over {link} {size} B to {receivers}"));
    }
    writer.agent.set_attr(writer.source, attrs::CAM_RGB, payload_of(STOP, 8))?;
    let reports = collect_reports(helpers);
    writer.agent.shutdown();
    Ok(windows
        .into_iter()
        .map(|(written, mut window)| {
            record_latencies(&mut window, &written, &reports);
            window.cell(path, receivers)
        })
        .collect())
}

/// Records in `window` the latency of every delivery in `reports` of a sample in `written` (`(number, stamp)`).
fn record_latencies(window: &mut Window, written: &[(u64, u64)], reports: &[ReceiverReport]) {
    let (Some(&(first, _)), Some(&(last, _))) = (written.first(), written.last()) else { return };
    for report in reports {
        for &[number, delivered_ns] in &report.delivered {
            if (first..=last).contains(&number) {
                let written_ns = written[(number - first) as usize].1;
                window.latencies.saturating_record(delivered_ns.saturating_sub(written_ns).max(1));
            }
        }
    }
}

/// A receiver process of an agent path: an agent of the graph on `domain` and `prefix` over `link` that stamps
/// every new value of the source's `cam_rgb` in a change callback (on the thread that joined it, as raw iceoryx2's
/// receivers stamp on theirs) and answers those that ask, until told to stop.
pub(super) fn receive(link: Link, domain: u16, prefix: &str, index: u32) -> anyhow::Result<ReceiverReport> {
    let agent = link.start(config(2 + index, Duration::from_secs(30)), rtps(domain, prefix), None)?;
    if !agent.wait_ready(Duration::from_secs(30)) {
        bail!("receiver {index} got no graph within 30 s");
    }
    let deadline = Instant::now() + Duration::from_secs(30);
    let source = loop {
        if let Some(node) = agent.node_by_name(SOURCE) {
            break node.id;
        }
        if Instant::now() > deadline {
            bail!("receiver {index}: the graph has no {SOURCE} node after 30 s");
        }
        std::thread::sleep(Duration::from_millis(10));
    };
    let me = agent.insert_node(NewNode::new("object", &receiver_node(index))).context("the receiver's node")?;
    let stamps = Arc::new(Mutex::new(Stamps { heard_ns: SystemClock.now_ns(), ..Stamps::default() }));
    let (stop, stopped) = std::sync::mpsc::sync_channel(1);
    let callback = {
        let (weak, stamps) = (Arc::downgrade(&agent), Arc::clone(&stamps));
        agent.on_change(move |signal| {
            let from_source = matches!(&signal.change, Change::AttrUpdated { element: Element::Node(id), name }
                if *id == source && name.as_str() == "cam_rgb");
            let Some(agent) = weak.upgrade().filter(|_| from_source && !signal.local) else { return };
            let at = SystemClock.now_ns();
            let Some(value) = agent.attr(source, attrs::CAM_RGB).and_then(|b| seq_of(&b)) else { return };
            // Taken under the lock, which is released before the answer: a failed answer records itself under it.
            let heard = stamps.lock().unwrap_or_else(|p| p.into_inner()).take(value, at);
            match heard {
                Heard::Stop => drop(stop.try_send(())),
                Heard::Answer(number) => {
                    if let Err(error) = agent.set_attr(me, attrs::CAM_RGB, payload_of(number, 8)) {
                        let failure = format!("receiver {index}: answering sample {number} failed: {error}");
                        stamps.lock().unwrap_or_else(|p| p.into_inner()).failure.get_or_insert(failure);
                    }
                }
                Heard::Quiet => {}
            }
        })
    };
    let outcome = wait_for_stop(&stamps, &stopped, index);
    agent.remove_on_change(callback);
    agent.shutdown();
    outcome?;
    let delivered = std::mem::take(&mut stamps.lock().unwrap_or_else(|p| p.into_inner()).delivered);
    Ok(ReceiverReport { index, delivered })
}

/// Waits for the stop value; fails when the writer has been silent for [`WRITER_SILENT`].
fn wait_for_stop(stamps: &Mutex<Stamps>, stopped: &std::sync::mpsc::Receiver<()>, index: u32) -> anyhow::Result<()> {
    loop {
        if stopped.recv_timeout(Duration::from_secs(1)).is_ok() {
            return Ok(());
        }
        let (heard_ns, failure) = {
            let stamps = stamps.lock().unwrap_or_else(|p| p.into_inner());
            (stamps.heard_ns, stamps.failure.clone())
        };
        if let Some(failure) = failure {
            bail!(failure);
        }
        if SystemClock.now_ns().saturating_sub(heard_ns) > WRITER_SILENT.as_nanos() as u64 {
            bail!("receiver {index}: the writer fell silent");
        }
    }
}

/// What a receiver has heard from the writer.
#[derive(Default)]
struct Stamps {
    /// `[number, stamp ns]` of every measured sample.
    delivered: Vec<[u64; 2]>,
    /// The last value taken.
    last: Option<u64>,
    /// When the last value was taken (at first, when the receiver started listening).
    heard_ns: u64,
    /// The first answer that could not be written.
    failure: Option<String>,
}

/// What to do about a value the writer wrote.
#[derive(Debug, PartialEq, Eq)]
enum Heard {
    /// Nothing more (a measured or probe sample that asks for no answer, or a repeat).
    Quiet,
    /// Answer with this number.
    Answer(u64),
    /// The writer is done.
    Stop,
}

impl Stamps {
    /// Takes the value `value` stamped `at_ns`: records it if it is measured and new, and says what to do.
    fn take(&mut self, value: u64, at_ns: u64) -> Heard {
        self.heard_ns = at_ns;
        if value == STOP {
            return Heard::Stop;
        }
        if self.last == Some(value) {
            return Heard::Quiet;
        }
        self.last = Some(value);
        if value & PROBE == 0 {
            self.delivered.push([value & NUMBER, at_ns]);
        }
        if value & ANSWER != 0 { Heard::Answer(value & NUMBER) } else { Heard::Quiet }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bench::payload::Mark;

    #[test]
    fn flags_stay_above_every_number_and_stop_is_no_sample() {
        assert_eq!(NUMBER & (PROBE | ANSWER), 0);
        assert_eq!((5 | PROBE | ANSWER) & NUMBER, 5);
        assert_ne!(STOP & PROBE, 0, "a stop is never measured");
    }

    #[test]
    fn deliveries_of_the_window_samples_are_recorded_and_others_ignored() {
        let mark = Mark { counters: None, cpu_ns: Vec::new() };
        let mut window =
            Window { size_bytes: 16, samples: 2, start: mark.clone(), end: mark, latencies: latency::histogram() };
        let written = [(10, 1_000), (11, 2_000)];
        let reports = [
            ReceiverReport { index: 0, delivered: vec![[9, 5_000], [10, 1_500], [11, 2_700]] },
            ReceiverReport { index: 1, delivered: vec![[11, 2_100], [12, 9_000]] },
        ];
        record_latencies(&mut window, &written, &reports);
        assert_eq!(window.latencies.len(), 3);
        assert_eq!(window.latencies.max(), 700);
        assert_eq!(window.latencies.min(), 100);
    }

    #[test]
    fn a_receiver_records_measured_values_once_answers_those_that_ask_and_stops_on_stop() {
        let mut stamps = Stamps::default();
        assert_eq!(stamps.take(3, 10), Heard::Quiet);
        assert_eq!(stamps.take(3, 11), Heard::Quiet, "a repeat is not recorded twice");
        assert_eq!(stamps.take(4 | PROBE | ANSWER, 12), Heard::Answer(4));
        assert_eq!(stamps.take(5 | ANSWER, 13), Heard::Answer(5));
        assert_eq!(stamps.take(STOP, 14), Heard::Stop);
        assert_eq!(stamps.delivered, vec![[3, 10], [5, 13]], "probes are not measured");
        assert_eq!(stamps.heard_ns, 14);
    }
}
