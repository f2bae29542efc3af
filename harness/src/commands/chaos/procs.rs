//! The campaign's agent processes: each a `cortex chaos-agent` started inside its slot's namespace with
//! `ip netns exec`, its standard output read by a thread that forwards every line, time-stamped, to the campaign;
//! its standard error kept in `agents/a<SLOT>.log` under the campaign's directory.

use std::io::{BufRead, BufReader, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdin, Command, Stdio};
use std::sync::mpsc::Sender;
use std::time::Instant;

use anyhow::{Context, Result};

use super::protocol::Command as AgentCommand;

/// A line from an agent process (or the end of its output).
#[derive(Debug)]
pub struct Line {
    /// The agent slot.
    pub slot: usize,
    /// The life (0 for the first start of the slot).
    pub life: u32,
    /// When the campaign read it.
    pub at: Instant,
    /// The line; `None` at the end of the output (the process exited or was killed).
    pub text: Option<String>,
}

/// How agent processes are started.
#[derive(Clone, Debug)]
pub struct Launch {
    /// The `cortex` binary.
    pub program: PathBuf,
    /// DDS domain.
    pub domain: u16,
    /// How long a new life waits for a running agent's graph.
    pub join_wait_ms: u64,
    /// Period of status lines.
    pub status_ms: u64,
    /// Bytes of a camera frame.
    pub image_bytes: usize,
    /// The campaign's directory (agent logs and incarnation records go under it).
    pub dir: PathBuf,
    /// The campaign's PKI (`cortex security init`), when its agents run with DDS Security: slot N uses the
    /// credentials of [`identity`]`(N)`.
    pub security: Option<PathBuf>,
    /// Start the agents without `--graph-id` (`cortex chaos --unnamed`).
    pub unnamed: bool,
    /// A protocol bug to plant in every agent.
    #[cfg(feature = "mutants")]
    pub plant: Option<String>,
}

/// One running agent process.
#[derive(Debug)]
pub struct Proc {
    child: Child,
    stdin: ChildStdin,
    /// Its life.
    pub life: u32,
}

impl Proc {
    /// Starts life `life` of agent slot `slot` in namespace `namespace`.
    ///
    /// # Errors
    /// The process cannot start or its log cannot be opened.
    pub fn start(launch: &Launch, namespace: &str, slot: usize, life: u32, lines: Sender<Line>) -> Result<Proc> {
        let logs = launch.dir.join("agents");
        std::fs::create_dir_all(&logs).with_context(|| format!("creating {}", logs.display()))?;
        let log_path = logs.join(format!("a{slot}.log"));
        let mut log = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(&log_path)
            .with_context(|| format!("opening {}", log_path.display()))?;
        let _ = writeln!(log, "--- life {life}");
        let mut command = Command::new("ip");
        command
            .args(["netns", "exec", namespace])
            .arg(&launch.program)
            .arg("chaos-agent")
            .args(["--id", &slot.to_string(), "--domain", &launch.domain.to_string()])
            .args(["--join-wait-ms", &launch.join_wait_ms.to_string()])
            .args(["--status-ms", &launch.status_ms.to_string()])
            .args(["--image-bytes", &launch.image_bytes.to_string()])
            .arg("--life-file")
            .arg(life_file(&launch.dir, slot));
        // One graph, named: a life that starts alone (a restart with no reachable peer, a late join across a
        // partition) is still of the campaign's graph. Unnamed, such a life makes a graph of its own that must move.
        if !launch.unnamed {
            command.args(["--graph-id", &agent::GraphId::from_nonce(u64::from(launch.domain)).to_string()]);
        }
        if let Some(pki) = &launch.security {
            command.arg("--security").arg(pki.join(identity(slot)));
        }
        #[cfg(feature = "mutants")]
        if let Some(name) = &launch.plant {
            command.args(["--plant", name]);
        }
        let mut child = command
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::from(log))
            .spawn()
            .with_context(|| format!("starting agent {slot} in {namespace}"))?;
        let stdin = child.stdin.take().context("the agent's standard input")?;
        let stdout = child.stdout.take().context("the agent's standard output")?;
        std::thread::spawn(move || {
            for text in BufReader::new(stdout).lines() {
                let Ok(text) = text else { break };
                if lines.send(Line { slot, life, at: Instant::now(), text: Some(text) }).is_err() {
                    return;
                }
            }
            let _ = lines.send(Line { slot, life, at: Instant::now(), text: None });
        });
        Ok(Proc { child, stdin, life })
    }

    /// Sends a command; a process that cannot take it has died, which its end of output reports.
    pub fn send(&mut self, command: &AgentCommand) {
        if let Ok(line) = serde_json::to_string(command) {
            let _ = writeln!(self.stdin, "{line}");
            let _ = self.stdin.flush();
        }
    }

    /// Sends `SIGSTOP` or `SIGCONT` (`name` is `STOP` or `CONT`).
    ///
    /// # Errors
    /// `kill` could not run.
    pub fn signal(&self, name: &str) -> Result<()> {
        Command::new("kill")
            .args([&format!("-{name}"), &self.child.id().to_string()])
            .status()
            .context("running kill")?;
        Ok(())
    }

    /// `SIGKILL`, and waits for the process.
    pub fn kill(mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }

    /// Closes its standard input (it stops by itself) and waits up to 10 s, then kills it.
    pub fn stop(mut self) {
        drop(self.stdin);
        let deadline = Instant::now() + std::time::Duration::from_secs(10);
        while matches!(self.child.try_wait(), Ok(None)) && Instant::now() < deadline {
            std::thread::sleep(std::time::Duration::from_millis(20));
        }
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// The name of slot `slot`'s identity in the campaign's PKI.
pub fn identity(slot: usize) -> String {
    format!("slot{slot}")
}

/// The incarnation record of agent slot `slot`, kept across its lives.
pub fn life_file(dir: &Path, slot: usize) -> PathBuf {
    dir.join("agents").join(format!("a{slot}.life"))
}

/// The last lines of agent slot `slot`'s log, for an error message.
pub fn log_tail(dir: &Path, slot: usize) -> String {
    let text = std::fs::read_to_string(dir.join("agents").join(format!("a{slot}.log"))).unwrap_or_default();
    let lines: Vec<&str> = text.lines().rev().take(5).collect();
    lines.into_iter().rev().collect::<Vec<_>>().join("\n")
}
