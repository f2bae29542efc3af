//! "CPU and memory": the source's and the receivers' CPU time and peak resident memory, per run.

use std::fmt::Write as _;

use super::format::label;
use super::{Context, Section};
use crate::results::Results;
use crate::units::{mib_from_bytes, ms_from_ns, ms_from_ns_f64};

/// The section.
pub(super) const SECTION: Section = Section { heading: "## CPU and memory", figures: &[], draw: None, write };

fn write(md: &mut String, r: &Results, _: &Context<'_>) {
    let _ = writeln!(
        md,
        "The source: CPU time of its publishing thread while publishing (`/proc/thread-self/schedstat`; it mostly \
         sleeps until writes are due). A receiver on a thread (`inproc`, `rtps`): its thread while receiving \
         (decoding and applying; for `rtps` the rustdds threads are not counted), and the shared process's peak \
         resident size (`VmHWM`) is the only memory figure. A receiver process (`rtps-processes`): every thread of \
         the process, rustdds included (`getrusage`), from its first probe until it stops, and its own peak \
         resident size. The source's memory is the `cortex` process's peak (it also holds the planned workload).\n"
    );
    let _ = writeln!(
        md,
        "| log (transport) | N | seed | source CPU ms | receiver CPU ms (mean) | receiver CPU % of span (mean) | receiver peak RSS MiB (max) | cortex process peak RSS MiB |\n|---|---:|---:|---:|---:|---:|---:|---:|"
    );
    let mib = |v: u64| format!("{:.0}", mib_from_bytes(v));
    for x in r.replay.iter().chain(r.payload.iter()).chain(r.faults.iter().map(|f| &f.run)) {
        let receivers = || x.agent_costs.iter().filter(|c| c.agent != 1);
        let cpus: Vec<u64> = receivers().filter_map(|c| c.cpu_ns).collect();
        let mean_ns = cpus.iter().sum::<u64>() as f64 / cpus.len().max(1) as f64;
        let own_rss = receivers().filter(|c| c.kind == "process").filter_map(|c| c.peak_rss_bytes).max();
        let _ = writeln!(
            md,
            "| {} | {} | {} | {} | {:.1} | {:.1} | {} | {} |",
            label(x),
            x.agents,
            x.seed,
            x.agent_costs
                .first()
                .and_then(|c| c.cpu_ns)
                .map_or_else(|| "?".to_owned(), |v| format!("{:.1}", ms_from_ns(v))),
            ms_from_ns_f64(mean_ns),
            // A share of the publishing span, in percent: CPU seconds over span seconds.
            100.0 * mean_ns / 1e9 / x.publish_seconds.max(1e-3),
            own_rss.map_or_else(|| "shared".to_owned(), mib),
            x.process_peak_rss_bytes.map_or_else(|| "?".to_owned(), mib)
        );
    }
    let _ = writeln!(md);
}
