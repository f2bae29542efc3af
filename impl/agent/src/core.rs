//! The agent protocol as a pure state machine: [`AgentCore`].
//!
//! The core decides everything agents say to each other — the late join (graph requests and answers, starting
//! alone after the join wait), the choice of this life's replica id, periodic and quiet announces, missing-delta
//! requests on an announce or a gap, their answers (retained deltas or a snapshot), collisions of agent ids — and
//! keeps the replica. It opens no socket, spawns no thread, takes no lock and reads no clock: every input carries
//! `now_ns`, and every call returns an [`Output`] — the messages to send, the replica's change events and the
//! [`Event`]s worth telling a person. Three runtimes run it unchanged: the threaded [`crate::Agent`] over RTPS or
//! the in-process bus, the seeded simulations that pump agents by hand, and the Stateright model of N agents
//! (`model::agents`) with loss, duplication, reordering, partitions, crashes and restarts.
//!
//! Inputs: [`AgentCore::handle`] a received message (decoded with [`Input::decode`]), [`AgentCore::tick`] the
//! periodic work at `now_ns`, [`AgentCore::discovery_matched`] a new peer endpoint, [`AgentCore::write`] a local
//! operation. [`AgentCore::next_deadline_ns`] says when the next tick has work to do.
//!
//! **Channels.** Each message travels on its own channel ([`Message::channel`]): deltas on updates, answers on sync,
//! and asking alone ([`Message::asks`]: graph requests, announces, missing-requests) on [`Channel::Requests`], the
//! one channel a read-only participant may write. [`AgentCore::admit_channel`] refuses anything else arriving on
//! it (counted, never applied), so a participant allowed to ask cannot change a graph. A read-only life
//! ([`ProtocolConfig::read_only`]) publishes on that channel alone.
//!
//! **Lives.** Replica ids are `incarnation << 12 | agent_id`. A life chooses its incarnation when it becomes ready:
//! one above every incarnation of this agent id seen in what it heard (announces, snapshots, the graph it joined)
//! and above the incarnation recorded by the previous life on this host ([`LifeSeed::recorded_incarnation`]; the
//! shell persists each life's incarnation before the life writes, see [`Event::Ready`]). With no record (a fresh
//! state directory, another host) the floor is instead a number drawn from the life's random nonce in
//! `0..2^16`, so two record-less lives that heard nothing of each other share a replica id with probability
//! at most 2^-16. A reuse that becomes visible anyway — a peer holds operations of this life's replica id that this
//! life did not make — is an id collision: reported, and local writes are refused from then on.
//!
//! **Graphs.** Every envelope carries its sender's graph id ([`GraphId`]); a life belongs to one graph and refuses
//! every message of another ([`AgentCore::admit`]: counted, reported once per foreign graph as
//! [`Event::ForeignGraph`], never merged), so agents of several graphs can share a DDS domain. A life's graph is
//! *named* when its settings name it ([`ProtocolConfig::graph`]) or it took it from an agent whose graph is named;
//! naming none, a life takes the graph of the first answer it takes; starting alone without one, the one graph that
//! the agents it heard while it joined belong to (their announces and deltas; a joiner's graph request proves no
//! graph), else the unnamed graph of its previous life ([`LifeSeed::recorded_graph`]), else a graph of its own, its
//! id drawn from the life's nonce ([`GraphId::from_nonce`]) — all unnamed; and a graph of its own, named, when it
//! heard agents of several graphs ([`Event::SeveralGraphsHeard`]: it cannot tell which it was meant to join). A
//! named graph never moves. A life whose graph is unnamed moves to the graph of an announce it hears that is named,
//! or unnamed with a smaller id ([`Event::GraphMoved`]; announces and answers carry the flag), and becomes named on
//! a named announce of its own graph ([`Event::GraphNamed`]). So a joiner whose answers were lost or late — its
//! only peer stopped or cut off, a DDS Security handshake that outlasted the join wait — still ends in one graph
//! with its peers once they hear each other, and anti-entropy merges the copies: the named graph if there is one,
//! else the smallest id among theirs.

mod graphs;
mod input;
mod join;
mod lives;
mod output;
mod settings;
mod sync;

use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::sync::Arc;

use bytes::Bytes;
use dsr::json::CortexGraph;
use dsr::{CausalContext, Delta, Digest, OpError, Replica};
use transport::Channel;

use crate::AgentId;
use crate::envelope::Message;
use crate::graph_id::GraphId;
use crate::mutants::ProtocolMutant;
use lives::reused_id;

pub use input::{Decoded, Input};
pub use output::{Dest, Event, Output, Send, WriteRefusal, Written};
pub use settings::{
    INCARNATION_LIMIT, LifeSeed, MAX_ANSWERED, MAX_FOREIGN_GRAPHS, PEER_FORGET_INTERVALS, ProtocolConfig,
    RANDOM_FLOOR_LIMIT, SNAPSHOT_IF_SMALLER_ABOVE_BYTES,
};

/// model checker's states do not multiply by them (caches, a seed graph consumed once).
#[derive(Clone, Debug, Default)]
pub struct Unhashed<T>(pub T);

impl<T> PartialEq for Unhashed<T> {
    fn eq(&self, _: &Self) -> bool {
        true
    }
}
impl<T> Eq for Unhashed<T> {}
impl<T> std::hash::Hash for Unhashed<T> {
    fn hash<H: std::hash::Hasher>(&self, _: &mut H) {}
}

/// Encodings kept per causal context: several joiners (or repeated requests) cost one snapshot encoding, several
/// announces one digest.
#[derive(Clone, Debug, Default)]
struct Caches {
    digest: Option<(CausalContext, Digest)>,
    snapshot: Option<(CausalContext, Bytes)>,
}

/// The agent protocol's state: one life of one agent. See the module documentation.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct AgentCore {
    config: ProtocolConfig,
    life: LifeSeed,
    replica: Option<Replica>,
    joining_since_ns: u64,
    last_request_ns: Option<u64>,
    /// A peer endpoint was matched since the last graph request: ask again at the next tick.
    request_now: bool,
    /// Highest incarnation of this agent id seen anywhere.
    incarnation_floor: u32,
    /// The graph this life belongs to (see **Graphs**); `None` only while joining without a named graph.
    graph: Option<GraphId>,
    /// Whether `graph` is named (see **Graphs**): an unnamed one may still move.
    named: bool,
    /// Foreign graph ids seen (each reported once), at most [`MAX_FOREIGN_GRAPHS`].
    foreign: BTreeSet<GraphId>,
    /// Messages of other graphs refused.
    foreign_refused: u64,
    /// Messages refused for arriving on a channel that does not carry them ([`AgentCore::admit_channel`]).
    misrouted_refused: u64,
    /// While joining without a named graph: the graphs of the agents heard (in the order first heard, at most
    /// [`MAX_FOREIGN_GRAPHS`]), one of which a life that starts alone takes (see **Graphs**).
    heard_graphs: Vec<GraphId>,
    /// Deltas received while joining, with their graph.
    buffered: VecDeque<(GraphId, AgentId, Arc<Delta>)>,
    collision: Option<String>,
    next_announce_ns: u64,
    /// The latest local write not yet followed by an announce.
    unannounced_write_ns: Option<u64>,
    /// The operations joined at the last announce: an announce carries the digest only when nothing was joined
    /// since (a still graph), so a stream of frames is not hashed at every announce.
    announced: Option<CausalContext>,
    /// The outstanding missing-request: the peer asked and when.
    pending_ask: Option<(AgentId, u64)>,
    /// The agents heard from lately, with when each was last heard (see [`ProtocolConfig::peer_forget_intervals`]).
    peers: BTreeMap<AgentId, u64>,
    /// Graph requests answered recently, by (joiner, nonce), with the time.
    answered: BTreeMap<(AgentId, u64), u64>,
    /// Whether the replica queues its visible changes for [`Output::changes`] (on unless turned off).
    change_tracking: bool,
    seed: Unhashed<Option<CortexGraph>>,
    caches: Unhashed<Caches>,
}

impl AgentCore {
    /// A life that starts joining at `now_ns`; `seed` is the graph to start from if no peer answers.
    pub fn new(config: ProtocolConfig, life: LifeSeed, seed: Option<CortexGraph>, now_ns: u64) -> Self {
        AgentCore {
            graph: config.graph,
            named: config.graph.is_some(),
            config,
            life,
            replica: None,
            joining_since_ns: now_ns,
            last_request_ns: None,
            request_now: false,
            incarnation_floor: 0,
            foreign: BTreeSet::new(),
            foreign_refused: 0,
            misrouted_refused: 0,
            heard_graphs: Vec::new(),
            buffered: VecDeque::new(),
            collision: None,
            next_announce_ns: now_ns,
            unannounced_write_ns: None,
            announced: None,
            pending_ask: None,
            peers: BTreeMap::new(),
            answered: BTreeMap::new(),
            change_tracking: true,
            seed: Unhashed(seed),
            caches: Unhashed(Caches::default()),
        }
    }

    /// This agent's id.
    pub fn id(&self) -> AgentId {
        self.config.id
    }

    /// The settings.
    pub fn config(&self) -> &ProtocolConfig {
        &self.config
    }

    /// The graph this life belongs to; `None` while it joins without a named graph (see **Graphs**).
    pub fn graph(&self) -> Option<GraphId> {
        self.graph
    }

    /// Whether this life's graph is named (see **Graphs**): named in its settings, taken from an agent whose graph
    /// is named, or heard named since. An unnamed graph may still move.
    pub fn graph_named(&self) -> bool {
        self.named
    }

    /// Messages of other graphs refused so far.
    pub fn foreign_refused(&self) -> u64 {
        self.foreign_refused
    }

    /// Messages refused so far for arriving on a channel that does not carry them ([`AgentCore::admit_channel`]).
    pub fn misrouted_refused(&self) -> u64 {
        self.misrouted_refused
    }

    /// Whether `message`, received on `channel`, may be handled: anything that does not ask ([`Message::asks`])
    /// arriving on [`Channel::Requests`] is refused — counted, reported in `out`, never applied — since the
    /// requests channel is the one a read-only participant may write, and nothing on it may change a graph.
    pub fn admit_channel(&mut self, channel: Channel, message: &Message, out: &mut Output) -> bool {
        if channel != Channel::Requests || message.asks() {
            return true;
        }
        self.misrouted_refused += 1;
        let first = self.misrouted_refused == 1;
        out.events.push(Event::Misrouted { from: message.from(), kind: message.kind(), first });
        false
    }

    /// The foreign graph ids seen (at most [`MAX_FOREIGN_GRAPHS`]).
    pub fn foreign_graphs(&self) -> &BTreeSet<GraphId> {
        &self.foreign
    }

    /// This life's nonce.
    pub fn nonce(&self) -> u64 {
        self.life.nonce
    }

    /// The replica, once ready.
    pub fn replica(&self) -> Option<&Replica> {
        self.replica.as_ref()
    }

    /// Turns the report of visible changes ([`Output::changes`], [`Written::changes`]) on or off, now and for the
    /// replica a join makes later. Off, a write or a join skips the before-and-after look at what it touches: an
    /// agent whose changes nobody listens to turns it off.
    pub fn set_change_tracking(&mut self, on: bool) {
        self.change_tracking = on;
        if let Some(replica) = self.replica.as_mut() {
            replica.set_change_tracking(on);
        }
    }

    /// Whether visible changes are reported ([`AgentCore::set_change_tracking`]).
    pub fn change_tracking(&self) -> bool {
        self.change_tracking
    }

    /// Whether the life has its replica.
    pub fn is_ready(&self) -> bool {
        self.replica.is_some()
    }

    /// The id collision seen, if any.
    pub fn collision(&self) -> Option<&str> {
        self.collision.as_deref()
    }

    /// Notes a message from `from` at `now_ns` that is not the protocol's (a remote call).
    pub fn heard_from(&mut self, from: AgentId, now_ns: u64) {
        self.peers.insert(from, now_ns);
    }

    /// The agents heard from lately, by id: each is forgotten at the first tick after it has been silent for
    /// [`ProtocolConfig::peer_forget_intervals`] of this agent's announce intervals.
    pub fn peers(&self) -> impl ExactSizeIterator<Item = AgentId> + '_ {
        self.peers.keys().copied()
    }

    /// Forgets the peers silent for [`ProtocolConfig::peer_forget_intervals`] announce intervals at `now_ns`: an
    /// agent that left (or a life that ended) no longer counts in [`AgentCore::announce_interval_ns`] nor in
    /// [`AgentCore::peers`]. A live peer announces at least once an interval (its own, the same as this agent's when
    /// both hear the same group), so only a long silence — a departure, a cut, a pause — forgets it; its next message
    /// brings it back.
    fn forget_silent_peers(&mut self, now_ns: u64) {
        if self.config.peer_forget_intervals == 0 {
            return;
        }
        let silence_ns = self.announce_interval_ns().saturating_mul(self.config.peer_forget_intervals);
        self.peers.retain(|_, heard_ns| now_ns.saturating_sub(*heard_ns) < silence_ns);
    }

    /// When this life started joining, moved later by the time it could not listen (see `discount_absence`): the
    /// join wait runs from here.
    pub fn joining_since_ns(&self) -> u64 {
        self.joining_since_ns
    }

    /// A joining life ticks at its next graph request, one join retry after the last (the first at once). A tick
    /// more than a further join retry late finds a life that could not listen meanwhile — its process was stopped
    /// (SIGSTOP, a debugger) or starved of the CPU — so that time does not count against the join wait: the life
    /// asks again and waits out the rest, instead of starting alone at once beside peers it had no chance to hear
    /// (a graph of its own, which merges with theirs only once they hear each other).
    fn discount_absence(&mut self, now_ns: u64) {
        let due = self.last_request_ns.map_or(self.joining_since_ns, |at| at.saturating_add(self.config.join_retry_ns));
        let late_ns = now_ns.saturating_sub(due);
        if late_ns > self.config.join_retry_ns && !self.config.plant.is(ProtocolMutant::JoinWaitCountsAbsence) {
            self.joining_since_ns = self.joining_since_ns.saturating_add(late_ns);
        }
    }

    /// When the last graph request went out (while joining).
    pub fn last_request_ns(&self) -> Option<u64> {
        self.last_request_ns
    }

    /// Deltas buffered while joining.
    pub fn buffered(&self) -> usize {
        self.buffered.len()
    }

    /// Remembered answered graph requests.
    pub fn answered(&self) -> usize {
        self.answered.len()
    }

    /// The outstanding missing-request: the peer asked and when.
    pub fn pending_ask(&self) -> Option<(AgentId, u64)> {
        self.pending_ask
    }

    /// The digest of the visible graph (cached per causal context).
    pub fn digest(&mut self) -> Option<Digest> {
        let replica = self.replica.as_ref()?;
        if let Some((ctx, digest)) = &self.caches.0.digest
            && ctx == replica.context()
        {
            return Some(*digest);
        }
        let digest = replica.digest();
        self.caches.0.digest = Some((replica.context().clone(), digest));
        Some(digest)
    }

    /// The earliest time at which [`AgentCore::tick`] has work to do.
    pub fn next_deadline_ns(&self) -> u64 {
        if self.replica.is_none() {
            let wait_end = if self.config.read_only {
                u64::MAX
            } else {
                self.joining_since_ns.saturating_add(self.config.join_wait_ns)
            };
            let retry =
                self.last_request_ns.map_or(self.joining_since_ns, |at| at.saturating_add(self.config.join_retry_ns));
            return wait_end.min(retry);
        }
        let quiet = self
            .unannounced_write_ns
            .filter(|_| self.config.quiet_announce_ns > 0)
            .map_or(u64::MAX, |at| at.saturating_add(self.config.quiet_announce_ns));
        if self.config.read_only { u64::MAX } else { self.next_announce_ns.min(quiet) }
    }

    /// Discovery matched a new peer endpoint: while joining, the next tick asks for the graph at once (a request
    /// published before the match reached nobody).
    pub fn discovery_matched(&mut self) {
        self.request_now = true;
    }

    /// The periodic work due at `now_ns`: graph requests while joining, starting alone after the join wait,
    /// announces.
    pub fn tick(&mut self, now_ns: u64) -> Output {
        let out = self.tick_unstamped(now_ns);
        out.stamp(self.graph)
    }

    fn tick_unstamped(&mut self, now_ns: u64) -> Output {
        let mut out = Output::default();
        if self.replica.is_none() {
            self.discount_absence(now_ns);
            if now_ns.saturating_sub(self.joining_since_ns) >= self.config.join_wait_ns && !self.config.read_only {
                self.become_ready(now_ns, None, &mut out);
            } else {
                let due = self.last_request_ns.is_none_or(|at| {
                    now_ns.saturating_sub(at) >= self.config.join_retry_ns
                        && !(self.config.plant.is(ProtocolMutant::JoinRequestOnce))
                }) || self.request_now;
                if due {
                    self.last_request_ns = Some(now_ns);
                    self.request_now = false;
                    out.events.push(Event::GraphRequested);
                    let request = Message::GraphRequest { from: self.id(), nonce: self.life.nonce };
                    out.send(request, Dest::All);
                }
            }
            return out;
        }
        self.forget_silent_peers(now_ns);
        if self.config.read_only {
            return out;
        }
        let quiet = self.config.quiet_announce_ns;
        let quiet_after_writes =
            quiet > 0 && self.unannounced_write_ns.is_some_and(|at| now_ns.saturating_sub(at) >= quiet);
        if (now_ns >= self.next_announce_ns || quiet_after_writes)
            && let Some(replica) = &self.replica
        {
            let (replica_id, applied) = (replica.id(), replica.applied().clone());
            let still = self.announced.as_ref() == Some(&applied);
            let digest = if still { self.digest().map(|d| d.0) } else { None };
            self.announced = Some(applied.clone());
            let announce = Message::Announce {
                from: self.config.id,
                nonce: self.life.nonce,
                replica: replica_id,
                applied,
                digest,
                named: self.named,
            };
            out.send(announce, Dest::All);
            self.next_announce_ns = if self.config.plant.is(ProtocolMutant::AnnounceTimerLost) {
                u64::MAX
            } else {
                now_ns + self.announce_interval_ns()
            };
            self.unannounced_write_ns = None;
        }
        out
    }

    /// The time between this agent's periodic announces: the announce period, times the number of groups of
    /// [`ProtocolConfig::announce_group`] agents among this one and the peers heard lately ([`AgentCore::peers`]),
    /// so a group of any size sends about `announce_group` announces per period.
    pub fn announce_interval_ns(&self) -> u64 {
        let group = u64::from(self.config.announce_group);
        if group == 0 {
            return self.config.announce_period_ns;
        }
        let agents = self.peers.len() as u64 + 1;
        self.config.announce_period_ns.saturating_mul(agents.div_ceil(group).max(1))
    }

    /// Handles at `now_ns` a received message of graph `graph` (the envelope's graph id). A message of another
    /// graph is refused (see **Graphs**).
    pub fn handle(&mut self, now_ns: u64, graph: Option<GraphId>, input: Input) -> Output {
        let mut out = Output::default();
        if let Input::Announce { from, named, .. } = &input {
            self.follow_graph(graph, *from, *named, now_ns, &mut out);
        }
        if !self.admit(graph, input.from(), input.kind(), &mut out) {
            return out;
        }
        // Admitted: `graph` is this life's, or any while joining without one (then a graph request may carry none).
        if !matches!(input, Input::GraphRequest { .. }) {
            self.hear_graph(graph);
        }
        let tag = graph.or(self.graph).map(|graph| (graph, input.from()));
        self.peers.insert(input.from(), now_ns);
        match input {
            Input::Delta { from, delta } => {
                self.gap_request(from, &delta, now_ns, &mut out);
                self.apply("delta", tag, vec![delta], &mut out);
            }
            Input::Announce { from, nonce, replica, applied, digest, .. } => {
                self.note_incarnations(&applied, &mut out);
                if from == self.id() {
                    self.check_collision(nonce, Some(replica), "announce", &mut out);
                }
                self.on_announce(from, &applied, digest, now_ns, &mut out);
            }
            Input::MissingRequest { from, applied, full } => self.answer_missing(from, &applied, full, &mut out),
            Input::Deltas { from, deltas } => {
                self.answered_by(from);
                self.apply("missing delta", tag, deltas, &mut out);
            }
            Input::Snapshot { from, snapshot } => {
                self.answered_by(from);
                self.note_incarnations(snapshot.context(), &mut out);
                self.apply("snapshot", tag, vec![snapshot], &mut out);
            }
            Input::GraphRequest { from, nonce } => {
                if from == self.id() {
                    self.check_collision(nonce, None, "graph request", &mut out);
                } else {
                    self.answer_graph_request(from, nonce, now_ns, &mut out);
                }
            }
            Input::GraphAnswer { nonce, named, snapshot, .. } => {
                if nonce == self.life.nonce && self.replica.is_none() {
                    // The first answer gives its graph to a joiner that named none (unless it is refused), named
                    // if the answerer's is.
                    let (before, named_before) = (self.graph, self.named);
                    self.graph = before.or(graph);
                    self.named |= named;
                    self.become_ready(now_ns, Some(snapshot), &mut out);
                    if self.replica.is_none() {
                        (self.graph, self.named) = (before, named_before);
                    }
                }
            }
        }
        out.stamp(self.graph)
    }

    /// Runs a local operation on the replica at `now_ns`. Its deltas go out on [`Channel::Updates`]:
    /// [`Written::sends`] encodes them, so that a caller holding a lock around the core can encode after releasing
    /// it (a camera frame's encoding would otherwise keep readers waiting).
    ///
    /// # Errors
    /// [`WriteRefusal`]: read-only, not ready, an id collision, or the replica refused the operation (nothing changed).
    pub fn write<R>(
        &mut self,
        now_ns: u64,
        op: impl FnOnce(&mut Replica, u64) -> Result<(R, Vec<Arc<Delta>>), OpError>,
    ) -> Result<(R, Written), WriteRefusal> {
        if self.config.read_only {
            return Err(WriteRefusal::ReadOnly);
        }
        if let Some(detail) = &self.collision {
            return Err(WriteRefusal::Collision(detail.clone()));
        }
        let replica = self.replica.as_mut().ok_or(WriteRefusal::NotJoined)?;
        let (result, deltas) = op(replica, now_ns).map_err(WriteRefusal::Op)?;
        let changes = replica.drain_changes();
        if !deltas.is_empty() {
            self.unannounced_write_ns = Some(now_ns);
        }
        let graph = self.graph.unwrap_or_else(|| GraphId::from_nonce(self.life.nonce));
        Ok((result, Written { from: self.config.id, graph, deltas, changes }))
    }

    /// Joins remote deltas into the replica, or buffers them while joining, tagged with their graph and sender
    /// (`source`).
    fn apply(
        &mut self,
        what: &'static str,
        source: Option<(GraphId, AgentId)>,
        deltas: Vec<Arc<Delta>>,
        out: &mut Output,
    ) {
        // A join can change the store without moving the context (the snapshot repair): drop the caches.
        self.caches.0 = Caches::default();
        let Some(replica) = self.replica.as_mut() else {
            if self.config.plant.is(ProtocolMutant::DropEarlyDelta) {
                return;
            }
            let Some((graph, from)) = source else { return };
            for delta in deltas {
                if self.buffered.len() >= self.config.max_buffered_deltas {
                    self.buffered.pop_front();
                }
                self.buffered.push_back((graph, from, delta));
            }
            return;
        };
        for delta in deltas {
            if let Some(detail) = reused_id(replica, delta.context())
                && self.collision.is_none()
            {
                out.events.push(Event::Collision { detail: detail.clone() });
                self.collision = Some(detail);
            }
            if let Err(error) = replica.apply_shared(delta) {
                out.events.push(Event::Rejected { what, error: error.to_string() });
            }
        }
        let changes = replica.drain_changes();
        if out.changes.is_empty() {
            out.changes = changes;
        } else {
            out.changes.extend(changes);
        }
    }
}
