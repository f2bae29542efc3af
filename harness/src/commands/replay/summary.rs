//! What `cortex replay` prints: the summary of a replay, as text or as one JSON object (`--json`). Its keys are
//! what users and tests read; a change to them is a change of the command's interface.

use std::collections::BTreeMap;
use std::fmt::Write as _;

use anyhow::bail;
use measure::Percentiles;
use measure::record;
use replay::log::Log;
use replay::{BridgeStats, Rate};
use serde::Serialize;

use super::config::Resolved;

/// What a replay did.
#[derive(Debug, Serialize)]
pub(super) struct Summary {
    pub(super) file: String,
    /// The log's container (`mcap`, `ros1 bag`, `rosbag2 sqlite3`, `rosbag2 mcap`).
    pub(super) container: &'static str,
    pub(super) transport: &'static str,
    pub(super) agents: u32,
    pub(super) rate: String,
    pub(super) loops: u32,
    pub(super) file_bytes: u64,
    pub(super) damage: Option<String>,
    pub(super) unread_bytes: u64,
    pub(super) messages: u64,
    pub(super) payload_bytes: u64,
    /// Seconds spent reading the log (mapping, decompressing, indexing, sorting) before the replay.
    pub(super) read_seconds: f64,
    /// Payload MB per second of reading and replaying together.
    pub(super) read_megabytes_per_second: f64,
    pub(super) seconds: f64,
    pub(super) messages_per_second: f64,
    pub(super) megabytes_per_second: f64,
    pub(super) bridge: BridgeStats,
    pub(super) deltas: u64,
    pub(super) delta_bytes: u64,
    pub(super) deliveries: u64,
    pub(super) digests: Vec<String>,
    pub(super) digests_equal: bool,
    /// Faults injected into what the agent processes receive (`--faults`), as a specification.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub(super) faults: Option<String>,
    /// Over RTPS: each agent's graph at the end, the bridge first.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub(super) agent_reports: Vec<measure::roles::AgentRow>,
    /// Over RTPS: milliseconds from the quiesce (every writer stopped) until every agent had the bridge's digest.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub(super) converged_ms: Option<f64>,
    /// Over RTPS: milliseconds from the end of the replay to the quiesce (the roles' statistics fetched meanwhile).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub(super) quiesced_after_ms: Option<f64>,
    /// What `--out` recorded (in-process runs).
    pub(super) recording: Option<Recording>,
}

/// What `--out` recorded.
#[derive(Debug, Serialize)]
pub(super) struct Recording {
    pub(super) path: String,
    pub(super) messages: BTreeMap<&'static str, u64>,
    /// Latencies at the in-process receivers (not recorded over RTPS).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub(super) latency: Option<Percentiles>,
    /// Convergence windows (not recorded over RTPS).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub(super) convergence: Option<Percentiles>,
}

/// The part of a summary both transports fill alike; what differs (bytes, deliveries, digests, agents,
/// recording) is set by the caller. `[read_seconds, seconds]`: reading the log, and replaying it.
pub(super) fn summary(
    args: &Resolved,
    log: &Log,
    transport: &'static str,
    drive: &replay::inproc::DriveStats,
    [read_seconds, seconds]: [f64; 2],
    bridge: BridgeStats,
) -> Summary {
    Summary {
        file: args.file.display().to_string(),
        container: log.container.name(),
        transport,
        agents: args.agents,
        rate: rate_text(args.rate),
        loops: args.loops,
        file_bytes: log.file_bytes,
        damage: log.damage.as_ref().map(ToString::to_string),
        unread_bytes: log.unread_bytes,
        messages: drive.messages,
        payload_bytes: drive.bytes,
        read_seconds,
        read_megabytes_per_second: drive.bytes as f64 / 1e6 / (read_seconds + seconds).max(1e-9),
        seconds,
        messages_per_second: drive.messages as f64 / seconds.max(1e-9),
        megabytes_per_second: drive.bytes as f64 / 1e6 / seconds.max(1e-9),
        bridge,
        deltas: drive.deltas,
        delta_bytes: 0,
        deliveries: 0,
        digests: Vec::new(),
        digests_equal: false,
        faults: None,
        agent_reports: Vec::new(),
        converged_ms: None,
        quiesced_after_ms: None,
        recording: None,
    }
}

fn rate_text(rate: Rate) -> String {
    match rate {
        Rate::Max => "max".to_owned(),
        Rate::Factor(factor) => factor.to_string(),
    }
}

/// Prints the summary; an error if the digests differ.
pub(super) fn finish(args: &Resolved, summary: &Summary) -> anyhow::Result<()> {
    if args.json {
        println!("{}", serde_json::to_string_pretty(summary)?);
    } else {
        print!("{}", text(summary));
    }
    if !summary.digests_equal {
        bail!("the agents' final digests differ: {}", summary.digests.join(" "));
    }
    Ok(())
}

/// The summary as text.
pub(super) fn text(s: &Summary) -> String {
    let mut out = String::new();
    let _ = writeln!(
        out,
        "replay {} ({}, {} bytes) over {} with {} agents, rate {}, {} loop(s)",
        s.file, s.container, s.file_bytes, s.transport, s.agents, s.rate, s.loops
    );
    if let Some(faults) = &s.faults {
        let _ = writeln!(out, "  faults        {faults} (on what each agent process receives)");
    }
    if let Some(damage) = &s.damage {
        let _ = writeln!(out, "  damage        {damage} ({} bytes unread)", s.unread_bytes);
    }
    let _ = writeln!(
        out,
        "  messages      {} in {:.3} s: {:.0} messages/s, {:.1} MB/s of payload ({} bytes)",
        s.messages, s.seconds, s.messages_per_second, s.megabytes_per_second, s.payload_bytes
    );
    let _ = writeln!(
        out,
        "  read          in {:.3} s before the replay: {:.1} MB/s of payload read and replayed",
        s.read_seconds, s.read_megabytes_per_second
    );
    bridge_text(&mut out, &s.bridge);
    let _ = if s.transport == "rtps" {
        // Over RTPS the bridge agent's counters: its deltas, and its announces and re-sends meanwhile.
        writeln!(
            out,
            "  deltas        {} ({} bytes the bridge agent published during the replay), {} samples received by the others",
            s.deltas, s.delta_bytes, s.deliveries
        )
    } else {
        writeln!(out, "  deltas        {} ({} bytes encoded), {} deliveries", s.deltas, s.delta_bytes, s.deliveries)
    };
    for agent in &s.agent_reports {
        agent_text(&mut out, agent);
    }
    if let Some(ms) = s.converged_ms {
        let _ = writeln!(
            out,
            "  converged     every agent had the bridge's digest {ms:.1} ms after the writers stopped (status every \
             100 ms; the roles were quiesced {:.1} ms after the replay ended, their statistics fetched meanwhile)",
            s.quiesced_after_ms.unwrap_or(0.0)
        );
    }
    let verdict = if s.digests_equal { "equal" } else { "DIFFER" };
    let _ = writeln!(out, "  digests       {verdict}: {}", s.digests.join(" "));
    if let Some(recording) = &s.recording {
        recording_text(&mut out, recording);
    }
    out
}

/// The bridge's counters: messages by type, what it carried, refused and failed on.
fn bridge_text(out: &mut String, b: &BridgeStats) {
    let table = |out: &mut String, title: &str, rows: &BTreeMap<String, u64>| {
        for (name, count) in rows {
            let _ = writeln!(out, "  {title:<13} {count:>8}  {name}");
        }
    };
    table(out, "decoded", &b.decoded);
    table(out, "described", &b.described);
    table(out, "unknown", &b.unknown);
    let _ = writeln!(
        out,
        "  carried       {} opaque, {} filtered out, {} TF transforms refused",
        b.opaque, b.filtered, b.tf_refused
    );
    table(out, "errors", &b.errors);
    for error in &b.first_errors {
        let _ = writeln!(out, "    {error}");
    }
}

/// An agent's graph at the end of an RTPS replay, with its role's BICA statistics.
fn agent_text(out: &mut String, a: &measure::roles::AgentRow) {
    let _ = writeln!(
        out,
        "  agent {:<3}     {:<15} {:>6} nodes  digest {}  {} samples received, {} sent",
        a.id, a.role, a.nodes, a.digest, a.samples_received, a.samples_sent
    );
    for c in &a.components {
        let _ = writeln!(
            out,
            "      {:>6.1} of {:>6.1} Hz {:>6} runs {:>5} misses {:>5} skipped  lateness p99 {:>7.2} ms  step p99 \
             {:>6.2} ms  {}",
            c.achieved_hz, c.nominal_hz, c.runs, c.misses, c.skipped_releases, c.lateness_p99_ms, c.wall_p99_ms, c.name
        );
    }
    if let Some(error) = &a.components_error {
        let _ = writeln!(out, "      BICA statistics unavailable: {error}");
    }
}

/// What `--out` recorded.
fn recording_text(out: &mut String, r: &Recording) {
    let count = |topic: &str| r.messages.get(topic).copied().unwrap_or(0);
    match r.latency {
        Some(latency) => {
            let _ = writeln!(
                out,
                "  recorded      {}: {} deltas, {} latencies (p50 {:.3} ms, p99 {:.3} ms), {} convergence windows",
                r.path,
                count(record::DELTA_TOPIC),
                count(record::Metric::Latency.topic()),
                latency.p50_ns as f64 / 1e6,
                latency.p99_ns as f64 / 1e6,
                count(record::Metric::Convergence.topic())
            );
        }
        None => {
            let _ = writeln!(
                out,
                "  recorded      {}: {} deltas as the bridge published them, {} bandwidth windows",
                r.path,
                count(record::DELTA_TOPIC),
                count(record::Metric::Bandwidth.topic())
            );
        }
    }
}
