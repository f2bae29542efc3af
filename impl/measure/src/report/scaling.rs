//! "Control traffic against number of agents": anti-entropy traffic (announces, missing-requests) and repairs
//! beside the data, per agent and in total, from [`crate::results::ScalingResult`]: a figure, a table and the
//! growth exponent between the smallest and the largest group. Says "not run" when the set has no `scaling`
//! section.

use std::fmt::Write as _;
use std::path::Path;

use super::format::{figure, footer};
use super::{Context, Section};
use crate::figures::{self, Chart, Series};
use crate::results::{Results, ScalingRates, ScalingResult, ScalingRow};

const FIGURE: &str = "control_traffic_vs_agents";

/// The section.
pub(super) const SECTION: Section =
    Section { heading: "## Control traffic against number of agents", figures: &[FIGURE], draw: Some(draw), write };

/// What the figure's transport line says.
const HOW: &str = "in-process bus, seeded simulator: N real agent::Agent values pumped on one manual clock";

fn draw(results: &Results, out: &Path) -> anyhow::Result<()> {
    let Some(result) = &results.scaling else { return Ok(()) };
    let line = |name: &str, value: &dyn Fn(ScalingRates) -> f64| Series {
        name: name.to_owned(),
        points: result.rows.iter().map(|row| (f64::from(row.agents), value(row.rates()))).collect(),
    };
    let chart = Chart {
        title: "Anti-entropy and data traffic against number of agents".into(),
        x_label: "agents".into(),
        y_label: "bytes per second (log)".into(),
        x_log: true,
        y_log: true,
        series: vec![
            line("control sent, all agents", &|r| r.control_bytes_sent),
            line("control received, per agent", &|r| r.control_bytes_received_per_agent),
            line("repairs sent, all agents", &|r| r.repair_bytes_sent),
            line("data sent, all agents", &|r| r.data_bytes_sent),
            line("data received, per agent", &|r| r.data_bytes_received_per_agent),
        ],
        footer: footer(&results.provenance, HOW),
        legend_upper_left: true,
    };
    figures::render(&chart, out, FIGURE)
}

fn write(md: &mut String, r: &Results, _: &Context<'_>) {
    let Some(result) = &r.scaling else {
        let _ = writeln!(md, "Not run: the experiment set has no `scaling` section.\n");
        return;
    };
    let e = &result.experiment;
    figure(md, FIGURE, "control traffic against number of agents");
    let _ = writeln!(
        md,
        "N agents on the in-process bus, driven by hand on one manual clock (`measure::scaling`, seed {}): agent 1 \
         starts the graph, the others join it, then {} writers take turns writing one float at {} Hz in total for \
         {} ms of simulated time, with a base announce period of {} ms. Bytes are envelope bytes (no RTPS or UDP \
         headers), counted by message kind where each agent publishes (*sent*) and where each agent takes a sample \
         off its inbox (*received*). Control = announces and missing-requests; repairs = their answers (deltas, \
         snapshots). The bus gives every sample to every other agent, like a multicast group without directed \
         writes (over RTPS an answer goes to the asker alone).\n",
        e.seed, e.writers, e.write_rate_hz, e.window_ms, e.announce_ms
    );
    let _ = writeln!(
        md,
        "| N | writes/s | announces sent/s | control B/s sent (all) | control B/s received per agent | control B/s received (all) | repairs B/s sent (all) | data B/s sent (all) | data B/s received per agent | converged |\n|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|"
    );
    for row in &result.rows {
        table_row(md, row);
    }
    let _ = writeln!(md);
    growth(md, result);
}

fn table_row(md: &mut String, row: &ScalingRow) {
    let r = row.rates();
    let _ = writeln!(
        md,
        "| {} | {:.0} | {:.1} | {:.0} | {:.0} | {:.0} | {:.0} | {:.0} | {:.0} | {} |",
        row.agents,
        r.writes,
        r.announces_sent,
        r.control_bytes_sent,
        r.control_bytes_received_per_agent,
        r.control_bytes_received,
        r.repair_bytes_sent,
        r.data_bytes_sent,
        r.data_bytes_received_per_agent,
        if row.converged { "yes" } else { "no" }
    );
}

/// The exponent k of N^k that takes the smallest group's figure to the largest's, for the totals.
fn growth(md: &mut String, result: &ScalingResult) {
    let (Some(small), Some(large)) =
        (result.rows.iter().min_by_key(|r| r.agents), result.rows.iter().max_by_key(|r| r.agents))
    else {
        return;
    };
    if small.agents == large.agents {
        return;
    }
    let exponent = |value: &dyn Fn(ScalingRates) -> f64| {
        let (a, b) = (value(small.rates()), value(large.rates()));
        if a > 0.0 && b > 0.0 {
            format!("{:.2}", (b / a).ln() / (f64::from(large.agents) / f64::from(small.agents)).ln())
        } else {
            "n/a".to_owned()
        }
    };
    let _ = writeln!(
        md,
        "From {} to {} agents, control bytes sent by all agents grow as N^{}, control bytes received by all as N^{}, \
         announces sent per second as N^{} (the exponent between the two groups; 1 is linear, 2 quadratic).\n",
        small.agents,
        large.agents,
        exponent(&|r| r.control_bytes_sent),
        exponent(&|r| r.control_bytes_received),
        exponent(&|r| r.announces_sent),
    );
}
