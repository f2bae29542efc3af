//! The [`Agent`]: a `dsr::Replica` behind a thread-safe API, joined to other agents through a [`Transport`].
//!
//! The agent is the thin impure shell around the protocol's pure core ([`crate::core::AgentCore`]), as
//! `bica::runtime` wraps `SchedulerCore`: it owns the threads, the transport, the clock and the one lock. Every
//! protocol decision is the core's, made under that short lock from a received sample or a tick with the clock's
//! `now_ns`; the messages it returns are published after the lock is released, its events logged and counted, a
//! new life's incarnation recorded. The same code runs threaded ([`Agent::start`]: samples handled on the
//! transport's receiving thread or the agent's own) or driven by hand ([`Agent::pump`]: a simulation calls it with a
//! [`transport::ManualClock`] and a seeded fault injector, so runs are reproducible).

use std::collections::BTreeMap;
use std::hash::{BuildHasher, Hasher};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use bytes::Bytes;
use dsr::{AttrKey, AttrType, Change, Digest, Element, NodeId, OpError, Replica, Value, VisibleGraph};
use transport::{Channel, Clock, Sample, Transport, TransportError};

pub use crate::config::AgentConfig;
pub use crate::status::{AgentStatus, AnswerTiming, JoinTimeline, StatusLine};

use crate::AgentId;
use crate::calls::{CallError, CallServer, CallService, CallTable, PendingCall};
use crate::core::{AgentCore, Dest, Event, Input, LifeSeed, Output, Send};
use crate::envelope::{Envelope, Message};

mod drive;
mod signals;
mod timer;
mod writes;

pub use signals::CallbackId;

/// Errors of the agent API.
#[derive(Debug, thiserror::Error)]
pub enum AgentError {
    /// The agent id is out of range.
    #[error("agent id {0} is out of range (0..{limit})", limit = AgentId::LIMIT)]
    InvalidId(u32),
    /// The agent has not received or started its graph yet.
    #[error("{0} has not joined a graph yet")]
    NotJoined(AgentId),
    /// Another live agent uses this id; local writes are refused.
    #[error("{agent}: id collision ({detail}); local writes are refused")]
    IdCollision {
        /// This agent.
        agent: AgentId,
        /// What was seen.
        detail: String,
    },
    /// The agent is read-only ([`AgentConfig::read_only`]): it follows the graph and never changes it.
    #[error("{0} is read-only: it follows the graph and cannot change it (local edits are refused)")]
    ReadOnly(AgentId),
    /// The replica refused the operation.
    #[error("{agent}: {source}")]
    Op {
        /// This agent.
        agent: AgentId,
        /// Why.
        source: OpError,
    },
    /// The transport failed.
    #[error("{agent}: {source}")]
    Transport {
        /// This agent.
        agent: AgentId,
        /// Why.
        source: TransportError,
    },
    /// The seed graph could not be imported.
    #[error("{agent}: seed graph: {source}")]
    Seed {
        /// This agent.
        agent: AgentId,
        /// Why.
        source: dsr::json::JsonError,
    },
    /// A thread could not be started.
    #[error("{agent}: cannot start the receiving thread: {detail}")]
    Thread {
        /// This agent.
        agent: AgentId,
        /// Why.
        detail: String,
    },
}

/// One visible change, with the agent whose operation made it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ChangeSignal {
    /// What changed.
    pub change: Change,
    /// The originating agent (`None` when a snapshot made it and the origin is unknown).
    pub origin: Option<AgentId>,
    /// Whether this agent's own operation made it.
    pub local: bool,
    /// Whether this is the last change of the ones that became visible together (one write, one received delta):
    /// a subscriber that groups the changes of one write reads on until it has one with this set.
    pub last_together: bool,
}

/// A value copy of a visible node.
#[derive(Clone, Debug, PartialEq)]
pub struct NodeCopy {
    /// Its id.
    pub id: NodeId,
    /// Its type.
    pub node_type: String,
    /// Its visible name.
    pub name: String,
    /// Its attributes' winning values.
    pub attrs: BTreeMap<String, Value>,
}

/// What the lock guards: the protocol core and what the shell measures about it.
struct Locked {
    core: AgentCore,
    /// The transport's [`Transport::sync_matches`] when the core was last told of a match.
    sync_matches_seen: u64,
    /// How the late join went.
    timeline: JoinTimeline,
}

/// Where a sample came from, for messages: formatted only when one is written.
struct SampleOrigin<'a>(&'a Sample);

impl std::fmt::Display for SampleOrigin<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{} on channel {}", self.0.origin, self.0.channel.name())
    }
}

struct Inner<T> {
    config: AgentConfig,
    nonce: u64,
    transport: T,
    clock: Arc<dyn Clock>,
    state: Mutex<Locked>,
    signals: signals::Signals,
    stop: AtomicBool,
    /// Whether the replica exists (the receiving thread polls faster while joining).
    joined: AtomicBool,
    /// The latest graph request answered.
    last_answer: Mutex<Option<AnswerTiming>>,
    rejected: AtomicU64,
    digest_mismatches: AtomicU64,
    gap_requests: AtomicU64,
    /// Large values received, read in place from their sample (`.0`) or copied out of it (`.1`).
    large_values: (AtomicU64, AtomicU64),
    publish_failures: AtomicU64,
    calls: Arc<CallTable>,
    service: CallService,
    /// When the agent's thread next has periodic work, and its bell.
    timer: timer::Timer,
    /// Tells the replies thread to stop (it waits for replies with no timeout).
    halt: (crossbeam_channel::Sender<()>, crossbeam_channel::Receiver<()>),
}

/// A DSR_d agent. Thread-safe: share it by reference or in an `Arc`.
pub struct Agent<T: Transport + 'static> {
    inner: Arc<Inner<T>>,
    threads: Mutex<Vec<JoinHandle<()>>>,
}

impl<T: Transport + 'static> std::fmt::Debug for Agent<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Agent").field("id", &self.inner.config.id).field("nonce", &self.inner.nonce).finish()
    }
}

fn random_nonce() -> u64 {
    let mut hasher = std::collections::hash_map::RandomState::new().build_hasher();
    hasher.write_u32(std::process::id());
    hasher
        .write_u128(std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).unwrap_or_default().as_nanos());
    hasher.finish()
}

impl<T: Transport + 'static> Agent<T> {
    /// An agent driven by hand ([`Agent::pump`]): it starts joining at the clock's current time.
    ///
    /// # Errors
    /// [`AgentError::InvalidId`] for an id out of range.
    pub fn new(mut config: AgentConfig, transport: T, clock: Arc<dyn Clock>) -> Result<Self, AgentError> {
        if config.id.0 >= AgentId::LIMIT {
            return Err(AgentError::InvalidId(config.id.0));
        }
        let now = clock.now_ns();
        let nonce = config.nonce.unwrap_or_else(random_nonce);
        let seed = config.seed.take();
        let recorded_incarnation = match (&config.life_file, config.recorded_incarnation) {
            (_, Some(recorded)) => Some(recorded),
            (Some(path), None) => crate::life::recorded(path).unwrap_or_else(|error| {
                tracing::error!("{}: cannot read the incarnation record {}: {error}", config.id, path.display());
                None
            }),
            (None, None) => None,
        };
        let mut recorded_graph = None;
        if config.graph.is_none()
            && let Some(path) = &config.life_file
        {
            match crate::life::recorded_graph(path) {
                Ok(Some((graph, true))) => config.graph = Some(graph),
                Ok(unnamed) => recorded_graph = unnamed.map(|(graph, _)| graph),
                Err(error) => {
                    tracing::error!("{}: cannot read the graph record {}: {error}", config.id, path.display())
                }
            }
        }
        let life = LifeSeed { nonce, recorded_incarnation, recorded_graph };
        let mut core = AgentCore::new(config.protocol(), life, seed, now);
        // Nobody listens yet: a subscription or callback turns the report of changes on.
        core.set_change_tracking(false);
        let state = Locked {
            core,
            sync_matches_seen: 0,
            timeline: JoinTimeline { started_ns: now, ..JoinTimeline::default() },
        };
        let inner = Inner {
            nonce,
            transport,
            clock,
            state: Mutex::new(state),
            signals: signals::Signals::default(),
            stop: AtomicBool::new(false),
            joined: AtomicBool::new(false),
            last_answer: Mutex::new(None),
            rejected: AtomicU64::new(0),
            digest_mismatches: AtomicU64::new(0),
            gap_requests: AtomicU64::new(0),
            large_values: (AtomicU64::new(0), AtomicU64::new(0)),
            publish_failures: AtomicU64::new(0),
            calls: Arc::new(CallTable::new(config.max_calls_in_flight, nonce)),
            service: CallService::new(config.call_reply_outbox),
            timer: timer::Timer::new(now, config.tick()),
            halt: crossbeam_channel::bounded(1),
            config,
        };
        Ok(Agent { inner: Arc::new(inner), threads: Mutex::new(Vec::new()) })
    }

    /// Waits (up to `timeout`) until the agent has its graph; returns whether it has.
    pub fn wait_ready(&self, timeout: Duration) -> bool {
        let deadline = Instant::now() + timeout;
        loop {
            if self.is_ready() {
                return true;
            }
            if Instant::now() >= deadline {
                return false;
            }
            std::thread::sleep(Duration::from_millis(1));
        }
    }

    /// Stops the agent's threads (if any) and the handling of samples on the transport's receiving thread, and
    /// waits for both.
    pub fn shutdown(&self) {
        self.inner.stop.store(true, Ordering::SeqCst);
        self.inner.timer.ring();
        let _ = self.inner.halt.0.try_send(());
        // Waits for a sample being handled on the transport's thread, and releases the sink's hold on the state.
        self.inner.transport.set_sink(None);
        let handles = std::mem::take(&mut *self.threads.lock().unwrap_or_else(|p| p.into_inner()));
        for handle in handles {
            let _ = handle.join();
        }
    }

    /// This agent's id.
    pub fn id(&self) -> AgentId {
        self.inner.config.id
    }

    /// This life's nonce.
    pub fn nonce(&self) -> u64 {
        self.inner.nonce
    }

    /// The transport.
    pub fn transport(&self) -> &T {
        &self.inner.transport
    }

    /// Whether the graph has been received or started.
    pub fn is_ready(&self) -> bool {
        self.inner.lock().core.is_ready()
    }

    /// Status and counters.
    pub fn status(&self) -> AgentStatus {
        let locked = self.inner.lock();
        let core = &locked.core;
        AgentStatus {
            id: self.inner.config.id,
            replica: core.replica().map(Replica::id),
            ready: core.is_ready(),
            collision: core.collision().map(str::to_owned),
            graph: core.graph(),
            graph_named: core.graph_named(),
            foreign_refused: core.foreign_refused(),
            foreign_graphs: core.foreign_graphs().iter().copied().collect(),
            misrouted_refused: core.misrouted_refused(),
            read_only: self.inner.config.read_only,
            rejected: self.inner.rejected.load(Ordering::Relaxed),
            signals_dropped: self.inner.signals.dropped(),
            change_tracking: core.change_tracking(),
            publish_failures: self.inner.publish_failures.load(Ordering::Relaxed),
            digest_mismatches: self.inner.digest_mismatches.load(Ordering::Relaxed),
            gap_requests: self.inner.gap_requests.load(Ordering::Relaxed),
            large_values_shared: self.inner.large_values.0.load(Ordering::Relaxed),
            large_values_copied: self.inner.large_values.1.load(Ordering::Relaxed),
            calls_served: self.inner.service.served.load(Ordering::Relaxed),
            call_replies_dropped: self.inner.service.dropped.load(Ordering::Relaxed),
            late_call_replies: self.inner.calls.late.load(Ordering::Relaxed),
            calls_in_flight: self.inner.calls.in_flight(),
            peers: core.peers().collect(),
            nodes: core.replica().map_or(0, Replica::node_count),
            edges: core.replica().map_or(0, Replica::edge_count),
            transport: self.inner.transport.stats(),
            join: locked.timeline,
            last_answer: *self.inner.last_answer.lock().unwrap_or_else(|p| p.into_inner()),
        }
    }

    /// This agent's status as one machine-readable line, `uptime_ms` after its process started.
    pub fn status_line(&self, uptime_ms: u64) -> StatusLine {
        let status = self.status();
        StatusLine {
            id: status.id.0,
            ready: status.ready,
            alone: status.ready && status.join.alone,
            graph: status.graph,
            graph_named: status.graph_named,
            foreign_refused: status.foreign_refused,
            foreign_graphs: status.foreign_graphs,
            misrouted_refused: status.misrouted_refused,
            read_only: status.read_only,
            replica: status.replica.map(|r| r.0),
            nodes: status.nodes,
            edges: status.edges,
            digest: self.digest().map(|d| d.to_string()),
            peers: status.peers.iter().map(|p| p.0).collect(),
            rejected: status.rejected,
            collision: status.collision,
            uptime_ms,
            samples_sent: status.transport.samples_sent,
            samples_received: status.transport.samples_received,
            calls_served: status.calls_served,
            node_types: self.read(|r| {
                let mut counts = std::collections::BTreeMap::<String, u64>::new();
                for node in r.nodes() {
                    *counts.entry(node.node_type().to_string()).or_default() += 1;
                }
                counts
            }),
            wire_bytes_sent: status.transport.wire_bytes_sent,
            participant_failures: status.transport.participant_failures,
            participant_rebuilds: status.transport.participant_rebuilds,
            shm_samples_sent: status.transport.shm_samples_sent,
            shm_samples_received: status.transport.shm_samples_received,
            shm_samples_leased: status.transport.shm_samples_leased,
            same_host_peers: status.transport.same_host_peers,
            large_values_shared: status.large_values_shared,
            large_values_copied: status.large_values_copied,
            unaddressed_writes: status.transport.unaddressed_writes,
        }
    }

    // -------------------------------------------------------------------------------------------------------
    // Reads: a short lock, never the network.

    /// Runs `f` on the replica (`None` before the agent has its graph). Keep `f` short: it holds the lock.
    pub fn read<R>(&self, f: impl FnOnce(&Replica) -> R) -> Option<R> {
        self.inner.lock().core.replica().map(f)
    }

    /// A value copy of node `id`, if visible.
    pub fn node(&self, id: NodeId) -> Option<NodeCopy> {
        self.read(|r| r.node(id).map(|n| node_copy(&n))).flatten()
    }

    /// A value copy of the node named `name`, if visible.
    pub fn node_by_name(&self, name: &str) -> Option<NodeCopy> {
        self.read(|r| r.node_by_name(name).map(|n| node_copy(&n))).flatten()
    }

    /// The typed value of an attribute of a visible node or edge.
    pub fn attr<V: AttrType>(&self, element: impl Into<Element>, key: AttrKey<V>) -> Option<V> {
        let element = element.into();
        self.read(|r| match &element {
            Element::Node(id) => r.node(*id).and_then(|n| n.get(key)),
            Element::Edge(edge) => r.edge(edge).and_then(|e| e.get(key)),
        })
        .flatten()
    }

    /// The digest of the visible graph.
    pub fn digest(&self) -> Option<Digest> {
        self.read(Replica::digest)
    }

    /// The visible graph in canonical form.
    pub fn visible_graph(&self) -> Option<VisibleGraph> {
        self.read(Replica::visible_graph)
    }

    // -------------------------------------------------------------------------------------------------------
    // Remote calls (see `crate::calls`).

    /// Serves the calls addressed to this agent with `server` from now on (replacing an earlier one).
    pub fn serve_calls(&self, server: Arc<dyn CallServer>) {
        *self.inner.service.server.lock().unwrap_or_else(|p| p.into_inner()) = Some(server);
    }

    /// Stops serving calls: later requests are answered [`crate::CallFault::NoRuntime`].
    pub fn stop_serving_calls(&self) {
        *self.inner.service.server.lock().unwrap_or_else(|p| p.into_inner()) = None;
    }

    /// Sends a call of `method` with the request bytes `args` to agent `to`; does not wait.
    ///
    /// # Errors
    /// [`CallError::TooManyInFlight`], or [`CallError::Send`] when the transport refuses the request.
    pub fn call_start(&self, to: AgentId, method: &str, args: Bytes) -> Result<PendingCall, CallError> {
        let (call, receiver) = self.inner.calls.open(to, method)?;
        let pending =
            PendingCall { table: Arc::clone(&self.inner.calls), call, to, method: method.to_owned(), receiver };
        let message = Message::CallRequest { from: self.id(), to, call, method: method.to_owned(), args };
        let graph = self.inner.lock().core.graph();
        self.inner.transport.publish(Channel::Calls, message.encode(graph)).map_err(|e| CallError::Send {
            to,
            method: method.to_owned(),
            detail: e.to_string(),
        })?;
        Ok(pending)
    }

    /// Calls `method` of agent `to` with raw request bytes and waits up to `timeout` for the response bytes.
    ///
    /// # Errors
    /// [`CallError`]: the server's fault, a timeout, too many calls in flight, a send failure.
    pub fn call_bytes(&self, to: AgentId, method: &str, args: Bytes, timeout: Duration) -> Result<Bytes, CallError> {
        self.call_start(to, method, args)?.wait(timeout)
    }

    /// Calls `method` of agent `to` with a typed request (`postcard`-encoded) and waits up to `timeout` for the
    /// typed response.
    ///
    /// # Errors
    /// As [`Agent::call_bytes`], and [`CallError::Codec`] when the request does not encode or the response is not
    /// an `R`.
    pub fn call<Q: serde::Serialize, R: serde::de::DeserializeOwned>(
        &self,
        to: AgentId,
        method: &str,
        request: &Q,
        timeout: Duration,
    ) -> Result<R, CallError> {
        let args = postcard::to_allocvec(request).map_err(|e| CallError::Codec {
            to,
            method: method.to_owned(),
            detail: format!("encoding the request: {e}"),
        })?;
        let bytes = self.call_bytes(to, method, Bytes::from(args), timeout)?;
        crate::calls::decode_response(to, method, &bytes)
    }
}

impl<T: Transport + 'static> Drop for Agent<T> {
    fn drop(&mut self) {
        self.shutdown();
    }
}

fn node_copy(node: &dsr::NodeRef<'_>) -> NodeCopy {
    NodeCopy {
        id: node.id(),
        node_type: node.node_type().to_string(),
        name: node.name().into_owned(),
        attrs: node.attrs().map(|(k, v)| (k.to_string(), v.clone())).collect(),
    }
}

impl<T: Transport> Inner<T> {
    fn lock(&self) -> MutexGuard<'_, Locked> {
        self.state.lock().unwrap_or_else(|p| p.into_inner())
    }

    fn me(&self) -> AgentId {
        self.config.id
    }

    /// Publishes what the core asked for (never called with the state lock held): to everyone, or to the endpoint
    /// `sender` alone where the transport can address one.
    fn send(&self, sends: Vec<Send>, sender: Option<transport::EndpointId>) {
        for send in sends {
            let bytes = send.encode();
            let result = match (send.dest, sender) {
                (Dest::Sender, Some(to)) => self.transport.publish_to(send.channel, bytes, to),
                _ => self.transport.publish(send.channel, bytes),
            };
            if let Err(error) = result {
                self.publish_failures.fetch_add(1, Ordering::Relaxed);
                tracing::warn!("{}: publishing a {} message failed: {error}", self.me(), send.message.kind());
            }
        }
    }

    /// Publishes the deltas of a local write to every agent (never called with the state lock held). Each goes as
    /// [`Message::delta_pieces`]: what [`crate::core::Written::sends`] would send, without first copying its large
    /// values into one buffer, so a transport that writes into shared memory copies a camera frame once.
    fn publish_written(&self, written: &crate::core::Written) {
        for delta in &written.deltas {
            let pieces = Message::delta_pieces(written.graph, written.from, delta);
            let pieces: Vec<&[u8]> = pieces.iter().collect();
            if let Err(error) = self.transport.publish_pieces(Channel::Updates, &pieces) {
                self.publish_failures.fetch_add(1, Ordering::Relaxed);
                tracing::warn!("{}: publishing a delta message failed: {error}", self.me());
            }
        }
    }

    fn signal(&self, changes: Vec<dsr::ChangeEvent>) {
        // No state lock and no signal for a change nobody listens to (every write and every joined delta comes here).
        if changes.is_empty() {
            return;
        }
        if !self.signals.listened() {
            // The last listener went (a dropped subscription is noticed as a signal fails to reach it).
            return self.track_changes_if_listened();
        }
        let mine = self.lock().core.replica().map(Replica::id);
        self.signals.deliver(mine, changes);
    }

    /// Reports changes while someone listens, and stops looking for them when nobody does: the look before and
    /// after every write and join is a good part of their cost (`AgentCore::set_change_tracking`). Decided under
    /// the state lock, where a new listener turns it on after registering, so the last word is always right.
    fn track_changes_if_listened(&self) {
        let mut locked = self.lock();
        let listened = self.signals.listened();
        if locked.core.change_tracking() != listened {
            locked.core.set_change_tracking(listened);
        }
    }

    fn reject(&self, origin: &dyn std::fmt::Display, what: &str, error: &dyn std::fmt::Display) {
        self.rejected.fetch_add(1, Ordering::Relaxed);
        tracing::error!("{}: dropped a {what} from {origin}: {error}", self.me());
    }

    /// Records the incarnation of `replica`, this life's, and its graph, named or not, in the life file (if any).
    fn record_life(&self, replica: dsr::ReplicaId, graph: crate::GraphId, named: bool) {
        let Some(path) = &self.config.life_file else { return };
        let incarnation = AgentId::incarnation_of(replica);
        if let Err(error) = crate::life::record(path, incarnation, graph, named) {
            tracing::error!(
                "{}: cannot record incarnation {incarnation} in {}: {error}; a later life started alone may reuse \
                 replica {replica}",
                self.me(),
                path.display()
            );
        }
    }

    /// Tells a person, counts and records what the core reported (under the state lock: a new life's incarnation
    /// is recorded before the life can write).
    fn report(&self, locked: &mut Locked, events: &[Event], origin: &dyn std::fmt::Display) {
        let me = self.me();
        for event in events {
            match event {
                Event::Rejected { what, error } => self.reject(origin, what, error),
                Event::GraphRequested => {
                    let now = locked.core.last_request_ns().unwrap_or_default();
                    let timeline = &mut locked.timeline;
                    timeline.first_request_ns.get_or_insert(now);
                    timeline.last_request_ns = Some(now);
                    timeline.requests += 1;
                }
                Event::Ready { graph, replica, incarnation, alone, named, seed_nodes } => {
                    self.record_life(*replica, *graph, *named);
                    let heard: Vec<AgentId> = locked.core.peers().collect();
                    if *alone && heard.is_empty() {
                        tracing::info!("{me}: no peer answered within {:?}; started alone", self.config.join_wait);
                    } else if *alone {
                        // Peers were there, yet no graph came: a split brain until anti-entropy merges the
                        // replicas (of one graph: the one named, or the one graph the peers were heard in).
                        tracing::warn!(
                            "{me}: started alone after {:?} although it heard {heard:?}: no graph answer came (a \
                             peer answers a repeated request only {:?} after the last; a join wait above that plus \
                             a retry lets it); anti-entropy merges it with the agents of graph {graph} it hears",
                            self.config.join_wait,
                            self.config.answer_hold
                        );
                    }
                    if let Some(nodes) = seed_nodes {
                        tracing::info!("{me}: started from the seed graph ({nodes} nodes)");
                    }
                    tracing::info!("{me}: ready as replica {replica} (incarnation {incarnation}) of graph {graph}");
                    locked.timeline.alone = *alone;
                    self.joined.store(true, Ordering::Relaxed);
                }
                Event::SeedRefused { error } => {
                    tracing::error!("{me}: the seed graph was refused, starting empty: {error}")
                }
                Event::SeedWarning { warning } => tracing::warn!("{me}: seed graph: {warning}"),
                Event::SeedUnused => tracing::warn!("{me}: joined a running graph; the seed graph is not used"),
                Event::SeveralGraphsHeard { graphs } => {
                    let graphs: Vec<String> = graphs.iter().map(ToString::to_string).collect();
                    tracing::warn!(
                        "{me}: heard agents of graphs {} and no graph answer came: it cannot tell which to join, \
                         so it starts a graph of its own; name the graph to join (`cortex agent --graph-id`)",
                        graphs.join(", ")
                    );
                }
                Event::Answered { .. } => {}
                Event::Collision { detail } => {
                    tracing::error!("{me}: id collision: {detail}; local writes are refused")
                }
                Event::DigestMismatch { peer } => {
                    self.digest_mismatches.fetch_add(1, Ordering::Relaxed);
                    tracing::error!(
                        "{me}: same operations joined as {peer} but a different graph digest; exchanging snapshots"
                    );
                }
                Event::GapRequest { .. } => {
                    self.gap_requests.fetch_add(1, Ordering::Relaxed);
                }
                Event::IncarnationsExhausted => {
                    tracing::error!("{me}: no incarnation is left for a new life; local writes are refused")
                }
                Event::Misrouted { from, kind, first: true } => tracing::warn!(
                    "{me}: refused a {kind} from {from} ({origin}): only requests travel on the requests channel; \
                     later ones are counted (`misrouted_refused`) without another warning"
                ),
                Event::Misrouted { from, kind, first: false } => {
                    tracing::debug!("{me}: refused a {kind} from {from} ({origin}) on the requests channel")
                }
                Event::ForeignGraph { graph, from, kind, mine } => {
                    let mine = mine.map_or_else(|| "none yet".to_string(), |g| g.to_string());
                    let moves = if locked.core.graph_named() {
                        ""
                    } else {
                        " (this agent's graph is unnamed: it moves to a named graph, or to a smaller unnamed id, it \
                         hears announced)"
                    };
                    tracing::warn!(
                        "{me}: refused a {kind} of graph {graph} from {from} ({origin}): this agent's graph is \
                         {mine}; every message of graph {graph} is refused and counted, without another warning{moves}"
                    );
                }
                Event::GraphMoved { left, graph, by, named } => {
                    if let Some(replica) = locked.core.replica().map(Replica::id) {
                        self.record_life(replica, *graph, *named);
                    }
                    let what = if *named { "named" } else { "unnamed, with a smaller id" };
                    tracing::warn!(
                        "{me}: left its unnamed graph {left} for graph {graph} ({what}) announced by {by} ({origin}); \
                         anti-entropy merges the two copies"
                    );
                }
                Event::GraphNamed { graph, by } => {
                    if let Some(replica) = locked.core.replica().map(Replica::id) {
                        self.record_life(replica, *graph, true);
                    }
                    tracing::info!("{me}: graph {graph} is named ({by} names it); this agent stays in it");
                }
            }
        }
    }

    fn handle(&self, sample: Sample) {
        let received_ns = self.clock.now_ns();
        let origin = SampleOrigin(&sample);
        let Envelope { graph, message } = match Envelope::decode(&sample.bytes) {
            Ok(envelope) => envelope,
            Err(error) => return self.reject(&origin, "sample", &error),
        };
        if message.to().is_some_and(|to| to != self.me()) {
            return;
        }
        {
            // Only asking travels on the requests channel: anything else there is refused before it touches anything.
            let mut locked = self.lock();
            let mut out = Output::default();
            let admitted = locked.core.admit_channel(sample.channel, &message, &mut out);
            self.report(&mut locked, &out.events, &origin);
            if !admitted {
                return;
            }
        }
        let me = self.me();
        // Calls never touch the replica: route them without holding the state lock across the server.
        let message = match message {
            Message::CallRequest { .. } | Message::CallReply { .. } => {
                let admitted = {
                    let mut locked = self.lock();
                    let mut out = Output::default();
                    let admitted = locked.core.admit(graph, message.from(), message.kind(), &mut out);
                    self.report(&mut locked, &out.events, &origin);
                    if admitted {
                        locked.core.heard_from(message.from(), received_ns);
                    }
                    admitted
                };
                match message {
                    // A read-only agent may not publish the reply; it serves no calls.
                    Message::CallRequest { from, call, method, args, .. } if admitted && !self.config.read_only => {
                        return self.service.request(me, from, call, &method, args);
                    }
                    Message::CallReply { from, call, result, .. } if admitted => {
                        return self.calls.deliver(from, call, result);
                    }
                    _ => return,
                }
            }
            other => other,
        };
        let answer_bytes = match &message {
            Message::GraphAnswer { snapshot, .. } => Some(snapshot.len()),
            _ => None,
        };
        let decoded = Input::decode(message);
        for (what, error) in &decoded.rejected {
            self.reject(&origin, what, error);
        }
        self.large_values.0.fetch_add(decoded.large.shared, Ordering::Relaxed);
        self.large_values.1.fetch_add(decoded.large.copied, Ordering::Relaxed);
        let Some(input) = decoded.input else { return };
        let decoded_ns = self.clock.now_ns();
        let (out, answered, earlier) = {
            let mut locked = self.lock();
            let out = locked.core.handle(decoded_ns, graph, input);
            // Handled on the transport's thread (a sink), the agent's is rung below; handled on its own, the bell
            // only makes its next sleep look again.
            let earlier = self.timer.schedule(locked.core.next_deadline_ns());
            self.report(&mut locked, &out.events, &origin);
            if let (Some(bytes), true) = (answer_bytes, out.events.iter().any(|e| matches!(e, Event::Ready { .. }))) {
                let timeline = &mut locked.timeline;
                timeline.answer_received_ns = Some(received_ns);
                timeline.answer_bytes = bytes;
                timeline.decoded_ns = Some(decoded_ns);
                timeline.ready_ns = Some(self.clock.now_ns());
            }
            let answered = out.events.iter().find_map(|event| match event {
                Event::Answered { to, snapshot_bytes, from_cache } => Some(AnswerTiming {
                    to: *to,
                    request_received_ns: received_ns,
                    snapshot_ready_ns: self.clock.now_ns(),
                    from_cache: *from_cache,
                    published_ns: 0,
                    snapshot_bytes: *snapshot_bytes,
                }),
                _ => None,
            });
            (out, answered, earlier)
        };
        self.send(out.sends, Some(sample.origin));
        if let Some(mut answer) = answered {
            answer.published_ns = self.clock.now_ns();
            *self.last_answer.lock().unwrap_or_else(|p| p.into_inner()) = Some(answer);
        }
        self.signal(out.changes);
        if earlier {
            self.timer.ring();
        }
    }

    /// Periodic work: graph requests while joining, starting alone after the wait, announces.
    fn tick(&self) {
        let now = self.clock.now_ns();
        let out = {
            let mut locked = self.lock();
            // A request published before discovery matched a peer reaches nobody: ask again at once when a new
            // match appears, besides the periodic retry.
            let matches = self.transport.sync_matches();
            if matches != locked.sync_matches_seen {
                locked.sync_matches_seen = matches;
                locked.core.discovery_matched();
            }
            let out = locked.core.tick(now);
            self.timer.reset(locked.core.next_deadline_ns());
            self.report(&mut locked, &out.events, &"this agent");
            if out.events.iter().any(|e| matches!(e, Event::Ready { .. })) {
                locked.timeline.ready_ns = Some(now);
            }
            out
        };
        self.send(out.sends, None);
        self.signal(out.changes);
    }
}
