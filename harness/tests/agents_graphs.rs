//! Issue 22, graph identity, on real `cortex agent` processes: two graphs on one DDS domain and topic prefix never
//! merge. Agents 1 (seeded, creating graph A with `--graph-id`) and 2 (naming no graph, so it takes the graph it
//! joins) form graph A; agent 3 creates graph B on the same domain and prefix and writes into it. A's agents
//! converge on A's nodes alone, B's writes never reach them, and every agent reports the other graph as foreign.

mod common;

use std::time::Duration;

use common::{converge, seed_nodes, seed_path, spawn};

const GRAPH_A: &str = "00000000000000aa";
const GRAPH_B: &str = "00000000000000bb";

#[test]
fn an_agent_of_another_graph_on_the_same_domain_and_prefix_is_refused_and_never_merged() {
    let domain = 88;
    let prefix = format!("graphs{}", std::process::id());
    let nodes = seed_nodes();
    let seed = seed_path();
    let mut a1 = spawn(
        1,
        domain,
        &prefix,
        &["--graph-id", GRAPH_A, "--seed-json", seed.to_str().unwrap(), "--join-wait-ms", "300"],
    );
    a1.wait_ready_with(nodes);
    // Agent 2 names no graph: it takes A's, the only one running, and writes into it.
    let mut a2 = common::join(2, domain, &prefix, &["--insert-nodes", "4"], nodes);
    // Agent 3 creates graph B alone (it names B, so A's agents never answer it) and writes 6 nodes into it.
    let mut b3 = spawn(3, domain, &prefix, &["--graph-id", GRAPH_B, "--join-wait-ms", "1500", "--insert-nodes", "6"]);
    let b_status =
        b3.wait_for("graph B ready with its 6 nodes", Duration::from_secs(30), |s| s.ready && s.nodes == 6, |_| false);
    assert_eq!(b_status.graph.map(|g| g.to_string()).as_deref(), Some(GRAPH_B));
    converge(&mut [&mut a1, &mut a2], nodes + 4);
    // Both graphs have announced to each other by now (every 500 ms): each side has refused the other.
    let refused = |s: &agent::StatusLine, foreign: &str| {
        s.foreign_refused > 0 && s.foreign_graphs.iter().map(ToString::to_string).collect::<Vec<_>>() == [foreign]
    };
    let within = Duration::from_secs(30);
    let a1_status = a1.wait_for("graph B refused", within, |s| refused(s, GRAPH_B), |s| s.nodes != nodes + 4);
    let a2_status = a2.wait_for("graph B refused", within, |s| refused(s, GRAPH_B), |s| s.nodes != nodes + 4);
    let b_status = b3.wait_for("graph A refused", within, |s| refused(s, GRAPH_A), |s| s.nodes != 6);
    assert_eq!(a2_status.graph.map(|g| g.to_string()).as_deref(), Some(GRAPH_A), "the joiner took graph A");
    assert_eq!(a1_status.digest, a2_status.digest);
    // B writes more; A's graph does not move.
    drop(b3);
    let mut b3 = spawn(3, domain, &prefix, &["--graph-id", GRAPH_B, "--join-wait-ms", "1500", "--insert-nodes", "5"]);
    b3.wait_for("graph B ready again", within, |s| s.ready && s.nodes >= 5, |_| false);
    std::thread::sleep(Duration::from_secs(2));
    for agent in [&mut a1, &mut a2] {
        let status = agent.latest().cloned().expect("a status line");
        assert_eq!((status.nodes, &status.digest), (nodes + 4, &a1_status.digest), "agent {}", agent.id);
        assert!(!status.peers.contains(&3), "agent {} counts agent 3 of graph B as a peer: {status:?}", agent.id);
    }
    assert_eq!(b_status.peers, Vec::<u32>::new());
}
