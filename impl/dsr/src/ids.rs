//! Identifiers shared by every part of the replica: replicas, dots, node ids, edge keys and timestamps.
//!
//! A *replica id* names one life of one agent's replica; a *dot* `(replica, counter)` names one event that replica
//! produced. Node ids are `u64` like CORTEX's, and are minted from the replica id and a per-replica node counter, so
//! no id server is needed.

use std::fmt;
use std::sync::Arc;

use serde::{Deserialize, Serialize};

/// Identifies one replica: one life of one agent.
///
/// Must be non-zero (zero is reserved for "no replica") and must never be reused by a later life of the same
/// agent: a restarted agent takes a fresh replica id, so its dots and minted node ids never collide with those of
/// its previous life.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
pub struct ReplicaId(pub u32);

impl fmt::Display for ReplicaId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "r{}", self.0)
    }
}

/// One event of one replica: the `counter`-th dot it generated (counters start at 1).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
pub struct Dot {
    /// The replica that generated the event.
    pub replica: ReplicaId,
    /// Its sequence number at that replica, from 1.
    pub counter: u64,
}

impl Dot {
    /// Builds a dot.
    pub const fn new(replica: ReplicaId, counter: u64) -> Self {
        Dot { replica, counter }
    }
}

impl fmt::Display for Dot {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}:{}", self.replica, self.counter)
    }
}

/// A node id, unique across all agents. Zero is invalid (CORTEX uses `parent = 0` for "no parent").
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
pub struct NodeId(pub u64);

impl NodeId {
    /// The id minted by `replica` for its `sequence`-th node (from 1): replica id in the high 32 bits, sequence in
    /// the low 32 bits. Ids read from CORTEX JSON are kept as they are; minting skips any id already known.
    pub const fn minted(replica: ReplicaId, sequence: u32) -> Self {
        NodeId(((replica.0 as u64) << 32) | sequence as u64)
    }
}

impl fmt::Display for NodeId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.0)
    }
}

/// A hybrid-logical-clock timestamp in nanoseconds: close to physical time, but strictly greater than every
/// timestamp the replica has produced or received before (see [`crate::Replica`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
pub struct Stamp(pub u64);

/// A short interned-by-sharing name: node types, edge types and attribute names.
///
/// Cloning is a reference-count increment; comparison and hashing are by content.
#[derive(Clone, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Name(Arc<str>);

impl Name {
    /// Makes a name.
    pub fn new(name: &str) -> Self {
        Name(Arc::from(name))
    }

    /// The name as a string slice.
    pub fn as_str(&self) -> &str {
        &self.0
    }
}

impl std::borrow::Borrow<str> for Name {
    fn borrow(&self) -> &str {
        &self.0
    }
}

impl std::ops::Deref for Name {
    type Target = str;
    fn deref(&self) -> &str {
        &self.0
    }
}

impl From<&str> for Name {
    fn from(name: &str) -> Self {
        Name::new(name)
    }
}

impl fmt::Debug for Name {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        fmt::Debug::fmt(&*self.0, f)
    }
}

impl fmt::Display for Name {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl Serialize for Name {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.serialize_str(&self.0)
    }
}

impl<'de> Deserialize<'de> for Name {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        let text = <std::borrow::Cow<'de, str>>::deserialize(deserializer)?;
        Ok(Name::new(&text))
    }
}

/// The key of an edge: at most one edge exists per `(from, to, edge type)`.
#[derive(Clone, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
pub struct EdgeKey {
    /// Source node.
    pub from: NodeId,
    /// Destination node.
    pub to: NodeId,
    /// Edge type, e.g. `RT`.
    pub edge_type: Name,
}

impl EdgeKey {
    /// Builds an edge key.
    pub fn new(from: NodeId, to: NodeId, edge_type: &str) -> Self {
        EdgeKey { from, to, edge_type: Name::new(edge_type) }
    }
}

impl fmt::Display for EdgeKey {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}-[{}]->{}", self.from, self.edge_type, self.to)
    }
}

/// A graph element that carries attributes.
#[derive(Clone, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
pub enum Element {
    /// A node.
    Node(NodeId),
    /// An edge.
    Edge(EdgeKey),
}

impl fmt::Display for Element {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Element::Node(id) => write!(f, "node {id}"),
            Element::Edge(key) => write!(f, "edge {key}"),
        }
    }
}

impl From<NodeId> for Element {
    fn from(id: NodeId) -> Self {
        Element::Node(id)
    }
}

impl From<EdgeKey> for Element {
    fn from(key: EdgeKey) -> Self {
        Element::Edge(key)
    }
}

impl From<&EdgeKey> for Element {
    fn from(key: &EdgeKey) -> Self {
        Element::Edge(key.clone())
    }
}

/// The longest name accepted (node names, type names, attribute names), in bytes.
pub const MAX_NAME_LEN: usize = 255;

/// Whether `name` is acceptable as a node name: 1 to 255 bytes, no control characters, no `#`.
pub fn valid_node_name(name: &str) -> bool {
    !name.is_empty() && name.len() <= MAX_NAME_LEN && !name.contains('#') && !name.chars().any(char::is_control)
}
