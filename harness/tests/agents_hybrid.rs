//! `cortex agent` processes on the default transport, RTPS with same-host shared memory (`transport::hybrid`,
//! issue 20): agents of one host find each other on the lanes and move their samples through them, through a late
//! join, a kill and restart, and a pause; an agent in another network namespace is another host, reached by RTPS
//! alone, while the pair beside it keeps its lanes. Claims on status lines (nodes, digests, same-host peers,
//! samples through shared memory), never on speed.
//!
//! The second test needs root and `ip` (CI runs `scripts/test.sh` as root) to make two network namespaces joined by
//! a veth pair; without them it prints why and skips.

mod common;

use std::process::Command;
use std::time::Duration;

use common::{
    Agent, converge, converge_at_least, join, pause, seed_nodes, seed_path, signal, spawn_in, spawn_seeded, workspace,
};

/// Waits until `agent` knows `peers` same-host peers and has taken samples from the lanes.
fn wait_on_lanes(agent: &mut Agent, peers: u64) {
    agent.wait_for(
        &format!("{peers} same-host peer(s) and samples through shared memory"),
        Duration::from_secs(30),
        |s| s.same_host_peers == peers && s.shm_samples_received > 0,
        |_| false,
    );
}

#[test]
fn same_host_agents_move_their_samples_through_shared_memory_through_a_join_a_kill_and_a_pause() {
    let prefix = format!("hybrid_a{}", std::process::id());
    let domain = 97;
    let nodes = seed_nodes();
    let mut seeded = spawn_seeded(domain, &prefix);
    seeded.wait_ready_with(nodes);

    let mut joiner = join(7, domain, &prefix, &["--insert-nodes", "3"], nodes);
    converge(&mut [&mut seeded, &mut joiner], nodes + 3);
    wait_on_lanes(&mut seeded, 1);
    wait_on_lanes(&mut joiner, 1);

    // Killed without closing its ports; its new life finds the lanes again (the dead life's ports reclaimed).
    signal(&joiner.child, "KILL");
    let _ = joiner.child.wait();
    let mut again = join(7, domain, &prefix, &[], nodes + 3);
    converge(&mut [&mut seeded, &mut again], nodes + 3);
    wait_on_lanes(&mut again, 1);

    // Paused long enough to be forgotten as a same-host peer (3 s), then back; a new writer's nodes reach it.
    pause(&seeded, Duration::from_secs(4));
    let mut writer = join(8, domain, &prefix, &["--insert-nodes", "2"], nodes + 3);
    converge(&mut [&mut seeded, &mut again, &mut writer], nodes + 5);
    wait_on_lanes(&mut writer, 2);
    wait_on_lanes(&mut seeded, 2);
}

/// Camera frames (360,960 B, above the lanes' lease size) are taken in place by the receivers: their writer is
/// killed while its frames are leased, a receiver is paused while the writer's next life streams, and every agent
/// still converges, with nothing refused and no receiver lost.
#[test]
fn camera_frames_taken_in_place_survive_their_writers_kill_and_a_paused_receiver() {
    let prefix = format!("hybrid_c{}", std::process::id());
    let domain = 84;
    let nodes = seed_nodes();
    let mut seeded = spawn_seeded(domain, &prefix);
    seeded.wait_ready_with(nodes);
    let mut reader = join(3, domain, &prefix, &[], nodes);
    let log = workspace().join("datasets/logs/euroc_v1_01_easy_cam0_1s.mcap");
    let log = log.to_str().unwrap();
    let mut writer = join(2, domain, &prefix, &["--role", "bridge", "--log", log, "--loops", "50"], nodes);
    // Frames reach the receivers through the lanes, are taken in place, and are decoded in place (no copy on receipt).
    let streaming = |s: &agent::StatusLine| s.shm_samples_leased > 20 && s.large_values_shared > 20 && s.nodes > nodes;
    reader.wait_for("frames through shared memory", Duration::from_secs(30), streaming, |_| false);
    let frames = seeded.wait_for("frames through shared memory", Duration::from_secs(30), streaming, |_| false);

    // Killed while the receivers hold its frames; a receiver paused while the writer's next life streams.
    signal(&writer.child, "KILL");
    let _ = writer.child.wait();
    signal(&reader.child, "STOP");
    let mut again = join(2, domain, &prefix, &["--role", "bridge", "--log", log, "--loops", "3"], frames.nodes);
    again.wait_for("frames written", Duration::from_secs(30), |s| s.shm_samples_sent > 20, |_| false);
    signal(&reader.child, "CONT");
    converge(&mut [&mut seeded, &mut reader, &mut again], frames.nodes);
}

/// Two network namespaces joined by a veth pair, deleted when dropped.
struct Namespaces {
    names: [String; 2],
}

impl Namespaces {
    fn create() -> Result<Self, String> {
        let tag = std::process::id();
        let names = [format!("cxhy{tag}a"), format!("cxhy{tag}b")];
        let made = Namespaces { names: names.clone() };
        let [a, b] = [names[0].as_str(), names[1].as_str()];
        let (va, vb) = (format!("vh{tag}a"), format!("vh{tag}b"));
        let steps: Vec<Vec<&str>> = vec![
            vec!["netns", "add", a],
            vec!["netns", "add", b],
            vec!["link", "add", &va, "netns", a, "type", "veth", "peer", "name", &vb, "netns", b],
            vec!["-n", a, "addr", "add", "10.78.0.1/24", "dev", &va],
            vec!["-n", b, "addr", "add", "10.78.0.2/24", "dev", &vb],
            vec!["-n", a, "link", "set", &va, "up"],
            vec!["-n", b, "link", "set", &vb, "up"],
            vec!["-n", a, "link", "set", "lo", "up"],
            vec!["-n", b, "link", "set", "lo", "up"],
            vec!["-n", a, "route", "add", "224.0.0.0/4", "dev", &va],
            vec!["-n", b, "route", "add", "224.0.0.0/4", "dev", &vb],
        ];
        for step in steps {
            let output = Command::new("ip").args(&step).output().map_err(|e| format!("ip {step:?}: {e}"))?;
            if !output.status.success() {
                return Err(format!("ip {step:?}: {}", String::from_utf8_lossy(&output.stderr).trim()));
            }
        }
        Ok(made)
    }
}

impl Drop for Namespaces {
    fn drop(&mut self) {
        for name in &self.names {
            let _ = Command::new("ip").args(["netns", "del", name]).output();
        }
    }
}

#[test]
fn an_agent_in_another_network_namespace_is_reached_by_rtps_while_a_same_host_pair_keeps_its_lanes() {
    let namespaces = match Namespaces::create() {
        Ok(namespaces) => namespaces,
        Err(error) => {
            eprintln!("skipped: cannot create two network namespaces (needs root and iproute2): {error}");
            return;
        }
    };
    let [a, b] = [Some(namespaces.names[0].as_str()), Some(namespaces.names[1].as_str())];
    let prefix = format!("hybrid_b{}", std::process::id());
    let domain = 98;
    let nodes = seed_nodes();
    let seed = seed_path();
    let mut alone = spawn_in(a, 5, domain, &prefix, &["--seed-json", seed.to_str().unwrap(), "--join-wait-ms", "300"]);
    alone.wait_ready_with(nodes);
    let joiner = |id: u32, inserts: &str| {
        let mut agent = spawn_in(b, id, domain, &prefix, &["--join-wait-ms", "20000", "--insert-nodes", inserts]);
        agent.wait_for(
            "joined",
            Duration::from_secs(30),
            |s| s.ready && s.nodes >= nodes,
            |s| s.ready && s.nodes < nodes,
        );
        agent
    };
    let mut first = joiner(6, "3");
    let mut second = joiner(7, "2");
    converge(&mut [&mut alone, &mut first, &mut second], nodes + 5);
    wait_on_lanes(&mut first, 1);
    wait_on_lanes(&mut second, 1);
    let status = alone.latest().cloned().expect("a status line");
    assert_eq!(status.same_host_peers, 0, "the other namespace is another host: {status:?}");
    assert_eq!(status.shm_samples_received, 0, "nothing reaches another host by shared memory: {status:?}");
    assert!(status.samples_received > 0, "the pair's deltas reach it by RTPS: {status:?}");

    // The pair loses one of its own; its new life finds the lanes and the other host again, and streams camera
    // frames: each a delta in pieces, copied into the lane for its same-host peer and joined into one buffer for
    // RTPS, which the other host needs.
    let before = alone.latest().cloned().expect("a status line").samples_received;
    signal(&second.child, "KILL");
    let _ = second.child.wait();
    let log = workspace().join("datasets/logs/euroc_v1_01_easy_cam0_1s.mcap");
    let bridge = ["--join-wait-ms", "20000", "--role", "bridge", "--log", log.to_str().unwrap(), "--loops", "3"];
    let mut again = spawn_in(b, 7, domain, &prefix, &bridge);
    // Its joining alone can send 20 samples through the lane before the log's first frame, so it has streamed once
    // its graph holds nodes of the log. Those come in more than one write (CI saw the agents agree on 27 nodes while
    // the bridge's status had shown 26): the agents converge on what the bridge has at least.
    let through_lane = |s: &agent::StatusLine| s.ready && s.shm_samples_sent > 20 && s.nodes > nodes + 5;
    let streamed = again.wait_for("frames through the lane", Duration::from_secs(30), through_lane, |_| false);
    converge_at_least(&mut [&mut alone, &mut first, &mut again], streamed.nodes);
    wait_on_lanes(&mut again, 1);
    // Everything reached the other host by RTPS, its only path (as written or, for what a fault lost, repaired:
    // this test does not tell the two apart; transport/tests/hybrid.rs checks that pieces go by both paths). The
    // agents agree on nodes while the bridge still streams frames (in one CI run the count then was short of it),
    // so the count is waited for, not read at once; a sample through shared memory fails at once (and `wait_for`
    // fails on any rejected sample).
    alone.wait_for(
        "the stream reached the other host by RTPS",
        Duration::from_secs(30),
        |s| s.samples_received >= before + 60,
        |s| s.shm_samples_received > 0,
    );
}
