//! The visible graph as plain data ([`VisibleGraph`]) and its [`Digest`]: what replicas that joined the same
//! operations must agree on, whatever the order of delivery.

use std::collections::BTreeMap;

use super::Replica;
use crate::ids::{EdgeKey, Name, NodeId, ReplicaId, Stamp};
use crate::store::Attrs;
use crate::value::Value;

impl Replica {
    /// The visible graph in canonical form (what [`Replica::digest`] hashes).
    pub fn visible_graph(&self) -> VisibleGraph {
        let attrs = |attrs: &Attrs| -> BTreeMap<Name, VisibleAttr> {
            attrs
                .iter()
                .filter_map(|(name, register)| {
                    let winner = register.winner_planted(self.plant)?;
                    let mut concurrent: Vec<(Stamp, ReplicaId, Value)> =
                        register.values.iter().map(|e| (e.stamp, e.dot.replica, e.value.clone())).collect();
                    concurrent.sort_by_key(|(stamp, replica, _)| (*stamp, *replica));
                    Some((name.clone(), VisibleAttr { value: winner.value.clone(), concurrent }))
                })
                .collect()
        };
        VisibleGraph {
            nodes: self
                .nodes()
                .map(|node| {
                    let visible = VisibleNode {
                        node_type: node.core.value.node_type.clone(),
                        name: node.name().into_owned(),
                        attrs: attrs(&node.entry.attrs),
                    };
                    (node.id, visible)
                })
                .collect(),
            edges: self.edges().map(|edge| (edge.key.clone(), attrs(&edge.entry.attrs))).collect(),
        }
    }

    /// A digest of the visible graph: equal on two replicas exactly when their visible graphs are equal (up to
    /// BLAKE3 collisions). Covers every visible node, edge and attribute, including concurrent values.
    pub fn digest(&self) -> Digest {
        self.visible_graph().digest()
    }
}

/// A visible attribute: the winning value and every concurrent value with its stamp and writer.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct VisibleAttr {
    /// The winner (highest stamp, then replica id).
    pub value: Value,
    /// All concurrent values, sorted by stamp then replica.
    pub concurrent: Vec<(Stamp, ReplicaId, Value)>,
}

/// A visible node in canonical form.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct VisibleNode {
    /// Node type.
    pub node_type: Name,
    /// Visible name (`name#id` for the loser of a concurrent name conflict).
    pub name: String,
    /// Attributes.
    pub attrs: BTreeMap<Name, VisibleAttr>,
}

/// The visible graph in canonical form: sorted, with derived data only.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct VisibleGraph {
    /// Visible nodes by id.
    pub nodes: BTreeMap<NodeId, VisibleNode>,
    /// Visible edges with their attributes.
    pub edges: BTreeMap<EdgeKey, BTreeMap<Name, VisibleAttr>>,
}

/// A 256-bit digest of a visible graph.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Digest(pub [u8; 32]);

impl std::fmt::Display for Digest {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        for byte in &self.0[..8] {
            write!(f, "{byte:02x}")?;
        }
        Ok(())
    }
}

impl VisibleGraph {
    /// The BLAKE3 digest of the canonical form.
    pub fn digest(&self) -> Digest {
        let mut hasher = blake3::Hasher::new();
        let text = |hasher: &mut blake3::Hasher, text: &str| {
            hasher.update(&(text.len() as u64).to_le_bytes());
            hasher.update(text.as_bytes());
        };
        let attrs = |hasher: &mut blake3::Hasher, attrs: &BTreeMap<Name, VisibleAttr>| {
            hasher.update(&(attrs.len() as u64).to_le_bytes());
            for (name, attr) in attrs {
                text(hasher, name);
                hasher.update(&(attr.concurrent.len() as u64).to_le_bytes());
                for (stamp, replica, value) in &attr.concurrent {
                    hasher.update(&stamp.0.to_le_bytes());
                    hasher.update(&replica.0.to_le_bytes());
                    value.hash_into(hasher);
                }
                // The winner is one of the concurrent values: its place among them, not its bytes again (a camera
                // frame is hashed once, not twice). A winner outside them (no replica makes one) is hashed whole.
                match attr.concurrent.iter().position(|(_, _, value)| value.same_as(&attr.value)) {
                    Some(at) => {
                        hasher.update(&(at as u64).to_le_bytes());
                    }
                    None => {
                        hasher.update(&u64::MAX.to_le_bytes());
                        attr.value.hash_into(hasher);
                    }
                }
            }
        };
        hasher.update(&(self.nodes.len() as u64).to_le_bytes());
        for (id, node) in &self.nodes {
            hasher.update(&id.0.to_le_bytes());
            text(&mut hasher, &node.node_type);
            text(&mut hasher, &node.name);
            attrs(&mut hasher, &node.attrs);
        }
        hasher.update(&(self.edges.len() as u64).to_le_bytes());
        for (key, edge_attrs) in &self.edges {
            hasher.update(&key.from.0.to_le_bytes());
            hasher.update(&key.to.0.to_le_bytes());
            text(&mut hasher, &key.edge_type);
            attrs(&mut hasher, edge_attrs);
        }
        Digest(*hasher.finalize().as_bytes())
    }
}
