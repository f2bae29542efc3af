//! The expensive self-check of a replica's state and indices ([`Replica::check_invariants`]).

use std::collections::BTreeSet;

use super::Replica;
use crate::ids::NodeId;

impl Replica {
    /// Checks the replica's invariants; a failure is a bug. Walks the whole state: for tests and debugging.
    ///
    /// # Errors
    /// A description of the first violated invariant.
    pub fn check_invariants(&self) -> Result<(), String> {
        for edge in self.edges() {
            if !self.node_visible(edge.key.from) || !self.node_visible(edge.key.to) {
                return Err(format!("dangling visible edge {}", edge.key));
            }
        }
        let mut seen = BTreeSet::new();
        for node in self.nodes() {
            if !seen.insert(node.name().into_owned()) {
                return Err(format!("two visible nodes named {:?}", node.name()));
            }
        }
        for id in &self.store.tombstones {
            if self.store.nodes.contains_key(id) {
                return Err(format!("deleted node {id} still has an entry"));
            }
        }
        for (id, node) in &self.store.nodes {
            for dot in node.dots() {
                if !self.ctx.contains(dot) {
                    return Err(format!("node {id}: dot {dot} not in the causal context"));
                }
            }
        }
        for (key, edge) in &self.store.edges {
            for dot in edge.dots() {
                if !self.ctx.contains(dot) {
                    return Err(format!("edge {key}: dot {dot} not in the causal context"));
                }
            }
            if !self.out_edges.get(&key.from).is_some_and(|keys| keys.contains(key)) {
                return Err(format!("edge {key} missing from the out-edge index"));
            }
        }
        let visible: BTreeSet<NodeId> = self.nodes().map(|n| n.id).collect();
        let indexed: BTreeSet<NodeId> = self.indexed_names.keys().copied().collect();
        if visible != indexed {
            return Err("name index out of step with visible nodes".into());
        }
        Ok(())
    }
}
