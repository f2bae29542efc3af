//! "How this report was obtained": command, commit, compiler, machine, network, seeds, and what latency means.

use std::fmt::Write as _;

use super::format::seeds;
use super::{Context, Section};
use crate::results::Results;

/// The section.
pub(super) const SECTION: Section =
    Section { heading: "## How this report was obtained", figures: &[], draw: None, write };

fn write(md: &mut String, r: &Results, _: &Context<'_>) {
    let p = &r.provenance;
    let _ = writeln!(md, "| | |\n|---|---|");
    let _ = writeln!(md, "| command | `{}` |", p.command);
    let _ = writeln!(
        md,
        "| commit | `{}`{} |",
        p.commit,
        if p.dirty == Some(true) { " (uncommitted changes)" } else { "" }
    );
    let _ = writeln!(md, "| compiler | {} ({} build) |", p.rustc, if p.release_build { "release" } else { "debug" });
    let _ = writeln!(md, "| machine | {} |", p.machine.summary());
    let _ = writeln!(md, "| network | {} |", p.network);
    let _ = writeln!(md, "| started | {} s after the Unix epoch; the set took {:.1} s |", p.started_unix_s, r.seconds);
    let _ = writeln!(md, "| seeds | {} |", seeds(p));
    if let Some(restarted) = restarted_runs(r) {
        let _ = writeln!(md, "| runs started again | {restarted} |");
    }
    let _ = writeln!(md, "| results | [`results.json`](results.json), schema version {} |\n", p.schema_version);
    let _ = writeln!(
        md,
        "Latency is measured from the publication of a write's encoded delta at the source to its application (decoded \
         and applied) at each receiver, on one monotonic clock; the bridge's decoding of the ROS messages happens \
         before the clock starts. A sample carries the delta behind an 8-byte sequence number.\n"
    );
}

/// The runs whose receiver processes were started more than once, because some did not answer the source's
/// probes (`measure::process`), with their starts; `None` when every run started once.
fn restarted_runs(r: &Results) -> Option<String> {
    let runs = r.replay.iter().chain(&r.payload).chain(r.faults.iter().map(|f| &f.run));
    let restarted: Vec<String> = runs
        .filter(|run| run.start_attempts > 1)
        .map(|run| {
            format!(
                "{} over {} with {} agents, seed {}: {} starts",
                run.workload, run.transport, run.agents, run.seed, run.start_attempts
            )
        })
        .collect();
    (!restarted.is_empty()).then(|| {
        format!(
            "{} (a receiver did not answer the source's probes; nothing is measured before all have answered)",
            restarted.join("; ")
        )
    })
}
