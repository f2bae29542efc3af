//! Real `cortex agent` processes for the fault tests (`agents_pause`, `agents_restart`): spawned with JSON status
//! lines read on a channel, signalled (`SIGSTOP`, `SIGCONT`), awaited, and killed when dropped. Each agent keeps
//! its incarnation record in a temporary state directory of its graph (its topic prefix), so restarted lives of a
//! test see their predecessors' records and nothing lands in the user's home.
#![allow(dead_code)]

use std::io::{BufRead, BufReader};
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use agent::StatusLine;

pub fn workspace() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

pub fn seed_path() -> PathBuf {
    workspace().join("datasets/cortex-graphs/Robot_viriato.json")
}

/// Nodes of the seed graph.
pub fn seed_nodes() -> usize {
    dsr::json::parse(&std::fs::read_to_string(seed_path()).unwrap()).unwrap().nodes.len()
}

/// A spawned agent whose JSON status lines arrive on a channel; killed when dropped (also when a test fails).
pub struct Agent {
    pub id: u32,
    pub child: Child,
    status: mpsc::Receiver<StatusLine>,
    /// The latest status line read.
    last: Option<StatusLine>,
}

impl Drop for Agent {
    fn drop(&mut self) {
        // A stopped process must be resumed to die of SIGKILL promptly in every case; SIGKILL works anyway.
        signal(&self.child, "CONT");
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// The state directory of the agents of the graph with topic prefix `prefix` (see the module documentation). The
/// first call of a test process removes the state directories of earlier runs left untouched for an hour (a failed
/// test's is kept that long for a look), so repeated runs do not pile them up in the temporary directory.
pub fn state_dir(prefix: &str) -> PathBuf {
    static SWEEP: std::sync::Once = std::sync::Once::new();
    SWEEP.call_once(|| remove_state_dirs_older_than(Duration::from_secs(3600)));
    std::env::temp_dir().join(format!("{STATE_DIR_PREFIX}{prefix}"))
}

const STATE_DIR_PREFIX: &str = "cortex-test-state-";

fn remove_state_dirs_older_than(age: Duration) {
    let Ok(entries) = std::fs::read_dir(std::env::temp_dir()) else { return };
    for entry in entries.flatten() {
        let stale = entry.file_name().to_string_lossy().starts_with(STATE_DIR_PREFIX)
            && entry.metadata().and_then(|m| m.modified()).is_ok_and(|at| at.elapsed().is_ok_and(|e| e > age));
        if stale {
            let _ = std::fs::remove_dir_all(entry.path());
        }
    }
}

/// Starts agent `id` on `domain` with the topic prefix `prefix`, printing its status every 100 ms.
pub fn spawn(id: u32, domain: u16, prefix: &str, extra: &[&str]) -> Agent {
    spawn_in(None, id, domain, prefix, extra)
}

/// [`spawn`] inside the network namespace `namespace` (`ip netns exec`, which becomes the agent process itself, so
/// signals reach the agent), or in this process's namespace for `None`.
pub fn spawn_in(namespace: Option<&str>, id: u32, domain: u16, prefix: &str, extra: &[&str]) -> Agent {
    let cortex = env!("CARGO_BIN_EXE_cortex");
    let mut command = match namespace {
        Some(namespace) => {
            let mut command = Command::new("ip");
            command.args(["netns", "exec", namespace, cortex]);
            command
        }
        None => Command::new(cortex),
    };
    let mut child = command
        .args(["agent", "--id", &id.to_string(), "--domain", &domain.to_string(), "--topic-prefix", prefix])
        .args(["--json-status", "--status-ms", "100", "--state-dir"])
        .arg(state_dir(prefix))
        .args(extra)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .expect("cortex agent starts");
    let stdout = child.stdout.take().unwrap();
    let (tx, status) = mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(stdout).lines().map_while(Result::ok) {
            if !line.starts_with('{') {
                continue;
            }
            let status: StatusLine = serde_json::from_str(&line).unwrap_or_else(|e| panic!("{e}: {line}"));
            if tx.send(status).is_err() {
                return;
            }
        }
    });
    Agent { id, child, status, last: None }
}

/// The seeded agent every test pauses: `id` 5, starting from the seed graph at once.
pub fn spawn_seeded(domain: u16, prefix: &str) -> Agent {
    spawn_seeded_with(domain, prefix, &[])
}

/// [`spawn_seeded`] with more arguments (e.g. another transport).
pub fn spawn_seeded_with(domain: u16, prefix: &str, extra: &[&str]) -> Agent {
    let seed = seed_path();
    let args = [&["--seed-json", seed.to_str().unwrap(), "--join-wait-ms", "300"][..], extra].concat();
    spawn(5, domain, prefix, &args)
}

/// Sends `SIGname` to the process.
pub fn signal(child: &Child, name: &str) {
    let _ = Command::new("kill").args([&format!("-{name}"), &child.id().to_string()]).status();
}

/// Stops the process for `pause`, then resumes it.
pub fn pause(agent: &Agent, pause: Duration) {
    signal(&agent.child, "STOP");
    std::thread::sleep(pause);
    signal(&agent.child, "CONT");
}

impl Agent {
    /// Reads every status line waiting; returns the latest one.
    pub fn latest(&mut self) -> Option<&StatusLine> {
        while let Ok(status) = self.status.try_recv() {
            assert_eq!(status.rejected, 0, "agent {}: {status:?}", self.id);
            assert!(status.collision.is_none(), "agent {}: {status:?}", self.id);
            self.last = Some(status);
        }
        self.last.as_ref()
    }

    /// Waits until a status line satisfies `done` (panicking with `what` after `within`); returns that line.
    /// `fail` is checked on every line and ends the test at once when it holds (e.g. a joiner that started alone).
    pub fn wait_for(
        &mut self,
        what: &str,
        within: Duration,
        done: impl Fn(&StatusLine) -> bool,
        fail: impl Fn(&StatusLine) -> bool,
    ) -> StatusLine {
        let deadline = Instant::now() + within;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            let status = match self.status.recv_timeout(left) {
                Ok(status) => status,
                Err(_) => panic!("agent {}: {what} not within {within:?}; last status {:?}", self.id, self.last),
            };
            assert_eq!(status.rejected, 0, "agent {}: {status:?}", self.id);
            assert!(!fail(&status), "agent {}: {what}: {status:?}", self.id);
            self.last = Some(status.clone());
            if done(&status) {
                return status;
            }
        }
    }

    /// Waits until the agent is ready with `nodes` nodes.
    pub fn wait_ready_with(&mut self, nodes: usize) -> StatusLine {
        self.wait_for(
            &format!("ready with {nodes} nodes"),
            Duration::from_secs(30),
            |s| s.ready && s.nodes == nodes,
            |_| false,
        )
    }

    /// Waits (at most `within`) until the agent is ready with at least `nodes` nodes taken from its peers; one that
    /// is ready with fewer before it received anything (it started alone) fails the test at once.
    pub fn wait_joined(&mut self, nodes: usize, within: Duration) {
        self.wait_for(
            &format!("joined with at least {nodes} nodes (not alone)"),
            within,
            |s| s.ready && s.nodes >= nodes,
            |s| s.ready && s.nodes < nodes && s.samples_received == 0,
        );
    }

    /// The latest count of samples received.
    pub fn samples_received(&mut self) -> u64 {
        self.latest().map_or(0, |s| s.samples_received)
    }
}

/// A joiner that must get the graph from the running agents: it waits long for an answer, and a joiner that
/// is ready without the expected nodes (it started alone) fails the test at once.
pub fn join(id: u32, domain: u16, prefix: &str, extra: &[&str], nodes: usize) -> Agent {
    let mut joiner = spawn(id, domain, prefix, &[&["--join-wait-ms", "20000"], extra].concat());
    joiner.wait_joined(nodes, Duration::from_secs(30));
    joiner
}

/// Waits until every agent reports `nodes` nodes and one digest.
pub fn converge(agents: &mut [&mut Agent], nodes: usize) {
    converge_where(agents, &format!("{nodes} nodes"), |n| n == nodes);
}

/// Waits until every agent reports one digest and the same number of nodes, at least `nodes` (for a graph that a
/// writer may still be growing when the wait begins); returns that number.
pub fn converge_at_least(agents: &mut [&mut Agent], nodes: usize) -> usize {
    converge_where(agents, &format!("at least {nodes} nodes"), |n| n >= nodes)
}

fn converge_where(agents: &mut [&mut Agent], what: &str, nodes_ok: impl Fn(usize) -> bool) -> usize {
    let deadline = Instant::now() + Duration::from_secs(30);
    loop {
        let statuses: Vec<Option<StatusLine>> = agents.iter_mut().map(|a| a.latest().cloned()).collect();
        let done = statuses.iter().all(|s| s.as_ref().is_some_and(|s| nodes_ok(s.nodes) && s.digest.is_some()))
            && statuses
                .windows(2)
                .all(|w| w[0].as_ref().map(|s| (&s.digest, s.nodes)) == w[1].as_ref().map(|s| (&s.digest, s.nodes)));
        if let (true, Some(Some(first))) = (done, statuses.first()) {
            return first.nodes;
        }
        assert!(Instant::now() < deadline, "no convergence on {what} within 30 s: {statuses:?}");
        std::thread::sleep(Duration::from_millis(50));
    }
}
