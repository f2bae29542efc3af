//! The reference specification of the DSR graph: what the visible graph must be, computed from the set of
//! operations and their causal order alone.
//!
//! It is written from the semantics in the `dsr` crate documentation (its "Specification" section), not from the
//! replica's code: no deltas, dots, causal contexts, joins or indices, so that a bug shared by the implementation and
//! the specification is unlikely. Two relations between operations carry it:
//!
//! - *applied*: `b` is in `a`'s recorded past when `a`'s replica had joined `b`'s delta before issuing `a`. This is
//!   what the docs call "seen" for the observed-remove rules (a write supersedes, a removal or delete removes, the
//!   values and inserts its replica has seen), because the replica does not deliver causally;
//! - *happens-before* ([`CausalOrder`]): the transitive closure of *applied*, the causal order of the operations.
//!   The docs' ordering rules are stated with it: a register's winner is its causally latest value, and a shared
//!   name is held by the causally first insert; only operations concurrent in this order fall back to the documented
//!   tie-breaks, (stamp, replica id, counter) for values and (insert stamp, id) for names.
//!
//! Then:
//!
//! - a node is visible iff it was inserted and no operation deleted it (remove wins);
//! - an edge is visible iff some insert of it was not applied by a delete of it (add wins), and both endpoints are
//!   visible;
//! - a register keeps the writes that no write or removal of the same attribute (nor, for an edge, a delete or a
//!   re-insert of the edge) had applied; it shows the causally latest of them, or among concurrent latest ones the
//!   highest (stamp, replica id, counter);
//! - among visible nodes inserted with one name, the causally first insert shows the plain name, or among concurrent
//!   first ones the lowest (insert stamp, id); the others show `name#id`.
//!
//! The implementation picks the highest (stamp, replica id, counter) among all kept values and the lowest (insert
//! stamp, id) among all holders, which agrees with this only because stamps follow causality; the comparison checks
//! that too.
//!
//! Since "seen" means applied, a replica that has applied an operation without one its writer had seen may show what
//! this specification does not (an overwritten value beside its overwrite). The convergence model therefore compares
//! a replica with this specification when its applied operations are causally closed (each one's past among them),
//! and at quiescence, where all are. Happens-before cannot replace *applied* in the supersession rules: a write that
//! reached a replica only through a third replica's unrelated operation stays among the concurrent values for good
//! (the docs say so), which a happens-before reading would drop.

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

impl Write<'_> {
    /// The documented tie-break among concurrent values: the highest (stamp, replica id, counter) wins.
    fn rank(&self) -> (Stamp, ReplicaId, u64) {
        (self.op.stamp, self.op.replica, self.op.id.counter)
    }
}

/// Whether `later` ends `write` when its replica had applied it: a write or removal of the same attribute, or, for
/// an edge's attribute, a delete or a re-insert of the edge (which gives it exactly the attributes it carries).
fn supersedes(later: &OpRecord, write: &Write<'_>) -> bool {
    let ends = match &later.kind {
        OpKind::SetAttr { element, name, .. } | OpKind::RemoveAttr { element, name } => {
            *element == write.element && *name == write.name
        }
        OpKind::DeleteEdge { key } | OpKind::InsertEdge { key, .. } => write.element == Element::Edge(key.clone()),
        OpKind::InsertNode { .. } | OpKind::DeleteNode { .. } => false,
    };
    ends && later.past.contains(&write.op.id)
}

/// A visible node: the insert that made it, its type and its inserted name.
type Inserted<'a> = (&'a OpRecord, &'a Name, &'a Name);

/// The nodes the docs make visible: inserted, and deleted by no operation (remove wins, forever).
fn visible_nodes(ops: &[OpRecord]) -> BTreeMap<NodeId, Inserted<'_>> {
    let deleted: BTreeSet<NodeId> = ops
        .iter()
        .filter_map(|op| match op.kind {
            OpKind::DeleteNode { id } => Some(id),
            _ => None,
        })
        .collect();
    ops.iter()
        .filter_map(|op| match &op.kind {
            OpKind::InsertNode { id, node_type, name, .. } if !deleted.contains(id) => {
                Some((*id, (op, node_type, name)))
            }
            _ => None,
        })
        .collect()
}

/// The edges the docs make visible: some insert of it that no delete of it had applied (add wins), between two
/// visible nodes.
fn visible_edges(ops: &[OpRecord], nodes: &BTreeMap<NodeId, Inserted<'_>>) -> BTreeSet<EdgeKey> {
    let deletes_applying = |insert: &OpRecord, key: &EdgeKey| {
        ops.iter().any(|later| {
            matches!(&later.kind, OpKind::DeleteEdge { key: k } if k == key) && later.past.contains(&insert.id)
        })
    };
    ops.iter()
        .filter_map(|op| match &op.kind {
            OpKind::InsertEdge { key, .. } if !deletes_applying(op, key) => Some(key),
            _ => None,
        })
        .filter(|key| nodes.contains_key(&key.from) && nodes.contains_key(&key.to))
        .cloned()
        .collect()
}

/// Every attribute write: the initial attributes of inserts and the writes.
fn writes(ops: &[OpRecord]) -> Vec<Write<'_>> {
    let initial = |op, element: Element, attrs: &[(Name, Value)]| -> Vec<Write<'_>> {
        attrs
            .iter()
            .map(|(name, value)| Write { op, element: element.clone(), name: name.clone(), value: value.clone() })
            .collect()
    };
    ops.iter()
        .flat_map(|op| match &op.kind {
            OpKind::InsertNode { id, attrs, .. } => initial(op, Element::Node(*id), attrs),
            OpKind::InsertEdge { key, attrs } => initial(op, Element::Edge(key.clone()), attrs),
            OpKind::SetAttr { element, name, value } => {
                vec![Write { op, element: element.clone(), name: name.clone(), value: value.clone() }]
            }
            _ => Vec::new(),
        })
        .collect()
}

/// The register of one attribute as the docs describe it: the values kept (writes that no later write, removal,
/// edge delete or re-insert had applied), and the winner: the causally latest of them, or, among several concurrent
/// ones, the highest (stamp, replica id, counter).
/// `None` only for operations whose pasts form a cycle (a recorded history that no run can produce).
fn register(order: &CausalOrder<'_>, kept: &[&Write<'_>]) -> Option<VisibleAttr> {
    let latest = kept.iter().filter(|w| !kept.iter().any(|other| order.sees(other.op.id, w.op.id)));
    let winner = latest.max_by_key(|w| w.rank())?;
    let mut concurrent: Vec<(Stamp, ReplicaId, Value)> =
        kept.iter().map(|w| (w.op.stamp, w.op.replica, w.value.clone())).collect();
    concurrent.sort_by_key(|(stamp, replica, _)| (*stamp, *replica));
    Some(VisibleAttr { value: winner.value.clone(), concurrent })
}

/// The shown name of each visible node: among visible nodes inserted with one name, the first insert in causal order
/// keeps it, or, among several concurrent first inserts, the lowest (insert stamp, id); the others show `name#id`.
fn shown_names(order: &CausalOrder<'_>, nodes: &BTreeMap<NodeId, Inserted<'_>>) -> BTreeMap<NodeId, String> {
    let mut by_name: BTreeMap<&Name, Vec<(NodeId, &OpRecord)>> = BTreeMap::new();
    for (id, (op, _, name)) in nodes {
        by_name.entry(name).or_default().push((*id, op));
    }
    let mut shown = BTreeMap::new();
    for (name, inserts) in by_name {
        let first = inserts.iter().filter(|(_, op)| !inserts.iter().any(|(_, other)| order.sees(op.id, other.id)));
        let holder = first.min_by_key(|(id, op)| (op.stamp, *id)).map(|(id, _)| *id);
        for (id, _) in &inserts {
            shown.insert(*id, if Some(*id) == holder { name.to_string() } else { format!("{name}#{id}") });
        }
    }
    shown
}

/// The visible graph the specification requires after all of `ops` have been applied.
pub fn visible_graph(ops: &[OpRecord]) -> VisibleGraph {
    let order = CausalOrder::new(ops);
    let nodes = visible_nodes(ops);
    let edges = visible_edges(ops, &nodes);
    let all_writes = writes(ops);
    let mut kept: BTreeMap<(Element, Name), Vec<&Write<'_>>> = BTreeMap::new();
    for write in all_writes.iter().filter(|w| !ops.iter().any(|later| supersedes(later, w))) {
        kept.entry((write.element.clone(), write.name.clone())).or_default().push(write);
    }
    let attrs_of = |element: &Element| -> BTreeMap<Name, VisibleAttr> {
        kept.range((element.clone(), Name::new(""))..)
            .take_while(|((e, _), _)| e == element)
            .filter_map(|((_, name), writes)| Some((name.clone(), register(&order, writes)?)))
            .collect()
    };
    let mut names = shown_names(&order, &nodes);
    let node = |(id, (_, node_type, _)): (&NodeId, &Inserted<'_>)| {
        let name = names.remove(id).unwrap_or_default();
        (*id, VisibleNode { node_type: (*node_type).clone(), name, attrs: attrs_of(&Element::Node(*id)) })
    };
    VisibleGraph {
        nodes: nodes.iter().map(node).collect(),
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

#[cfg(test)]
mod tests {
    use super::*;
    use dsr::Dot;

    /// An operation of replica `replica`, counter `counter`, at `stamp`, having applied `past`.
    fn op(replica: u32, counter: u64, stamp: u64, past: &[&OpRecord], kind: OpKind) -> OpRecord {
        let id = Dot::new(ReplicaId(replica), counter);
        let past = past.iter().map(|p| p.id).collect();
        OpRecord { id, replica: ReplicaId(replica), stamp: Stamp(stamp), past, kind }
    }

    fn insert(id: u64, name: &str) -> OpKind {
        OpKind::InsertNode { id: NodeId(id), node_type: Name::new("object"), name: Name::new(name), attrs: Vec::new() }
    }

    fn set_level(id: u64, level: i32) -> OpKind {
        OpKind::SetAttr { element: Element::Node(NodeId(id)), name: Name::new("level"), value: Value::I32(level) }
    }

    fn level(graph: &VisibleGraph, id: u64) -> (Value, usize) {
        let attr = &graph.nodes[&NodeId(id)].attrs[&Name::new("level")];
        (attr.value.clone(), attr.concurrent.len())
    }

    #[test]
    fn a_write_known_only_through_a_third_replica_stays_listed_but_the_causally_latest_wins() {
        let x = op(9, 1, 1, &[], insert(1, "x"));
        let a = op(1, 1, 2, &[&x], set_level(1, 1));
        let b = op(2, 1, 3, &[&x, &a], insert(2, "y"));
        let c = op(3, 1, 4, &[&x, &b], set_level(1, 3));
        assert_eq!(level(&visible_graph(&[x, a, b, c]), 1), (Value::I32(3), 2));
    }

    #[test]
    fn a_write_its_overwriter_had_applied_is_gone() {
        let x = op(9, 1, 1, &[], insert(1, "x"));
        let a = op(1, 1, 2, &[&x], set_level(1, 1));
        let c = op(3, 1, 4, &[&x, &a], set_level(1, 3));
        assert_eq!(level(&visible_graph(&[x, a, c]), 1), (Value::I32(3), 1));
    }

    #[test]
    fn concurrent_writes_fall_back_to_the_highest_stamp_then_replica() {
        let x = op(9, 1, 1, &[], insert(1, "x"));
        let a = op(1, 1, 5, &[&x], set_level(1, 1));
        let b = op(2, 1, 5, &[&x], set_level(1, 2));
        assert_eq!(level(&visible_graph(&[x.clone(), a, b]), 1), (Value::I32(2), 2));
        let a = op(1, 1, 6, &[&x], set_level(1, 1));
        let b = op(2, 1, 5, &[&x], set_level(1, 2));
        assert_eq!(level(&visible_graph(&[x, a, b]), 1), (Value::I32(1), 2));
    }

    #[test]
    fn the_winner_follows_causality_even_where_stamps_do_not() {
        // A history no correct replica produces (the later write stamped lower): the specification still shows the
        // causally latest write, where "highest stamp" would show the overwritten one beside it.
        let x = op(9, 1, 1, &[], insert(1, "x"));
        let a = op(1, 1, 9, &[&x], set_level(1, 1));
        let via = op(3, 1, 2, &[&a], insert(5, "z"));
        let b = op(2, 1, 3, &[&x, &via], set_level(1, 2));
        assert_eq!(level(&visible_graph(&[x, a, via, b]), 1), (Value::I32(2), 2));
    }

    #[test]
    fn the_causally_first_insert_keeps_a_shared_name_and_concurrent_ones_the_lowest_stamp_and_id() {
        let first = op(1, 1, 2, &[], insert(10, "n"));
        let relay = op(2, 1, 3, &[&first], insert(20, "m"));
        let later = op(3, 1, 4, &[&relay], insert(30, "n"));
        let graph = visible_graph(&[first.clone(), relay, later]);
        assert_eq!(graph.nodes[&NodeId(10)].name, "n");
        assert_eq!(graph.nodes[&NodeId(30)].name, "n#30");
        let concurrent = op(3, 1, 2, &[], insert(5, "n"));
        let graph = visible_graph(&[first, concurrent]);
        assert_eq!((graph.nodes[&NodeId(5)].name.as_str(), graph.nodes[&NodeId(10)].name.as_str()), ("n", "n#10"));
    }

    #[test]
    fn pasts_that_form_a_cycle_give_a_graph_without_panicking() {
        let x = op(9, 1, 1, &[], insert(1, "x"));
        let mut a = op(1, 1, 2, &[&x], set_level(1, 1));
        let b = op(2, 1, 3, &[&x, &a], set_level(1, 2));
        a.past.insert(b.id);
        let graph = visible_graph(&[x, a, b]);
        assert!(graph.nodes.contains_key(&NodeId(1)));
    }
}
