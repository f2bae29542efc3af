//! Change events: what a join changed in the visible graph (nodes, edges, names, attribute winners), found by
//! looking at the elements a delta touches before and after it is joined.

use std::collections::BTreeSet;

use smallvec::SmallVec;

use super::Replica;
use crate::delta::Delta;
use crate::ids::{Dot, EdgeKey, Element, Name, NodeId, ReplicaId};
use crate::mutants::{DsrMutant, Plant};
use crate::store::Attrs;

/// A change to the visible graph, reported when change tracking is on ([`Replica::set_change_tracking`]).
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Change {
    /// A node became visible.
    NodeInserted {
        /// The node.
        id: NodeId,
    },
    /// A node stopped being visible (deleted).
    NodeDeleted {
        /// The node.
        id: NodeId,
    },
    /// A visible node's shown name changed: it took its plain name back (the node that held the name was deleted)
    /// or became `name#id` (a concurrent insert of the same name holds it now).
    NodeRenamed {
        /// The node.
        id: NodeId,
    },
    /// An edge became visible.
    EdgeInserted {
        /// The edge.
        key: EdgeKey,
    },
    /// An edge stopped being visible.
    EdgeDeleted {
        /// The edge.
        key: EdgeKey,
    },
    /// An attribute's winning value changed (or the attribute appeared) on a visible element.
    AttrUpdated {
        /// The element.
        element: Element,
        /// The attribute.
        name: Name,
    },
    /// An attribute disappeared from a visible element.
    AttrRemoved {
        /// The element.
        element: Element,
        /// The attribute.
        name: Name,
    },
}

/// A change together with the replica whose operation caused it (`None` for a snapshot).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ChangeEvent {
    /// What changed.
    pub change: Change,
    /// Whose operation made it.
    pub origin: Option<ReplicaId>,
}

/// The elements a join may change, for change events.
#[derive(Default)]
pub(super) struct Touched {
    pub(super) nodes: BTreeSet<NodeId>,
    pub(super) edges: BTreeSet<EdgeKey>,
    pub(super) attrs: BTreeSet<(Element, Name)>,
}

/// What is visible of the touched elements (before or after a join), for change events: one entry per touched
/// element, in [`Touched`]'s order. Held in place for the one or two elements of an attribute write: as maps, the
/// looks before and after cost a receiving agent eight allocations a join.
pub(super) struct Visibility {
    /// `None` if invisible, else whether the node shows its plain name (not `name#id`).
    pub(super) nodes: SmallVec<[Option<bool>; 2]>,
    pub(super) edges: SmallVec<[bool; 2]>,
    pub(super) attrs: SmallVec<[Option<Dot>; 2]>,
}

impl Replica {
    /// The elements a delta may change: its own entries, tombstoned nodes and their incident edges, and the
    /// attributes of all of them; for an attribute write, only its own attributes ([`Replica::touched_by_attrs`]).
    pub(super) fn touched_by(&self, delta: &Delta) -> Touched {
        self.touched_by_attrs(delta).unwrap_or_else(|| self.touched_by_any(delta))
    }

    /// What an attribute write touches, or `None` for any other delta. A delta of node attributes alone (no core,
    /// edge or tombstone; not a snapshot) whose context takes no value of those nodes' cores away changes no
    /// node's or edge's visibility or name: only its own attributes may change, and the look before and after is
    /// theirs and their nodes', without the names and incident edges [`Replica::touched_by_any`] walks. Its
    /// events are the general look's (a property test in `replica/changes_tests.rs` checks it).
    pub(super) fn touched_by_attrs(&self, delta: &Delta) -> Option<Touched> {
        let store = &delta.store;
        if delta.complete || self.plant != Plant::NONE || !store.tombstones.is_empty() || !store.edges.is_empty() {
            return None;
        }
        let mut touched = Touched::default();
        for (id, theirs) in &store.nodes {
            let keeps_core =
                self.store.nodes.get(id).is_none_or(|mine| mine.core.dots().all(|dot| !delta.ctx.contains(dot)));
            if !theirs.core.is_empty() || !keeps_core {
                return None;
            }
            touched.nodes.insert(*id);
            touched.attrs.extend(theirs.attrs.keys().map(|name| (Element::Node(*id), name.clone())));
        }
        Some(touched)
    }

    /// What any delta may change ([`Replica::touched_by`]).
    pub(super) fn touched_by_any(&self, delta: &Delta) -> Touched {
        let mut touched = Touched::default();
        touched.nodes.extend(delta.store.nodes.keys().copied());
        touched.nodes.extend(delta.store.tombstones.iter().copied());
        touched.edges.extend(delta.store.edges.keys().cloned());
        if delta.complete {
            touched.nodes.extend(self.store.nodes.keys().copied());
            touched.edges.extend(self.store.edges.keys().cloned());
        }
        // A node that arrives or goes may take a name from, or give it back to, the visible nodes sharing it.
        let names: BTreeSet<&Name> = touched
            .nodes
            .iter()
            .flat_map(|id| {
                let mine = self.store.nodes.get(id).map(|n| n.core.values.iter()).into_iter().flatten();
                let theirs = delta.store.nodes.get(id).map(|n| n.core.values.iter()).into_iter().flatten();
                mine.chain(theirs).map(|core| &core.value.name)
            })
            .collect();
        let sharing: Vec<NodeId> =
            names.into_iter().flat_map(|name| self.names.get(name).into_iter().flatten().map(|(_, id)| *id)).collect();
        touched.nodes.extend(sharing);
        let nodes: Vec<NodeId> = touched.nodes.iter().copied().collect();
        for id in nodes.into_iter().filter(|_| !self.plant.is(DsrMutant::IncidentEdgeEventsMissing)) {
            touched.edges.extend(self.incident_edges(id));
        }
        let mut names = |element: Element, attrs: Option<&Attrs>| {
            for name in attrs.into_iter().flat_map(|a| a.keys()) {
                touched.attrs.insert((element.clone(), name.clone()));
            }
        };
        for id in touched.nodes.clone() {
            names(Element::Node(id), self.store.nodes.get(&id).map(|n| &n.attrs));
            names(Element::Node(id), delta.store.nodes.get(&id).map(|n| &n.attrs));
        }
        for key in touched.edges.clone() {
            names(Element::Edge(key.clone()), self.store.edges.get(&key).map(|e| &e.attrs));
            names(Element::Edge(key.clone()), delta.store.edges.get(&key).map(|e| &e.attrs));
        }
        touched
    }

    pub(super) fn look(&self, touched: &Touched) -> Visibility {
        let plant = self.plant;
        Visibility {
            nodes: touched.nodes.iter().map(|id| self.node(*id).map(|node| node.holds_name())).collect(),
            edges: touched.edges.iter().map(|key| self.edge_visible(key)).collect(),
            attrs: touched
                .attrs
                .iter()
                .map(|(element, name)| {
                    let visible = match element {
                        Element::Node(id) => self.node_visible(*id),
                        Element::Edge(key) => self.edge_visible(key),
                    };
                    let attrs = match element {
                        Element::Node(id) => self.store.nodes.get(id).map(|n| &n.attrs),
                        Element::Edge(key) => self.store.edges.get(key).map(|e| &e.attrs),
                    };
                    attrs
                        .filter(|_| visible)
                        .and_then(|a| a.get(name))
                        .and_then(|r| r.winner_planted(plant))
                        .map(|e| e.dot)
                })
                .collect(),
        }
    }

    /// Queues the events of a join that took the touched elements from `before` to `after` (this replica's look
    /// now), if change tracking is on.
    pub(super) fn record_changes(
        &mut self,
        touched: &Touched,
        before: &Visibility,
        after: &Visibility,
        origin: Option<ReplicaId>,
    ) {
        // Whether an element is visible now (every touched attribute's element is touched too).
        let visible_now = |element: &Element| match element {
            Element::Node(id) => self.node(*id).is_some(),
            Element::Edge(key) => self.edge_visible(key),
        };
        let mut events = Vec::new();
        let mut push = |change| events.push(ChangeEvent { change, origin });
        for ((id, was), now) in touched.nodes.iter().zip(&before.nodes).zip(&after.nodes) {
            match (was, now) {
                (None, Some(_)) => push(Change::NodeInserted { id: *id }),
                (Some(_), None) => push(Change::NodeDeleted { id: *id }),
                (Some(plain), Some(now)) if plain != now => push(Change::NodeRenamed { id: *id }),
                _ => {}
            }
        }
        for ((key, was), now) in touched.edges.iter().zip(&before.edges).zip(&after.edges) {
            match (was, now) {
                (false, true) => push(Change::EdgeInserted { key: key.clone() }),
                (true, false) => push(Change::EdgeDeleted { key: key.clone() }),
                _ => {}
            }
        }
        for (((element, name), was), now) in touched.attrs.iter().zip(&before.attrs).zip(&after.attrs) {
            let change = match (was, now) {
                (_, Some(dot)) if *was != Some(*dot) => {
                    Change::AttrUpdated { element: element.clone(), name: name.clone() }
                }
                // An element's deletion says it all.
                (Some(_), None) if visible_now(element) => {
                    Change::AttrRemoved { element: element.clone(), name: name.clone() }
                }
                _ => continue,
            };
            push(change);
        }
        match self.changes.as_mut() {
            // Drained since the last join (an agent drains after each): the events become the queue.
            Some(queue) if queue.is_empty() => *queue = events,
            Some(queue) => queue.extend(events),
            None => {}
        }
    }
}
