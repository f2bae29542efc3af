//! "Convergence windows": per-write convergence windows with and without injected faults (figure and table), the
//! end-of-replay convergence of every replay run, and the reconvergence after a healed partition.

use std::fmt::Write as _;
use std::path::Path;

use super::format::{PCT_HEAD, PCT_RULE, cdf_ms, figure, footer, label, pct_row};
use super::{Context, Section};
use crate::figures::{self, Chart, Series};
use crate::results::{Results, RunResult};
use crate::units::ms_from_ns;

const FIGURE: &str = "convergence_windows";

/// The section.
pub(super) const SECTION: Section =
    Section { heading: "## Convergence windows", figures: &[FIGURE], draw: Some(draw), write };

fn draw(results: &Results, out: &Path) -> anyhow::Result<()> {
    let series = results
        .faults
        .iter()
        .map(|f| Series {
            name: format!("{} ({})", f.label, f.run.transport.trim_end_matches("+faults")),
            points: cdf_ms(&f.run.convergence_histogram),
        })
        .collect();
    let chart = Chart {
        title: format!(
            "Per-write convergence window, {} agents, {}",
            results.set.faults.agents,
            results.faults.first().map_or("", |f| f.run.workload.as_str())
        ),
        x_label: "time until every replica reflects the write (ms, log scale)".into(),
        y_label: "fraction of writes".into(),
        x_log: true,
        series,
        footer: footer(
            &results.provenance,
            &format!(
                "{}; the seeded fault injector (transport::fault) on each receiver",
                results.set.faults.transports.join(", ")
            ),
        ),
        ..Chart::default()
    };
    figures::render(&chart, out, FIGURE)
}

fn write(md: &mut String, r: &Results, _: &Context<'_>) {
    figure(md, FIGURE, "convergence windows with and without faults");
    let _ = writeln!(
        md,
        "Per write: the time until every replica reflects it. After the replay ends: the time from the last write to \
         the last application anywhere, when every receiver then has the source's digest.\n"
    );
    windows_table(md, r);
    partition_table(md, r);
    let _ = writeln!(md);
}

fn windows_table(md: &mut String, r: &Results) {
    let _ = writeln!(
        md,
        "| run | N | per-write {PCT_HEAD} | end of replay ms | digests equal | duplicates injected |\n|---|---:|{PCT_RULE}|---:|---|---:|"
    );
    let end =
        |x: &RunResult| x.end_convergence_ns.map_or_else(|| "never".to_owned(), |ns| format!("{:.3}", ms_from_ns(ns)));
    for f in &r.faults {
        let x = &f.run;
        let _ = writeln!(
            md,
            "| {} ({}) | {} | {} | {} | {} | {} |",
            f.label,
            label(x),
            x.agents,
            pct_row(&x.convergence),
            end(x),
            x.digests_equal,
            x.bandwidth.injected_duplicates
        );
    }
    for x in &r.replay {
        let _ = writeln!(
            md,
            "| replay {} seed {} | {} | {} | {} | {} | 0 |",
            label(x),
            x.seed,
            x.agents,
            pct_row(&x.convergence),
            end(x),
            x.digests_equal
        );
    }
}

fn partition_table(md: &mut String, r: &Results) {
    let _ = writeln!(
        md,
        "\nAfter a healed partition (real agents with anti-entropy, all in this process, on the in-process bus or one \
         RTPS participant each; the last agent cut off while both sides write, then healed; time from the heal until \
         every digest is equal; the announce period bounds it):\n"
    );
    let _ = writeln!(
        md,
        "| transport | seed | agents | partition ms | announce ms | writes during it | samples cut | reconverged after ms |\n|---|---:|---:|---:|---:|---:|---:|---:|"
    );
    for x in &r.partition {
        let _ = writeln!(
            md,
            "| {} | {} | {} | {} | {} | {} | {} | {} |",
            x.transport,
            x.seed,
            x.agents,
            x.partition_ms,
            x.announce_period_ms,
            x.writes,
            x.dropped,
            x.reconverge_ns.map_or_else(|| "not within the timeout".to_owned(), |ns| format!("{:.1}", ms_from_ns(ns)))
        );
    }
    for transport in &r.set.partition.transports {
        let mut times: Vec<u64> =
            r.partition.iter().filter(|x| &x.transport == transport).filter_map(|x| x.reconverge_ns).collect();
        times.sort_unstable();
        if let (Some(first), Some(last)) = (times.first(), times.last()) {
            let _ = writeln!(
                md,
                "\n{transport}: median {:.1} ms, min {:.1} ms, max {:.1} ms over {} runs.",
                ms_from_ns(times[times.len() / 2]),
                ms_from_ns(*first),
                ms_from_ns(*last),
                times.len()
            );
        }
    }
}
