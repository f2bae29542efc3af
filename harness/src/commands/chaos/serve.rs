//! `cortex chaos-agent`: one agent process of a chaos campaign. It runs a DSR_d agent over RTPS, prints its status
//! every `--status-ms` and answers the campaign's commands on standard input ([`Command`]) with [`Report`] lines on
//! standard output; end of input stops it. A malformed command is reported on standard error and skipped.

use std::io::{BufRead, Write};
use std::path::PathBuf;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use agent::rtps::AgentTransport;
use agent::{Agent, AgentConfig, AgentId};
use anyhow::{Context, Result};
use clap::Args;
use transport::rtps::RtpsConfig;

use super::protocol::{Command, FinalState, Report, parse_command};
use super::workload::Workload;

/// Arguments of `cortex chaos-agent` (started by `cortex chaos`, not by hand).
#[derive(Debug, Args)]
pub struct ChaosAgentArgs {
    /// Agent id.
    #[arg(long)]
    pub id: u32,
    /// DDS domain id.
    #[arg(long)]
    pub domain: u16,
    /// Topic name prefix.
    #[arg(long, default_value = "dsr")]
    pub topic_prefix: String,
    /// The graph the agent belongs to (see `cortex agent --graph-id`).
    #[arg(long)]
    pub graph_id: Option<agent::GraphId>,
    /// DDS Security credentials (a participant directory of `cortex security init`).
    #[arg(long)]
    pub security: Option<PathBuf>,
    /// The incarnation record of this agent (kept across its restarts).
    #[arg(long)]
    pub life_file: PathBuf,
    /// How long to wait for a running agent's graph before starting alone.
    #[arg(long, default_value_t = 2000)]
    pub join_wait_ms: u64,
    /// Period of status lines.
    #[arg(long, default_value_t = 100)]
    pub status_ms: u64,
    /// Bytes of a camera frame.
    #[arg(long, default_value_t = 307_200)]
    pub image_bytes: usize,
    /// Plant this protocol bug (an `agent::mutants::ProtocolMutant` name), so that a test can check that the
    /// campaign catches it. Only in a build with the `mutants` feature.
    #[cfg(feature = "mutants")]
    #[arg(long)]
    pub plant: Option<String>,
}

/// The protocol bug named `name` (`agent::mutants::ProtocolMutant`'s variant name).
///
/// # Errors
/// No such mutant; the message lists them.
#[cfg(feature = "mutants")]
pub fn protocol_mutant(name: &str) -> Result<agent::mutants::ProtocolMutant> {
    use agent::mutants::ProtocolMutant;
    ProtocolMutant::ALL.into_iter().find(|m| format!("{m:?}") == name).ok_or_else(|| {
        let names: Vec<String> = ProtocolMutant::ALL.iter().map(|m| format!("{m:?}")).collect();
        anyhow::anyhow!("no protocol mutant {name:?} (one of {})", names.join(", "))
    })
}

/// Runs `cortex chaos-agent`.
pub fn run(args: ChaosAgentArgs) -> Result<()> {
    let rtps = RtpsConfig {
        domain_id: args.domain,
        topic_prefix: args.topic_prefix.clone(),
        security: crate::commands::agent::security_files(args.security.as_deref())?,
        ..RtpsConfig::default()
    };
    let mut config = AgentConfig::new(AgentId(args.id));
    config.join_wait = Duration::from_millis(args.join_wait_ms);
    config.life_file = Some(args.life_file.clone());
    config.graph = args.graph_id;
    #[cfg(feature = "mutants")]
    if let Some(name) = &args.plant {
        config.plant = agent::mutants::Plant::of(Some(protocol_mutant(name)?));
    }
    // The default transport, as `cortex agent` runs it: RTPS with same-host shared memory (lanes of this network
    // namespace, so only `cortex chaos --same-host` puts peers on them); with DDS Security, RTPS alone.
    let agent = agent::Link::Auto.start(config, rtps, None).context("joining the DDS domain")?;
    let out = Arc::new(Mutex::new(std::io::stdout()));
    {
        // Prints until the process ends (its output closed, or the process exits after the input ends).
        let (agent, out) = (Arc::clone(&agent), Arc::clone(&out));
        let period = Duration::from_millis(args.status_ms.max(1));
        let started = std::time::Instant::now();
        std::thread::spawn(move || {
            while print(&out, &Report::Status(agent.status_line(started.elapsed().as_millis() as u64))).is_ok() {
                std::thread::sleep(period);
            }
        });
    }
    let workload = Workload { agent: args.id, image_bytes: args.image_bytes };
    for line in std::io::stdin().lock().lines() {
        let line = line.context("reading standard input")?;
        if line.trim().is_empty() {
            continue;
        }
        let report = match parse_command(&line) {
            Ok(Command::Write { seq, draw }) => write(&agent, workload, seq, draw),
            Ok(Command::Final) => Report::Final(final_state(&agent)),
            Err(error) => {
                eprintln!("chaos-agent {}: {error}", args.id);
                continue;
            }
        };
        print(&out, &report).context("writing standard output")?;
    }
    agent.shutdown();
    Ok(())
}

fn print(out: &Mutex<std::io::Stdout>, report: &Report) -> std::io::Result<()> {
    let line = serde_json::to_string(report).map_err(std::io::Error::other)?;
    let mut out = out.lock().unwrap_or_else(|p| p.into_inner());
    writeln!(out, "{line}")?;
    out.flush()
}

fn write(agent: &Agent<AgentTransport>, workload: Workload, seq: u64, draw: u64) -> Report {
    let outcome = agent.update(|replica, now_ns| match workload.write(replica, now_ns, seq, draw) {
        Ok((record, delta)) => (Ok(record), vec![delta]),
        Err(reason) => (Err(reason), Vec::new()),
    });
    match outcome {
        Ok(Ok(record)) => Report::Wrote(record),
        Ok(Err(reason)) => Report::Skipped { seq, reason },
        Err(error) => Report::Skipped { seq, reason: error.to_string() },
    }
}

fn final_state(agent: &Agent<AgentTransport>) -> FinalState {
    let state = agent.read(final_state_of).unwrap_or(FinalState {
        graph: None,
        digest: None,
        full_digest: None,
        applied: None,
        nodes: 0,
        edges: 0,
    });
    FinalState { graph: agent.status().graph, ..state }
}

/// The final state of `replica` (its graph id is the agent's, not the replica's: `None` here).
pub fn final_state_of(replica: &dsr::Replica) -> FinalState {
    let digest = replica.digest();
    FinalState {
        graph: None,
        digest: Some(digest.to_string()),
        full_digest: Some(digest.0.iter().map(|b| format!("{b:02x}")).collect()),
        applied: Some(replica.applied().clone()),
        nodes: replica.nodes().count(),
        edges: replica.edges().count(),
    }
}
