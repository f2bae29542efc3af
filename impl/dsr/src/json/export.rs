//! Writing a replica or a [`CortexGraph`] as CORTEX JSON, byte-stable.

use super::*;

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
