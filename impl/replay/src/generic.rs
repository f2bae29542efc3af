//! Decoding any message from the definition its log carries ([`crate::msgdef`]) into flat graph attributes, in CDR
//! or ROS 1 serialization.
//!
//! The rule, for a message of type `package/Type` (attribute names start with `Type.`):
//!
//! - a top-level `std_msgs/Header` gives the node's frame and `stamp_ns` (as for the known types), and no attribute;
//!   a `seq` field of a ROS 1 `Header` is read and ignored wherever it is;
//! - nested fields are flattened with dotted names (`RadarScan.targets.0.range`): elements of arrays of messages,
//!   strings, times and durations are unrolled with their index, the first [`Limits::unrolled`] of them;
//! - scalars: `bool` → `Bool`; 8-, 16- and 32-bit signed and 8- and 16-bit unsigned integers → `I32`; `uint32` →
//!   `U32`; `uint64` → `U64`; `int64` → `F64` (exact up to 2^53); `float32` → `F32`; `float64` → `F64`; `string` →
//!   `String` (invalid UTF-8 replaced); times (ROS 1 `time`, ROS 2 `builtin_interfaces/Time`) → `U64` ns since the
//!   epoch (0 before it); durations → `F64` ns;
//! - arrays of `uint8`, `int8`, `byte`, `char` and `bool` → `Bytes` (a view of the payload, not a copy); arrays of
//!   `uint64` → `VecU64`; other numeric arrays → `VecF32` (`float64` and 32/64-bit integers rounded to `f32`);
//! - at most [`Limits::attributes`] attributes per message; the rest are read past and counted in
//!   [`Decoded::dropped`]; nesting deeper than [`Limits::depth`] is an error.
//!
//! Every length is checked against the bytes left before anything is read, so a damaged payload or a definition that
//! does not match it gives a [`GenericError`] naming the field path and byte offset, never a panic.

use std::sync::Arc;

use bytes::Bytes;
use dsr::Value;

use crate::msgdef::{Arity, Definitions, Field, FieldType, Primitive, is_builtin_time};
use crate::ros2::{DecodeError, Encoding, Wire};

/// Bounds on what one message may produce.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Limits {
    /// Attributes per message.
    pub attributes: usize,
    /// Elements of an array of messages or strings that become attributes.
    pub unrolled: usize,
    /// Nesting depth of message types.
    pub depth: usize,
}

impl Default for Limits {
    fn default() -> Self {
        Limits { attributes: 256, unrolled: 64, depth: 16 }
    }
}

/// A message decoded from its definition.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Decoded {
    /// Attributes, in field order.
    pub values: Vec<(String, Value)>,
    /// The top-level header's frame, if the type has a header.
    pub frame_id: Option<String>,
    /// The top-level header's stamp in ns since the epoch, if the type has a header.
    pub stamp_ns: Option<u64>,
    /// Values read but not kept (over [`Limits::attributes`] or [`Limits::unrolled`]).
    pub dropped: u64,
}

/// A payload that does not decode as its definition says.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{type_name}: field `{path}` at byte {offset}: {what}")]
pub struct GenericError {
    /// The message type.
    pub type_name: String,
    /// The dotted path of the field.
    pub path: String,
    /// Byte offset in the payload.
    pub offset: usize,
    /// What is wrong.
    pub what: String,
}

/// Decodes `data` (of `encoding`) as the root type of `definitions`.
///
/// # Errors
/// [`GenericError`] if the payload is shorter than the definition needs, a length cannot fit in the bytes left, or
/// the nesting is too deep.
pub fn decode(
    definitions: &Definitions,
    encoding: Encoding,
    data: &Bytes,
    limits: Limits,
) -> Result<Decoded, GenericError> {
    let root = definitions.root();
    let prefix = root.rsplit('/').next().unwrap_or(root);
    let to_error = |error: DecodeError, path: &str| GenericError {
        type_name: root.to_owned(),
        path: path.to_owned(),
        offset: error.offset,
        what: error.what,
    };
    let wire = Wire::new("", encoding, data).map_err(|error| to_error(error, ""))?;
    let mut walker = Walker { definitions, wire, data, limits, out: Decoded::default(), silent: 0 };
    walker.message(root, prefix, 0).map_err(|(error, path)| to_error(error, &path))?;
    Ok(walker.out)
}

/// A decode error with the dotted path of the field it happened in.
type Failure = (DecodeError, String);

struct Walker<'a> {
    definitions: &'a Definitions,
    wire: Wire<'a>,
    data: &'a Bytes,
    limits: Limits,
    out: Decoded,
    /// Above zero while reading values that are not kept (array elements past the unrolled limit).
    silent: usize,
}

impl Walker<'_> {
    fn emit(&mut self, name: &str, value: Value) {
        if self.silent > 0 || self.out.values.len() >= self.limits.attributes {
            self.out.dropped += 1;
        } else {
            self.out.values.push((name.to_owned(), value));
        }
    }

    fn fail(&self, path: &str, what: String) -> Failure {
        (self.wire.error("", what), path.to_owned())
    }

    fn message(&mut self, type_name: &str, path: &str, depth: usize) -> Result<(), Failure> {
        if depth > self.limits.depth {
            return Err(self.fail(path, format!("nesting deeper than {} message types", self.limits.depth)));
        }
        if is_builtin_time(type_name) {
            let value = self.builtin_time(type_name, path)?;
            self.emit(path, value);
            return Ok(());
        }
        let definitions = self.definitions;
        let Some(fields) = definitions.fields(type_name) else {
            return Err(self.fail(path, format!("{type_name} is not defined")));
        };
        for field in fields {
            let field_path = format!("{path}.{}", field.name);
            if type_name == "std_msgs/Header" && field.name == "seq" {
                self.primitive(Primitive::Uint32, &field_path)?;
            } else if depth == 0 && field.name == "header" && field.field_type == header_type() {
                self.top_header(&field_path)?;
            } else {
                self.field(field, &field_path, depth)?;
            }
        }
        Ok(())
    }

    /// The top-level header: its stamp and frame are kept aside, not emitted.
    fn top_header(&mut self, path: &str) -> Result<(), Failure> {
        let start = self.out.values.len();
        self.message("std_msgs/Header", path, 1)?;
        let header: Vec<(String, Value)> = self.out.values.drain(start..).collect();
        for (name, value) in header {
            match (name.rsplit('.').next(), value) {
                (Some("stamp"), Value::U64(ns)) => self.out.stamp_ns = Some(ns),
                (Some("frame_id"), Value::String(frame)) => self.out.frame_id = Some(frame.to_string()),
                _ => {}
            }
        }
        Ok(())
    }

    fn field(&mut self, field: &Field, path: &str, depth: usize) -> Result<(), Failure> {
        let count = match field.arity {
            Arity::Single => return self.single(&field.field_type, path, depth),
            Arity::Fixed(n) => n,
            Arity::Sequence => {
                let min_element = match &field.field_type {
                    FieldType::Primitive(primitive) => primitive.size_bytes(),
                    FieldType::Message(_) => 1,
                };
                self.wire.length("", min_element).map_err(|error| (error, path.to_owned()))?
            }
        };
        match &field.field_type {
            FieldType::Primitive(primitive) if vector_of(*primitive).is_some() => self.vector(*primitive, count, path),
            _ => self.unrolled(&field.field_type, count, path, depth),
        }
    }

    fn single(&mut self, field_type: &FieldType, path: &str, depth: usize) -> Result<(), Failure> {
        match field_type {
            FieldType::Primitive(primitive) => {
                let value = self.primitive(*primitive, path)?;
                self.emit(path, value);
                Ok(())
            }
            FieldType::Message(type_name) => self.message(type_name, path, depth + 1),
        }
    }

    /// Elements of an array of messages, strings, times or durations, each under its index.
    fn unrolled(&mut self, field_type: &FieldType, count: usize, path: &str, depth: usize) -> Result<(), Failure> {
        for index in 0..count {
            if index >= self.limits.unrolled {
                self.silent += 1;
            }
            let outcome = self.single(field_type, &format!("{path}.{index}"), depth);
            if index >= self.limits.unrolled {
                self.silent -= 1;
            }
            outcome?;
        }
        Ok(())
    }

    /// A numeric or byte array as one vector value.
    fn vector(&mut self, primitive: Primitive, count: usize, path: &str) -> Result<(), Failure> {
        let at = |error| (error, path.to_owned());
        let size = primitive.size_bytes();
        self.wire.align(size);
        if count.saturating_mul(size) > self.wire.left() {
            let what = format!("{count} elements of {size} bytes cannot fit in the {} bytes left", self.wire.left());
            return Err(self.fail(path, what));
        }
        let value = match vector_of(primitive) {
            Some(VectorKind::Bytes) => {
                let start = self.wire.pos();
                self.wire.take("", count).map_err(at)?;
                Value::Bytes(self.data.slice(start..start + count))
            }
            Some(VectorKind::U64) => {
                let values: Result<Arc<[u64]>, _> =
                    (0..count).map(|_| self.wire.primitive::<8>("").map(u64::from_le_bytes)).collect();
                Value::VecU64(values.map_err(at)?.into())
            }
            _ => {
                let values: Result<Arc<[f32]>, Failure> =
                    (0..count).map(|_| self.number(primitive, path).map(|value| value as f32)).collect();
                Value::VecF32(values?.into())
            }
        };
        self.emit(path, value);
        Ok(())
    }

    /// A numeric primitive as `f64`.
    fn number(&mut self, primitive: Primitive, path: &str) -> Result<f64, Failure> {
        Ok(match self.primitive(primitive, path)? {
            Value::I32(value) => f64::from(value),
            Value::U32(value) => f64::from(value),
            Value::U64(value) => value as f64,
            Value::F32(value) => f64::from(value),
            Value::F64(value) => value,
            _ => 0.0,
        })
    }

    fn primitive(&mut self, primitive: Primitive, path: &str) -> Result<Value, Failure> {
        let at = |error| (error, path.to_owned());
        let wire = &mut self.wire;
        Ok(match primitive {
            Primitive::Bool => Value::Bool(wire.u8("").map_err(at)? != 0),
            Primitive::Int8 => Value::I32(i32::from(wire.u8("").map_err(at)? as i8)),
            Primitive::Uint8 => Value::I32(i32::from(wire.u8("").map_err(at)?)),
            Primitive::Int16 => Value::I32(i32::from(wire.u16("").map_err(at)? as i16)),
            Primitive::Uint16 => Value::I32(i32::from(wire.u16("").map_err(at)?)),
            Primitive::Int32 => Value::I32(wire.i32("").map_err(at)?),
            Primitive::Uint32 => Value::U32(wire.u32("").map_err(at)?),
            Primitive::Int64 => Value::F64(i64::from_le_bytes(wire.primitive::<8>("").map_err(at)?) as f64),
            Primitive::Uint64 => Value::U64(u64::from_le_bytes(wire.primitive::<8>("").map_err(at)?)),
            Primitive::Float32 => Value::F32(wire.f32("").map_err(at)?),
            Primitive::Float64 => Value::F64(wire.f64("").map_err(at)?),
            Primitive::String => Value::String(Arc::from(wire.string("").map_err(at)?.as_str())),
            Primitive::Time => {
                let (sec, nsec) = (wire.u32("").map_err(at)?, wire.u32("").map_err(at)?);
                Value::U64(u64::from(sec) * 1_000_000_000 + u64::from(nsec))
            }
            Primitive::Duration => {
                let (sec, nsec) = (wire.i32("").map_err(at)?, wire.i32("").map_err(at)?);
                Value::F64(f64::from(sec) * 1e9 + f64::from(nsec))
            }
        })
    }

    /// ROS 2 `builtin_interfaces/Time` (`int32 sec`, `uint32 nanosec`) or `Duration` (`int32 sec`, `uint32 nanosec`).
    fn builtin_time(&mut self, type_name: &str, path: &str) -> Result<Value, Failure> {
        let at = |error| (error, path.to_owned());
        let sec = self.wire.i32("").map_err(at)?;
        let nanosec = self.wire.u32("").map_err(at)?;
        let ns = i64::from(sec) * 1_000_000_000 + i64::from(nanosec);
        Ok(match type_name {
            "builtin_interfaces/Time" => Value::U64(u64::try_from(ns).unwrap_or(0)),
            _ => Value::F64(ns as f64),
        })
    }
}

fn header_type() -> FieldType {
    FieldType::Message("std_msgs/Header".to_owned())
}

/// How an array of a primitive becomes one value.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum VectorKind {
    Bytes,
    U64,
    F32,
}

fn vector_of(primitive: Primitive) -> Option<VectorKind> {
    match primitive {
        Primitive::Uint8 | Primitive::Int8 | Primitive::Bool => Some(VectorKind::Bytes),
        Primitive::Uint64 => Some(VectorKind::U64),
        Primitive::String | Primitive::Time | Primitive::Duration => None,
        _ => Some(VectorKind::F32),
    }
}

/// Whether an encoding names a definition this module can decode from (`ros1msg`, `ros2msg`).
pub fn is_msg_definition(schema_encoding: &str) -> bool {
    matches!(schema_encoding, "ros1msg" | "ros2msg")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ros1_payload_decodes_from_its_definition() {
        let text = "Header header\nuint16 id\nfloat32[] r\nstring[] names\n===\nMSG: std_msgs/Header\nuint32 seq\n\
                    time stamp\nstring frame_id\n";
        let definitions = Definitions::parse("acme/T", text).unwrap();
        let mut bytes = Vec::new();
        bytes.extend_from_slice(&7u32.to_le_bytes());
        bytes.extend_from_slice(&2u32.to_le_bytes());
        bytes.extend_from_slice(&5u32.to_le_bytes());
        bytes.extend_from_slice(&4u32.to_le_bytes());
        bytes.extend_from_slice(b"base");
        bytes.extend_from_slice(&9u16.to_le_bytes());
        bytes.extend_from_slice(&1u32.to_le_bytes());
        bytes.extend_from_slice(&1.5f32.to_le_bytes());
        bytes.extend_from_slice(&1u32.to_le_bytes());
        bytes.extend_from_slice(&1u32.to_le_bytes());
        bytes.push(b'a');
        let decoded = decode(&definitions, Encoding::Ros1, &Bytes::from(bytes), Limits::default()).unwrap();
        assert_eq!(decoded.stamp_ns, Some(2_000_000_005));
        assert_eq!(decoded.frame_id.as_deref(), Some("base"));
        let names: Vec<&str> = decoded.values.iter().map(|(name, _)| name.as_str()).collect();
        assert_eq!(names, ["T.id", "T.r", "T.names.0"]);
    }

    #[test]
    fn lengths_that_cannot_fit_are_errors_with_the_path() {
        let definitions = Definitions::parse("acme/T", "float64[] values\n").unwrap();
        let data = Bytes::from(u32::MAX.to_le_bytes().to_vec());
        let error = decode(&definitions, Encoding::Ros1, &data, Limits::default()).unwrap_err();
        assert_eq!(error.path, "T.values", "{error}");
    }
}
