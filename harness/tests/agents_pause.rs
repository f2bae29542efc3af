//! `cortex agent` processes on loopback over RTPS, one of them stopped with SIGSTOP and resumed with SIGCONT (issue
//! 14). On Linux a thread blocked in `epoll_wait` gets EINTR when its process resumes, even without a signal
//! handler, and `rustdds` 0.15 ends its participants' event loops on any poll error: before the transport
//! rebuilt its participants, a resumed agent was deaf and mute for good — a new agent found nobody and started
//! alone with an empty graph, and a connected peer's samples stopped arriving. Each test uses its own domain and
//! topic prefix, so the tests of this file (and of other files) can run at the same time.

mod common;

use std::time::Duration;

use common::{converge, join, pause, seed_nodes, spawn_seeded};

/// The reported failure: after a 2 s pause of the seeded agent, a new agent must still get its graph.
#[test]
fn a_joiner_gets_the_graph_of_an_agent_that_was_paused() {
    let prefix = format!("pause_a{}", std::process::id());
    let domain = 91;
    let nodes = seed_nodes();
    let mut seeded = spawn_seeded(domain, &prefix);
    seeded.wait_ready_with(nodes);
    pause(&seeded, Duration::from_secs(2));
    let mut joiner = join(7, domain, &prefix, &[], nodes);
    converge(&mut [&mut seeded, &mut joiner], nodes);
}

/// A peer connected before the pause keeps reaching the resumed agent (its announces keep arriving, so the resumed
/// agent's received-sample count keeps growing), and what a new agent writes after the pause reaches both.
#[test]
fn a_connected_peer_keeps_reaching_an_agent_that_was_paused() {
    let prefix = format!("pause_b{}", std::process::id());
    let domain = 92;
    let nodes = seed_nodes();
    let mut seeded = spawn_seeded(domain, &prefix);
    seeded.wait_ready_with(nodes);
    let mut peer = join(6, domain, &prefix, &[], nodes);
    converge(&mut [&mut seeded, &mut peer], nodes);

    pause(&seeded, Duration::from_secs(2));
    // Samples must keep arriving well after the resume, not only the ones queued while it was stopped: the peer
    // announces twice a second, so 30 s without a dozen new samples means the resumed agent is deaf.
    std::thread::sleep(Duration::from_secs(2));
    let _ = seeded.latest();
    let after_resume = seeded.samples_received();
    seeded.wait_for(
        "samples from the connected peer after the resume",
        Duration::from_secs(30),
        |s| s.samples_received >= after_resume + 12,
        |_| false,
    );

    let mut writer = join(8, domain, &prefix, &["--insert-nodes", "5"], nodes);
    converge(&mut [&mut seeded, &mut peer, &mut writer], nodes + 5);
}

/// A long pause, then a second one: the agent recovers from both, and a writer that joins afterwards reaches it.
#[test]
fn an_agent_recovers_from_a_long_pause_and_from_a_second_one() {
    let prefix = format!("pause_c{}", std::process::id());
    let domain = 93;
    let nodes = seed_nodes();
    let mut seeded = spawn_seeded(domain, &prefix);
    seeded.wait_ready_with(nodes);
    pause(&seeded, Duration::from_secs(6));
    std::thread::sleep(Duration::from_secs(2));
    pause(&seeded, Duration::from_secs(2));
    let mut writer = join(7, domain, &prefix, &["--insert-nodes", "3"], nodes);
    converge(&mut [&mut seeded, &mut writer], nodes + 3);
}

/// A joiner stopped while it joins, for longer than its whole join wait (2 s, the default): when it resumes it must
/// still take the running graph, not start alone. Two faults met here: a stop during the transport's build
/// deadlocked `rustdds` (the process hung for good, before printing a status), and a stop during the join wait
/// counted against it, so the resumed joiner started alone at once with a graph of its own, which never merges.
/// Where a stop lands depends on the machine's speed: with the release build on the project's 2-core VM, stops 40–55
/// ms after the spawn met the first (in some runs) and stops 80–120 ms after it the second; the debug build these
/// tests run starts more slowly, so three stops are spread over its start.
#[test]
fn a_joiner_stopped_while_it_joins_takes_the_running_graph_when_it_resumes() {
    let prefix = format!("pause_j{}", std::process::id());
    let domain = 71;
    let nodes = seed_nodes();
    let mut seeded = spawn_seeded(domain, &prefix);
    seeded.wait_ready_with(nodes);
    for (id, stop_after_ms) in [(11, 50), (12, 150), (13, 400)] {
        let mut joiner = common::spawn(id, domain, &prefix, &[]);
        std::thread::sleep(Duration::from_millis(stop_after_ms));
        pause(&joiner, Duration::from_secs(3));
        // A build stuck in rustdds after the stop can take its 10 s timeout, twice at worst, before the join.
        joiner.wait_joined(nodes, Duration::from_secs(60));
    }
}

/// The only running agent stopped for longer than a joiner's whole join wait: the joiner, naming no graph, hears
/// nobody and starts alone, in an unnamed graph of its own, and writes into it. Before unnamed graphs could move,
/// the two graphs refused each other for good once the stopped agent resumed (reproduced on 2026-12-03 with the
/// same steps by hand: 3 of 4 trials of a joiner that heard nothing stayed apart). Now one of the two moves to the
/// other's graph and anti-entropy merges them.
#[test]
fn a_joiner_that_started_alone_while_the_running_agent_was_stopped_merges_with_it_when_it_resumes() {
    let prefix = format!("pause_m{}", std::process::id());
    let domain = 72;
    let nodes = seed_nodes();
    let mut seeded = spawn_seeded(domain, &prefix);
    seeded.wait_ready_with(nodes);
    common::signal(&seeded.child, "STOP");
    let mut joiner = common::spawn(14, domain, &prefix, &["--join-wait-ms", "1000", "--insert-nodes", "3"]);
    let alone = joiner.wait_for(
        "ready alone with its 3 nodes",
        Duration::from_secs(30),
        |s| s.ready && s.nodes == 3,
        |s| s.ready && s.nodes > 3,
    );
    common::signal(&seeded.child, "CONT");
    assert!(alone.alone && !alone.graph_named, "{alone:?}");
    assert_ne!(alone.graph, seeded.latest().and_then(|s| s.graph), "two graphs before the resume");
    converge(&mut [&mut seeded, &mut joiner], nodes + 3);
    let graphs = [seeded.latest().and_then(|s| s.graph), joiner.latest().and_then(|s| s.graph)];
    assert_eq!(graphs[0], graphs[1], "one graph after the merge");
}
