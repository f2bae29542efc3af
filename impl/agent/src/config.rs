//! [`AgentConfig`]: the settings of an agent, and the protocol core's settings they give.

use std::time::Duration;

use dsr::LogLimits;
use dsr::json::CortexGraph;

use crate::AgentId;
use crate::core::ProtocolConfig;
use crate::graph_id::GraphId;
use crate::mutants::Plant;

/// Default of [`AgentConfig::announce_group`]: groups of up to 8 agents announce every period.
pub const DEFAULT_ANNOUNCE_GROUP: u32 = 8;

/// Settings of an agent.
#[derive(Clone, Debug)]
pub struct AgentConfig {
    /// This agent's id (below [`AgentId::LIMIT`]).
    pub id: AgentId,
    /// The graph this agent belongs to ([`ProtocolConfig::graph`]). `None`: the named graph its previous life
    /// recorded in `life_file`, if any, else the graph it joins, else (starting alone) one unnamed, which may move
    /// (`crate::core`, **Graphs**).
    pub graph: Option<GraphId>,
    /// How long to wait for a graph from peers before starting alone.
    pub join_wait: Duration,
    /// How often to repeat the graph request while joining.
    pub join_retry: Duration,
    /// How often to announce the causal context (anti-entropy).
    pub announce_period: Duration,
    /// After this long without a local write, announce once more, out of period: a peer that lost this agent's
    /// last writes (which no later delta of it reveals as a gap) asks for them then, not at the next periodic
    /// announce. A writer faster than this never pauses that long until it stops, so it costs one announce per
    /// burst; a slower one, one per write. Zero turns it off. Checked on the agent's tick, so it fires up to one
    /// tick later.
    pub quiet_announce: Duration,
    /// How many agents' announces fit in one announce period. An agent that has heard from more agents than this
    /// announces less often, in proportion (every `announce_period × ⌈agents / announce_group⌉`), so the group
    /// sends about `announce_group` periodic announces per period whatever its size, and the control traffic each
    /// agent receives does not grow with the group. Gap requests and the quiet announce, which repair most losses,
    /// do not depend on it; what waits longer in a larger group is the repair that only a periodic announce starts
    /// (a partition that heals without a write). 0: every agent announces every period.
    pub announce_group: u32,
    /// History kept for anti-entropy.
    pub log_limits: LogLimits,
    /// Deltas kept while joining, to apply once the graph arrives (older ones are dropped past it; anti-entropy
    /// brings them back).
    pub max_buffered_deltas: usize,
    /// Most bytes of deltas in one anti-entropy answer message.
    pub max_batch_bytes: usize,
    /// How long a graph request stays answered: a joiner's repeat within it gets no second copy, one after it does
    /// (the first answer may have been lost). Keep [`AgentConfig::join_wait`] above this plus a join retry, or a
    /// joiner whose answer was lost starts alone (and says so with a warning).
    pub answer_hold: Duration,
    /// The graph to start from if no peer answers (the first agent of a system).
    pub seed: Option<CortexGraph>,
    /// This life's nonce; `None` draws a random one (set it only in deterministic simulations).
    pub nonce: Option<u64>,
    /// The file where each life records its incarnation before it writes (`cortex agent` keeps one per agent id
    /// and graph in its state directory): the next life reads it and takes a higher one, so lives on one host
    /// never share a replica id even when no peer is reachable. `None`: no record (see the crate's **Identity**).
    pub life_file: Option<std::path::PathBuf>,
    /// The previous life's incarnation, given directly instead of read from `life_file` (simulations).
    pub recorded_incarnation: Option<u32>,
    /// Most remote calls of this agent waiting for replies at once.
    pub max_calls_in_flight: usize,
    /// Most call replies of this agent's server waiting to be published.
    pub call_reply_outbox: usize,
    /// Read-only ([`ProtocolConfig::read_only`]): the agent asks for the graph and follows it, publishes nothing but
    /// requests ([`transport::Channel::Requests`]), never starts alone, and refuses local writes
    /// ([`crate::AgentError::ReadOnly`]). Give its RTPS transport `read_only` too when its credentials grant
    /// publishing requests alone.
    pub read_only: bool,
    /// A planted protocol bug (always none without the `mutants` feature).
    pub plant: Plant,
}

impl AgentConfig {
    /// Defaults for agent `id`: join wait 2 s (request every 200 ms), announce every 500 ms and 100 ms after the
    /// last of a burst of writes.
    pub fn new(id: AgentId) -> Self {
        AgentConfig {
            id,
            graph: None,
            join_wait: Duration::from_secs(2),
            join_retry: Duration::from_millis(200),
            announce_period: Duration::from_millis(500),
            quiet_announce: Duration::from_millis(100),
            announce_group: DEFAULT_ANNOUNCE_GROUP,
            log_limits: LogLimits::default(),
            max_buffered_deltas: 65_536,
            max_batch_bytes: 256 << 10,
            answer_hold: Duration::from_millis(500),
            seed: None,
            nonce: None,
            life_file: None,
            recorded_incarnation: None,
            max_calls_in_flight: 64,
            call_reply_outbox: 256,
            read_only: false,
            plant: Plant::NONE,
        }
    }

    /// The grid a threaded agent's own thread wakes on (a quarter of the shorter of `join_retry` and
    /// `announce_period`, within 1–50 ms): the periodic work's precision, and a transport's longest wait when it
    /// cannot be interrupted.
    pub fn tick(&self) -> Duration {
        (self.join_retry.min(self.announce_period) / 4).clamp(Duration::from_millis(1), Duration::from_millis(50))
    }

    /// The protocol core's settings.
    pub fn protocol(&self) -> ProtocolConfig {
        ProtocolConfig {
            id: self.id,
            graph: self.graph,
            join_wait_ns: self.join_wait.as_nanos() as u64,
            join_retry_ns: self.join_retry.as_nanos() as u64,
            announce_period_ns: self.announce_period.as_nanos() as u64,
            announce_group: self.announce_group,
            peer_forget_intervals: crate::core::PEER_FORGET_INTERVALS,
            quiet_announce_ns: self.quiet_announce.as_nanos() as u64,
            log_limits: self.log_limits,
            max_buffered_deltas: self.max_buffered_deltas,
            max_batch_bytes: self.max_batch_bytes,
            answer_hold_ns: self.answer_hold.as_nanos() as u64,
            read_only: self.read_only,
            plant: self.plant,
        }
    }
}
