//! "Latency against payload size": p50, p99 and max latency of the synthetic payload sweep, figure and table.

use std::fmt::Write as _;
use std::path::Path;

use super::format::{PCT_HEAD, PCT_RULE, figure, footer, link_description, pct_row};
use super::{Context, Section};
use crate::figures::{self, Chart, Series};
use crate::latency::Percentiles;
use crate::results::Results;
use crate::units::ms_from_ns;

const FIGURE: &str = "latency_vs_payload";

/// The section.
pub(super) const SECTION: Section =
    Section { heading: "## Latency against payload size", figures: &[FIGURE], draw: Some(draw), write };

fn draw(results: &Results, out: &Path) -> anyhow::Result<()> {
    let point = |f: fn(&Percentiles) -> u64| -> Vec<(f64, f64)> {
        results
            .set
            .payload
            .sizes
            .iter()
            .zip(&results.payload)
            .map(|(&size, r)| (size as f64, ms_from_ns(f(&r.latency))))
            .collect()
    };
    let chart = Chart {
        title: format!(
            "Latency against payload size ({} agents, {} Hz, {} writes per size)",
            results.set.payload.agents, results.set.payload.rate_hz, results.set.payload.count
        ),
        x_label: "bytes of the attribute written (log scale)".into(),
        y_label: "latency (ms, log scale)".into(),
        x_log: true,
        y_log: true,
        series: vec![
            Series { name: "p50".into(), points: point(|p| p.p50_ns) },
            Series { name: "p99".into(), points: point(|p| p.p99_ns) },
            Series { name: "max".into(), points: point(|p| p.max_ns) },
        ],
        footer: footer(&results.provenance, &link_description(&results.set.payload.transport)),
        legend_upper_left: false,
    };
    figures::render(&chart, out, FIGURE)
}

fn write(md: &mut String, r: &Results, _: &Context<'_>) {
    figure(md, FIGURE, "latency against payload size");
    let _ = writeln!(md, "Transport: {}.\n", link_description(&r.set.payload.transport));
    let _ = writeln!(md, "| bytes | {PCT_HEAD} |\n|---:|{PCT_RULE}|");
    for (size, run) in r.set.payload.sizes.iter().zip(&r.payload) {
        let _ = writeln!(md, "| {size} | {} |", pct_row(&run.latency));
    }
    let _ = writeln!(md);
}
