//! "Latency by number of agents": the latency CDF per transport and number of agents (every log and seed merged)
//! and a table of every run's percentiles per payload class.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;

use super::format::{ALL_TRANSPORTS, PCT_HEAD, PCT_RULE, cdf_ms, figure, footer, label, merged, pct_row};
use super::{Context, Section};
use crate::figures::{self, Chart, Series};
use crate::results::{Results, RunResult};

const FIGURE: &str = "latency_cdf_by_agents";

/// The section.
pub(super) const SECTION: Section =
    Section { heading: "## Latency by number of agents", figures: &[FIGURE], draw: Some(draw), write };

fn draw(results: &Results, out: &Path) -> anyhow::Result<()> {
    let mut by_agents: BTreeMap<(&str, u32), Vec<&RunResult>> = BTreeMap::new();
    for run in &results.replay {
        by_agents.entry((&run.transport, run.agents)).or_default().push(run);
    }
    let series = by_agents
        .iter()
        .map(|((transport, n), runs)| Series {
            name: format!("{transport} N = {n}"),
            points: cdf_ms(&merged(runs.iter().copied(), |r| &r.latency_histogram)),
        })
        .collect();
    let chart = Chart {
        title: "Latency from write to application, all bundled logs".into(),
        x_label: "latency (ms, log scale)".into(),
        y_label: "fraction of (write, receiver) pairs".into(),
        x_log: true,
        series,
        footer: footer(&results.provenance, ALL_TRANSPORTS),
        ..Chart::default()
    };
    figures::render(&chart, out, FIGURE)
}

fn write(md: &mut String, r: &Results, _: &Context<'_>) {
    figure(md, FIGURE, "latency CDFs by number of agents");
    let _ = writeln!(md, "Every log and seed, per payload class (pairs of write and receiver):\n");
    let _ = writeln!(md, "| log (transport) | N | seed | class | {PCT_HEAD} |\n|---|---:|---:|---|{PCT_RULE}|");
    for run in &r.replay {
        for (class, p) in &run.latency_by_class {
            let _ =
                writeln!(md, "| {} | {} | {} | {} | {} |", label(run), run.agents, run.seed, class.name(), pct_row(p));
        }
    }
    let _ = writeln!(md);
}
