//! `cortex bench fanout` and `cortex bench rtt` in fresh network namespaces, where the loopback counters count
//! exactly the measurement's traffic. Creating a namespace needs root, `unshare` and `ip` (CI runs
//! `scripts/test.sh` as root); without them these tests print why and skip. Nothing here asserts on speed: only on
//! bytes that must (or must not) have crossed the wire for the samples that were delivered.

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
