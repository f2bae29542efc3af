//! The convergence model's check of change events: applying a step's events, in order, to the visible graph
//! before the step must give the visible graph after it.

use std::collections::BTreeMap;

use dsr::{Change, ChangeEvent, Element, Name, VisibleGraph};

/// Whether two graphs agree on what change events promise to keep a reader up to date with: the nodes with their
/// types, shown names and winning attribute values, the edges with their winning attribute values.
fn same_winners(a: &VisibleGraph, b: &VisibleGraph) -> bool {
    let same_attrs = |a: &BTreeMap<Name, dsr::VisibleAttr>, b: &BTreeMap<Name, dsr::VisibleAttr>| {
        a.len() == b.len() && a.iter().zip(b).all(|((n1, a1), (n2, a2))| n1 == n2 && a1.value == a2.value)
    };
    a.nodes.len() == b.nodes.len()
        && a.edges.len() == b.edges.len()
        && a.nodes.iter().zip(&b.nodes).all(|((i1, n1), (i2, n2))| {
            i1 == i2 && n1.node_type == n2.node_type && n1.name == n2.name && same_attrs(&n1.attrs, &n2.attrs)
        })
        && a.edges.iter().zip(&b.edges).all(|((k1, a1), (k2, a2))| k1 == k2 && same_attrs(a1, a2))
}

/// Applies `events` in order to `before`, taking the values they announce from `after`, and compares the result
/// with `after` (winners only: events report winning values).
pub(super) fn check_change_events(
    before: &VisibleGraph,
    after: &VisibleGraph,
    events: &[ChangeEvent],
) -> Result<(), String> {
    let mut graph = before.clone();
    for event in events {
        match &event.change {
            Change::NodeInserted { id } => {
                let node = after.nodes.get(id).ok_or_else(|| format!("{:?} for an invisible node", event.change))?;
                let mut node = node.clone();
                node.attrs.clear();
                graph.nodes.insert(*id, node);
            }
            Change::NodeDeleted { id } => {
                graph.nodes.remove(id);
            }
            Change::NodeRenamed { id } => {
                let now = after.nodes.get(id).ok_or_else(|| format!("{:?} for an invisible node", event.change))?;
                let node = graph.nodes.get_mut(id).ok_or_else(|| format!("{:?} before it appeared", event.change))?;
                node.name.clone_from(&now.name);
            }
            Change::EdgeInserted { key } => {
                graph.edges.insert(key.clone(), BTreeMap::new());
            }
            Change::EdgeDeleted { key } => {
                graph.edges.remove(key);
            }
            Change::AttrUpdated { element, name } => {
                let value = match element {
                    Element::Node(id) => after.nodes.get(id).and_then(|n| n.attrs.get(name)),
                    Element::Edge(key) => after.edges.get(key).and_then(|a| a.get(name)),
                };
                let value = value.ok_or_else(|| format!("{:?} for an attribute not shown", event.change))?;
                let target = match element {
                    Element::Node(id) => graph.nodes.get_mut(id).map(|n| &mut n.attrs),
                    Element::Edge(key) => graph.edges.get_mut(key),
                };
                target
                    .ok_or_else(|| format!("{:?} before its element appeared", event.change))?
                    .insert(name.clone(), value.clone());
            }
            Change::AttrRemoved { element, name } => {
                let target = match element {
                    Element::Node(id) => graph.nodes.get_mut(id).map(|n| &mut n.attrs),
                    Element::Edge(key) => graph.edges.get_mut(key),
                };
                if let Some(attrs) = target {
                    attrs.remove(name);
                }
            }
        }
    }
    if same_winners(&graph, after) {
        return Ok(());
    }
    let kinds: Vec<String> = events.iter().map(|e| format!("{:?}", e.change)).collect();
    Err(format!("events [{}] leave {graph:?}, the replica shows {after:?}", kinds.join(", ")))
}
