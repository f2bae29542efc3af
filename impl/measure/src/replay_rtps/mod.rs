//! The replay of a log over RTPS into agent processes: a bridge agent in this process plays the log into a graph
//! shared over RTPS with N−1 `cortex agent` processes (plain agents, or BICA roles such as `camera-detector`),
//! which join it from the bridge like any late joiner. `cortex replay --transport rtps` prints what [`run`]
//! returns, and the roles experiment of `cortex report` ([`crate::roles`]) keeps it as a [`RolesResult`].
//!
//! The sequence: the bridge agent starts alone on a fresh topic prefix (its own empty graph after a short wait);
//! the agent processes start with `--control-stdin --json-status` and report ready once they hold the graph; the
//! log is played at its pace; then every role is told to `quiesce` (its runtime stops writing, the agent keeps
//! replicating) and the runner waits until every agent reports the bridge's digest — the time from the quiesce,
//! when every writer has stopped, to that moment is the end-of-replay convergence window. Just before the quiesce,
//! the bridge asks every role for its BICA statistics (`runtime.components`, a remote call over the same DDS
//! engine): frequency achieved, misses, skipped releases, lateness. Closing the processes' standard input stops
//! them. The processes are separate on purpose (each its own DDS participant and scheduler); they speak typed
//! lines both ways ([`agent::StatusLine`] out, [`agent::Control`] in).

mod processes;
mod statistics;

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::str::FromStr;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;
use std::sync::mpsc;
use std::time::{Duration, Instant};

use agent::rtps::AgentTransport;
use agent::{Agent, AgentConfig, AgentId, Control, StatusLine};
use anyhow::{Context as _, bail};
use perception::roles::Role;
use transport::fault::FaultConfig;
use transport::rtps::RtpsConfig;

use crate::bridge_agent::{Played, play_log};
use crate::record::{self, RecordCounts, RunRecorder};
use crate::results::{AgentRow, ComponentRow, RolesResult};
use crate::units::ms_from_duration;
use processes::{AgentProcess, Launch};

pub use statistics::{STATISTICS_ATTEMPTS, role_statistics};

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

    /// `ROLE[:NODE]`; the bridge is refused (it is the runner's own agent).
    fn from_str(text: &str) -> Result<Self, String> {
        let (name, sensor) = match text.split_once(':') {
            Some((name, sensor)) if !sensor.is_empty() => (name, Some(sensor.to_owned())),
            Some(_) => return Err(format!("{text:?}: empty sensor after ':'")),
            None => (text, None),
        };
        let role: Role = name.parse()?;
        if role == Role::Bridge {
            return Err("the bridge is this process; give the other agents' roles".to_owned());
        }
        Ok(RoleSpec { role, sensor })
    }
}

/// How the RTPS replay runs.
#[derive(Debug, Clone)]
pub struct RtpsReplay {
    /// Agents, the bridge included (1 to 64).
    pub agents: u32,
    /// DDS domain id.
    pub domain: u16,
    /// Roles of agents 2, 3, ... (the rest are plain agents).
    pub roles: Vec<RoleSpec>,
    /// Faults injected into what every agent process receives (not the bridge).
    pub faults: Option<FaultConfig>,
    /// What the bridge plays: topics, opaque messages.
    pub bridge: replay::BridgeOptions,
    /// Pace of the replay.
    pub rate: replay::Rate,
    /// Passes over the log.
    pub loops: u32,
    /// How long to wait for the agents to be ready, and after the replay for equal digests.
    pub settle: Duration,
    /// Record the deltas the bridge publishes, and the bytes per 100 ms, as this MCAP file.
    pub record: Option<PathBuf>,
    /// The `cortex` binary, which runs the agent processes (`cortex agent`).
    pub program: PathBuf,
    /// Discard the agent processes' standard error instead of sharing this process's.
    pub quiet_agents: bool,
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
    pub recorded: Option<(PathBuf, RecordCounts)>,
}

impl RtpsOutcome {
    /// The roles experiment's result; `faults` as the replay ran with them.
    pub fn roles_result(&self, faults: Option<&FaultConfig>) -> RolesResult {
        RolesResult {
            messages: self.played.drive.messages,
            deltas: self.played.drive.deltas,
            seconds: self.seconds,
            faults: faults.map(FaultConfig::to_spec),
            converged_ms: self.converged_ms,
            quiesced_after_ms: Some(self.quiesced_after_ms),
            digests_equal: self.digests_equal,
            agents: self.agents.clone(),
        }
    }
}

/// The bridge agent and the agent processes, all ready.
struct Agents {
    bridge: Arc<Agent<AgentTransport>>,
    procs: Vec<AgentProcess>,
    statuses: mpsc::Receiver<(u32, StatusLine)>,
}

/// Plays `log` from a bridge agent in this process to `settings.agents - 1` agent processes over RTPS.
///
/// # Errors
/// Bad settings (agents out of range, more roles than agent processes), the DDS domain cannot be joined, an agent
/// process cannot start or is not ready within the settle time, the bridge's agent refuses a write, or the
/// recording cannot be written.
pub fn run(log: &replay::Log, settings: &RtpsReplay) -> anyhow::Result<RtpsOutcome> {
    check(settings)?;
    let Agents { bridge, mut procs, statuses } = start(settings)?;
    let before = bridge.status().transport;
    let started = Instant::now();
    let (played, recorded) = play(&bridge, log, settings)?;
    let seconds = started.elapsed().as_secs_f64();
    let ended = Instant::now();
    let bridge_bytes = bridge.status().transport.payload_bytes_sent - before.payload_bytes_sent;
    let mut components = BTreeMap::new();
    for proc in procs.iter().filter(|p| p.has_role()) {
        components.insert(proc.id, role_statistics(&bridge, proc.id));
    }
    for proc in procs.iter_mut().filter(|p| p.has_role()) {
        proc.send(Control::Quiesce);
    }
    let quiesced = Instant::now();
    let quiesced_after_ms = ms_from_duration(quiesced.duration_since(ended));
    let (last, converged_ms) = wait_converged(&bridge, &statuses, procs.len(), quiesced, settings.settle);
    let mut agents = vec![bridge_row(&bridge)];
    for proc in &procs {
        let status = last.get(&proc.id).cloned().unwrap_or_default();
        agents.push(process_row(proc, &status, components.remove(&proc.id)));
    }
    processes::close(procs);
    bridge.shutdown();
    let digests_equal = agents.iter().all(|a| a.digest == agents[0].digest);
    Ok(RtpsOutcome { played, seconds, bridge_bytes, agents, digests_equal, converged_ms, quiesced_after_ms, recorded })
}

/// Refuses settings the runner cannot run: agents out of range, more roles than agent processes.
fn check(settings: &RtpsReplay) -> anyhow::Result<()> {
    if !(1..=64).contains(&settings.agents) {
        bail!("agents must be between 1 and 64, not {}", settings.agents);
    }
    if settings.roles.len() > settings.agents.saturating_sub(1) as usize {
        bail!("{} roles given for {} agent processes", settings.roles.len(), settings.agents.saturating_sub(1));
    }
    Ok(())
}

/// Starts the bridge agent alone on a fresh topic prefix, then the agent processes, and waits until they are ready.
fn start(settings: &RtpsReplay) -> anyhow::Result<Agents> {
    let prefix = format!("replay{}", std::process::id());
    let rtps = RtpsConfig { domain_id: settings.domain, topic_prefix: prefix.clone(), ..RtpsConfig::default() };
    // A graph of this run alone (its own topic prefix): nobody to wait for, no earlier life to keep apart from, no
    // record.
    let mut config = AgentConfig::new(AgentId(1));
    config.join_wait = Duration::ZERO;
    let bridge = agent::rtps::start(config, rtps, None).context("cannot start the bridge agent")?;
    if !bridge.wait_ready(Duration::from_secs(10)) {
        bail!("the bridge agent did not start its graph");
    }
    let (tx, statuses) = mpsc::channel();
    let faults = settings.faults.map(|f| f.to_spec());
    let launch = Launch {
        program: &settings.program,
        domain: settings.domain,
        prefix: &prefix,
        faults: faults.as_deref(),
        quiet: settings.quiet_agents,
    };
    let mut procs = Vec::new();
    for id in 2..=settings.agents {
        let role = settings.roles.get((id - 2) as usize);
        procs.push(processes::spawn(id, &launch, role, tx.clone())?);
    }
    drop(tx);
    processes::wait_ready(&statuses, procs.len(), settings.settle)?;
    Ok(Agents { bridge, procs, statuses })
}

/// Plays the log from the bridge, recording what it publishes if asked.
fn play(
    bridge: &Agent<AgentTransport>,
    log: &replay::Log,
    settings: &RtpsReplay,
) -> anyhow::Result<(Played, Option<(PathBuf, RecordCounts)>)> {
    let stop = AtomicBool::new(false);
    let (options, rate, loops) = (settings.bridge.clone(), settings.rate, settings.loops);
    let Some(path) = &settings.record else {
        return Ok((play_log(bridge, log, options, rate, loops, &stop, &mut |_| Ok(()))?, None));
    };
    let mut metadata = record::provenance_metadata(&crate::Provenance::current());
    metadata.insert("run".to_owned(), format!("cortex replay {} --transport rtps", log.file));
    metadata.insert("agents".to_owned(), settings.agents.to_string());
    metadata.insert(
        "recorded".to_owned(),
        "the deltas the bridge agent published (log time: when its update returned, after publication) and \
         published bytes per 100 ms; latencies of RTPS runs are measured by cortex report"
            .to_owned(),
    );
    let mut recorder = RunRecorder::create(path, metadata)?;
    recorder.add_delta_channel("replay::bridge::dictionary()")?;
    let clock = crate::MonoClock::start();
    let mut index = 0u64;
    let mut on_deltas = |deltas: &[Arc<dsr::Delta>]| -> anyhow::Result<()> {
        let now = clock.now_ns();
        for delta in deltas {
            recorder.delta(index, now, &delta.encode())?;
            index += 1;
        }
        Ok(())
    };
    let played = play_log(bridge, log, options, rate, loops, &stop, &mut on_deltas)?;
    let counts = record::finish_file(recorder).with_context(|| format!("cannot write {}", path.display()))?;
    Ok((played, Some((path.clone(), counts))))
}

/// Waits, from the quiesce until `settle` after it, for every one of `count` processes to report the bridge's
/// digest; the last status of each (reported after the quiesce: the roles may have been writing before it) and the
/// milliseconds from the quiesce to convergence, if reached.
fn wait_converged(
    bridge: &Agent<AgentTransport>,
    statuses: &mpsc::Receiver<(u32, StatusLine)>,
    count: usize,
    quiesced: Instant,
    settle: Duration,
) -> (BTreeMap<u32, StatusLine>, Option<f64>) {
    let deadline = quiesced + settle;
    let mut last = BTreeMap::new();
    while Instant::now() < deadline {
        let Ok((id, status)) = statuses.recv_timeout(Duration::from_millis(50)) else { continue };
        last.insert(id, status);
        let Some(target) = bridge.digest().map(|d| d.to_string()) else { continue };
        if last.len() == count && last.values().all(|s| s.digest.as_deref() == Some(target.as_str())) {
            return (last, Some(ms_from_duration(quiesced.elapsed())));
        }
    }
    (last, None)
}

/// The bridge agent's row.
fn bridge_row(bridge: &Agent<AgentTransport>) -> AgentRow {
    let status = bridge.status();
    AgentRow {
        id: 1,
        role: "bridge".to_owned(),
        nodes: status.nodes as u64,
        digest: bridge.digest().map_or_else(|| "none".to_owned(), |d| d.to_string()),
        samples_received: status.transport.samples_received,
        samples_sent: status.transport.samples_sent,
        components: Vec::new(),
        components_error: None,
    }
}

/// An agent process's row from its last status and its role's statistics (if it has a role).
fn process_row(
    proc: &AgentProcess,
    status: &StatusLine,
    components: Option<Result<Vec<ComponentRow>, String>>,
) -> AgentRow {
    let (components, components_error) = match components {
        Some(Ok(components)) => (components, None),
        Some(Err(error)) => (Vec::new(), Some(error)),
        None => (Vec::new(), None),
    };
    AgentRow {
        id: proc.id,
        role: proc.role.clone(),
        nodes: status.nodes as u64,
        digest: status.digest.clone().unwrap_or_else(|| "none".to_owned()),
        samples_received: status.samples_received,
        samples_sent: status.samples_sent,
        components,
        components_error,
    }
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

    #[test]
    fn settings_with_too_many_roles_or_agents_out_of_range_are_refused() {
        let mut settings = RtpsReplay {
            agents: 2,
            domain: 0,
            roles: vec!["attention".parse().unwrap(), "camera-detector".parse().unwrap()],
            faults: None,
            bridge: replay::BridgeOptions::default(),
            rate: replay::Rate::Max,
            loops: 1,
            settle: Duration::from_secs(1),
            record: None,
            program: PathBuf::from("/nonexistent/cortex"),
            quiet_agents: true,
        };
        let error = check(&settings).unwrap_err().to_string();
        assert!(error.contains("2 roles given for 1 agent processes"), "{error}");
        settings.roles.pop();
        assert!(check(&settings).is_ok());
        settings.agents = 65;
        assert!(check(&settings).unwrap_err().to_string().contains("between 1 and 64"));
        settings.agents = 0;
        assert!(check(&settings).unwrap_err().to_string().contains("between 1 and 64"));
    }
}
