//! The time for a new agent process to receive and rebuild a graph of N nodes: the snapshot's encoding and
//! rebuilding in this process, then a joining process (the helper of `bench join-child`, [`child`]) that reports
//! its milestones as a typed [`JoinChildReport`], broken down against the serving agent's own times.

use std::io::{BufRead as _, BufReader};
use std::path::Path;
use std::sync::Arc;
use std::time::{Duration, Instant};

use agent::{Agent, AgentConfig, AgentId, AnswerTiming};
use anyhow::{Context as _, bail};
use dsr::{NewNode, NodeId, Replica, Value};
use serde::{Deserialize, Serialize};
use transport::rtps::{DiscoveryTimes, Multicast, UpdateDelivery};
use transport::{Channel, Clock, SystemClock, Transport};

use super::helper::{self, Helper};
use super::{Credentials, loadavg, rtps_secured};
use crate::units::ms_from_duration;

/// What `cortex bench join --json` prints.
#[derive(Debug, Serialize)]
pub struct JoinResult {
    /// Nodes in the graph.
    pub nodes: u32,
    /// Bytes of its snapshot.
    pub snapshot_bytes: usize,
    /// Encoding the snapshot in this process, ms.
    pub snapshot_encode_ms: f64,
    /// Encoding, decoding and joining it into an empty replica in this process, ms.
    pub snapshot_encode_decode_join_ms: f64,
    /// What the joining process reported.
    pub process: JoinChildReport,
    /// The join step by step.
    pub breakdown: JoinBreakdown,
    /// The machine's load average when the join ended.
    pub loadavg: String,
}

/// What the joining process reports: its own steps and discovery, in ns since the Unix epoch.
#[derive(Clone, Debug, Default, Serialize, Deserialize, PartialEq, Eq)]
pub struct JoinChildReport {
    /// Visible nodes once ready.
    pub nodes: usize,
    /// Whether all nodes arrived.
    pub complete: bool,
    /// `main` of the helper ran (the binary was loaded).
    pub main_ns: u64,
    /// The RTPS participant, topics, readers and writers exist.
    pub participant_ns: u64,
    /// The first remote participant was discovered.
    pub peer_discovered_ns: Option<u64>,
    /// The helper's requests writer matched a remote reader (its graph request, on `Channel::Requests`, can be
    /// heard).
    pub sync_writer_matched_ns: Option<u64>,
    /// The helper's sync reader matched a remote writer (the answer can reach it).
    pub sync_reader_matched_ns: Option<u64>,
    /// Graph requests published.
    pub join_requests: u32,
    /// The first graph request published.
    pub first_request_ns: Option<u64>,
    /// The last graph request published.
    pub last_request_ns: Option<u64>,
    /// The answer reached the agent.
    pub answer_received_ns: Option<u64>,
    /// The snapshot was decoded.
    pub decoded_ns: Option<u64>,
    /// The replica was built: the agent became ready.
    pub ready_ns: Option<u64>,
    /// `wait_ready` returned in the helper's main thread.
    pub ready_seen_ns: u64,
}

/// The join, step by step, in ms since the parent spawned the joining process (`at_ms`) and as durations.
#[derive(Debug, Serialize, PartialEq)]
pub struct JoinBreakdown {
    /// Milestones since the spawn, in order: name and ms (absent when not reached or not known).
    pub at_ms: Vec<(&'static str, Option<f64>)>,
    /// Spawn → ready: what a user waits for.
    pub total_ms: Option<f64>,
    /// Participant created → the sync channel matched both ways (rustdds discovery).
    pub discovery_ms: Option<f64>,
    /// The answered request reached the server → the joiner was ready (encode, transfer, decode, join).
    pub request_to_ready_ms: Option<f64>,
    /// Server: request received → encoded snapshot ready.
    pub server_encode_ms: Option<f64>,
    /// Whether the server took the snapshot from its cache.
    pub server_snapshot_cached: Option<bool>,
    /// Server: snapshot ready → publish returned.
    pub server_publish_ms: Option<f64>,
    /// Snapshot ready at the server → answer taken from the joiner's inbox.
    pub transfer_ms: Option<f64>,
    /// Joiner: answer received → snapshot decoded.
    pub decode_ms: Option<f64>,
    /// Joiner: decoded → replica built and ready.
    pub join_ms: Option<f64>,
}

impl JoinBreakdown {
    /// The breakdown of a join whose process was spawned at `spawned_ns` (system clock, ns since the Unix epoch),
    /// from the joiner's report and the server's answer and discovery times. Pure.
    pub fn new(
        spawned_ns: u64,
        child: &JoinChildReport,
        answer: Option<&AnswerTiming>,
        server_discovery: DiscoveryTimes,
    ) -> JoinBreakdown {
        // Signed: the two processes' milestones may be read in either order.
        let ms_between = |from: u64, to: u64| (to as f64 - from as f64) / 1e6;
        let since = |t: Option<u64>| t.map(|t| ms_between(spawned_ns, t));
        let between = |a: Option<u64>, b: Option<u64>| Some(ms_between(a?, b?));
        let sync_matched = match (child.sync_writer_matched_ns, child.sync_reader_matched_ns) {
            (Some(w), Some(r)) => Some(w.max(r)),
            _ => None,
        };
        let sync = Channel::Sync.index();
        JoinBreakdown {
            at_ms: vec![
                ("main", since(Some(child.main_ns))),
                ("participant created", since(Some(child.participant_ns))),
                ("first graph request", since(child.first_request_ns)),
                ("peer discovered", since(child.peer_discovered_ns)),
                ("server: sync writer matched joiner", since(server_discovery.writer_matched_ns[sync])),
                ("joiner: sync writer matched", since(child.sync_writer_matched_ns)),
                ("joiner: sync reader matched", since(child.sync_reader_matched_ns)),
                ("last graph request", since(child.last_request_ns)),
                ("server: request received", since(answer.map(|a| a.request_received_ns))),
                ("server: snapshot encoded", since(answer.map(|a| a.snapshot_ready_ns))),
                ("server: answer published", since(answer.map(|a| a.published_ns))),
                ("joiner: answer received", since(child.answer_received_ns)),
                ("joiner: decoded", since(child.decoded_ns)),
                ("joiner: ready", since(child.ready_ns)),
                ("joiner: ready seen by wait_ready", since(Some(child.ready_seen_ns))),
            ],
            total_ms: since(child.ready_ns),
            discovery_ms: between(Some(child.participant_ns), sync_matched),
            request_to_ready_ms: between(answer.map(|a| a.request_received_ns), child.ready_ns),
            server_encode_ms: answer.map(|a| ms_between(a.request_received_ns, a.snapshot_ready_ns)),
            server_snapshot_cached: answer.map(|a| a.from_cache),
            server_publish_ms: answer.map(|a| ms_between(a.snapshot_ready_ns, a.published_ns)),
            transfer_ms: between(answer.map(|a| a.snapshot_ready_ns), child.answer_received_ns),
            decode_ms: between(child.answer_received_ns, child.decoded_ns),
            join_ms: between(child.decoded_ns, child.ready_ns),
        }
    }
}

fn agent_config(id: u32, join_wait: Duration) -> AgentConfig {
    let mut config = AgentConfig::new(AgentId(id));
    config.join_wait = join_wait;
    config
}

fn transport(domain: u16, prefix: &str, security: Option<&Path>) -> anyhow::Result<transport::rtps::RtpsTransport> {
    rtps_secured(domain, prefix, Multicast::Auto, UpdateDelivery::Reliable, security)
}

/// Builds the join benchmark's graph: a tree with 6 attributes and one RT edge per node.
fn build_tree<T: Transport>(agent: &Agent<T>, nodes: u32) -> anyhow::Result<()> {
    let mut ids: Vec<NodeId> = Vec::with_capacity(nodes as usize);
    for i in 0..nodes {
        let parent = if i == 0 { None } else { Some(ids[((i - 1) / 4) as usize]) };
        let node = NewNode::new(if i == 0 { "world" } else { "object" }, &format!("n{i}"))
            .with_attr("pos_x", i as f32)
            .with_attr("pos_y", -(i as f32))
            .with_attr("level", if i == 0 { 0 } else { 1 + (i as f64).log(4.0) as i32 })
            .with_attr("parent", parent.map_or(0, |p| p.0))
            .with_attr("color", Value::String("SteelBlue".into()))
            .with_attr("width", 100);
        let id = agent.insert_node(node)?;
        if let Some(parent) = parent {
            agent.insert_edge(
                parent,
                id,
                "RT",
                vec![
                    ("rt_translation".into(), vec![100.0f32, 0.0, 0.0].into()),
                    ("rt_rotation_euler_xyz".into(), vec![0.0f32, 0.0, 0.1].into()),
                ],
            )?;
        }
        ids.push(id);
    }
    Ok(())
}

/// Builds a graph of `nodes` nodes in an agent of this process on `domain`, times its snapshot here, then starts
/// `program` as the joining process and breaks its join down. With `security`, both agents use DDS Security.
///
/// # Errors
/// An agent that cannot start, a graph that cannot be built or encoded, or a joining process that reports nothing.
pub fn run(nodes: u32, domain: u16, program: &Path, security: Option<&Credentials>) -> anyhow::Result<JoinResult> {
    let prefix = format!("join{}{}", std::process::id(), if security.is_some() { "sec" } else { "" });
    let transport = transport(domain, &prefix, security.map(|c| c.this.as_path()))?;
    let agent = Agent::start(agent_config(1, Duration::from_millis(300)), transport, Arc::new(SystemClock))?;
    if !agent.wait_ready(Duration::from_secs(10)) {
        bail!("the first agent did not start");
    }
    build_tree(&agent, nodes)?;
    // In-process: snapshot encode (timed inside the agent's lock, so a wait for the lock is not counted), decode
    // and join into an empty replica (the rebuild alone).
    let (bytes, encoded) = agent
        .read(|replica| {
            let started = Instant::now();
            (replica.encode_snapshot(), started.elapsed())
        })
        .context("no graph")?;
    let started = Instant::now();
    let mut fresh = Replica::new(dsr::ReplicaId(9999));
    fresh.apply(&dsr::Delta::decode(&bytes)?)?;
    let rebuilt = encoded + started.elapsed();
    // A new agent process joins; both processes read the system clock, so their times compare.
    let spawned_at_ns = SystemClock.now_ns();
    let args = helper::join_child_args(domain, &prefix, nodes, security.map(|c| c.helper.as_path()));
    let mut helper = Helper::spawn(program, &args)?;
    let stdout = helper.take_stdout().context("the joining process's standard output")?;
    let line = BufReader::new(stdout).lines().next().context("the joining process printed nothing")??;
    let child: JoinChildReport = serde_json::from_str(&line).context("the joining process's report")?;
    let server = agent.status();
    let breakdown =
        JoinBreakdown::new(spawned_at_ns, &child, server.last_answer.as_ref(), agent.transport().discovery());
    Ok(JoinResult {
        nodes,
        snapshot_bytes: bytes.len(),
        snapshot_encode_ms: ms_from_duration(encoded),
        snapshot_encode_decode_join_ms: ms_from_duration(rebuilt),
        process: child,
        breakdown,
        loadavg: loadavg(),
    })
}

/// The joining process (the helper of `bench join-child`): an agent on `domain` that joins and waits for the graph
/// (60 s at most), then reports its milestones. `expected_nodes` is what the graph should hold. With `security`, it joins with DDS Security.
///
/// # Errors
/// The transport or agent cannot start, or no graph arrives within 60 s.
pub fn child(
    domain: u16,
    prefix: &str,
    expected_nodes: usize,
    security: Option<&Path>,
) -> anyhow::Result<JoinChildReport> {
    let main_ns = SystemClock.now_ns();
    let transport = transport(domain, prefix, security)?;
    let participant_ns = transport.discovery().created_ns;
    let agent = Agent::start(agent_config(2, Duration::from_secs(60)), transport, Arc::new(SystemClock))?;
    if !agent.wait_ready(Duration::from_secs(60)) {
        bail!("no graph within 60 s");
    }
    let ready_seen_ns = SystemClock.now_ns();
    let status = agent.status();
    let discovery = agent.transport().discovery();
    let sync = Channel::Sync.index();
    Ok(JoinChildReport {
        nodes: status.nodes,
        complete: status.nodes == expected_nodes,
        main_ns,
        participant_ns,
        peer_discovered_ns: discovery.first_participant_ns,
        sync_writer_matched_ns: discovery.writer_matched_ns[Channel::Requests.index()],
        sync_reader_matched_ns: discovery.reader_matched_ns[sync],
        join_requests: status.join.requests,
        first_request_ns: status.join.first_request_ns,
        last_request_ns: status.join.last_request_ns,
        answer_received_ns: status.join.answer_received_ns,
        decoded_ns: status.join.decoded_ns,
        ready_ns: status.join.ready_ns,
        ready_seen_ns,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_breakdown_measures_each_step_from_the_spawn() {
        let ms = 1_000_000;
        let child = JoinChildReport {
            nodes: 10,
            complete: true,
            main_ns: 1_000 + 5 * ms,
            participant_ns: 1_000 + 10 * ms,
            sync_writer_matched_ns: Some(1_000 + 40 * ms),
            sync_reader_matched_ns: Some(1_000 + 50 * ms),
            answer_received_ns: Some(1_000 + 70 * ms),
            decoded_ns: Some(1_000 + 72 * ms),
            ready_ns: Some(1_000 + 75 * ms),
            ready_seen_ns: 1_000 + 76 * ms,
            ..JoinChildReport::default()
        };
        let breakdown = JoinBreakdown::new(1_000, &child, None, DiscoveryTimes::default());
        assert_eq!(breakdown.total_ms, Some(75.0));
        assert_eq!(breakdown.discovery_ms, Some(40.0));
        assert_eq!((breakdown.decode_ms, breakdown.join_ms), (Some(2.0), Some(3.0)));
        assert_eq!(breakdown.request_to_ready_ms, None, "no answer timing from the server");
        assert_eq!(breakdown.at_ms[0], ("main", Some(5.0)));
        assert_eq!(breakdown.at_ms.len(), 15);
    }
}
