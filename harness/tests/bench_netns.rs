//! `cortex bench fanout`, `cortex bench rtt` and `cortex bench payload` in fresh network namespaces, where the
//! loopback counters count exactly the measurement's traffic. Creating a namespace needs root, `unshare` and `ip`
//! (CI runs `scripts/test.sh` as root); without them these tests print why and skip. Nothing here asserts on speed: only on
//! bytes that must (or must not) have crossed the wire for the samples that were delivered, and on the samples
//! delivered.

use std::process::Command;

use measure::netns::{self, NetnsSetup};
use serde_json::Value;

/// Whether a namespace can be made here; prints why not.
fn namespaces_available() -> bool {
    match netns::probe(NetnsSetup { multicast: true }) {
        Ok(()) => true,
        Err(error) => {
            eprintln!("skipped: cannot create a network namespace: {error}");
            false
        }
    }
}

fn cortex_json(args: &[&str]) -> Value {
    let output = Command::new(env!("CARGO_BIN_EXE_cortex")).args(args).output().expect("cortex runs");
    assert!(
        output.status.success(),
        "cortex {args:?} failed: {}\n{}",
        output.status,
        String::from_utf8_lossy(&output.stderr)
    );
    serde_json::from_slice(&output.stdout).unwrap_or_else(|e| {
        panic!("cortex {args:?} printed no JSON ({e}): {}", String::from_utf8_lossy(&output.stdout))
    })
}

fn number(value: &Value, path: &[&str]) -> f64 {
    let mut at = value;
    for key in path {
        at = &at[*key];
    }
    at.as_f64().unwrap_or_else(|| panic!("no number at {path:?} in {value}"))
}

#[test]
fn multicast_sends_each_sample_once_and_unicast_once_per_reader() {
    if !namespaces_available() {
        return;
    }
    const PAYLOAD: f64 = 50_000.0;
    const FRAMES: f64 = 20.0;
    let report = cortex_json(&[
        "bench",
        "fanout",
        "--readers",
        "1,3",
        "--payload",
        "50000",
        "--rate",
        "50",
        "--frames",
        "20",
        "--multicast",
        "on,off",
        "--netns",
        "require",
        "--json",
    ]);
    assert_eq!(report["netns"], Value::Bool(true), "{report}");
    let runs = report["runs"].as_array().expect("runs");
    assert_eq!(runs.len(), 4, "{report}");
    for run in runs {
        let readers = number(run, &["readers"]);
        let setting = run["multicast_setting"].as_str().expect("setting");
        assert_eq!(number(run, &["delivered_min"]), FRAMES, "every reader gets every sample: {run}");
        let steady_bytes = number(run, &["steady", "tx_bytes"]);
        let multicast_bytes = number(run, &["steady", "tx_multicast_bytes"]);
        // At least one copy of every payload crossed the wire, whatever the mode.
        assert!(steady_bytes >= FRAMES * PAYLOAD, "{run}");
        match setting {
            "on" => {
                assert_eq!(run["multicast"], Value::Bool(true), "lo is multicast-capable in the namespace: {run}");
                assert!(multicast_bytes >= FRAMES * PAYLOAD, "the samples went to the multicast group: {run}");
                if readers == 3.0 {
                    // One shared copy, not one per reader (and not a second copy to the writer's own reader).
                    assert!(steady_bytes < 2.0 * FRAMES * PAYLOAD, "multicast to 3 readers: {run}");
                }
            }
            "off" => {
                assert_eq!(run["multicast"], Value::Bool(false), "{run}");
                assert!(multicast_bytes < FRAMES * PAYLOAD, "unicast mode sent the samples as multicast: {run}");
                // Unicast: every reader needs its own copy.
                assert!(steady_bytes >= readers * FRAMES * PAYLOAD, "unicast to {readers} readers: {run}");
            }
            other => panic!("unexpected multicast setting {other}"),
        }
    }
}

#[test]
fn rtt_in_a_namespace_counts_every_update_with_its_acknowledgements() {
    if !namespaces_available() {
        return;
    }
    const PAYLOAD: f64 = 100.0;
    let report = cortex_json(&[
        "bench",
        "rtt",
        "--payload",
        "100",
        "--rate",
        "200",
        "--count",
        "100",
        "--netns",
        "require",
        "--json",
    ]);
    assert_eq!(report["netns"], Value::Bool(true), "{report}");
    let runs = report["runs"].as_array().expect("runs");
    let deliveries: Vec<&str> = runs.iter().map(|r| r["updates"].as_str().expect("updates")).collect();
    assert_eq!(deliveries, ["reliable", "best-effort"], "{report}");
    for run in runs {
        let reliable = run["updates"] == "reliable";
        for side in ["agent", "raw"] {
            let figures = &run[side];
            let updates = number(figures, &["socket", "updates"]);
            let steady_bytes = number(figures, &["socket", "steady", "tx_bytes"]);
            let steady_packets = number(figures, &["socket", "steady", "tx_packets"]);
            // 100 warm-up and 100 measured pings, each answered unless lost.
            let lost = number(figures, &["lost"]);
            assert!(updates >= 2.0 * (200.0 - lost) && updates <= 400.0, "{side}: {figures}");
            // Every update is at least one IPv4 + UDP datagram carrying its payload...
            assert!(steady_bytes >= updates * (PAYLOAD + 28.0), "{side}: {figures}");
            if reliable {
                // ...reliable delivery adds an acknowledgement per matched reader (the peer's and the writer's own
                // transport's), each sent once: no second copy to another address of the same participant.
                assert!(steady_packets > 2.0 * updates && steady_packets < 3.5 * updates, "{side}: {figures}");
            } else {
                // ...best-effort sends the sample alone; periodic discovery and anti-entropy stay a small share.
                assert!(steady_packets < 1.5 * updates, "{side}: {figures}");
            }
            // A sane bound on the per-update overhead (the C++ reference: ~466 B per small update).
            assert!(number(figures, &["socket", "bytes_per_update"]) < 4096.0, "{side}: {figures}");
            assert!(number(figures, &["socket", "discovery", "tx_bytes"]) > 0.0, "{side}: discovery was counted");
        }
    }
}

#[test]
fn rtt_over_shared_memory_answers_pings_through_threaded_and_app_driven_agents_as_processes() {
    if !namespaces_available() {
        return;
    }
    let report =
        cortex_json(&["bench", "rtt", "--shm", "--updates", "reliable", "--rate", "200", "--count", "100", "--json"]);
    for side in ["shm_agent", "shm_agent_driven", "shm_raw"] {
        let figures = &report[side];
        let (measured, lost) = (number(figures, &["count"]), number(figures, &["lost"]));
        // Every measured ping is answered or counted lost (a pong later than 1 s); over shared memory on one host
        // nearly all are answered, whichever thread takes the pong.
        assert_eq!(measured + lost, 100.0, "{side}: {figures}");
        assert!(measured >= 90.0, "{side}: {figures}");
        assert!(number(figures, &["p50_us"]) > 0.0, "{side}: {figures}");
    }
    // Both agent loops' pings went through the agent's envelope, larger than the raw loop's bare sample.
    let envelope = |side: &str| number(&report[side], &["envelope_bytes_per_update"]);
    assert!(envelope("shm_agent_driven") > envelope("shm_raw") && envelope("shm_agent") > envelope("shm_raw"));
}

#[test]
fn bench_payload_reports_every_cell_and_no_loopback_bytes_through_shared_memory() {
    if !namespaces_available() {
        return;
    }
    let dir = std::env::temp_dir().join(format!("cortex-bench-payload-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let json_path = dir.join("payload.json");
    let json = json_path.to_str().expect("utf-8 path");
    // RTPS first, so the shared-memory cell also shows that nothing of the RTPS session leaks into its window.
    let args = [
        "bench",
        "payload",
        "--sizes",
        "4096",
        "--receivers",
        "1",
        "--count",
        "5",
        "--rate-hz",
        "50",
        "--paths",
        "rtps,shm,transport,iceoryx2",
        "--netns",
        "require",
        "--json",
        json,
    ];
    let output = Command::new(env!("CARGO_BIN_EXE_cortex")).args(args).output().expect("cortex runs");
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert!(output.status.success(), "{}\n{stdout}\n{}", output.status, String::from_utf8_lossy(&output.stderr));
    let report: Value = serde_json::from_slice(&std::fs::read(&json_path).expect("the JSON file")).expect("JSON");
    let _ = std::fs::remove_dir_all(&dir);

    assert_eq!(report["netns"], Value::Bool(true), "{report}");
    let cells = report["cells"].as_array().expect("cells");
    let paths: Vec<&str> = cells.iter().map(|c| c["path"].as_str().expect("path")).collect();
    assert_eq!(paths, ["rtps", "shm", "transport", "iceoryx2"], "one cell per path, in the order asked: {report}");
    for cell in cells {
        assert_eq!((number(cell, &["size_bytes"]), number(cell, &["receivers"])), (4096.0, 1.0), "{cell}");
        assert_eq!(number(cell, &["expected"]), 5.0, "{cell}");
        let delivered = number(cell, &["latency", "count"]);
        assert!((1.0..=5.0).contains(&delivered), "{cell}");
        assert!(number(cell, &["latency", "p50_ns"]) <= number(cell, &["latency", "max_ns"]), "{cell}");
        assert!(number(cell, &["cpu_ns_per_sample"]) >= 0.0, "{cell}");
        let above = cell["path"] != "iceoryx2";
        assert_eq!(cell["to_iceoryx2"].is_object(), above, "cells above raw iceoryx2 carry ratios to it: {cell}");
    }
    // At least one copy of every RTPS sample crossed the loopback; not one byte through shared memory.
    assert!(number(&cells[0], &["loopback_bytes_per_sample"]) >= 4096.0, "{report}");
    assert_eq!(number(&cells[1], &["loopback_bytes_per_sample"]), 0.0, "{report}");
    assert_eq!(number(&cells[2], &["loopback_bytes_per_sample"]), 0.0, "{report}");
    assert_eq!(number(&cells[3], &["loopback_bytes_per_sample"]), 0.0, "{report}");
    // The table: a heading, a header and a row per cell, with every column.
    let lines: Vec<&str> = stdout.lines().collect();
    assert!(lines[0].starts_with("payload paths:") && lines[1].contains("loopback B/sample"), "{stdout}");
    for (line, label) in lines[2..6].iter().zip(["agents, rtps", "agents, shm", "shm transport", "raw iceoryx2"]) {
        assert!(line.contains(label) && line.contains("/5"), "{stdout}");
        // 13 columns; the path's label is two words.
        assert_eq!(line.split_whitespace().count(), 14, "{line}");
    }
}
