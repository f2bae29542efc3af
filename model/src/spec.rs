//! The reference specification of the DSR graph: what the visible graph must be, computed from the set of
//! operations and their causal order alone.
//!
//! It is written as the simplest, obviously correct reading of the semantics in the `dsr` crate documentation — no
//! deltas, no dots, no causal contexts, no joins — so that a bug shared by the implementation and the specification
//! is unlikely. An operation *saw* another if its replica had applied the other's delta when it issued it (directly:
//! deltas are not delivered causally, so seeing an operation does not mean seeing everything it saw). Then:
//!
//! - a node is visible iff it was inserted and no operation deleted it;
//! - an edge is visible iff some insert of it was not seen by a delete of it, and both endpoints are visible;
//! - an attribute write is live iff no later write or removal of the same attribute (nor, for edges, a delete or a
//!   re-insert of the edge) saw it; the shown value is the live write with the highest (stamp, replica);
//! - among visible nodes sharing a name, the earliest (insert stamp, id) keeps it and the others are `name#id`.
//!
//! The replica does not deliver causally (see the `dsr` crate docs), so a replica that has applied an operation
//! without one its writer had seen may show what this specification does not (an overwritten value beside its
//! overwrite). The convergence model therefore compares a replica with this specification when its applied
//! operations are causally closed (each one's past among them), and at quiescence, where all are.
//!
//! Because stamps follow causality transitively (each replica's hybrid logical clock moves past every delta it
//! applies), the shown value of a register is always the causally latest write; a write that was only seen through a
//! third replica's unrelated operation may stay listed among the concurrent values beside it.

use std::collections::{BTreeMap, BTreeSet};

use dsr::{EdgeKey, Element, Name, NodeId, ReplicaId, Stamp, Value, VisibleAttr, VisibleGraph, VisibleNode};

/// Identifies an operation: the first dot it generated.
pub type OpId = dsr::Dot;

/// What an operation did.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub enum OpKind {
    /// Inserted a node with initial attributes.
    InsertNode {
        /// The node.
        id: NodeId,
        /// Its type.
        node_type: Name,
        /// Its name.
        name: Name,
        /// Initial attributes.
        attrs: Vec<(Name, Value)>,
    },
    /// Deleted a node.
    DeleteNode {
        /// The node.
        id: NodeId,
    },
    /// Inserted an edge with initial attributes.
    InsertEdge {
        /// The edge.
        key: EdgeKey,
        /// Initial attributes.
        attrs: Vec<(Name, Value)>,
    },
    /// Deleted an edge.
    DeleteEdge {
        /// The edge.
        key: EdgeKey,
    },
    /// Wrote an attribute.
    SetAttr {
        /// The element.
        element: Element,
        /// The attribute.
        name: Name,
        /// The value.
        value: Value,
    },
    /// Removed an attribute.
    RemoveAttr {
        /// The element.
        element: Element,
        /// The attribute.
        name: Name,
    },
}

/// One operation as the specification sees it.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct OpRecord {
    /// Its id.
    pub id: OpId,
    /// The replica that issued it.
    pub replica: ReplicaId,
    /// Its hybrid-logical-clock stamp.
    pub stamp: Stamp,
    /// The operations its replica had applied when it issued it (not necessarily transitively closed).
    pub past: BTreeSet<OpId>,
    /// What it did.
    pub kind: OpKind,
}

impl std::fmt::Display for OpRecord {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let element = |e: &Element| match e {
            Element::Node(id) => format!("node {id}"),
            Element::Edge(key) => format!("edge {key}"),
        };
        match &self.kind {
            OpKind::InsertNode { id, name, .. } => write!(f, "{} inserts node {id} {name:?}", self.replica),
            OpKind::DeleteNode { id } => write!(f, "{} deletes node {id}", self.replica),
            OpKind::InsertEdge { key, .. } => write!(f, "{} inserts edge {key}", self.replica),
            OpKind::DeleteEdge { key } => write!(f, "{} deletes edge {key}", self.replica),
            OpKind::SetAttr { element: e, name, value } => {
                write!(f, "{} sets {}.{name} = {value:?}", self.replica, element(e))
            }
            OpKind::RemoveAttr { element: e, name } => write!(f, "{} removes {}.{name}", self.replica, element(e)),
        }?;
        write!(f, " [op {} at stamp {}]", self.id, self.stamp.0)
    }
}

/// The causal order of a set of operations: `sees(a, b)` iff `b` happened before `a`.
pub struct CausalOrder<'a> {
    ops: &'a [OpRecord],
    closure: BTreeMap<OpId, BTreeSet<OpId>>,
}

impl<'a> CausalOrder<'a> {
    /// Builds the transitive closure of the recorded pasts.
    pub fn new(ops: &'a [OpRecord]) -> Self {
        let by_id: BTreeMap<OpId, &OpRecord> = ops.iter().map(|op| (op.id, op)).collect();
        let mut closure = BTreeMap::new();
        for op in ops {
            let mut seen = BTreeSet::new();
            let mut stack: Vec<OpId> = op.past.iter().copied().collect();
            while let Some(id) = stack.pop() {
                if seen.insert(id)
                    && let Some(earlier) = by_id.get(&id)
                {
                    stack.extend(earlier.past.iter().copied());
                }
            }
            closure.insert(op.id, seen);
        }
        CausalOrder { ops, closure }
    }

    /// Whether `later` happened after `earlier` (transitively).
    pub fn sees(&self, later: OpId, earlier: OpId) -> bool {
        self.closure.get(&later).is_some_and(|past| past.contains(&earlier))
    }

    /// Whether `later`'s replica had applied `earlier` when it issued `later`.
    pub fn applied(&self, later: OpId, earlier: OpId) -> bool {
        self.ops.iter().any(|op| op.id == later && op.past.contains(&earlier))
    }

    /// Whether neither saw the other.
    pub fn concurrent(&self, a: OpId, b: OpId) -> bool {
        a != b && !self.sees(a, b) && !self.sees(b, a)
    }

    /// The operations.
    pub fn ops(&self) -> &'a [OpRecord] {
        self.ops
    }
}

/// A write of an attribute, by an operation.
struct Write<'a> {
    op: &'a OpRecord,
    element: Element,
    name: Name,
    value: Value,
}

/// Whether operation `later` ends write `write` (given that `later` saw it).
fn supersedes(later: &OpKind, write: &Write<'_>) -> bool {
    match later {
        OpKind::SetAttr { element, name, .. } | OpKind::RemoveAttr { element, name } => {
            *element == write.element && *name == write.name
        }
        OpKind::DeleteEdge { key } | OpKind::InsertEdge { key, .. } => write.element == Element::Edge(key.clone()),
        OpKind::InsertNode { .. } | OpKind::DeleteNode { .. } => false,
    }
}

/// The visible graph the specification requires after all of `ops` have been applied.
pub fn visible_graph(ops: &[OpRecord]) -> VisibleGraph {
    let deleted: BTreeSet<NodeId> = ops
        .iter()
        .filter_map(|op| match op.kind {
            OpKind::DeleteNode { id } => Some(id),
            _ => None,
        })
        .collect();
    let mut nodes: BTreeMap<NodeId, (&OpRecord, &Name, &Name)> = BTreeMap::new();
    for op in ops {
        if let OpKind::InsertNode { id, node_type, name, .. } = &op.kind
            && !deleted.contains(id)
        {
            nodes.insert(*id, (op, node_type, name));
        }
    }

    let mut edges: BTreeSet<EdgeKey> = BTreeSet::new();
    for op in ops {
        if let OpKind::InsertEdge { key, .. } = &op.kind {
            let removed = ops.iter().any(|later| {
                matches!(&later.kind, OpKind::DeleteEdge { key: k } if k == key) && later.past.contains(&op.id)
            });
            if !removed && nodes.contains_key(&key.from) && nodes.contains_key(&key.to) {
                edges.insert(key.clone());
            }
        }
    }

    let mut writes: Vec<Write<'_>> = Vec::new();
    for op in ops {
        match &op.kind {
            OpKind::InsertNode { id, attrs, .. } => {
                writes.extend(attrs.iter().map(|(name, value)| Write {
                    op,
                    element: Element::Node(*id),
                    name: name.clone(),
                    value: value.clone(),
                }));
            }
            OpKind::InsertEdge { key, attrs } => {
                writes.extend(attrs.iter().map(|(name, value)| Write {
                    op,
                    element: Element::Edge(key.clone()),
                    name: name.clone(),
                    value: value.clone(),
                }));
            }
            OpKind::SetAttr { element, name, value } => {
                writes.push(Write { op, element: element.clone(), name: name.clone(), value: value.clone() })
            }
            _ => {}
        }
    }
    let mut live: BTreeMap<(Element, Name), Vec<&Write<'_>>> = BTreeMap::new();
    for write in &writes {
        let ended = ops.iter().any(|later| later.past.contains(&write.op.id) && supersedes(&later.kind, write));
        if !ended {
            live.entry((write.element.clone(), write.name.clone())).or_default().push(write);
        }
    }
    let attrs_of = |element: &Element| -> BTreeMap<Name, VisibleAttr> {
        live.range((element.clone(), Name::new(""))..)
            .take_while(|((e, _), _)| e == element)
            .map(|((_, name), writes)| {
                let mut concurrent: Vec<(Stamp, ReplicaId, Value)> =
                    writes.iter().map(|w| (w.op.stamp, w.op.replica, w.value.clone())).collect();
                concurrent.sort_by_key(|(stamp, replica, _)| (*stamp, *replica));
                let value = concurrent.last().expect("a live register has a write").2.clone();
                (name.clone(), VisibleAttr { value, concurrent })
            })
            .collect()
    };

    let mut holders: BTreeMap<&Name, (Stamp, NodeId)> = BTreeMap::new();
    for (id, (op, _, name)) in &nodes {
        let candidate = (op.stamp, *id);
        holders.entry(name).and_modify(|held| *held = (*held).min(candidate)).or_insert(candidate);
    }
    VisibleGraph {
        nodes: nodes
            .iter()
            .map(|(id, (_, node_type, name))| {
                let shown = if holders[name].1 == *id { name.to_string() } else { format!("{name}#{id}") };
                let node =
                    VisibleNode { node_type: (*node_type).clone(), name: shown, attrs: attrs_of(&Element::Node(*id)) };
                (*id, node)
            })
            .collect(),
        edges: edges.iter().map(|key| (key.clone(), attrs_of(&Element::Edge(key.clone())))).collect(),
    }
}

/// Checks that every operation's stamp is above those of the operations it saw (the hybrid logical clock's job);
/// returns the first violation.
pub fn check_stamps(ops: &[OpRecord]) -> Result<(), String> {
    let by_id: BTreeMap<OpId, &OpRecord> = ops.iter().map(|op| (op.id, op)).collect();
    for op in ops {
        for earlier in op.past.iter().filter_map(|id| by_id.get(id)) {
            if earlier.stamp >= op.stamp {
                return Err(format!("{op} does not stamp after {earlier}, which it saw"));
            }
        }
    }
    Ok(())
}

/// Whether two operations conflict: they touch the same element and at least one deletes or removes, or both
/// write the same attribute.
pub fn conflict(a: &OpKind, b: &OpKind) -> bool {
    let node_of = |kind: &OpKind| -> Vec<NodeId> {
        match kind {
            OpKind::InsertNode { id, .. } | OpKind::DeleteNode { id } => vec![*id],
            OpKind::InsertEdge { key, .. } | OpKind::DeleteEdge { key } => vec![key.from, key.to],
            OpKind::SetAttr { element, .. } | OpKind::RemoveAttr { element, .. } => match element {
                Element::Node(id) => vec![*id],
                Element::Edge(key) => vec![key.from, key.to],
            },
        }
    };
    let destructive = |kind: &OpKind| {
        matches!(kind, OpKind::DeleteNode { .. } | OpKind::DeleteEdge { .. } | OpKind::RemoveAttr { .. })
    };
    let same_attr = match (a, b) {
        (OpKind::SetAttr { element: e1, name: n1, .. }, OpKind::SetAttr { element: e2, name: n2, .. }) => {
            e1 == e2 && n1 == n2
        }
        _ => false,
    };
    let same_name = match (a, b) {
        (OpKind::InsertNode { name: n1, .. }, OpKind::InsertNode { name: n2, .. }) => n1 == n2,
        _ => false,
    };
    let shared = node_of(a).iter().any(|id| node_of(b).contains(id));
    same_attr || same_name || (shared && (destructive(a) || destructive(b)))
}
