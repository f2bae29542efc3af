//! What a campaign records: its settings, the lines of `history.jsonl`, the episodes' outcomes, the timeline of
//! what each agent showed, and everything [`super::check`] and [`super::output`] need. Plain data.

use serde::{Deserialize, Serialize};

use super::protocol::{FinalState, WriteRecord};
use super::schedule::{Fault, Schedule};

/// A campaign's settings.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CampaignConfig {
    /// The seed of the schedule and of the writers' draws.
    pub seed: u64,
    /// Agent slots (the last joins late).
    pub agents: usize,
    /// Rounds of episodes (one of each fault kind per round).
    pub rounds: usize,
    /// How long each fault is on, in milliseconds.
    pub fault_ms: u64,
    /// Writes per second per agent while the writers run.
    pub write_hz: f64,
    /// Bytes of a camera frame.
    pub image_bytes: usize,
    /// How long to wait for convergence after a heal before the campaign fails, in milliseconds.
    pub settle_ms: u64,
    /// How long a new life waits for a running agent's graph, in milliseconds.
    pub join_wait_ms: u64,
    /// DDS domain.
    pub domain: u16,
    /// Whether the agents ran with DDS Security.
    #[serde(default)]
    pub security: bool,
    /// Whether every agent ran in one network namespace, on one host to each other (`--same-host`).
    #[serde(default)]
    pub same_host: bool,
    /// Whether the agents ran without a graph id (`--unnamed`).
    #[serde(default)]
    pub unnamed: bool,
    /// A protocol bug planted in every agent (tests of the campaign itself).
    #[cfg(feature = "mutants")]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub plant: Option<String>,
}

/// One line of `history.jsonl`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "event", rename_all = "snake_case")]
pub enum Event {
    /// The campaign's settings and schedule (the first line).
    Campaign {
        /// The settings.
        config: CampaignConfig,
        /// The schedule.
        schedule: Schedule,
    },
    /// An agent process started.
    Started {
        /// Milliseconds since the campaign started.
        t_ms: f64,
        /// The slot.
        slot: usize,
        /// The life.
        life: u32,
    },
    /// An agent life got its graph (joined or started alone).
    Ready {
        /// Milliseconds since the campaign started.
        t_ms: f64,
        /// Its replica id.
        replica: u32,
        /// The life, whether it started alone, and the peers that had a graph when it started.
        #[serde(flatten)]
        life: ReadyLife,
    },
    /// A signal sent to an agent process (`STOP`, `CONT`, `KILL`).
    Signal {
        /// Milliseconds since the campaign started.
        t_ms: f64,
        /// The slot.
        slot: usize,
        /// The signal.
        signal: String,
    },
    /// An episode's fault started.
    Fault {
        /// Milliseconds since the campaign started.
        t_ms: f64,
        /// The episode's index.
        episode: usize,
        /// The fault.
        fault: Fault,
    },
    /// An episode's fault healed; the writers stop.
    Heal {
        /// Milliseconds since the campaign started.
        t_ms: f64,
        /// The episode's index.
        episode: usize,
    },
    /// Every running agent showed the same graph (or the settle time ran out: `heal_to_converge_ms` is `None`).
    Converged {
        /// Milliseconds since the campaign started.
        t_ms: f64,
        /// The episode's index.
        episode: usize,
        /// Milliseconds from the heal until every running agent heard every other one.
        heal_to_heard_ms: Option<f64>,
        /// Milliseconds from the heal to the first status round in which all digests were equal.
        heal_to_converge_ms: Option<f64>,
    },
    /// A write.
    Write(WriteRecord),
    /// A write an agent could not make.
    Skipped {
        /// Milliseconds since the campaign started.
        t_ms: f64,
        /// The slot.
        slot: usize,
        /// The write's number.
        seq: u64,
        /// Why.
        reason: String,
    },
    /// An agent's final state.
    Final {
        /// The slot.
        slot: usize,
        /// Its life.
        life: u32,
        /// The state.
        state: FinalState,
    },
}

/// A life that got its graph, as the joins' check ([`super::check`]) needs it.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct ReadyLife {
    /// The slot.
    pub slot: usize,
    /// The life.
    pub life: u32,
    /// It started alone (no graph answer within its join wait) rather than from a peer's graph.
    #[serde(default)]
    pub alone: bool,
    /// The other slots that had a graph, were running, not stopped, and reachable (the new life's namespace not
    /// cut off) when this life started.
    #[serde(default)]
    pub ready_peers: Vec<usize>,
}

/// What an agent slot shows at a moment, for the timeline figure.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Shown {
    /// No process.
    Down,
    /// Stopped by `SIGSTOP`.
    Paused,
    /// Running, no graph yet.
    Joining,
    /// Its graph and digest are the ones more than half of the agents with a graph show.
    Agrees,
    /// Its digest differs from that majority's, or there is no majority.
    Differs,
}

/// A stretch of time in which a slot showed one thing.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Segment {
    /// Start, milliseconds since the campaign started.
    pub from_ms: f64,
    /// End.
    pub to_ms: f64,
    /// What it showed.
    pub shown: Shown,
}

/// One episode's outcome.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EpisodeResult {
    /// The fault's kind.
    pub kind: String,
    /// The fault.
    pub description: String,
    /// When the fault started, milliseconds since the campaign started.
    pub start_ms: f64,
    /// When it healed.
    pub heal_ms: f64,
    /// Milliseconds from the heal until every running agent heard every other one (a new life's peers discovered;
    /// `None`: not within the settle time). Agents keep hearing each other through short faults, so this is near 0
    /// after them; after a restart, a late join, or a cut or pause longer than four announce intervals (after which
    /// an agent forgets a silent peer, 2 s by default) it is the time until they hear each other again.
    pub heal_to_heard_ms: Option<f64>,
    /// Milliseconds from the heal until every running agent showed the same graph (`None`: not within the settle
    /// time).
    pub heal_to_converge_ms: Option<f64>,
}

/// What a campaign recorded.
#[derive(Debug)]
pub struct Recorded {
    /// Every write, in the order the campaign received them.
    pub writes: Vec<WriteRecord>,
    /// Every life that got its graph, in that order.
    pub lives: Vec<ReadyLife>,
    /// Replica ids of lives that were killed.
    pub killed_replicas: Vec<u32>,
    /// Final states of the agents running at the end.
    pub finals: Vec<(usize, FinalState)>,
    /// The episodes.
    pub episodes: Vec<EpisodeResult>,
    /// Per slot, what it showed over time.
    pub timeline: Vec<Vec<Segment>>,
    /// Writes skipped by the agents.
    pub skipped: u64,
    /// Problems seen while running (a process that died by itself, a final state missing).
    pub problems: Vec<String>,
    /// Milliseconds the campaign ran.
    pub duration_ms: f64,
    /// Samples the lives running at the end took from same-host shared memory (their last status lines).
    pub shm_samples_received: u64,
}
