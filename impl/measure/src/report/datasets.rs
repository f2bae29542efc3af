//! "Datasets": every log a run read, with its size, SHA-256 and whether it matches the manifest.

use std::fmt::Write as _;

use super::{Context, Section};
use crate::results::Results;

/// The section.
pub(super) const SECTION: Section = Section { heading: "## Datasets", figures: &[], draw: None, write };

fn write(md: &mut String, r: &Results, _: &Context<'_>) {
    let _ = writeln!(md, "| file | bytes | sha256 | matches manifest |\n|---|---:|---|---|");
    for d in &r.provenance.datasets {
        let matches = match d.matches_manifest() {
            Some(true) => "yes",
            Some(false) => "**no**",
            None => "not listed",
        };
        let _ = writeln!(md, "| {} | {} | `{}` | {matches} |", d.file, d.bytes, d.sha256);
    }
    let _ = writeln!(md);
}
