//! Reading CORTEX JSON: the text to a generic tree that keeps duplicate keys, then the tree to a [`CortexGraph`].

use super::*;
use crate::value::Numbers;

/// A parsed JSON value that keeps every key of an object, in order, so duplicates can be reported.
#[derive(Clone, Debug, PartialEq)]
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

/// An attribute value of an integer type (i32, u32, or the items of a byte vector) with every fractional number
/// rounded to the nearest integer, halves away from zero, as the C++ loader's conversion does; `None` if it holds
/// no fractional number. Also returns how many numbers changed and the first of them.
fn round_fractions(raw: &Json) -> Option<(Json, usize, f64)> {
    let round = |value: &Json| match value {
        Json::Float(number) if number.round() >= 0.0 && number.round() <= u64::MAX as f64 => {
            Some((Json::Unsigned(number.round() as u64), *number))
        }
        Json::Float(number) if number.round() >= i64::MIN as f64 => {
            Some((Json::Negative(number.round() as i64), *number))
        }
        _ => None,
    };
    match raw {
        Json::Array(items) => {
            let rounded: Vec<Option<(Json, f64)>> = items.iter().map(round).collect();
            let count = rounded.iter().flatten().count();
            let first = rounded.iter().flatten().next()?.1;
            let items =
                rounded.into_iter().zip(items).map(|(new, old)| new.map_or_else(|| old.clone(), |(new, _)| new));
            Some((Json::Array(items.collect()), count, first))
        }
        scalar => round(scalar).map(|(json, original)| (json, 1, original)),
    }
}

/// A type code as a value type.
fn type_code(value: &Json, path: String) -> Result<ValueType, JsonError> {
    match value {
        Json::Unsigned(code) => {
            ValueType::from_code(*code).ok_or_else(|| JsonError::UnknownTypeCode { path, code: code.to_string() })
        }
        Json::Negative(code) => Err(JsonError::UnknownTypeCode { path, code: code.to_string() }),
        other => Err(JsonError::WrongKind { path, expected: "an integer type code", found: describe(other) }),
    }
}

/// A JSON value as a value of `value_type` (the file's type code), converted by the strict rules.
fn typed_value(value_type: ValueType, raw: &Json, path: &str) -> Result<Value, JsonError> {
    let scalar = |result: Result<Value, Problem>| result.map_err(|problem| problem.at(path.to_owned()));
    match value_type {
        ValueType::String => match raw {
            Json::String(text) => Ok(Value::String(Arc::from(text.as_str()))),
            other => scalar(Err(Problem::Kind("a string", describe(other)))),
        },
        ValueType::I32 => scalar(integer::<i32>(raw, "i32").map(Value::I32)),
        ValueType::F32 => scalar(float32(raw).map(Value::F32)),
        ValueType::VecF32 => Ok(Value::VecF32(items::<f32, Numbers<f32>>(raw, path, float32)?)),
        ValueType::Bool => match raw {
            Json::Bool(flag) => Ok(Value::Bool(*flag)),
            other => scalar(Err(Problem::Kind("true or false", describe(other)))),
        },
        ValueType::Bytes => {
            let bytes: Vec<u8> = items(raw, path, |item| integer::<u8>(item, "u8"))?;
            Ok(Value::Bytes(bytes::Bytes::from(bytes)))
        }
        ValueType::U32 => scalar(integer::<u32>(raw, "u32").map(Value::U32)),
        ValueType::U64 => scalar(unsigned64(raw).map(Value::U64)),
        ValueType::F64 => scalar(number(raw).map(Value::F64)),
        ValueType::VecU64 => Ok(Value::VecU64(items::<u64, Numbers<u64>>(raw, path, unsigned64)?)),
        ValueType::F32x2 => Ok(Value::F32x2(floats(raw, path, value_type)?)),
        ValueType::F32x3 => Ok(Value::F32x3(floats(raw, path, value_type)?)),
        ValueType::F32x4 => Ok(Value::F32x4(floats(raw, path, value_type)?)),
        ValueType::F32x6 => Ok(Value::F32x6(floats(raw, path, value_type)?)),
    }
}

/// One read: how strict it is, and what it accepted with a warning.
struct Reader {
    strictness: Strictness,
    warnings: Vec<JsonWarning>,
}

impl Reader {
    fn lenient(&self) -> bool {
        self.strictness == Strictness::Lenient
    }

    fn warn(&mut self, path: String, what: String) {
        self.warnings.push(JsonWarning { path, what });
    }

    /// An object whose keys are distinct; leniently, a key repeated with the same value is read once (with a
    /// warning), as any JSON reader that keeps one of them would; a key repeated with another value is refused,
    /// since which one a reader keeps is not defined.
    fn object<'a>(&mut self, value: &'a Json, path: &str) -> Result<&'a [(String, Json)], JsonError> {
        let fields = as_object(value, path)?;
        let mut seen: BTreeMap<&str, &Json> = BTreeMap::new();
        for (key, value) in fields {
            match seen.insert(key.as_str(), value) {
                Some(first) if self.lenient() && first == value => {
                    self.warn(
                        path.to_owned(),
                        format!("key {:?} appears twice with the same value; read once", cut(key, 64)),
                    );
                }
                Some(_) => return Err(JsonError::DuplicateKey { path: path.to_owned(), key: cut(key, 64) }),
                None => {}
            }
        }
        Ok(fields)
    }

    /// An attribute object `{"type": code, "value": v}` as a value of the file's type code.
    fn attribute(&mut self, value: &Json, path: &str) -> Result<Value, JsonError> {
        let fields = self.object(value, path)?;
        let value_type = type_code(field(fields, "type", path)?, format!("{path}.type"))?;
        let raw = field(fields, "value", path)?;
        let path = format!("{path}.value");
        let integer_code = matches!(value_type, ValueType::I32 | ValueType::U32 | ValueType::Bytes);
        if let Some((rounded, count, first)) = round_fractions(raw).filter(|_| self.lenient() && integer_code) {
            let value = typed_value(value_type, &rounded, &path)?;
            let what = match &rounded {
                Json::Unsigned(integer) => format!("the number {first} is rounded to {integer} ({value_type})"),
                Json::Negative(integer) => format!("the number {first} is rounded to {integer} ({value_type})"),
                _ => format!(
                    "{count} numbers with a fraction, the first {first}, are rounded to integers ({value_type})"
                ),
            };
            self.warn(path, what);
            return Ok(value);
        }
        typed_value(value_type, raw, &path)
    }

    fn attributes(&mut self, value: &Json, path: &str) -> Result<Attributes, JsonError> {
        let mut attrs = Attributes::new();
        for (name, attr) in self.object(value, path)? {
            let value = self.attribute(attr, &format!("{path}{}", key_segment(name)))?;
            attrs.insert(name.clone(), value);
        }
        Ok(attrs)
    }

    fn graph(&mut self, root: &Json) -> Result<CortexGraph, JsonError> {
        let root = self.object(root, "document")?;
        let model = self.object(field(root, "DSRModel", "document")?, "DSRModel")?;
        let symbols = match field(model, "symbols", "DSRModel")? {
            Json::Array(_) => return Err(JsonError::OldFormat { path: "DSRModel.symbols".into() }),
            symbols => as_object(symbols, "DSRModel.symbols")?,
        };
        let mut graph = CortexGraph::default();
        for (key, symbol) in symbols {
            let path = format!("DSRModel.symbols{}", key_segment(key));
            let fields = self.object(symbol, &path)?;
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
            let attrs = self.attributes(field(fields, "attribute", &path)?, &format!("{path}.attribute"))?;
            let links_path = format!("{path}.links");
            for (index, link) in as_array(field(fields, "links", &path)?, &links_path)?.iter().enumerate() {
                let (key, link_attrs) = self.link(link, id, &format!("{links_path}[{index}]"))?;
                if graph.edges.contains_key(&key) {
                    return Err(JsonError::DuplicateLink { path: format!("{links_path}[{index}]"), key });
                }
                graph.edges.insert(key, link_attrs);
            }
            graph.nodes.insert(id, CortexNode { node_type, name, attrs });
        }
        Ok(graph)
    }

    /// A link listed under `symbol`. Leniently, a link whose `src` is another symbol is that symbol's link, as the
    /// C++ loader reads it.
    fn link(&mut self, link: &Json, symbol: NodeId, path: &str) -> Result<(EdgeKey, Attributes), JsonError> {
        let fields = self.object(link, path)?;
        let src_path = format!("{path}.src");
        let src = node_id(field(fields, "src", path)?, &src_path)?;
        if src != symbol && !self.lenient() {
            return Err(JsonError::LinkSourceMismatch { path: src_path, src, symbol });
        }
        if src != symbol {
            self.warn(
                src_path,
                format!("the link is listed under symbol {symbol} but starts at {src}; read as {src}'s"),
            );
        }
        let dst = node_id(field(fields, "dst", path)?, &format!("{path}.dst"))?;
        let label = string_field(fields, "label", path)?;
        let attrs = self.attributes(field(fields, "linkAttribute", path)?, &format!("{path}.linkAttribute"))?;
        Ok((EdgeKey::new(src, dst, label), attrs))
    }
}

/// Reads CORTEX JSON text strictly: the exact picture of a file that needs no warning.
///
/// # Errors
/// [`JsonError`] naming the line and column of a syntax error, or the path of anything that does not follow the
/// format (see the module documentation).
pub fn parse(text: &str) -> Result<CortexGraph, JsonError> {
    parse_bytes(text.as_bytes())
}

/// Reads CORTEX JSON from bytes strictly (e.g. a file's contents); a leading UTF-8 byte order mark is skipped.
///
/// # Errors
/// As [`parse`]; bytes that are not UTF-8 are a syntax error at their position.
pub fn parse_bytes(bytes: &[u8]) -> Result<CortexGraph, JsonError> {
    read(bytes, Strictness::Strict).map(|reading| reading.graph)
}

/// Reads CORTEX JSON from bytes, leniently or strictly (see the module documentation for what each accepts).
///
/// # Errors
/// As [`parse`], for what `strictness` does not accept.
pub fn read(bytes: &[u8], strictness: Strictness) -> Result<Reading, JsonError> {
    let bytes = bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(bytes);
    let tree: Json = serde_json::from_slice(bytes).map_err(|error| {
        let (line, column) = (error.line(), error.column());
        let full = error.to_string();
        let suffix = format!(" at line {line} column {column}");
        let what = full.strip_suffix(&suffix).unwrap_or(&full).to_owned();
        JsonError::Syntax { line, column, what }
    })?;
    let mut reader = Reader { strictness, warnings: Vec::new() };
    let graph = reader.graph(&tree)?;
    Ok(Reading { graph, warnings: reader.warnings })
}
