//! The protocol's settings and limits, and what a new life starts from.

use crate::AgentId;
use crate::graph_id::GraphId;
use crate::mutants::Plant;
use dsr::LogLimits;

/// Most remembered answered requests.
pub const MAX_ANSWERED: usize = 1024;
/// Largest incarnation plus one (replica ids are 32 bits, 12 of them the agent id).
pub const INCARNATION_LIMIT: u32 = 1 << 20;
/// Without a recorded incarnation, the floor is drawn from the nonce below this.
pub const RANDOM_FLOOR_LIMIT: u32 = 1 << 16;
/// Above this many payload bytes of retained deltas, a missing-request is answered with a snapshot instead when the
/// snapshot is smaller: the history keeps the values of every operation not wholly overwritten since (a camera frame
/// written together with a pose, and the next frame written alone, keeps the earlier frame), a snapshot only the
/// current ones.
pub const SNAPSHOT_IF_SMALLER_ABOVE_BYTES: usize = 1 << 20;
/// The running agents' [`ProtocolConfig::peer_forget_intervals`]: peers that hear the same group announce once an
/// interval each; four leave room for lost announces and for a peer whose interval is longer, since it heard more
/// agents lately.
pub const PEER_FORGET_INTERVALS: u64 = 4;
/// Most foreign graph ids remembered (each reported once); messages of further ones are refused and counted without
/// a report.
pub const MAX_FOREIGN_GRAPHS: usize = 64;

/// The protocol's settings, in nanoseconds.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct ProtocolConfig {
    /// This agent's id (below [`AgentId::LIMIT`]).
    pub id: AgentId,
    /// The graph this agent belongs to: it joins only this graph, and creates it with this id when it starts alone.
    /// `None`: it takes the graph of the first answer to its graph request (or creates one with an id drawn from
    /// its life's nonce when it starts alone).
    pub graph: Option<GraphId>,
    /// How long to wait for a graph from peers before starting alone.
    pub join_wait_ns: u64,
    /// How often to repeat the graph request while joining.
    pub join_retry_ns: u64,
    /// How often to announce the applied operations while the group is small (see `announce_group`).
    pub announce_period_ns: u64,
    /// The number of agents whose announces fit in one announce period: with more agents heard lately, each
    /// announces less often, in proportion, so the group as a whole sends about this many announces per period
    /// whatever its size (0: every agent announces every period, however many there are). Agents that left stop
    /// counting after `peer_forget_intervals` intervals of silence.
    pub announce_group: u32,
    /// A peer silent for this many of this agent's announce intervals is forgotten ([`super::AgentCore::peers`]),
    /// so agents that left stop stretching the announce interval of those that stay (running agents:
    /// [`PEER_FORGET_INTERVALS`]; 0: never forgotten).
    pub peer_forget_intervals: u64,
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
    /// A read-only life (an inspector whose credentials let it publish requests alone): it asks — graph requests,
    /// missing-requests — and never publishes anything else. It never starts alone (it asks until an agent of the
    /// graph answers), never announces (a peer could ask it for operations it cannot send), answers no request, and
    /// refuses local writes ([`super::WriteRefusal::ReadOnly`]).
    pub read_only: bool,
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
    /// The unnamed graph the previous life on this host belonged to, as the shell recorded it (a named one is
    /// named in [`ProtocolConfig::graph`] instead): a life that starts alone having heard no graph starts in it
    /// again, unnamed, so that what peers kept of the previous life's writes still belongs to its graph.
    pub recorded_graph: Option<GraphId>,
}
