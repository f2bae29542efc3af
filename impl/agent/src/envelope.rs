//! The agent-level wire envelope: what agents say to each other, around `dsr`'s delta encoding.
//!
//! Every sample starts with an 11-byte header — a magic byte ([`MAGIC`]), the envelope version ([`VERSION`]), the
//! message kind and the sender's graph id ([`GraphId`], 8 bytes little-endian; 0 = "no graph yet", allowed only in
//! a joiner's graph request) — followed by the kind's fields in `postcard` and, for kinds that carry one delta or
//! snapshot, the `dsr` bytes as the raw tail (no copy, no length). A one-attribute update is therefore the delta's
//! ~40 bytes plus 12 or 13. An [`Envelope`] is the graph id with the [`Message`]. **Decoding never panics**: foreign bytes, an unknown version or kind, truncated or trailing bytes,
//! and lists over the limits are [`EnvelopeError`]s that say which kind and what; payload slices share the
//! sample's buffer. Deltas inside are decoded (and checked) by the agent with `dsr::Delta::decode`.
//!
//! A call request is `(from, to, call id, method name, request bytes)` and its reply `(from, to, call id,
//! Ok(response bytes) | Err(CallFault))`, the bytes being the method's `postcard` encoding (see [`crate::calls`]).

use bytes::Bytes;
use dsr::{CausalContext, Dot, ReplicaId};
use serde::{Deserialize, Serialize};
use transport::Channel;

use crate::AgentId;
use crate::graph_id::GraphId;

/// Why the serving agent could not answer with a response (sent in a call reply).
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum CallFault {
    /// The server has no method of that name.
    UnknownMethod(String),
    /// The request bytes do not decode as the method's request.
    BadRequest(String),
    /// The method ran and failed.
    Failed(String),
    /// The server's queue is full or it has stopped; nothing ran.
    Busy(String),
    /// The agent serves no calls (no BICA runtime attached).
    NoRuntime(String),
}

/// First byte of every envelope: a foreign sample on our topics is recognised at once.
pub const MAGIC: u8 = 0xD5;
/// The envelope version this build writes and reads (2: the graph id in the header; 3: an announce's digest is
/// optional, and asking goes on the requests channel; 4: announces and graph answers say whether their sender's
/// graph is named).
pub const VERSION: u8 = 4;
/// Bytes of the header: magic, version, kind, graph id.
pub const HEADER_BYTES: usize = 11;
/// Most version-vector entries in a carried context.
pub const MAX_VV: usize = 1 << 16;
/// Most out-of-order dots in a carried context.
pub const MAX_CLOUD: usize = 1 << 20;
/// Most deltas in one [`Message::Deltas`].
pub const MAX_BATCH: usize = 1 << 16;

/// One message between agents. Payload fields hold encoded `dsr` deltas.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Message {
    /// The delta of one local operation.
    Delta {
        /// The writer.
        from: AgentId,
        /// `dsr::Delta::encode` bytes.
        delta: Bytes,
    },
    /// Periodic anti-entropy announce: who I am (nonce of this life) and what I have seen.
    Announce {
        /// The announcer.
        from: AgentId,
        /// Random number of the announcer's life: another nonce with the same agent id is a collision.
        nonce: u64,
        /// The announcer's replica id.
        replica: ReplicaId,
        /// The operations the announcer has joined (`dsr::Replica::applied`): what anti-entropy compares.
        applied: CausalContext,
        /// Digest of the announcer's visible graph, when its graph is still: it joined nothing since its previous
        /// announce (a digest hashes every value, a camera frame included, and a graph still changing would be
        /// compared with nothing). Equal applied sets with different digests would be a bug in the replica; the
        /// receiver logs it as an error and repairs with whole states.
        digest: Option<[u8; 32]>,
        /// Whether the announcer's graph is named (`agent::core`, **Graphs**): an agent whose graph is unnamed
        /// moves to the graph of a named announce it hears.
        named: bool,
    },
    /// "Send me what I lack": sent to a peer whose announce showed dots the sender has not seen.
    MissingRequest {
        /// The asker.
        from: AgentId,
        /// The peer asked.
        to: AgentId,
        /// The operations the asker has joined.
        applied: CausalContext,
        /// Ask for a whole snapshot, whatever the applied sets say (the digests differed).
        full: bool,
    },
    /// Deltas a peer lacked (answer to [`Message::MissingRequest`]).
    Deltas {
        /// The sender.
        from: AgentId,
        /// The asker.
        to: AgentId,
        /// Encoded deltas.
        deltas: Vec<Bytes>,
    },
    /// A whole state, when it is cheaper than the deltas or the history does not cover the gap.
    Snapshot {
        /// The sender.
        from: AgentId,
        /// The asker.
        to: AgentId,
        /// Encoded snapshot.
        snapshot: Bytes,
    },
    /// A joining agent asks for the graph; any running agent answers.
    GraphRequest {
        /// The joiner.
        from: AgentId,
        /// Random number of the joiner's life.
        nonce: u64,
    },
    /// The graph, for a joiner.
    GraphAnswer {
        /// The answering agent.
        from: AgentId,
        /// The joiner.
        to: AgentId,
        /// The joiner's nonce, echoed (an answer meant for an earlier life is ignored).
        nonce: u64,
        /// Whether the answerer's graph is named: the joiner's graph is then named too.
        named: bool,
        /// Encoded snapshot.
        snapshot: Bytes,
    },
    /// A remote component call.
    CallRequest {
        /// The caller.
        from: AgentId,
        /// The agent whose runtime serves it.
        to: AgentId,
        /// Caller-chosen id, echoed in the reply.
        call: u64,
        /// Which registered method.
        method: String,
        /// Its argument bytes.
        args: Bytes,
    },
    /// The reply to a [`Message::CallRequest`].
    CallReply {
        /// The serving agent.
        from: AgentId,
        /// The caller.
        to: AgentId,
        /// The request's id.
        call: u64,
        /// Response bytes, or why there is no response.
        result: Result<Bytes, CallFault>,
    },
}

/// Why a sample is not a message of this build. Messages name the kind and what is wrong.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum EnvelopeError {
    /// Fewer than [`HEADER_BYTES`] header bytes.
    #[error("envelope of {0} bytes is shorter than its {HEADER_BYTES}-byte header")]
    Short(usize),
    /// Not our magic byte: some other program's sample.
    #[error("foreign sample: first byte {found:#04x} is not the dsr envelope magic {MAGIC:#04x}")]
    Foreign {
        /// The byte found.
        found: u8,
    },
    /// An envelope version this build does not read.
    #[error("envelope version {found} is not supported (this build reads version {VERSION})")]
    Version {
        /// Version found.
        found: u8,
    },
    /// An unknown message kind.
    #[error("unknown message kind {0}")]
    Kind(u8),
    /// The kind's fields do not decode.
    #[error("malformed {kind} message: {detail}")]
    Malformed {
        /// The message kind.
        kind: &'static str,
        /// What is wrong.
        detail: String,
    },
}

const K_DELTA: u8 = 1;
const K_ANNOUNCE: u8 = 2;
const K_MISSING_REQUEST: u8 = 3;
const K_DELTAS: u8 = 4;
const K_SNAPSHOT: u8 = 5;
const K_GRAPH_REQUEST: u8 = 6;
const K_GRAPH_ANSWER: u8 = 7;
const K_CALL_REQUEST: u8 = 8;
const K_CALL_REPLY: u8 = 9;

/// A causal context as carried: version vector and out-of-order dots as plain pairs.
#[derive(Serialize, Deserialize)]
struct WireContext {
    vv: Vec<(u32, u64)>,
    cloud: Vec<(u32, u64)>,
}

impl WireContext {
    fn of(ctx: &CausalContext) -> Self {
        WireContext {
            vv: ctx.version_vector().iter().map(|(r, n)| (r.0, *n)).collect(),
            cloud: ctx.cloud().iter().map(|d| (d.replica.0, d.counter)).collect(),
        }
    }

    fn into_context(self, kind: &'static str) -> Result<CausalContext, EnvelopeError> {
        if self.vv.len() > MAX_VV || self.cloud.len() > MAX_CLOUD {
            return Err(EnvelopeError::Malformed {
                kind,
                detail: format!(
                    "context of {} entries and {} dots is over the limits",
                    self.vv.len(),
                    self.cloud.len()
                ),
            });
        }
        if self.vv.iter().any(|(r, _)| *r == 0) || self.cloud.iter().any(|(r, c)| *r == 0 || *c == 0) {
            return Err(EnvelopeError::Malformed { kind, detail: "context holds replica id 0 or counter 0".into() });
        }
        Ok(CausalContext::from_parts(
            self.vv.into_iter().map(|(r, n)| (ReplicaId(r), n)).collect(),
            self.cloud.into_iter().map(|(r, c)| Dot::new(ReplicaId(r), c)).collect(),
        ))
    }
}

/// An announce's fields on the wire: from, nonce, replica, applied operations, digest of a still graph, named.
type WireAnnounce = (u32, u64, u32, WireContext, Option<[u8; 32]>, bool);

/// A byte slice that postcard writes as one length-prefixed block (not byte by byte).
struct Block<'a>(&'a [u8]);

impl Serialize for Block<'_> {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.serialize_bytes(self.0)
    }
}

fn header(kind: u8, graph: Option<GraphId>) -> Vec<u8> {
    let mut out = Vec::with_capacity(64);
    out.extend_from_slice(&[MAGIC, VERSION, kind]);
    out.extend_from_slice(&graph.map_or(0, GraphId::get).to_le_bytes());
    out
}

/// A message with the graph id of its sender's graph: what one sample carries.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Envelope {
    /// The sender's graph; `None` only in the graph request of a joiner that names no graph.
    pub graph: Option<GraphId>,
    /// The message.
    pub message: Message,
}

impl Envelope {
    /// Encodes the message with its graph id.
    pub fn encode(&self) -> Bytes {
        self.message.encode(self.graph)
    }

    /// Decodes a sample. Payload fields are slices of `bytes` (no copy).
    ///
    /// # Errors
    /// [`EnvelopeError`] for anything that is not a well-formed message of this version, including a message
    /// other than a graph request without a graph id.
    pub fn decode(bytes: &Bytes) -> Result<Envelope, EnvelopeError> {
        Message::decode_envelope(bytes)
    }
}

/// A delta message's envelope fields (header and sender), which the delta's own bytes follow.
fn delta_fields(graph: Option<GraphId>, from: AgentId) -> Vec<u8> {
    put(header(K_DELTA, graph), &from.0)
}

fn put<T: Serialize + ?Sized>(out: Vec<u8>, value: &T) -> Vec<u8> {
    postcard::to_extend(value, out).expect("encoding into a Vec cannot fail")
}

impl Message {
    /// Whether the message only asks: a graph request, an announce of the operations its sender has applied, or a
    /// missing-request. Nothing asking can change a receiver's graph (at most it makes the receiver answer, or ask
    /// in turn), so these alone travel on [`Channel::Requests`], the one channel a read-only participant may write.
    pub fn asks(&self) -> bool {
        matches!(self, Message::Announce { .. } | Message::MissingRequest { .. } | Message::GraphRequest { .. })
    }

    /// The channel the message travels on: deltas on [`Channel::Updates`], asking ([`Message::asks`]) on
    /// [`Channel::Requests`], answers (missing deltas, snapshots, graph answers) on [`Channel::Sync`], calls on
    /// [`Channel::Calls`].
    pub fn channel(&self) -> Channel {
        match self {
            Message::Delta { .. } => Channel::Updates,
            Message::Announce { .. } | Message::MissingRequest { .. } | Message::GraphRequest { .. } => {
                Channel::Requests
            }
            Message::Deltas { .. } | Message::Snapshot { .. } | Message::GraphAnswer { .. } => Channel::Sync,
            Message::CallRequest { .. } | Message::CallReply { .. } => Channel::Calls,
        }
    }

    /// The kind's name, for logs.
    pub fn kind(&self) -> &'static str {
        match self {
            Message::Delta { .. } => "delta",
            Message::Announce { .. } => "announce",
            Message::MissingRequest { .. } => "missing-request",
            Message::Deltas { .. } => "deltas",
            Message::Snapshot { .. } => "snapshot",
            Message::GraphRequest { .. } => "graph-request",
            Message::GraphAnswer { .. } => "graph-answer",
            Message::CallRequest { .. } => "call-request",
            Message::CallReply { .. } => "call-reply",
        }
    }

    /// The sending agent.
    pub fn from(&self) -> AgentId {
        match self {
            Message::Delta { from, .. }
            | Message::Announce { from, .. }
            | Message::MissingRequest { from, .. }
            | Message::Deltas { from, .. }
            | Message::Snapshot { from, .. }
            | Message::GraphRequest { from, .. }
            | Message::GraphAnswer { from, .. }
            | Message::CallRequest { from, .. }
            | Message::CallReply { from, .. } => *from,
        }
    }

    /// The addressee, for messages meant for one agent.
    pub fn to(&self) -> Option<AgentId> {
        match self {
            Message::MissingRequest { to, .. }
            | Message::Deltas { to, .. }
            | Message::Snapshot { to, .. }
            | Message::GraphAnswer { to, .. }
            | Message::CallRequest { to, .. }
            | Message::CallReply { to, .. } => Some(*to),
            _ => None,
        }
    }

    /// The sample of a local delta, encoded once: the envelope's fields, then the delta straight after them in the
    /// same buffer (no second copy of a camera frame). Returns the sample and the message it holds, whose delta is a
    /// slice of the sample; `message.encode(Some(graph))` gives the same bytes.
    pub fn delta_sample(graph: GraphId, from: AgentId, delta: &dsr::Delta) -> (Bytes, Message) {
        let mut out = delta_fields(Some(graph), from);
        let fields = out.len();
        delta.encode_into(&mut out);
        let sample = Bytes::from(out);
        let message = Message::Delta { from, delta: sample.slice(fields..) };
        (sample, message)
    }

    /// The sample of a local delta in pieces: the envelope's fields and the delta's own bytes, with its large values
    /// (a camera frame, a point cloud's columns) as pieces of their own that point into the delta
    /// ([`dsr::Delta::encode_pieces`]). Concatenated, the pieces are [`Message::delta_sample`]'s sample; a transport
    /// that writes into shared memory copies a frame once on its way ([`transport::Transport::publish_pieces`]).
    pub fn delta_pieces(graph: GraphId, from: AgentId, delta: &dsr::Delta) -> dsr::Pieces<'_> {
        delta.encode_pieces(delta_fields(Some(graph), from))
    }

    /// Encodes the message as a sample of graph `graph` (`None`: a joiner that names no graph; only for a graph
    /// request).
    pub fn encode(&self, graph: Option<GraphId>) -> Bytes {
        let header = |kind| header(kind, graph);
        let out = match self {
            Message::Delta { from, delta } => {
                let mut out = delta_fields(graph, *from);
                out.extend_from_slice(delta);
                out
            }
            Message::Announce { from, nonce, replica, applied, digest, named } => {
                put(header(K_ANNOUNCE), &(from.0, nonce, replica.0, WireContext::of(applied), digest, named))
            }
            Message::MissingRequest { from, to, applied, full } => {
                put(header(K_MISSING_REQUEST), &(from.0, to.0, WireContext::of(applied), full))
            }
            Message::Deltas { from, to, deltas } => {
                let blocks: Vec<Block<'_>> = deltas.iter().map(|d| Block(d)).collect();
                put(header(K_DELTAS), &(from.0, to.0, blocks))
            }
            Message::Snapshot { from, to, snapshot } => {
                let mut out = put(header(K_SNAPSHOT), &(from.0, to.0));
                out.extend_from_slice(snapshot);
                out
            }
            Message::GraphRequest { from, nonce } => put(header(K_GRAPH_REQUEST), &(from.0, nonce)),
            Message::GraphAnswer { from, to, nonce, named, snapshot } => {
                let mut out = put(header(K_GRAPH_ANSWER), &(from.0, to.0, nonce, named));
                out.extend_from_slice(snapshot);
                out
            }
            Message::CallRequest { from, to, call, method, args } => {
                put(header(K_CALL_REQUEST), &(from.0, to.0, call, method, Block(args)))
            }
            Message::CallReply { from, to, call, result } => {
                let result: Result<Block<'_>, &CallFault> = result.as_ref().map(|b| Block(b));
                put(header(K_CALL_REPLY), &(from.0, to.0, call, result))
            }
        };
        Bytes::from(out)
    }

    fn decode_envelope(bytes: &Bytes) -> Result<Envelope, EnvelopeError> {
        if let Some(&magic) = bytes.first()
            && magic != MAGIC
        {
            return Err(EnvelopeError::Foreign { found: magic });
        }
        if let Some(&version) = bytes.get(1)
            && version != VERSION
        {
            return Err(EnvelopeError::Version { found: version });
        }
        let Some((head, body)) = bytes.split_at_checked(HEADER_BYTES) else {
            return Err(EnvelopeError::Short(bytes.len()));
        };
        let kind = head[2];
        let mut graph_bytes = [0u8; 8];
        graph_bytes.copy_from_slice(&head[3..HEADER_BYTES]);
        let graph = GraphId::new(u64::from_le_bytes(graph_bytes));
        let name = match kind {
            K_DELTA => "delta",
            K_ANNOUNCE => "announce",
            K_MISSING_REQUEST => "missing-request",
            K_DELTAS => "deltas",
            K_SNAPSHOT => "snapshot",
            K_GRAPH_REQUEST => "graph-request",
            K_GRAPH_ANSWER => "graph-answer",
            K_CALL_REQUEST => "call-request",
            K_CALL_REPLY => "call-reply",
            other => return Err(EnvelopeError::Kind(other)),
        };
        let malformed = |detail: String| EnvelopeError::Malformed { kind: name, detail };
        if graph.is_none() && kind != K_GRAPH_REQUEST {
            return Err(malformed("no graph id (only a joiner's graph request may name no graph)".into()));
        }
        // Fields, then the raw tail (a payload) or nothing.
        let tail = |rest: &[u8]| bytes.slice_ref(rest);
        let whole = |rest: &[u8]| {
            if rest.is_empty() { Ok(()) } else { Err(malformed(format!("{} trailing bytes", rest.len()))) }
        };
        let take = |e: postcard::Error| malformed(format!("{e} (body of {} bytes)", body.len()));
        let message = match kind {
            K_DELTA => {
                let (from, rest): (u32, _) = postcard::take_from_bytes(body).map_err(take)?;
                if rest.is_empty() {
                    return Err(malformed("no delta bytes".into()));
                }
                Message::Delta { from: AgentId(from), delta: tail(rest) }
            }
            K_ANNOUNCE => {
                let ((from, nonce, replica, context, digest, named), rest): (WireAnnounce, _) =
                    postcard::take_from_bytes(body).map_err(take)?;
                whole(rest)?;
                if replica == 0 {
                    return Err(malformed("replica id 0".into()));
                }
                Message::Announce {
                    from: AgentId(from),
                    nonce,
                    replica: ReplicaId(replica),
                    applied: context.into_context(name)?,
                    digest,
                    named,
                }
            }
            K_MISSING_REQUEST => {
                let ((from, to, context, full), rest): ((u32, u32, WireContext, bool), _) =
                    postcard::take_from_bytes(body).map_err(take)?;
                whole(rest)?;
                Message::MissingRequest {
                    from: AgentId(from),
                    to: AgentId(to),
                    applied: context.into_context(name)?,
                    full,
                }
            }
            K_DELTAS => {
                let ((from, to, blocks), rest): ((u32, u32, Vec<&[u8]>), _) =
                    postcard::take_from_bytes(body).map_err(take)?;
                whole(rest)?;
                if blocks.len() > MAX_BATCH {
                    return Err(malformed(format!("{} deltas in one batch (limit {MAX_BATCH})", blocks.len())));
                }
                Message::Deltas { from: AgentId(from), to: AgentId(to), deltas: blocks.into_iter().map(tail).collect() }
            }
            K_SNAPSHOT => {
                let ((from, to), rest): ((u32, u32), _) = postcard::take_from_bytes(body).map_err(take)?;
                if rest.is_empty() {
                    return Err(malformed("no snapshot bytes".into()));
                }
                Message::Snapshot { from: AgentId(from), to: AgentId(to), snapshot: tail(rest) }
            }
            K_GRAPH_REQUEST => {
                let ((from, nonce), rest): ((u32, u64), _) = postcard::take_from_bytes(body).map_err(take)?;
                whole(rest)?;
                Message::GraphRequest { from: AgentId(from), nonce }
            }
            K_GRAPH_ANSWER => {
                let ((from, to, nonce, named), rest): ((u32, u32, u64, bool), _) =
                    postcard::take_from_bytes(body).map_err(take)?;
                if rest.is_empty() {
                    return Err(malformed("no snapshot bytes".into()));
                }
                Message::GraphAnswer { from: AgentId(from), to: AgentId(to), nonce, named, snapshot: tail(rest) }
            }
            K_CALL_REQUEST => {
                let ((from, to, call, method, args), rest): ((u32, u32, u64, String, &[u8]), _) =
                    postcard::take_from_bytes(body).map_err(take)?;
                whole(rest)?;
                Message::CallRequest { from: AgentId(from), to: AgentId(to), call, method, args: tail(args) }
            }
            _ => {
                type Reply<'b> = (u32, u32, u64, Result<&'b [u8], CallFault>);
                let ((from, to, call, result), rest): (Reply<'_>, _) = postcard::take_from_bytes(body).map_err(take)?;
                whole(rest)?;
                Message::CallReply { from: AgentId(from), to: AgentId(to), call, result: result.map(tail) }
            }
        };
        Ok(Envelope { graph, message })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    const G: Option<GraphId> = GraphId::new(0x5eed);

    fn decode(bytes: &Bytes) -> Result<Message, EnvelopeError> {
        Envelope::decode(bytes).map(|envelope| envelope.message)
    }

    fn samples() -> Vec<Message> {
        let mut replica = dsr::Replica::new(ReplicaId(7));
        let (id, d1) = replica.insert_node(5, dsr::NewNode::new("world", "world")).unwrap();
        let d2 = replica.set_attr(6, id, dsr::attrs::LEVEL, 3).unwrap();
        let ctx = CausalContext::from_parts(vec![(ReplicaId(7), 2)], vec![Dot::new(ReplicaId(9), 4)]);
        let (from, to) = (AgentId(3), AgentId(4));
        vec![
            Message::Delta { from, delta: Bytes::from(d2.encode()) },
            Message::Announce {
                from,
                nonce: 99,
                replica: ReplicaId(7),
                applied: ctx.clone(),
                digest: Some([3; 32]),
                named: true,
            },
            Message::MissingRequest { from, to, applied: ctx, full: true },
            Message::Deltas { from, to, deltas: vec![Bytes::from(d1.encode()), Bytes::from(d2.encode())] },
            Message::Snapshot { from, to, snapshot: Bytes::from(replica.snapshot().encode()) },
            Message::GraphRequest { from, nonce: 1 },
            Message::GraphAnswer {
                from,
                to,
                nonce: 1,
                named: false,
                snapshot: Bytes::from(replica.snapshot().encode()),
            },
            Message::CallRequest {
                from,
                to,
                call: 8,
                method: "Walk.set_speed".into(),
                args: Bytes::from_static(b"1.5"),
            },
            Message::CallReply { from, to, call: 8, result: Ok(Bytes::from_static(b"ok")) },
            Message::CallReply { from, to, call: 9, result: Err(CallFault::UnknownMethod("no such method".into())) },
        ]
    }

    #[test]
    fn every_kind_round_trips_and_an_update_is_small() {
        for message in samples() {
            let bytes = message.encode(G);
            assert_eq!(Envelope::decode(&bytes).unwrap(), Envelope { graph: G, message: message.clone() });
        }
        let update = samples()[0].encode(G);
        assert!(update.len() < 68, "a one-attribute update is {} bytes", update.len());
    }

    #[test]
    fn a_delta_encoded_straight_into_its_sample_is_the_same_sample_and_its_message_a_view_of_it() {
        let mut replica = dsr::Replica::new(ReplicaId(7));
        let (id, _) = replica.insert_node(5, dsr::NewNode::new("camera", "cam")).unwrap();
        let frame = Bytes::from(vec![0xA5; 64 << 10]);
        let delta = replica.set_attr(6, id, dsr::attrs::CAM_RGB, frame.clone()).unwrap();
        let graph = G.unwrap();
        let (sample, message) = Message::delta_sample(graph, AgentId(3), &delta);
        assert_eq!(sample, message.encode(G), "the same bytes as encoding the message");
        assert_eq!(message, Message::Delta { from: AgentId(3), delta: Bytes::from(delta.encode()) });
        let Message::Delta { delta: view, .. } = &message else { unreachable!() };
        let inside = sample.as_ptr_range();
        assert!(inside.contains(&view.as_ptr()), "the message's delta is a slice of the sample, not a copy");
        let pieces = Message::delta_pieces(graph, AgentId(3), &delta);
        assert_eq!(pieces.to_vec(), sample, "the pieces are the sample");
        assert!(pieces.iter().any(|piece| piece.as_ptr() == frame.as_ptr()), "the frame is referred to, not copied");
    }

    #[test]
    fn only_a_graph_request_may_name_no_graph() {
        let request = Message::GraphRequest { from: AgentId(1), nonce: 4 };
        assert_eq!(Envelope::decode(&request.encode(None)).unwrap(), Envelope { graph: None, message: request });
        for message in samples().into_iter().filter(|m| m.kind() != "graph-request") {
            let error = Envelope::decode(&message.encode(None)).unwrap_err();
            assert!(error.to_string().contains("no graph id"), "{}: {error}", message.kind());
        }
    }

    #[test]
    fn foreign_version_kind_short_and_trailing_are_named_errors() {
        let good = samples()[5].encode(G);
        assert_eq!(decode(&Bytes::from(vec![MAGIC, VERSION])), Err(EnvelopeError::Short(2)));
        let mut foreign = good.to_vec();
        foreign[0] = b'R';
        assert!(matches!(decode(&Bytes::from(foreign)), Err(EnvelopeError::Foreign { found: b'R' })));
        let mut version = good.to_vec();
        version[1] = 9;
        assert_eq!(decode(&Bytes::from(version)), Err(EnvelopeError::Version { found: 9 }));
        let mut kind = good.to_vec();
        kind[2] = 200;
        assert_eq!(decode(&Bytes::from(kind)), Err(EnvelopeError::Kind(200)));
        let mut trailing = good.to_vec();
        trailing.push(0);
        let error = decode(&Bytes::from(trailing)).unwrap_err();
        assert!(error.to_string().contains("graph-request") && error.to_string().contains("trailing"), "{error}");
    }

    proptest! {
        #[test]
        fn random_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..256), kind in 0u8..12) {
            let mut framed = vec![MAGIC, VERSION, kind, 0xed, 0x5e, 0, 0, 0, 0, 0, 0];
            framed.extend_from_slice(&bytes);
            let _ = decode(&Bytes::from(framed));
            let _ = decode(&Bytes::from(bytes));
        }

        #[test]
        fn truncated_and_flipped_messages_never_panic(which in 0usize..10, cut in any::<prop::sample::Index>(),
                                                      flip in any::<prop::sample::Index>(), bit in 0u8..8) {
            let bytes = samples()[which].encode(G).to_vec();
            let n = cut.index(bytes.len());
            let _ = decode(&Bytes::copy_from_slice(&bytes[..n]));
            let mut flipped = bytes.clone();
            let at = flip.index(flipped.len());
            flipped[at] ^= 1 << bit;
            if let Ok(Message::Delta { delta, .. }) = decode(&Bytes::from(flipped)) {
                let _ = dsr::Delta::decode(&delta);
            }
        }
    }
}
