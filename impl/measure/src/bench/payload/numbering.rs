//! How the writer of a session with receiver processes (the agent and lane paths) numbers its samples, how a
//! receiver takes them, and how the writer turns the receivers' stamps into latencies.
//!
//! A sample starts with its number (little-endian, [`crate::bench::payload_of`]) and two flags in the top bits:
//! [`PROBE`] (not measured: probes and warm-up samples) and [`ANSWER`] (the receivers answer it). [`STOP`] tells the
//! receivers to report and exit. Each receiver stamps every measured sample as it gets it and reports the stamps
//! when it stops ([`super::ReceiverReport`]); the writer waits for the answers of the probes (every receiver is
//! up) and of each size's last sample (every delivery is in before the window closes).

use std::time::{Duration, Instant};

use bytes::Bytes;
use transport::{Clock as _, SystemClock};

use super::{Counting, Mark, ReceiverReport, Window, collect_reports, paced};
use crate::bench::helper::Helper;
use crate::bench::payload_of;
use crate::latency;
use crate::results::PayloadCell;
use crate::spec::{PayloadPath, PayloadPathsExperiment};

/// A sample that is not measured (a probe or a warm-up sample).
pub(super) const PROBE: u64 = 1 << 62;
/// A sample every receiver answers.
pub(super) const ANSWER: u64 = 1 << 63;
/// The sample number, below the flags.
pub(super) const NUMBER: u64 = PROBE - 1;
/// The value that tells receivers to report and exit.
pub(super) const STOP: u64 = u64::MAX;
/// Probes of one size go out this far apart until every receiver has answered one.
const PROBE_INTERVAL: Duration = Duration::from_millis(200);
/// How long the receivers have to answer a probe (for the first size, discovery and join included) before the
/// session gives up and starts again with new receivers ([`crate::restart::MAX_STARTS`]).
const FIRST_ANSWER_TIMEOUT: Duration = Duration::from_secs(30);
/// How long the receivers have to answer the last sample of a size before its window closes anyway.
pub(super) const LAST_ANSWER_TIMEOUT: Duration = Duration::from_secs(20);
/// A receiver that hears nothing from the writer for this long gives up.
pub(super) const WRITER_SILENT: Duration = Duration::from_secs(60);

/// The receivers of a session did not all answer a probe in time (as when an RTPS discovery between two
/// participants never completes): the session starts again with new receivers ([`crate::restart::MAX_STARTS`]).
#[derive(Debug, thiserror::Error)]
#[error("the receivers did not all answer a probe of {size_bytes} B within {window:?}")]
pub(super) struct ProbesUnanswered {
    /// Bytes of the probe.
    pub(super) size_bytes: usize,
    /// How long the writer probed.
    pub(super) window: Duration,
}

/// The writer of a session with receiver processes: what it writes, and what its receivers have answered.
pub(super) trait NumberedWriter {
    /// The next sample number (0, 1, 2, ...).
    fn next_number(&mut self) -> u64;

    /// Writes `value` by the path's own means.
    fn send(&mut self, value: Bytes) -> anyhow::Result<()>;

    /// Writes a sample of `size` bytes numbered with the next number and `flags`; returns the number and when the
    /// write began (ns on the system clock): every path stamps at the same point, the sample made, just before it
    /// is handed to the path.
    fn write(&mut self, size: usize, flags: u64) -> anyhow::Result<(u64, u64)> {
        let number = self.next_number();
        let value = payload_of(number | flags, size);
        let at = SystemClock.now_ns();
        self.send(value)?;
        Ok((number, at))
    }

    /// Whether every receiver has answered a sample numbered `at_least` or later.
    fn answered(&self, at_least: u64) -> bool;

    /// Waits up to `timeout` for every receiver to answer `at_least` or later, looking every 2 ms; says whether
    /// they did.
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
    ///
    /// # Errors
    /// A write that fails; no answer within [`FIRST_ANSWER_TIMEOUT`] ([`ProbesUnanswered`]).
    fn probe(&mut self, size: usize) -> anyhow::Result<()> {
        let deadline = Instant::now() + FIRST_ANSWER_TIMEOUT;
        let (first, _) = self.write(size, PROBE | ANSWER)?;
        loop {
            if self.wait_answers(first, PROBE_INTERVAL) {
                return Ok(());
            }
            if Instant::now() > deadline {
                return Err(ProbesUnanswered { size_bytes: size, window: FIRST_ANSWER_TIMEOUT }.into());
            }
            self.write(size, PROBE | ANSWER)?;
        }
    }
}

/// Measures every size of `experiment` by `path` (`label` in progress lines) from `writer` to its receiver
/// processes (`receivers`: the helpers and their pids), then tells them to stop and makes a cell per size from
/// their reports: for each size, probes until every receiver answers, the warm-up, then the measured samples, the
/// last of which every receiver answers before the window closes.
///
/// # Errors
/// A write that fails or probes nobody answers.
pub(super) fn measure(
    writer: &mut dyn NumberedWriter,
    path: PayloadPath,
    label: &str,
    experiment: &PayloadPathsExperiment,
    (helpers, pids): (Vec<Helper>, &[u32]),
    counting: &Counting,
    progress: &mut dyn FnMut(&str),
) -> anyhow::Result<Vec<PayloadCell>> {
    let receivers = pids.len() as u32;
    let mut windows = Vec::new();
    for &size in &experiment.sizes {
        writer.probe(size)?;
        paced(experiment.warmup_for(size), experiment.rate_hz, |_| writer.write(size, PROBE).map(drop))?;
        let start = Mark::now(counting, pids)?;
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
        let end = Mark::now(counting, pids)?;
        let latencies = latency::histogram();
        windows.push((written, Window { size_bytes: size, samples: experiment.count, start, end, latencies }));
        progress(&format!("payload paths: {label} {size} B to {receivers}"));
    }
    writer.write(8, STOP)?;
    let reports = collect_reports(helpers);
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

/// What a receiver has heard from the writer.
#[derive(Default)]
pub(super) struct Stamps {
    /// `[number, stamp ns]` of every measured sample.
    pub(super) delivered: Vec<[u64; 2]>,
    /// The last value taken.
    last: Option<u64>,
    /// When the last value was taken (at first, when the receiver started listening).
    pub(super) heard_ns: u64,
    /// The first answer that could not be written.
    pub(super) failure: Option<String>,
}

/// What to do about a value the writer wrote.
#[derive(Debug, PartialEq, Eq)]
pub(super) enum Heard {
    /// Nothing more (a measured or probe sample that asks for no answer, or a repeat).
    Quiet,
    /// Answer with this number.
    Answer(u64),
    /// The writer is done.
    Stop,
}

impl Stamps {
    /// Stamps a receiver that starts listening at `now_ns`.
    pub(super) fn starting_at(now_ns: u64) -> Stamps {
        Stamps { heard_ns: now_ns, ..Stamps::default() }
    }

    /// Takes the value `value` stamped `at_ns`: records it if it is measured and new, and says what to do.
    pub(super) fn take(&mut self, value: u64, at_ns: u64) -> Heard {
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

    /// Whether the writer has been silent for longer than [`WRITER_SILENT`] at `now_ns`.
    pub(super) fn writer_silent(&self, now_ns: u64) -> bool {
        now_ns.saturating_sub(self.heard_ns) > WRITER_SILENT.as_nanos() as u64
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
        let mut stamps = Stamps::starting_at(1);
        assert!(!stamps.writer_silent(2));
        assert_eq!(stamps.take(3, 10), Heard::Quiet);
        assert_eq!(stamps.take(3, 11), Heard::Quiet, "a repeat is not recorded twice");
        assert_eq!(stamps.take(4 | PROBE | ANSWER, 12), Heard::Answer(4));
        assert_eq!(stamps.take(5 | ANSWER, 13), Heard::Answer(5));
        assert_eq!(stamps.take(STOP, 14), Heard::Stop);
        assert_eq!(stamps.delivered, vec![[3, 10], [5, 13]], "probes are not measured");
        assert_eq!(stamps.heard_ns, 14);
        assert!(stamps.writer_silent(14 + WRITER_SILENT.as_nanos() as u64 + 1));
    }

    #[test]
    fn probes_go_out_until_answered_and_the_answer_to_the_first_counts() {
        /// Answers from the second probe on.
        struct Slow {
            sent: Vec<u64>,
        }
        impl NumberedWriter for Slow {
            fn next_number(&mut self) -> u64 {
                self.sent.len() as u64
            }
            fn send(&mut self, value: Bytes) -> anyhow::Result<()> {
                let flagged = crate::bench::seq_of(&value).expect("a number");
                assert_eq!(flagged & (PROBE | ANSWER), PROBE | ANSWER);
                self.sent.push(flagged & NUMBER);
                Ok(())
            }
            fn answered(&self, at_least: u64) -> bool {
                self.sent.len() >= 2 && at_least <= 1
            }
        }
        let mut writer = Slow { sent: Vec::new() };
        writer.probe(16).expect("answered");
        assert_eq!(writer.sent, [0, 1], "a second probe, then the answer");
    }
}
