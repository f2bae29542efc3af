//! Issue 22, DDS Security, on real `cortex agent` processes with a test PKI made by `cortex security init`: a
//! secured graph of three agents converges, and a fourth process cannot change it — one with no credentials, one
//! whose identity another CA signed, one whose permissions only let it subscribe, one whose credentials expired —
//! while the three agents' digests stay what they were.

mod common;

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

use common::{Agent, converge, seed_nodes, seed_path, spawn};

const GRAPH: &str = "5ec0000000000001";

/// A fresh directory under the system's temporary directory.
fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("cortex-test-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

/// `cortex security init DIR ARGS...`, which must succeed.
fn pki(dir: &Path, args: &[&str]) {
    let output = Command::new(env!("CARGO_BIN_EXE_cortex"))
        .args(["security", "init"])
        .arg(dir)
        .args(args)
        .output()
        .expect("cortex security init runs");
    assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
}

/// A `cortex agent` that must refuse to start; returns its standard error.
fn refused(args: &[&str]) -> String {
    let output = Command::new(env!("CARGO_BIN_EXE_cortex"))
        .args(["agent", "--json-status", "--state-dir", "none", "--run-for-ms", "8000"])
        .args(args)
        .output()
        .expect("cortex agent runs");
    assert!(!output.status.success(), "the agent ran: {}", String::from_utf8_lossy(&output.stdout));
    String::from_utf8_lossy(&output.stderr).into_owned()
}

/// The digests and node counts of `agents` now.
fn snapshot(agents: &mut [&mut Agent]) -> Vec<(usize, Option<String>)> {
    agents.iter_mut().map(|a| a.latest().map(|s| (s.nodes, s.digest.clone())).expect("a status line")).collect()
}

#[test]
fn a_secured_graph_converges_and_no_process_without_valid_write_credentials_changes_it() {
    let domain = 89;
    let prefix = format!("secure{}", std::process::id());
    let (ours, theirs) = (scratch("pki"), scratch("pki-other"));
    pki(&ours, &["--agents", "agent1,agent2,agent3,late", "--readers", "inspector", "--expired", "late"]);
    pki(&theirs, &["--agents", "agent1"]);
    let credentials = |pki: &Path, name: &str| pki.join(name).to_str().unwrap().to_owned();
    let nodes = seed_nodes();
    let seed = seed_path();
    let secured = |name: &str| {
        ["--graph-id", GRAPH, "--security"].map(str::to_owned).into_iter().chain([credentials(&ours, name)])
    };

    let first: Vec<String> = secured("agent1")
        .chain(["--seed-json", seed.to_str().unwrap(), "--join-wait-ms", "300"].map(str::to_owned))
        .collect();
    let mut a1 = spawn(1, domain, &prefix, &first.iter().map(String::as_str).collect::<Vec<_>>());
    a1.wait_ready_with(nodes);
    let joiner = |name: &str, inserts: &str| -> Vec<String> {
        secured(name).chain(["--insert-nodes", inserts].map(str::to_owned)).collect()
    };
    let (args2, args3) = (joiner("agent2", "4"), joiner("agent3", "5"));
    let mut a2 = common::join(2, domain, &prefix, &args2.iter().map(String::as_str).collect::<Vec<_>>(), nodes);
    let mut a3 = common::join(3, domain, &prefix, &args3.iter().map(String::as_str).collect::<Vec<_>>(), nodes);
    converge(&mut [&mut a1, &mut a2, &mut a3], nodes + 9);
    let before = snapshot(&mut [&mut a1, &mut a2, &mut a3]);

    // Read-only and expired credentials are refused before the process joins, with errors that say why.
    let read_only = refused(&[
        "--id",
        "7",
        "--domain",
        "89",
        "--topic-prefix",
        &prefix,
        "--graph-id",
        GRAPH,
        "--security",
        &credentials(&ours, "inspector"),
        "--insert-nodes",
        "3",
    ]);
    assert!(read_only.contains("Not allowed to create a DataWriter"), "{read_only}");
    let expired =
        refused(&["--id", "8", "--domain", "89", "--topic-prefix", &prefix, "--security", &credentials(&ours, "late")]);
    assert!(expired.contains("expired"), "{expired}");
    let missing = refused(&[
        "--id",
        "9",
        "--domain",
        "89",
        "--topic-prefix",
        &prefix,
        "--security",
        &credentials(&ours, "nobody"),
    ]);
    assert!(missing.contains("is missing"), "{missing}");

    // A process with no credentials, and one whose identity another CA signed, naming the secured graph and writing:
    // neither is matched, so each starts alone and writes to nobody.
    let plain = ["--graph-id", GRAPH, "--join-wait-ms", "1500", "--insert-nodes", "3"];
    let mut intruder = spawn(5, domain, &prefix, &plain);
    let other_ca = credentials(&theirs, "agent1");
    let forged = ["--graph-id", GRAPH, "--security", &other_ca, "--join-wait-ms", "1500", "--insert-nodes", "3"];
    let mut stranger = spawn(6, domain, &prefix, &forged);
    for outsider in [&mut intruder, &mut stranger] {
        outsider.wait_for(
            "ready alone with its 3 nodes",
            Duration::from_secs(30),
            |s| s.ready && s.nodes == 3,
            |_| false,
        );
    }
    // Several announce periods (500 ms) and quiet announces later, nothing of theirs has reached the graph.
    std::thread::sleep(Duration::from_secs(4));
    assert_eq!(snapshot(&mut [&mut a1, &mut a2, &mut a3]), before);
    for agent in [&mut a1, &mut a2, &mut a3] {
        let status = agent.latest().cloned().unwrap();
        assert!(status.peers.iter().all(|p| [1, 2, 3].contains(p)), "agent {} heard {:?}", agent.id, status.peers);
    }
    for outsider in [&mut intruder, &mut stranger] {
        let status = outsider.latest().cloned().unwrap();
        assert!(status.peers.is_empty() && status.nodes == 3, "agent {} reached the graph: {status:?}", outsider.id);
    }
    let _ = std::fs::remove_dir_all(ours);
    let _ = std::fs::remove_dir_all(theirs);
}
