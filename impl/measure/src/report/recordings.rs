//! "Runs as MCAP": the recording of every run (written by [`crate::record::write_runs`] before the text), with
//! its message counts.

use std::fmt::Write as _;

use super::{Context, Section};
use crate::record::Metric;
use crate::results::Results;
use crate::units::mb_from_bytes;

/// The section.
pub(super) const SECTION: Section = Section { heading: "## Runs as MCAP", figures: &[], draw: None, write };

fn write(md: &mut String, _: &Results, context: &Context<'_>) {
    let bytes = context
        .runs
        .iter()
        .filter_map(|run| std::fs::metadata(context.out.join(&run.path)).ok())
        .map(|m| m.len())
        .sum::<u64>();
    let _ = writeln!(
        md,
        "One MCAP file per run, to open in Foxglove (or read with the `mcap` tools): per-write latencies \
         (`/metrics/latency`), convergence windows (`/metrics/convergence`), published bytes per 100 ms \
         (`/metrics/bandwidth`) and the run's summary (`/metrics/summary`), each a JSON-schema channel; times are ns \
         on the run's clock. The graph deltas of a replayed log are recorded by `cortex replay FILE --out DIR`. \
         Together they take {:.0} MB here, so the copy of a report committed to the repository leaves `runs/` out \
         (`.gitignore`): regenerate the report to get them.\n",
        mb_from_bytes(bytes as f64)
    );
    let _ = writeln!(md, "| run | file | latency messages | convergence messages |\n|---|---|---:|---:|");
    for run in context.runs {
        let count = |topic: &str| run.counts.get(topic).copied().unwrap_or(0);
        let path = run.path.display();
        let _ = writeln!(
            md,
            "| {} | [`{path}`]({path}) | {} | {} |",
            run.label,
            count(Metric::Latency.topic()),
            count(Metric::Convergence.topic())
        );
    }
}
