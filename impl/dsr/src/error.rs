//! Errors of the `dsr` crate. Every message says what went wrong and where.

use crate::ids::{Dot, EdgeKey, Element, NodeId};
use crate::value::ValueType;

/// A name or type did not pass the type dictionary.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum DictionaryError {
    /// An attribute name the dictionary does not know, with unknown names not allowed.
    #[error("unknown attribute name {name:?} (value of type {found}); declare it or allow unknown names")]
    UnknownAttr {
        /// The name.
        name: String,
        /// The type it came with.
        found: ValueType,
    },
    /// A known attribute name used with another value type.
    #[error("attribute {name:?} has type {known}, not {found}")]
    AttrTypeConflict {
        /// The name.
        name: String,
        /// Its type in the dictionary.
        known: ValueType,
        /// The type it came with.
        found: ValueType,
    },
    /// A node or edge type the dictionary does not know, with unknown names not allowed.
    #[error("unknown {what} {name:?}; declare it or allow unknown names")]
    UnknownType {
        /// "node type" or "edge type".
        what: &'static str,
        /// The name (cut to 64 characters).
        name: String,
    },
    /// An empty, over-long or control-character name.
    #[error("invalid {what} {name:?}: names are 1 to 255 bytes without control characters")]
    InvalidName {
        /// What kind of name.
        what: &'static str,
        /// The name (cut to 64 characters).
        name: String,
    },
}

/// A local operation was refused; the replica is unchanged.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum OpError {
    /// The node does not exist (or is not visible).
    #[error("node {0} does not exist")]
    NoSuchNode(NodeId),
    /// The edge does not exist (or is not visible).
    #[error("edge {0} does not exist")]
    NoSuchEdge(EdgeKey),
    /// The element does not exist.
    #[error("{0} does not exist")]
    NoSuchElement(Element),
    /// The element has no such attribute.
    #[error("{element} has no attribute {name:?}")]
    NoSuchAttr {
        /// The element.
        element: Element,
        /// The attribute name.
        name: String,
    },
    /// A node with this id exists, or existed and was deleted (ids are never reused).
    #[error("node id {0} is already in use or was deleted")]
    IdTaken(NodeId),
    /// Node id zero is reserved.
    #[error("node id 0 is reserved")]
    ZeroId,
    /// A visible node already has this name.
    #[error("node name {0:?} is already taken")]
    NameTaken(String),
    /// Node names may not contain '#': it marks nodes renamed after a concurrent name conflict.
    #[error("invalid node name {0:?}: names are 1 to 255 bytes, without control characters or '#'")]
    InvalidNodeName(String),
    /// An edge already exists with this key (use the attribute operations to change it).
    #[error("edge {0} already exists")]
    EdgeExists(EdgeKey),
    /// The dictionary refused a name or type.
    #[error(transparent)]
    Dictionary(#[from] DictionaryError),
    /// This replica has minted all the node ids its id space allows.
    #[error("node id space of this replica is exhausted")]
    IdSpaceExhausted,
}

/// A received delta or snapshot was refused; the replica is unchanged.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DeltaError {
    /// The bytes are not a delta of a version this build understands.
    #[error("delta encoding: {0}")]
    Encoding(String),
    /// Unsupported format version.
    #[error("delta format version {found} is not supported (this build reads version {supported})")]
    Version {
        /// Version found.
        found: u8,
        /// Version supported.
        supported: u8,
    },
    /// Replica id zero, counter zero, or node id zero.
    #[error("invalid identifier in {place}: {what}")]
    InvalidId {
        /// Where in the delta.
        place: String,
        /// What is wrong.
        what: String,
    },
    /// A value in the store whose dot the delta's context does not hold.
    #[error("{place}: dot {dot} is in the store but not in the delta's context")]
    DotOutsideContext {
        /// Where in the delta.
        place: String,
        /// The dot.
        dot: Dot,
    },
    /// A name or type the dictionary refused.
    #[error("{place}: {source}")]
    Dictionary {
        /// Where in the delta.
        place: String,
        /// Why.
        source: DictionaryError,
    },
    /// An invalid node name.
    #[error("{place}: invalid node name {name:?}")]
    InvalidNodeName {
        /// Where in the delta.
        place: String,
        /// The name (cut to 64 characters).
        name: String,
    },
    /// A structural limit was exceeded.
    #[error("{place}: {what}")]
    Limit {
        /// Where in the delta.
        place: String,
        /// What is over the limit.
        what: String,
    },
}
