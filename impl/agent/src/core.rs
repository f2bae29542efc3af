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
//! **Lives.** Replica ids are `incarnation << 12 | agent_id`. A life chooses its incarnation when it becomes ready:
//! one above every incarnation of this agent id seen in what it heard (announces, snapshots, the graph it joined)
//! and above the incarnation recorded by the previous life on this host ([`LifeSeed::recorded_incarnation`]; the
//! shell persists each life's incarnation before the life writes, see [`Event::Ready`]). With no record (a fresh
//! state directory, another host) the floor is instead a number drawn from the life's random nonce in
//! `0..2^16`, so two record-less lives that heard nothing of each other share a replica id with probability
//! at most 2^-16. A reuse that becomes visible anyway — a peer holds operations of this life's replica id that this
//! life did not make — is an id collision: reported, and local writes are refused from then on.

use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::sync::Arc;

use bytes::Bytes;
use dsr::json::CortexGraph;
use dsr::{CausalContext, ChangeEvent, Delta, Digest, LogLimits, Missing, OpError, Replica, ReplicaId};
use transport::Channel;

use crate::AgentId;
use crate::envelope::{MAX_BATCH, Message};
use crate::mutants::{Plant, ProtocolMutant};

/// Most remembered answered requests.
pub const MAX_ANSWERED: usize = 1024;
/// Largest incarnation plus one (replica ids are 32 bits, 12 of them the agent id).
pub const INCARNATION_LIMIT: u32 = 1 << 20;
/// Without a recorded incarnation, the floor is drawn from the nonce below this.
pub const RANDOM_FLOOR_LIMIT: u32 = 1 << 16;
/// Above this many payload bytes of retained deltas, a missing-request is answered with a snapshot instead when the
/// snapshot is smaller: the history keeps every overwritten camera frame, a snapshot only the current ones.
pub const SNAPSHOT_IF_SMALLER_ABOVE_BYTES: usize = 1 << 20;

/// The protocol's settings, in nanoseconds.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct ProtocolConfig {
    /// This agent's id (below [`AgentId::LIMIT`]).
    pub id: AgentId,
    /// How long to wait for a graph from peers before starting alone.
    pub join_wait_ns: u64,
    /// How often to repeat the graph request while joining.
    pub join_retry_ns: u64,
    /// How often to announce the applied operations.
    pub announce_period_ns: u64,
    /// Announce once more this long after the last local write (0: never).
    pub quiet_announce_ns: u64,
    /// History kept for anti-entropy.
    pub log_limits: LogLimits,
    /// Deltas kept while joining.
    pub max_buffered_deltas: usize,
    /// Most bytes of deltas in one anti-entropy answer.
    pub max_batch_bytes: usize,
    /// How long a graph request stays answered: a joiner's repeat within it gets no second copy (a large answer
    /// may still be on its way), one after it does (the answer may have been lost). A joiner whose answer was lost
    /// is served again only after this, so its join wait must be longer than this plus a join retry.
    pub answer_hold_ns: u64,
    /// A planted protocol bug (always none without the `mutants` feature).
    pub plant: Plant,
}

/// What a new life starts from.
#[derive(Clone, Debug, Default, PartialEq, Eq, Hash)]
pub struct LifeSeed {
    /// This life's random nonce: tells lives of one agent id apart in graph requests and announces.
    pub nonce: u64,
    /// The incarnation of this agent's previous life on this host, as the shell recorded it (`None`: no record).
    pub recorded_incarnation: Option<u32>,
}

/// Where a message goes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Dest {
    /// Every agent of the graph.
    All,
    /// The endpoint the handled input came from, alone where the transport can address one.
    Sender,
}

/// One message to send.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Send {
    /// The channel.
    pub channel: Channel,
    /// The message.
    pub message: Message,
    /// Where it goes.
    pub dest: Dest,
}

/// Something the shell should tell a person, count or act on.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Event {
    /// A received delta or snapshot was refused (the replica is unchanged).
    Rejected {
        /// What it was ("delta", "snapshot", ...).
        what: &'static str,
        /// Why.
        error: String,
    },
    /// A graph request went out while joining.
    GraphRequested,
    /// This life became ready as `replica`. The shell records `incarnation` before this life's first write.
    Ready {
        /// This life's replica id.
        replica: ReplicaId,
        /// Its incarnation.
        incarnation: u32,
        /// Whether it started alone (no graph answer within the join wait).
        alone: bool,
        /// Nodes of the seed graph imported, when it started alone from one.
        seed_nodes: Option<usize>,
    },
    /// The seed graph could not be imported; the life starts empty.
    SeedRefused {
        /// Why.
        error: String,
    },
    /// The seed graph was imported with a warning (a name it taught the graph's dictionary, an attribute kept
    /// under another type than the dictionary's, a link skipped: see `dsr::json`).
    SeedWarning {
        /// The warning, with its place in the file.
        warning: String,
    },
    /// A running graph was joined, so the seed graph is not used.
    SeedUnused,
    /// A graph request was answered with a snapshot.
    Answered {
        /// The joiner.
        to: AgentId,
        /// Bytes of the snapshot.
        snapshot_bytes: usize,
        /// Whether the encoded snapshot came from the cache.
        from_cache: bool,
    },
    /// Another life uses this agent id (or this life's replica id); local writes are refused from now on.
    Collision {
        /// What was seen.
        detail: String,
    },
    /// A peer has joined the same operations but shows another digest (a replica bug; repaired with snapshots).
    DigestMismatch {
        /// The peer.
        peer: AgentId,
    },
    /// A delta showed a gap in its writer's operations: a missing-request went out at once.
    GapRequest {
        /// The writer asked.
        peer: AgentId,
    },
    /// No incarnation is left for a new life (more than 2^20 lives of this agent id).
    IncarnationsExhausted,
}

/// What one call of the core asks its runtime to do.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Output {
    /// Messages to send, in order.
    pub sends: Vec<Send>,
    /// The replica's change events, in order.
    pub changes: Vec<ChangeEvent>,
    /// Events.
    pub events: Vec<Event>,
}

impl Output {
    fn send(&mut self, channel: Channel, message: Message, dest: Dest) {
        self.sends.push(Send { channel, message, dest });
    }
}

/// What a local write produced.
#[derive(Clone, Debug, PartialEq)]
pub struct Written {
    /// The writer.
    pub from: AgentId,
    /// The deltas of the operation, in order.
    pub deltas: Vec<Arc<Delta>>,
    /// The replica's change events.
    pub changes: Vec<ChangeEvent>,
}

impl Written {
    /// The messages that publish the deltas to every agent (encoding each).
    pub fn sends(&self) -> Vec<Send> {
        let encode = |delta: &Arc<Delta>| Message::Delta { from: self.from, delta: Bytes::from(delta.encode()) };
        self.deltas
            .iter()
            .map(|delta| Send { channel: Channel::Updates, message: encode(delta), dest: Dest::All })
            .collect()
    }
}

/// A received protocol message, with its deltas decoded (calls are not protocol messages).
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Input {
    /// The delta of one operation.
    Delta {
        /// The writer.
        from: AgentId,
        /// The delta.
        delta: Arc<Delta>,
    },
    /// An announce.
    Announce {
        /// The announcer.
        from: AgentId,
        /// Its life's nonce.
        nonce: u64,
        /// Its replica id.
        replica: ReplicaId,
        /// Its applied operations.
        applied: CausalContext,
        /// Its digest.
        digest: [u8; 32],
    },
    /// A missing-request addressed to this agent.
    MissingRequest {
        /// The asker.
        from: AgentId,
        /// What it has applied.
        applied: CausalContext,
        /// Whether it asks for a whole snapshot.
        full: bool,
    },
    /// Missing deltas.
    Deltas {
        /// The sender.
        from: AgentId,
        /// The deltas that decoded.
        deltas: Vec<Arc<Delta>>,
    },
    /// A snapshot answering a missing-request.
    Snapshot {
        /// The sender.
        from: AgentId,
        /// The snapshot.
        snapshot: Arc<Delta>,
    },
    /// A joiner's graph request.
    GraphRequest {
        /// The joiner.
        from: AgentId,
        /// Its life's nonce.
        nonce: u64,
    },
    /// A graph answer addressed to this agent.
    GraphAnswer {
        /// The answering agent.
        from: AgentId,
        /// The nonce it echoes.
        nonce: u64,
        /// The graph.
        snapshot: Arc<Delta>,
    },
}

/// [`Input::decode`]'s result.
#[derive(Clone, Debug, Default)]
pub struct Decoded {
    /// The input, unless the message is a call or its payload did not decode.
    pub input: Option<Input>,
    /// Payloads that did not decode, with what they were.
    pub rejected: Vec<(&'static str, String)>,
}

impl Input {
    /// Decodes the deltas of a protocol message (pure; never panics). Call messages give no input.
    pub fn decode(message: Message) -> Decoded {
        let mut rejected = Vec::new();
        // Payloads are slices of the received sample: large byte values stay in its buffer (no copy per receiver).
        let mut delta = |what: &'static str, bytes: &Bytes| match Delta::decode_shared(bytes) {
            Ok(delta) => Some(Arc::new(delta)),
            Err(error) => {
                rejected.push((what, error.to_string()));
                None
            }
        };
        let input = match message {
            Message::Delta { from, delta: bytes } => delta("delta", &bytes).map(|delta| Input::Delta { from, delta }),
            Message::Announce { from, nonce, replica, applied, digest } => {
                Some(Input::Announce { from, nonce, replica, applied, digest })
            }
            Message::MissingRequest { from, applied, full, .. } => Some(Input::MissingRequest { from, applied, full }),
            Message::Deltas { from, deltas, .. } => {
                let deltas = deltas.iter().filter_map(|bytes| delta("missing delta", bytes)).collect();
                Some(Input::Deltas { from, deltas })
            }
            Message::Snapshot { from, snapshot, .. } => {
                delta("snapshot", &snapshot).map(|snapshot| Input::Snapshot { from, snapshot })
            }
            Message::GraphRequest { from, nonce } => Some(Input::GraphRequest { from, nonce }),
            Message::GraphAnswer { from, nonce, snapshot, .. } => {
                delta("graph answer", &snapshot).map(|snapshot| Input::GraphAnswer { from, nonce, snapshot })
            }
            Message::CallRequest { .. } | Message::CallReply { .. } => None,
        };
        Decoded { input, rejected }
    }

    /// The sender.
    pub fn from(&self) -> AgentId {
        match self {
            Input::Delta { from, .. }
            | Input::Announce { from, .. }
            | Input::MissingRequest { from, .. }
            | Input::Deltas { from, .. }
            | Input::Snapshot { from, .. }
            | Input::GraphRequest { from, .. }
            | Input::GraphAnswer { from, .. } => *from,
        }
    }
}

/// Why a local write was refused.
#[derive(Clone, Debug, PartialEq)]
pub enum WriteRefusal {
    /// The life has no replica yet.
    NotJoined,
    /// An id collision was seen; local writes are refused.
    Collision(String),
    /// The replica refused the operation.
    Op(OpError),
}

/// Values that belong to the runtime, not to the protocol's state: equal and hashed alike whatever they hold, so a
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
    buffered: VecDeque<Arc<Delta>>,
    collision: Option<String>,
    next_announce_ns: u64,
    /// The latest local write not yet followed by an announce.
    unannounced_write_ns: Option<u64>,
    /// The outstanding missing-request: the peer asked and when.
    pending_ask: Option<(AgentId, u64)>,
    peers: BTreeSet<AgentId>,
    /// Graph requests answered recently, by (joiner, nonce), with the time.
    answered: BTreeMap<(AgentId, u64), u64>,
    seed: Unhashed<Option<CortexGraph>>,
    caches: Unhashed<Caches>,
}

impl AgentCore {
    /// A life that starts joining at `now_ns`; `seed` is the graph to start from if no peer answers.
    pub fn new(config: ProtocolConfig, life: LifeSeed, seed: Option<CortexGraph>, now_ns: u64) -> Self {
        AgentCore {
            config,
            life,
            replica: None,
            joining_since_ns: now_ns,
            last_request_ns: None,
            request_now: false,
            incarnation_floor: 0,
            buffered: VecDeque::new(),
            collision: None,
            next_announce_ns: now_ns,
            unannounced_write_ns: None,
            pending_ask: None,
            peers: BTreeSet::new(),
            answered: BTreeMap::new(),
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

    /// This life's nonce.
    pub fn nonce(&self) -> u64 {
        self.life.nonce
    }

    /// The replica, once ready.
    pub fn replica(&self) -> Option<&Replica> {
        self.replica.as_ref()
    }

    /// Whether the life has its replica.
    pub fn is_ready(&self) -> bool {
        self.replica.is_some()
    }

    /// The id collision seen, if any.
    pub fn collision(&self) -> Option<&str> {
        self.collision.as_deref()
    }

    /// Notes a message from `from` that is not the protocol's (a remote call).
    pub fn heard_from(&mut self, from: AgentId) {
        self.peers.insert(from);
    }

    /// The agents heard from.
    pub fn peers(&self) -> &BTreeSet<AgentId> {
        &self.peers
    }

    /// When this life started joining.
    pub fn joining_since_ns(&self) -> u64 {
        self.joining_since_ns
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
            let wait_end = self.joining_since_ns.saturating_add(self.config.join_wait_ns);
            let retry =
                self.last_request_ns.map_or(self.joining_since_ns, |at| at.saturating_add(self.config.join_retry_ns));
            return wait_end.min(retry);
        }
        let quiet = self
            .unannounced_write_ns
            .filter(|_| self.config.quiet_announce_ns > 0)
            .map_or(u64::MAX, |at| at.saturating_add(self.config.quiet_announce_ns));
        self.next_announce_ns.min(quiet)
    }

    /// Discovery matched a new peer endpoint: while joining, the next tick asks for the graph at once (a request
    /// published before the match reached nobody).
    pub fn discovery_matched(&mut self) {
        self.request_now = true;
    }

    /// The periodic work due at `now_ns`: graph requests while joining, starting alone after the join wait,
    /// announces.
    pub fn tick(&mut self, now_ns: u64) -> Output {
        let mut out = Output::default();
        if self.replica.is_none() {
            if now_ns.saturating_sub(self.joining_since_ns) >= self.config.join_wait_ns {
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
                    out.send(Channel::Sync, request, Dest::All);
                }
            }
            return out;
        }
        let quiet = self.config.quiet_announce_ns;
        let quiet_after_writes =
            quiet > 0 && self.unannounced_write_ns.is_some_and(|at| now_ns.saturating_sub(at) >= quiet);
        if (now_ns >= self.next_announce_ns || quiet_after_writes)
            && let Some(digest) = self.digest()
            && let Some(replica) = &self.replica
        {
            let announce = Message::Announce {
                from: self.config.id,
                nonce: self.life.nonce,
                replica: replica.id(),
                applied: replica.applied().clone(),
                digest: digest.0,
            };
            out.send(Channel::Sync, announce, Dest::All);
            self.next_announce_ns = if self.config.plant.is(ProtocolMutant::AnnounceTimerLost) {
                u64::MAX
            } else {
                now_ns + self.config.announce_period_ns
            };
            self.unannounced_write_ns = None;
        }
        out
    }

    /// Handles a received message at `now_ns`.
    pub fn handle(&mut self, now_ns: u64, input: Input) -> Output {
        let mut out = Output::default();
        self.peers.insert(input.from());
        match input {
            Input::Delta { from, delta } => {
                self.gap_request(from, &delta, now_ns, &mut out);
                self.apply("delta", vec![delta], &mut out);
            }
            Input::Announce { from, nonce, replica, applied, digest } => {
                self.note_incarnations(&applied, &mut out);
                if from == self.id() {
                    self.check_collision(nonce, Some(replica), "announce", &mut out);
                }
                self.on_announce(from, &applied, digest, now_ns, &mut out);
            }
            Input::MissingRequest { from, applied, full } => self.answer_missing(from, &applied, full, &mut out),
            Input::Deltas { from, deltas } => {
                self.answered_by(from);
                self.apply("missing delta", deltas, &mut out);
            }
            Input::Snapshot { from, snapshot } => {
                self.answered_by(from);
                self.note_incarnations(snapshot.context(), &mut out);
                self.apply("snapshot", vec![snapshot], &mut out);
            }
            Input::GraphRequest { from, nonce } => {
                if from == self.id() {
                    self.check_collision(nonce, None, "graph request", &mut out);
                } else {
                    self.answer_graph_request(from, nonce, now_ns, &mut out);
                }
            }
            Input::GraphAnswer { nonce, snapshot, .. } => {
                if nonce == self.life.nonce && self.replica.is_none() {
                    self.become_ready(now_ns, Some(snapshot), &mut out);
                }
            }
        }
        out
    }

    /// Runs a local operation on the replica at `now_ns`. Its deltas go out on [`Channel::Updates`]:
    /// [`Written::sends`] encodes them, so that a caller holding a lock around the core can encode after releasing
    /// it (a camera frame's encoding would otherwise keep readers waiting).
    ///
    /// # Errors
    /// [`WriteRefusal`]: not ready, an id collision, or the replica refused the operation (nothing changed).
    pub fn write<R>(
        &mut self,
        now_ns: u64,
        op: impl FnOnce(&mut Replica, u64) -> Result<(R, Vec<Arc<Delta>>), OpError>,
    ) -> Result<(R, Written), WriteRefusal> {
        if let Some(detail) = &self.collision {
            return Err(WriteRefusal::Collision(detail.clone()));
        }
        let replica = self.replica.as_mut().ok_or(WriteRefusal::NotJoined)?;
        let (result, deltas) = op(replica, now_ns).map_err(WriteRefusal::Op)?;
        let changes = replica.drain_changes();
        if !deltas.is_empty() {
            self.unannounced_write_ns = Some(now_ns);
        }
        Ok((result, Written { from: self.config.id, deltas, changes }))
    }

    // -------------------------------------------------------------------------------------------------------

    fn answered_by(&mut self, from: AgentId) {
        if self.pending_ask.is_some_and(|(peer, _)| peer == from)
            && !self.config.plant.is(ProtocolMutant::PendingAskNeverExpires)
        {
            self.pending_ask = None;
        }
    }

    /// Whether a missing-request is still outstanding: an answer clears it, and one unanswered for half an
    /// announce period no longer counts (a lost request or answer is asked again at the next evidence).
    fn asked_recently(&self, now_ns: u64) -> bool {
        let expiry = if self.config.plant.is(ProtocolMutant::PendingAskNeverExpires) {
            u64::MAX
        } else {
            self.config.announce_period_ns / 2
        };
        self.pending_ask.is_some_and(|(_, at)| now_ns.saturating_sub(at) < expiry)
    }

    fn ask(&mut self, peer: AgentId, full: bool, now_ns: u64, out: &mut Output) {
        let Some(replica) = &self.replica else { return };
        let request =
            Message::MissingRequest { from: self.config.id, to: peer, applied: replica.applied().clone(), full };
        out.send(Channel::Sync, request, Dest::All);
        self.pending_ask = Some((peer, now_ns));
    }

    /// Asks the writer of `delta` at once for its operations before it that were not joined (a lost sample, or
    /// one overtaken in flight), unless a request is outstanding.
    fn gap_request(&mut self, from: AgentId, delta: &Delta, now_ns: u64, out: &mut Output) {
        if self.config.plant.is(ProtocolMutant::NoGapRequest) {
            return;
        }
        let (Some(origin), Some(replica)) = (delta.origin(), &self.replica) else { return };
        if replica.applied().version(origin.replica).saturating_add(1) >= origin.first || self.asked_recently(now_ns) {
            return;
        }
        out.events.push(Event::GapRequest { peer: from });
        self.ask(from, false, now_ns, out);
    }

    fn on_announce(&mut self, from: AgentId, applied: &CausalContext, digest: [u8; 32], now_ns: u64, out: &mut Output) {
        if self.replica.is_none() || self.asked_recently(now_ns) {
            return;
        }
        let lacks = self.replica.as_ref().is_some_and(|r| !r.applied().includes(applied));
        if lacks {
            return self.ask(from, false, now_ns, out);
        }
        let same_ops = self.replica.as_ref().is_some_and(|r| r.applied() == applied);
        if same_ops && self.digest().map(|d| d.0) != Some(digest) {
            // The same operations joined, yet another graph: a bug in the replica. Repair with whole states.
            out.events.push(Event::DigestMismatch { peer: from });
            self.ask(from, true, now_ns, out);
        }
    }

    fn answer_missing(&mut self, from: AgentId, applied: &CausalContext, full: bool, out: &mut Output) {
        let missing = match &self.replica {
            Some(replica) if !full => replica.missing_for(applied),
            _ => Missing::UpToDate,
        };
        let snapshot = match missing {
            Missing::UpToDate => {
                if full {
                    self.snapshot_bytes()
                } else {
                    None
                }
            }
            Missing::Deltas(deltas) => match self.smaller_snapshot(&deltas) {
                Some(snapshot) => Some(snapshot),
                None => {
                    self.batches(from, &deltas, out);
                    None
                }
            },
            Missing::Snapshot => self.snapshot_bytes(),
        };
        if let Some((snapshot, _)) = snapshot {
            out.send(Channel::Sync, Message::Snapshot { from: self.config.id, to: from, snapshot }, Dest::Sender);
        }
    }

    fn answer_graph_request(&mut self, from: AgentId, nonce: u64, now_ns: u64, out: &mut Output) {
        let recent =
            self.answered.get(&(from, nonce)).is_some_and(|at| now_ns.saturating_sub(*at) < self.config.answer_hold_ns);
        if recent {
            return;
        }
        let Some((snapshot, from_cache)) = self.snapshot_bytes() else { return };
        self.answered.retain(|_, at| now_ns.saturating_sub(*at) < self.config.answer_hold_ns);
        if self.answered.len() < MAX_ANSWERED {
            self.answered.insert((from, nonce), now_ns);
        }
        out.events.push(Event::Answered { to: from, snapshot_bytes: snapshot.len(), from_cache });
        let answer = Message::GraphAnswer { from: self.config.id, to: from, nonce, snapshot };
        out.send(Channel::Sync, answer, Dest::Sender);
    }

    /// The encoded snapshot, if `deltas` carry more than [`SNAPSHOT_IF_SMALLER_ABOVE_BYTES`] of payload and the
    /// snapshot is smaller than that payload.
    fn smaller_snapshot(&mut self, deltas: &[Arc<Delta>]) -> Option<(Bytes, bool)> {
        let payload: usize = deltas.iter().map(|d| d.payload_bytes()).sum();
        if payload <= SNAPSHOT_IF_SMALLER_ABOVE_BYTES {
            return None;
        }
        self.snapshot_bytes().filter(|(snapshot, _)| snapshot.len() < payload)
    }

    /// The encoded snapshot (cached per causal context), and whether it came from the cache.
    fn snapshot_bytes(&mut self) -> Option<(Bytes, bool)> {
        let replica = self.replica.as_ref()?;
        if let Some((ctx, bytes)) = &self.caches.0.snapshot
            && ctx == replica.context()
        {
            return Some((bytes.clone(), true));
        }
        let bytes = Bytes::from(replica.encode_snapshot());
        self.caches.0.snapshot = Some((replica.context().clone(), bytes.clone()));
        Some((bytes, false))
    }

    /// Splits retained deltas into answer messages of bounded size.
    fn batches(&self, to: AgentId, deltas: &[Arc<Delta>], out: &mut Output) {
        let me = self.config.id;
        let mut batch = Vec::new();
        let mut bytes = 0;
        for delta in deltas {
            let encoded = Bytes::from(delta.encode());
            if !batch.is_empty() && (bytes + encoded.len() > self.config.max_batch_bytes || batch.len() >= MAX_BATCH) {
                out.send(
                    Channel::Sync,
                    Message::Deltas { from: me, to, deltas: std::mem::take(&mut batch) },
                    Dest::Sender,
                );
                bytes = 0;
            }
            bytes += encoded.len();
            batch.push(encoded);
        }
        if !batch.is_empty() {
            out.send(Channel::Sync, Message::Deltas { from: me, to, deltas: batch }, Dest::Sender);
        }
    }

    /// Joins remote deltas into the replica, or buffers them while joining.
    fn apply(&mut self, what: &'static str, deltas: Vec<Arc<Delta>>, out: &mut Output) {
        // A join can change the store without moving the context (the snapshot repair): drop the caches.
        self.caches.0 = Caches::default();
        let Some(replica) = self.replica.as_mut() else {
            if self.config.plant.is(ProtocolMutant::DropEarlyDelta) {
                return;
            }
            for delta in deltas {
                if self.buffered.len() >= self.config.max_buffered_deltas {
                    self.buffered.pop_front();
                }
                self.buffered.push_back(delta);
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
        out.changes.extend(replica.drain_changes());
    }

    /// Raises the incarnation floor to every incarnation of this agent id in `context`, and reports a reuse of
    /// this life's replica id.
    fn note_incarnations(&mut self, context: &CausalContext, out: &mut Output) {
        let me = self.config.id;
        for replica in context.replicas() {
            if AgentId::of_replica(replica) == me {
                self.incarnation_floor = self.incarnation_floor.max(AgentId::incarnation_of(replica));
            }
        }
        if let Some(detail) = self.replica.as_ref().and_then(|mine| reused_id(mine, context))
            && self.collision.is_none()
        {
            self.collide(detail, out);
        }
    }

    fn collide(&mut self, detail: String, out: &mut Output) {
        out.events.push(Event::Collision { detail: detail.clone() });
        self.collision = Some(detail);
    }

    /// Whether a message with this agent's id from life `nonce` (replica `replica`, if known) is a collision: a
    /// message of another life not older than this one.
    fn check_collision(&mut self, nonce: u64, replica: Option<ReplicaId>, kind: &str, out: &mut Output) {
        if nonce == self.life.nonce || self.collision.is_some() {
            return;
        }
        let mine = self.replica.as_ref().map(|r| AgentId::incarnation_of(r.id()));
        let older = match (replica, mine) {
            (Some(theirs), Some(mine)) => AgentId::incarnation_of(theirs) < mine,
            _ => false,
        };
        if !older {
            let detail = format!(
                "a {kind} from another life of {} (nonce {nonce:#x}, mine {:#x})",
                self.config.id, self.life.nonce
            );
            self.collide(detail, out);
        }
    }

    /// This life's incarnation: above every one seen and the recorded one (or a random floor without a record).
    fn incarnation(&self) -> Option<u32> {
        if self.config.plant.is(ProtocolMutant::IncarnationForgotten) {
            // Only what peers showed counts: a life that starts alone reuses the first life's id.
            return Some(self.incarnation_floor + 1);
        }
        let floor = match self.life.recorded_incarnation {
            Some(recorded) => recorded,
            None => (self.life.nonce % u64::from(RANDOM_FLOOR_LIMIT)) as u32,
        };
        let incarnation = self.incarnation_floor.max(floor).checked_add(1)?;
        (incarnation < INCARNATION_LIMIT).then_some(incarnation)
    }

    /// Creates this life's replica from a graph answer (or alone, from the seed), then applies what was buffered
    /// while joining.
    fn become_ready(&mut self, now_ns: u64, snapshot: Option<Arc<Delta>>, out: &mut Output) {
        if let Some(snapshot) = &snapshot {
            self.note_incarnations(snapshot.context(), out);
        }
        let Some(incarnation) = self.incarnation() else {
            out.events.push(Event::IncarnationsExhausted);
            self.collision = Some(format!("no incarnation of {} is left", self.config.id));
            return;
        };
        let mut replica = Replica::new(self.config.id.replica(incarnation));
        replica.set_log_limits(self.config.log_limits);
        replica.set_change_tracking(true);
        let alone = snapshot.is_none();
        let mut seed_nodes = None;
        if let Some(snapshot) = snapshot {
            if let Err(error) = replica.apply_shared(snapshot) {
                out.events.push(Event::Rejected { what: "graph answer", error: error.to_string() });
                return;
            }
            if self.seed.0.take().is_some() {
                out.events.push(Event::SeedUnused);
            }
        } else if let Some(seed) = self.seed.0.take() {
            match seed.import_into(&mut replica, now_ns) {
                Ok(report) => {
                    seed_nodes = Some(report.nodes);
                    let warnings = report.warnings.iter().map(|w| Event::SeedWarning { warning: w.to_string() });
                    out.events.extend(warnings);
                }
                Err(error) => out.events.push(Event::SeedRefused { error: error.to_string() }),
            }
        }
        out.events.push(Event::Ready { replica: replica.id(), incarnation, alone, seed_nodes });
        self.replica = Some(replica);
        self.caches.0 = Caches::default();
        let buffered: Vec<Arc<Delta>> = std::mem::take(&mut self.buffered).into();
        self.apply("buffered delta", buffered, out);
    }
}

/// Whether `context` holds operations of `replica`'s own id that it did not make (an earlier life used the id).
fn reused_id(replica: &Replica, context: &CausalContext) -> Option<String> {
    let id = replica.id();
    let (held, made) = (context.version(id), replica.applied().version(id));
    (held > made).then(|| {
        format!(
            "a peer holds {held} operations of replica {id}, this life's id, which made {made}: an earlier life used it"
        )
    })
}
