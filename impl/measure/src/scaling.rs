//! How control traffic grows with the number of agents: N real [`agent::Agent`]s on the in-process bus, driven
//! by hand on one manual clock (the seeded simulator of `impl/agent/tests/simulation.rs`), every sample counted
//! by message kind as it is published and as each agent takes it off its inbox.
//!
//! A run: N agents start together; agent 1 starts the graph alone at once and the others join it; each
//! writer inserts one node; then, in the measured window, the writers take turns writing a float attribute of their
//! own node at the experiment's total rate. The window's traffic by kind is the row. After the window the agents
//! run on (no writes) until every digest is equal, or a bounded settling time passes.
//!
//! The bus hands every sample to every other endpoint (it has no directed writes: RTPS sends an answer to the
//! asker alone), so "received" counts every agent's inbox. Nothing here reads the real clock: the same seed gives
//! the same counts.

use std::collections::BTreeMap;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use agent::envelope::Envelope;
use agent::{Agent, AgentConfig, AgentId};
use anyhow::Context as _;
use bytes::Bytes;
use dsr::{NewNode, NodeId, attrs};
use transport::inproc::{Bus, InProcTransport};
use transport::{Channel, EndpointId, ManualClock, Sample, Transport, TransportError, TransportStats};

use crate::results::{KindTraffic, ScalingResult, ScalingRow};
use crate::spec::ScalingExperiment;

/// One simulated step: every agent is pumped once per step.
const STEP_NS: u64 = 1_000_000;
/// Inbox capacity of each agent on the bus. A pump empties the inbox, so between two of an agent's pumps it holds
/// at most what the group publishes in one step (a few samples per agent). A full inbox would drop, and this measures
/// traffic, not loss: a run that dropped any sample is an error, not a row. The bus allocates and touches every
/// slot up front (about 80 bytes each), so this is also the run's memory: 2^14 slots are 1.3 MB an agent, where
/// 2^20 were 84 MB an agent and 10.8 GB at 128 agents.
const INBOX_SAMPLES: usize = 1 << 14;
/// Longest the agents are given to join, and to settle after the window, ms of simulated time.
const SETTLE_LIMIT_MS: u64 = 30_000;
/// Name of the one kind counted for bytes that are not an agent envelope (none are expected).
const NOT_AN_ENVELOPE: &str = "not an envelope";

/// Traffic by message kind, shared by every counting endpoint of a run.
type Tally = Arc<Mutex<BTreeMap<&'static str, KindTraffic>>>;

/// A transport that counts what passes through it by envelope kind.
struct Counted {
    inner: InProcTransport,
    tally: Tally,
}

impl Counted {
    fn count(&self, bytes: &Bytes, sent: bool) {
        let kind = Envelope::decode(bytes).map_or(NOT_AN_ENVELOPE, |envelope| envelope.message.kind());
        let mut tally = self.tally.lock().unwrap_or_else(|p| p.into_inner());
        let entry = tally.entry(kind).or_default();
        let len = bytes.len() as u64;
        if sent {
            entry.samples_sent += 1;
            entry.bytes_sent += len;
        } else {
            entry.samples_received += 1;
            entry.bytes_received += len;
        }
    }
}

impl Transport for Counted {
    fn local_id(&self) -> EndpointId {
        self.inner.local_id()
    }

    fn publish(&self, channel: Channel, bytes: Bytes) -> Result<(), TransportError> {
        self.count(&bytes, true);
        self.inner.publish(channel, bytes)
    }

    fn try_recv(&self) -> Option<Sample> {
        let sample = self.inner.try_recv()?;
        self.count(&sample.bytes, false);
        Some(sample)
    }

    fn recv_timeout(&self, timeout: Duration) -> Option<Sample> {
        let sample = self.inner.recv_timeout(timeout)?;
        self.count(&sample.bytes, false);
        Some(sample)
    }

    fn stats(&self) -> TransportStats {
        self.inner.stats()
    }
}

/// Runs every number of agents of `experiment`, calling `progress` after each.
///
/// # Errors
/// The experiment's numbers are invalid (see [`ScalingExperiment::validate`]), or a run's agents do not all join
/// in time.
pub fn run(experiment: &ScalingExperiment, progress: &mut dyn FnMut(&str)) -> anyhow::Result<ScalingResult> {
    experiment.validate()?;
    let mut rows = Vec::new();
    for &agents in &experiment.agents {
        rows.push(
            run_one(experiment, agents, INBOX_SAMPLES)
                .with_context(|| format!("control traffic with {agents} agents"))?,
        );
        progress(&format!("control traffic N={agents}"));
    }
    Ok(ScalingResult { experiment: experiment.clone(), rows })
}

/// N agents on one bus and clock.
struct Group {
    clock: ManualClock,
    agents: Vec<Agent<Counted>>,
    tally: Tally,
}

impl Group {
    fn new(experiment: &ScalingExperiment, n: u32, inbox_samples: usize) -> anyhow::Result<Group> {
        let bus = Bus::new();
        let clock = ManualClock::new(1_000_000_000);
        let tally = Tally::default();
        let mut agents = Vec::new();
        for id in 1..=n {
            let config = AgentConfig {
                announce_period: Duration::from_millis(experiment.announce_ms),
                announce_group: experiment.announce_group,
                nonce: Some(experiment.seed.wrapping_mul(0x9E37_79B9_7F4A_7C15).wrapping_add(u64::from(id)) | 1),
                // Agent 1 starts the graph at its first pump, before anything reaches it; the others join it,
                // asking again every 20 ms until it answers.
                join_wait: if id == 1 { Duration::ZERO } else { Duration::from_millis(SETTLE_LIMIT_MS) },
                join_retry: Duration::from_millis(20),
                ..AgentConfig::new(AgentId(id))
            };
            let transport = Counted { inner: bus.attach(inbox_samples), tally: Arc::clone(&tally) };
            agents.push(Agent::new(config, transport, Arc::new(clock.clone()))?);
        }
        Ok(Group { clock, agents, tally })
    }

    fn step(&self) {
        self.clock.advance(STEP_NS);
        for agent in &self.agents {
            agent.pump();
        }
    }

    /// Steps until `done` holds, at most `limit_ms`; returns whether it held.
    fn run_until(&self, limit_ms: u64, done: impl Fn(&Group) -> bool) -> bool {
        for _ in 0..limit_ms {
            if done(self) {
                return true;
            }
            self.step();
        }
        done(self)
    }

    fn converged(&self) -> bool {
        let first = self.agents[0].digest();
        first.is_some() && self.agents.iter().all(|agent| agent.digest() == first)
    }
}

fn run_one(experiment: &ScalingExperiment, n: u32, inbox_samples: usize) -> anyhow::Result<ScalingRow> {
    let group = Group::new(experiment, n, inbox_samples)?;
    let all_ready = |g: &Group| g.agents.iter().all(|agent| agent.is_ready());
    anyhow::ensure!(group.run_until(SETTLE_LIMIT_MS, all_ready), "not every agent joined");
    let writers = experiment.writers.min(n) as usize;
    let mut nodes: Vec<NodeId> = Vec::with_capacity(writers);
    for (i, agent) in group.agents[..writers].iter().enumerate() {
        nodes.push(agent.insert_node(NewNode::new("object", &format!("writer_{}", i + 1)).with_attr("pos_x", 0.0f32))?);
    }
    group.run_until(SETTLE_LIMIT_MS, Group::converged);
    group.tally.lock().unwrap_or_else(|p| p.into_inner()).clear();
    let writes = write_window(&group, experiment, &nodes)?;
    let kinds = std::mem::take(&mut *group.tally.lock().unwrap_or_else(|p| p.into_inner()));
    let converged = group.run_until(SETTLE_LIMIT_MS, Group::converged);
    let dropped: u64 = group.agents.iter().map(|agent| agent.transport().stats().dropped_full).sum();
    anyhow::ensure!(
        dropped == 0,
        "{dropped} samples found an agent's inbox of {inbox_samples} full: the counts would be short"
    );
    Ok(ScalingRow {
        agents: n,
        window_ms: experiment.window_ms,
        writes,
        kinds: kinds.into_iter().map(|(kind, traffic)| (kind.to_owned(), traffic)).collect(),
        converged,
    })
}

/// The measured window: writers take turns at the total rate, one float each. Returns the writes made.
fn write_window(group: &Group, experiment: &ScalingExperiment, nodes: &[NodeId]) -> anyhow::Result<u64> {
    let interval_ns = (1e9 / experiment.write_rate_hz).max(1.0);
    let mut next_write_ns = 0.0f64;
    let mut writes = 0u64;
    for step in 0..experiment.window_ms {
        let elapsed_ns = (step * STEP_NS) as f64;
        while next_write_ns <= elapsed_ns {
            let writer = writes as usize % nodes.len();
            let value = (experiment.seed.wrapping_add(writes) % 1_000) as f32;
            group.agents[writer].set_attr(nodes[writer], attrs::POS_X, value)?;
            writes += 1;
            next_write_ns += interval_ns;
        }
        group.step();
    }
    Ok(writes)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::results::{CONTROL_KINDS, DATA_KINDS};

    fn experiment(agents: Vec<u32>) -> ScalingExperiment {
        ScalingExperiment {
            agents,
            writers: 2,
            write_rate_hz: 50.0,
            window_ms: 2_000,
            announce_ms: 500,
            announce_group: 8,
            seed: 7,
        }
    }

    #[test]
    fn every_write_reaches_every_other_agent_once_and_the_group_converges() {
        let result = run(&experiment(vec![3, 5]), &mut |_| {}).unwrap();
        for row in &result.rows {
            assert!(row.converged, "{} agents did not converge", row.agents);
            assert_eq!(row.writes, 100, "2 s at 50 Hz");
            let data = row.sum(DATA_KINDS);
            assert_eq!(data.samples_sent, row.writes, "one delta per write");
            assert_eq!(data.samples_received, row.writes * u64::from(row.agents - 1), "the bus reaches every other");
        }
    }

    #[test]
    fn a_run_that_drops_a_sample_is_an_error_not_a_row() {
        let error = run_one(&experiment(vec![5]), 5, 2).unwrap_err();
        assert!(format!("{error:#}").contains("inbox of 2 full"), "{error:#}");
    }

    #[test]
    fn the_same_seed_gives_the_same_counts() {
        let a = run(&experiment(vec![4]), &mut |_| {}).unwrap();
        let b = run(&experiment(vec![4]), &mut |_| {}).unwrap();
        assert_eq!(a, b);
    }

    #[test]
    fn announces_are_counted_as_control_traffic() {
        let result = run(&experiment(vec![3]), &mut |_| {}).unwrap();
        let control = result.rows[0].sum(CONTROL_KINDS);
        assert!(control.samples_sent > 0, "periodic announces in a 2 s window: {:?}", result.rows[0].kinds);
        assert!(!result.rows[0].kinds.contains_key(NOT_AN_ENVELOPE));
    }

    #[test]
    fn an_experiment_with_one_agent_is_refused_with_its_number() {
        let error = run(&experiment(vec![1]), &mut |_| {}).unwrap_err();
        assert!(error.to_string().contains("1 agents"), "{error}");
    }
}
