//! `cortex report`'s runs as recordings: one MCAP file per run, written after the set from each [`RunResult`]'s
//! bounded [`crate::results::WriteTimeline`].

use std::io::{Seek, Write};
use std::path::{Path, PathBuf};

use anyhow::Context as _;

use super::{ConvergenceWindow, RecordCounts, RunRecorder, RunSummary, WriteLatency, finish_file, provenance_metadata};
use crate::results::{Results, RunResult};

/// The summary of a [`RunResult`].
pub fn summary_of(result: &RunResult) -> RunSummary {
    RunSummary {
        run: result.workload.clone(),
        transport: result.transport.clone(),
        agents: result.agents,
        seed: result.seed,
        writes: result.writes,
        published_bytes: result.sample_bytes,
        latency: result.latency,
        latency_by_class: result.latency_by_class.iter().map(|(c, p)| (c.name().to_owned(), *p)).collect(),
        convergence: result.convergence,
        writes_not_everywhere: result.writes_not_everywhere,
        end_convergence_ns: result.end_convergence_ns,
        digests_equal: result.digests_equal,
        digests: Vec::new(),
        writes_recorded: result.timeline.writes().len() as u64,
    }
}

/// Records a finished run from its [`crate::results::WriteTimeline`]: bandwidth windows of its publications, a
/// latency message per (write, receiver) that was applied, a convergence window per write that reached every
/// receiver, all in log-time order, then the summary.
///
/// # Errors
/// The output cannot be written.
pub fn record_result<W: Write + Seek>(recorder: &mut RunRecorder<W>, result: &RunResult) -> anyhow::Result<()> {
    #[derive(PartialEq, Eq, PartialOrd, Ord)]
    enum Event {
        Publish(usize),
        Apply(usize, usize),
        Converged(usize, u64),
    }
    let timeline = &result.timeline;
    let receivers = timeline.receivers() as usize;
    let mut events: Vec<(u64, Event)> = Vec::with_capacity(timeline.writes().len() * (receivers + 2));
    for (seq, write) in timeline.writes().iter().enumerate() {
        events.push((write.publish_ns, Event::Publish(seq)));
        let mut last = Some(write.publish_ns);
        for receiver in 0..receivers {
            let applied = timeline.applied_ns(seq, receiver);
            if let Some(at) = applied {
                events.push((at, Event::Apply(seq, receiver)));
            }
            last = last.zip(applied).map(|(a, b)| a.max(b));
        }
        if let Some(at) = last.filter(|_| receivers > 0) {
            events.push((at, Event::Converged(seq, at)));
        }
    }
    events.sort_unstable();
    let mut end_ns = 0;
    for (at, event) in events {
        end_ns = at;
        match event {
            Event::Publish(seq) => recorder.published(at, timeline.writes()[seq].bytes)?,
            Event::Apply(seq, receiver) => {
                let write = timeline.writes()[seq];
                recorder.latency(&WriteLatency {
                    seq: seq as u64,
                    class: write.class,
                    receiver: receiver as u32 + 1,
                    publish_ns: write.publish_ns,
                    apply_ns: at,
                    latency_ns: at.saturating_sub(write.publish_ns),
                    bytes: write.bytes,
                })?;
            }
            Event::Converged(seq, converged_ns) => {
                let write = timeline.writes()[seq];
                recorder.convergence(&ConvergenceWindow {
                    seq: seq as u64,
                    class: write.class,
                    publish_ns: write.publish_ns,
                    converged_ns,
                    window_ns: converged_ns.saturating_sub(write.publish_ns).max(1),
                    receivers: receivers as u32,
                })?;
            }
        }
    }
    recorder.summary(end_ns, &summary_of(result))
}

/// One file written by [`write_runs`].
#[derive(Clone, Debug)]
pub struct RecordedRun {
    /// Path relative to the report's directory (`runs/…mcap`).
    pub path: PathBuf,
    /// What the run was (`replay`, `payload` or `faults`, and the run's label).
    pub label: String,
    /// Messages written, per topic.
    pub counts: RecordCounts,
}

pub(super) fn slug(text: &str) -> String {
    let mut out = String::new();
    for c in text.replace(".mcap", "").chars() {
        if c.is_ascii_alphanumeric() || c == '.' {
            out.push(c.to_ascii_lowercase());
        } else if !out.ends_with('-') {
            out.push('-');
        }
    }
    out.trim_matches('-').chars().take(80).collect()
}

/// Writes one MCAP file per run of `results` into `out/runs/`: its summary, per-write latencies, convergence
/// windows and bandwidth windows, with the set's provenance as metadata.
///
/// # Errors
/// A file that cannot be written.
pub fn write_runs(results: &Results, out: &Path) -> anyhow::Result<Vec<RecordedRun>> {
    let dir = out.join("runs");
    std::fs::create_dir_all(&dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let mut runs: Vec<(String, String, &RunResult)> = Vec::new();
    for (i, run) in results.replay.iter().enumerate() {
        let label = format!("{} {} N={} seed {}", run.workload, run.transport, run.agents, run.seed);
        runs.push((format!("replay-{i:02}"), label, run));
    }
    for (i, run) in results.payload.iter().enumerate() {
        runs.push((format!("payload-{i:02}"), format!("{} N={}", run.workload, run.agents), run));
    }
    for (i, fault) in results.faults.iter().enumerate() {
        runs.push((format!("faults-{i:02}"), format!("{} ({})", fault.label, fault.run.workload), &fault.run));
    }
    let mut recorded = Vec::new();
    for (kind, label, run) in runs {
        let path = PathBuf::from("runs").join(format!("{kind}-{}.mcap", slug(&label)));
        let mut metadata = provenance_metadata(&results.provenance);
        metadata.insert("experiment".to_owned(), format!("{} ({})", results.experiment, results.mode));
        metadata.insert("run".to_owned(), format!("{kind}: {label}"));
        let mut recorder = RunRecorder::create(&out.join(&path), metadata)?;
        record_result(&mut recorder, run).with_context(|| format!("cannot record {}", path.display()))?;
        let counts = finish_file(recorder).with_context(|| format!("cannot finish {}", path.display()))?;
        recorded.push(RecordedRun { path, label: format!("{kind}: {label}"), counts });
    }
    Ok(recorded)
}
