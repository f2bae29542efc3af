//! Reads of the visible graph: nodes by id or name, edges by key or endpoint, counts.

use std::collections::BTreeSet;

use super::Replica;
use super::views::{EdgeRef, NodeRef};
use crate::ids::{EdgeKey, NodeId, Stamp};
use crate::mutants::DsrMutant;

impl Replica {
    /// A visible node.
    pub fn node(&self, id: NodeId) -> Option<NodeRef<'_>> {
        if !self.node_visible(id) {
            return None;
        }
        let entry = &self.store.nodes[&id];
        let core = entry.core.winner_planted(self.plant)?;
        Some(NodeRef { replica: self, id, entry, core })
    }

    /// Which of the visible nodes sharing a name, indexed by (insert stamp, id), holds it: the lowest (a planted
    /// mutant may change the rule).
    pub(super) fn name_holder(&self, holders: &BTreeSet<(Stamp, NodeId)>) -> Option<NodeId> {
        let holder = if self.plant.is(DsrMutant::NameHeldByLatest) { holders.last() } else { holders.first() };
        holder.map(|(_, id)| *id)
    }

    /// The visible node shown under `name` (see the crate docs for renamed nodes, `name#id`).
    pub fn node_by_name(&self, name: &str) -> Option<NodeRef<'_>> {
        if let Some(holders) = self.names.get(name) {
            return self.name_holder(holders).and_then(|id| self.node(id));
        }
        let (base, id) = name.rsplit_once('#')?;
        let node = self.node(NodeId(id.parse().ok()?))?;
        (node.core.value.name.as_str() == base && node.name() == name).then_some(node)
    }

    /// Every visible node, in id order.
    pub fn nodes(&self) -> impl Iterator<Item = NodeRef<'_>> + '_ {
        self.store.nodes.keys().filter_map(|id| self.node(*id))
    }

    /// Number of visible nodes.
    pub fn node_count(&self) -> usize {
        self.nodes().count()
    }

    /// A visible edge.
    pub fn edge(&self, key: &EdgeKey) -> Option<EdgeRef<'_>> {
        let (key, entry) = self.store.edges.get_key_value(key)?;
        self.edge_entry_visible(key, entry).then_some(EdgeRef { replica: self, key, entry })
    }

    /// Every visible edge, in key order.
    pub fn edges(&self) -> impl Iterator<Item = EdgeRef<'_>> + '_ {
        self.store.edges.iter().filter(|(key, entry)| self.edge_entry_visible(key, entry)).map(|(key, entry)| EdgeRef {
            replica: self,
            key,
            entry,
        })
    }

    /// Number of visible edges.
    pub fn edge_count(&self) -> usize {
        self.edges().count()
    }

    /// Visible edges leaving `id`.
    pub fn out_edges(&self, id: NodeId) -> impl Iterator<Item = EdgeRef<'_>> + '_ {
        self.out_edges.get(&id).into_iter().flatten().filter_map(|key| self.edge(key))
    }

    /// Visible edges entering `id`.
    pub fn in_edges(&self, id: NodeId) -> impl Iterator<Item = EdgeRef<'_>> + '_ {
        self.in_edges.get(&id).into_iter().flatten().filter_map(|key| self.edge(key))
    }

    /// Whether `id` was deleted (it can never be visible again).
    pub fn is_deleted(&self, id: NodeId) -> bool {
        self.store.tombstones.contains(&id)
    }
}
