//! The report of an experiment set: `results.json` (the versioned schema), the figures (SVG and PNG), one MCAP
//! recording per run under `runs/` (see [`crate::record`]) and `report.md`, which puts every number beside how it was obtained and beside the DSR_d paper's claims and the
//! published figures of the C++ implementation (labelled as measured elsewhere).

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;

use anyhow::Context as _;
use hdrhistogram::Histogram;

use crate::experiment::Results;
use crate::figures::{self, Chart, Series};
use crate::latency::{self, Percentiles};
use crate::run::RunResult;

/// Stems of the figures a report contains (each written as `.svg` and `.png`); a set with a timeline adds
/// [`crate::timeline::FIGURE`].
pub const FIGURES: [&str; 4] =
    ["latency_cdf_by_agents", "latency_vs_payload", "bandwidth_vs_agents", "convergence_windows"];

/// Headings of the sections of `report.md`, in order; [`crate::timeline::SECTION`] comes just before "Not measured
/// yet".
pub const SECTIONS: [&str; 10] = [
    "## How this report was obtained",
    "## Beside the paper's claims and the C++ implementation",
    "## Latency by number of agents",
    "## Latency against payload size",
    "## Bandwidth against number of agents",
    "## Convergence windows",
    "## CPU and memory",
    "## Not measured yet",
    "## Datasets",
    "## Runs as MCAP",
];

fn ms(ns: u64) -> f64 {
    ns as f64 / 1e6
}

fn pct_row(p: &Percentiles) -> String {
    format!(
        "{} | {:.3} | {:.3} | {:.3} | {:.3} | {:.3}",
        p.count,
        ms(p.p50_ns),
        ms(p.p90_ns),
        ms(p.p99_ns),
        ms(p.p999_ns),
        ms(p.max_ns)
    )
}

const PCT_HEAD: &str = "count | p50 ms | p90 ms | p99 ms | p99.9 ms | max ms";
const PCT_RULE: &str = "---:|---:|---:|---:|---:|---:";

fn merged<'a>(runs: impl Iterator<Item = &'a RunResult>, pick: fn(&RunResult) -> &Histogram<u64>) -> Histogram<u64> {
    let mut all = latency::histogram();
    for run in runs {
        let _ = all.add(pick(run));
    }
    all
}

/// `log (transport)`: the first columns of the replay tables.
fn label(run: &RunResult) -> String {
    format!("{} ({})", run.workload, run.transport)
}

fn cdf_ms(h: &Histogram<u64>) -> Vec<(f64, f64)> {
    latency::cdf(h, 200).into_iter().map(|(ns, q)| (ms(ns), q)).collect()
}

/// Writes `results.json`, the figures, the runs as MCAP (`runs/*.mcap`) and `report.md` into `out`.
///
/// # Errors
/// A file that cannot be written or a figure that cannot be drawn.
pub fn write(results: &Results, out: &Path) -> anyhow::Result<()> {
    std::fs::create_dir_all(out).with_context(|| format!("cannot create {}", out.display()))?;
    let json = serde_json::to_string_pretty(results)?;
    std::fs::write(out.join("results.json"), json).context("cannot write results.json")?;
    let p = &results.provenance;
    let seeds = p.seeds.iter().map(|(k, v)| format!("{k}={v}")).collect::<Vec<_>>().join(", ");
    let footer = |transport: &str| {
        vec![
            format!("command: {}   commit {}   {}", p.command, p.short_commit(), p.rustc),
            format!("machine: {}", p.machine.summary()),
            format!("network: {}", p.network),
            format!("transport: {transport}"),
            format!("seeds: {seeds}"),
        ]
    };
    let both = "inproc = in-process bus, one process; rtps = a rustdds participant per agent, one process; \
                rtps-processes = a process and participant per receiver; loopback UDP";

    // Figure 1: latency CDF per transport and number of agents, all logs and seeds merged.
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
        footer: footer(both),
        ..Chart::default()
    };
    figures::render(&chart, out, FIGURES[0])?;

    // Figure 2: latency against payload size.
    let point = |f: fn(&Percentiles) -> u64| -> Vec<(f64, f64)> {
        results
            .set
            .payload
            .sizes
            .iter()
            .zip(&results.payload)
            .map(|(&size, r)| (size as f64, ms(f(&r.latency))))
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
        footer: footer(&link_description(&results.set.payload.transport)),
        legend_upper_left: false,
    };
    figures::render(&chart, out, FIGURES[1])?;

    // Figure 3: bandwidth against number of agents, on the first log (mean over seeds), per transport.
    let first_log = results.set.logs.first().and_then(|l| l.path.file_name()).map(|n| n.to_string_lossy().into_owned());
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
            points: by_n.iter().map(|(n, runs)| (f64::from(*n), mean(runs, f) / 1e6)).collect(),
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
        footer: footer(both),
        legend_upper_left: true,
        ..Chart::default()
    };
    figures::render(&chart, out, FIGURES[2])?;

    // Figure 4: convergence windows with and without faults.
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
        footer: footer(&format!(
            "{}; the seeded fault injector (transport::fault) on each receiver",
            results.set.faults.transports.join(", ")
        )),
        ..Chart::default()
    };
    figures::render(&chart, out, FIGURES[3])?;

    if let Some(timeline) = &results.timeline {
        let how = "none: one BICA runtime on one thread, real monotonic clock, overload injected by another component";
        crate::timeline::render_figure(timeline, footer(how), out)?;
    }

    let runs = crate::record::write_runs(results, out)?;
    std::fs::write(out.join("report.md"), markdown(results, &runs, out)).context("cannot write report.md")?;
    Ok(())
}

/// What a transport name of an experiment file means, for figure footers and tables.
fn link_description(name: &str) -> String {
    match name {
        "inproc" => "in-process bus (transport::inproc), receivers on threads of one process".to_owned(),
        "rtps" => "rustdds, one participant per agent, all in one process, loopback UDP".to_owned(),
        "rtps-processes" => "rustdds, every receiver a process of its own, loopback UDP".to_owned(),
        other => other.to_owned(),
    }
}

/// `one process` or `separate processes`, for verdicts.
fn placement(transport: &str) -> &'static str {
    if transport.starts_with("rtps-processes") { "separate processes" } else { "one process" }
}

fn figure(md: &mut String, stem: &str, alt: &str) {
    let _ = writeln!(md, "![{alt}]({stem}.svg)\n\n(also [{stem}.png]({stem}.png))\n");
}

fn markdown(r: &Results, runs: &[crate::record::RecordedRun], out: &Path) -> String {
    let p = &r.provenance;
    let mut md = String::new();
    let _ = writeln!(md, "# Performance report: {} ({})\n", r.experiment, r.mode);
    let _ = writeln!(
        md,
        "Generated by `cortex report`. Each table and figure names its transport: `inproc` — the agents are replicas \
         on threads of one process joined by the in-process bus (`transport::inproc`); `rtps` — one RTPS participant \
         per agent (`transport::rtps` on rustdds, loopback UDP), all in one process; `rtps-processes` — the source is \
         the `cortex` process and **every receiver is a separate process** (`cortex measure-receiver`) with its own \
         replica and RTPS participant, all reading one host clock (`CLOCK_MONOTONIC`). `+faults` marks the seeded \
         fault injector on each receiver's receiving side (in the receiver's own process for `rtps-processes`). The \
         receivers hold a `dsr::Replica` and apply the source's deltas, without the agent layer's envelope, \
         anti-entropy and lock; the partition runs use real agents (`agent::Agent`, with anti-entropy) in one \
         process, on the in-process bus or RTPS as their table says. Medians and percentiles of all runs, never a best run.\n"
    );
    let _ = writeln!(md, "{}\n", SECTIONS[0]);
    let _ = writeln!(md, "| | |\n|---|---|");
    let _ = writeln!(md, "| command | `{}` |", p.command);
    let _ = writeln!(
        md,
        "| commit | `{}`{} |",
        p.commit,
        if p.dirty == Some(true) { " (uncommitted changes)" } else { "" }
    );
    let _ = writeln!(md, "| compiler | {} ({} build) |", p.rustc, if p.release_build { "release" } else { "debug" });
    let _ = writeln!(md, "| machine | {} |", p.machine.summary());
    let _ = writeln!(md, "| network | {} |", p.network);
    let _ = writeln!(md, "| started | {} s after the Unix epoch; the set took {:.1} s |", p.started_unix_s, r.seconds);
    let seeds = p.seeds.iter().map(|(k, v)| format!("{k}={v}")).collect::<Vec<_>>().join(", ");
    let _ = writeln!(md, "| seeds | {seeds} |");
    let _ = writeln!(md, "| results | [`results.json`](results.json), schema version {} |\n", p.schema_version);
    let _ = writeln!(
        md,
        "Latency is measured from the publication of a write's encoded delta at the source to its application (decoded \
         and applied) at each receiver, on one monotonic clock; the bridge's decoding of the ROS messages happens \
         before the clock starts. A sample carries the delta behind an 8-byte sequence number.\n"
    );

    // Comparison.
    let _ = writeln!(md, "{}\n", SECTIONS[1]);
    let _ = writeln!(md, "| claim or figure | source | ours (this run) | verdict |\n|---|---|---|---|");
    let mut links: Vec<&str> = r.replay.iter().map(|x| x.transport.as_str()).collect();
    links.sort_unstable();
    links.dedup();
    for link in &links {
        let runs = || r.replay.iter().filter(|x| x.transport == *link);
        let worst = runs().max_by_key(|x| x.latency.p99_ns);
        let worst_p99 = worst.map_or(0, |x| x.latency.p99_ns);
        let worst_at =
            worst.map_or_else(String::new, |x| format!(" ({}, N={}, seed {})", x.workload, x.agents, x.seed));
        let worst_max = runs().map(|x| x.latency.max_ns).max().unwrap_or(0);
        let worst_conv = runs().map(|x| x.convergence.p99_ns).max().unwrap_or(0);
        let _ = writeln!(
            md,
            "| latency below 50 ms \"for a wide range of configurations and payloads\" | DSR_d paper | {link}: worst p99 \
             over every log and N: {:.2} ms{worst_at}, largest max {:.2} ms; worst per-write convergence p99 {:.2} ms \
             | {} ({link}, {}) |",
            ms(worst_p99),
            ms(worst_max),
            ms(worst_conv),
            if worst_p99 < 50_000_000 { "holds at p99" } else { "does not hold at p99" },
            placement(link)
        );
    }
    let n_hi = r.set.agents.iter().max().copied().unwrap_or(0);
    let first_log = r.set.logs.first().and_then(|l| l.path.file_name()).map(|n| n.to_string_lossy().into_owned());
    let bw = |link: &str, n: u32, f: fn(&RunResult) -> Option<f64>| {
        let values: Vec<f64> = r
            .replay
            .iter()
            .filter(|x| x.transport == link && x.agents == n && Some(&x.workload) == first_log.as_ref())
            .filter_map(f)
            .collect();
        (!values.is_empty()).then(|| values.iter().sum::<f64>() / values.len() as f64 / 1e6)
    };
    let sent = |x: &RunResult| Some(x.bandwidth.wire_bytes_per_second);
    let lo = |x: &RunResult| x.bandwidth.loopback_tx_bytes_per_second;
    let log_name = first_log.clone().unwrap_or_default();
    // Prefer the runs with separate processes: they are the paper's configuration.
    let bw_link = ["rtps-processes", "rtps"]
        .into_iter()
        .find(|link| r.replay.iter().any(|x| x.transport == *link))
        .unwrap_or("rtps");
    let mut ns: Vec<u32> = r.set.agents.clone();
    ns.sort_unstable();
    ns.dedup();
    let points: Vec<(u32, f64, f64)> =
        ns.iter().filter_map(|&n| Some((n, bw(bw_link, n, sent)?, bw(bw_link, n, lo)?))).collect();
    match points.first() {
        Some(&(n_first, _, l_first)) if points.len() > 1 => {
            let growth = |l: f64| l / l_first.max(1e-9);
            let series = points
                .iter()
                .map(|(n, s, l)| format!("N={n}: {l:.2} MB/s (x{:.1}; transport counters {s:.2})", growth(*l)))
                .collect::<Vec<_>>()
                .join(", ");
            let flat_until = points.iter().take_while(|(_, _, l)| growth(*l) < 1.5).last().map_or(n_first, |p| p.0);
            let multicast =
                if r.provenance.network.contains("multicast on") { "multicast on" } else { "multicast off" };
            let verdict = if flat_until == n_hi {
                format!("holds on loopback ({multicast})")
            } else if flat_until > n_first {
                format!(
                    "holds up to N={flat_until} ({multicast}), not beyond: see the latency and CPU tables for what \
                     happens at larger N"
                )
            } else {
                format!("does not hold ({multicast}): loopback traffic grows with N")
            };
            let _ = writeln!(
                md,
                "| bandwidth constant in the number of agents (multicast) | DSR_d paper | {bw_link}, {log_name}, loopback \
                 tx (OS, the report's network namespace) per N: {series} | {verdict} |"
            );
        }
        _ => {
            let _ = writeln!(
                md,
                "| bandwidth constant in the number of agents (multicast) | DSR_d paper | no RTPS runs in this set | \
                 not tested (the in-process bus hands one copy to all receivers: constant by construction) |"
            );
        }
    }
    let image_at = |size: usize| {
        r.set.payload.sizes.iter().position(|&s| s == size).and_then(|i| r.payload.get(i)).map(|x| x.latency)
    };
    if let Some(l) = image_at(360_960) {
        let _ = writeln!(
            md,
            "| one-way latency, 360,960 B attribute at 20 Hz: N=1 reader p50 1.0–1.2 ms, p99 1.5–2.9 ms; N=6 p50 \
             2.0–2.2 ms, p99 5.1–5.9 ms | C++ (FastDDS, separate processes), measured elsewhere (FACTS.md) | \
             360,960 B at {} Hz to {} receivers over {}: p50 {:.3} ms, p99 {:.3} ms | {} |",
            r.set.payload.rate_hz,
            r.set.payload.agents - 1,
            r.set.payload.transport,
            ms(l.p50_ns),
            ms(l.p99_ns),
            if r.set.payload.transport == "rtps-processes" {
                "comparable setting (separate processes on loopback), other DDS implementation and machine load"
            } else {
                "not comparable (one process here, FastDDS processes there)"
            }
        );
    }
    let _ = writeln!(
        md,
        "| bandwidth flat in N: 7.26 MB/s at N=1, 7.28 MB/s at N=6 (control traffic 1.5→40 KB/s) | C++ (FastDDS), \
         measured elsewhere (FACTS.md) | see the row above | compare the shape, not the values (other log) |"
    );
    let _ = writeln!(
        md,
        "| wire cost of one small attribute update: ~443 B at 100 Hz | C++ (FastDDS), measured elsewhere (FACTS.md) | \
         mean sample size of the Husky log (small updates): {} | sample size (delta + 8 B) without RTPS, UDP and IP headers |\n",
        r.replay
            .iter()
            .find(|x| x.workload.starts_with("husky"))
            .map_or_else(|| "—".to_owned(), |x| format!("{:.0} B", x.sample_bytes as f64 / x.writes.max(1) as f64))
    );

    // Latency.
    let _ = writeln!(md, "{}\n", SECTIONS[2]);
    figure(&mut md, FIGURES[0], "latency CDFs by number of agents");
    let _ = writeln!(md, "Every log and seed, per payload class (pairs of write and receiver):\n");
    let _ = writeln!(md, "| log (transport) | N | seed | class | {PCT_HEAD} |\n|---|---:|---:|---|{PCT_RULE}|");
    for run in &r.replay {
        for (class, p) in &run.latency_by_class {
            let _ =
                writeln!(md, "| {} | {} | {} | {} | {} |", label(run), run.agents, run.seed, class.name(), pct_row(p));
        }
    }
    let _ = writeln!(md);

    // Payload.
    let _ = writeln!(md, "{}\n", SECTIONS[3]);
    figure(&mut md, FIGURES[1], "latency against payload size");
    let _ = writeln!(md, "Transport: {}.\n", link_description(&r.set.payload.transport));
    let _ = writeln!(md, "| bytes | {PCT_HEAD} |\n|---:|{PCT_RULE}|");
    for (size, run) in r.set.payload.sizes.iter().zip(&r.payload) {
        let _ = writeln!(md, "| {size} | {} |", pct_row(&run.latency));
    }
    let _ = writeln!(md);

    // Bandwidth.
    let _ = writeln!(md, "{}\n", SECTIONS[4]);
    figure(&mut md, FIGURES[2], "bandwidth against number of agents");
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
            b.wire_bytes_per_second / 1e6,
            b.received_bytes_per_second / 1e6,
            b.received_bytes_per_second / 1e6 / f64::from(run.agents - 1),
            b.loopback_tx_bytes.map_or_else(|| "unreadable".to_owned(), |v| v.to_string()),
            b.dropped_full
        );
    }
    let _ = writeln!(md);

    // Convergence.
    let _ = writeln!(md, "{}\n", SECTIONS[5]);
    figure(&mut md, FIGURES[3], "convergence windows with and without faults");
    let _ = writeln!(
        md,
        "Per write: the time until every replica reflects it. After the replay ends: the time from the last write to \
         the last application anywhere, when every receiver then has the source's digest.\n"
    );
    let _ = writeln!(
        md,
        "| run | N | per-write {PCT_HEAD} | end of replay ms | digests equal | duplicates injected |\n|---|---:|{PCT_RULE}|---:|---|---:|"
    );
    let end = |x: &RunResult| x.end_convergence_ns.map_or_else(|| "never".to_owned(), |ns| format!("{:.3}", ms(ns)));
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
            x.reconverge_ns.map_or_else(|| "not within the timeout".to_owned(), |ns| format!("{:.1}", ms(ns)))
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
                ms(times[times.len() / 2]),
                ms(*first),
                ms(*last),
                times.len()
            );
        }
    }
    let _ = writeln!(md);

    // CPU.
    let _ = writeln!(md, "{}\n", SECTIONS[6]);
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
    let mib = |v: u64| format!("{:.0}", v as f64 / (1u64 << 20) as f64);
    for x in r.replay.iter().chain(r.payload.iter()).chain(r.faults.iter().map(|f| &f.run)) {
        let receivers = || x.agent_costs.iter().filter(|c| c.agent != 1);
        let cpus: Vec<u64> = receivers().filter_map(|c| c.cpu_ns).collect();
        let mean = cpus.iter().sum::<u64>() as f64 / cpus.len().max(1) as f64;
        let own_rss = receivers().filter(|c| c.kind == "process").filter_map(|c| c.peak_rss_bytes).max();
        let _ = writeln!(
            md,
            "| {} | {} | {} | {} | {:.1} | {:.1} | {} | {} |",
            label(x),
            x.agents,
            x.seed,
            x.agent_costs.first().and_then(|c| c.cpu_ns).map_or_else(|| "?".to_owned(), |v| format!("{:.1}", ms(v))),
            mean / 1e6,
            100.0 * mean / 1e9 / x.publish_seconds.max(1e-3),
            own_rss.map_or_else(|| "shared".to_owned(), mib),
            x.process_peak_rss_bytes.map_or_else(|| "?".to_owned(), mib)
        );
    }
    let _ = writeln!(md);

    crate::timeline::section(&mut md, r.timeline.as_ref());
    crate::roles::section(&mut md, r.set.roles.as_ref(), r.roles.as_ref());

    let _ = writeln!(md, "{}\n", SECTIONS[7]);
    let _ = writeln!(
        md,
        "- The full agent layer (`agent::Agent`: envelope, anti-entropy, lock) on the measured path: receivers apply \
         the source's deltas to a bare `dsr::Replica`.\n\
         - Partitions with agents as separate processes (the partition runs put their agents in one process).\n\
         {}{}",
        if r.roles.is_some() {
            ""
        } else {
            "- BICA statistics of detector roles during a replay (no `roles` section).\n"
        },
        if r.timeline.is_some() { "" } else { "- The scheduler timeline of a detector under an injected overload.\n" }
    );

    let _ = writeln!(md, "{}\n", SECTIONS[8]);
    let _ = writeln!(md, "| file | bytes | sha256 | matches manifest |\n|---|---:|---|---|");
    for d in &p.datasets {
        let matches = match d.matches_manifest() {
            Some(true) => "yes",
            Some(false) => "**no**",
            None => "not listed",
        };
        let _ = writeln!(md, "| {} | {} | `{}` | {matches} |", d.file, d.bytes, d.sha256);
    }

    let _ = writeln!(md, "\n{}\n", SECTIONS[9]);
    let _ = writeln!(
        md,
        "One MCAP file per run, to open in Foxglove (or read with the `mcap` tools): per-write latencies \
         (`/metrics/latency`), convergence windows (`/metrics/convergence`), published bytes per 100 ms \
         (`/metrics/bandwidth`) and the run's summary (`/metrics/summary`), each a JSON-schema channel; times are ns \
         on the run's clock. The graph deltas of a replayed log are recorded by `cortex replay FILE --out DIR`. \
         Together they take {:.0} MB here, so the copy of a report committed to the repository leaves `runs/` out \
         (`.gitignore`): regenerate the report to get them.\n",
        runs.iter().filter_map(|run| std::fs::metadata(out.join(&run.path)).ok()).map(|m| m.len()).sum::<u64>() as f64
            / 1e6
    );
    let _ = writeln!(md, "| run | file | latency messages | convergence messages |\n|---|---|---:|---:|");
    for run in runs {
        let count = |topic: &str| run.counts.get(topic).copied().unwrap_or(0);
        let path = run.path.display();
        let _ = writeln!(
            md,
            "| {} | [`{path}`]({path}) | {} | {} |",
            run.label,
            count(crate::record::Metric::Latency.topic()),
            count(crate::record::Metric::Convergence.topic())
        );
    }
    md
}
