//! `cortex agent --transport shm` processes on one host (issue 20): agents that move every sample through iceoryx2
//! shared memory converge, a late joiner gets the graph, an agent killed with SIGKILL comes back as a new life and
//! converges again, and an agent paused with SIGSTOP/SIGCONT keeps up. Claims on status lines (nodes, digests,
//! samples received), never on speed. Each test uses its own topic prefix, so its services are its own.

mod common;

use std::time::Duration;

use common::{converge, join, pause, seed_nodes, signal, spawn_seeded_with};

const SHM: [&str; 2] = ["--transport", "shm"];

/// Agent 5 over shared memory, seeded with the bundled graph and ready; with the graph's node count.
fn seeded_agent(domain: u16, prefix: &str) -> (common::Agent, usize) {
    let nodes = seed_nodes();
    let mut seeded = spawn_seeded_with(domain, prefix, &SHM);
    seeded.wait_ready_with(nodes);
    (seeded, nodes)
}

#[test]
fn agents_over_shared_memory_converge_after_a_late_join_a_kill_and_restart_and_a_pause() {
    let prefix = format!("shm_a{}", std::process::id());
    let domain = 95;
    let (mut seeded, nodes) = seeded_agent(domain, &prefix);

    // A late joiner gets the graph (from shared memory: the only path these agents have) and writes.
    let mut joiner = join(7, domain, &prefix, &[&SHM[..], &["--insert-nodes", "3"]].concat(), nodes);
    converge(&mut [&mut seeded, &mut joiner], nodes + 3);
    assert!(joiner.samples_received() > 0 && seeded.samples_received() > 0);

    // Killed without a chance to close its ports, then a new life of the same id joins (its node names are
    // taken by its first life's writes, so it writes nothing itself).
    signal(&joiner.child, "KILL");
    let _ = joiner.child.wait();
    let mut again = join(7, domain, &prefix, &SHM, nodes + 3);
    converge(&mut [&mut seeded, &mut again], nodes + 3);

    // The seeded agent is paused; what a new writer writes meanwhile and after reaches it and the new life.
    pause(&seeded, Duration::from_secs(2));
    let mut writer = join(8, domain, &prefix, &[&SHM[..], &["--insert-nodes", "2"]].concat(), nodes + 3);
    converge(&mut [&mut seeded, &mut again, &mut writer], nodes + 5);
}

/// Losses and duplicates on the shared-memory path (the seeded fault injector on what the joiner receives) are
/// repaired by the anti-entropy as on RTPS: the anti-entropy does not care which path a delta took.
#[test]
fn agents_over_shared_memory_converge_through_injected_loss_and_duplication() {
    let prefix = format!("shm_b{}", std::process::id());
    let domain = 96;
    let (mut seeded, nodes) = seeded_agent(domain, &prefix);
    let faults = ["--faults", "loss=0.3,duplicate=0.2"];
    let mut lossy = join(7, domain, &prefix, &[&SHM[..], &faults[..], &["--insert-nodes", "5"]].concat(), nodes);
    let mut writer = join(8, domain, &prefix, &[&SHM[..], &["--insert-nodes", "5"]].concat(), nodes);
    converge(&mut [&mut seeded, &mut lossy, &mut writer], nodes + 10);
}
