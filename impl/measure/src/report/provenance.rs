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
    let _ = writeln!(md, "| results | [`results.json`](results.json), schema version {} |\n", p.schema_version);
    let _ = writeln!(
        md,
        "Latency is measured from the publication of a write's encoded delta at the source to its application (decoded \
         and applied) at each receiver, on one monotonic clock; the bridge's decoding of the ROS messages happens \
         before the clock starts. A sample carries the delta behind an 8-byte sequence number.\n"
    );
}
