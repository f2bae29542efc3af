//! The text output of `cortex bench`: the benchmarks' figures as tables, with how they were counted.

use measure::bench::fanout::{FanoutFigures, FanoutResult};
use measure::bench::join::{JoinBreakdown, JoinResult};
use measure::bench::rtt::RttResult;
use measure::bench::{Counting, loadavg};
use measure::results::ScalingResult;

/// The RTT table: agent and raw loops of every delivery, then the socket-level bytes or why they are missing.
pub(super) fn rtt(result: &RttResult, counting: &Counting) {
    println!(
        "RTT, {} B payload, {} Hz, {} pings, two processes {}, multicast {}",
        result.payload,
        result.rate_hz,
        result.count,
        counting.place(),
        if result.multicast { "on" } else { "off" }
    );
    println!(
        "{:<26} {:>7} {:>7} {:>7} {:>7} {:>5} {:>8} {:>14} {:>12} {:>12} {:>9}",
        "",
        "p50 us",
        "p90 us",
        "p99 us",
        "max us",
        "lost",
        "repairs",
        "envelope B/upd",
        "est. wire B",
        "socket B/upd",
        "pkts/upd"
    );
    for run in &result.runs {
        let secured = run.secured.as_ref().map(|f| ("agent, DDS Security", f));
        for (who, f) in [("agent", &run.agent), ("raw rustdds", &run.raw)].into_iter().chain(secured) {
            let (socket_bytes, packets) = match &f.socket {
                Some(s) => (format!("{:.1}", s.bytes_per_update), format!("{:.2}", s.packets_per_update)),
                None => ("-".into(), "-".into()),
            };
            let repairs = f.gap_requests.map_or("-".into(), |n| n.to_string());
            let name = format!("{who}, {}", run.updates);
            println!(
                "{name:<26} {:>7} {:>7} {:>7} {:>7} {:>5} {repairs:>8} {:>14.1} {:>12.1} {socket_bytes:>12} {packets:>9}",
                f.p50_us, f.p90_us, f.p99_us, f.max_us, f.lost, f.envelope_bytes_per_update, f.wire_bytes_per_update
            );
        }
    }
    let shm = [
        ("agent, shared memory", &result.shm_agent),
        ("agent, shm, app-driven", &result.shm_agent_driven),
        ("raw shared memory", &result.shm_raw),
    ];
    for (who, f) in shm.into_iter().filter_map(|(who, f)| Some((who, f.as_ref()?))) {
        let socket_bytes = f.socket.as_ref().map_or("-".into(), |s| format!("{:.1}", s.bytes_per_update));
        let repairs = f.gap_requests.map_or("-".into(), |n| n.to_string());
        println!(
            "{who:<26} {:>7} {:>7} {:>7} {:>7} {:>5} {repairs:>8} {:>14.1} {:>12} {socket_bytes:>12} {:>9}",
            f.p50_us, f.p90_us, f.p99_us, f.max_us, f.lost, f.envelope_bytes_per_update, "-", "-"
        );
    }
    // The app-driven loop's pinging agent is driven by the bench's own thread (`Agent::pump_wait`).
    let agents = [("agent", &result.shm_agent), ("app-driven agent", &result.shm_agent_driven)];
    for (who, agent) in agents {
        if let (Some(agent), Some(raw)) = (agent, &result.shm_raw) {
            let ratio = agent.p50_us as f64 / raw.p50_us.max(1) as f64;
            println!("shared memory: {who} p50 / raw p50 = {ratio:.2}");
        }
    }
    for run in &result.runs {
        println!("{} updates: agent p50 / raw p50 = {:.2}", run.updates, run.p50_ratio);
        if let (Some(p50), Some(p99), Some(secured)) = (run.secured_p50_ratio, run.secured_p99_ratio, &run.secured) {
            let bytes = |f: &measure::bench::rtt::RttFigures| f.socket.as_ref().map(|s| s.bytes_per_update);
            let socket = match (bytes(secured), bytes(&run.agent)) {
                (Some(s), Some(a)) => format!(", socket B/upd {:.2}x", s / a.max(1.0)),
                _ => String::new(),
            };
            println!(
                "{} updates: protected / unprotected agent: p50 {p50:.2}x, p99 {p99:.2}x{socket} (DDS Security, \
                 submessages encrypted with AES-GCM)",
                run.updates
            );
        }
    }
    match counting {
        Counting::Socket => rtt_socket(result),
        Counting::EstimateOnly(why) => println!("socket-level bytes not measured ({why}); est. wire B is an estimate"),
    }
}

fn rtt_socket(result: &RttResult) {
    for run in &result.runs {
        let secured = run.secured.as_ref().map(|f| ("agent with DDS Security (discovery + handshake + join)", f));
        let loops = [("agent (discovery + join)", &run.agent), ("raw rustdds (discovery)", &run.raw)];
        for (who, f) in loops.into_iter().chain(secured) {
            if let Some(s) = &f.socket {
                println!(
                    "{who}, {}: {} B in {} packets before the first echo; steady state {} B in {} packets \
                     ({} B multicast) for {} updates (pings + pongs)",
                    run.updates,
                    s.discovery.tx_bytes,
                    s.discovery.tx_packets,
                    s.steady.tx_bytes,
                    s.steady.tx_packets,
                    s.steady.tx_multicast_bytes,
                    s.updates
                );
            }
        }
    }
    println!(
        "socket B/upd: loopback tx bytes (IPv4 + UDP + RTPS, acknowledgements, heartbeats, periodic discovery, \
         anti-entropy) in the steady state / updates both ways; est. wire B: the transport's estimate for one \
         sample; repairs: the pinging agent's gap requests"
    );
}

/// The join: in-process snapshot figures, the new process's count, the breakdown and the load average.
pub(super) fn join(result: &JoinResult) {
    println!("join of a {}-node graph (tree, 6 attributes + 1 RT edge per node)", result.nodes);
    println!(
        "  in process: snapshot {} bytes; encode {:.1} ms; encode+decode+join {:.1} ms",
        result.snapshot_bytes, result.snapshot_encode_ms, result.snapshot_encode_decode_join_ms
    );
    println!(
        "  new agent process: {} of {} nodes, {} graph request(s)",
        result.process.nodes, result.nodes, result.process.join_requests
    );
    breakdown(&result.breakdown);
    println!("  load average: {}", loadavg());
}

/// The protected join's total and discovery against the unprotected join's.
pub(super) fn join_ratio(plain: &JoinResult, secured: &JoinResult) {
    let ratio = |a: Option<f64>, b: Option<f64>| match (a, b) {
        (Some(a), Some(b)) if b > 0.0 => format!("{:.2}x", a / b),
        _ => "-".into(),
    };
    println!(
        "protected / unprotected join: total {}, discovery {}, request → ready {}",
        ratio(secured.breakdown.total_ms, plain.breakdown.total_ms),
        ratio(secured.breakdown.discovery_ms, plain.breakdown.discovery_ms),
        ratio(secured.breakdown.request_to_ready_ms, plain.breakdown.request_to_ready_ms)
    );
}

fn breakdown(b: &JoinBreakdown) {
    let show = |v: Option<f64>| v.map_or_else(|| "-".to_owned(), |v| format!("{v:.1} ms"));
    println!("  timeline, from spawning the joining process:");
    for (name, at) in &b.at_ms {
        println!("    {name:<38} {:>10}", show(*at));
    }
    println!("  total (spawn → ready)                  {:>10}", show(b.total_ms));
    println!("  discovery (participant → sync matched) {:>10}", show(b.discovery_ms));
    println!("  request received → ready               {:>10}", show(b.request_to_ready_ms));
    let cached = match b.server_snapshot_cached {
        Some(true) => " (cached)",
        Some(false) => " (encoded)",
        None => "",
    };
    println!("    server snapshot{cached:<11}            {:>10}", show(b.server_encode_ms));
    println!("    server publish                       {:>10}", show(b.server_publish_ms));
    println!("    transfer (encoded → received)        {:>10}", show(b.transfer_ms));
    println!("    decode                               {:>10}", show(b.decode_ms));
    println!("    join                                 {:>10}", show(b.join_ms));
}

/// The fan-out table, one row per run, then how the bytes were counted.
pub(super) fn fanout(result: &FanoutResult, counting: &Counting) {
    for (index, run) in result.runs.iter().enumerate() {
        fanout_row(run, index == 0, result.rate_hz, counting);
    }
    match counting {
        Counting::EstimateOnly(why) => println!("socket-level bytes not measured ({why})"),
        Counting::Socket => println!(
            "bytes: loopback tx (IPv4 + UDP + RTPS, acknowledgements, heartbeats) from the first frame until every \
             reader reported its count, per frame sent; copies = bytes per frame / payload; mcast = share of those \
             bytes sent to a multicast group. Each multicast setting ran in its own namespace (`lo` multicast-capable \
             unless `off`)."
        ),
    }
}

fn fanout_row(run: &FanoutFigures, header: bool, rate: f64, counting: &Counting) {
    if header {
        println!(
            "fan-out: one writer of {} B samples at {rate} Hz, {} samples, to N reader processes {}",
            run.payload_bytes,
            run.frames,
            counting.place()
        );
        println!(
            "{:>9} {:>3} {:>10} {:>12} {:>14} {:>8} {:>7} {:>9} {:>12}",
            "multicast", "N", "delivered", "discovery B", "bytes/frame", "copies", "mcast", "MB/s", "est. B/frame"
        );
    }
    let fmt = |v: Option<f64>, digits: usize| v.map_or_else(|| "-".to_owned(), |v| format!("{v:.digits$}"));
    let mcast_share = run.steady.map(|s| s.tx_multicast_bytes as f64 / s.tx_bytes.max(1) as f64 * 100.0);
    println!(
        "{:>9} {:>3} {:>10} {:>12} {:>14} {:>8} {:>7} {:>9} {:>12}",
        format!("{}{}", run.multicast_setting, if run.multicast { "" } else { "*" }),
        run.readers,
        format!("{}/{}", run.delivered_min, run.frames),
        run.discovery.map_or_else(|| "-".to_owned(), |d| d.tx_bytes.to_string()),
        fmt(run.bytes_per_frame, 0),
        fmt(run.copies_per_frame, 2),
        mcast_share.map_or_else(|| "-".to_owned(), |v| format!("{v:.0}%")),
        fmt(run.megabytes_per_second, 2),
        run.estimated_wire_bytes_per_frame,
    );
}

/// `cortex bench scaling`'s table: per second of the window, envelope bytes.
pub(super) fn scaling(result: &ScalingResult) {
    let e = &result.experiment;
    println!(
        "Seeded simulator, in-process bus: {} writers, {} writes/s, {} ms window, announce every {} ms, announce \
         group {}, seed {}; envelope bytes per second",
        e.writers,
        e.write_rate_hz,
        e.window_ms,
        e.announce_ms,
        if e.announce_group == 0 { "none (every agent every period)".to_owned() } else { e.announce_group.to_string() },
        e.seed
    );
    println!(
        "{:>5} {:>9} {:>12} {:>16} {:>18} {:>16} {:>14} {:>18} {:>9}",
        "N",
        "writes/s",
        "announces/s",
        "control B/s all",
        "control rx/agent",
        "control rx all",
        "data B/s all",
        "data rx/agent",
        "converged"
    );
    for row in &result.rows {
        let r = row.rates();
        println!(
            "{:>5} {:>9.0} {:>12.1} {:>16.0} {:>18.0} {:>16.0} {:>14.0} {:>18.0} {:>9}",
            row.agents,
            r.writes,
            r.announces_sent,
            r.control_bytes_sent,
            r.control_bytes_received_per_agent,
            r.control_bytes_received,
            r.data_bytes_sent,
            r.data_bytes_received_per_agent,
            if row.converged { "yes" } else { "NO" }
        );
    }
}
