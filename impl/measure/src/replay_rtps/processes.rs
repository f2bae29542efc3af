//! The agent processes of an RTPS replay: `cortex agent --control-stdin --json-status` children, whose typed
//! status lines ([`agent::StatusLine`]) arrive on one channel and which take typed commands on standard input
//! ([`agent::Control`]); closing their standard input stops them.

use std::collections::BTreeMap;
use std::io::{BufRead as _, BufReader, Write as _};
use std::path::Path;
use std::process::{Child, ChildStdin, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use agent::{Control, StatusLine};
use anyhow::Context as _;

use super::RoleSpec;

/// How an agent process is started.
pub(super) struct Launch<'a> {
    /// The `cortex` binary.
    pub program: &'a Path,
    /// DDS domain id.
    pub domain: u16,
    /// Topic prefix of this run's graph.
    pub prefix: &'a str,
    /// Faults on what the process receives, as a specification.
    pub faults: Option<&'a str>,
    /// Discard the process's standard error instead of sharing this process's.
    pub quiet: bool,
}

/// An agent process; killed if dropped while still running.
pub(super) struct AgentProcess {
    /// Its agent id.
    pub id: u32,
    /// `plain` or its role's name.
    pub role: String,
    child: Child,
    stdin: Option<ChildStdin>,
}

impl Drop for AgentProcess {
    fn drop(&mut self) {
        if matches!(self.child.try_wait(), Ok(None)) {
            let _ = self.child.kill();
        }
        let _ = self.child.wait();
    }
}

impl AgentProcess {
    /// Whether it runs a role (not a plain agent).
    pub fn has_role(&self) -> bool {
        self.role != "plain"
    }

    /// Sends `control`; an agent that has died shows up later as not converged, so a failed write is ignored.
    pub fn send(&mut self, control: Control) {
        if let Some(stdin) = self.stdin.as_mut() {
            let _ = writeln!(stdin, "{}", control.line());
        }
    }
}

/// Starts agent `id` (with `role`, if any); its status lines go to `tx`.
///
/// # Errors
/// The program cannot start.
pub(super) fn spawn(
    id: u32,
    launch: &Launch<'_>,
    role: Option<&RoleSpec>,
    tx: mpsc::Sender<(u32, StatusLine)>,
) -> anyhow::Result<AgentProcess> {
    let mut command = Command::new(launch.program);
    command.args(["agent", "--id", &id.to_string(), "--domain", &launch.domain.to_string()]);
    command.args(["--topic-prefix", launch.prefix]).args([
        "--json-status",
        "--status-ms",
        "100",
        "--join-wait-ms",
        "60000",
        "--control-stdin",
        // A graph of this run alone (its own topic prefix): no earlier life to keep apart from, so no record left
        // in the user's state directory.
        "--state-dir",
        "none",
    ]);
    if let Some(faults) = launch.faults {
        command.args(["--faults", faults]);
    }
    if let Some(spec) = role {
        command.args(["--role", spec.role.name()]);
        if let Some(sensor) = &spec.sensor {
            command.args(["--sensor", sensor]);
        }
    }
    let stderr = if launch.quiet { Stdio::null() } else { Stdio::inherit() };
    let mut child = command
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(stderr)
        .spawn()
        .with_context(|| format!("cannot start a cortex agent process ({})", launch.program.display()))?;
    let stdout = child.stdout.take().context("agent stdout")?;
    let stdin = child.stdin.take();
    std::thread::spawn(move || {
        for line in BufReader::new(stdout).lines().map_while(Result::ok) {
            // Lines that are not status lines (a role's own output) are skipped; a status line that does not parse
            // is a mismatch between writer and reader, which the shared type rules out.
            if let Ok(status) = serde_json::from_str::<StatusLine>(&line)
                && tx.send((id, status)).is_err()
            {
                return;
            }
        }
    });
    let role = role.map_or("plain", |r| r.role.name()).to_owned();
    Ok(AgentProcess { id, role, child, stdin })
}

/// Waits until every one of `count` processes has reported ready; the last status of each.
///
/// # Errors
/// Not all were ready within `settle`.
pub(super) fn wait_ready(
    rx: &mpsc::Receiver<(u32, StatusLine)>,
    count: usize,
    settle: Duration,
) -> anyhow::Result<BTreeMap<u32, StatusLine>> {
    let mut last: BTreeMap<u32, StatusLine> = BTreeMap::new();
    let deadline = Instant::now() + settle;
    while last.len() < count || !last.values().all(|s| s.ready) {
        let Ok((id, status)) = rx.recv_timeout(deadline.saturating_duration_since(Instant::now())) else {
            let ready = last.values().filter(|s| s.ready).count();
            anyhow::bail!("{ready} of {count} agent processes were ready within {settle:?}");
        };
        last.insert(id, status);
    }
    Ok(last)
}

/// Stops the processes by closing their standard input, waits up to 10 s in all for them to end, and kills those
/// still running.
pub(super) fn close(mut procs: Vec<AgentProcess>) {
    for proc in &mut procs {
        proc.stdin = None;
    }
    let give_up = Instant::now() + Duration::from_secs(10);
    for proc in &mut procs {
        while matches!(proc.child.try_wait(), Ok(None)) && Instant::now() < give_up {
            std::thread::sleep(Duration::from_millis(20));
        }
    }
    drop(procs);
}
