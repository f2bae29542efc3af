//! Read-only views of a visible node ([`NodeRef`]), edge ([`EdgeRef`]) and their attributes ([`Attributes`]).

use std::borrow::Cow;

use super::Replica;
use crate::dictionary::AttrKey;
use crate::ids::{EdgeKey, Name, NodeId, Stamp};
use crate::mutants::Plant;
use crate::store::{Attrs, EdgeEntry, Entry, NodeCore, NodeEntry};
use crate::value::{AttrType, Value};

/// The attribute reads of a view, written once for [`NodeRef`] and [`EdgeRef`]: each delegates to the view's
/// `attributes()` ([`Attributes`]), so that `node.attr(..)` and `edge.attr(..)` need no trait in scope.
macro_rules! attribute_accessors {
    ($a:lifetime) => {
        /// The winning value of an attribute.
        pub fn attr(&self, name: &str) -> Option<&$a Value> {
            self.attributes().attr(name)
        }

        /// The winning value of an attribute with its stamp and writer.
        pub fn attr_entry(&self, name: &str) -> Option<&$a Entry<Value>> {
            self.attributes().attr_entry(name)
        }

        /// Every concurrent value of an attribute (empty if absent).
        pub fn concurrent(&self, name: &str) -> &$a [Entry<Value>] {
            self.attributes().concurrent(name)
        }

        /// A typed attribute value (`None` if absent or of another type).
        pub fn get<T: AttrType>(&self, key: AttrKey<T>) -> Option<T> {
            self.attributes().get(key)
        }

        /// Every attribute with its winning value, in name order.
        pub fn attrs(&self) -> impl Iterator<Item = (&$a Name, &$a Value)> + $a {
            self.attributes().winners()
        }
    };
}

/// A read-only view of a visible node.
#[derive(Clone, Copy)]
pub struct NodeRef<'a> {
    pub(super) replica: &'a Replica,
    pub(super) id: NodeId,
    pub(super) entry: &'a NodeEntry,
    pub(super) core: &'a Entry<NodeCore>,
}

impl<'a> NodeRef<'a> {
    /// The node's id.
    pub fn id(&self) -> NodeId {
        self.id
    }

    /// The node's type.
    pub fn node_type(&self) -> &'a str {
        &self.core.value.node_type
    }

    /// The name the node is shown under: its inserted name, or `name#id` if another visible node inserted
    /// concurrently with the same name holds it (the earliest stamp, then the lowest id, keeps the plain name).
    pub fn name(&self) -> Cow<'a, str> {
        let name = &self.core.value.name;
        if self.holds_name() { Cow::Borrowed(name.as_str()) } else { Cow::Owned(format!("{name}#{}", self.id)) }
    }

    /// Whether the node is shown under its plain inserted name (not `name#id`).
    pub fn holds_name(&self) -> bool {
        let holders = self.replica.names.get(&self.core.value.name);
        holders.and_then(|holders| self.replica.name_holder(holders)) == Some(self.id)
    }

    /// The name as inserted.
    pub fn inserted_name(&self) -> &'a str {
        &self.core.value.name
    }

    /// The stamp of the node's insertion.
    pub fn inserted_at(&self) -> Stamp {
        self.core.stamp
    }

    /// The node's attributes.
    pub fn attributes(&self) -> Attributes<'a> {
        Attributes { attrs: &self.entry.attrs, plant: self.replica.plant }
    }

    attribute_accessors!('a);
}

impl std::fmt::Debug for NodeRef<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Node")
            .field("id", &self.id)
            .field("type", &self.node_type())
            .field("name", &self.name())
            .finish()
    }
}

/// A read-only view of a visible edge.
#[derive(Clone, Copy)]
pub struct EdgeRef<'a> {
    pub(super) replica: &'a Replica,
    pub(super) key: &'a EdgeKey,
    pub(super) entry: &'a EdgeEntry,
}

impl<'a> EdgeRef<'a> {
    /// The edge's key.
    pub fn key(&self) -> &'a EdgeKey {
        self.key
    }

    /// Source node.
    pub fn from(&self) -> NodeId {
        self.key.from
    }

    /// Destination node.
    pub fn to(&self) -> NodeId {
        self.key.to
    }

    /// Edge type.
    pub fn edge_type(&self) -> &'a str {
        &self.key.edge_type
    }

    /// The edge's attributes.
    pub fn attributes(&self) -> Attributes<'a> {
        Attributes { attrs: &self.entry.attrs, plant: self.replica.plant }
    }

    attribute_accessors!('a);
}

impl std::fmt::Debug for EdgeRef<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Edge({})", self.key)
    }
}

/// A read-only view of one element's attributes (what [`NodeRef`] and [`EdgeRef`] share).
#[derive(Clone, Copy)]
pub struct Attributes<'a> {
    pub(super) attrs: &'a Attrs,
    pub(super) plant: Plant,
}

impl<'a> Attributes<'a> {
    /// The winning value of an attribute.
    pub fn attr(&self, name: &str) -> Option<&'a Value> {
        self.attr_entry(name).map(|entry| &entry.value)
    }

    /// The winning value of an attribute with its stamp and writer.
    pub fn attr_entry(&self, name: &str) -> Option<&'a Entry<Value>> {
        self.attrs.get(name)?.winner_planted(self.plant)
    }

    /// Every concurrent value of an attribute (empty if absent).
    pub fn concurrent(&self, name: &str) -> &'a [Entry<Value>] {
        self.attrs.get(name).map_or(&[], |register| register.entries())
    }

    /// A typed attribute value (`None` if absent or of another type).
    pub fn get<T: AttrType>(&self, key: AttrKey<T>) -> Option<T> {
        self.attr(key.name()).and_then(T::from_value)
    }

    /// Every attribute with its winning value, in name order.
    pub fn winners(self) -> impl Iterator<Item = (&'a Name, &'a Value)> + 'a {
        let plant = self.plant;
        self.attrs.iter().filter_map(move |(name, register)| Some((name, &register.winner_planted(plant)?.value)))
    }

    /// Number of attributes.
    pub fn len(&self) -> usize {
        self.attrs.len()
    }

    /// Whether there is no attribute.
    pub fn is_empty(&self) -> bool {
        self.attrs.is_empty()
    }
}
