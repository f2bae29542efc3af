//! Three `cortex agent` processes on loopback over RTPS: one seeded from a real CORTEX JSON graph, two that join
//! it from the network and each insert nodes (agent 3 sends its updates best-effort, the others reliably: settings
//! mix). All three must end with the same digest and write identical CORTEX JSON dumps when interrupted with SIGINT.

use std::io::{BufRead, BufReader};
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use agent::StatusLine;

fn workspace() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// A spawned agent whose status lines arrive on a channel; killed if the test fails half-way.
struct Proc {
    child: Child,
    dump: PathBuf,
}

impl Drop for Proc {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn spawn(id: u32, prefix: &str, dir: &std::path::Path, extra: &[&str], tx: mpsc::Sender<(u32, StatusLine)>) -> Proc {
    let dump = dir.join(format!("dump{id}.json"));
    let mut child = Command::new(env!("CARGO_BIN_EXE_cortex"))
        .args(["agent", "--id", &id.to_string(), "--domain", "0", "--topic-prefix", prefix, "--json-status"])
        // A graph of this test alone: no incarnation record left in the home directory.
        .args(["--state-dir", "none"])
        .args(["--status-ms", "100", "--dump-json"])
        .arg(&dump)
        .args(extra)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .expect("cortex agent starts");
    let stdout = child.stdout.take().unwrap();
    std::thread::spawn(move || {
        for line in BufReader::new(stdout).lines().map_while(Result::ok) {
            if !line.starts_with('{') {
                continue;
            }
            let status: StatusLine = serde_json::from_str(&line).unwrap_or_else(|e| panic!("{e}: {line}"));
            if tx.send((id, status)).is_err() {
                return;
            }
        }
    });
    Proc { child, dump }
}

#[test]
fn three_agent_processes_converge_to_identical_dumps() {
    let dir = std::env::temp_dir().join(format!("cortex-agents-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let prefix = format!("mp{}", std::process::id());
    let seed = workspace().join("datasets/cortex-graphs/Robot_viriato.json");
    let seed_nodes = dsr::json::parse(&std::fs::read_to_string(&seed).unwrap()).unwrap().nodes.len();
    let (tx, rx) = mpsc::channel();

    let mut procs =
        vec![spawn(1, &prefix, &dir, &["--seed-json", seed.to_str().unwrap(), "--join-wait-ms", "1000"], tx.clone())];
    let deadline = Instant::now() + Duration::from_secs(30);
    loop {
        let (_, status) = rx.recv_timeout(deadline.saturating_duration_since(Instant::now())).expect("agent 1 status");
        if status.ready {
            assert_eq!(status.nodes, seed_nodes);
            break;
        }
    }
    for (id, updates) in [(2, "reliable"), (3, "best-effort")] {
        let args = ["--join-wait-ms", "60000", "--insert-nodes", "5", "--updates", updates];
        procs.push(spawn(id, &prefix, &dir, &args, tx.clone()));
    }

    let mut last = std::collections::BTreeMap::new();
    let deadline = Instant::now() + Duration::from_secs(90);
    loop {
        let (id, status) =
            rx.recv_timeout(deadline.saturating_duration_since(Instant::now())).expect("converged in time");
        assert_eq!(status.rejected, 0, "{status:?}");
        assert!(status.collision.is_none(), "{status:?}");
        last.insert(id, status);
        let done = last.len() == 3
            && last.values().all(|s: &StatusLine| s.nodes == seed_nodes + 10 && s.digest.is_some())
            && last.values().all(|s| s.digest == last[&1].digest);
        if done {
            break;
        }
    }
    let replicas: std::collections::BTreeSet<_> = last.values().map(|s| s.replica.unwrap()).collect();
    assert_eq!(replicas.len(), 3, "distinct replica ids");

    for proc in &mut procs {
        let status = Command::new("kill").args(["-INT", &proc.child.id().to_string()]).status().unwrap();
        assert!(status.success());
    }
    for proc in &mut procs {
        let exit = proc.child.wait().unwrap();
        assert!(exit.success(), "agent exited with {exit}");
    }
    let dumps: Vec<String> = procs.iter().map(|p| std::fs::read_to_string(&p.dump).expect("dump written")).collect();
    assert_eq!(dumps[0], dumps[1]);
    assert_eq!(dumps[0], dumps[2]);
    let graph = dsr::json::parse(&dumps[0]).unwrap();
    assert_eq!(graph.nodes.len(), seed_nodes + 10);
    for id in [2, 3] {
        for i in 0..5 {
            let name = format!("a{id}_{i}");
            assert!(graph.nodes.values().any(|n| n.name == name), "{name} in the dump");
        }
    }
    drop(procs);
    let _ = std::fs::remove_dir_all(&dir);
}
