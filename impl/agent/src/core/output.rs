//! What the core asks its runtime to do: messages to send ([`Send`], [`Dest`]), events worth telling a person
//! ([`Event`]), the result of a call ([`Output`]) and of a local write ([`Written`], [`WriteRefusal`]).

use std::sync::Arc;

use bytes::Bytes;
use dsr::{ChangeEvent, Delta, OpError, ReplicaId};
use transport::Channel;

use crate::AgentId;
use crate::envelope::Message;
use crate::graph_id::GraphId;

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
    /// The sender's graph, carried in the envelope (`None` only in the graph request of a joiner that names no
    /// graph).
    pub graph: Option<GraphId>,
    /// The message already in its envelope with `graph`, when it was encoded straight into its sample (a local
    /// delta, [`Message::delta_sample`]); [`Send::encode`] returns it instead of encoding again.
    pub sample: Option<Bytes>,
}

impl Send {
    /// The sample's bytes: the message in its envelope, with the graph id.
    pub fn encode(&self) -> Bytes {
        match &self.sample {
            Some(sample) => sample.clone(),
            None => self.message.encode(self.graph),
        }
    }
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
    /// This life became ready as `replica` of graph `graph`. The shell records `incarnation` (and the graph)
    /// before this life's first write.
    Ready {
        /// The graph it belongs to: its own (named in the settings), the one it joined, the one graph it heard
        /// its peers in when it started alone, or one it created alone.
        graph: GraphId,
        /// This life's replica id.
        replica: ReplicaId,
        /// Its incarnation.
        incarnation: u32,
        /// Whether it started alone (no graph answer within the join wait).
        alone: bool,
        /// Whether its graph is named (see the core's **Graphs**), recorded with it: the next life names a named
        /// graph, and starts alone in an unnamed one only if it hears no graph.
        named: bool,
        /// Nodes of the seed graph imported, when it started alone from one.
        seed_nodes: Option<usize>,
    },
    /// This life, whose graph was unnamed, moved to the graph of an announce it heard: a named graph, or an
    /// unnamed one with a smaller id (see the core's **Graphs**). Anti-entropy then merges the two copies.
    GraphMoved {
        /// The graph it left.
        left: GraphId,
        /// The graph it belongs to now.
        graph: GraphId,
        /// The announcer heard.
        by: AgentId,
        /// Whether the graph it belongs to now is named (the shell records it then, as at [`Event::Ready`]).
        named: bool,
    },
    /// This life's unnamed graph turned out to be named: it heard a named agent of it. It stays in it for good.
    GraphNamed {
        /// The graph.
        graph: GraphId,
        /// The named agent heard.
        by: AgentId,
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
    /// A life that names no graph starts alone after hearing agents of several graphs: it cannot tell which it
    /// was meant to join, so it starts a graph of its own, named (it never moves; see the core's **Graphs**).
    SeveralGraphsHeard {
        /// The graphs heard, in the order first heard.
        graphs: Vec<GraphId>,
    },
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
    /// A message that does not ask arrived on [`Channel::Requests`] (where only asking travels, see
    /// [`Message::asks`]) and was refused, never applied; counted in [`super::AgentCore::misrouted_refused`].
    Misrouted {
        /// The sender it names.
        from: AgentId,
        /// The message's kind.
        kind: &'static str,
        /// Whether it is the first refused so (the shell warns once, then counts).
        first: bool,
    },
    /// A message of another graph was refused (reported once per foreign graph id; later ones are only counted,
    /// see [`super::AgentCore::foreign_refused`]).
    ForeignGraph {
        /// The foreign graph.
        graph: GraphId,
        /// The agent that sent the first refused message of it.
        from: AgentId,
        /// That message's kind.
        kind: &'static str,
        /// This agent's graph (`None` while it joins without naming one).
        mine: Option<GraphId>,
    },
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
    /// Queues a message on its channel ([`Message::channel`]); its graph id is stamped by [`Output::stamp`] when the
    /// core returns.
    pub(super) fn send(&mut self, message: Message, dest: Dest) {
        self.sends.push(Send { channel: message.channel(), message, dest, graph: None, sample: None });
    }

    /// Stamps every queued message with the sender's graph.
    pub(super) fn stamp(mut self, graph: Option<GraphId>) -> Output {
        for send in &mut self.sends {
            if send.graph != graph {
                send.sample = None;
            }
            send.graph = graph;
        }
        self
    }
}

/// What a local write produced.
#[derive(Clone, Debug, PartialEq)]
pub struct Written {
    /// The writer.
    pub from: AgentId,
    /// The writer's graph.
    pub graph: GraphId,
    /// The deltas of the operation, in order.
    pub deltas: Vec<Arc<Delta>>,
    /// The replica's change events.
    pub changes: Vec<ChangeEvent>,
}

impl Written {
    /// The messages that publish the deltas to every agent (encoding each once, straight into its sample).
    pub fn sends(&self) -> Vec<Send> {
        self.deltas
            .iter()
            .map(|delta| {
                let (sample, message) = Message::delta_sample(self.graph, self.from, delta);
                Send {
                    channel: Channel::Updates,
                    message,
                    dest: Dest::All,
                    graph: Some(self.graph),
                    sample: Some(sample),
                }
            })
            .collect()
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
    /// The agent is read-only ([`super::ProtocolConfig::read_only`]): it never changes the graph.
    ReadOnly,
}
