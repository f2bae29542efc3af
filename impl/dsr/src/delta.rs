//! Deltas: the unit of replication, and their wire format.
//!
//! A [`Delta`] is a small causal-CRDT state — a dot store plus the causal context of the dots it adds or removes —
//! produced by one local operation, or a whole replica state (a *snapshot*). Joining deltas is commutative,
//! associative and idempotent, so they may travel in any order, any number of times.
//!
//! The wire format is `postcard` (varints) behind a one-byte header (format version and flags; the sender's clock
//! and a snapshot's applied operations follow the body only when the flags say so). Built-in attribute
//! names travel as their 1–2 byte code in the type dictionary, and dots as offsets from the delta's own dots where
//! they can, so a one-attribute `f32` update is about 40 bytes. Decoding checks structure (ids, dots, names,
//! limits) and returns a [`DeltaError`] that says where; it never panics. Type checks against the receiving
//! replica's dictionary happen in [`crate::Replica::apply`].
//!
//! Layout of an encoded delta, in order:
//!
//! 1. one header byte: `WIRE_VERSION << 3`, or-ed with flags `1` (a snapshot), `2` (a clock follows the body) and
//!    `4` (a snapshot's applied operations follow);
//! 2. the body, postcard-encoded: the origin (replica, first dot, number of dots) if any, the causal context (version
//!    vector, then out-of-order dots), tombstoned node ids, then the node and edge entries of the dot store;
//! 3. if flag `2`: the sender's clock stamp, 8 bytes little-endian;
//! 4. if flag `4`: the applied operations (a version vector and out-of-order dots), postcard-encoded.
//!
//! A numeric vector of 4 KiB or more starts at a multiple of its element's size (4 bytes for `vec<f32>`, 8 for
//! `vec<u64>`) from the start of the buffer the delta is encoded into, whatever precedes the delta there: its length
//! and variant varints carry as many extra zero groups as that takes, up to 5 bytes each (`0x85 0x80 0x00` is 5, as
//! `0x05` is, to postcard and to any LEB128 reader; a large `u64` vector is sometimes a byte short, see
//! `aligned_head`). A receiver whose buffer starts 8-aligned, as heap and shared-memory buffers do, reads such a
//! vector in place ([`Delta::decode_shared`]). So the bytes of one delta depend on where it is encoded (all of them
//! decode to the same delta), and everything else is postcard's shortest encoding.
//!
//! Nothing follows; [`Delta::decode`] refuses trailing bytes. Run recordings carry exactly these bytes as MCAP
//! messages with message encoding `dsr-delta-v1` (version 1 of this layout).
//!
//! Both directions work item by item with postcard's own serializer and deserializer, straight from and into the
//! store's types (a snapshot of a whole graph is neither copied into nor read through intermediate wire lists).
//! Decoding checks each item as it reads it and stops at the first problem, so of several problems the one
//! reported is the first in the bytes (trailing bytes are found last). The bytes are pinned by
//! `delta/wire_tests.rs`, which also holds this codec to the list-building one it replaced (`delta/reference.rs`).

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};
use smallvec::SmallVec;

use crate::causal::CausalContext;
use crate::dictionary::Dictionary;
use crate::error::DeltaError;
use crate::ids::{Dot, EdgeKey, Name, NodeId, ReplicaId, Stamp};
use crate::mutants::{DsrMutant, Plant};
use crate::store::{Attrs, EdgeEntry, Entry, NodeCore, NodeEntry, Register, Store};
use crate::value::Value;

mod pieces;
mod shared;
pub use pieces::Pieces;
pub use shared::LargeValues;

/// The wire format version this build writes and reads (the header byte's upper five bits).
pub const WIRE_VERSION: u8 = 1;

/// Header flag: the delta is a whole replica state.
const FLAG_COMPLETE: u8 = 1;
/// Header flag: the sender's clock follows the body (it is not the highest value stamp).
const FLAG_CLOCK: u8 = 1 << 1;
/// Header flag: a snapshot's applied operations follow the body.
const FLAG_APPLIED: u8 = 1 << 2;

/// The largest number of dots one delta may generate, and of items in one list (a decoding limit).
pub const MAX_ITEMS: usize = 1 << 24;

/// The dots a delta generated: `first..=last` of one replica.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Origin {
    /// The replica whose operation made the delta.
    pub replica: ReplicaId,
    /// First dot counter generated.
    pub first: u64,
    /// Last dot counter generated.
    pub last: u64,
}

impl Origin {
    /// The dots generated.
    pub fn dots(&self) -> impl Iterator<Item = Dot> + '_ {
        (self.first..=self.last).map(|counter| Dot::new(self.replica, counter))
    }
}

/// A delta (the effect of one operation) or a snapshot (a whole replica state), ready to join into a replica.
#[derive(Clone, Debug, Default, PartialEq, Eq, Hash)]
pub struct Delta {
    pub(crate) origin: Option<Origin>,
    pub(crate) complete: bool,
    /// The sender's hybrid-logical-clock stamp when it made the delta. A receiver's clock moves past it, so an
    /// operation that has seen this delta stamps after it — even when the delta holds no stamped value (a delete).
    pub(crate) clock: Stamp,
    pub(crate) ctx: CausalContext,
    /// For a snapshot: the operations its sender had joined (see [`crate::Replica::applied`]); empty otherwise.
    pub(crate) applied: CausalContext,
    pub(crate) store: Store,
    /// The mutant planted in the replica that made it (the codec's mutants live in encoding).
    pub(crate) plant: Plant,
}

impl Delta {
    /// The dots this delta generated, if it is the effect of one operation.
    pub fn origin(&self) -> Option<Origin> {
        self.origin
    }

    /// Whether this is a whole replica state (a snapshot) rather than the effect of one operation.
    pub fn is_snapshot(&self) -> bool {
        self.complete
    }

    /// The causal context: the dots this delta adds or removes.
    pub fn context(&self) -> &CausalContext {
        &self.ctx
    }

    /// For a snapshot, the operations its sender had joined; empty for the delta of one operation.
    pub fn applied(&self) -> &CausalContext {
        &self.applied
    }

    /// The dot store (for inspection and tests).
    pub fn store(&self) -> &Store {
        &self.store
    }

    /// Number of node entries, edge entries and tombstones carried.
    pub fn len(&self) -> usize {
        self.store.nodes.len() + self.store.edges.len() + self.store.tombstones.len()
    }

    /// Whether the delta carries nothing but its context.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Bytes of attribute payload carried (contents only).
    pub fn payload_bytes(&self) -> usize {
        let attrs = |attrs: &Attrs| -> usize {
            attrs.values().flat_map(|r| r.values.iter()).map(|e| e.value.payload_len()).sum()
        };
        self.store.nodes.values().map(|n| attrs(&n.attrs)).sum::<usize>()
            + self.store.edges.values().map(|e| attrs(&e.attrs)).sum::<usize>()
    }

    /// The sender's clock when it made the delta.
    pub fn clock(&self) -> Stamp {
        self.clock
    }

    /// The delta's parts, borrowed: what encoding reads.
    fn borrowed(&self) -> DeltaParts<'_> {
        DeltaParts {
            origin: self.origin,
            complete: self.complete,
            clock: self.clock,
            ctx: &self.ctx,
            applied: &self.applied,
            store: &self.store,
            plant: self.plant,
        }
    }

    /// Encodes the delta into a new buffer.
    ///
    /// # Examples
    /// ```
    /// use dsr::{Delta, Replica, ReplicaId, NewNode};
    /// let mut a = Replica::new(ReplicaId(1));
    /// let (_, delta) = a.insert_node(10, NewNode::new("world", "world")).unwrap();
    /// let bytes = delta.encode();
    /// let decoded = Delta::decode(&bytes).unwrap();
    /// assert_eq!(&decoded, &*delta);
    /// ```
    pub fn encode(&self) -> Vec<u8> {
        let mut out = Vec::new();
        self.encode_into(&mut out);
        out
    }

    /// Appends the encoded delta to `out`. Large numeric vectors are placed aligned from the start of `out` (see the
    /// module documentation), so the bytes appended depend on `out.len() % 8`.
    pub fn encode_into(&self, out: &mut Vec<u8>) {
        self.borrowed().encode_into(out, None);
    }

    /// Encodes the delta after `prefix` (an envelope's fields) without copying its large values: a byte value or a
    /// numeric vector of [`Pieces::MIN_SHARED_BYTES`] or more stays where it is and the result refers to it. The
    /// pieces, concatenated, are what [`Delta::encode_into`] appends to `prefix`; a transport that writes samples
    /// into memory of its own (a shared-memory chunk) copies a camera frame once, from the delta, instead of twice.
    ///
    /// # Examples
    /// ```
    /// use dsr::{Delta, NewNode, Replica, ReplicaId, Value};
    /// let mut a = Replica::new(ReplicaId(1));
    /// let (id, _) = a.insert_node(10, NewNode::new("camera", "cam")).unwrap();
    /// let frame = bytes::Bytes::from(vec![7u8; 64 * 1024]);
    /// let delta = a.set_attrs(20, id, [("cam_rgb", Value::Bytes(frame.clone()))]).unwrap();
    /// let pieces = delta.encode_pieces(b"envelope".to_vec());
    /// assert!(pieces.iter().any(|piece| piece.as_ptr() == frame.as_ptr()), "the frame is referred to, not copied");
    /// let mut whole = b"envelope".to_vec();
    /// delta.encode_into(&mut whole);
    /// assert_eq!(pieces.to_vec(), whole);
    /// ```
    pub fn encode_pieces(&self, prefix: Vec<u8>) -> Pieces<'_> {
        let mut own = prefix;
        let mut shared = Vec::new();
        self.borrowed().encode_into(&mut own, Some(&mut shared));
        Pieces::new(own, shared)
    }

    /// Decodes a delta from a shared buffer, as [`Delta::decode`] does, keeping large byte values (a camera frame) as
    /// slices of `bytes` instead of copies: the receivers of one sample share its buffer. A byte value is shared when
    /// it is at least 4 KiB and a quarter of the buffer (so the values of a big snapshot are still copied, and one of
    /// them kept for long does not hold the whole snapshot alive). Numeric vectors are shared alike where their bytes
    /// lie aligned in `bytes` (they do when `bytes` starts where the encoding's buffer started, at an 8-aligned
    /// address) and are copied once otherwise ([`crate::value::Numbers`]).
    ///
    /// # Errors
    /// As [`Delta::decode`].
    pub fn decode_shared(bytes: &bytes::Bytes) -> Result<Delta, DeltaError> {
        crate::value::decoding_from(bytes, || Delta::decode(bytes))
    }

    /// Decodes a delta, checking its structure.
    ///
    /// # Errors
    /// [`DeltaError`] saying what is wrong and where: bad bytes, an unknown version, zero ids, a value whose dot is
    /// not in the context, an invalid name, or a list over [`MAX_ITEMS`].
    pub fn decode(bytes: &[u8]) -> Result<Delta, DeltaError> {
        let (&header, body) =
            bytes.split_first().ok_or_else(|| DeltaError::Encoding("empty input (no header byte)".into()))?;
        let version = header >> 3;
        if version != WIRE_VERSION {
            return Err(DeltaError::Version { found: version, supported: WIRE_VERSION });
        }
        let mut reader = Reader { de: postcard::Deserializer::from_bytes(body), body_len: body.len() };
        let (mut delta, max_stamp) = reader.delta(header & FLAG_COMPLETE != 0)?;
        let rest = reader.de.finalize().map_err(|e| DeltaError::Encoding(format!("end of the body: {e}")))?;
        let (clock, rest) = if header & FLAG_CLOCK != 0 {
            let (clock, rest) = rest
                .split_first_chunk::<8>()
                .ok_or_else(|| DeltaError::Encoding(format!("clock: 8 bytes expected, {} left", rest.len())))?;
            (Some(*clock), rest)
        } else {
            (None, rest)
        };
        let (applied, rest) = if header & FLAG_APPLIED != 0 {
            let (applied, rest): (WireContext, &[u8]) = postcard::take_from_bytes(rest)
                .map_err(|e| DeltaError::Encoding(format!("applied operations: {e}")))?;
            (Some(applied), rest)
        } else {
            (None, rest)
        };
        if !rest.is_empty() {
            return Err(DeltaError::Encoding(format!("{} trailing bytes after the delta", rest.len())));
        }
        if let Some((vv, cloud)) = applied {
            check_len(|| "applied operations", vv.len().saturating_add(cloud.len()))?;
            if vv.iter().chain(&cloud).any(|(replica, _)| *replica == 0) {
                return Err(invalid("applied operations", "replica id 0"));
            }
            if cloud.iter().any(|(_, counter)| *counter == 0) {
                return Err(invalid("applied operations", "dot counter 0"));
            }
            delta.applied = CausalContext::from_parts(
                vv.into_iter().map(|(r, c)| (ReplicaId(r), c)).collect(),
                cloud.into_iter().map(|(r, c)| Dot::new(ReplicaId(r), c)).collect(),
            );
        }
        delta.clock = match clock {
            Some(bytes) => Stamp(u64::from_le_bytes(bytes)),
            None => max_stamp,
        };
        Ok(delta)
    }
}

/// The parts of a delta, borrowed: a [`Delta`] encodes through it, and a replica encodes its snapshot from its own
/// fields through it without copying its store (`Replica::encode_snapshot`).
#[derive(Clone, Copy)]
pub(crate) struct DeltaParts<'a> {
    pub(crate) origin: Option<Origin>,
    pub(crate) complete: bool,
    pub(crate) clock: Stamp,
    pub(crate) ctx: &'a CausalContext,
    pub(crate) applied: &'a CausalContext,
    pub(crate) store: &'a Store,
    pub(crate) plant: Plant,
}

impl<'a> DeltaParts<'a> {
    /// Appends the encoded delta to `out` (the format of [`Delta::encode`]).
    ///
    /// The body is written straight from the store, item by item, with postcard's own serializer (so every number
    /// and string has postcard's encoding, and the bytes are those of the wire structures the layout describes);
    /// nothing is copied first. The header byte is written last, once the body has shown whether the clock must
    /// travel (it must when it is not the highest value stamp, which the body finds on the way).
    ///
    /// With `shared`, a large value is not copied into `out`: its bytes are listed in `shared` at the position in
    /// `out` where they belong ([`Pieces`]).
    pub(crate) fn encode_into(&self, out: &mut Vec<u8>, shared: Option<&mut Vec<(usize, &'a [u8])>>) {
        let header_at = out.len();
        out.push(0);
        let mut body = Body {
            ser: postcard::Serializer { output: Out(out) },
            origin: self.origin,
            max_stamp: Stamp(0),
            plant: self.plant,
            shared,
            shared_bytes: 0,
        };
        body.delta(self).expect("encoding into a Vec cannot fail");
        let Body { ser, max_stamp, .. } = body;
        let out = ser.output.0;
        let clock = self.clock != max_stamp;
        if clock {
            out.extend_from_slice(&self.clock.0.to_le_bytes());
        }
        let applied = !self.applied.is_empty();
        if applied {
            let mut ser = postcard::Serializer { output: Out(out) };
            context(&mut ser, self.applied).expect("encoding into a Vec cannot fail");
        }
        let mut header = WIRE_VERSION << 3;
        header |= if self.complete { FLAG_COMPLETE } else { 0 };
        header |= if clock { FLAG_CLOCK } else { 0 };
        header |= if applied { FLAG_APPLIED } else { 0 };
        out[header_at] = header;
    }
}

/// postcard output appended straight to the caller's buffer.
struct Out<'a>(&'a mut Vec<u8>);

impl postcard::ser_flavors::Flavor for Out<'_> {
    type Output = ();

    fn try_push(&mut self, byte: u8) -> postcard::Result<()> {
        self.0.push(byte);
        Ok(())
    }

    fn try_extend(&mut self, bytes: &[u8]) -> postcard::Result<()> {
        // Most pieces are varints of a few bytes: copied inline, not through a `memcpy` call each.
        if bytes.len() <= 16 {
            self.0.reserve(bytes.len());
            for &byte in bytes {
                self.0.push(byte);
            }
        } else {
            self.0.extend_from_slice(bytes);
        }
        Ok(())
    }

    fn finalize(self) -> postcard::Result<()> {
        Ok(())
    }
}

type Ser<'a> = postcard::Serializer<Out<'a>>;

/// Writes one item in postcard's encoding.
fn put<T: Serialize + ?Sized>(ser: &mut Ser<'_>, item: &T) -> postcard::Result<()> {
    item.serialize(ser)
}

/// Writes a list's length (postcard: a varint, as `usize`).
fn put_len(ser: &mut Ser<'_>, len: usize) -> postcard::Result<()> {
    put(ser, &len)
}

/// A causal context: version vector `(replica, counter)`, then out-of-order dots `(replica, counter)`.
fn context(ser: &mut Ser<'_>, ctx: &CausalContext) -> postcard::Result<()> {
    put_len(ser, ctx.version_vector().len())?;
    for (replica, counter) in ctx.version_vector() {
        put(ser, &(replica.0, *counter))?;
    }
    put_len(ser, ctx.cloud().len())?;
    for dot in ctx.cloud() {
        put(ser, &(dot.replica.0, dot.counter))?;
    }
    Ok(())
}

/// The body writer: knows the delta's origin (dots are written relative to it) and finds the highest value stamp.
struct Body<'o, 'v> {
    ser: Ser<'o>,
    origin: Option<Origin>,
    max_stamp: Stamp,
    plant: Plant,
    /// Where large values are listed instead of copied, if they are ([`Delta::encode_pieces`]).
    shared: Option<&'o mut Vec<(usize, &'v [u8])>>,
    /// The bytes listed in `shared` so far: the encoding's length is theirs and the output's.
    shared_bytes: usize,
}

impl<'v> Body<'_, 'v> {
    fn delta(&mut self, delta: &DeltaParts<'v>) -> postcard::Result<()> {
        let origin = self.origin;
        put(&mut self.ser, &origin.map(|o| (o.replica.0, o.first, (o.last - o.first + 1) as u32)))?;
        // The generated dots are implied by `origin`; the rest of the context travels explicitly.
        let mut vv: SmallVec<[(u32, u64); 4]> = SmallVec::new();
        for &(replica, counter) in delta.ctx.version_vector() {
            match origin {
                // The entry ends at the generated range: send only the part before it.
                Some(o) if o.replica == replica && counter == o.last => {
                    if o.first > 1 {
                        vv.push((replica.0, o.first - 1));
                    }
                }
                _ => vv.push((replica.0, counter)),
            }
        }
        put(&mut self.ser, vv.as_slice())?;
        let generated =
            |dot: &Dot| origin.is_some_and(|o| o.replica == dot.replica && (o.first..=o.last).contains(&dot.counter));
        put_len(&mut self.ser, delta.ctx.cloud().iter().filter(|dot| !generated(dot)).count())?;
        for dot in delta.ctx.cloud().iter().filter(|dot| !generated(dot)) {
            put(&mut self.ser, &wire_dot(*dot, origin))?;
        }

        let store = delta.store;
        put_len(&mut self.ser, store.tombstones.len())?;
        for id in &store.tombstones {
            put(&mut self.ser, &id.0)?;
        }
        put_len(&mut self.ser, store.nodes.len())?;
        for (id, node) in &store.nodes {
            put(&mut self.ser, &id.0)?;
            put_len(&mut self.ser, node.core.values.len())?;
            for entry in &node.core.values {
                self.entry_head(entry)?;
                put(&mut self.ser, &(entry.value.node_type.as_str(), entry.value.name.as_str()))?;
            }
            self.attrs(&node.attrs)?;
        }
        put_len(&mut self.ser, store.edges.len())?;
        for (key, edge) in &store.edges {
            put(&mut self.ser, &(key.from.0, key.to.0, key.edge_type.as_str()))?;
            put_len(&mut self.ser, edge.presence.values.len())?;
            for entry in &edge.presence.values {
                // The value `()` takes no bytes.
                self.entry_head(entry)?;
            }
            self.attrs(&edge.attrs)?;
        }
        Ok(())
    }

    /// An entry's dot and stamp (its value follows).
    fn entry_head<T>(&mut self, entry: &Entry<T>) -> postcard::Result<()> {
        self.max_stamp = self.max_stamp.max(entry.stamp);
        let mut dot = wire_dot(entry.dot, self.origin);
        if let WireDot::Same(offset) = &mut dot
            && *offset > 0
            && self.plant.is(DsrMutant::CodecDotOffset)
        {
            *offset -= 1;
        }
        put(&mut self.ser, &dot)?;
        // A `[u8; 8]` is its 8 bytes in postcard: written in one piece rather than byte by byte.
        self.ser.output.0.extend_from_slice(&entry.stamp.0.to_le_bytes());
        Ok(())
    }

    fn attrs(&mut self, attrs: &'v Attrs) -> postcard::Result<()> {
        put_len(&mut self.ser, attrs.len())?;
        for (name, register) in attrs {
            let name = match Dictionary::builtin_attr_code(name) {
                Some(code) => WireName::Builtin(code),
                None => WireName::Text(name.as_str()),
            };
            put(&mut self.ser, &name)?;
            put_len(&mut self.ser, register.values.len())?;
            for entry in &register.values {
                self.entry_head(entry)?;
                self.value(&entry.value)?;
            }
        }
        Ok(())
    }

    /// A value, in postcard's encoding. A byte value or numeric vector of [`Pieces::MIN_SHARED_BYTES`] or more is one
    /// block after its variant and length, which are written so that the block starts aligned ([`aligned_head`]);
    /// when large values are listed apart, the block is listed at its position instead of copied in.
    fn value(&mut self, value: &'v Value) -> postcard::Result<()> {
        let Some(block) = value.wire_block().filter(|block| block.bytes.len() >= Pieces::MIN_SHARED_BYTES) else {
            return put(&mut self.ser, value);
        };
        let out = &mut *self.ser.output.0;
        aligned_head(out, self.shared_bytes, block.variant, block.bytes.len(), block.align);
        match &mut self.shared {
            Some(shared) => {
                shared.push((out.len(), block.bytes));
                self.shared_bytes += block.bytes.len();
            }
            None => out.extend_from_slice(block.bytes),
        }
        Ok(())
    }
}

/// The longest padded varint written: the longest postcard reads for a `u32`, and for a `usize` on a 32-bit host.
const MAX_PADDED_VARINT_BYTES: usize = 5;

// A block is placed aligned from the size at which a receiver may keep it as a view: one threshold for both.
const _: () = assert!(Pieces::MIN_SHARED_BYTES == crate::value::SHARE_MIN_BYTES);

/// Writes a block's variant index and length as postcard varints, so that the block written next starts at a
/// multiple of `align` from the start of the output (`out`, plus `listed_apart` bytes of pieces not copied into it).
/// The padding is extra zero groups at the end of the length's varint, then of the variant's: `0x85 0x80 0x00` is 5
/// as `0x05` is, and postcard reads both. Neither varint grows past 5 bytes, so the padding reaches 7 bytes while the
/// length is under 16 KiB, 6 under 2 MiB and 5 under 256 MiB: an `f32` vector (at most 3) is always placed aligned,
/// a `u64` one in 7 of 8 positions from 16 KiB and 6 of 8 from 2 MiB, the rest a byte or two short (then copied once
/// on receipt).
/// A receiver whose buffer starts aligned (a heap or shared-memory buffer) reads a vector placed aligned in place
/// ([`crate::value::Numbers`]).
fn aligned_head(out: &mut Vec<u8>, listed_apart: usize, variant: u32, len: usize, align: usize) {
    let (variant, len) = (u64::from(variant), len as u64);
    let at = out.len() + listed_apart + varint_bytes(variant) + varint_bytes(len);
    let pad = (align - at % align) % align;
    let room = |value: u64| MAX_PADDED_VARINT_BYTES.saturating_sub(varint_bytes(value));
    let len_pad = pad.min(room(len));
    let variant_pad = (pad - len_pad).min(room(variant));
    put_varint(out, variant, variant_pad);
    put_varint(out, len, len_pad);
}

/// Bytes of `value`'s shortest varint.
fn varint_bytes(value: u64) -> usize {
    ((u64::BITS - value.leading_zeros()).max(1) as usize).div_ceil(7)
}

/// Writes `value` as a varint of its shortest length plus `extra` zero groups.
fn put_varint(out: &mut Vec<u8>, mut value: u64, extra: usize) {
    let groups = varint_bytes(value) + extra;
    for index in 1..=groups {
        let group = (value & 0x7f) as u8;
        value >>= 7;
        out.push(if index < groups { group | 0x80 } else { group });
    }
}

// ---------------------------------------------------------------------------------------------------------------
// Wire items.

/// A causal context on the wire: version vector `(replica, counter)`, then out-of-order dots.
type WireContext = (Vec<(u32, u64)>, Vec<(u32, u64)>);

/// A dot, relative to the delta's first generated dot when it is of the same replica.
#[derive(Serialize, Deserialize, Clone, Copy)]
enum WireDot {
    Same(i64),
    Other(u32, u64),
}

/// An attribute name: a built-in name's code in the dictionary, or the text of any other.
#[derive(Serialize, Deserialize)]
enum WireName<'a> {
    Builtin(u16),
    Text(&'a str),
}

fn wire_dot(dot: Dot, origin: Option<Origin>) -> WireDot {
    match origin {
        Some(o) if o.replica == dot.replica => WireDot::Same(dot.counter.wrapping_sub(o.first) as i64),
        _ => WireDot::Other(dot.replica.0, dot.counter),
    }
}

fn invalid(place: impl Into<String>, what: impl Into<String>) -> DeltaError {
    DeltaError::InvalidId { place: place.into(), what: what.into() }
}

fn limit(place: impl Into<String>, what: impl Into<String>) -> DeltaError {
    DeltaError::Limit { place: place.into(), what: what.into() }
}

/// Checks a list length; the place is only formatted when the check fails (decoding is a hot path).
fn check_len<P: AsRef<str>>(place: impl FnOnce() -> P, len: usize) -> Result<(), DeltaError> {
    if len > MAX_ITEMS {
        return Err(limit(place().as_ref(), format!("{len} items (limit {MAX_ITEMS})")));
    }
    Ok(())
}

/// Checks a name's length; the place is only formatted when the check fails.
fn check_type_name(place: impl FnOnce() -> String, what: &str, name: &str) -> Result<(), DeltaError> {
    if name.is_empty() || name.len() > crate::dictionary::MAX_NAME_LEN {
        return Err(limit(place(), format!("{what} of {} bytes (1 to 255 allowed)", name.len())));
    }
    Ok(())
}

/// Checks the dots of a delta being decoded (it knows the delta's origin and context) and finds the highest value
/// stamp.
struct Decoder {
    origin: Option<Origin>,
    ctx: CausalContext,
    max_stamp: Stamp,
}

impl Decoder {
    fn origin(wire: Option<(u32, u64, u32)>) -> Result<Option<Origin>, DeltaError> {
        let Some((replica, first, count)) = wire else { return Ok(None) };
        if replica == 0 {
            return Err(invalid("origin", "replica id 0"));
        }
        if first == 0 || count == 0 {
            return Err(invalid("origin", format!("dots {first}+{count} (counters start at 1, count >= 1)")));
        }
        if count as usize > MAX_ITEMS {
            return Err(limit("origin", format!("{count} dots")));
        }
        let last = first.checked_add(u64::from(count) - 1).ok_or_else(|| invalid("origin", "dot counter overflows"))?;
        Ok(Some(Origin { replica: ReplicaId(replica), first, last }))
    }

    fn dot(&self, wire: WireDot, place: &dyn Fn() -> String) -> Result<Dot, DeltaError> {
        match wire {
            WireDot::Same(offset) => {
                let o = self.origin.ok_or_else(|| invalid(place(), "relative dot in a delta without origin"))?;
                let counter = o.first.wrapping_add(offset as u64);
                if counter == 0 || (offset < 0 && counter >= o.first) || (offset >= 0 && counter < o.first) {
                    return Err(invalid(place(), format!("relative dot offset {offset} leaves the counter range")));
                }
                Ok(Dot::new(o.replica, counter))
            }
            WireDot::Other(replica, counter) => {
                if replica == 0 || counter == 0 {
                    return Err(invalid(place(), format!("dot r{replica}:{counter} (ids and counters start at 1)")));
                }
                Ok(Dot::new(ReplicaId(replica), counter))
            }
        }
    }

    /// A dot of a stored value: valid, and held by the delta's context.
    fn stored_dot(&self, wire: WireDot, place: &dyn Fn() -> String) -> Result<Dot, DeltaError> {
        let dot = self.dot(wire, place)?;
        if !self.ctx.contains(dot) {
            return Err(DeltaError::DotOutsideContext { place: place(), dot });
        }
        Ok(dot)
    }
}

/// The largest capacity reserved for a list before its items have been read (a list's length is untrusted).
const RESERVE_LIMIT: usize = 1 << 12;

/// Reads the body of a delta item by item, straight into the store's types, with postcard's own deserializer
/// (so every number and string is read as postcard reads it), checking each item as it comes.
struct Reader<'de> {
    de: postcard::Deserializer<'de, postcard::de_flavors::Slice<'de>>,
    body_len: usize,
}

impl<'de> Reader<'de> {
    /// Reads one item; `place` says where it is, for the error.
    fn take<T: Deserialize<'de>, P: AsRef<str>>(&mut self, place: impl FnOnce() -> P) -> Result<T, DeltaError> {
        T::deserialize(&mut self.de)
            .map_err(|e| DeltaError::Encoding(format!("{}: {e} (body of {} bytes)", place().as_ref(), self.body_len)))
    }

    /// Reads a list's length, within [`MAX_ITEMS`].
    fn len<P: AsRef<str>>(&mut self, place: impl Fn() -> P) -> Result<usize, DeltaError> {
        let len: usize = self.take(&place)?;
        check_len(place, len)?;
        Ok(len)
    }

    /// A stamp (8 bytes, little-endian).
    fn stamp<P: AsRef<str>>(&mut self, place: impl FnOnce() -> P) -> Result<Stamp, DeltaError> {
        Ok(Stamp(u64::from_le_bytes(self.take::<[u8; 8], _>(place)?)))
    }

    /// The body: origin, context, tombstones, nodes, edges. Returns the delta (without its clock and applied
    /// operations, which follow the body) and the highest value stamp.
    fn delta(&mut self, complete: bool) -> Result<(Delta, Stamp), DeltaError> {
        let origin = Decoder::origin(self.take(|| "origin")?)?;
        let mut decoder = Decoder { origin, ctx: CausalContext::default(), max_stamp: Stamp(0) };
        let vv: Vec<(u32, u64)> = self.take(|| "context version vector")?;
        let cloud: Vec<WireDot> = self.take(|| "context dots")?;
        check_len(|| "context", vv.len().saturating_add(cloud.len()))?;
        let mut ctx_vv = Vec::with_capacity(vv.len());
        for (replica, counter) in vv {
            if replica == 0 {
                return Err(invalid("context version vector", "replica id 0"));
            }
            ctx_vv.push((ReplicaId(replica), counter));
        }
        let mut ctx_cloud = Vec::with_capacity(cloud.len());
        for (index, wire_dot) in cloud.into_iter().enumerate() {
            ctx_cloud.push(decoder.dot(wire_dot, &|| format!("context dot {index}"))?);
        }
        decoder.ctx = CausalContext::from_parts(ctx_vv, ctx_cloud);
        if let Some(o) = origin {
            for generated in o.dots() {
                decoder.ctx.insert(generated);
            }
        }

        let tombstones: Vec<u64> = self.take(|| "tombstones")?;
        check_len(|| "tombstones", tombstones.len())?;
        if tombstones.contains(&0) {
            return Err(invalid("tombstones", "node id 0"));
        }
        let tombstones = tombstones.into_iter().map(NodeId).collect();

        // Entries usually come in key order (an encoder walks a sorted map); then they are collected in a list
        // and the map is built from it in one go. Out of order, they go into the map one by one.
        let count = self.len(|| "nodes")?;
        let mut sorted: Vec<(NodeId, NodeEntry)> = Vec::with_capacity(count.min(RESERVE_LIMIT));
        let mut unsorted: Option<BTreeMap<NodeId, NodeEntry>> = None;
        for _ in 0..count {
            let (id, entry) = self.node(&mut decoder)?;
            if unsorted.is_none() && sorted.last().is_none_or(|(last, _)| *last < id) {
                sorted.push((id, entry));
                continue;
            }
            let map = unsorted.get_or_insert_with(|| std::mem::take(&mut sorted).into_iter().collect());
            if map.insert(id, entry).is_some() {
                return Err(limit(format!("node {id}"), "node listed twice"));
            }
        }
        let nodes = unsorted.unwrap_or_else(|| sorted.into_iter().collect());

        let count = self.len(|| "edges")?;
        let mut sorted: Vec<(EdgeKey, EdgeEntry)> = Vec::with_capacity(count.min(RESERVE_LIMIT));
        let mut unsorted: Option<BTreeMap<EdgeKey, EdgeEntry>> = None;
        for _ in 0..count {
            let (key, entry) = self.edge(&mut decoder)?;
            if unsorted.is_none() && sorted.last().is_none_or(|(last, _)| *last < key) {
                sorted.push((key, entry));
                continue;
            }
            let map = unsorted.get_or_insert_with(|| std::mem::take(&mut sorted).into_iter().collect());
            if map.contains_key(&key) {
                return Err(limit(format!("edge {key}"), "edge listed twice"));
            }
            map.insert(key, entry);
        }
        let edges = unsorted.unwrap_or_else(|| sorted.into_iter().collect());

        let store = Store { tombstones, nodes, edges };
        let delta = Delta {
            origin,
            complete,
            clock: Stamp(0),
            ctx: decoder.ctx,
            applied: CausalContext::default(),
            store,
            plant: Plant::NONE,
        };
        Ok((delta, decoder.max_stamp))
    }

    fn node(&mut self, decoder: &mut Decoder) -> Result<(NodeId, NodeEntry), DeltaError> {
        let id: u64 = self.take(|| "node list")?;
        if id == 0 {
            return Err(invalid("node list", "node id 0"));
        }
        let owner = || format!("node {id}");
        let count = self.len(owner)?;
        let mut core = Register::default();
        for index in 0..count {
            let place = || format!("node {id} core value {index}");
            let dot = self.take(place)?;
            let stamp = self.stamp(place)?;
            let (node_type, name): (&str, &str) = self.take(place)?;
            let dot = decoder.stored_dot(dot, &place)?;
            check_type_name(place, "node type", node_type)?;
            if !crate::ids::valid_node_name(name) {
                return Err(DeltaError::InvalidNodeName { place: place(), name: name.chars().take(64).collect() });
            }
            if core.values.iter().any(|e: &Entry<NodeCore>| e.dot == dot) {
                return Err(limit(place(), format!("dot {dot} listed twice")));
            }
            decoder.max_stamp = decoder.max_stamp.max(stamp);
            core.values.push(Entry {
                dot,
                stamp,
                value: NodeCore { node_type: crate::dictionary::intern_type(node_type), name: Name::new(name) },
            });
        }
        core.values.sort_unstable_by_key(|entry| entry.dot);
        let attrs = self.attrs(decoder, &owner)?;
        Ok((NodeId(id), NodeEntry { core, attrs }))
    }

    fn edge(&mut self, decoder: &mut Decoder) -> Result<(EdgeKey, EdgeEntry), DeltaError> {
        let (from, to, edge_type): (u64, u64, &str) = self.take(|| "edge list")?;
        let place = || format!("edge {from}->{to}");
        if from == 0 || to == 0 {
            return Err(invalid(place(), "node id 0"));
        }
        check_type_name(place, "edge type", edge_type)?;
        let key = EdgeKey { from: NodeId(from), to: NodeId(to), edge_type: crate::dictionary::intern_type(edge_type) };
        let owner = || format!("edge {key}");
        let presence = self.entries(decoder, &|| format!("edge {key} presence"), |_, _| Ok(()))?;
        let attrs = self.attrs(decoder, &owner)?;
        Ok((key, EdgeEntry { presence, attrs }))
    }

    /// A register's entries: dot, stamp, value (read by `value`).
    fn entries<T>(
        &mut self,
        decoder: &mut Decoder,
        place: &dyn Fn() -> String,
        mut value: impl FnMut(&mut Self, &dyn Fn() -> String) -> Result<T, DeltaError>,
    ) -> Result<Register<T>, DeltaError> {
        let count = self.len(place)?;
        let mut values: SmallVec<[Entry<T>; 1]> = SmallVec::with_capacity(count.min(RESERVE_LIMIT));
        for index in 0..count {
            let entry_place = || format!("{} value {index}", place());
            let dot = self.take(entry_place)?;
            let stamp = self.stamp(entry_place)?;
            let value = value(self, &entry_place)?;
            let dot = decoder.stored_dot(dot, &entry_place)?;
            if values.iter().any(|e| e.dot == dot) {
                return Err(limit(entry_place(), format!("dot {dot} listed twice")));
            }
            decoder.max_stamp = decoder.max_stamp.max(stamp);
            values.push(Entry { dot, stamp, value });
        }
        values.sort_unstable_by_key(|entry| entry.dot);
        Ok(Register { values })
    }

    fn attrs(&mut self, decoder: &mut Decoder, owner: &dyn Fn() -> String) -> Result<Attrs, DeltaError> {
        let count = self.len(owner)?;
        let mut attrs = Attrs::new();
        for index in 0..count {
            let name = match self.take(|| format!("{} attribute {index}", owner()))? {
                WireName::Builtin(code) => crate::dictionary::interned_attr(code)
                    .ok_or_else(|| invalid(owner(), format!("unknown built-in attribute code {code}")))?,
                WireName::Text(text) => {
                    check_type_name(|| format!("{} attribute {text:?}", owner()), "attribute name", text)?;
                    Name::new(text)
                }
            };
            let place = || format!("{} attribute {name:?}", owner());
            let values = self.entries(decoder, &place, |reader, place| reader.take::<Value, _>(place))?;
            match attrs.entry(name) {
                std::collections::btree_map::Entry::Vacant(slot) => {
                    slot.insert(values);
                }
                std::collections::btree_map::Entry::Occupied(slot) => {
                    return Err(limit(format!("{} attribute {:?}", owner(), slot.key()), "attribute listed twice"));
                }
            }
        }
        Ok(attrs)
    }
}

#[cfg(test)]
mod reference;
#[cfg(test)]
mod wire_tests;
