//! Issue 14, failure 2, on real `cortex agent` processes: an agent restarted while no peer is reachable must not
//! take the replica id of its previous life, whose operations a paused peer still holds; when that peer resumes,
//! the two graphs meet. Each life records its incarnation in the state directory before it writes. Also an agent
//! killed with SIGKILL and restarted while a peer runs: its new life joins the peer's graph under a new replica id.
//! And an agent killed for good is forgotten by its peer (it no longer stretches the peer's announce interval),
//! and counts again when it comes back.
//!
//! Before the fix the second life took replica 4098 again: its new dots collided with the first life's, which the
//! paused agent held, and after `SIGCONT` the two digests never met.

mod common;

use std::time::Duration;

use agent::StatusLine;
use common::{Agent, converge, seed_nodes, signal, spawn, spawn_seeded};

/// Waits until `agent` is ready with at least `nodes` nodes; returns its replica id.
fn ready_replica(agent: &mut Agent, nodes: usize) -> u32 {
    let status = agent.wait_for(
        &format!("ready with at least {nodes} nodes"),
        Duration::from_secs(30),
        |s| s.ready && s.nodes >= nodes,
        |_| false,
    );
    status.replica.expect("a ready agent has a replica id")
}

/// Agent 2 writes 3 nodes into the seeded agent's graph and stops; the seeded agent is paused; `restarts` lives of
/// agent 2 start alone one after the other (each killed before the next, the last one kept), each writing 5
/// nodes; the seeded agent resumes and meets the last life. Returns the replica ids of agent 2's lives.
fn restart_alone_while_the_peer_is_paused(domain: u16, restarts: u32) -> Vec<u32> {
    let prefix = format!("restart{}d{domain}", std::process::id());
    let nodes = seed_nodes();
    let mut seeded = spawn_seeded(domain, &prefix);
    seeded.wait_ready_with(nodes);

    let mut first = spawn(2, domain, &prefix, &["--join-wait-ms", "20000", "--insert-nodes", "3"]);
    let mut replicas = vec![ready_replica(&mut first, nodes + 3)];
    converge(&mut [&mut seeded, &mut first], nodes + 3);
    drop(first);

    signal(&seeded.child, "STOP");
    let mut last = None;
    for _ in 0..restarts {
        // Nobody answers: the new life starts alone and writes 5 nodes.
        drop(last.take());
        let mut life = spawn(2, domain, &prefix, &["--join-wait-ms", "1500", "--insert-nodes", "5"]);
        replicas.push(ready_replica(&mut life, 5));
        last = Some(life);
    }
    signal(&seeded.child, "CONT");
    // The seed, the first life's nodes and the last life's (a life in between wrote to nobody before it was
    // killed); `converge` also fails on any id collision either agent reports.
    let mut life = last.expect("at least one restart");
    converge(&mut [&mut seeded, &mut life], nodes + 3 + 5);
    replicas
}

#[test]
fn a_restart_while_alone_takes_a_new_replica_id_and_the_graphs_meet() {
    let replicas = restart_alone_while_the_peer_is_paused(81, 1);
    assert_ne!(replicas[0], replicas[1], "the second life reused the first life's replica id");
}

#[test]
fn two_restarts_in_a_row_while_alone_take_three_replica_ids() {
    let replicas = restart_alone_while_the_peer_is_paused(82, 2);
    let distinct: std::collections::BTreeSet<_> = replicas.iter().collect();
    assert_eq!(distinct.len(), 3, "replica ids of the lives: {replicas:?}");
}

/// The seeded agent is killed with SIGKILL after a peer wrote into its graph, and restarted with the same seed: its
/// new life takes the running graph from the peer (not its seed alone), under a new replica id, and what it writes
/// reaches the peer.
#[test]
fn an_agent_killed_and_restarted_rejoins_the_running_graph_under_a_new_id() {
    let (domain, prefix) = (83, format!("restart{}d83", std::process::id()));
    let nodes = seed_nodes();
    let mut seeded = spawn_seeded(domain, &prefix);
    let before = ready_replica(&mut seeded, nodes);
    let mut peer = spawn(6, domain, &prefix, &["--join-wait-ms", "20000", "--insert-nodes", "3"]);
    ready_replica(&mut peer, nodes + 3);
    converge(&mut [&mut seeded, &mut peer], nodes + 3);

    signal(&seeded.child, "KILL");
    drop(seeded);
    let seed = common::seed_path();
    let args = ["--seed-json", seed.to_str().unwrap(), "--join-wait-ms", "20000", "--insert-nodes", "2"];
    let mut again = spawn(5, domain, &prefix, &args);
    let after = ready_replica(&mut again, nodes + 3);
    assert_ne!(before, after, "the restarted life reused replica {before}");
    converge(&mut [&mut again, &mut peer], nodes + 3 + 2);
}

/// Agent 6 joins the seeded agent 5, is killed with SIGKILL and stays down: agent 5 stops listing it among its peers
/// once it has been silent for four announce intervals (2 s with the default 500 ms period), and lists it again
/// when it comes back. Before, an agent kept every peer it had ever heard, and each stretched its announce interval.
#[test]
fn an_agent_killed_for_good_is_forgotten_by_its_peer_and_counts_again_when_it_returns() {
    let (domain, prefix) = (72, format!("forget{}d72", std::process::id()));
    let nodes = seed_nodes();
    let mut seeded = spawn_seeded(domain, &prefix);
    ready_replica(&mut seeded, nodes);
    let peer = common::join(6, domain, &prefix, &[], nodes);
    let hears = |ids: &'static [u32]| move |s: &StatusLine| s.peers == ids;
    seeded.wait_for("hears agent 6", Duration::from_secs(30), hears(&[6]), |_| false);

    signal(&peer.child, "KILL");
    drop(peer);
    seeded.wait_for("forgot agent 6", Duration::from_secs(30), hears(&[]), |_| false);

    let _back = common::join(6, domain, &prefix, &[], nodes);
    seeded.wait_for("hears agent 6 again", Duration::from_secs(30), hears(&[6]), |_| false);
}
