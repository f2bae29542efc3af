//! The payload paths' table, written once for both readers: as text (`cortex bench payload`) and as Markdown (the
//! report's section), with the notes that say how each column was taken and the issue 20 targets beside what was
//! measured.

use std::fmt::Write as _;

use crate::results::{PathRatios, PayloadCell, PayloadPathsResult};
use crate::spec::PayloadPath;
use crate::units::{ms_from_ns, us_from_ns, us_from_ns_f64};

/// The columns, in order.
pub const COLUMNS: [&str; 13] = [
    "bytes",
    "N",
    "path",
    "delivered",
    "p50 us",
    "p99 us",
    "max us",
    "CPU us/sample",
    "loopback B/sample",
    "p50 /iox",
    "p99 /iox",
    "max /iox",
    "CPU /iox",
];

/// Text widths of the columns (the path is left-aligned, the others right-aligned).
const WIDTHS: [usize; 13] = [9, 3, 14, 10, 9, 9, 9, 13, 17, 8, 8, 8, 8];

/// The cells of one row.
pub fn row(cell: &PayloadCell) -> [String; 13] {
    let dash = || "-".to_owned();
    let latency = |ns: u64| if cell.latency.count == 0 { dash() } else { format!("{:.1}", us_from_ns(ns)) };
    let ratio = |pick: fn(&PathRatios) -> Option<f64>| {
        cell.to_iceoryx2.as_ref().and_then(pick).map_or_else(dash, |r| format!("{r:.2}"))
    };
    [
        cell.size_bytes.to_string(),
        if cell.path.has_receivers() { cell.receivers.to_string() } else { dash() },
        cell.path.label(),
        format!("{}/{}", cell.latency.count, cell.expected),
        latency(cell.latency.p50_ns),
        latency(cell.latency.p99_ns),
        latency(cell.latency.max_ns),
        cell.cpu_ns_per_sample.map_or_else(dash, |ns| format!("{:.1}", us_from_ns_f64(ns))),
        cell.loopback_bytes_per_sample.map_or_else(dash, |b| format!("{b:.1}")),
        ratio(|r| Some(r.p50)),
        ratio(|r| Some(r.p99)),
        ratio(|r| Some(r.max)),
        ratio(|r| r.cpu),
    ]
}

/// The heading line: what ran, where, and the load.
pub fn heading(result: &PayloadPathsResult) -> String {
    let e = &result.experiment;
    format!(
        "payload paths: one writer to N receiver processes on this host, {} Hz, {} measured samples per cell, {}; \
         load average {}",
        e.rate_hz,
        e.count,
        if result.netns { "loopback bytes counted in a fresh network namespace" } else { "loopback bytes not counted" },
        result.loadavg
    )
}

/// What the columns mean.
pub fn notes(result: &PayloadPathsResult) -> Vec<String> {
    let mut notes = vec![
        format!("latency: {}", result.latency),
        "delivered: deliveries measured / samples x receivers; CPU us/sample: a receiver process's CPU time (all its \
         threads) over the window, per sample, mean over the receivers"
            .to_owned(),
        "/iox: the agents' (or the transport's) figure over raw iceoryx2's for the same size and receivers \
         (1.00 = the limit)"
            .to_owned(),
    ];
    let experiment = &result.experiment;
    let fewest_receivers = experiment.receivers.iter().copied().min().unwrap_or(1);
    if u64::from(experiment.count) * u64::from(fewest_receivers) < 100 {
        notes.push(format!(
            "p99 of a cell with fewer than 100 deliveries ({} samples to {fewest_receivers} receiver(s) here) is its \
             slowest delivery, as its max is: one slow sample decides it",
            experiment.count
        ));
    }
    if let Some(restarted) = restarted_sessions(result) {
        notes.push(restarted);
    }
    notes.push(if result.netns {
        "loopback B/sample: bytes sent on the namespace's loopback over the window (every process of the run), per \
         sample"
            .to_owned()
    } else {
        "loopback B/sample: not measured (no fresh network namespace: the host's counters include other traffic)"
            .to_owned()
    });
    notes
}

/// The sessions whose receivers were started more than once ([`PayloadCell::session_starts`]), as a note; `None`
/// when every session started once.
fn restarted_sessions(result: &PayloadPathsResult) -> Option<String> {
    let mut sessions: Vec<String> = Vec::new();
    for cell in result.cells.iter().filter(|c| c.session_starts > 1) {
        let session = format!("{} to {} ({} starts)", cell.path.label(), cell.receivers, cell.session_starts);
        if !sessions.contains(&session) {
            sessions.push(session);
        }
    }
    (!sessions.is_empty()).then(|| {
        format!(
            "started again: {} (a receiver did not answer the probes; nothing is measured before all have answered)",
            sessions.join("; ")
        )
    })
}

/// The table as text: the heading, a header row and a row per cell, the notes, and the targets.
pub fn text(result: &PayloadPathsResult) -> String {
    let mut out = heading(result);
    out.push('\n');
    let line = |cells: &[String]| -> String {
        let mut line = String::new();
        for (i, (cell, width)) in cells.iter().zip(WIDTHS).enumerate() {
            let _ = if i == 2 { write!(line, " {cell:<width$}") } else { write!(line, " {cell:>width$}") };
        }
        line.trim_end().to_owned()
    };
    out += &line(&COLUMNS.map(String::from));
    out.push('\n');
    for cell in &result.cells {
        out += &line(&row(cell));
        out.push('\n');
    }
    for note in notes(result).into_iter().chain(targets(result)) {
        out += &note;
        out.push('\n');
    }
    out
}

/// The table as Markdown: header, alignment row and a row per cell (no heading or notes).
pub fn markdown(result: &PayloadPathsResult) -> String {
    let mut md = format!("| {} |\n|", COLUMNS.join(" | "));
    for i in 0..COLUMNS.len() {
        md += if i == 2 { ":---|" } else { "---:|" };
    }
    md.push('\n');
    for cell in &result.cells {
        let _ = writeln!(md, "| {} |", row(cell).join(" | "));
    }
    md
}

/// Issue 20's targets beside what this run measured, one line each, for every agent path with the cells a target
/// needs (none when the run has none of them).
pub fn targets(result: &PayloadPathsResult) -> Vec<String> {
    let mut lines = Vec::new();
    let agent_paths = result.experiment.paths.iter().filter(|p| matches!(p, PayloadPath::Agents(_)));
    for &path in agent_paths {
        let label = path.label();
        if let Some(cell) = result.cell(path, 4 << 20, 1).filter(|c| c.latency.count > 0) {
            lines.push(format!(
                "target, 4 MiB to 1 receiver process, p50 <= 0.5 ms and p99 <= 2 ms: {label} p50 {} and p99 {}",
                against(cell.latency.p50_ns, 0.5),
                against(cell.latency.p99_ns, 2.0)
            ));
        }
        if let Some(cell) = result.cell(path, 360_960, 8).filter(|c| c.latency.count > 0) {
            lines.push(format!(
                "target, 360,960 B at {} Hz to 8 receiver processes, p99 <= 1 ms: {label} p99 {}",
                result.experiment.rate_hz,
                against(cell.latency.p99_ns, 1.0)
            ));
        }
        let ratios: Vec<f64> =
            result.cells.iter().filter(|c| c.path == path).filter_map(|c| c.to_iceoryx2).map(|r| r.p50).collect();
        if let Some(worst) = ratios.iter().copied().reduce(f64::max) {
            let within = ratios.iter().filter(|&&r| r <= 1.5).count();
            lines.push(format!(
                "target, latency within 1.5x raw iceoryx2 (p50): {label} {within} of {} cells within, the largest {worst:.2}x",
                ratios.len()
            ));
        }
        let frames: Vec<f64> = result
            .cells
            .iter()
            .filter(|c| c.path == path && c.size_bytes >= 65_536)
            .filter_map(|c| c.loopback_bytes_per_sample)
            .collect();
        if let Some(most) = frames.iter().copied().reduce(f64::max) {
            lines.push(format!(
                "target, loopback bytes of same-host frames (64 KiB and up) near zero: {label} at most {most:.1} B per sample"
            ));
        }
    }
    lines
}

/// `ns` in ms beside a target of `target_ms`: met, or missed by how much.
fn against(ns: u64, target_ms: f64) -> String {
    let ms = ms_from_ns(ns);
    if ms <= target_ms {
        format!("{ms:.3} ms (met)")
    } else {
        format!("{ms:.3} ms (missed: {:.1}x the target)", ms / target_ms)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::latency::Percentiles;
    use crate::spec::PayloadPathsExperiment;

    fn cell(path: PayloadPath, size_bytes: usize, receivers: u32, p50_ns: u64, loopback: f64) -> PayloadCell {
        PayloadCell {
            path,
            size_bytes,
            receivers,
            expected: 4,
            latency: Percentiles { count: 4, p50_ns, p99_ns: 2 * p50_ns, max_ns: 3 * p50_ns, ..Percentiles::default() },
            cpu_ns_per_sample: Some(1_500.0),
            loopback_bytes_per_sample: Some(loopback),
            to_iceoryx2: None,
            session_starts: 1,
        }
    }

    fn result() -> PayloadPathsResult {
        let shm = PayloadPath::Agents(agent::Link::Shm);
        let experiment = PayloadPathsExperiment {
            sizes: vec![360_960, 4 << 20],
            receivers: vec![1, 8],
            paths: vec![PayloadPath::Iceoryx2, shm],
            ..PayloadPathsExperiment::default()
        };
        let cells = vec![
            cell(PayloadPath::Iceoryx2, 4 << 20, 1, 100_000, 0.0),
            cell(shm, 4 << 20, 1, 400_000, 0.0),
            cell(PayloadPath::Iceoryx2, 360_960, 8, 200_000, 0.0),
            cell(shm, 360_960, 8, 600_000, 12.0),
        ];
        PayloadPathsResult::new(experiment, true, "0.50 0.40 0.30 1/100 7".into(), cells)
    }

    #[test]
    fn the_text_has_a_row_per_cell_under_its_header_and_names_every_target() {
        let text = text(&result());
        let lines: Vec<&str> = text.lines().collect();
        assert!(lines[0].starts_with("payload paths:") && lines[0].contains("0.50 0.40"), "{text}");
        assert!(lines[1].contains("p50 us") && lines[1].contains("CPU /iox"), "{text}");
        assert!(lines[2].contains("raw iceoryx2") && lines[2].contains("200.0"), "{text}");
        assert!(lines[5].contains("agents, shm") && lines[5].contains("4.00"), "{text}");
        assert!(text.contains("p50 0.400 ms (met) and p99 0.800 ms (met)"), "{text}");
        assert!(text.contains("p99 1.200 ms (missed: 1.2x the target)"), "{text}");
        assert!(text.contains("0 of 2 cells within, the largest 4.00x"), "{text}");
        assert!(text.contains("at most 12.0 B per sample"), "{text}");
    }

    #[test]
    fn the_markdown_has_a_row_per_cell_with_every_column() {
        let md = markdown(&result());
        let lines: Vec<&str> = md.lines().collect();
        assert_eq!(lines.len(), 2 + 4);
        for line in &lines {
            assert_eq!(line.matches('|').count(), COLUMNS.len() + 1, "{line}");
        }
        assert!(lines[2].starts_with("| 360960 | 8 | raw iceoryx2 | 4/4 | 200.0 |"), "{md}");
    }

    #[test]
    fn sessions_started_again_are_named_once_each_and_only_then() {
        let mut result = result();
        assert!(!notes(&result).iter().any(|n| n.starts_with("started again")));
        result.cells.iter_mut().filter(|c| c.receivers == 8).for_each(|c| c.session_starts = 2);
        let notes = notes(&result);
        let started: Vec<&String> = notes.iter().filter(|n| n.starts_with("started again")).collect();
        assert_eq!(started.len(), 1, "{notes:?}");
        assert!(started[0].contains("raw iceoryx2 to 8 (2 starts); agents, shm to 8 (2 starts) ("), "{notes:?}");
    }

    #[test]
    fn a_cell_without_deliveries_shows_dashes_not_zeros() {
        let mut empty = cell(PayloadPath::Agents(agent::Link::Rtps), 16, 1, 0, 0.0);
        empty.latency = Percentiles::default();
        let row = row(&empty);
        assert_eq!(row[3], "0/4");
        assert_eq!(&row[4..7], ["-", "-", "-"]);
    }
}
