//! CORTEX JSON: reading, importing and writing the world-graph files of the C++ DSR implementation.
//!
//! CORTEX keeps its initial worlds in a JSON file
//! (`{"DSRModel":{"symbols":{"<id>":{"id","type","name","attribute":{..},"links":[..]}}}}`), and agents load and
//! save them. This module reads such a file into a [`CortexGraph`], an exact, typed picture of the file; imports
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
//!   integers in range; floats may be written as integers (`0`).
//! - A UTF-8 byte order mark at the very start is accepted and skipped (editors on some systems add one; it
//!   carries no meaning). Anything after the document is an error.
//! - Each link is listed under its `src` symbol; a symbol's key must be its id.
//! - Output is indented by four spaces like CORTEX's files, symbols in id order, keys and attributes in name
//!   order, links in (dst, label) order, so the same graph always gives the same bytes. NaN and infinities have
//!   no JSON form and make the export fail.
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
//! let error = json::parse(r#"{"DSRModel": {"symbols": {"5": {"id": 6}}}}"#).unwrap_err();
//! assert_eq!(error.to_string(), r#"DSRModel.symbols["5"]: symbol key "5" differs from its id 6"#);
//! ```

use std::collections::{BTreeMap, BTreeSet};
use std::fmt;
use std::sync::Arc;

use serde::{Serialize, Serializer};

use crate::delta::Delta;
use crate::error::{DictionaryError, OpError};
use crate::ids::{EdgeKey, NodeId};
use crate::kinematics::RT;
use crate::replica::{NewNode, Replica, valid_node_name};
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

// ---------------------------------------------------------------------------------------------------------------
// Reading: text to a generic tree that keeps duplicate keys, then the tree to a CortexGraph.

/// A parsed JSON value that keeps every key of an object, in order, so duplicates can be reported.
#[derive(Debug)]
enum Json {
    Null,
    Bool(bool),
    Unsigned(u64),
    Negative(i64),
    Float(f64),
    String(String),
    Array(Vec<Json>),
    Object(Vec<(String, Json)>),
}

impl<'de> serde::Deserialize<'de> for Json {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Json, D::Error> {
        deserializer.deserialize_any(JsonVisitor)
    }
}

struct JsonVisitor;

impl<'de> serde::de::Visitor<'de> for JsonVisitor {
    type Value = Json;

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("any json value")
    }

    fn visit_unit<E>(self) -> Result<Json, E> {
        Ok(Json::Null)
    }

    fn visit_none<E>(self) -> Result<Json, E> {
        Ok(Json::Null)
    }

    fn visit_bool<E>(self, value: bool) -> Result<Json, E> {
        Ok(Json::Bool(value))
    }

    fn visit_u64<E>(self, value: u64) -> Result<Json, E> {
        Ok(Json::Unsigned(value))
    }

    fn visit_i64<E>(self, value: i64) -> Result<Json, E> {
        Ok(u64::try_from(value).map_or(Json::Negative(value), Json::Unsigned))
    }

    fn visit_f64<E>(self, value: f64) -> Result<Json, E> {
        Ok(Json::Float(value))
    }

    fn visit_str<E>(self, value: &str) -> Result<Json, E> {
        Ok(Json::String(value.to_owned()))
    }

    fn visit_string<E>(self, value: String) -> Result<Json, E> {
        Ok(Json::String(value))
    }

    fn visit_seq<A: serde::de::SeqAccess<'de>>(self, mut seq: A) -> Result<Json, A::Error> {
        let mut items = Vec::with_capacity(seq.size_hint().unwrap_or(0).min(4096));
        while let Some(item) = seq.next_element()? {
            items.push(item);
        }
        Ok(Json::Array(items))
    }

    fn visit_map<A: serde::de::MapAccess<'de>>(self, mut map: A) -> Result<Json, A::Error> {
        let mut fields = Vec::new();
        while let Some((key, value)) = map.next_entry::<String, Json>()? {
            fields.push((key, value));
        }
        Ok(Json::Object(fields))
    }
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

/// A short description of a JSON value, for messages.
fn describe(value: &Json) -> String {
    match value {
        Json::Null => "null".into(),
        Json::Bool(value) => format!("{value}"),
        Json::Unsigned(value) => format!("the number {value}"),
        Json::Negative(value) => format!("the number {value}"),
        Json::Float(value) => format!("the number {value}"),
        Json::String(text) => format!("the string {:?}", cut(text, 32)),
        Json::Array(items) => format!("an array of {} items", items.len()),
        Json::Object(_) => "an object".into(),
    }
}

/// A path segment selecting an object key: `["key"]`.
fn key_segment(key: &str) -> String {
    format!("[{:?}]", cut(key, 64))
}

/// What is wrong with a scalar, before its place is known.
enum Problem {
    Kind(&'static str, String),
    Bad(String),
}

impl Problem {
    fn at(self, path: String) -> JsonError {
        match self {
            Problem::Kind(expected, found) => JsonError::WrongKind { path, expected, found },
            Problem::Bad(what) => JsonError::BadValue { path, what },
        }
    }
}

fn as_object<'a>(value: &'a Json, path: &str) -> Result<&'a [(String, Json)], JsonError> {
    match value {
        Json::Object(fields) => Ok(fields),
        other => Err(JsonError::WrongKind { path: path.to_owned(), expected: "an object", found: describe(other) }),
    }
}

fn as_array<'a>(value: &'a Json, path: &str) -> Result<&'a [Json], JsonError> {
    match value {
        Json::Array(items) => Ok(items),
        other => Err(JsonError::WrongKind { path: path.to_owned(), expected: "an array", found: describe(other) }),
    }
}

/// An object whose keys have been checked to be distinct.
fn unique_object<'a>(value: &'a Json, path: &str) -> Result<&'a [(String, Json)], JsonError> {
    let fields = as_object(value, path)?;
    let mut seen = BTreeSet::new();
    for (key, _) in fields {
        if !seen.insert(key.as_str()) {
            return Err(JsonError::DuplicateKey { path: path.to_owned(), key: cut(key, 64) });
        }
    }
    Ok(fields)
}

fn field<'a>(fields: &'a [(String, Json)], name: &'static str, path: &str) -> Result<&'a Json, JsonError> {
    fields
        .iter()
        .find(|(key, _)| key == name)
        .map(|(_, value)| value)
        .ok_or_else(|| JsonError::MissingField { path: path.to_owned(), field: name })
}

fn string_field<'a>(fields: &'a [(String, Json)], name: &'static str, path: &str) -> Result<&'a str, JsonError> {
    match field(fields, name, path)? {
        Json::String(text) => Ok(text),
        other => {
            Err(JsonError::WrongKind { path: format!("{path}.{name}"), expected: "a string", found: describe(other) })
        }
    }
}

/// A decimal string of digits only, as a u64.
fn decimal_u64(text: &str) -> Option<u64> {
    if text.is_empty() || !text.bytes().all(|byte| byte.is_ascii_digit()) {
        return None;
    }
    text.parse().ok()
}

fn node_id(value: &Json, path: &str) -> Result<NodeId, JsonError> {
    let id = match value {
        Json::Unsigned(id) => *id,
        Json::String(text) => decimal_u64(text).ok_or_else(|| JsonError::BadValue {
            path: path.to_owned(),
            what: format!("node id {:?} is not a decimal number from 1 to 2^64-1", cut(text, 32)),
        })?,
        Json::Negative(_) => {
            return Err(JsonError::BadValue {
                path: path.to_owned(),
                what: format!("node id {} is negative", describe(value)),
            });
        }
        other => {
            return Err(JsonError::WrongKind {
                path: path.to_owned(),
                expected: "a node id (an integer or a decimal string)",
                found: describe(other),
            });
        }
    };
    if id == 0 {
        return Err(JsonError::ZeroId { path: path.to_owned() });
    }
    Ok(NodeId(id))
}

fn number(value: &Json) -> Result<f64, Problem> {
    match value {
        Json::Unsigned(number) => Ok(*number as f64),
        Json::Negative(number) => Ok(*number as f64),
        Json::Float(number) => Ok(*number),
        other => Err(Problem::Kind("a number", describe(other))),
    }
}

fn float32(value: &Json) -> Result<f32, Problem> {
    let wide = number(value)?;
    let narrow = wide as f32;
    if wide.is_finite() && !narrow.is_finite() {
        return Err(Problem::Bad(format!("{wide} is out of the f32 range")));
    }
    Ok(narrow)
}

/// An integer of type `T` (i32, u32 or u8), named `type_name` in messages.
fn integer<T: TryFrom<u64> + TryFrom<i64>>(value: &Json, type_name: &'static str) -> Result<T, Problem> {
    let fits = match value {
        Json::Unsigned(number) => T::try_from(*number).ok(),
        Json::Negative(number) => T::try_from(*number).ok(),
        other => {
            return Err(Problem::Kind("an integer", describe(other)));
        }
    };
    fits.ok_or_else(|| Problem::Bad(format!("{} is out of the {type_name} range", describe(value))))
}

fn unsigned64(value: &Json) -> Result<u64, Problem> {
    match value {
        Json::Unsigned(number) => Ok(*number),
        Json::String(text) => decimal_u64(text)
            .ok_or_else(|| Problem::Bad(format!("{:?} is not a u64 written in decimal digits", cut(text, 32)))),
        Json::Negative(number) => Err(Problem::Bad(format!("the number {number} is out of the u64 range"))),
        other => Err(Problem::Kind("a u64 (a decimal string or an integer)", describe(other))),
    }
}

/// Each item of a JSON array converted by `item`, with the item's index in any error.
fn items<T, C: FromIterator<T>>(
    value: &Json,
    path: &str,
    item: impl Fn(&Json) -> Result<T, Problem>,
) -> Result<C, JsonError> {
    as_array(value, path)?
        .iter()
        .enumerate()
        .map(|(index, value)| item(value).map_err(|problem| problem.at(format!("{path}[{index}]"))))
        .collect()
}

fn floats<const N: usize>(value: &Json, path: &str, value_type: ValueType) -> Result<[f32; N], JsonError> {
    let floats: Vec<f32> = items(value, path, float32)?;
    <[f32; N]>::try_from(floats).map_err(|floats| JsonError::BadValue {
        path: path.to_owned(),
        what: format!("a {value_type} needs {N} numbers, found {}", floats.len()),
    })
}

/// An attribute object `{"type": code, "value": v}` as a typed value.
fn attribute(value: &Json, path: &str) -> Result<Value, JsonError> {
    let fields = unique_object(value, path)?;
    let code_path = format!("{path}.type");
    let value_type = match field(fields, "type", path)? {
        Json::Unsigned(code) => ValueType::from_code(*code)
            .ok_or_else(|| JsonError::UnknownTypeCode { path: code_path, code: code.to_string() })?,
        Json::Negative(code) => {
            return Err(JsonError::UnknownTypeCode { path: code_path, code: code.to_string() });
        }
        other => {
            return Err(JsonError::WrongKind {
                path: code_path,
                expected: "an integer type code",
                found: describe(other),
            });
        }
    };
    let raw = field(fields, "value", path)?;
    let path = format!("{path}.value");
    let scalar = |result: Result<Value, Problem>| result.map_err(|problem| problem.at(path.clone()));
    match value_type {
        ValueType::String => match raw {
            Json::String(text) => Ok(Value::String(Arc::from(text.as_str()))),
            other => scalar(Err(Problem::Kind("a string", describe(other)))),
        },
        ValueType::I32 => scalar(integer::<i32>(raw, "i32").map(Value::I32)),
        ValueType::F32 => scalar(float32(raw).map(Value::F32)),
        ValueType::VecF32 => Ok(Value::VecF32(items::<f32, Arc<[f32]>>(raw, &path, float32)?)),
        ValueType::Bool => match raw {
            Json::Bool(flag) => Ok(Value::Bool(*flag)),
            other => scalar(Err(Problem::Kind("true or false", describe(other)))),
        },
        ValueType::Bytes => {
            let bytes: Vec<u8> = items(raw, &path, |item| integer::<u8>(item, "u8"))?;
            Ok(Value::Bytes(bytes::Bytes::from(bytes)))
        }
        ValueType::U32 => scalar(integer::<u32>(raw, "u32").map(Value::U32)),
        ValueType::U64 => scalar(unsigned64(raw).map(Value::U64)),
        ValueType::F64 => scalar(number(raw).map(Value::F64)),
        ValueType::VecU64 => Ok(Value::VecU64(items::<u64, Arc<[u64]>>(raw, &path, unsigned64)?)),
        ValueType::F32x2 => Ok(Value::F32x2(floats(raw, &path, value_type)?)),
        ValueType::F32x3 => Ok(Value::F32x3(floats(raw, &path, value_type)?)),
        ValueType::F32x4 => Ok(Value::F32x4(floats(raw, &path, value_type)?)),
        ValueType::F32x6 => Ok(Value::F32x6(floats(raw, &path, value_type)?)),
    }
}

fn attributes(value: &Json, path: &str) -> Result<Attributes, JsonError> {
    let mut attrs = Attributes::new();
    for (name, attr) in unique_object(value, path)? {
        let value = attribute(attr, &format!("{path}{}", key_segment(name)))?;
        attrs.insert(name.clone(), value);
    }
    Ok(attrs)
}

impl CortexGraph {
    fn from_tree(root: &Json) -> Result<CortexGraph, JsonError> {
        let root = unique_object(root, "document")?;
        let model = unique_object(field(root, "DSRModel", "document")?, "DSRModel")?;
        let symbols = as_object(field(model, "symbols", "DSRModel")?, "DSRModel.symbols")?;
        let mut graph = CortexGraph::default();
        for (key, symbol) in symbols {
            let path = format!("DSRModel.symbols{}", key_segment(key));
            let fields = unique_object(symbol, &path)?;
            let id_path = format!("{path}.id");
            let id = node_id(field(fields, "id", &path)?, &id_path)?;
            if decimal_u64(key) != Some(id.0) {
                return Err(JsonError::KeyMismatch { path, key: cut(key, 64), id });
            }
            if graph.nodes.contains_key(&id) {
                return Err(JsonError::DuplicateId { path: id_path, id });
            }
            let node_type = string_field(fields, "type", &path)?.to_owned();
            let name = string_field(fields, "name", &path)?.to_owned();
            let attrs = attributes(field(fields, "attribute", &path)?, &format!("{path}.attribute"))?;
            let links_path = format!("{path}.links");
            for (index, link) in as_array(field(fields, "links", &path)?, &links_path)?.iter().enumerate() {
                let link_path = format!("{links_path}[{index}]");
                let link_fields = unique_object(link, &link_path)?;
                let src_path = format!("{link_path}.src");
                let src = node_id(field(link_fields, "src", &link_path)?, &src_path)?;
                if src != id {
                    return Err(JsonError::LinkSourceMismatch { path: src_path, src, symbol: id });
                }
                let dst = node_id(field(link_fields, "dst", &link_path)?, &format!("{link_path}.dst"))?;
                let label = string_field(link_fields, "label", &link_path)?;
                let link_attrs = attributes(
                    field(link_fields, "linkAttribute", &link_path)?,
                    &format!("{link_path}.linkAttribute"),
                )?;
                let key = EdgeKey::new(src, dst, label);
                if graph.edges.contains_key(&key) {
                    return Err(JsonError::DuplicateLink { path: link_path, key });
                }
                graph.edges.insert(key, link_attrs);
            }
            graph.nodes.insert(id, CortexNode { node_type, name, attrs });
        }
        Ok(graph)
    }
}

/// Reads CORTEX JSON text.
///
/// # Errors
/// [`JsonError`] naming the line and column of a syntax error, or the path of anything that does not follow the
/// format (see the module documentation).
pub fn parse(text: &str) -> Result<CortexGraph, JsonError> {
    parse_bytes(text.as_bytes())
}

/// Reads CORTEX JSON from bytes (e.g. a file's contents); a leading UTF-8 byte order mark is skipped.
///
/// # Errors
/// As [`parse`]; bytes that are not UTF-8 are a syntax error at their position.
pub fn parse_bytes(bytes: &[u8]) -> Result<CortexGraph, JsonError> {
    let bytes = bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(bytes);
    let tree: Json = serde_json::from_slice(bytes).map_err(|error| {
        let (line, column) = (error.line(), error.column());
        let full = error.to_string();
        let suffix = format!(" at line {line} column {column}");
        let what = full.strip_suffix(&suffix).unwrap_or(&full).to_owned();
        JsonError::Syntax { line, column, what }
    })?;
    CortexGraph::from_tree(&tree)
}

// ---------------------------------------------------------------------------------------------------------------
// Import.

/// What an import did.
#[derive(Clone, Debug)]
pub struct ImportReport {
    /// Nodes inserted.
    pub nodes: usize,
    /// Edges inserted.
    pub edges: usize,
    /// Attributes written (on nodes and edges).
    pub attributes: usize,
    /// The deltas produced, in order: one per node, then one per edge. An agent publishes them.
    pub deltas: Vec<Arc<Delta>>,
}

fn symbol_path(id: NodeId) -> String {
    format!("DSRModel.symbols[\"{id}\"]")
}

fn link_path(key: &EdgeKey) -> String {
    format!("DSRModel.symbols[\"{}\"].links[dst={}, label={:?}]", key.from, key.to, cut(&key.edge_type, 64))
}

impl CortexGraph {
    /// Inserts every symbol and link into `replica` with their ids, as local operations at `now_ns`.
    ///
    /// All or nothing: everything is checked first (ids already used or deleted in the replica, names taken in
    /// the file or the replica, invalid names, names and types the replica's dictionary refuses, links whose ends
    /// are neither in the file nor visible in the replica, links the replica already has); on any error the
    /// replica is unchanged. Links may end at nodes the replica already holds.
    ///
    /// # Errors
    /// [`JsonError`] naming the symbol or link at fault.
    pub fn import_into(&self, replica: &mut Replica, now_ns: u64) -> Result<ImportReport, JsonError> {
        self.validate_import(replica)?;
        // Validation passed; apply to a copy so that even an unforeseen refusal leaves the replica unchanged.
        let mut staged = replica.clone();
        let mut deltas = Vec::with_capacity(self.nodes.len() + self.edges.len());
        let mut attributes = 0;
        for (id, node) in &self.nodes {
            let (_, delta) = staged
                .insert_node(
                    now_ns,
                    NewNode {
                        id: Some(*id),
                        node_type: node.node_type.clone(),
                        name: node.name.clone(),
                        attrs: node.attrs.iter().map(|(name, value)| (name.clone(), value.clone())).collect(),
                    },
                )
                .map_err(|source| JsonError::Refused { path: symbol_path(*id), source })?;
            attributes += node.attrs.len();
            deltas.push(delta);
        }
        for (key, attrs) in &self.edges {
            let (_, delta) = staged
                .insert_edge(
                    now_ns,
                    key.from,
                    key.to,
                    &key.edge_type,
                    attrs.iter().map(|(name, value)| (name.clone(), value.clone())).collect(),
                )
                .map_err(|source| JsonError::Refused { path: link_path(key), source })?;
            attributes += attrs.len();
            deltas.push(delta);
        }
        *replica = staged;
        Ok(ImportReport { nodes: self.nodes.len(), edges: self.edges.len(), attributes, deltas })
    }

    /// Every check of [`CortexGraph::import_into`], against a copy of the replica's dictionary so that an unknown
    /// name first seen with one type and later with another is caught too.
    fn validate_import(&self, replica: &Replica) -> Result<(), JsonError> {
        let mut dictionary = replica.dictionary().clone();
        let mut names: BTreeMap<&str, NodeId> = BTreeMap::new();
        let refused = |path: String| move |source| JsonError::Dictionary { path, source };
        for (id, node) in &self.nodes {
            let path = symbol_path(*id);
            if replica.is_deleted(*id) || replica.store().nodes.contains_key(id) {
                return Err(JsonError::IdInUse { path: format!("{path}.id"), id: *id });
            }
            if !valid_node_name(&node.name) {
                return Err(JsonError::InvalidNodeName { path: format!("{path}.name"), name: cut(&node.name, 64) });
            }
            let holder = match names.insert(&node.name, *id) {
                Some(other) => Some(format!("symbol {other} of the file")),
                None => replica.node_by_name(&node.name).map(|holder| format!("node {} of the replica", holder.id())),
            };
            if let Some(holder) = holder {
                return Err(JsonError::NameTaken { path: format!("{path}.name"), name: node.name.clone(), holder });
            }
            dictionary.check_node_type(&node.node_type).map_err(refused(format!("{path}.type")))?;
            for (name, value) in &node.attrs {
                dictionary
                    .check_attr(name, value.value_type())
                    .map_err(refused(format!("{path}.attribute{}", key_segment(name))))?;
            }
        }
        for (key, attrs) in &self.edges {
            let path = link_path(key);
            for (end, id) in [("src", key.from), ("dst", key.to)] {
                if !self.nodes.contains_key(&id) && replica.node(id).is_none() {
                    return Err(JsonError::MissingEndpoint { path: format!("{path}.{end}"), id });
                }
            }
            if replica.edge(key).is_some() {
                return Err(JsonError::EdgeExists { path, key: key.clone() });
            }
            dictionary.check_edge_type(&key.edge_type).map_err(refused(format!("{path}.label")))?;
            for (name, value) in attrs {
                dictionary
                    .check_attr(name, value.value_type())
                    .map_err(refused(format!("{path}.linkAttribute{}", key_segment(name))))?;
            }
        }
        Ok(())
    }
}

// ---------------------------------------------------------------------------------------------------------------
// Export.

impl CortexGraph {
    /// The visible graph of a replica (winning attribute values; renamed nodes under their shown `name#id`).
    pub fn from_replica(replica: &Replica) -> CortexGraph {
        let copy = |(name, value): (&crate::ids::Name, &Value)| (name.to_string(), value.clone());
        CortexGraph {
            nodes: replica
                .nodes()
                .map(|node| {
                    (
                        node.id(),
                        CortexNode {
                            node_type: node.node_type().to_owned(),
                            name: node.name().into_owned(),
                            attrs: node.attrs().map(copy).collect(),
                        },
                    )
                })
                .collect(),
            edges: replica.edges().map(|edge| (edge.key().clone(), edge.attrs().map(copy).collect())).collect(),
        }
    }

    /// The graph as CORTEX JSON text: four-space indents, symbols in id order, links in (dst, label) order,
    /// attributes in name order, ids and u64 values as decimal strings, a final newline.
    ///
    /// # Errors
    /// [`JsonError::NotFinite`] for a NaN or infinite float, which JSON cannot hold.
    pub fn to_json(&self) -> Result<String, JsonError> {
        let mut symbols = Vec::with_capacity(self.nodes.len());
        for (id, node) in &self.nodes {
            let place = format!("node {id}");
            let links = self
                .edges
                .range(EdgeKey::new(*id, NodeId(0), "")..)
                .take_while(|(key, _)| key.from == *id)
                .map(|(key, attrs)| {
                    Ok(Out::Object(vec![
                        ("dst", Out::Raw(quoted(&key.to.to_string()))),
                        ("label", Out::Raw(quoted(&key.edge_type))),
                        ("linkAttribute", attributes_out(attrs, &format!("edge {key}"))?),
                        ("src", Out::Raw(quoted(&key.from.to_string()))),
                    ]))
                })
                .collect::<Result<Vec<Out>, JsonError>>()?;
            symbols.push((
                id.to_string(),
                Out::Object(vec![
                    ("attribute", attributes_out(&node.attrs, &place)?),
                    ("id", Out::Raw(quoted(&id.to_string()))),
                    ("links", Out::Array(links)),
                    ("name", Out::Raw(quoted(&node.name))),
                    ("type", Out::Raw(quoted(&node.node_type))),
                ]),
            ));
        }
        let symbols = Out::Map(symbols);
        let document = Out::Object(vec![("DSRModel", Out::Object(vec![("symbols", symbols)]))]);
        let mut text = String::new();
        document.render(0, &mut text);
        text.push('\n');
        Ok(text)
    }
}

/// Writes a replica's visible graph as CORTEX JSON (see [`CortexGraph::to_json`]).
///
/// # Errors
/// [`JsonError::NotFinite`] for a NaN or infinite float.
pub fn export(replica: &Replica) -> Result<String, JsonError> {
    CortexGraph::from_replica(replica).to_json()
}

/// A JSON document to print: scalars already rendered, objects with fixed or computed keys.
enum Out {
    Raw(String),
    Array(Vec<Out>),
    Object(Vec<(&'static str, Out)>),
    Map(Vec<(String, Out)>),
}

const INDENT: &str = "    ";

impl Out {
    fn render(&self, depth: usize, text: &mut String) {
        let newline = |text: &mut String, depth: usize| {
            text.push('\n');
            for _ in 0..depth {
                text.push_str(INDENT);
            }
        };
        match self {
            Out::Raw(raw) => text.push_str(raw),
            Out::Array(items) if items.is_empty() => text.push_str("[]"),
            Out::Array(items) => {
                text.push('[');
                for (index, item) in items.iter().enumerate() {
                    if index > 0 {
                        text.push(',');
                    }
                    newline(text, depth + 1);
                    item.render(depth + 1, text);
                }
                newline(text, depth);
                text.push(']');
            }
            Out::Object(fields) => Out::render_fields(fields.iter().map(|(k, v)| (*k, v)), depth, text),
            Out::Map(fields) => Out::render_fields(fields.iter().map(|(k, v)| (k.as_str(), v)), depth, text),
        }
    }

    fn render_fields<'a>(fields: impl ExactSizeIterator<Item = (&'a str, &'a Out)>, depth: usize, text: &mut String) {
        if fields.len() == 0 {
            text.push_str("{}");
            return;
        }
        text.push('{');
        for (index, (key, value)) in fields.enumerate() {
            if index > 0 {
                text.push(',');
            }
            text.push('\n');
            for _ in 0..=depth {
                text.push_str(INDENT);
            }
            text.push_str(&quoted(key));
            text.push_str(": ");
            value.render(depth + 1, text);
        }
        text.push('\n');
        for _ in 0..depth {
            text.push_str(INDENT);
        }
        text.push('}');
    }
}

/// A JSON string literal.
fn quoted(text: &str) -> String {
    let mut out = String::with_capacity(text.len() + 2);
    out.push('"');
    for character in text.chars() {
        match character {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            '\n' => out.push_str("\\n"),
            '\r' => out.push_str("\\r"),
            '\t' => out.push_str("\\t"),
            control if u32::from(control) < 0x20 => {
                out.push_str(&format!("\\u{:04x}", u32::from(control)));
            }
            other => out.push(other),
        }
    }
    out.push('"');
    out
}

/// The shortest text for an f32 that reads back (as f64, then `as f32`) to the same bits; `None` if not finite.
fn f32_text(value: f32) -> Option<String> {
    if !value.is_finite() {
        return None;
    }
    let short = format!("{value:?}");
    let reads_back = short.parse::<f64>().is_ok_and(|wide| (wide as f32).to_bits() == value.to_bits());
    Some(if reads_back { short } else { format!("{:?}", f64::from(value)) })
}

/// The shortest text for an f64 that reads back to the same bits; `None` if not finite.
fn f64_text(value: f64) -> Option<String> {
    value.is_finite().then(|| format!("{value:?}"))
}

fn floats_out(values: &[f32], place: &str) -> Result<Out, JsonError> {
    values
        .iter()
        .map(|value| {
            f32_text(*value)
                .map(Out::Raw)
                .ok_or_else(|| JsonError::NotFinite { place: place.to_owned(), value: format!("{value}") })
        })
        .collect::<Result<Vec<Out>, JsonError>>()
        .map(Out::Array)
}

fn value_out(value: &Value, place: &str) -> Result<Out, JsonError> {
    let not_finite = |shown: String| JsonError::NotFinite { place: place.to_owned(), value: shown };
    Ok(match value {
        Value::String(text) => Out::Raw(quoted(text)),
        Value::I32(number) => Out::Raw(number.to_string()),
        Value::F32(number) => Out::Raw(f32_text(*number).ok_or_else(|| not_finite(format!("{number}")))?),
        Value::VecF32(values) => floats_out(values, place)?,
        Value::Bool(flag) => Out::Raw(flag.to_string()),
        Value::Bytes(bytes) => Out::Array(bytes.iter().map(|byte| Out::Raw(byte.to_string())).collect()),
        Value::U32(number) => Out::Raw(number.to_string()),
        Value::U64(number) => Out::Raw(quoted(&number.to_string())),
        Value::F64(number) => Out::Raw(f64_text(*number).ok_or_else(|| not_finite(format!("{number}")))?),
        Value::VecU64(values) => {
            Out::Array(values.iter().map(|number| Out::Raw(quoted(&number.to_string()))).collect())
        }
        Value::F32x2(values) => floats_out(values, place)?,
        Value::F32x3(values) => floats_out(values, place)?,
        Value::F32x4(values) => floats_out(values, place)?,
        Value::F32x6(values) => floats_out(values, place)?,
    })
}

fn attributes_out(attrs: &Attributes, owner: &str) -> Result<Out, JsonError> {
    attrs
        .iter()
        .map(|(name, value)| {
            let place = format!("{owner} attribute {name:?}");
            Ok((
                name.clone(),
                Out::Object(vec![
                    ("type", Out::Raw(value.value_type().code().to_string())),
                    ("value", value_out(value, &place)?),
                ]),
            ))
        })
        .collect::<Result<Vec<_>, JsonError>>()
        .map(Out::Map)
}

// ---------------------------------------------------------------------------------------------------------------
// Analysis.

/// A summary of a graph's contents and RT structure, for `cortex graph info`. Node ids serialize as decimal
/// strings, like in CORTEX JSON.
#[derive(Clone, Debug, PartialEq, Eq, Serialize)]
pub struct GraphAnalysis {
    /// Number of symbols.
    pub nodes: usize,
    /// Number of links.
    pub edges: usize,
    /// Number of attributes on symbols and links.
    pub attributes: usize,
    /// Symbols by node type.
    pub node_types: BTreeMap<String, usize>,
    /// Links by label.
    pub edge_labels: BTreeMap<String, usize>,
    /// Attributes by value type, in type-code order (types that do not occur are left out).
    pub attribute_types: Vec<TypeCount>,
    /// Attributes by (name, value type), in that order.
    pub attribute_names: Vec<AttributeCount>,
    /// RT links on the longest path from an RT root (a node without an RT parent) down to a leaf; nodes on or
    /// below an RT cycle are not counted.
    pub rt_depth: usize,
    /// Symbols that have RT children but no RT parent.
    #[serde(serialize_with = "ids_as_text")]
    pub rt_roots: Vec<NodeId>,
    /// Links whose src or dst is not a symbol of the graph.
    pub dangling_links: Vec<DanglingLink>,
    /// Groups of symbols that reach each other along RT links (each group holds at least one cycle), each sorted.
    #[serde(serialize_with = "id_groups_as_text")]
    pub rt_cycles: Vec<Vec<NodeId>>,
    /// Symbols with more than one RT parent.
    pub several_rt_parents: Vec<SeveralParents>,
}

/// How many attributes have one value type.
#[derive(Clone, Debug, PartialEq, Eq, Serialize)]
pub struct TypeCount {
    /// The value type, e.g. `f32`.
    #[serde(serialize_with = "type_as_text")]
    pub value_type: ValueType,
    /// Its CORTEX type code.
    pub code: u8,
    /// Attributes of this type.
    pub count: usize,
}

/// How often an attribute name occurs with one value type.
#[derive(Clone, Debug, PartialEq, Eq, Serialize)]
pub struct AttributeCount {
    /// The attribute name.
    pub name: String,
    /// Its value type.
    #[serde(serialize_with = "type_as_text")]
    pub value_type: ValueType,
    /// Occurrences on symbols.
    pub on_nodes: usize,
    /// Occurrences on links.
    pub on_edges: usize,
}

/// A link with an end that is not a symbol.
#[derive(Clone, Debug, PartialEq, Eq, Serialize)]
pub struct DanglingLink {
    /// Source.
    #[serde(serialize_with = "id_as_text")]
    pub src: NodeId,
    /// Destination.
    #[serde(serialize_with = "id_as_text")]
    pub dst: NodeId,
    /// Label.
    pub label: String,
    /// Which ends are missing: `src`, `dst` or both.
    pub missing: Vec<&'static str>,
}

/// A symbol with several RT parents.
#[derive(Clone, Debug, PartialEq, Eq, Serialize)]
pub struct SeveralParents {
    /// The symbol.
    #[serde(serialize_with = "id_as_text")]
    pub node: NodeId,
    /// Its RT parents, in id order.
    #[serde(serialize_with = "ids_as_text")]
    pub parents: Vec<NodeId>,
}

fn id_as_text<S: Serializer>(id: &NodeId, serializer: S) -> Result<S::Ok, S::Error> {
    serializer.collect_str(id)
}

fn ids_as_text<S: Serializer>(ids: &[NodeId], serializer: S) -> Result<S::Ok, S::Error> {
    serializer.collect_seq(ids.iter().map(NodeId::to_string))
}

fn id_groups_as_text<S: Serializer>(groups: &[Vec<NodeId>], serializer: S) -> Result<S::Ok, S::Error> {
    serializer.collect_seq(groups.iter().map(|group| group.iter().map(NodeId::to_string).collect::<Vec<_>>()))
}

fn type_as_text<S: Serializer>(value_type: &ValueType, serializer: S) -> Result<S::Ok, S::Error> {
    serializer.serialize_str(value_type.name())
}

impl CortexGraph {
    /// RT links between two symbols of the graph, as parent → children lists (children in id order).
    fn rt_children(&self) -> BTreeMap<NodeId, Vec<NodeId>> {
        let mut children: BTreeMap<NodeId, Vec<NodeId>> = BTreeMap::new();
        for key in self.edges.keys() {
            if &*key.edge_type == RT && self.nodes.contains_key(&key.from) && self.nodes.contains_key(&key.to) {
                children.entry(key.from).or_default().push(key.to);
            }
        }
        children
    }

    /// Counts and RT structure of the graph. Runs in time linear in the graph's size, cycles included.
    pub fn analyze(&self) -> GraphAnalysis {
        let mut node_types: BTreeMap<String, usize> = BTreeMap::new();
        let mut edge_labels: BTreeMap<String, usize> = BTreeMap::new();
        let mut by_name: BTreeMap<(String, ValueType), (usize, usize)> = BTreeMap::new();
        for node in self.nodes.values() {
            *node_types.entry(node.node_type.clone()).or_default() += 1;
            for (name, value) in &node.attrs {
                by_name.entry((name.clone(), value.value_type())).or_default().0 += 1;
            }
        }
        let mut dangling_links = Vec::new();
        for (key, attrs) in &self.edges {
            *edge_labels.entry(key.edge_type.to_string()).or_default() += 1;
            for (name, value) in attrs {
                by_name.entry((name.clone(), value.value_type())).or_default().1 += 1;
            }
            let missing: Vec<&'static str> = [("src", key.from), ("dst", key.to)]
                .into_iter()
                .filter(|(_, id)| !self.nodes.contains_key(id))
                .map(|(end, _)| end)
                .collect();
            if !missing.is_empty() {
                dangling_links.push(DanglingLink {
                    src: key.from,
                    dst: key.to,
                    label: key.edge_type.to_string(),
                    missing,
                });
            }
        }
        let mut by_type: BTreeMap<ValueType, usize> = BTreeMap::new();
        for ((_, value_type), (on_nodes, on_edges)) in &by_name {
            *by_type.entry(*value_type).or_default() += on_nodes + on_edges;
        }
        let children = self.rt_children();
        let mut parents: BTreeMap<NodeId, Vec<NodeId>> = BTreeMap::new();
        for (parent, kids) in &children {
            for kid in kids {
                parents.entry(*kid).or_default().push(*parent);
            }
        }
        let rt_roots = children.keys().filter(|id| !parents.contains_key(id)).copied().collect();
        GraphAnalysis {
            nodes: self.nodes.len(),
            edges: self.edges.len(),
            attributes: by_type.values().sum(),
            node_types,
            edge_labels,
            attribute_types: by_type
                .into_iter()
                .map(|(value_type, count)| TypeCount { value_type, code: value_type.code(), count })
                .collect(),
            attribute_names: by_name
                .into_iter()
                .map(|((name, value_type), (on_nodes, on_edges))| AttributeCount {
                    name,
                    value_type,
                    on_nodes,
                    on_edges,
                })
                .collect(),
            rt_depth: self.rt_depth(&children, &parents),
            rt_roots,
            dangling_links,
            rt_cycles: rt_cycles(&children),
            several_rt_parents: parents
                .into_iter()
                .filter(|(_, parents)| parents.len() > 1)
                .map(|(node, parents)| SeveralParents { node, parents })
                .collect(),
        }
    }

    /// The longest root-to-leaf RT path, in links, by visiting nodes in topological order (Kahn's algorithm):
    /// nodes on or below a cycle are never reached, so a cycle cannot make it loop.
    fn rt_depth(&self, children: &BTreeMap<NodeId, Vec<NodeId>>, parents: &BTreeMap<NodeId, Vec<NodeId>>) -> usize {
        let mut waiting: BTreeMap<NodeId, usize> =
            parents.iter().map(|(node, parents)| (*node, parents.len())).collect();
        let mut depth: BTreeMap<NodeId, usize> = BTreeMap::new();
        let mut ready: Vec<NodeId> = self.nodes.keys().filter(|id| !parents.contains_key(id)).copied().collect();
        for root in &ready {
            depth.insert(*root, 0);
        }
        let mut deepest = 0;
        while let Some(node) = ready.pop() {
            let here = depth.get(&node).copied().unwrap_or(0);
            deepest = deepest.max(here);
            for child in children.get(&node).into_iter().flatten() {
                let below = depth.entry(*child).or_insert(0);
                *below = (*below).max(here + 1);
                if let Some(count) = waiting.get_mut(child) {
                    *count -= 1;
                    if *count == 0 {
                        ready.push(*child);
                    }
                }
            }
        }
        deepest
    }
}

/// The strongly connected groups of the RT graph that contain a cycle (more than one node, or a self-link),
/// found with Kosaraju's two passes, both iterative so that no graph can overflow the stack.
fn rt_cycles(children: &BTreeMap<NodeId, Vec<NodeId>>) -> Vec<Vec<NodeId>> {
    let mut reverse: BTreeMap<NodeId, Vec<NodeId>> = BTreeMap::new();
    let mut all: BTreeSet<NodeId> = BTreeSet::new();
    for (parent, kids) in children {
        all.insert(*parent);
        for kid in kids {
            all.insert(*kid);
            reverse.entry(*kid).or_default().push(*parent);
        }
    }
    let empty: Vec<NodeId> = Vec::new();
    // Pass 1: nodes in order of finishing a depth-first search.
    let mut finished: Vec<NodeId> = Vec::with_capacity(all.len());
    let mut visited: BTreeSet<NodeId> = BTreeSet::new();
    for start in &all {
        if !visited.insert(*start) {
            continue;
        }
        let mut stack: Vec<(NodeId, usize)> = vec![(*start, 0)];
        while let Some((node, next)) = stack.last_mut() {
            let kids = children.get(node).unwrap_or(&empty);
            if let Some(kid) = kids.get(*next) {
                *next += 1;
                if visited.insert(*kid) {
                    stack.push((*kid, 0));
                }
            } else {
                finished.push(*node);
                stack.pop();
            }
        }
    }
    // Pass 2: on the reversed graph, in reverse finishing order; each search collects one group.
    let mut assigned: BTreeSet<NodeId> = BTreeSet::new();
    let mut cycles = Vec::new();
    for start in finished.iter().rev() {
        if !assigned.insert(*start) {
            continue;
        }
        let mut group = vec![*start];
        let mut stack = vec![*start];
        while let Some(node) = stack.pop() {
            for parent in reverse.get(&node).unwrap_or(&empty) {
                if assigned.insert(*parent) {
                    group.push(*parent);
                    stack.push(*parent);
                }
            }
        }
        let self_link = children.get(start).is_some_and(|kids| kids.contains(start));
        if group.len() > 1 || self_link {
            group.sort_unstable();
            cycles.push(group);
        }
    }
    cycles.sort();
    cycles
}
