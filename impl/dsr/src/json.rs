//! CORTEX JSON: reading, importing and writing the world-graph files of the C++ DSR implementation.
//!
//! CORTEX keeps its initial worlds in a JSON file
//! (`{"DSRModel":{"symbols":{"<id>":{"id","type","name","attribute":{..},"links":[..]}}}}`), and agents load and
//! save them. This module reads such a file ([`read`]) into a [`CortexGraph`], a typed picture of the file; imports
//! that picture into a [`Replica`] all at once (validating everything first, so a refused import changes nothing);
//! and writes a replica, or a `CortexGraph`, back in the same format. The CLI (`cortex graph info`) also uses the
//! analysis helpers of [`CortexGraph`] ([`CortexGraph::analyze`]).
//!
//! # Format details
//!
//! - Attribute values carry a type code: 0 string, 1 i32, 2 f32, 3 vector of f32, 4 bool, 5 vector of bytes,
//!   6 u32, 7 u64, 8 f64, 9 vector of u64, 10/11/12/13 arrays of 2/3/4/6 f32.
//! - Node ids, link ends and u64 values are read from JSON integers or decimal strings (real files use both);
//!   they are written as decimal strings, which no JSON reader rounds (ids reach 3.6e16, beyond 2^53).
//! - f32 values are read as f64 and converted with `as f32`, which is what CORTEX's writer round-trips; they are
//!   written with the shortest text that reads back to the same f32 bits. Integers (codes 1, 5, 6) must be JSON
//!   integers in range (but see the lenient rules); floats may be written as integers (`0`).
//! - A UTF-8 byte order mark at the very start is accepted and skipped (editors on some systems add one; it
//!   carries no meaning). Anything after the document is an error.
//! - Each link is listed under its `src` symbol; a symbol's key must be its id.
//! - Output is indented by four spaces like CORTEX's files, symbols in id order, keys and attributes in name
//!   order, links in (dst, label) order, so the same graph always gives the same bytes. NaN and infinities have
//!   no JSON form and make the export fail.
//!
//! # Lenient and strict
//!
//! Files of every CORTEX era are in use, and the C++ loader accepts more than the format above: the type code
//! written in the file decides how a value is read, whatever the name's registered type. Reading and importing
//! are therefore lenient by default ([`Strictness::Lenient`]) and accept, each with a [`JsonWarning`] that names
//! the place:
//!
//! - **the file's type code wins**: an attribute whose name the dictionary declares with another type (`parent`
//!   as u32 or i32 in older files, u64 today) is stored with the file's type, and the graph's dictionary accepts
//!   that type under that name from then on ([`crate::Dictionary::learned_types`]); the export writes it back
//!   with the same code and value;
//! - **names the dictionary does not know** (a user's own node types, edge types and attributes) join the graph's
//!   dictionary, so local calls may use them; a name that neither the built-in dictionary nor the graph knows is
//!   still refused by local calls;
//! - **a number with a fraction under an integer code** (1 i32, 5 bytes, 6 u32; e.g. `"height": {"type": 1,
//!   "value": 5010.7}`) is rounded to the nearest integer, halves away from zero (the C++ loader converts it
//!   through Qt's `QVariant::toInt`, which rounds too); out of range it is refused;
//! - **a key repeated with the same value** is read once; repeated with another value it is refused, since which
//!   one a reader keeps is not defined;
//! - **a link listed under a symbol other than its `src`** is read as its `src`'s link, as the C++ loader does;
//! - **a link whose end is neither a symbol of the file nor a node of the replica** is skipped on import (the
//!   replica never holds a dangling edge; the C++ loader skips it too).
//!
//! The conversions happen once: what is written back reads again without a conversion warning. Refused in both
//! modes, with the place named: syntax errors (the C++ loader silently loads an empty graph from them), the older
//! AGM format (`symbols` as an array), missing fields, node id 0, duplicate ids, names taken twice, values that do
//! not fit their type code after the rules above. [`Strictness::Strict`] refuses everything the lenient rules
//! accept; [`parse`] and [`parse_bytes`] read strictly.
//!
//! Every error names the place in the document, as a path like
//! `DSRModel.symbols["12"].attribute["pos_x"].value`, or gives the line and column of a syntax error.
//!
//! # Examples
//!
//! ```
//! use dsr::{Replica, ReplicaId, json};
//!
//! let text = r#"{"DSRModel": {"symbols": {
//!     "1": {"id": "1", "type": "world", "name": "world", "links": [
//!             {"src": "1", "dst": "2", "label": "RT", "linkAttribute": {
//!                 "rt_translation": {"type": 3, "value": [1000, 0, 0]},
//!                 "rt_rotation_euler_xyz": {"type": 3, "value": [0, 0, 0.5]}}}],
//!           "attribute": {"level": {"type": 1, "value": 0}}},
//!     "2": {"id": 2, "type": "omnirobot", "name": "robot", "links": [],
//!           "attribute": {"parent": {"type": 7, "value": "1"}, "pos_x": {"type": 2, "value": 0.1}}}}}}"#;
//! let graph = json::parse(text).unwrap();
//! assert_eq!((graph.nodes.len(), graph.edges.len()), (2, 1));
//!
//! let mut replica = Replica::new(ReplicaId(1));
//! let report = graph.import_into(&mut replica, 1_000).unwrap();
//! assert_eq!((report.nodes, report.edges, report.deltas.len()), (2, 1, 3));
//!
//! let written = json::export(&replica).unwrap();
//! assert_eq!(json::parse(&written).unwrap(), graph);
//! assert!(written.contains(r#""value": "1""#)); // u64 as a decimal string
//!
//! // A file of an older era: `parent` as a u32, a height with a fraction under the i32 code, a user's type.
//! let old = r#"{"DSRModel": {"symbols": {"5": {"id": 5, "type": "room", "name": "hall", "links": [],
//!     "attribute": {"parent": {"type": 6, "value": 1}, "height": {"type": 1, "value": 2500.4}}}}}}"#;
//! assert!(json::read(old.as_bytes(), json::Strictness::Strict).is_err());
//! let reading = json::read(old.as_bytes(), json::Strictness::Lenient).unwrap();
//! let report = reading.graph.import_into(&mut replica, 2_000).unwrap();
//! assert_eq!(reading.warnings.len() + report.warnings.len(), 3); // rounded; kept as u32; "room" learnt
//! assert_eq!(replica.node_by_name("hall").unwrap().attr("parent"), Some(&dsr::Value::U32(1)));
//!
//! let error = json::parse(r#"{"DSRModel": {"symbols": {"5": {"id": 6}}}}"#).unwrap_err();
//! assert_eq!(error.to_string(), r#"DSRModel.symbols["5"]: symbol key "5" differs from its id 6"#);
//! ```

use std::collections::{BTreeMap, BTreeSet};
use std::fmt;
use std::sync::Arc;

use serde::{Serialize, Serializer};

use crate::delta::Delta;
use crate::dictionary::Dictionary;
use crate::error::{DictionaryError, OpError};
use crate::ids::valid_node_name;
use crate::ids::{EdgeKey, NodeId};
use crate::kinematics::RT;
use crate::replica::{NewNode, Replica};
use crate::value::{Value, ValueType};

/// Attributes of a node or link, by name.
pub type Attributes = BTreeMap<String, Value>;

/// A CORTEX graph as read from JSON: every symbol and link with its typed attributes, in canonical order.
///
/// Two graphs are equal when they have the same nodes, links, attribute types and values (floats by bits), however
/// the files spelled them (ids as numbers or strings, `0` or `0.0`, key order, link order).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct CortexGraph {
    /// The symbols, by id.
    pub nodes: BTreeMap<NodeId, CortexNode>,
    /// The links, by (src, dst, label), with their attributes. A link's ends need not be symbols of the file
    /// (see [`GraphAnalysis::dangling_links`]); [`CortexGraph::import_into`] refuses such a link.
    pub edges: BTreeMap<EdgeKey, Attributes>,
}

/// One symbol (node) of a CORTEX graph.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct CortexNode {
    /// Node type, e.g. `omnirobot`.
    pub node_type: String,
    /// Node name, e.g. `robot`.
    pub name: String,
    /// Typed attributes.
    pub attrs: Attributes,
}

/// How much of the real world's variety a read ([`read`]) or an import ([`CortexGraph::import_with`]) accepts.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Strictness {
    /// What the C++ loader accepts, with a [`JsonWarning`] for everything converted, skipped or learnt (see the
    /// module documentation). The default: files of every CORTEX era are in use, and a user's own types are normal.
    #[default]
    Lenient,
    /// Only files that need no warning: everything the lenient rules accept is an error.
    Strict,
}

/// Something a lenient read or import accepted with a conversion, a skip or a new name, and where.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct JsonWarning {
    /// Where, as a path like the errors'.
    pub path: String,
    /// What was done.
    pub what: String,
}

impl fmt::Display for JsonWarning {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}: {}", self.path, self.what)
    }
}

/// A file read by [`read`]: the graph, and what was accepted with a warning.
#[derive(Clone, Debug)]
pub struct Reading {
    /// The graph.
    pub graph: CortexGraph,
    /// In document order.
    pub warnings: Vec<JsonWarning>,
}

/// What went wrong reading, importing or writing CORTEX JSON, and where.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum JsonError {
    /// The text is not JSON (or has something after the document).
    #[error("json syntax error at line {line} column {column}: {what}")]
    Syntax {
        /// Line, from 1.
        line: usize,
        /// Column, from 1.
        column: usize,
        /// What the parser found.
        what: String,
    },
    /// `symbols` as an array of symbols with `key`/`value` attribute lists: the format of CORTEX's predecessor,
    /// which the C++ loader does not read either (it loads an empty graph from such a file).
    #[error("{path}: an array of symbols is the older AGM format, not CORTEX's (symbols is an object keyed by id)")]
    OldFormat {
        /// Where the array is.
        path: String,
    },
    /// An object lacks a field the format requires.
    #[error("{path}: missing field {field:?}")]
    MissingField {
        /// Where the object is.
        path: String,
        /// The field.
        field: &'static str,
    },
    /// A JSON value of the wrong kind (e.g. a string where an object belongs).
    #[error("{path}: expected {expected}, found {found}")]
    WrongKind {
        /// Where the value is.
        path: String,
        /// What the format wants there.
        expected: &'static str,
        /// What the file has.
        found: String,
    },
    /// An attribute type code outside 0 to 13.
    #[error("{path}: unknown attribute type code {code} (codes are 0 to 13)")]
    UnknownTypeCode {
        /// Where the code is.
        path: String,
        /// The code as written.
        code: String,
    },
    /// A value that does not fit its type code: out of range, wrong length, not a decimal number.
    #[error("{path}: {what}")]
    BadValue {
        /// Where the value is.
        path: String,
        /// What is wrong with it.
        what: String,
    },
    /// An object with the same key twice.
    #[error("{path}: key {key:?} appears more than once")]
    DuplicateKey {
        /// Where the object is.
        path: String,
        /// The repeated key (cut to 64 characters).
        key: String,
    },
    /// Two symbols with the same id.
    #[error("{path}: node id {id} is used by more than one symbol")]
    DuplicateId {
        /// Where the second symbol's id is.
        path: String,
        /// The id.
        id: NodeId,
    },
    /// Node id zero, which is reserved.
    #[error("{path}: node id 0 is reserved")]
    ZeroId {
        /// Where the id is.
        path: String,
    },
    /// A symbol listed under a key that is not its id.
    #[error("{path}: symbol key {key:?} differs from its id {id}")]
    KeyMismatch {
        /// Where the symbol is.
        path: String,
        /// The key (cut to 64 characters).
        key: String,
        /// The id.
        id: NodeId,
    },
    /// A link listed under a symbol other than its source.
    #[error("{path}: link src {src} is not the symbol it is listed under ({symbol})")]
    LinkSourceMismatch {
        /// Where the link's `src` is.
        path: String,
        /// The link's source.
        src: NodeId,
        /// The symbol it is listed under.
        symbol: NodeId,
    },
    /// The same (src, dst, label) link twice.
    #[error("{path}: link {key} is listed more than once")]
    DuplicateLink {
        /// Where the second link is.
        path: String,
        /// The link.
        key: EdgeKey,
    },
    /// A link end that is neither a symbol of the file nor a node of the replica (import only).
    #[error("{path}: node {id} does not exist in the file or the replica")]
    MissingEndpoint {
        /// Where the link end is.
        path: String,
        /// The missing node.
        id: NodeId,
    },
    /// A symbol id the replica already uses or has deleted (import only).
    #[error("{path}: node id {id} is already in use in the replica or was deleted")]
    IdInUse {
        /// Where the id is.
        path: String,
        /// The id.
        id: NodeId,
    },
    /// A symbol name another symbol or a replica node already has (import only).
    #[error("{path}: node name {name:?} is already taken by {holder}")]
    NameTaken {
        /// Where the name is.
        path: String,
        /// The name.
        name: String,
        /// Who has it.
        holder: String,
    },
    /// A name the replica cannot hold (import only).
    #[error("{path}: invalid node name {name:?}: names are 1 to 255 bytes, without control characters or '#'")]
    InvalidNodeName {
        /// Where the name is.
        path: String,
        /// The name (cut to 64 characters).
        name: String,
    },
    /// A link the replica already has (import only).
    #[error("{path}: edge {key} already exists in the replica")]
    EdgeExists {
        /// Where the link is.
        path: String,
        /// The edge.
        key: EdgeKey,
    },
    /// A type or attribute name the replica's dictionary refuses (import only).
    #[error("{path}: {source}")]
    Dictionary {
        /// Where the name is.
        path: String,
        /// Why it was refused.
        source: DictionaryError,
    },
    /// The replica refused an operation that validation had passed (import only; the replica is unchanged).
    #[error("{path}: the replica refused the import: {source}")]
    Refused {
        /// Which symbol or link.
        path: String,
        /// Why.
        source: OpError,
    },
    /// A NaN or infinite float, which JSON cannot hold (export only).
    #[error("{place}: {value} cannot be written as json (only finite numbers can)")]
    NotFinite {
        /// Which attribute of which node or edge.
        place: String,
        /// The value.
        value: String,
    },
}

/// Text cut to `limit` characters, for messages.
fn cut(text: &str, limit: usize) -> String {
    if text.chars().count() <= limit {
        text.to_owned()
    } else {
        let mut short: String = text.chars().take(limit).collect();
        short.push('…');
        short
    }
}

/// A path segment selecting an object key: `["key"]`.
fn key_segment(key: &str) -> String {
    format!("[{:?}]", cut(key, 64))
}

mod analysis;
mod export;
mod import;
mod read;

pub use analysis::{AttributeCount, DanglingLink, GraphAnalysis, OutsideDictionary, SeveralParents, TypeCount};
pub use export::export;
pub use import::ImportReport;
pub use read::{parse, parse_bytes, read};
