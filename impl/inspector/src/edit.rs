//! Edit requests from the page (`POST /api/edit`, only with `--allow-edit`): JSON naming an operation, parsed into
//! a [`feed::Edit`](crate::feed::Edit). Attribute values arrive as the text the user typed and are parsed by the
//! attribute's type in the replica's dictionary (or the `type` the page gives for a name the dictionary lacks).
//! Every failure is a message saying what and where; nothing here panics on input.

use dsr::{EdgeKey, Element, NodeId, Value, ValueType};
use serde::Deserialize;

use crate::feed::Edit;
use crate::view::parse_element;

/// The JSON body of an edit request.
#[derive(Clone, Debug, Deserialize, PartialEq, Eq)]
#[serde(tag = "op", rename_all = "snake_case", deny_unknown_fields)]
pub enum EditRequest {
    /// Write an attribute.
    SetAttr {
        /// `n:ID` or `e:FROM:TO:TYPE`.
        element: String,
        /// Attribute name.
        name: String,
        /// The value as typed.
        value: String,
        /// The type, for names the dictionary does not know (`f32`, `vec<f32>`, ...).
        #[serde(default, rename = "type")]
        value_type: Option<String>,
    },
    /// Remove an attribute.
    RemoveAttr {
        /// The element.
        element: String,
        /// Attribute name.
        name: String,
    },
    /// Insert a node.
    InsertNode {
        /// Node type.
        node_type: String,
        /// Node name.
        name: String,
    },
    /// Delete a node.
    DeleteNode {
        /// `n:ID` or a bare id.
        id: String,
    },
    /// Insert an edge.
    InsertEdge {
        /// Source node id.
        from: String,
        /// Target node id.
        to: String,
        /// Edge type.
        edge_type: String,
    },
    /// Delete an edge.
    DeleteEdge {
        /// `e:FROM:TO:TYPE`.
        element: String,
    },
}

fn node_id(text: &str) -> Result<NodeId, String> {
    let digits = text.strip_prefix("n:").unwrap_or(text).trim();
    digits.parse::<u64>().map(NodeId).map_err(|_| format!("`{text}` is not a node id"))
}

fn value_type_named(name: &str) -> Result<ValueType, String> {
    ValueType::ALL
        .into_iter()
        .find(|t| t.name() == name)
        .ok_or_else(|| format!("unknown value type `{name}` (one of {})", ValueType::ALL.map(|t| t.name()).join(", ")))
}

fn numbers<T: std::str::FromStr>(text: &str, what: &str) -> Result<Vec<T>, String> {
    text.trim()
        .trim_start_matches('[')
        .trim_end_matches(']')
        .split([',', ' ', '\t', '\n'])
        .filter(|s| !s.is_empty())
        .map(|s| s.parse::<T>().map_err(|_| format!("`{s}` is not a {what}")))
        .collect()
}

fn fixed<const N: usize>(text: &str) -> Result<[f32; N], String> {
    let values = numbers::<f32>(text, "number")?;
    values.try_into().map_err(|v: Vec<f32>| format!("{} numbers given, {N} needed", v.len()))
}

/// Parses `text` as a value of type `value_type`.
///
/// # Errors
/// A message naming the type and the part that does not parse.
pub fn parse_value(value_type: ValueType, text: &str) -> Result<Value, String> {
    let t = text.trim();
    let scalar = |what: &str| format!("`{t}` is not a {what}");
    let value = match value_type {
        ValueType::String => Value::String(text.into()),
        ValueType::I32 => Value::I32(t.parse().map_err(|_| scalar("32-bit integer"))?),
        ValueType::U32 => Value::U32(t.parse().map_err(|_| scalar("non-negative 32-bit integer"))?),
        ValueType::U64 => Value::U64(t.parse().map_err(|_| scalar("non-negative 64-bit integer"))?),
        ValueType::F32 => Value::F32(t.parse().map_err(|_| scalar("number"))?),
        ValueType::F64 => Value::F64(t.parse().map_err(|_| scalar("number"))?),
        ValueType::Bool => Value::Bool(match t {
            "true" | "1" => true,
            "false" | "0" => false,
            _ => return Err(scalar("boolean (true or false)")),
        }),
        ValueType::VecF32 => Value::VecF32(numbers::<f32>(t, "number")?.into()),
        ValueType::VecU64 => Value::VecU64(numbers::<u64>(t, "non-negative integer")?.into()),
        ValueType::F32x2 => Value::F32x2(fixed(t)?),
        ValueType::F32x3 => Value::F32x3(fixed(t)?),
        ValueType::F32x4 => Value::F32x4(fixed(t)?),
        ValueType::F32x6 => Value::F32x6(fixed(t)?),
        ValueType::Bytes => return Err("byte buffers cannot be edited from the page".into()),
    };
    Ok(value)
}

impl EditRequest {
    /// The edit, with values parsed by the type `known_type` gives for an attribute name.
    ///
    /// # Errors
    /// A message saying which part of the request is wrong.
    pub fn into_edit(self, known_type: impl Fn(&str) -> Option<ValueType>) -> Result<Edit, String> {
        Ok(match self {
            EditRequest::SetAttr { element, name, value, value_type } => {
                let element = parse_element(&element)?;
                let ty = match (known_type(&name), value_type) {
                    (Some(known), _) => known,
                    (None, Some(given)) => value_type_named(&given)?,
                    (None, None) => {
                        return Err(format!("attribute `{name}` is not in the dictionary: give its type"));
                    }
                };
                let value = parse_value(ty, &value).map_err(|e| format!("attribute `{name}` ({ty}): {e}"))?;
                Edit::SetAttr { element, name, value }
            }
            EditRequest::RemoveAttr { element, name } => Edit::RemoveAttr { element: parse_element(&element)?, name },
            EditRequest::InsertNode { node_type, name } => Edit::InsertNode { node_type, name },
            EditRequest::DeleteNode { id } => Edit::DeleteNode { id: node_id(&id)? },
            EditRequest::InsertEdge { from, to, edge_type } => {
                Edit::InsertEdge { key: EdgeKey::new(node_id(&from)?, node_id(&to)?, &edge_type) }
            }
            EditRequest::DeleteEdge { element } => match parse_element(&element)? {
                Element::Edge(key) => Edit::DeleteEdge { key },
                Element::Node(_) => return Err(format!("`{element}` is a node, not an edge")),
            },
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn values_parse_by_type_and_errors_say_what() {
        assert_eq!(parse_value(ValueType::F32, " 1.5 "), Ok(Value::F32(1.5)));
        assert_eq!(parse_value(ValueType::VecF32, "[1, 2 3]"), Ok(Value::VecF32(vec![1.0f32, 2.0, 3.0].into())));
        assert_eq!(parse_value(ValueType::F32x3, "1,2,3"), Ok(Value::F32x3([1.0, 2.0, 3.0])));
        assert!(parse_value(ValueType::F32x3, "1,2").unwrap_err().contains("3 needed"));
        assert!(parse_value(ValueType::I32, "x").unwrap_err().contains("`x`"));
        assert!(parse_value(ValueType::Bytes, "").is_err());
    }

    #[test]
    fn requests_become_edits_or_say_what_is_wrong() {
        let request: EditRequest =
            serde_json::from_str(r#"{"op":"set_attr","element":"n:3","name":"level","value":"4"}"#).unwrap();
        let edit = request.into_edit(|n| (n == "level").then_some(ValueType::I32)).unwrap();
        assert_eq!(
            edit,
            Edit::SetAttr { element: Element::Node(NodeId(3)), name: "level".into(), value: Value::I32(4) }
        );
        let unknown: EditRequest =
            serde_json::from_str(r#"{"op":"set_attr","element":"n:3","name":"zzz","value":"4"}"#).unwrap();
        assert!(unknown.into_edit(|_| None).unwrap_err().contains("give its type"));
        let typed: EditRequest =
            serde_json::from_str(r#"{"op":"set_attr","element":"n:3","name":"zzz","value":"4","type":"u32"}"#).unwrap();
        assert!(matches!(typed.into_edit(|_| None), Ok(Edit::SetAttr { value: Value::U32(4), .. })));
        let bad_edge: EditRequest = serde_json::from_str(r#"{"op":"delete_edge","element":"n:3"}"#).unwrap();
        assert!(bad_edge.into_edit(|_| None).is_err());
        assert!(serde_json::from_str::<EditRequest>(r#"{"op":"explode"}"#).is_err());
    }
}
