//! What the core takes in: a received protocol message with its deltas decoded ([`Input`], [`Decoded`]).

use std::sync::Arc;

use bytes::Bytes;
use dsr::{CausalContext, Delta, LargeValues, ReplicaId};

use crate::AgentId;
use crate::envelope::Message;

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
        /// Its digest, when its graph is still.
        digest: Option<[u8; 32]>,
        /// Whether its graph is named.
        named: bool,
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
        /// Whether its graph is named.
        named: bool,
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
    /// The decoded deltas' large values, by whether they stayed in the sample's buffer or were copied out of it.
    pub large: LargeValues,
}

impl Input {
    /// Decodes the deltas of a protocol message (pure; never panics). Call messages give no input.
    pub fn decode(message: Message) -> Decoded {
        let mut rejected = Vec::new();
        let mut large = LargeValues::default();
        // Payloads are slices of the received sample: large values stay in its buffer (no copy per receiver).
        let mut delta = |what: &'static str, bytes: &Bytes| match Delta::decode_shared(bytes) {
            Ok(delta) => {
                large += delta.large_values_in(bytes);
                Some(Arc::new(delta))
            }
            Err(error) => {
                rejected.push((what, error.to_string()));
                None
            }
        };
        let input = match message {
            Message::Delta { from, delta: bytes } => delta("delta", &bytes).map(|delta| Input::Delta { from, delta }),
            Message::Announce { from, nonce, replica, applied, digest, named } => {
                Some(Input::Announce { from, nonce, replica, applied, digest, named })
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
            Message::GraphAnswer { from, nonce, named, snapshot, .. } => {
                delta("graph answer", &snapshot).map(|snapshot| Input::GraphAnswer { from, nonce, named, snapshot })
            }
            Message::CallRequest { .. } | Message::CallReply { .. } => None,
        };
        Decoded { input, rejected, large }
    }

    /// The message kind's name (as [`Message::kind`]).
    pub fn kind(&self) -> &'static str {
        match self {
            Input::Delta { .. } => "delta",
            Input::Announce { .. } => "announce",
            Input::MissingRequest { .. } => "missing-request",
            Input::Deltas { .. } => "deltas",
            Input::Snapshot { .. } => "snapshot",
            Input::GraphRequest { .. } => "graph-request",
            Input::GraphAnswer { .. } => "graph-answer",
        }
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
