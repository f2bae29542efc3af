//! Attribute values: the 14 CORTEX value types.
//!
//! Large payloads (camera images, laser scans, point clouds) live in shared buffers (`bytes::Bytes`, [`Numbers`]),
//! so a value is cloned by reference count, never by copying its contents. Decoding a value from the wire copies
//! its payload at most once, into its final buffer, and not at all when it is decoded from a shared buffer and
//! large (a byte value: `Delta::decode_shared`; a numeric vector: when aligned too, see [`Numbers`]); encoding
//! copies it once, into the output buffer.

use std::fmt;
use std::sync::Arc;

use bytes::Bytes;
use serde::{Deserialize, Serialize};

mod numbers;
pub use numbers::Numbers;

/// The type of an attribute value. The discriminants are CORTEX's JSON type codes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[repr(u8)]
pub enum ValueType {
    /// UTF-8 text (code 0).
    String = 0,
    /// `i32` (code 1).
    I32 = 1,
    /// `f32` (code 2).
    F32 = 2,
    /// A vector of `f32` (code 3).
    VecF32 = 3,
    /// `bool` (code 4).
    Bool = 4,
    /// A vector of bytes, e.g. an image (code 5).
    Bytes = 5,
    /// `u32` (code 6).
    U32 = 6,
    /// `u64` (code 7).
    U64 = 7,
    /// `f64` (code 8).
    F64 = 8,
    /// A vector of `u64` (code 9).
    VecU64 = 9,
    /// `[f32; 2]` (code 10).
    F32x2 = 10,
    /// `[f32; 3]` (code 11).
    F32x3 = 11,
    /// `[f32; 4]` (code 12).
    F32x4 = 12,
    /// `[f32; 6]` (code 13).
    F32x6 = 13,
}

impl ValueType {
    /// Every type, in code order.
    pub const ALL: [ValueType; 14] = [
        ValueType::String,
        ValueType::I32,
        ValueType::F32,
        ValueType::VecF32,
        ValueType::Bool,
        ValueType::Bytes,
        ValueType::U32,
        ValueType::U64,
        ValueType::F64,
        ValueType::VecU64,
        ValueType::F32x2,
        ValueType::F32x3,
        ValueType::F32x4,
        ValueType::F32x6,
    ];

    /// The CORTEX JSON type code.
    pub const fn code(self) -> u8 {
        self as u8
    }

    /// The type for a CORTEX JSON type code, if the code is known.
    pub fn from_code(code: u64) -> Option<ValueType> {
        ValueType::ALL.get(usize::try_from(code).ok()?).copied()
    }

    /// A short lowercase name, used in error messages.
    pub const fn name(self) -> &'static str {
        match self {
            ValueType::String => "string",
            ValueType::I32 => "i32",
            ValueType::F32 => "f32",
            ValueType::VecF32 => "vec<f32>",
            ValueType::Bool => "bool",
            ValueType::Bytes => "vec<u8>",
            ValueType::U32 => "u32",
            ValueType::U64 => "u64",
            ValueType::F64 => "f64",
            ValueType::VecU64 => "vec<u64>",
            ValueType::F32x2 => "[f32; 2]",
            ValueType::F32x3 => "[f32; 3]",
            ValueType::F32x4 => "[f32; 4]",
            ValueType::F32x6 => "[f32; 6]",
        }
    }
}

impl fmt::Display for ValueType {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// An attribute value.
///
/// Equality compares floats by their bits, so a NaN equals itself and `0.0 != -0.0`: two replicas are equal exactly
/// when they hold the same bits, which is what convergence means.
#[derive(Clone, Serialize, Deserialize)]
pub enum Value {
    /// UTF-8 text.
    String(#[serde(with = "arc_str")] Arc<str>),
    /// A 32-bit signed integer.
    I32(i32),
    /// A 32-bit float.
    F32(f32),
    /// A vector of 32-bit floats (laser distances, point coordinates, CORTEX's `rt_translation`).
    VecF32(#[serde(with = "numbers_wire")] Numbers<f32>),
    /// A boolean.
    Bool(bool),
    /// A byte vector (camera images, opaque payloads).
    Bytes(#[serde(with = "byte_buffer")] Bytes),
    /// A 32-bit unsigned integer.
    U32(u32),
    /// A 64-bit unsigned integer.
    U64(u64),
    /// A 64-bit float.
    F64(f64),
    /// A vector of 64-bit unsigned integers.
    VecU64(#[serde(with = "numbers_wire")] Numbers<u64>),
    /// Two 32-bit floats.
    F32x2([f32; 2]),
    /// Three 32-bit floats.
    F32x3([f32; 3]),
    /// Four 32-bit floats.
    F32x4([f32; 4]),
    /// Six 32-bit floats.
    F32x6([f32; 6]),
}

impl Value {
    /// The value's type.
    pub fn value_type(&self) -> ValueType {
        match self {
            Value::String(_) => ValueType::String,
            Value::I32(_) => ValueType::I32,
            Value::F32(_) => ValueType::F32,
            Value::VecF32(_) => ValueType::VecF32,
            Value::Bool(_) => ValueType::Bool,
            Value::Bytes(_) => ValueType::Bytes,
            Value::U32(_) => ValueType::U32,
            Value::U64(_) => ValueType::U64,
            Value::F64(_) => ValueType::F64,
            Value::VecU64(_) => ValueType::VecU64,
            Value::F32x2(_) => ValueType::F32x2,
            Value::F32x3(_) => ValueType::F32x3,
            Value::F32x4(_) => ValueType::F32x4,
            Value::F32x6(_) => ValueType::F32x6,
        }
    }

    /// Feeds a canonical byte form of the value (type code, then contents; floats as bits) to a hasher.
    pub(crate) fn hash_into(&self, hasher: &mut blake3::Hasher) {
        hasher.update(&[self.value_type().code()]);
        let floats = |hasher: &mut blake3::Hasher, values: &[f32]| {
            hasher.update(&(values.len() as u64).to_le_bytes());
            for value in values {
                hasher.update(&value.to_bits().to_le_bytes());
            }
        };
        match self {
            Value::String(text) => {
                hasher.update(&(text.len() as u64).to_le_bytes());
                hasher.update(text.as_bytes());
            }
            Value::I32(value) => {
                hasher.update(&value.to_le_bytes());
            }
            Value::F32(value) => {
                hasher.update(&value.to_bits().to_le_bytes());
            }
            Value::VecF32(values) => floats(hasher, values),
            Value::Bool(value) => {
                hasher.update(&[u8::from(*value)]);
            }
            Value::Bytes(bytes) => {
                hasher.update(&(bytes.len() as u64).to_le_bytes());
                hasher.update(bytes);
            }
            Value::U32(value) => {
                hasher.update(&value.to_le_bytes());
            }
            Value::U64(value) => {
                hasher.update(&value.to_le_bytes());
            }
            Value::F64(value) => {
                hasher.update(&value.to_bits().to_le_bytes());
            }
            Value::VecU64(values) => {
                hasher.update(&(values.len() as u64).to_le_bytes());
                for value in values.iter() {
                    hasher.update(&value.to_le_bytes());
                }
            }
            Value::F32x2(values) => floats(hasher, values),
            Value::F32x3(values) => floats(hasher, values),
            Value::F32x4(values) => floats(hasher, values),
            Value::F32x6(values) => floats(hasher, values),
        }
    }

    /// The payload size in bytes (contents only), for accounting.
    pub fn payload_len(&self) -> usize {
        match self {
            Value::String(text) => text.len(),
            Value::I32(_) | Value::F32(_) | Value::U32(_) => 4,
            Value::Bool(_) => 1,
            Value::U64(_) | Value::F64(_) | Value::F32x2(_) => 8,
            Value::VecF32(values) => values.len() * 4,
            Value::Bytes(bytes) => bytes.len(),
            Value::VecU64(values) => values.len() * 8,
            Value::F32x3(_) => 12,
            Value::F32x4(_) => 16,
            Value::F32x6(_) => 24,
        }
    }

    /// A value whose wire form is its variant's index and one block of bytes in memory already (a byte value; a
    /// numeric vector on a little-endian host): that index and block, exactly as the serializer writes them.
    /// [`crate::Delta::encode_pieces`] refers to such a block instead of copying it. The variants are declared in
    /// the order of their [`ValueType`] codes, so a variant's index is its code (the wire tests pin both).
    pub(crate) fn wire_block(&self) -> Option<WireBlock<'_>> {
        let (bytes, align): (&[u8], usize) = match self {
            Value::Bytes(bytes) => (bytes, 1),
            Value::VecF32(values) if cfg!(target_endian = "little") => (bytemuck::cast_slice(values), 4),
            Value::VecU64(values) if cfg!(target_endian = "little") => (bytemuck::cast_slice(values), 8),
            _ => return None,
        };
        Some(WireBlock { variant: u32::from(self.value_type() as u8), bytes, align })
    }
}

/// A value's wire form as one block of bytes ([`Value::wire_block`]).
pub(crate) struct WireBlock<'a> {
    /// The variant's index (its [`ValueType`] code).
    pub variant: u32,
    /// The bytes, exactly as the serializer writes them after their length.
    pub bytes: &'a [u8],
    /// The alignment a receiver needs to read them in place (1 for bytes, the element's size for a vector).
    pub align: usize,
}

fn f32_bits_eq(a: &[f32], b: &[f32]) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits())
}

impl Value {
    /// Whether `self` equals `other` (as `==`), answered without reading a large payload when both share one
    /// buffer (clones of one value do).
    pub fn same_as(&self, other: &Value) -> bool {
        match (self, other) {
            (Value::Bytes(a), Value::Bytes(b)) if a.as_ptr() == b.as_ptr() && a.len() == b.len() => true,
            (Value::VecF32(a), Value::VecF32(b)) if a.as_ptr() == b.as_ptr() && a.len() == b.len() => true,
            (Value::VecU64(a), Value::VecU64(b)) if a.as_ptr() == b.as_ptr() && a.len() == b.len() => true,
            _ => self == other,
        }
    }
}

impl PartialEq for Value {
    fn eq(&self, other: &Value) -> bool {
        match (self, other) {
            (Value::String(a), Value::String(b)) => a == b,
            (Value::I32(a), Value::I32(b)) => a == b,
            (Value::F32(a), Value::F32(b)) => a.to_bits() == b.to_bits(),
            (Value::VecF32(a), Value::VecF32(b)) => f32_bits_eq(a, b),
            (Value::Bool(a), Value::Bool(b)) => a == b,
            (Value::Bytes(a), Value::Bytes(b)) => a == b,
            (Value::U32(a), Value::U32(b)) => a == b,
            (Value::U64(a), Value::U64(b)) => a == b,
            (Value::F64(a), Value::F64(b)) => a.to_bits() == b.to_bits(),
            (Value::VecU64(a), Value::VecU64(b)) => a == b,
            (Value::F32x2(a), Value::F32x2(b)) => f32_bits_eq(a, b),
            (Value::F32x3(a), Value::F32x3(b)) => f32_bits_eq(a, b),
            (Value::F32x4(a), Value::F32x4(b)) => f32_bits_eq(a, b),
            (Value::F32x6(a), Value::F32x6(b)) => f32_bits_eq(a, b),
            _ => false,
        }
    }
}

impl Eq for Value {}

impl std::hash::Hash for Value {
    /// Consistent with `Eq`: floats hash by their bits.
    fn hash<H: std::hash::Hasher>(&self, state: &mut H) {
        state.write_u8(self.value_type().code());
        let floats = |state: &mut H, values: &[f32]| {
            state.write_usize(values.len());
            for value in values {
                state.write_u32(value.to_bits());
            }
        };
        match self {
            Value::String(text) => text.hash(state),
            Value::I32(value) => value.hash(state),
            Value::F32(value) => state.write_u32(value.to_bits()),
            Value::VecF32(values) => floats(state, values),
            Value::Bool(value) => value.hash(state),
            Value::Bytes(bytes) => bytes.hash(state),
            Value::U32(value) => value.hash(state),
            Value::U64(value) => value.hash(state),
            Value::F64(value) => state.write_u64(value.to_bits()),
            Value::VecU64(values) => values.hash(state),
            Value::F32x2(values) => floats(state, values),
            Value::F32x3(values) => floats(state, values),
            Value::F32x4(values) => floats(state, values),
            Value::F32x6(values) => floats(state, values),
        }
    }
}

impl fmt::Debug for Value {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        const SHOWN: usize = 8;
        fn list<T: fmt::Debug>(f: &mut fmt::Formatter<'_>, name: &str, values: &[T]) -> fmt::Result {
            if values.len() <= SHOWN {
                write!(f, "{name}({values:?})")
            } else {
                write!(f, "{name}({:?}… {} items)", &values[..SHOWN], values.len())
            }
        }
        match self {
            Value::String(text) => write!(f, "String({text:?})"),
            Value::I32(value) => write!(f, "I32({value})"),
            Value::F32(value) => write!(f, "F32({value:?})"),
            Value::VecF32(values) => list(f, "VecF32", values),
            Value::Bool(value) => write!(f, "Bool({value})"),
            Value::Bytes(bytes) => list(f, "Bytes", bytes),
            Value::U32(value) => write!(f, "U32({value})"),
            Value::U64(value) => write!(f, "U64({value})"),
            Value::F64(value) => write!(f, "F64({value:?})"),
            Value::VecU64(values) => list(f, "VecU64", values),
            Value::F32x2(values) => write!(f, "F32x2({values:?})"),
            Value::F32x3(values) => write!(f, "F32x3({values:?})"),
            Value::F32x4(values) => write!(f, "F32x4({values:?})"),
            Value::F32x6(values) => write!(f, "F32x6({values:?})"),
        }
    }
}

/// A Rust type that maps to one attribute value type; typed attribute keys ([`crate::AttrKey`]) use it so that
/// writing a value of the wrong type does not compile.
pub trait AttrType: Sized {
    /// The value type this Rust type maps to.
    const TYPE: ValueType;
    /// Wraps the value.
    fn into_value(self) -> Value;
    /// Unwraps a value of this type (cheap: shared buffers are reference-counted).
    fn from_value(value: &Value) -> Option<Self>;
}

macro_rules! attr_type {
    ($rust:ty, $variant:ident, $copy:expr) => {
        impl AttrType for $rust {
            const TYPE: ValueType = ValueType::$variant;
            fn into_value(self) -> Value {
                Value::$variant(self)
            }
            fn from_value(value: &Value) -> Option<Self> {
                match value {
                    Value::$variant(inner) => Some($copy(inner)),
                    _ => None,
                }
            }
        }
    };
}

attr_type!(Arc<str>, String, Arc::clone);
attr_type!(i32, I32, |v: &i32| *v);
attr_type!(f32, F32, |v: &f32| *v);
attr_type!(Numbers<f32>, VecF32, Numbers::clone);
attr_type!(bool, Bool, |v: &bool| *v);
attr_type!(Bytes, Bytes, Bytes::clone);
attr_type!(u32, U32, |v: &u32| *v);
attr_type!(u64, U64, |v: &u64| *v);
attr_type!(f64, F64, |v: &f64| *v);
attr_type!(Numbers<u64>, VecU64, Numbers::clone);
attr_type!([f32; 2], F32x2, |v: &[f32; 2]| *v);
attr_type!([f32; 3], F32x3, |v: &[f32; 3]| *v);
attr_type!([f32; 4], F32x4, |v: &[f32; 4]| *v);
attr_type!([f32; 6], F32x6, |v: &[f32; 6]| *v);

impl From<&str> for Value {
    fn from(text: &str) -> Self {
        Value::String(Arc::from(text))
    }
}

macro_rules! value_from {
    ($($rust:ty),*) => {$(
        impl From<$rust> for Value {
            fn from(value: $rust) -> Self {
                value.into_value()
            }
        }
    )*};
}
value_from!(i32, f32, bool, u32, u64, f64, [f32; 2], [f32; 3], [f32; 4], [f32; 6], Bytes);

impl From<Vec<f32>> for Value {
    fn from(values: Vec<f32>) -> Self {
        Value::VecF32(Numbers::from(values))
    }
}

impl From<Vec<u64>> for Value {
    fn from(values: Vec<u64>) -> Self {
        Value::VecU64(Numbers::from(values))
    }
}

/// `Arc<str>` as a plain string (the encoding of serde's own `Arc<str>`), decoded with one allocation: the text is
/// copied straight into the `Arc` instead of through an intermediate `Box<str>`.
mod arc_str {
    use super::*;

    pub fn serialize<S: serde::Serializer>(text: &Arc<str>, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.serialize_str(text)
    }

    pub fn deserialize<'de, D: serde::Deserializer<'de>>(deserializer: D) -> Result<Arc<str>, D::Error> {
        deserializer.deserialize_str(Visitor)
    }

    struct Visitor;

    impl serde::de::Visitor<'_> for Visitor {
        type Value = Arc<str>;
        fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
            f.write_str("a string")
        }
        fn visit_str<E: serde::de::Error>(self, text: &str) -> Result<Arc<str>, E> {
            Ok(Arc::from(text))
        }
    }
}

/// Encodes a `Numbers<f32>` or `Numbers<u64>` as one byte string of little-endian values, so decoding fills the
/// final buffer in one copy, or none (a view of the shared buffer being decoded, see [`Numbers`]).
mod numbers_wire {
    use super::*;

    pub fn serialize<T: WireNumber, S: serde::Serializer>(
        values: &Numbers<T>,
        serializer: S,
    ) -> Result<S::Ok, S::Error> {
        super::serialize_numbers(values, serializer)
    }

    pub fn deserialize<'de, T: WireNumber, D: serde::Deserializer<'de>>(
        deserializer: D,
    ) -> Result<Numbers<T>, D::Error> {
        deserializer.deserialize_bytes(NumbersVisitor::<T>(std::marker::PhantomData))
    }
}

/// A number type of a vector value: `f32` or `u64`, little-endian on the wire.
trait WireNumber: bytemuck::Pod {
    const NAME: &'static str;
    fn from_le(bytes: &[u8]) -> Self;
    fn put_le(self, out: &mut Vec<u8>);
}

macro_rules! wire_number {
    ($t:ty) => {
        impl WireNumber for $t {
            const NAME: &'static str = stringify!($t);
            fn from_le(bytes: &[u8]) -> Self {
                <$t>::from_le_bytes(bytes.try_into().unwrap_or_default())
            }
            fn put_le(self, out: &mut Vec<u8>) {
                out.extend_from_slice(&self.to_le_bytes());
            }
        }
    };
}

wire_number!(f32);
wire_number!(u64);

/// One byte string of little-endian values: the values' own bytes on a little-endian host, no conversion.
fn serialize_numbers<T: WireNumber, S: serde::Serializer>(values: &[T], serializer: S) -> Result<S::Ok, S::Error> {
    if cfg!(target_endian = "little") {
        return serializer.serialize_bytes(bytemuck::cast_slice(values));
    }
    let mut bytes = Vec::with_capacity(std::mem::size_of_val(values));
    for value in values {
        value.put_le(&mut bytes);
    }
    serializer.serialize_bytes(&bytes)
}

struct NumbersVisitor<T>(std::marker::PhantomData<T>);

impl<T: WireNumber> NumbersVisitor<T> {
    fn copied<E: serde::de::Error>(bytes: &[u8]) -> Result<Numbers<T>, E> {
        let size = std::mem::size_of::<T>();
        if !bytes.len().is_multiple_of(size) {
            return Err(E::custom(format!("{} vector of {} bytes is not a multiple of {size}", T::NAME, bytes.len())));
        }
        Ok(bytes.chunks_exact(size).map(T::from_le).collect())
    }
}

impl<'de, T: WireNumber> serde::de::Visitor<'de> for NumbersVisitor<T> {
    type Value = Numbers<T>;
    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "a byte string of little-endian {} values", T::NAME)
    }
    fn visit_borrowed_bytes<E: serde::de::Error>(self, bytes: &'de [u8]) -> Result<Numbers<T>, E> {
        let view = SOURCE.with_borrow(|source| {
            let source = source.as_ref()?;
            shared_slice(source, bytes, VECTOR_SHARE_FRACTION).and_then(Numbers::view)
        });
        view.map_or_else(|| Self::copied(bytes), Ok)
    }
    fn visit_bytes<E: serde::de::Error>(self, bytes: &[u8]) -> Result<Numbers<T>, E> {
        Self::copied(bytes)
    }
}

std::thread_local! {
    /// The shared buffer being decoded on this thread, if the decoder was given one ([`decoding_from`]).
    static SOURCE: std::cell::RefCell<Option<Bytes>> = const { std::cell::RefCell::new(None) };
}

/// A byte value decoded from `source` is kept as a slice of it when it is at least this big and at least
/// `1/SHARE_FRACTION` of the buffer: a frame in a one-operation delta is shared, while the values of a large
/// snapshot are copied, so that one small value kept for long never holds a whole snapshot's buffer alive.
pub(crate) const SHARE_MIN_BYTES: usize = 4096;
/// See [`SHARE_MIN_BYTES`].
pub(crate) const SHARE_FRACTION: usize = 4;
/// As [`SHARE_FRACTION`], for numeric vectors: a point cloud's four columns travel in one delta.
pub(crate) const VECTOR_SHARE_FRACTION: usize = 8;

/// `bytes` as a slice of `source` when it lies inside it and is worth sharing: [`SHARE_MIN_BYTES`] and at least
/// `1/fraction` of `source`.
fn shared_slice(source: &Bytes, bytes: &[u8], fraction: usize) -> Option<Bytes> {
    let inside =
        source.as_ptr_range().contains(&bytes.as_ptr()) && bytes.as_ptr_range().end <= source.as_ptr_range().end;
    let worth = bytes.len() >= SHARE_MIN_BYTES && bytes.len() * fraction >= source.len();
    (inside && worth).then(|| source.slice_ref(bytes))
}

/// Runs `decode` with `source` as the buffer that byte values may share (see `byte_buffer`); restores the previous
/// one after, also if `decode` panics (it does not: decoding never panics).
pub(crate) fn decoding_from<R>(source: &Bytes, decode: impl FnOnce() -> R) -> R {
    struct Restore(Option<Bytes>);
    impl Drop for Restore {
        fn drop(&mut self) {
            let previous = self.0.take();
            SOURCE.with_borrow_mut(|slot| *slot = previous);
        }
    }
    let _restore = Restore(SOURCE.with_borrow_mut(|slot| slot.replace(source.clone())));
    decode()
}

/// Encodes `Bytes` as one byte string. Decoding copies it once into a fresh buffer, unless the bytes being decoded
/// are a shared buffer ([`decoding_from`]) and the value is a large part of it: then the value is a slice of that
/// buffer, no copy (the receivers of one in-process sample then share one frame).
mod byte_buffer {
    use super::*;

    pub fn serialize<S: serde::Serializer>(bytes: &Bytes, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.serialize_bytes(bytes)
    }

    pub fn deserialize<'de, D: serde::Deserializer<'de>>(deserializer: D) -> Result<Bytes, D::Error> {
        deserializer.deserialize_bytes(Visitor)
    }

    struct Visitor;

    impl<'de> serde::de::Visitor<'de> for Visitor {
        type Value = Bytes;
        fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
            f.write_str("a byte string")
        }
        fn visit_borrowed_bytes<E: serde::de::Error>(self, bytes: &'de [u8]) -> Result<Bytes, E> {
            Ok(SOURCE
                .with_borrow(|source| source.as_ref().and_then(|source| shared_slice(source, bytes, SHARE_FRACTION)))
                .unwrap_or_else(|| Bytes::copy_from_slice(bytes)))
        }
        fn visit_bytes<E: serde::de::Error>(self, bytes: &[u8]) -> Result<Bytes, E> {
            Ok(Bytes::copy_from_slice(bytes))
        }
        fn visit_byte_buf<E: serde::de::Error>(self, bytes: Vec<u8>) -> Result<Bytes, E> {
            Ok(Bytes::from(bytes))
        }
    }
}
