//! "Bandwidth against number of agents": bytes per second on the first log against N, from the transports'
//! counters and the loopback interface, figure and a table of every replay run.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;

use super::format::{ALL_TRANSPORTS, figure, footer, label};
use super::{Context, Section};
use crate::figures::{self, Chart, Series};
use crate::results::{Results, RunResult};
use crate::units::mb_from_bytes;

const FIGURE: &str = "bandwidth_vs_agents";

/// The section.
pub(super) const SECTION: Section =
    Section { heading: "## Bandwidth against number of agents", figures: &[FIGURE], draw: Some(draw), write };

/// The file name of the set's first log: the bandwidth figure and the claims' bandwidth row use its runs.
pub(super) fn first_log(results: &Results) -> Option<String> {
    results.set.logs.first().and_then(|l| l.path.file_name()).map(|n| n.to_string_lossy().into_owned())
}

fn draw(results: &Results, out: &Path) -> anyhow::Result<()> {
    let first_log = first_log(results);
    let mut per_link: BTreeMap<&str, BTreeMap<u32, Vec<&RunResult>>> = BTreeMap::new();
    for run in results.replay.iter().filter(|r| Some(&r.workload) == first_log.as_ref()) {
        per_link.entry(&run.transport).or_default().entry(run.agents).or_default().push(run);
    }
    let mean = |runs: &[&RunResult], f: &dyn Fn(&RunResult) -> f64| {
        runs.iter().map(|r| f(r)).sum::<f64>() / runs.len().max(1) as f64
    };
    let mut series = Vec::new();
    for (link, by_n) in &per_link {
        let line = |name: &str, f: &dyn Fn(&RunResult) -> f64| Series {
            name: format!("{link}: {name}"),
            points: by_n.iter().map(|(n, runs)| (f64::from(*n), mb_from_bytes(mean(runs, f)))).collect(),
        };
        series.push(line("sent (transport counters)", &|r| r.bandwidth.wire_bytes_per_second));
        series.push(line("received by all receivers", &|r| r.bandwidth.received_bytes_per_second));
        series.push(line("loopback tx (OS counter)", &|r| r.bandwidth.loopback_tx_bytes_per_second.unwrap_or(0.0)));
    }
    let chart = Chart {
        title: format!("Bytes per second against number of agents, {}", first_log.unwrap_or_default()),
        x_label: "agents (the source included)".into(),
        y_label: "MB/s".into(),
        series,
        footer: footer(&results.provenance, ALL_TRANSPORTS),
        legend_upper_left: true,
        ..Chart::default()
    };
    figures::render(&chart, out, FIGURE)
}

fn write(md: &mut String, r: &Results, _: &Context<'_>) {
    figure(md, FIGURE, "bandwidth against number of agents");
    let _ = writeln!(
        md,
        "Bytes per second of the publishing span, from the transports' counters (`TransportStats`). The OS-level \
         cross-check is the growth of the loopback interface's transmitted bytes (`/proc/self/net/dev`, the \
         loopback of the report's network namespace) from the first write until every receiver has everything: near \
         zero for the in-process bus, which does not use the network (other processes on the machine add to it); \
         for RTPS it includes acknowledgements, heartbeats and discovery, while the transport's own count is an \
         estimate of data submessages and headers. Exact figures against the number of reader processes, with \
         multicast on and off, come from `cortex bench fanout` in fresh network namespaces.\n"
    );
    let _ = writeln!(
        md,
        "| log (transport) | N | seed | sent MB/s | received MB/s (all receivers) | per receiver MB/s | loopback tx bytes | dropped |\n|---|---:|---:|---:|---:|---:|---:|---:|"
    );
    for run in &r.replay {
        let b = &run.bandwidth;
        let _ = writeln!(
            md,
            "| {} | {} | {} | {:.3} | {:.3} | {:.3} | {} | {} |",
            label(run),
            run.agents,
            run.seed,
            mb_from_bytes(b.wire_bytes_per_second),
            mb_from_bytes(b.received_bytes_per_second),
            mb_from_bytes(b.received_bytes_per_second) / f64::from(run.agents - 1),
            b.loopback_tx_bytes.map_or_else(|| "unreadable".to_owned(), |v| v.to_string()),
            b.dropped_full
        );
    }
    let _ = writeln!(md);
}
