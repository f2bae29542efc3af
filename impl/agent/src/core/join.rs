//! The late join: answering a joiner's graph request with a snapshot, and becoming ready from a graph answer
//! (or alone, from the seed graph).

use std::sync::Arc;

use dsr::{Delta, Replica};

use super::{AgentCore, Caches, Dest, Event, MAX_ANSWERED, Output};
use crate::AgentId;
use crate::envelope::Message;
use crate::graph_id::GraphId;

impl AgentCore {
    pub(super) fn answer_graph_request(&mut self, from: AgentId, nonce: u64, now_ns: u64, out: &mut Output) {
        if self.config.read_only {
            return; // It may not publish answers; a writer of the graph answers.
        }
        let recent =
            self.answered.get(&(from, nonce)).is_some_and(|at| now_ns.saturating_sub(*at) < self.config.answer_hold_ns);
        if recent {
            return;
        }
        let Some((snapshot, from_cache)) = self.snapshot_bytes() else { return };
        self.answered.retain(|_, at| now_ns.saturating_sub(*at) < self.config.answer_hold_ns);
        if self.answered.len() < MAX_ANSWERED {
            self.answered.insert((from, nonce), now_ns);
        }
        out.events.push(Event::Answered { to: from, snapshot_bytes: snapshot.len(), from_cache });
        let answer = Message::GraphAnswer { from: self.config.id, to: from, nonce, named: self.named, snapshot };
        out.send(answer, Dest::Sender);
    }

    /// Creates this life's replica from a graph answer (or alone, from the seed), then applies what was buffered
    /// while joining.
    pub(super) fn become_ready(&mut self, now_ns: u64, snapshot: Option<Arc<Delta>>, out: &mut Output) {
        if let Some(snapshot) = &snapshot {
            self.note_incarnations(snapshot.context(), out);
        }
        let Some(incarnation) = self.incarnation() else {
            out.events.push(Event::IncarnationsExhausted);
            self.collision = Some(format!("no incarnation of {} is left", self.config.id));
            return;
        };
        let mut replica = Replica::new(self.config.id.replica(incarnation));
        replica.set_log_limits(self.config.log_limits);
        replica.set_change_tracking(self.change_tracking);
        let alone = snapshot.is_none();
        if self.graph.is_none() {
            let (graph, named) = self.graph_to_start(out);
            (self.graph, self.named) = (Some(graph), named);
        }
        let graph = self.graph.unwrap_or_else(|| GraphId::from_nonce(self.life.nonce));
        let mut seed_nodes = None;
        if let Some(snapshot) = snapshot {
            if let Err(error) = replica.apply_shared(snapshot) {
                out.events.push(Event::Rejected { what: "graph answer", error: error.to_string() });
                return;
            }
            if self.seed.0.take().is_some() {
                out.events.push(Event::SeedUnused);
            }
        } else if let Some(seed) = self.seed.0.take() {
            match seed.import_into(&mut replica, now_ns) {
                Ok(report) => {
                    seed_nodes = Some(report.nodes);
                    let warnings = report.warnings.iter().map(|w| Event::SeedWarning { warning: w.to_string() });
                    out.events.extend(warnings);
                }
                Err(error) => out.events.push(Event::SeedRefused { error: error.to_string() }),
            }
        }
        let named = self.named;
        out.events.push(Event::Ready { graph, replica: replica.id(), incarnation, alone, named, seed_nodes });
        self.replica = Some(replica);
        self.caches.0 = Caches::default();
        // Deltas buffered from another graph while this life did not know its own are refused now.
        let mut buffered = Vec::with_capacity(self.buffered.len());
        for (theirs, from, delta) in std::mem::take(&mut self.buffered) {
            if theirs == graph {
                buffered.push(delta);
            } else {
                self.refuse_foreign(theirs, from, "buffered delta", Some(graph), out);
            }
        }
        self.apply("buffered delta", None, buffered, out);
    }
}
