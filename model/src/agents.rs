//! The agents model: N real [`agent::core::AgentCore`]s — the protocol the running agents execute, unchanged —
//! exchanging real encoded messages over a network the checker controls.
//!
//! The checker chooses every step: deliver any message in flight (so the network reorders), lose one or deliver
//! one twice (within budgets), tick an agent (its clock jumps to its next deadline, so clocks advance and skew per
//! agent), a local write (insert a node, write an attribute, link two nodes, delete a node), crash an agent (its
//! messages in flight to it are lost) and restart it as a new life (reading the incarnation its previous life
//! recorded, as the shell does), cut the network between two groups of agents and heal it, and stop a joining
//! agent's process (`SIGSTOP`: it neither ticks, writes nor takes a message) and resume it after [`STOP_NS`], longer
//! than its join wait, when its first act is a tick that late. Every message is
//! encoded with [`agent::envelope::Message::encode`] when sent and decoded (envelope and deltas) when delivered.
//!
//! Agent 0 is the first agent of the system: it starts alone at its first tick. The others start joining and take
//! the graph from whoever answers; a restarted agent joins again.
//!
//! **Properties, on every state.** No two lives share a replica id (so no two ever mint the same dot or node id);
//! every buffer stays within its limit; every replica's invariants hold; a delta that shows a gap in its writer's
//! operations is asked for at once; a delta received while joining is joined when the life becomes ready. And the
//! bounded liveness property, checked from every state: **if the faults stop there** (the cut heals, nothing more
//! is lost, crashed agents stay down), then within [`SETTLE_ROUNDS`] rounds of timers — each live agent's clock
//! moves one join retry and it ticks, then every message is delivered — every live agent is ready, all are in one graph
//! and have equal digests, each
//! equals the reference specification ([`crate::spec`]) of the operations it has joined, and those include every
//! write a live life made (nothing lost, nothing resurrected); and a joiner that still had a graph request to make
//! before its join wait ran out, with a ready agent alive, becomes ready from that agent's graph, not alone.

use std::collections::BTreeSet;
use std::sync::Arc;

use agent::AgentId;
use agent::core::{AgentCore, Dest, Event, Input, LifeSeed, Output, ProtocolConfig};
use agent::envelope::Message;
use agent::mutants::Plant;
use bytes::Bytes;
use dsr::{Dot, EdgeKey, Element, LogLimits, Name, NewNode, NodeId, ReplicaId, Value};
use serde::Serialize;
use stateright::{Model, Property};

use crate::report::{CheckOptions, CheckReport, run_check};
use crate::spec::{self, OpKind, OpRecord};

mod display;
pub mod properties;

/// Rounds of timers after the faults stop within which everything must settle (each moves every clock by one
/// join retry, so three announce periods).
pub const SETTLE_ROUNDS: usize = 6;
/// Join retry period of the modelled agents.
const RETRY_NS: u64 = 20_000_000;
/// Join wait of the joiners: three retries, then alone.
const JOIN_WAIT_NS: u64 = 3 * RETRY_NS;
/// Announce period.
const ANNOUNCE_NS: u64 = 40_000_000;
/// How long a stopped agent's process stays stopped: twice the join wait, so a joiner that counted the time against
/// its wait would find it over at once on resume.
pub const STOP_NS: u64 = 2 * JOIN_WAIT_NS;

/// Configuration of the agents model: the number of agents and the budgets of the checker's choices.
#[derive(Clone, Debug, PartialEq, Eq, Hash, Serialize)]
pub struct AgentsConfig {
    /// Number of agents.
    pub agents: usize,
    /// What the checker may spend on one path.
    #[serde(flatten)]
    pub budgets: Budgets,
    /// History kept for anti-entropy (small, so answers fall back to snapshots).
    pub history: usize,
    /// Agents per announce group ([`agent::config::AgentConfig::announce_group`]): with fewer than there are
    /// agents, each agent stretches its periodic announce to `period × ⌈agents / group⌉` once it has heard its
    /// peers, as the running agents of a large group do.
    pub announce_group: u32,
    /// Announce intervals of silence after which an agent forgets a peer
    /// ([`agent::core::ProtocolConfig::peer_forget_intervals`]). The running agents wait 4; the model's default, 1,
    /// lets the checker's few ticks reach a forgetting, so that the interval's changes with it are checked too.
    pub peer_forget_intervals: u64,
    /// Whether the agents name no graph (`cortex agent` without `--graph-id`): each first life takes the graph of
    /// whoever answers, and one that starts alone under a cut makes a graph of its own, unnamed, which moves once
    /// the agents hear each other (`agent::core`, **Graphs**). A restarted agent names the graph its previous life
    /// recorded if named, as the shell does, and starts alone in an unnamed one it recorded if it hears no graph. Off, every agent names the one graph, as the
    /// agents of one deployment do.
    pub unnamed: bool,
    /// A planted protocol bug (with the `mutants` feature).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mutant: Option<String>,
    /// The planted bug itself.
    #[serde(skip)]
    #[cfg(feature = "mutants")]
    pub planted: Option<agent::mutants::ProtocolMutant>,
}

impl Default for AgentsConfig {
    fn default() -> Self {
        AgentsConfig {
            agents: 2,
            budgets: Budgets { writes: 2, losses: 1, duplicates: 0, crashes: 1, cuts: 1, ticks: 4, stops: 0 },
            history: 2,
            announce_group: agent::config::DEFAULT_ANNOUNCE_GROUP,
            peer_forget_intervals: 1,
            unnamed: false,
            mutant: None,
            #[cfg(feature = "mutants")]
            planted: None,
        }
    }
}

impl AgentsConfig {
    /// This configuration with `mutant` planted.
    #[cfg(feature = "mutants")]
    pub fn with_mutant(mut self, mutant: agent::mutants::ProtocolMutant) -> Self {
        self.mutant = Some(format!("{mutant:?}"));
        self.planted = Some(mutant);
        self
    }

    fn plant(&self) -> Plant {
        #[cfg(feature = "mutants")]
        {
            Plant::of(self.planted)
        }
        #[cfg(not(feature = "mutants"))]
        {
            Plant::NONE
        }
    }

    /// The protocol settings of agent `index`, whose previous life recorded graph `recorded` (if named).
    fn protocol(&self, index: usize, recorded: Option<agent::GraphId>) -> ProtocolConfig {
        ProtocolConfig {
            id: AgentId(index as u32 + 1),
            graph: if self.unnamed { recorded } else { Some(MODEL_GRAPH) },
            join_wait_ns: if index == 0 { 0 } else { JOIN_WAIT_NS },
            join_retry_ns: RETRY_NS,
            announce_period_ns: ANNOUNCE_NS,
            // The running agents' default (8) is more than the model's agents, so every agent announces every
            // period unless the configuration sets a smaller group (`AgentCore::announce_interval_ns`).
            announce_group: self.announce_group,
            peer_forget_intervals: self.peer_forget_intervals,
            quiet_announce_ns: ANNOUNCE_NS / 4,
            log_limits: LogLimits { max_deltas: self.history, max_payload_bytes: 1 << 20, fold_min_payload_bytes: 0 },
            max_buffered_deltas: 16,
            max_batch_bytes: 256 << 10,
            answer_hold_ns: RETRY_NS,
            read_only: false,
            plant: self.plant(),
        }
    }
}

/// The graph the model's agents belong to.
const MODEL_GRAPH: agent::GraphId = match agent::GraphId::new(0x6d) {
    Some(graph) => graph,
    None => panic!("a graph id is not zero"),
};

/// One message in flight: encoded, from one agent to one agent.
#[derive(Clone, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Envelope {
    /// Sender.
    pub from: usize,
    /// Receiver.
    pub to: usize,
    /// The channel it was sent on (the receiver admits it by channel, as a running agent does).
    pub channel: transport::Channel,
    /// The encoded message.
    pub bytes: Bytes,
}

/// One agent slot: its current life (none while crashed) and what survives a crash.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct Slot {
    /// The running life.
    pub core: Option<AgentCore>,
    /// The agent's clock.
    pub now_ns: u64,
    /// The incarnation its lives recorded (the shell's life file).
    pub record: Option<u32>,
    /// The graph its lives recorded: the latest life's, and whether it is named.
    pub recorded_graph: Option<(agent::GraphId, bool)>,
    /// Lives started so far.
    pub lives: u32,
    /// Dots of deltas received while the current life was joining, with their graph.
    pub early: BTreeSet<(Option<agent::GraphId>, Dot)>,
    /// Whether its process is stopped now (it neither ticks, writes nor takes a message).
    pub stopped: bool,
    /// Whether the current life's process was stopped while it joined.
    pub stopped_joining: bool,
}

/// Which checks failed, as bits, with what was seen.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Check {
    /// Two lives took one replica id.
    UniqueLives,
    /// A buffer went past its limit.
    Bounded,
    /// A replica's invariants broke, or a delta was refused.
    Invariants,
    /// A delta showing a gap was not asked for at once.
    GapAsked,
    /// A delta received while joining was not joined when the life became ready.
    EarlyDeltasKept,
}

impl Check {
    fn bit(self) -> u8 {
        1 << (self as u8)
    }
}

/// A state of the agents model.
#[derive(Clone, PartialEq, Eq, Hash)]
pub struct AgentsState {
    /// The agents.
    pub slots: Vec<Slot>,
    /// Messages in flight, kept sorted (a multiset).
    pub network: Vec<Envelope>,
    /// Every write made, in order.
    pub history: Vec<Arc<OpRecord>>,
    /// Every life that became ready.
    pub lives: Vec<Life>,
    /// The current cut: agents on one side as bits (none when whole).
    pub cut: Option<u8>,
    /// Budgets spent.
    pub spent: Budgets,
    /// Failed checks, as bits, and what was seen (the path ends at the first).
    pub violated: u8,
    /// What the failed checks saw.
    pub findings: Vec<String>,
    /// Witnesses seen on the path.
    pub witnessed: BTreeSet<Witness>,
}

impl AgentsState {
    /// Whether `check` has not failed on the path to this state.
    pub fn holds(&self, check: Check) -> bool {
        self.violated & check.bit() == 0
    }
}

/// A life that became ready.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Life {
    /// The agent.
    pub agent: usize,
    /// Its life number (from 1).
    pub life: u32,
    /// The replica id it took.
    pub replica: ReplicaId,
    /// It started alone.
    pub alone: bool,
    /// It started alone while another agent was ready.
    pub alone_beside_ready: bool,
    /// Its process was stopped while it joined.
    pub stopped_joining: bool,
}

/// Counts of the checker's choices: what a configuration allows on one path, and what a state has spent.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize)]
pub struct Budgets {
    /// Local writes, shared by all agents.
    pub writes: usize,
    /// Messages the network loses.
    pub losses: usize,
    /// Messages the network delivers twice.
    pub duplicates: usize,
    /// Crashes (each followed, when the checker chooses, by a restart as a new life).
    pub crashes: usize,
    /// Network cuts (each heals when the checker chooses).
    pub cuts: usize,
    /// Timer ticks, shared by all agents (the settling rounds after the faults are not counted).
    pub ticks: usize,
    /// Stops of a joining agent's process (each resumed when the checker chooses, or when the faults stop).
    pub stops: usize,
}

/// Transient things that happened on a path (for the `sometimes` properties; lives are in [`AgentsState::lives`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Witness {
    /// A gap request went out.
    GapRequest,
    /// A missing-request was answered with a snapshot.
    SnapshotAnswer,
    /// An agent forgot a silent peer.
    PeerForgotten,
    /// A life whose graph was unnamed moved to another graph.
    GraphMoved,
}

/// A step the checker chooses.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub enum Action {
    /// Deliver the message at this index of the network.
    Deliver(usize),
    /// Deliver it and keep a copy in flight.
    Duplicate(usize),
    /// Lose it.
    Lose(usize),
    /// Tick an agent at its next deadline.
    Tick(usize),
    /// A local write.
    Write(usize, WriteOp),
    /// Crash an agent.
    Crash(usize),
    /// Restart a crashed agent as a new life.
    Restart(usize),
    /// Stop a joining agent's process.
    Stop(usize),
    /// Resume a stopped agent's process, [`STOP_NS`] later.
    Resume(usize),
    /// Cut the agents in the bit set from the others.
    Cut(u8),
    /// Heal the cut.
    Heal,
}

/// A local write the checker may choose.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub enum WriteOp {
    /// Insert a node named after the writer and the write number, with a `level`.
    Insert,
    /// Write `level` of a node.
    SetLevel(NodeId),
    /// Link two nodes.
    Link(NodeId, NodeId),
    /// Delete a node (and hide its edges).
    Delete(NodeId),
}

/// The agents model.
#[derive(Clone, Debug)]
pub struct AgentsModel {
    config: AgentsConfig,
}

impl AgentsModel {
    /// The model of `config`.
    pub fn new(config: AgentsConfig) -> Self {
        AgentsModel { config }
    }

    fn new_life(&self, index: usize, slot: &mut Slot) {
        slot.lives += 1;
        // The nonce tells lives apart; the record is what the previous life wrote.
        let nonce = (index as u64 + 1) << 32 | u64::from(slot.lives);
        let (named, unnamed) = match slot.recorded_graph {
            Some((graph, true)) => (Some(graph), None),
            other => (None, other.map(|(graph, _)| graph)),
        };
        let life = LifeSeed { nonce, recorded_incarnation: slot.record, recorded_graph: unnamed };
        let config = self.config.protocol(index, named);
        slot.core = Some(AgentCore::new(config, life, None, slot.now_ns));
        slot.early.clear();
        slot.stopped_joining = false;
    }

    fn fail(&self, state: &mut AgentsState, check: Check, detail: String) {
        state.violated |= check.bit();
        state.findings.push(format!("[{check:?}] {detail}"));
    }

    fn crosses_cut(cut: Option<u8>, a: usize, b: usize) -> bool {
        cut.is_some_and(|side| (side >> a & 1) != (side >> b & 1))
    }

    /// Puts an agent's output on the network and records what it reported.
    fn emit(&self, state: &mut AgentsState, from: usize, reply_to: Option<usize>, out: &Output) {
        for send in &out.sends {
            let bytes = send.encode();
            let targets: Vec<usize> = match (send.dest, reply_to) {
                (Dest::Sender, Some(to)) => vec![to],
                _ => (0..state.slots.len()).filter(|&to| to != from).collect(),
            };
            for to in targets {
                if state.slots[to].core.is_some() && !Self::crosses_cut(state.cut, from, to) {
                    state.network.push(Envelope { from, to, channel: send.channel, bytes: bytes.clone() });
                }
            }
            if matches!(send.message, Message::Snapshot { .. }) {
                state.witnessed.insert(Witness::SnapshotAnswer);
            }
        }
        state.network.sort();
        for event in &out.events {
            match event {
                Event::Rejected { what, error } => {
                    self.fail(state, Check::Invariants, format!("agent {from} refused a {what}: {error}"))
                }
                Event::GapRequest { .. } => {
                    state.witnessed.insert(Witness::GapRequest);
                }
                Event::Ready { graph, replica, incarnation, alone, named, .. } => {
                    state.slots[from].recorded_graph = Some((*graph, *named));
                    self.on_ready(state, from, *replica, *incarnation, *alone)
                }
                Event::GraphMoved { graph, named, .. } => {
                    state.slots[from].recorded_graph = Some((*graph, *named));
                    state.witnessed.insert(Witness::GraphMoved);
                }
                Event::GraphNamed { graph, .. } => state.slots[from].recorded_graph = Some((*graph, true)),
                _ => {}
            }
        }
    }

    fn on_ready(&self, state: &mut AgentsState, index: usize, replica: ReplicaId, incarnation: u32, alone: bool) {
        let life = state.slots[index].lives;
        if let Some(other) = state.lives.iter().find(|l| l.replica == replica) {
            let detail = format!(
                "agent {index} life {life} took replica {replica}, as agent {} life {} did",
                other.agent, other.life
            );
            self.fail(state, Check::UniqueLives, detail);
        }
        let others_ready =
            state.slots.iter().enumerate().any(|(i, s)| i != index && s.core.as_ref().is_some_and(AgentCore::is_ready));
        let stopped_joining = state.slots[index].stopped_joining;
        state.lives.push(Life {
            agent: index,
            life,
            replica,
            alone,
            alone_beside_ready: alone && others_ready,
            stopped_joining,
        });
        let slot = &mut state.slots[index];
        slot.record = Some(slot.record.unwrap_or(0).max(incarnation));
        let slot = &state.slots[index];
        let applied = slot.core.as_ref().and_then(|c| c.replica()).map(|r| r.applied().clone()).unwrap_or_default();
        // Deltas of another graph are refused (with agents that name no graph, one of two unnamed graphs moves
        // later, and anti-entropy brings them then).
        let graph = slot.core.as_ref().and_then(AgentCore::graph);
        let lost: Vec<Dot> = slot
            .early
            .iter()
            .filter(|(of, dot)| *of == graph && !applied.contains(*dot))
            .map(|(_, dot)| *dot)
            .collect();
        if !lost.is_empty() {
            self.fail(
                state,
                Check::EarlyDeltasKept,
                format!("agent {index} became ready without early deltas {lost:?}"),
            );
        }
        state.slots[index].early.clear();
    }

    fn deliver(&self, state: &mut AgentsState, envelope: &Envelope) {
        let to = envelope.to;
        let now = state.slots[to].now_ns;
        let Some(core) = state.slots[to].core.as_ref() else { return };
        let Ok(agent::envelope::Envelope { graph, message }) = agent::envelope::Envelope::decode(&envelope.bytes)
        else {
            return self.fail(state, Check::Invariants, format!("agent {to} could not decode an envelope"));
        };
        if message.to().is_some_and(|id| id != core.id()) {
            return;
        }
        let mut routing = Output::default();
        if !state.slots[to].core.as_mut().expect("alive").admit_channel(envelope.channel, &message, &mut routing) {
            let detail = format!("agent {to} refused a {} on channel {}", message.kind(), envelope.channel.name());
            return self.fail(state, Check::Invariants, detail);
        }
        let core = state.slots[to].core.as_ref().expect("alive");
        let decoded = Input::decode(message);
        if let Some((what, error)) = decoded.rejected.first() {
            return self.fail(state, Check::Invariants, format!("agent {to} could not decode a {what}: {error}"));
        }
        let Some(input) = decoded.input else { return };
        // A delta of another graph is refused: it asks for nothing.
        let gap = match &input {
            Input::Delta { delta, .. } => graph == core.graph() && gap_unasked(core, delta, now),
            _ => false,
        };
        if let (Input::Delta { delta, .. }, false) = (&input, core.is_ready())
            && let Some(origin) = delta.origin()
            && state.slots[to].early.len() < core.config().max_buffered_deltas
        {
            state.slots[to].early.insert((graph, Dot::new(origin.replica, origin.first)));
        }
        let core = state.slots[to].core.as_mut().expect("alive");
        let out = core.handle(now, graph, input);
        if gap && !out.sends.iter().any(|s| matches!(s.message, Message::MissingRequest { .. })) {
            self.fail(state, Check::GapAsked, format!("agent {to} joined a delta after a gap and asked nothing"));
        }
        self.emit(state, to, Some(envelope.from), &out);
    }

    fn write(&self, state: &mut AgentsState, index: usize, op: &WriteOp) {
        let n = state.spent.writes;
        let slot = &mut state.slots[index];
        let now = slot.now_ns;
        let Some(core) = slot.core.as_mut() else { return };
        let Some(replica) = core.replica() else { return };
        let past: BTreeSet<Dot> =
            state.history.iter().map(|op| op.id).filter(|id| replica.applied().contains(*id)).collect();
        let level = Value::I32(index as i32 * 10 + n as i32 + 1);
        let name = format!("n{index}_{n}");
        let kind = std::cell::RefCell::new(None);
        let result = core.write(now, |r, now| {
            let (recorded, delta) = match op {
                WriteOp::Insert => {
                    let (id, delta) =
                        r.insert_node(now, NewNode::new("object", &name).with_attr("level", level.clone()))?;
                    let attrs = vec![(Name::new("level"), level.clone())];
                    (OpKind::InsertNode { id, node_type: Name::new("object"), name: Name::new(&name), attrs }, delta)
                }
                WriteOp::SetLevel(id) => {
                    let delta = r.set_attrs(now, Element::Node(*id), [("level", level.clone())])?;
                    (
                        OpKind::SetAttr { element: Element::Node(*id), name: Name::new("level"), value: level.clone() },
                        delta,
                    )
                }
                WriteOp::Link(from, to) => {
                    let (key, delta) = r.insert_edge(now, *from, *to, "in", vec![])?;
                    (OpKind::InsertEdge { key, attrs: Vec::new() }, delta)
                }
                WriteOp::Delete(id) => (OpKind::DeleteNode { id: *id }, r.delete_node(now, *id)?),
            };
            let origin = delta.origin().expect("local deltas have an origin");
            *kind.borrow_mut() = Some((origin, r.clock(), recorded));
            Ok(((), vec![delta]))
        });
        let Ok(((), written)) = result else { return };
        let out = Output { sends: written.sends(), changes: written.changes, events: Vec::new() };
        let (origin, stamp, recorded) = kind.into_inner().expect("the write ran");
        state.history.push(Arc::new(OpRecord {
            id: Dot::new(origin.replica, origin.first),
            replica: origin.replica,
            stamp,
            past,
            kind: recorded,
        }));
        state.spent.writes += 1;
        self.emit(state, index, None, &out);
    }

    fn tick(&self, state: &mut AgentsState, index: usize) {
        let slot = &mut state.slots[index];
        let Some(core) = slot.core.as_mut() else { return };
        let deadline = core.next_deadline_ns();
        if deadline == u64::MAX {
            // Nothing will ever be due (a planted bug lost the timer): time does not jump to the end of time.
            return;
        }
        slot.now_ns = slot.now_ns.max(deadline);
        let heard = core.peers().len();
        let out = core.tick(slot.now_ns);
        if core.peers().len() < heard {
            state.witnessed.insert(Witness::PeerForgotten);
        }
        self.emit(state, index, None, &out);
    }

    /// Resumes a stopped agent: its clock has moved [`STOP_NS`], and its first act is a tick that late (its thread's
    /// sleep is long over).
    fn resume(&self, state: &mut AgentsState, index: usize) {
        let slot = &mut state.slots[index];
        slot.stopped = false;
        let Some(core) = slot.core.as_mut() else { return };
        slot.now_ns = slot.now_ns.saturating_add(STOP_NS);
        let out = core.tick(slot.now_ns);
        self.emit(state, index, None, &out);
    }

    /// The state's own checks on every state: bounded buffers and replica invariants.
    fn audit(&self, state: &mut AgentsState) {
        for (index, slot) in state.slots.clone().iter().enumerate() {
            let Some(core) = &slot.core else { continue };
            if core.buffered() > core.config().max_buffered_deltas || core.answered() > agent::core::MAX_ANSWERED {
                self.fail(state, Check::Bounded, format!("agent {index}: a buffer is over its limit"));
            }
            if let Some(Err(error)) = core.replica().map(dsr::Replica::check_invariants) {
                self.fail(state, Check::Invariants, format!("agent {index}: {error}"));
            }
        }
    }
}

/// Whether `delta` shows a gap in its writer's operations that `core` has no request outstanding for.
fn gap_unasked(core: &AgentCore, delta: &dsr::Delta, now_ns: u64) -> bool {
    let (Some(origin), Some(replica)) = (delta.origin(), core.replica()) else { return false };
    let outstanding =
        core.pending_ask().is_some_and(|(_, at)| now_ns.saturating_sub(at) < core.config().announce_period_ns / 2);
    replica.applied().version(origin.replica) + 1 < origin.first && !outstanding
}

impl Model for AgentsModel {
    type State = AgentsState;
    type Action = Action;

    fn init_states(&self) -> Vec<AgentsState> {
        let mut slots = Vec::new();
        for index in 0..self.config.agents {
            let mut slot = Slot {
                core: None,
                now_ns: 0,
                record: None,
                recorded_graph: None,
                lives: 0,
                early: BTreeSet::new(),
                stopped: false,
                stopped_joining: false,
            };
            self.new_life(index, &mut slot);
            slots.push(slot);
        }
        vec![AgentsState {
            slots,
            network: Vec::new(),
            history: Vec::new(),
            lives: Vec::new(),
            cut: None,
            spent: Budgets::default(),
            violated: 0,
            findings: Vec::new(),
            witnessed: BTreeSet::new(),
        }]
    }

    fn actions(&self, state: &AgentsState, actions: &mut Vec<Action>) {
        if state.violated != 0 {
            return;
        }
        let (config, spent) = (&self.config.budgets, state.spent);
        for (i, envelope) in state.network.iter().enumerate() {
            if i > 0 && state.network[i - 1] == *envelope {
                continue;
            }
            // A stopped process takes nothing: its messages wait (or are lost).
            if !state.slots[envelope.to].stopped {
                actions.push(Action::Deliver(i));
                if spent.duplicates < config.duplicates {
                    actions.push(Action::Duplicate(i));
                }
            }
            if spent.losses < config.losses {
                actions.push(Action::Lose(i));
            }
        }
        for (index, slot) in state.slots.iter().enumerate() {
            let Some(core) = &slot.core else {
                actions.push(Action::Restart(index));
                continue;
            };
            if spent.crashes < config.crashes {
                actions.push(Action::Crash(index));
            }
            if slot.stopped {
                actions.push(Action::Resume(index));
                continue;
            }
            if spent.stops < config.stops && !core.is_ready() {
                actions.push(Action::Stop(index));
            }
            if spent.ticks < config.ticks {
                actions.push(Action::Tick(index));
            }
            if spent.writes < config.writes
                && let Some(replica) = core.replica()
            {
                actions.push(Action::Write(index, WriteOp::Insert));
                let nodes: Vec<NodeId> = replica.nodes().map(|n| n.id()).collect();
                for &id in &nodes {
                    actions.push(Action::Write(index, WriteOp::SetLevel(id)));
                    actions.push(Action::Write(index, WriteOp::Delete(id)));
                    for &other in &nodes {
                        if other != id && replica.edge(&EdgeKey::new(id, other, "in")).is_none() {
                            actions.push(Action::Write(index, WriteOp::Link(id, other)));
                        }
                    }
                }
            }
        }
        match state.cut {
            Some(_) => actions.push(Action::Heal),
            None if spent.cuts < config.cuts => {
                // Each agent alone against the others (for two agents, one cut).
                let n = state.slots.len();
                for index in 0..if n == 2 { 1 } else { n } {
                    actions.push(Action::Cut(1 << index));
                }
            }
            None => {}
        }
    }

    fn next_state(&self, last: &AgentsState, action: Action) -> Option<AgentsState> {
        let mut state = last.clone();
        match action {
            Action::Deliver(i) => {
                let envelope = state.network.remove(i);
                self.deliver(&mut state, &envelope);
            }
            Action::Duplicate(i) => {
                state.spent.duplicates += 1;
                let envelope = state.network[i].clone();
                self.deliver(&mut state, &envelope);
            }
            Action::Lose(i) => {
                state.spent.losses += 1;
                state.network.remove(i);
            }
            Action::Tick(index) => {
                state.spent.ticks += 1;
                self.tick(&mut state, index);
            }
            Action::Write(index, op) => self.write(&mut state, index, &op),
            Action::Crash(index) => {
                state.spent.crashes += 1;
                state.slots[index].core = None;
                state.slots[index].stopped = false;
                state.network.retain(|e| e.to != index);
            }
            Action::Stop(index) => {
                state.spent.stops += 1;
                state.slots[index].stopped = true;
                state.slots[index].stopped_joining = true;
            }
            Action::Resume(index) => self.resume(&mut state, index),
            Action::Restart(index) => {
                let mut slot = state.slots[index].clone();
                self.new_life(index, &mut slot);
                state.slots[index] = slot;
            }
            Action::Cut(side) => {
                state.spent.cuts += 1;
                state.cut = Some(side);
                state.network.retain(|e| !Self::crosses_cut(Some(side), e.from, e.to));
            }
            Action::Heal => state.cut = None,
        }
        self.audit(&mut state);
        Some(state)
    }

    fn properties(&self) -> Vec<Property<Self>> {
        let mut properties = vec![
            Property::always(properties::UNIQUE_LIVES, |_, s: &AgentsState| s.holds(Check::UniqueLives)),
            Property::always(properties::BOUNDED, |_, s: &AgentsState| s.holds(Check::Bounded)),
            Property::always(properties::INVARIANTS, |_, s: &AgentsState| s.holds(Check::Invariants)),
            Property::always(properties::GAP_ASKED, |_, s: &AgentsState| s.holds(Check::GapAsked)),
            Property::always(properties::EARLY_KEPT, |_, s: &AgentsState| s.holds(Check::EarlyDeltasKept)),
            Property::always(properties::SETTLES, |model: &AgentsModel, s: &AgentsState| model.settle(s).is_ok()),
            Property::always(properties::JOINER_SERVED, |model: &AgentsModel, s: &AgentsState| {
                model.joiners_served(s).is_ok()
            }),
            Property::sometimes(properties::W_JOINED, |_, s: &AgentsState| s.lives.iter().any(|l| !l.alone)),
            Property::sometimes(properties::W_RESTART, |_, s: &AgentsState| s.lives.iter().any(|l| l.life > 1)),
            Property::sometimes(properties::W_GAP, |_, s: &AgentsState| s.witnessed.contains(&Witness::GapRequest)),
            Property::sometimes(properties::W_SNAPSHOT, |_, s: &AgentsState| {
                s.witnessed.contains(&Witness::SnapshotAnswer)
            }),
            Property::sometimes(properties::W_FORGOTTEN, |_, s: &AgentsState| {
                s.witnessed.contains(&Witness::PeerForgotten)
            }),
            Property::sometimes(properties::W_ALONE, |_, s: &AgentsState| s.lives.iter().any(|l| l.alone_beside_ready)),
            Property::sometimes(properties::W_ALL_FAULTS, |model: &AgentsModel, s: &AgentsState| {
                let c = &model.config.budgets;
                s.spent == Budgets { duplicates: s.spent.duplicates, ticks: s.spent.ticks, ..*c }
            }),
        ];
        // A move on a path takes a joiner's four ticks of join wait, then an announce of each agent: below six ticks
        // only the settling rounds reach one (where the settling property checks it).
        if self.config.unnamed && self.config.budgets.ticks >= 6 {
            properties.push(Property::sometimes(properties::W_MOVED, |_, s: &AgentsState| {
                s.witnessed.contains(&Witness::GraphMoved)
            }));
        }
        if self.config.budgets.stops > 0 {
            properties.push(Property::sometimes(properties::W_STOPPED_JOINED, |_, s: &AgentsState| {
                s.lives.iter().any(|l| l.stopped_joining && !l.alone)
            }));
        }
        properties
    }

    fn format_action(&self, action: &Action) -> String {
        format!("{action:?}")
    }
}

/// What the settling rounds ended with.
struct Settled {
    state: AgentsState,
    /// Agents that were joining when the faults stopped and became ready alone in the rounds.
    alone: Vec<usize>,
}

impl AgentsModel {
    /// Runs the settling rounds from `state` with no more faults: the cut heals, nothing is lost, each round every
    /// live agent ticks at its next deadline and then every message is delivered (in order).
    fn settled(&self, state: &AgentsState) -> Settled {
        let mut state = state.clone();
        state.cut = None;
        let before = state.lives.len();
        for index in 0..state.slots.len() {
            if state.slots[index].stopped {
                self.resume(&mut state, index);
            }
        }
        for _ in 0..SETTLE_ROUNDS {
            for index in 0..state.slots.len() {
                // Time passes for every agent alike now: each clock moves one join retry per round.
                let slot = &mut state.slots[index];
                let Some(core) = slot.core.as_mut() else { continue };
                slot.now_ns = slot.now_ns.saturating_add(RETRY_NS);
                let out = core.tick(slot.now_ns);
                self.emit(&mut state, index, None, &out);
                let mut budget = 10_000;
                while !state.network.is_empty() && budget > 0 {
                    let envelope = state.network.remove(0);
                    self.deliver(&mut state, &envelope);
                    budget -= 1;
                }
            }
        }
        let alone = state.lives[before..].iter().filter(|l| l.alone).map(|l| l.agent).collect();
        Settled { state, alone }
    }

    /// The bounded liveness property (module documentation); `Err` says what did not settle.
    pub fn settle(&self, state: &AgentsState) -> Result<(), String> {
        let Settled { state: end, .. } = self.settled(state);
        let live: Vec<&AgentCore> = end.slots.iter().filter_map(|s| s.core.as_ref()).collect();
        if let Some(core) = live.iter().find(|c| !c.is_ready()) {
            return Err(format!("{} is not ready after {SETTLE_ROUNDS} rounds", core.id()));
        }
        if let Some(pair) = live.windows(2).find(|pair| pair[0].graph() != pair[1].graph()) {
            let graph = |core: &AgentCore| core.graph().map_or_else(|| "none".to_string(), |g| g.to_string());
            let (a, b) = (pair[0], pair[1]);
            return Err(format!("{} is in graph {}, {} in graph {}", a.id(), graph(a), b.id(), graph(b)));
        }
        let replicas: Vec<&dsr::Replica> = live.iter().filter_map(|c| c.replica()).collect();
        if let Some(pair) = replicas.windows(2).find(|pair| pair[0].digest() != pair[1].digest()) {
            return Err(format!("replicas {} and {} differ after {SETTLE_ROUNDS} rounds", pair[0].id(), pair[1].id()));
        }
        let live_lives: BTreeSet<ReplicaId> = replicas.iter().map(|r| r.id()).collect();
        for replica in &replicas {
            let ops: Vec<OpRecord> =
                end.history.iter().filter(|op| replica.applied().contains(op.id)).map(|op| (**op).clone()).collect();
            if replica.visible_graph() != spec::visible_graph(&ops) {
                return Err(format!("replica {} differs from the specification of its operations", replica.id()));
            }
            if let Some(lost) =
                end.history.iter().find(|op| live_lives.contains(&op.replica) && !replica.applied().contains(op.id))
            {
                return Err(format!("replica {} lacks a live life's write: {lost}", replica.id()));
            }
        }
        if end.violated != 0 {
            return Err(format!("while settling: {}", end.findings.join("; ")));
        }
        Ok(())
    }

    /// A joiner that had a request to make before its wait ran out, with a ready agent alive, becomes ready from a
    /// peer's graph when the faults stop.
    pub fn joiners_served(&self, state: &AgentsState) -> Result<(), String> {
        let any_ready = state.slots.iter().any(|s| s.core.as_ref().is_some_and(AgentCore::is_ready));
        if !any_ready {
            return Ok(());
        }
        let expected: Vec<usize> = state
            .slots
            .iter()
            .enumerate()
            .filter_map(|(index, slot)| {
                let core = slot.core.as_ref().filter(|c| !c.is_ready())?;
                let wait_end = core.joining_since_ns().saturating_add(core.config().join_wait_ns);
                let next_request =
                    core.last_request_ns().map_or(slot.now_ns, |at| at.saturating_add(core.config().join_retry_ns));
                (next_request.max(slot.now_ns) < wait_end).then_some(index)
            })
            .collect();
        if expected.is_empty() {
            return Ok(());
        }
        let settled = self.settled(state);
        match expected.iter().find(|index| settled.alone.contains(index)) {
            Some(index) => Err(format!("agent {index} started alone although a ready agent was reachable")),
            None => Ok(()),
        }
    }
}

/// Checks the agents model of `config`.
pub fn check_agents(config: &AgentsConfig, options: &CheckOptions) -> CheckReport {
    let configuration = serde_json::to_value(config).expect("the configuration serializes");
    run_check(AgentsModel::new(config.clone()), "agents", configuration, options)
}
