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
//! **Identity.** An agent id is the CORTEX 12-bit agent id. Each life of an agent takes the replica id
//! `incarnation << 12 | agent_id`, with an incarnation above every one of its own seen in the graph it joined,
//! so **a restarted agent never reuses the replica id, dots or minted node ids of an earlier life** that any peer
//! has seen. Each life also draws a random nonce; a message carrying this agent id with another nonce (from a
//! life not older than ours) is an **id collision**: it is logged, reported in [`AgentStatus`], and the agent
//! refuses local writes from then on, so two lives never mint the same dots.
//!
//! **Anti-entropy.** Every [`AgentConfig::announce_period`] an agent announces its causal context. An agent that
//! sees in an announce dots it lacks asks that peer ([`envelope::Message::MissingRequest`]); the peer answers with
//! `Replica::missing_for` — the retained deltas, or a snapshot when its bounded history does not cover the gap. So
//! the graph converges after loss, a healed partition and a restart.
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
pub mod core;
pub mod envelope;
pub mod life;
pub mod mutants;

pub use agent::{Agent, AgentConfig, AgentError, AgentStatus, AnswerTiming, ChangeSignal, JoinTimeline};
pub use calls::{CallError, CallFault, CallReplier, CallServer, PendingCall};

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
