//! # DSR_d agents
//!
//! An [`Agent`] owns one `dsr::Replica` and shares it with other agents through a [`transport::Transport`]:
//! RTPS between processes, or the in-process bus (with the seeded fault injector) in tests and simulations. The
//! replica stays a pure state machine; the agent adds the clock, the threads and the protocol.
//!
//! **Graph API.** Reads ([`Agent::read`], [`Agent::node`], [`Agent::digest`], ...) take a short lock on the
//! replica and never wait for the network. A local write runs the replica operation under the lock, then — with
//! the lock released — publishes the returned delta on [`transport::Channel::Updates`]. **No lock is held across a
//! network call.**
//!
//! **Change signals.** Every visible change (node, edge, attribute; insert, update, delete), local or remote,
//! goes to each subscriber ([`Agent::subscribe`]) with the originating agent id, through a bounded channel; a
//! subscriber that falls behind loses signals (counted), never blocks the agent.
//!
//! **Late join.** A starting agent asks for the graph ([`envelope::Message::GraphRequest`]) every
//! [`AgentConfig::join_retry`]; **any** running agent answers with a snapshot. An agent that hears no answer within
//! [`AgentConfig::join_wait`] starts alone — from its seed graph (CORTEX JSON) if it has one — and never aborts.
//!
//! **Identity.** An agent id is the CORTEX 12-bit agent id that users type. Each life of an agent takes the
//! replica id `incarnation << 12 | agent_id`, so its dots and minted node ids are its own. The incarnation is above
//! every incarnation of this agent id seen in the graph it joined (announces, snapshots) and above the one its
//! previous life recorded ([`AgentConfig::life_file`]: `cortex agent` keeps one per agent id and graph in its state
//! directory, written durably before the life's first write). Without a record the floor is a random number below
//! 2^16 drawn from the life's nonce. **What is guaranteed:** two lives of one agent id never share a replica id when
//! they ran with the same life file, or when the later one joined a graph that held any operation of the earlier
//! one; otherwise (no record, and nothing of the earlier life reachable) they share one with probability at most
//! 2^-16. A reuse that shows anyway — a peer holds operations of this life's replica id that this life did not
//! make — and a message carrying this agent id from another life not older than this one (another nonce) are **id
//! collisions**: logged, reported in [`AgentStatus`], and local writes are refused from then on, so two lives never
//! mint the same dots silently. No server and no reachable peer is needed for any of this.
//!
//! **The protocol core.** Every protocol decision is made by [`core::AgentCore`], a pure state machine (no I/O,
//! threads, locks or clock reads): the threaded [`Agent`], the seeded simulations and the Stateright agents model
//! (`model::agents`, with loss, duplication, reordering, crashes, restarts and cuts) run it unchanged.
//!
//! **Anti-entropy.** Every [`AgentConfig::announce_period`] an agent announces its causal context. An agent that
//! sees in an announce dots it lacks asks that peer ([`envelope::Message::MissingRequest`]); the peer answers with
//! `Replica::missing_for` — the retained deltas, or a snapshot when its bounded history does not cover the gap —
//! and with a snapshot also when the deltas carry more than [`core::SNAPSHOT_IF_SMALLER_ABOVE_BYTES`] of payload
//! and the snapshot is smaller (the history keeps every overwritten camera frame). So the graph converges after
//! loss, a healed partition and a restart.
//!
//! **Remote calls.** [`Agent::call`] calls a named method of another agent's BICA runtime (request/reply on
//! [`transport::Channel::Calls`], typed with serde, bounded in flight, with a timeout); an agent serves them once
//! [`Agent::serve_calls`] attached a [`CallServer`] such as `bica::service::Service`. See [`calls`].
//!
//! **Bad input.** A foreign or malformed sample, or a delta the replica refuses, is logged with its origin and
//! dropped; the replica is unchanged and the agent keeps running ([`AgentStatus::rejected`] counts them).

use std::fmt;

pub mod agent;
pub mod calls;
pub mod config;
pub mod core;
pub mod envelope;
pub mod graph_id;
pub mod life;
pub mod link;
pub mod mutants;
pub mod rtps;
pub mod shm;
pub mod status;

pub use agent::{
    Agent, AgentConfig, AgentError, AgentStatus, AnswerTiming, CallbackId, ChangeSignal, JoinTimeline, StatusLine,
};
pub use calls::{CallError, CallReplier, CallServer, PendingCall};
pub use envelope::CallFault;
pub use graph_id::GraphId;
pub use link::Link;
pub use status::Control;

/// A CORTEX agent id (12 bits: 0..4096).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct AgentId(pub u32);

impl AgentId {
    /// Largest agent id plus one.
    pub const LIMIT: u32 = 1 << 12;

    /// The agent whose life `replica` is (replica ids are `incarnation << 12 | agent_id`).
    pub fn of_replica(replica: dsr::ReplicaId) -> AgentId {
        AgentId(replica.0 & (Self::LIMIT - 1))
    }

    /// The incarnation (life number, from 1) that `replica` names.
    pub fn incarnation_of(replica: dsr::ReplicaId) -> u32 {
        replica.0 >> 12
    }

    /// The replica id of life `incarnation` (from 1) of this agent.
    pub fn replica(self, incarnation: u32) -> dsr::ReplicaId {
        dsr::ReplicaId((incarnation << 12) | self.0)
    }
}

impl fmt::Display for AgentId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "agent {}", self.0)
    }
}
