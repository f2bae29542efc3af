//! What an agent tells about itself: [`AgentStatus`], with the timelines of its late join ([`JoinTimeline`]) and
//! of the latest graph request it answered ([`AnswerTiming`]).

use dsr::ReplicaId;
use transport::TransportStats;

use crate::AgentId;
use crate::graph_id::GraphId;

/// When each step of this agent's late join happened, in nanoseconds on the agent's clock; `None` for a step not
/// reached (yet). With the system clock, times of agents in different processes on one host compare.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct JoinTimeline {
    /// The agent started joining (it was created).
    pub started_ns: u64,
    /// The first graph request was handed to the transport.
    pub first_request_ns: Option<u64>,
    /// The last graph request handed to the transport before the graph came.
    pub last_request_ns: Option<u64>,
    /// Graph requests published while joining (periodic retries, and repeats when discovery matched a peer).
    pub requests: u32,
    /// The graph answer reached the agent (taken from the transport's inbox).
    pub answer_received_ns: Option<u64>,
    /// Bytes of that answer's snapshot.
    pub answer_bytes: usize,
    /// The snapshot was decoded and checked.
    pub decoded_ns: Option<u64>,
    /// The replica was built (snapshot joined, buffered deltas applied): the agent became ready.
    pub ready_ns: Option<u64>,
    /// It became ready alone (no answer within the join wait) rather than from a peer's graph.
    pub alone: bool,
}

/// The latest graph request this agent answered, in nanoseconds on the agent's clock.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct AnswerTiming {
    /// The joiner.
    pub to: AgentId,
    /// The request reached the agent (taken from the transport's inbox).
    pub request_received_ns: u64,
    /// The encoded snapshot was ready (encoded under the state lock, or taken from the cache).
    pub snapshot_ready_ns: u64,
    /// Whether the snapshot came from the cache (no encoding).
    pub from_cache: bool,
    /// The answer's publish returned: handed to the transport, including any pacing wait.
    pub published_ns: u64,
    /// Bytes of the snapshot.
    pub snapshot_bytes: usize,
}

/// What an agent can tell about itself.
#[derive(Clone, Debug, PartialEq)]
pub struct AgentStatus {
    /// The agent id.
    pub id: AgentId,
    /// The replica id of this life, once joined.
    pub replica: Option<ReplicaId>,
    /// Whether the graph has been received or started.
    pub ready: bool,
    /// An id collision, if one was seen.
    pub collision: Option<String>,
    /// The graph this agent belongs to (`None` while it joins without naming one).
    pub graph: Option<GraphId>,
    /// Whether that graph is named; an unnamed one may still move (see `crate::core`, **Graphs**).
    pub graph_named: bool,
    /// Messages of other graphs refused (see `crate::core`, **Graphs**).
    pub foreign_refused: u64,
    /// The foreign graph ids heard (at most `crate::core::MAX_FOREIGN_GRAPHS`).
    pub foreign_graphs: Vec<GraphId>,
    /// Messages refused for arriving on a channel that does not carry them: anything but asking on the requests
    /// channel (see `crate::core`, **Channels**).
    pub misrouted_refused: u64,
    /// Whether the agent is read-only (`AgentConfig::read_only`).
    pub read_only: bool,
    /// Samples rejected (foreign, malformed, or refused by the replica).
    pub rejected: u64,
    /// Change signals dropped because a subscriber's channel was full.
    pub signals_dropped: u64,
    /// Whether the replica looks for the visible changes of each write and join: while a subscription or change
    /// callback is registered (a dropped subscription counts until the next change finds it gone).
    pub change_tracking: bool,
    /// Publishes that failed (the local state is kept; anti-entropy repairs).
    pub publish_failures: u64,
    /// Times a peer had joined the same operations but showed another graph digest (a replica bug; repaired with
    /// snapshots). Zero in a correct system.
    pub digest_mismatches: u64,
    /// Missing-delta requests sent at once because a received delta showed a gap: operations of its writer before
    /// it had not been joined (a lost sample, or one overtaken in flight). Anti-entropy would find the gap at the
    /// next announce; this asks sooner.
    pub gap_requests: u64,
    /// Large values received (byte values and numeric vectors of 4 KiB or more, [`dsr::LargeValues`]) that were
    /// read in place from their sample's buffer: no copy on receipt.
    pub large_values_shared: u64,
    /// Large values received that were copied out of their sample (not aligned, or a small part of a large snapshot).
    pub large_values_copied: u64,
    /// Call requests addressed to this agent (served, or answered with a fault).
    pub calls_served: u64,
    /// Call replies of this agent's server dropped because the reply outbox was full.
    pub call_replies_dropped: u64,
    /// Replies to this agent's calls that came after the caller gave up (or from another agent).
    pub late_call_replies: u64,
    /// This agent's calls waiting for replies now.
    pub calls_in_flight: usize,
    /// Peers heard from lately, by agent id (forgotten after `agent::core::PEER_FORGET_INTERVALS` announce intervals
    /// of silence).
    pub peers: Vec<AgentId>,
    /// Visible nodes.
    pub nodes: usize,
    /// Visible edges.
    pub edges: usize,
    /// The transport's counters.
    pub transport: TransportStats,
    /// How this life's late join went.
    pub join: JoinTimeline,
    /// The latest graph request this agent answered, if any.
    pub last_answer: Option<AnswerTiming>,
}

/// One line of an agent's machine-readable status (`cortex agent --json-status` prints one per period, as JSON):
/// the one type that writers and readers of status lines share, so a renamed field is a parse error, not a 0.
#[derive(Clone, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct StatusLine {
    /// The agent id.
    pub id: u32,
    /// Whether it has a graph (joined, or started alone).
    pub ready: bool,
    /// Whether this life became ready alone (no answer within its join wait) rather than from a peer's graph.
    #[serde(default)]
    pub alone: bool,
    /// The graph it belongs to (`None` while it joins without naming one).
    #[serde(default)]
    pub graph: Option<GraphId>,
    /// Whether that graph is named: named with `--graph-id`, recorded by a previous life, or taken from an agent
    /// whose graph is named. An unnamed graph may still move to a named one, or to a smaller unnamed id, it hears.
    #[serde(default)]
    pub graph_named: bool,
    /// Messages of other graphs on the same domain and topic prefix refused (never merged).
    #[serde(default)]
    pub foreign_refused: u64,
    /// The foreign graph ids heard.
    #[serde(default)]
    pub foreign_graphs: Vec<GraphId>,
    /// Messages refused for arriving on the requests channel without asking (never applied).
    #[serde(default)]
    pub misrouted_refused: u64,
    /// Whether the agent is read-only: it follows the graph and never changes it.
    #[serde(default)]
    pub read_only: bool,
    /// The replica id of this life, once ready.
    pub replica: Option<u32>,
    /// Visible nodes.
    pub nodes: usize,
    /// Visible edges.
    pub edges: usize,
    /// The visible graph's digest (the first 8 bytes, hex), once ready.
    pub digest: Option<String>,
    /// Peers heard from lately, by agent id (forgotten after `agent::core::PEER_FORGET_INTERVALS` announce intervals
    /// of silence).
    pub peers: Vec<u32>,
    /// Samples rejected (foreign, malformed, or refused by the replica).
    pub rejected: u64,
    /// An id collision, if one was seen.
    pub collision: Option<String>,
    /// Time since the process started, ms.
    pub uptime_ms: u64,
    /// Samples published.
    pub samples_sent: u64,
    /// Samples received.
    pub samples_received: u64,
    /// Call requests addressed to this agent.
    pub calls_served: u64,
    /// Visible nodes by node type, once ready.
    pub node_types: Option<std::collections::BTreeMap<String, u64>>,
    /// Bytes the transport put on the wire (its estimate where it cannot count them).
    pub wire_bytes_sent: u64,
    /// Times a DDS participant failed.
    pub participant_failures: u64,
    /// Times the DDS participants were rebuilt after a failure.
    pub participant_rebuilds: u64,
    /// Of the samples published, those that went through same-host shared memory.
    #[serde(default)]
    pub shm_samples_sent: u64,
    /// Of the samples received, those that came through same-host shared memory.
    #[serde(default)]
    pub shm_samples_received: u64,
    /// Of those, samples taken in place rather than copied out of shared memory.
    #[serde(default)]
    pub shm_samples_leased: u64,
    /// Same-host peers reachable through shared memory now.
    #[serde(default)]
    pub same_host_peers: u64,
    /// Large values received that were read in place from their sample (see [`AgentStatus::large_values_shared`]).
    #[serde(default)]
    pub large_values_shared: u64,
    /// Large values received that were copied out of their sample.
    #[serde(default)]
    pub large_values_copied: u64,
    /// Samples meant for one peer that went to every reader, the peer's reader not being known yet
    /// ([`transport::TransportStats::unaddressed_writes`]).
    #[serde(default)]
    pub unaddressed_writes: u64,
}

/// A command to an agent process, one line on its standard input (`cortex agent --control-stdin`): the other
/// direction of [`StatusLine`], shared by the process that reads it and the ones that write it. The end of input
/// stops the agent.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Control {
    /// Stop the role's runtime; the agent keeps replicating, so its graph can settle.
    Quiesce,
}

impl Control {
    /// Every command.
    pub const ALL: [Control; 1] = [Control::Quiesce];

    /// The command's line (without its line end).
    pub fn line(self) -> &'static str {
        match self {
            Control::Quiesce => "quiesce",
        }
    }

    /// The command `line` gives, space around it ignored; `None` for an unknown line.
    pub fn parse(line: &str) -> Option<Control> {
        Control::ALL.into_iter().find(|control| control.line() == line.trim())
    }
}

#[cfg(test)]
mod tests {
    use super::Control;

    #[test]
    fn every_control_line_parses_back_and_unknown_lines_do_not() {
        for control in Control::ALL {
            assert_eq!(Control::parse(control.line()), Some(control));
            assert_eq!(Control::parse(&format!("  {}\n", control.line())), Some(control));
        }
        assert_eq!(Control::parse("stop"), None);
        assert_eq!(Control::parse(""), None);
    }
}
