//! "Not measured yet": what the report does not cover, including the optional experiments this set left out.

use std::fmt::Write as _;

use super::{Context, Section};
use crate::results::Results;

/// The section.
pub(super) const SECTION: Section = Section { heading: "## Not measured yet", figures: &[], draw: None, write };

fn write(md: &mut String, r: &Results, _: &Context<'_>) {
    let _ = writeln!(
        md,
        "- The full agent layer (`agent::Agent`: envelope, anti-entropy, lock) on the measured path of the replay \
         and payload sweeps: receivers apply the source's deltas to a bare `dsr::Replica`{}.\n\
         - Partitions with agents as separate processes (the partition runs put their agents in one process).\n\
         {}{}",
        if r.payload_paths.is_some() {
            " (\"Same-host payloads against the machine's limit\" measures real agents in every receiver process)"
        } else {
            ""
        },
        if r.roles.is_some() {
            ""
        } else {
            "- BICA statistics of detector roles during a replay (no `roles` section).\n"
        },
        if r.timeline.is_some() { "" } else { "- The scheduler timeline of a detector under an injected overload.\n" }
    );
}
