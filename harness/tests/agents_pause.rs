//! `cortex agent` processes on loopback over RTPS, one of them stopped with SIGSTOP and resumed with SIGCONT (issue
//! 14). On Linux a thread blocked in `epoll_wait` gets EINTR when its process resumes, even without a signal
//! handler, and `rustdds` 0.15 ends its participants' event loops on any poll error: before the transport
//! rebuilt its participants, a resumed agent was deaf and mute for good — a new agent found nobody and started
//! alone with an empty graph, and a connected peer's samples stopped arriving. Each test uses its own domain and
//! topic prefix, so the tests of this file (and of other files) can run at the same time.

use std::io::{BufRead, BufReader};
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use serde_json::Value;

fn workspace() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn seed_path() -> PathBuf {
    workspace().join("datasets/cortex-graphs/Robot_viriato.json")
}

/// Nodes of the seed graph.
fn seed_nodes() -> u64 {
    dsr::json::parse(&std::fs::read_to_string(seed_path()).unwrap()).unwrap().nodes.len() as u64
}

/// A spawned agent whose JSON status lines arrive on a channel; killed when dropped (also when a test fails).
struct Agent {
    id: u32,
    child: Child,
    status: mpsc::Receiver<Value>,
    /// The latest status line read.
    last: Option<Value>,
}

impl Drop for Agent {
    fn drop(&mut self) {
        // A stopped process must be resumed to die of SIGKILL promptly in every case; SIGKILL works anyway.
        signal(&self.child, "CONT");
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Starts agent `id` on `domain` with the topic prefix `prefix`, printing its status every 100 ms.
fn spawn(id: u32, domain: u16, prefix: &str, extra: &[&str]) -> Agent {
    let mut child = Command::new(env!("CARGO_BIN_EXE_cortex"))
        .args(["agent", "--id", &id.to_string(), "--domain", &domain.to_string(), "--topic-prefix", prefix])
        .args(["--json-status", "--status-ms", "100"])
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
            if let Ok(value) = serde_json::from_str(&line)
                && tx.send(value).is_err()
            {
                return;
            }
        }
    });
    Agent { id, child, status, last: None }
}

/// The seeded agent every test pauses: `id` 5, starting from the seed graph at once.
fn spawn_seeded(domain: u16, prefix: &str) -> Agent {
    let seed = seed_path();
    spawn(5, domain, prefix, &["--seed-json", seed.to_str().unwrap(), "--join-wait-ms", "300"])
}

/// Sends `SIGname` to the process.
fn signal(child: &Child, name: &str) {
    let _ = Command::new("kill").args([&format!("-{name}"), &child.id().to_string()]).status();
}

/// Stops the process for `pause`, then resumes it.
fn pause(agent: &Agent, pause: Duration) {
    signal(&agent.child, "STOP");
    std::thread::sleep(pause);
    signal(&agent.child, "CONT");
}

impl Agent {
    /// Reads every status line waiting; returns the latest one.
    fn latest(&mut self) -> Option<&Value> {
        while let Ok(status) = self.status.try_recv() {
            assert_eq!(status["rejected"].as_u64(), Some(0), "agent {}: {status}", self.id);
            assert!(status["collision"].is_null(), "agent {}: {status}", self.id);
            self.last = Some(status);
        }
        self.last.as_ref()
    }

    /// Waits until a status line satisfies `done` (panicking with `what` after `within`); returns that line.
    /// `fail` is checked on every line and ends the test at once when it holds (e.g. a joiner that started alone).
    fn wait_for(
        &mut self,
        what: &str,
        within: Duration,
        done: impl Fn(&Value) -> bool,
        fail: impl Fn(&Value) -> bool,
    ) -> Value {
        let deadline = Instant::now() + within;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            let status = match self.status.recv_timeout(left) {
                Ok(status) => status,
                Err(_) => panic!("agent {}: {what} not within {within:?}; last status {:?}", self.id, self.last),
            };
            assert_eq!(status["rejected"].as_u64(), Some(0), "agent {}: {status}", self.id);
            assert!(!fail(&status), "agent {}: {what}: {status}", self.id);
            self.last = Some(status.clone());
            if done(&status) {
                return status;
            }
        }
    }

    /// Waits until the agent is ready with `nodes` nodes.
    fn wait_ready_with(&mut self, nodes: u64) -> Value {
        self.wait_for(
            &format!("ready with {nodes} nodes"),
            Duration::from_secs(30),
            |s| s["ready"] == true && s["nodes"].as_u64() == Some(nodes),
            |_| false,
        )
    }

    /// The latest count of samples received.
    fn samples_received(&mut self) -> u64 {
        self.latest().and_then(|s| s["samples_received"].as_u64()).unwrap_or(0)
    }
}

/// A joiner that must get the graph from the running agents: it waits long for an answer, and a joiner that
/// is ready without the expected nodes (it started alone) fails the test at once.
fn join(id: u32, domain: u16, prefix: &str, extra: &[&str], nodes: u64) -> Agent {
    let mut joiner = spawn(id, domain, prefix, &[&["--join-wait-ms", "20000"], extra].concat());
    joiner.wait_for(
        &format!("joined with at least {nodes} nodes (not alone)"),
        Duration::from_secs(30),
        |s| s["ready"] == true && s["nodes"].as_u64().is_some_and(|n| n >= nodes),
        |s| s["ready"] == true && s["nodes"].as_u64().is_some_and(|n| n < nodes) && s["samples_received"] == 0,
    );
    joiner
}

/// Waits until every agent reports `nodes` nodes and one digest.
fn converge(agents: &mut [&mut Agent], nodes: u64) {
    let deadline = Instant::now() + Duration::from_secs(30);
    loop {
        let statuses: Vec<Option<Value>> = agents.iter_mut().map(|a| a.latest().cloned()).collect();
        let done = statuses
            .iter()
            .all(|s| s.as_ref().is_some_and(|s| s["nodes"].as_u64() == Some(nodes) && !s["digest"].is_null()))
            && statuses.windows(2).all(|w| w[0].as_ref().map(|s| &s["digest"]) == w[1].as_ref().map(|s| &s["digest"]));
        if done {
            return;
        }
        assert!(Instant::now() < deadline, "no convergence on {nodes} nodes within 30 s: {statuses:?}");
        std::thread::sleep(Duration::from_millis(50));
    }
}

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
        |s| s["samples_received"].as_u64().is_some_and(|n| n >= after_resume + 12),
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
