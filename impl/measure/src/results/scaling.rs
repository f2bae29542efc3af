//! What the control-traffic simulation measured ([`crate::scaling`]): samples and bytes per message kind, sent and
//! received, for each number of agents.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::spec::ScalingExperiment;

/// Samples and bytes of one message kind in the measured window.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct KindTraffic {
    /// Samples published (one publish to all counts once).
    pub samples_sent: u64,
    /// Bytes published (envelope included; transport headers not).
    pub bytes_sent: u64,
    /// Samples taken off the agents' inboxes, summed over the receivers.
    pub samples_received: u64,
    /// Bytes taken off the agents' inboxes, summed over the receivers.
    pub bytes_received: u64,
}

impl KindTraffic {
    /// Adds `other` to this.
    pub fn add(&mut self, other: &KindTraffic) {
        self.samples_sent += other.samples_sent;
        self.bytes_sent += other.bytes_sent;
        self.samples_received += other.samples_received;
        self.bytes_received += other.bytes_received;
    }
}

/// The envelope kinds that are anti-entropy control traffic (`agent::envelope::Message::kind`).
pub const CONTROL_KINDS: &[&str] = &["announce", "missing-request"];
/// The kinds that repair: answers to missing-requests.
pub const REPAIR_KINDS: &[&str] = &["deltas", "snapshot"];
/// The kinds that carry the writes themselves.
pub const DATA_KINDS: &[&str] = &["delta"];

/// One number of agents.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ScalingRow {
    /// Agents in the group.
    pub agents: u32,
    /// Length of the measured window, ms of simulated time.
    pub window_ms: u64,
    /// Writes made in the window (all writers together).
    pub writes: u64,
    /// Traffic by message kind in the window.
    pub kinds: BTreeMap<String, KindTraffic>,
    /// Whether every replica had the same digest at the end (after the window and a settling time).
    pub converged: bool,
}

impl ScalingRow {
    /// The traffic of `kinds`, added up.
    pub fn sum(&self, kinds: &[&str]) -> KindTraffic {
        let mut total = KindTraffic::default();
        for kind in kinds {
            if let Some(traffic) = self.kinds.get(*kind) {
                total.add(traffic);
            }
        }
        total
    }

    /// `count` (bytes, samples or writes) over the window, per second.
    pub fn per_second(&self, count: u64) -> f64 {
        count as f64 * 1_000.0 / self.window_ms.max(1) as f64
    }

    /// The row's figures per second, as the report and `cortex bench scaling` show them.
    pub fn rates(&self) -> ScalingRates {
        let n = f64::from(self.agents.max(1));
        let (control, data) = (self.sum(CONTROL_KINDS), self.sum(DATA_KINDS));
        ScalingRates {
            writes: self.per_second(self.writes),
            announces_sent: self.per_second(self.kinds.get("announce").map_or(0, |k| k.samples_sent)),
            control_bytes_sent: self.per_second(control.bytes_sent),
            control_bytes_received: self.per_second(control.bytes_received),
            control_bytes_received_per_agent: self.per_second(control.bytes_received) / n,
            repair_bytes_sent: self.per_second(self.sum(REPAIR_KINDS).bytes_sent),
            data_bytes_sent: self.per_second(data.bytes_sent),
            data_bytes_received_per_agent: self.per_second(data.bytes_received) / n,
        }
    }
}

/// One row's figures per second of the window ([`ScalingRow::rates`]); bytes are envelope bytes, "sent" and
/// "received" summed over all agents unless the name says per agent.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ScalingRates {
    /// Writes per second.
    pub writes: f64,
    /// Announces published per second.
    pub announces_sent: f64,
    /// Control bytes (announces, missing-requests) published per second.
    pub control_bytes_sent: f64,
    /// Control bytes taken off all agents' inboxes per second.
    pub control_bytes_received: f64,
    /// Control bytes taken off one agent's inbox per second, on average.
    pub control_bytes_received_per_agent: f64,
    /// Repair bytes (deltas, snapshots answering missing-requests) published per second.
    pub repair_bytes_sent: f64,
    /// Data bytes (the writes' deltas) published per second.
    pub data_bytes_sent: f64,
    /// Data bytes taken off one agent's inbox per second, on average.
    pub data_bytes_received_per_agent: f64,
}

/// The experiment as run and its rows, one per number of agents.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ScalingResult {
    /// The experiment.
    pub experiment: ScalingExperiment,
    /// One row per number of agents, in the experiment's order.
    pub rows: Vec<ScalingRow>,
}
