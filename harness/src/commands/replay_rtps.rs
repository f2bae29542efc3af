//! `cortex replay --transport rtps`: the log is played by a bridge agent in this process into a graph shared over
//! RTPS with N−1 `cortex agent` processes (plain agents, or BICA roles such as `camera-detector`), which join it
//! from the bridge like any late joiner.
//!
//! The sequence: the bridge agent starts alone on a fresh topic prefix (its own empty graph after a short wait);
//! the agent processes start with `--control-stdin --json-status` and report ready once they hold the graph; the
//! log is played at its pace; then every role is told to `quiesce` (its runtime stops writing, the agent keeps
//! replicating) and the command waits until every agent reports the bridge's digest — the time from the quiesce,
//! when every writer has stopped, to that moment is the end-of-replay convergence window. Just before the quiesce,
//! the bridge asks
//! every role for its BICA statistics (`runtime.components`, a remote call over the same DDS engine): frequency
//! achieved, misses, skipped releases, lateness. Closing the processes' standard input stops them.

use std::collections::BTreeMap;
use std::io::{BufRead as _, BufReader, Write as _};
use std::process::{Child, ChildStdin, Command, Stdio};
use std::str::FromStr;
use std::sync::atomic::AtomicBool;
use std::sync::mpsc;
use std::time::{Duration, Instant};

use agent::StatusLine;
use anyhow::{Context as _, Result, bail};

use measure::roles::{AgentRow, ComponentRow};

use super::agent::{AgentTransport, Played, Role, play_log, start_rtps_agent};
use transport::rtps::RtpsConfig;

/// A BICA role for one agent process, with the node it works on: `camera-detector`, `laser-detector:scan`, ...
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RoleSpec {
    /// The role (`cortex agent --role`).
    pub role: Role,
    /// Its node (`cortex agent --sensor`), if not the role's default.
    pub sensor: Option<String>,
}

impl FromStr for RoleSpec {
    type Err = String;

    fn from_str(text: &str) -> Result<Self, String> {
        let (name, sensor) = match text.split_once(':') {
            Some((name, sensor)) if !sensor.is_empty() => (name, Some(sensor.to_owned())),
            Some(_) => return Err(format!("{text:?}: empty sensor after ':'")),
            None => (text, None),
        };
        let role = <Role as clap::ValueEnum>::from_str(name, true).map_err(|_| {
            format!("{name:?} is not a role (camera-detector, laser-detector, attention, fixture-camera, bridge)")
        })?;
        if role == Role::Bridge {
            return Err("the bridge is this process; give the other agents' roles".to_owned());
        }
        Ok(RoleSpec { role, sensor })
    }
}

/// How the RTPS replay runs.
#[derive(Debug, Clone)]
pub struct RtpsReplay {
    /// Agents, the bridge included.
    pub agents: u32,
    /// DDS domain id.
    pub domain: u16,
    /// Roles of agents 2, 3, ... (the rest are plain agents).
    pub roles: Vec<RoleSpec>,
    /// Faults injected into what every agent process receives (not the bridge).
    pub faults: Option<transport::fault::FaultConfig>,
    /// How long to wait for the agents to be ready, and after the replay for equal digests.
    pub settle: Duration,
    /// Record the deltas the bridge publishes, and the bytes per 100 ms, as this MCAP file.
    pub record: Option<std::path::PathBuf>,
}

/// What an RTPS replay did.
#[derive(Debug)]
pub struct RtpsOutcome {
    /// What the bridge played.
    pub played: Played,
    /// Seconds of the replay (pacing included).
    pub seconds: f64,
    /// Bytes of samples the bridge published during the replay.
    pub bridge_bytes: u64,
    /// Every agent's last report, the bridge first.
    pub agents: Vec<AgentRow>,
    /// Whether every agent reported the bridge's digest.
    pub digests_equal: bool,
    /// Milliseconds from the quiesce (the roles told to stop writing; the bridge had finished the log) until every
    /// agent reported the bridge's digest: the window from the last writes to convergence.
    pub converged_ms: Option<f64>,
    /// Milliseconds from the end of the replay to the quiesce: fetching the roles' statistics by remote calls.
    pub quiesced_after_ms: f64,
    /// The MCAP file written and its messages per topic, if asked.
    pub recorded: Option<(std::path::PathBuf, measure::record::RecordCounts)>,
}

/// An agent process whose status lines arrive on a channel; killed if dropped while still running.
struct AgentProcess {
    id: u32,
    role: String,
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

fn spawn(
    id: u32,
    domain: u16,
    prefix: &str,
    role: Option<&RoleSpec>,
    faults: Option<&str>,
    tx: mpsc::Sender<(u32, StatusLine)>,
) -> Result<AgentProcess> {
    let program = std::env::current_exe().context("cannot find the cortex binary")?;
    let mut command = Command::new(program);
    command.args(["agent", "--id", &id.to_string(), "--domain", &domain.to_string(), "--topic-prefix", prefix]).args([
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
    if let Some(faults) = faults {
        command.args(["--faults", faults]);
    }
    if let Some(spec) = role {
        command.args(["--role", &role_name(spec.role)]);
        if let Some(sensor) = &spec.sensor {
            command.args(["--sensor", sensor]);
        }
    }
    let mut child = command
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .context("cannot start a cortex agent process")?;
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
    let role = role.map_or_else(|| "plain".to_owned(), |r| role_name(r.role));
    Ok(AgentProcess { id, role, child, stdin })
}

/// The role's name on the command line (`camera-detector`).
fn role_name(role: Role) -> String {
    clap::ValueEnum::to_possible_value(&role).map(|v| v.get_name().to_owned()).unwrap_or_default()
}

fn report(id: u32, role: &str, status: &StatusLine) -> AgentRow {
    AgentRow {
        id,
        role: role.to_owned(),
        nodes: status.nodes as u64,
        digest: status.digest.clone().unwrap_or_else(|| "none".to_owned()),
        samples_received: status.samples_received,
        samples_sent: status.samples_sent,
        components: Vec::new(),
        components_error: None,
    }
}

/// How often [`role_statistics`] tries its call: with `loss=0.1` one attempt in five fails (the request or the
/// reply lost), so three attempts failed about one run in 140 (the likely cause of one CI run that had no statistics); six fail
/// about one in 20,000.
const STATISTICS_ATTEMPTS: usize = 6;

/// A role's BICA statistics, by a remote call from the bridge agent. The call is a read, so it is tried up to
/// [`STATISTICS_ATTEMPTS`] times (1 s each): with `--faults`, a request or reply can be lost like any other sample.
fn role_statistics(bridge: &agent::Agent<AgentTransport>, id: u32) -> Result<Vec<ComponentRow>, String> {
    let mut attempts = Vec::new();
    let reply: bica::service::ComponentsReply = loop {
        match bridge.call(agent::AgentId(id), bica::service::COMPONENTS, &(), Duration::from_secs(1)) {
            Ok(reply) => break reply,
            Err(error) if attempts.len() + 1 < STATISTICS_ATTEMPTS => attempts.push(error.to_string()),
            Err(error) => {
                attempts.push(error.to_string());
                return Err(format!("{} attempts: {}", attempts.len(), attempts.join("; ")));
            }
        }
    };
    let ms = |ns: u64| ns as f64 / 1e6;
    Ok(reply
        .statistics
        .components
        .into_iter()
        .map(|c| ComponentRow {
            name: c.name,
            nominal_hz: c.nominal_hz,
            achieved_hz: c.achieved_hz,
            runs: c.counters.runs,
            misses: c.counters.misses,
            skipped_releases: c.counters.skipped_releases,
            lateness_p99_ms: ms(c.lateness.p99_ns),
            wall_p99_ms: ms(c.wall.p99_ns),
        })
        .collect())
}

/// Plays `log` from a bridge agent in this process to `config.agents - 1` agent processes over RTPS.
///
/// # Errors
/// The DDS domain cannot be joined, an agent process cannot start or is not ready within the settle time, or the
/// bridge's agent refuses a write.
pub fn replay(
    log: &replay::Log,
    options: replay::BridgeOptions,
    rate: replay::Rate,
    loops: u32,
    config: &RtpsReplay,
) -> Result<RtpsOutcome> {
    if config.roles.len() > config.agents.saturating_sub(1) as usize {
        bail!("{} roles given for {} agent processes", config.roles.len(), config.agents.saturating_sub(1));
    }
    let prefix = format!("replay{}", std::process::id());
    let rtps = RtpsConfig { domain_id: config.domain, topic_prefix: prefix.clone(), ..RtpsConfig::default() };
    // A graph of this run alone (its own topic prefix): nobody to wait for, no earlier life to keep apart from, no
    // record.
    let bridge = start_rtps_agent(1, 0, None, rtps, None, None)?;
    if !bridge.wait_ready(Duration::from_secs(10)) {
        bail!("the bridge agent did not start its graph");
    }
    let (tx, rx) = mpsc::channel();
    let faults = config.faults.map(|f| f.to_spec());
    let mut procs = Vec::new();
    for id in 2..=config.agents {
        let role = config.roles.get((id - 2) as usize);
        procs.push(spawn(id, config.domain, &prefix, role, faults.as_deref(), tx.clone())?);
    }
    drop(tx);
    let mut last: BTreeMap<u32, StatusLine> = BTreeMap::new();
    let deadline = Instant::now() + config.settle;
    while last.len() < procs.len() || !last.values().all(|s| s.ready) {
        let Ok((id, status)) = rx.recv_timeout(deadline.saturating_duration_since(Instant::now())) else {
            let ready = last.values().filter(|s| s.ready).count();
            bail!("{ready} of {} agent processes were ready within {:?}", procs.len(), config.settle);
        };
        last.insert(id, status);
    }

    let stop = AtomicBool::new(false);
    let mut recording = match &config.record {
        Some(path) => {
            let mut metadata = measure::record::provenance_metadata(&measure::Provenance::current());
            metadata.insert("run".to_owned(), format!("cortex replay {} --transport rtps", log.file));
            metadata.insert("agents".to_owned(), config.agents.to_string());
            metadata.insert(
                "recorded".to_owned(),
                "the deltas the bridge agent published (log time: when its update returned, after publication) and \
                 published bytes per 100 ms; latencies of RTPS runs are measured by cortex report"
                    .to_owned(),
            );
            let mut recorder = measure::record::RunRecorder::create(path, metadata)?;
            recorder.add_delta_channel("replay::bridge::dictionary()")?;
            Some((recorder, measure::MonoClock::start(), 0u64))
        }
        None => None,
    };
    let mut record = |deltas: &[std::sync::Arc<dsr::Delta>]| -> Result<()> {
        if let Some((recorder, clock, index)) = recording.as_mut() {
            let now = clock.now_ns();
            for delta in deltas {
                recorder.delta(*index, now, &delta.encode())?;
                *index += 1;
            }
        }
        Ok(())
    };
    let before = bridge.status().transport;
    let started = Instant::now();
    let played = play_log(&bridge, log, options, rate, loops, &stop, &mut record)?;
    let mut recorded = None;
    if let (Some((recorder, _, _)), Some(path)) = (recording, &config.record) {
        let counts =
            measure::record::finish_file(recorder).with_context(|| format!("cannot write {}", path.display()))?;
        recorded = Some((path.clone(), counts));
    }
    let seconds = started.elapsed().as_secs_f64();
    let ended = Instant::now();
    let bridge_bytes = bridge.status().transport.payload_bytes_sent - before.payload_bytes_sent;
    let mut statistics = BTreeMap::new();
    for proc in procs.iter().filter(|p| p.role != "plain") {
        statistics.insert(proc.id, role_statistics(&bridge, proc.id));
    }
    for proc in &mut procs {
        if proc.role != "plain"
            && let Some(stdin) = proc.stdin.as_mut()
        {
            // An agent that has died shows up below as not converged.
            let _ = writeln!(stdin, "quiesce");
        }
    }
    let quiesced = Instant::now();
    let quiesced_after_ms = quiesced.duration_since(ended).as_secs_f64() * 1e3;
    let deadline = quiesced + config.settle;
    let mut converged_ms = None;
    // Statuses printed after the quiesce only: the roles may still have been writing before it.
    last.clear();
    while Instant::now() < deadline {
        let Ok((id, status)) = rx.recv_timeout(Duration::from_millis(50)) else { continue };
        last.insert(id, status);
        let Some(target) = bridge.digest().map(|d| d.to_string()) else { continue };
        if last.len() == procs.len() && last.values().all(|s| s.digest.as_deref() == Some(target.as_str())) {
            converged_ms = Some(quiesced.elapsed().as_secs_f64() * 1e3);
            break;
        }
    }
    let status = bridge.status();
    let mut agents = vec![AgentRow {
        id: 1,
        role: "bridge".to_owned(),
        nodes: status.nodes as u64,
        digest: bridge.digest().map_or_else(|| "none".to_owned(), |d| d.to_string()),
        samples_received: status.transport.samples_received,
        samples_sent: status.transport.samples_sent,
        components: Vec::new(),
        components_error: None,
    }];
    for proc in &procs {
        let status = last.get(&proc.id).cloned().unwrap_or_default();
        let mut agent = report(proc.id, &proc.role, &status);
        match statistics.remove(&proc.id) {
            Some(Ok(components)) => agent.components = components,
            Some(Err(error)) => agent.components_error = Some(error),
            None => {}
        }
        agents.push(agent);
    }
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
    bridge.shutdown();
    let digests_equal = agents.iter().all(|a| a.digest == agents[0].digest);
    Ok(RtpsOutcome { played, seconds, bridge_bytes, agents, digests_equal, converged_ms, quiesced_after_ms, recorded })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn role_specs_parse_with_and_without_a_sensor() {
        assert_eq!("camera-detector".parse(), Ok(RoleSpec { role: Role::CameraDetector, sensor: None }));
        assert_eq!(
            "laser-detector:scan".parse(),
            Ok(RoleSpec { role: Role::LaserDetector, sensor: Some("scan".to_owned()) })
        );
        assert!("bridge".parse::<RoleSpec>().unwrap_err().contains("this process"));
        assert!("painter".parse::<RoleSpec>().unwrap_err().contains("not a role"));
        assert!("attention:".parse::<RoleSpec>().unwrap_err().contains("empty sensor"));
    }
}
