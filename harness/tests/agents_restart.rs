//! Issue 14, failure 2, on real `cortex agent` processes: an agent restarted while no peer is reachable must not
//! take the replica id of its previous life, whose operations a paused peer still holds; when that peer resumes,
//! the two graphs meet. Each life records its incarnation in the state directory before it writes.
//!
//! Before the fix the second life took replica 4098 again: its new dots collided with the first life's, which the
//! paused agent held, and after `SIGCONT` the two digests never met.

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

fn workspace() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// A spawned agent whose status lines arrive on a channel; killed when dropped.
struct Proc {
    child: Child,
    rx: mpsc::Receiver<serde_json::Value>,
}

impl Drop for Proc {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

impl Proc {
    fn spawn(id: u32, domain: u16, prefix: &str, state: &Path, extra: &[&str]) -> Proc {
        let mut child = Command::new(env!("CARGO_BIN_EXE_cortex"))
            .args(["agent", "--id", &id.to_string(), "--domain", &domain.to_string(), "--topic-prefix", prefix])
            .args(["--json-status", "--status-ms", "100", "--state-dir"])
            .arg(state)
            .args(extra)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .expect("cortex agent starts");
        let stdout = child.stdout.take().unwrap();
        let (tx, rx) = mpsc::channel();
        std::thread::spawn(move || {
            for line in BufReader::new(stdout).lines().map_while(Result::ok) {
                if let Ok(value) = serde_json::from_str(&line)
                    && tx.send(value).is_err()
                {
                    return;
                }
            }
        });
        Proc { child, rx }
    }

    /// The first status line that satisfies `done` within `limit`.
    fn until(&self, limit: Duration, done: impl Fn(&serde_json::Value) -> bool) -> serde_json::Value {
        let deadline = Instant::now() + limit;
        loop {
            let status =
                self.rx.recv_timeout(deadline.saturating_duration_since(Instant::now())).expect("a status in time");
            if done(&status) {
                return status;
            }
        }
    }

    /// The latest status line within `wait`, or the one given.
    fn latest(&self, wait: Duration, mut last: serde_json::Value) -> serde_json::Value {
        let deadline = Instant::now() + wait;
        while let Ok(status) = self.rx.recv_timeout(deadline.saturating_duration_since(Instant::now())) {
            last = status;
        }
        last
    }

    fn signal(&self, name: &str) {
        let status = Command::new("kill").args([name, &self.child.id().to_string()]).status().unwrap();
        assert!(status.success(), "kill {name}");
    }
}

fn seed() -> (String, u64) {
    let path = workspace().join("datasets/cortex-graphs/Robot_viriato.json");
    let nodes = dsr::json::parse(&std::fs::read_to_string(&path).unwrap()).unwrap().nodes.len() as u64;
    (path.to_str().unwrap().to_owned(), nodes)
}

/// Runs the scenario with `restarts` lives of agent 2 started alone while agent 1 is paused; returns the replica
/// ids of agent 2's lives.
fn restart_alone_while_the_peer_is_paused(domain: u16, restarts: u32) -> Vec<u64> {
    let state = std::env::temp_dir().join(format!("cortex-restart-{}-{domain}", std::process::id()));
    let prefix = format!("rs{}d{domain}", std::process::id());
    let (seed, seed_nodes) = seed();
    let one = Proc::spawn(1, domain, &prefix, &state, &["--seed-json", &seed, "--join-wait-ms", "1000"]);
    one.until(Duration::from_secs(30), |s| s["ready"] == true);

    // Life 1 of agent 2 joins, writes 3 nodes and stops; agent 1 holds them.
    let first = Proc::spawn(2, domain, &prefix, &state, &["--join-wait-ms", "20000", "--insert-nodes", "3"]);
    let joined =
        first.until(Duration::from_secs(30), |s| s["ready"] == true && s["nodes"].as_u64() == Some(seed_nodes + 3));
    let mut replicas = vec![joined["replica"].as_u64().unwrap()];
    one.until(Duration::from_secs(30), |s| s["nodes"].as_u64() == Some(seed_nodes + 3));
    drop(first);

    one.signal("-STOP");
    let mut lives = Vec::new();
    for restart in 1..=restarts {
        // Nobody answers: the new life starts alone and writes 5 nodes.
        let life = Proc::spawn(2, domain, &prefix, &state, &["--join-wait-ms", "1500", "--insert-nodes", "5"]);
        let status = life.until(Duration::from_secs(30), |s| s["ready"] == true && s["nodes"].as_u64() >= Some(5));
        replicas.push(status["replica"].as_u64().unwrap());
        if restart == restarts {
            lives.push(life);
        }
    }
    one.signal("-CONT");

    // The paused agent and the last life meet: the same digest, the seed, the first life's nodes and the last
    // life's (a life in between wrote to nobody before it was killed).
    let life = lives.pop().unwrap();
    let expected = seed_nodes + 3 + 5;
    let deadline = Instant::now() + Duration::from_secs(60);
    let (mut a, mut b) = (serde_json::Value::Null, serde_json::Value::Null);
    while Instant::now() < deadline {
        a = one.latest(Duration::from_millis(300), a);
        b = life.latest(Duration::from_millis(300), b);
        if a["digest"] == b["digest"] && a["nodes"].as_u64() == Some(expected) && !a["digest"].is_null() {
            break;
        }
    }
    assert_eq!(a["nodes"].as_u64(), Some(expected), "agent 1: {a}\nagent 2: {b}");
    assert_eq!(a["digest"], b["digest"], "agent 1: {a}\nagent 2: {b}");
    assert!(a["collision"].is_null() && b["collision"].is_null(), "agent 1: {a}\nagent 2: {b}");
    drop((one, life));
    let _ = std::fs::remove_dir_all(&state);
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
