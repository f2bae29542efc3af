//! A life's graph (the core's **Graphs**): which messages belong to it, which graph a life that names none starts
//! alone, and when an unnamed graph moves to another.

use super::{AgentCore, Event, MAX_FOREIGN_GRAPHS, Output};
use crate::AgentId;
use crate::graph_id::GraphId;
use crate::mutants::ProtocolMutant;

impl AgentCore {
    /// Whether a message of kind `kind` carrying `graph` from `from` belongs to this life's graph. A foreign one
    /// is counted and, the first time its graph id is seen, reported in `out`. A message with no graph id is
    /// admitted only if it is a graph request; one of any graph is admitted while this life joins without a
    /// named graph (its deltas are buffered with their graph until it knows its own).
    pub fn admit(&mut self, graph: Option<GraphId>, from: AgentId, kind: &'static str, out: &mut Output) -> bool {
        let Some(theirs) = graph else { return kind == "graph-request" };
        match self.graph {
            None => true,
            Some(mine) if mine == theirs => true,
            mine => {
                self.refuse_foreign(theirs, from, kind, mine, out);
                false
            }
        }
    }

    pub(super) fn refuse_foreign(
        &mut self,
        theirs: GraphId,
        from: AgentId,
        kind: &'static str,
        mine: Option<GraphId>,
        out: &mut Output,
    ) {
        self.foreign_refused += 1;
        if !self.foreign.contains(&theirs) && self.foreign.len() < MAX_FOREIGN_GRAPHS {
            self.foreign.insert(theirs);
            out.events.push(Event::ForeignGraph { graph: theirs, from, kind, mine });
        }
    }

    /// While joining without a named graph, notes the graph of an admitted message (none for a joiner's graph
    /// request, which proves no graph).
    pub(super) fn hear_graph(&mut self, graph: Option<GraphId>) {
        let Some(graph) = graph.filter(|_| self.graph.is_none()) else { return };
        if !self.heard_graphs.contains(&graph) && self.heard_graphs.len() < MAX_FOREIGN_GRAPHS {
            self.heard_graphs.push(graph);
        }
    }

    /// The graph a life that names none starts alone, and whether it is named: the one graph its peers were heard
    /// in, unnamed (so that anti-entropy merges what it writes with theirs once they hear each other); having heard
    /// none, the unnamed graph of its previous life ([`super::LifeSeed::recorded_graph`]) or else a new one, its id
    /// drawn from the life's nonce, unnamed; having heard several, a new one, named, since it cannot tell which it
    /// was meant to join.
    pub(super) fn graph_to_start(&self, out: &mut Output) -> (GraphId, bool) {
        match self.heard_graphs.as_slice() {
            [graph] => (*graph, false),
            [] => (self.life.recorded_graph.unwrap_or_else(|| GraphId::from_nonce(self.life.nonce)), false),
            heard => {
                out.events.push(Event::SeveralGraphsHeard { graphs: heard.to_vec() });
                (GraphId::from_nonce(self.life.nonce), true)
            }
        }
    }

    /// An announce of graph `theirs` from `from`, named or not, heard at `now_ns` by a life whose graph is unnamed:
    /// of its own graph and named, its graph is named from now on; of another graph, named or unnamed with a
    /// smaller id, the life moves to that graph — it is admitted from then on, this life's next tick announces in
    /// it, and anti-entropy merges the two copies. Lives whose graph is unnamed thus end in one graph once they
    /// hear each other: a named one if they hear one, else the smallest id among theirs.
    pub(super) fn follow_graph(
        &mut self,
        theirs: Option<GraphId>,
        from: AgentId,
        theirs_named: bool,
        now_ns: u64,
        out: &mut Output,
    ) {
        let (Some(theirs), Some(mine)) = (theirs, self.graph) else { return };
        if self.named || self.config.plant.is(ProtocolMutant::UnnamedGraphNeverMoves) {
            return;
        }
        if theirs == mine {
            if theirs_named {
                self.named = true;
                out.events.push(Event::GraphNamed { graph: mine, by: from });
            }
            return;
        }
        if !theirs_named && theirs > mine {
            return;
        }
        (self.graph, self.named) = (Some(theirs), theirs_named);
        self.foreign.remove(&theirs);
        self.next_announce_ns = self.next_announce_ns.min(now_ns);
        out.events.push(Event::GraphMoved { left: mine, graph: theirs, by: from, named: theirs_named });
    }
}
