//! Small formatting helpers shared by the report's sections: percentile rows, run labels, figure links, what a
//! transport name means, and the footer every figure carries.

use std::fmt::Write as _;

use hdrhistogram::Histogram;

use crate::latency::{self, Percentiles};
use crate::provenance::Provenance;
use crate::results::RunResult;
use crate::units::ms_from_ns;

/// Header cells of a percentile row ([`pct_row`]).
pub(super) const PCT_HEAD: &str = "count | p50 ms | p90 ms | p99 ms | p99.9 ms | max ms";
/// Alignment cells of a percentile row.
pub(super) const PCT_RULE: &str = "---:|---:|---:|---:|---:|---:";

/// The cells of [`PCT_HEAD`]: count, then the percentiles in ms.
pub(super) fn pct_row(p: &Percentiles) -> String {
    format!(
        "{} | {:.3} | {:.3} | {:.3} | {:.3} | {:.3}",
        p.count,
        ms_from_ns(p.p50_ns),
        ms_from_ns(p.p90_ns),
        ms_from_ns(p.p99_ns),
        ms_from_ns(p.p999_ns),
        ms_from_ns(p.max_ns)
    )
}

/// One histogram holding every value of the histogram `pick` chooses from each run.
pub(super) fn merged<'a>(
    runs: impl Iterator<Item = &'a RunResult>,
    pick: fn(&RunResult) -> &Histogram<u64>,
) -> Histogram<u64> {
    let mut all = latency::histogram();
    for run in runs {
        let _ = all.add(pick(run));
    }
    all
}

/// `log (transport)`: the first columns of the replay tables.
pub(super) fn label(run: &RunResult) -> String {
    format!("{} ({})", run.workload, run.transport)
}

/// 200 points of a histogram's distribution, `(ms, fraction)`.
pub(super) fn cdf_ms(h: &Histogram<u64>) -> Vec<(f64, f64)> {
    latency::cdf(h, 200).into_iter().map(|(ns, q)| (ms_from_ns(ns), q)).collect()
}

/// What a transport name of an experiment file means, for figure footers and tables.
pub(super) fn link_description(name: &str) -> String {
    match name {
        "inproc" => "in-process bus (transport::inproc), receivers on threads of one process".to_owned(),
        "rtps" => "rustdds, one participant per agent, all in one process, loopback UDP".to_owned(),
        "rtps-processes" => "rustdds, every receiver a process of its own, loopback UDP".to_owned(),
        other => other.to_owned(),
    }
}

/// Footer of a figure of every transport of the replay sweep.
pub(super) const ALL_TRANSPORTS: &str = "inproc = in-process bus, one process; rtps = a rustdds participant per agent, \
     one process; rtps-processes = a process and participant per receiver; loopback UDP";

/// `one process` or `separate processes`, for verdicts.
pub(super) fn placement(transport: &str) -> &'static str {
    if transport.starts_with("rtps-processes") { "separate processes" } else { "one process" }
}

/// A figure's image and a link to its PNG.
pub(super) fn figure(md: &mut String, stem: &str, alt: &str) {
    let _ = writeln!(md, "![{alt}]({stem}.svg)\n\n(also [{stem}.png]({stem}.png))\n");
}

/// The seeds of a provenance, `name=seed, ...`.
pub(super) fn seeds(p: &Provenance) -> String {
    p.seeds.iter().map(|(k, v)| format!("{k}={v}")).collect::<Vec<_>>().join(", ")
}

/// The lines under every figure: command, commit, machine, network, transport and seeds.
pub(super) fn footer(p: &Provenance, transport: &str) -> Vec<String> {
    vec![
        format!("command: {}   commit {}   {}", p.command, p.short_commit(), p.rustc),
        format!("machine: {}", p.machine.summary()),
        format!("network: {}", p.network),
        format!("transport: {transport}"),
        format!("seeds: {}", seeds(p)),
    ]
}
