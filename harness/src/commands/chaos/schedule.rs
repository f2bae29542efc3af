//! The seeded fault schedule: which faults, on whom, in which order, for how long. Pure: one seed gives one
//! schedule, whatever the machine.
//!
//! A campaign is a sequence of episodes. In each, the writers run while one fault is on; then the fault heals, the
//! writers stop, and the campaign measures the time until every running agent shows the same graph. Every round has
//! one episode of each kind, in a seeded order; the last agent slot is started by the late-join episode of the
//! first round (until then no fault touches it): `late join` or `late join alone`, whichever the seeded order puts
//! first (the other is left out, since there is one late agent).

use std::collections::BTreeSet;
use std::fmt;

use serde::{Deserialize, Serialize};
use transport::rng::SplitMix64;

/// One fault.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Fault {
    /// Random loss of `percent` of what `agents` receive from everyone.
    Loss {
        /// The receivers.
        agents: BTreeSet<usize>,
        /// Percentage dropped.
        percent: u8,
    },
    /// `to` drops `percent` of what `from` sends; the other way is untouched.
    OneWay {
        /// The senders.
        from: BTreeSet<usize>,
        /// The receivers.
        to: BTreeSet<usize>,
        /// Percentage dropped (100: a one-way cut).
        percent: u8,
    },
    /// Nothing passes between `side` and the other running agents.
    Partition {
        /// One side.
        side: BTreeSet<usize>,
    },
    /// `SIGSTOP` at the start, `SIGCONT` at the heal.
    Pause {
        /// The paused agent.
        agent: usize,
    },
    /// `SIGKILL` at the start, restart (a new life) after `down_ms`. `isolated`: the agent's namespace is cut off
    /// from the start until the heal, so the new life finds no peer, starts alone and writes alone.
    Kill {
        /// The killed agent.
        agent: usize,
        /// Milliseconds between the kill and the restart.
        down_ms: u64,
        /// Whether no peer is reachable while it is down and after its restart.
        isolated: bool,
    },
    /// The agent starts for the first time, while the others write. `isolated`: its namespace is cut off from the
    /// start until the heal, so the new agent finds no peer and starts alone in a graph of its own (with `cortex
    /// chaos --unnamed`, a new unnamed graph: one side must move to the other's at the heal).
    LateJoin {
        /// The joining agent.
        agent: usize,
        /// Whether no peer is reachable when it starts.
        #[serde(default)]
        isolated: bool,
    },
    /// `SIGKILL`, a restart after `down_ms`, `SIGSTOP` of the new process during its start (`at`), `SIGCONT`
    /// `stopped_ms` later: the new life must not hang, and must take the running graph when it resumes (the time it
    /// was stopped does not count against its join wait), not start alone. Until it resumes, no peer's message
    /// reaches the new life (discovery does), so the stop always finds it waiting for a graph.
    StopAtStart {
        /// The stopped agent.
        agent: usize,
        /// Milliseconds between the kill and the restart.
        down_ms: u64,
        /// When the new process is stopped.
        at: StopPoint,
        /// Milliseconds the new process is stopped.
        stopped_ms: u64,
    },
}

/// When `stop at start` stops the new process.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum StopPoint {
    /// This many milliseconds after the process started: while it builds its transport (the first 10–60 ms).
    Building {
        /// Milliseconds after the start.
        after_ms: u64,
    },
    /// This many milliseconds after its first status line (the agent exists and waits for a graph): in its join
    /// wait, before a peer's answer comes (over RTPS discovery alone takes some 100 ms).
    Joining {
        /// Milliseconds after the first status line.
        after_ms: u64,
    },
}

impl fmt::Display for StopPoint {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            StopPoint::Building { after_ms } => write!(f, "{after_ms} ms after its start (building its transport)"),
            StopPoint::Joining { after_ms } => write!(f, "{after_ms} ms after its first status (joining)"),
        }
    }
}

impl Fault {
    /// The kind, as reported per fault kind.
    pub fn kind(&self) -> &'static str {
        match self {
            Fault::Loss { .. } => "loss",
            Fault::OneWay { .. } => "one-way loss",
            Fault::Partition { .. } => "partition",
            Fault::Pause { .. } => "pause",
            Fault::Kill { isolated: false, .. } => "kill+restart",
            Fault::Kill { isolated: true, .. } => "kill+restart alone",
            Fault::LateJoin { isolated: false, .. } => "late join",
            Fault::LateJoin { isolated: true, .. } => "late join alone",
            Fault::StopAtStart { .. } => "stop at start",
        }
    }

    /// Every kind, in a fixed order.
    pub const KINDS: [&'static str; 9] = [
        "loss",
        "one-way loss",
        "partition",
        "pause",
        "kill+restart",
        "kill+restart alone",
        "stop at start",
        "late join",
        "late join alone",
    ];

    /// The kinds that need no network fault (what `cortex chaos --same-host` draws from): a kill whose new life is
    /// isolated, and a late joiner that is, need its namespace cut off.
    pub const PROCESS_KINDS: [&'static str; 4] = ["pause", "kill+restart", "stop at start", "late join"];

    /// A one-line description.
    pub fn describe(&self) -> String {
        let set = |s: &BTreeSet<usize>| s.iter().map(|a| format!("a{a}")).collect::<Vec<_>>().join(",");
        match self {
            Fault::Loss { agents, percent } => format!("loss {percent}% into {}", set(agents)),
            Fault::OneWay { from, to, percent } => format!("one-way {percent}% {} -> {}", set(from), set(to)),
            Fault::Partition { side } => format!("partition {} | rest", set(side)),
            Fault::Pause { agent } => format!("pause a{agent}"),
            Fault::Kill { agent, down_ms, isolated } => {
                format!("kill a{agent}, restart after {down_ms} ms{}", if *isolated { ", isolated" } else { "" })
            }
            Fault::LateJoin { agent, isolated } => {
                format!("late join a{agent}{}", if *isolated { ", isolated" } else { "" })
            }
            Fault::StopAtStart { agent, down_ms, at, stopped_ms } => {
                format!("kill a{agent}, restart after {down_ms} ms, stop it {at} for {stopped_ms} ms")
            }
        }
    }
}

/// One episode.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Episode {
    /// The fault.
    pub fault: Fault,
    /// How long the fault is on, in milliseconds.
    pub fault_ms: u64,
}

/// A campaign's schedule.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Schedule {
    /// Agent slots (the last one joins late).
    pub agents: usize,
    /// The episodes, in order.
    pub episodes: Vec<Episode>,
}

impl Schedule {
    /// The schedule of `seed` for `agents` slots (at least 3), `rounds` rounds and faults of `fault_ms`, one fault of
    /// each of `kinds` ([`Fault::KINDS`], or [`Fault::PROCESS_KINDS`]) per round; one late join in all, of the first
    /// round (of the two late-join kinds, the one the round's seeded order puts first).
    pub fn generate(seed: u64, agents: usize, rounds: usize, fault_ms: u64, kinds: &[&'static str]) -> Schedule {
        assert!(agents >= 3, "a campaign needs at least 3 agents");
        let mut rng = SplitMix64::new(seed ^ 0xC4A0_5EED);
        let late = agents - 1;
        let mut running: Vec<usize> = (0..late).collect();
        let mut episodes = Vec::new();
        for round in 0..rounds {
            let mut kinds: Vec<&str> = kinds.to_vec();
            shuffle(&mut kinds, &mut rng);
            // One late join: the first of the first round; the late agent runs from then on.
            let mut joined = round > 0;
            kinds.retain(|kind| !LATE_JOINS.contains(kind) || !std::mem::replace(&mut joined, true));
            for kind in kinds {
                let fault = draw(kind, &running, late, fault_ms, &mut rng);
                if let Fault::LateJoin { agent, .. } = fault {
                    running.push(agent);
                }
                episodes.push(Episode { fault, fault_ms });
            }
        }
        Schedule { agents, episodes }
    }
}

/// The kinds that start the late agent.
const LATE_JOINS: [&str; 2] = ["late join", "late join alone"];

fn shuffle<T>(items: &mut [T], rng: &mut SplitMix64) {
    for i in (1..items.len()).rev() {
        items.swap(i, rng.range(0, i as u64) as usize);
    }
}

/// A random non-empty proper subset of `running`.
fn subset(running: &[usize], rng: &mut SplitMix64) -> BTreeSet<usize> {
    let mut pool = running.to_vec();
    shuffle(&mut pool, rng);
    let size = rng.range(1, (running.len() - 1) as u64) as usize;
    pool.into_iter().take(size).collect()
}

fn one(running: &[usize], rng: &mut SplitMix64) -> usize {
    running[rng.range(0, running.len() as u64 - 1) as usize]
}

fn draw(kind: &str, running: &[usize], late: usize, fault_ms: u64, rng: &mut SplitMix64) -> Fault {
    match kind {
        "loss" => Fault::Loss { agents: subset(running, rng), percent: rng.range(20, 50) as u8 },
        "one-way loss" => {
            let from = subset(running, rng);
            let to = running.iter().copied().filter(|a| !from.contains(a)).collect();
            Fault::OneWay { from, to, percent: [60, 100][rng.range(0, 1) as usize] }
        }
        "partition" => Fault::Partition { side: subset(running, rng) },
        "pause" => Fault::Pause { agent: one(running, rng) },
        "kill+restart" | "kill+restart alone" => Fault::Kill {
            agent: one(running, rng),
            down_ms: fault_ms / 4 + rng.range(0, fault_ms / 4),
            isolated: kind == "kill+restart alone",
        },
        // Stopped while it builds its transport or while it waits for a graph, one or the other, for longer than the
        // campaign's join wait at the defaults (1.5 s against fault_ms / 2 and more).
        "stop at start" => Fault::StopAtStart {
            agent: one(running, rng),
            down_ms: fault_ms / 10,
            at: if rng.range(0, 1) == 0 {
                StopPoint::Building { after_ms: rng.range(10, 60) }
            } else {
                StopPoint::Joining { after_ms: rng.range(0, 40) }
            },
            stopped_ms: fault_ms / 2 + rng.range(0, fault_ms / 4),
        },
        _ => Fault::LateJoin { agent: late, isolated: kind == "late join alone" },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_seed_one_schedule_every_kind_once_per_round_and_nothing_touches_the_late_agent_before_it_joins() {
        let a = Schedule::generate(1, 4, 2, 3000, &Fault::KINDS);
        assert_eq!(a, Schedule::generate(1, 4, 2, 3000, &Fault::KINDS));
        assert_ne!(a, Schedule::generate(2, 4, 2, 3000, &Fault::KINDS));
        assert_eq!(a.episodes.len(), 8 + 7);
        for kind in Fault::KINDS.iter().filter(|k| !LATE_JOINS.contains(k)) {
            assert_eq!(a.episodes[..8].iter().filter(|e| e.fault.kind() == *kind).count(), 1, "{kind}");
        }
        let joins = |s: &Schedule| s.episodes.iter().filter(|e| matches!(e.fault, Fault::LateJoin { .. })).count();
        assert_eq!(joins(&a), 1);
        let isolated = (0..40)
            .map(|seed| Schedule::generate(seed, 3, 1, 2000, &Fault::KINDS))
            .filter(|s| s.episodes.iter().any(|e| e.fault.kind() == "late join alone"))
            .count();
        assert!((10..=30).contains(&isolated), "{isolated} of 40 seeds join alone");
        let alone = Schedule::generate(1, 3, 1, 2000, &["partition", "late join alone"]);
        assert_eq!(alone.episodes.iter().map(|e| e.fault.kind()).filter(|k| *k == "late join alone").count(), 1);
        for seed in 0..50 {
            let schedule = Schedule::generate(seed, 3, 2, 2000, &Fault::KINDS);
            let joined = schedule.episodes.iter().position(|e| matches!(e.fault, Fault::LateJoin { .. })).unwrap();
            for episode in &schedule.episodes[..joined] {
                let touched: Vec<usize> = match &episode.fault {
                    Fault::Loss { agents, .. } => agents.iter().copied().collect(),
                    Fault::OneWay { from, to, .. } => from.union(to).copied().collect(),
                    Fault::Partition { side } => side.iter().copied().collect(),
                    Fault::Pause { agent } | Fault::Kill { agent, .. } | Fault::StopAtStart { agent, .. } => {
                        vec![*agent]
                    }
                    Fault::LateJoin { .. } => unreachable!(),
                };
                assert!(!touched.contains(&2), "seed {seed}: {}", episode.fault.describe());
            }
        }
    }
}
