//! Remote deltas: joining a received delta or snapshot into the state (the general join, and the install of a
//! snapshot into an empty replica), and keeping the derived indices (edges by endpoint, names) up to date.

use std::collections::{BTreeMap, BTreeSet};
use std::sync::Arc;

use smallvec::SmallVec;

use super::changes::{Change, ChangeEvent};
use super::{Replica, names};
use crate::delta::{Delta, Origin};
use crate::error::DeltaError;
use crate::ids::{EdgeKey, Element, Name, NodeId, Stamp};
use crate::mutants::{DsrMutant, Plant};
use crate::store::{Attrs, Register, Store, drop_covered_attrs, join_attrs};

impl Replica {
    /// Joins a delta or snapshot received from another replica.
    ///
    /// # Errors
    /// [`DeltaError::Dictionary`] if it uses a name or type this replica's dictionary refuses; the replica is then
    /// unchanged. (Structural errors are caught by [`Delta::decode`].)
    pub fn apply(&mut self, delta: &Delta) -> Result<(), DeltaError> {
        if self.can_install(delta) {
            return self.install(delta.clone());
        }
        self.apply_inner(delta, || Arc::new(delta.clone()))
    }

    /// Like [`Replica::apply`], for a delta already shared: it is retained for anti-entropy without a copy (and a
    /// snapshot joined into a fresh replica is moved in without a copy when this is its only holder).
    ///
    /// # Errors
    /// As [`Replica::apply`].
    pub fn apply_shared(&mut self, delta: Arc<Delta>) -> Result<(), DeltaError> {
        if self.can_install(&delta) {
            return self.install(Arc::try_unwrap(delta).unwrap_or_else(|shared| (*shared).clone()));
        }
        self.apply_inner(&delta, || Arc::clone(&delta))
    }

    /// Whether joining `delta` can take the fast path of [`Replica::install`]: a snapshot into a replica that has
    /// never held anything (a late joiner's first graph), with no planted mutant (mutants live in the general
    /// join).
    pub(super) fn can_install(&self, delta: &Delta) -> bool {
        delta.complete
            && delta.origin.is_none()
            && (self.plant == Plant::NONE || self.plant.is(DsrMutant::InstallDropsTombstones))
            && self.ctx.is_empty()
            && self.applied.is_empty()
            && self.store.nodes.is_empty()
            && self.store.edges.is_empty()
            && self.store.tombstones.is_empty()
            && self.log.is_empty()
    }

    /// The join of a snapshot into a replica that has never held anything ([`Replica::can_install`]), without the
    /// general join's per-entry work: the snapshot's store is moved in and put in the form the general join would
    /// leave (registers sorted by dot without repeated dots, tombstoned nodes and their edges dropped, empty
    /// entries dropped), the indices are built once, and the change events are the general join's, in its order.
    /// The result is exactly the general join's (a property test in `replica/install_tests.rs` checks state,
    /// indices, digest, applied operations and change events).
    pub(super) fn install(&mut self, delta: Delta) -> Result<(), DeltaError> {
        debug_assert!(self.can_install(&delta));
        let new = self.new_names(&delta)?;
        names::learn_names(&mut self.dictionary, new);
        let Delta { clock, ctx, applied, store, .. } = delta;
        let Store { mut tombstones, mut nodes, mut edges } = store;
        if self.plant.is(DsrMutant::InstallDropsTombstones) {
            tombstones.clear();
        }
        nodes.retain(|id, node| {
            if tombstones.contains(id) {
                return false;
            }
            normalize_register(&mut node.core);
            normalize_attrs(&mut node.attrs);
            !node.is_empty()
        });
        edges.retain(|key, edge| {
            if tombstones.contains(&key.from) || tombstones.contains(&key.to) {
                return false;
            }
            normalize_register(&mut edge.presence);
            normalize_attrs(&mut edge.attrs);
            !edge.is_empty()
        });
        self.store = Store { tombstones, nodes, edges };
        self.ctx.merge(&ctx);
        self.clock = self.clock.max(clock);
        self.applied.merge(&applied);

        // The indices, built in one go from the sorted store (they were empty, as the replica held nothing). What
        // the general join's `reindex_edges` and `reindex_names` would leave: every edge entry under both of its
        // endpoints, and every visible node under its winning core's name and stamp.
        let node_visible: Vec<bool> = self.store.nodes.keys().map(|id| self.node_visible(*id)).collect();
        let edge_visible: Vec<bool> = self.store.edges.iter().map(|(key, e)| self.edge_entry_visible(key, e)).collect();
        debug_assert!(self.out_edges.is_empty() && self.in_edges.is_empty() && self.names.is_empty());
        self.out_edges = group_sorted(self.store.edges.keys().map(|key| (key.from, key.clone())));
        let mut by_target: Vec<(NodeId, EdgeKey)> = self.store.edges.keys().map(|key| (key.to, key.clone())).collect();
        by_target.sort_unstable();
        self.in_edges = group_sorted(by_target.into_iter());
        let mut named: Vec<(Name, (Stamp, NodeId))> = Vec::with_capacity(self.store.nodes.len());
        let mut indexed: Vec<(NodeId, (Name, Stamp))> = Vec::with_capacity(self.store.nodes.len());
        for ((&id, node), _) in self.store.nodes.iter().zip(&node_visible).filter(|(_, visible)| **visible) {
            let core = node.core.winner_planted(self.plant).expect("a visible node has a core");
            named.push((core.value.name.clone(), (core.stamp, id)));
            indexed.push((id, (core.value.name.clone(), core.stamp)));
        }
        named.sort_unstable();
        self.names = group_sorted(named.into_iter());
        self.indexed_names = indexed.into_iter().collect();

        if let Some(mut queue) = self.changes.take() {
            // Nothing was visible before: every visible node and edge is inserted, then every winning attribute
            // of a visible element is updated, in the general join's order (nodes, edges, then attributes by
            // element and name).
            let nodes = || self.store.nodes.iter().zip(&node_visible).filter(|(_, v)| **v).map(|(node, _)| node);
            let edges = || self.store.edges.iter().zip(&edge_visible).filter(|(_, v)| **v).map(|(edge, _)| edge);
            let count = nodes().map(|(_, node)| 1 + node.attrs.len()).sum::<usize>()
                + edges().map(|(_, edge)| 1 + edge.attrs.len()).sum::<usize>();
            queue.reserve(count);
            let event = |change| ChangeEvent { change, origin: None };
            queue.extend(nodes().map(|(&id, _)| event(Change::NodeInserted { id })));
            queue.extend(edges().map(|(key, _)| event(Change::EdgeInserted { key: key.clone() })));
            for (&id, node) in nodes() {
                queue.extend(
                    node.attrs
                        .keys()
                        .map(|name| event(Change::AttrUpdated { element: Element::Node(id), name: name.clone() })),
                );
            }
            for (key, edge) in edges() {
                queue.extend(edge.attrs.keys().map(|name| {
                    event(Change::AttrUpdated { element: Element::Edge(key.clone()), name: name.clone() })
                }));
            }
            self.changes = Some(queue);
        }
        #[cfg(feature = "check-invariants")]
        self.check_invariants().expect("invariants after installing a snapshot");
        Ok(())
    }

    pub(super) fn apply_inner(&mut self, delta: &Delta, shared: impl FnOnce() -> Arc<Delta>) -> Result<(), DeltaError> {
        let new = self.new_names(delta)?;
        names::learn_names(&mut self.dictionary, new);
        // A delta whose own operation is joined already is not retained again, even when it carries folded ones
        // this replica lacked: the history keeps one entry per operation.
        let duplicate = delta.origin.is_some_and(|o| o.dots().all(|dot| self.applied.contains(dot)));
        self.join(delta);
        for dot in delta.origin.iter().flat_map(Origin::dots) {
            self.applied.insert(dot);
        }
        // A snapshot's applied operations are its sender's; a delta's are those folded into it (see `missing_for`).
        let planted = delta.complete && self.plant.is(DsrMutant::SnapshotAppliedFromContext);
        self.applied.merge(if planted { &delta.ctx } else { &delta.applied });
        if !duplicate && delta.origin.is_some() && !delta.complete {
            self.log.push(shared());
        }
        #[cfg(feature = "check-invariants")]
        self.check_invariants().expect("invariants after a join");
        Ok(())
    }

    /// The join: the single mutation path for local and remote deltas alike.
    pub(super) fn join(&mut self, delta: &Delta) {
        let plant = self.plant;
        let origin = delta.origin.map(|o| o.replica);
        // Change tracking looks at everything the delta may change, before and after; without it, only the
        // indices are kept up to date, for exactly the entries whose core or existence changed.
        let watched = self.changes.is_some().then(|| self.touched_by(delta));
        let before = watched.as_ref().map(|touched| self.look(touched));
        let mut names_to_reindex: SmallVec<[NodeId; 2]> = SmallVec::new();
        let mut edges_to_reindex: SmallVec<[EdgeKey; 2]> = SmallVec::new();

        // Tombstones first: a deleted node's entries and incident edges go, and nothing for it is accepted again.
        for &id in &delta.store.tombstones {
            if self.store.tombstones.insert(id) {
                self.store.nodes.remove(&id);
                names_to_reindex.push(id);
                if !plant.is(DsrMutant::DeleteKeepsIncidentEdges) {
                    for key in self.incident_edges(id) {
                        self.store.edges.remove(&key);
                        edges_to_reindex.push(key);
                    }
                }
            }
        }

        for (id, theirs) in &delta.store.nodes {
            if self.store.tombstones.contains(id) {
                continue;
            }
            let mine = self.store.nodes.entry(*id).or_default();
            if mine.core.join(&theirs.core, &self.ctx, &delta.ctx, plant) {
                names_to_reindex.push(*id);
            }
            if !(plant.is(DsrMutant::EarlyAttrDropped) && mine.core.is_empty()) {
                join_attrs(&mut mine.attrs, &theirs.attrs, &self.ctx, &delta.ctx, delta.complete, plant);
            }
            if mine.is_empty() {
                self.store.nodes.remove(id);
            }
        }
        if delta.complete {
            for (id, mine) in self.store.nodes.iter_mut() {
                if !delta.store.nodes.contains_key(id) {
                    if mine.core.drop_covered(&delta.ctx) {
                        names_to_reindex.push(*id);
                    }
                    drop_covered_attrs(&mut mine.attrs, &delta.ctx);
                }
            }
            self.store.nodes.retain(|_, node| !node.is_empty());
        }

        for (key, theirs) in &delta.store.edges {
            let dead_end = self.store.tombstones.contains(&key.from) || self.store.tombstones.contains(&key.to);
            if dead_end && !plant.is(DsrMutant::EdgeToDeletedNodeVisible) {
                continue;
            }
            let existed = self.store.edges.contains_key(key);
            let mine = self.store.edges.entry(key.clone()).or_default();
            mine.presence.join(&theirs.presence, &self.ctx, &delta.ctx, plant);
            join_attrs(&mut mine.attrs, &theirs.attrs, &self.ctx, &delta.ctx, delta.complete, plant);
            let exists = !mine.is_empty();
            if !exists {
                self.store.edges.remove(key);
            }
            if exists != existed {
                edges_to_reindex.push(key.clone());
            }
        }
        if delta.complete {
            for (key, mine) in self.store.edges.iter_mut() {
                if !delta.store.edges.contains_key(key) {
                    mine.presence.drop_covered(&delta.ctx);
                    drop_covered_attrs(&mut mine.attrs, &delta.ctx);
                    if mine.is_empty() {
                        edges_to_reindex.push(key.clone());
                    }
                }
            }
            self.store.edges.retain(|_, edge| !edge.is_empty());
        }

        self.ctx.merge_planted(&delta.ctx, plant);
        if origin != Some(self.id) && !(delta.complete && plant.is(DsrMutant::SnapshotJoinKeepsClock)) {
            // A local operation has already ticked the clock past its own stamp.
            self.clock = self.clock.max(delta.clock);
        }
        self.reindex_edges(&edges_to_reindex);
        self.reindex_names(&names_to_reindex);
        if let (Some(before), Some(watched)) = (before, watched) {
            let after = self.look(&watched);
            self.record_changes(&watched, &before, &after, origin);
        }
    }

    /// Brings the edge indices up to date for edge entries that appeared or went.
    fn reindex_edges(&mut self, keys: &[EdgeKey]) {
        for key in keys {
            if self.store.edges.contains_key(key) {
                self.out_edges.entry(key.from).or_default().insert(key.clone());
                self.in_edges.entry(key.to).or_default().insert(key.clone());
            } else {
                for (index, id) in [(&mut self.out_edges, key.from), (&mut self.in_edges, key.to)] {
                    if let Some(keys) = index.get_mut(&id) {
                        keys.remove(key);
                        if keys.is_empty() {
                            index.remove(&id);
                        }
                    }
                }
            }
        }
    }

    /// Brings the name index up to date for nodes whose core changed or that were deleted.
    fn reindex_names(&mut self, ids: &[NodeId]) {
        for id in ids {
            let stale_kept = self.plant.is(DsrMutant::NameKeptByDeletedHolder)
                && self.store.tombstones.contains(id)
                && self
                    .indexed_names
                    .get(id)
                    .is_some_and(|(name, _)| self.names.get(name).is_some_and(|h| h.len() > 1));
            if let Some((name, stamp)) = self.indexed_names.remove(id)
                && !stale_kept
                && let Some(holders) = self.names.get_mut(&name)
            {
                holders.remove(&(stamp, *id));
                if holders.is_empty() {
                    self.names.remove(&name);
                }
            }
            if !self.node_visible(*id) {
                continue;
            }
            let core = self.store.nodes[id].core.winner_planted(self.plant).expect("a visible node has a core");
            let (name, stamp) = (core.value.name.clone(), core.stamp);
            self.names.entry(name.clone()).or_default().insert((stamp, *id));
            self.indexed_names.insert(*id, (name, stamp));
        }
    }
}

/// Puts a register in the form the general join leaves when it joins the register into an empty one: sorted by
/// dot, the first of repeated dots kept.
fn normalize_register<T>(register: &mut Register<T>) {
    if register.values.windows(2).all(|pair| pair[0].dot < pair[1].dot) {
        return;
    }
    register.values.sort_by_key(|entry| entry.dot);
    register.values.dedup_by_key(|entry| entry.dot);
}

/// [`normalize_register`] for every register; empty registers go (the general join never inserts one).
fn normalize_attrs(attrs: &mut Attrs) {
    attrs.retain(|_, register| {
        normalize_register(register);
        !register.is_empty()
    });
}

/// A map of sets from `(key, item)` pairs sorted by key then item, each built in one go.
fn group_sorted<K: Ord, T: Ord>(pairs: impl Iterator<Item = (K, T)>) -> BTreeMap<K, BTreeSet<T>> {
    let mut groups: Vec<(K, Vec<T>)> = Vec::new();
    for (key, item) in pairs {
        match groups.last_mut() {
            Some((last, items)) if *last == key => items.push(item),
            _ => groups.push((key, vec![item])),
        }
    }
    groups.into_iter().map(|(key, items)| (key, items.into_iter().collect())).collect()
}
