//! "Same-host payloads against the machine's limit": payloads from one writer to N receiver processes by every path
//! (agents over each link, their shared-memory transport alone, raw iceoryx2, memcpy) in one run, from [`crate::results::PayloadPathsResult`]; the same
//! table and targets `cortex bench payload` prints ([`crate::bench::payload::table`]). Says "not run" when the set
//! has no `payload_paths` section.

use std::fmt::Write as _;

use super::{Context, Section};
use crate::bench::payload::table;
use crate::results::Results;
use crate::spec::PayloadPath;

/// The section.
pub(super) const SECTION: Section =
    Section { heading: "## Same-host payloads against the machine's limit", figures: &[], draw: None, write };

fn write(md: &mut String, r: &Results, _: &Context<'_>) {
    let Some(result) = &r.payload_paths else {
        let _ = writeln!(md, "Not run: the experiment set has no `payload_paths` section.\n");
        return;
    };
    let paths: Vec<String> = result.experiment.paths.iter().map(|p| format!("`{}`", p.label())).collect();
    let _ = writeln!(
        md,
        "One writer to N receiver processes on this host, by {} in one run (`cortex bench payload` measures the \
         same; `measure::bench::payload`). Agents: an `agent::Agent` in the report's process writes `cam_rgb` of a \
         node, and each receiver process runs its own agent over the same link (`cortex agent --transport`). Raw \
         iceoryx2 (`transport::shm::limit`): the sample copied once into a loaned chunk and read in place by each \
         receiver, no agent — the same-host limit; memcpy: one copy of the size in this process.{} Every size goes \
         through the same receivers in turn, after probes and {}.\n",
        paths.join(", "),
        transport_text(&result.experiment),
        warmup_text(&result.experiment)
    );
    let _ = writeln!(md, "{}.\n", table::heading(result));
    md.push_str(&table::markdown(result));
    md.push('\n');
    for note in table::notes(result) {
        let _ = writeln!(md, "- {note}");
    }
    let targets = table::targets(result);
    if !targets.is_empty() {
        let _ = writeln!(md, "\nIssue 20's targets (benchmarks, 2-core machine) beside this run:\n");
        for target in targets {
            let _ = writeln!(md, "- {}", target.trim_start_matches("target, "));
        }
    }
    md.push('\n');
}

/// What the shared-memory transport path is, when the run has it.
fn transport_text(experiment: &crate::spec::PayloadPathsExperiment) -> &'static str {
    if experiment.paths.contains(&PayloadPath::Transport) {
        " The shared-memory transport (`transport::shm::ShmTransport`): the agents' transport between processes with \
         no agent on either side, so that between raw iceoryx2 and the agents over `shm` it shows which layer a \
         difference is in."
    } else {
        ""
    }
}

/// The warm-up of each size, in words.
fn warmup_text(experiment: &crate::spec::PayloadPathsExperiment) -> String {
    let steady: Vec<String> = experiment
        .sizes
        .iter()
        .filter(|&&size| experiment.warmup_for(size) != experiment.warmup)
        .map(|&size| format!("{} of {size} B", experiment.warmup_for(size)))
        .collect();
    match steady.as_slice() {
        [] => format!("{} warm-up samples", experiment.warmup),
        _ => format!(
            "{} warm-up samples ({}: `steady_max`, the samples that filled a receiver's 64 MiB anti-entropy history \
             when it kept every overwritten frame, kept so that runs compare; the history now folds them and holds \
             one)",
            experiment.warmup,
            steady.join(", ")
        ),
    }
}
