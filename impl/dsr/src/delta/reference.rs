//! The delta codec as it was before encoding and decoding were rewritten to work straight from and into the store
//! (wire version 1): kept unchanged, for tests only, as the reference the current codec must match byte for byte
//! (encoding) and verdict for verdict (decoding). Do not "improve" it: its value is that it is the old code.

use serde::{Deserialize, Serialize};
use smallvec::SmallVec;

use super::{DeltaParts, FLAG_APPLIED, FLAG_CLOCK, FLAG_COMPLETE, MAX_ITEMS, Origin, WIRE_VERSION};
use crate::causal::CausalContext;
use crate::delta::Delta;
use crate::dictionary::Dictionary;
use crate::error::DeltaError;
use crate::ids::{Dot, EdgeKey, Name, NodeId, ReplicaId, Stamp};
use crate::store::{Attrs, EdgeEntry, Entry, NodeCore, NodeEntry, Register, Store};
use crate::value::Value;

/// The highest stamp of a value carried.
pub(super) fn max_value_stamp(parts: &DeltaParts<'_>) -> Stamp {
    let attrs = |attrs: &Attrs| attrs.values().flat_map(|r| r.values.iter().map(|e| e.stamp)).max();
    let nodes = parts.store.nodes.values().flat_map(|n| n.core.values.iter().map(|e| e.stamp).chain(attrs(&n.attrs)));
    let edges =
        parts.store.edges.values().flat_map(|e| e.presence.values.iter().map(|p| p.stamp).chain(attrs(&e.attrs)));
    nodes.chain(edges).max().unwrap_or_default()
}

/// The old `DeltaParts::encode_into`.
pub(crate) fn encode_into(parts: &DeltaParts<'_>, out: &mut Vec<u8>) {
    let wire = to_wire(parts);
    let clock = (parts.clock != max_value_stamp(parts)).then(|| parts.clock.0.to_le_bytes());
    let applied: Option<WireContext> = (!parts.applied.is_empty()).then(|| {
        (
            parts.applied.version_vector().iter().map(|(r, c)| (r.0, *c)).collect(),
            parts.applied.cloud().iter().map(|d| (d.replica.0, d.counter)).collect(),
        )
    });
    let mut header = WIRE_VERSION << 3;
    header |= if parts.complete { FLAG_COMPLETE } else { 0 };
    header |= if clock.is_some() { FLAG_CLOCK } else { 0 };
    header |= if applied.is_some() { FLAG_APPLIED } else { 0 };
    out.push(header);
    let mut encoded = postcard::to_extend(&wire, std::mem::take(out)).expect("encoding into a Vec cannot fail");
    if let Some(clock) = clock {
        encoded.extend_from_slice(&clock);
    }
    if let Some(applied) = applied {
        encoded = postcard::to_extend(&applied, encoded).expect("encoding into a Vec cannot fail");
    }
    *out = encoded;
}

/// The old encoding of a delta.
pub(crate) fn encode(delta: &Delta) -> Vec<u8> {
    let mut out = Vec::new();
    encode_into(&delta.borrowed(), &mut out);
    out
}

/// The old `Delta::decode`.
pub(crate) fn decode(bytes: &[u8]) -> Result<Delta, DeltaError> {
    let (&header, body) =
        bytes.split_first().ok_or_else(|| DeltaError::Encoding("empty input (no header byte)".into()))?;
    let version = header >> 3;
    if version != WIRE_VERSION {
        return Err(DeltaError::Version { found: version, supported: WIRE_VERSION });
    }
    let (wire, rest): (WireDelta<'_>, &[u8]) = postcard::take_from_bytes(body)
        .map_err(|e| DeltaError::Encoding(format!("{e} (body of {} bytes)", body.len())))?;
    let (clock, rest) = if header & FLAG_CLOCK != 0 {
        let (clock, rest) = rest
            .split_first_chunk::<8>()
            .ok_or_else(|| DeltaError::Encoding(format!("clock: 8 bytes expected, {} left", rest.len())))?;
        (Some(*clock), rest)
    } else {
        (None, rest)
    };
    let (applied, rest) = if header & FLAG_APPLIED != 0 {
        let (applied, rest): (WireContext, &[u8]) =
            postcard::take_from_bytes(rest).map_err(|e| DeltaError::Encoding(format!("applied operations: {e}")))?;
        (Some(applied), rest)
    } else {
        (None, rest)
    };
    if !rest.is_empty() {
        return Err(DeltaError::Encoding(format!("{} trailing bytes after the delta", rest.len())));
    }
    from_wire(wire, header & FLAG_COMPLETE != 0, clock, applied)
}

// Wire structures (visible to the tests, which build arbitrary ones to feed both decoders).

#[derive(Serialize, Deserialize, Debug, Clone)]
pub(super) struct WireDelta<'a> {
    pub(super) origin: Option<(u32, u64, u32)>,
    pub(super) vv: Vec<(u32, u64)>,
    pub(super) cloud: Vec<WireDot>,
    pub(super) tombstones: Vec<u64>,
    #[serde(borrow)]
    pub(super) nodes: Vec<WireNode<'a>>,
    #[serde(borrow)]
    pub(super) edges: Vec<WireEdge<'a>>,
}

/// A causal context on the wire: version vector `(replica, counter)`, then out-of-order dots.
pub(super) type WireContext = (Vec<(u32, u64)>, Vec<(u32, u64)>);

/// A dot, relative to the delta's first generated dot when it is of the same replica.
#[derive(Serialize, Deserialize, Clone, Copy, Debug)]
pub(super) enum WireDot {
    Same(i64),
    Other(u32, u64),
}

#[derive(Serialize, Deserialize, Debug, Clone)]
pub(super) struct WireNode<'a> {
    pub(super) id: u64,
    #[serde(borrow)]
    pub(super) core: Vec<WireEntry<(&'a str, &'a str)>>,
    #[serde(borrow)]
    pub(super) attrs: Vec<WireRegister<'a>>,
}

#[derive(Serialize, Deserialize, Debug, Clone)]
pub(super) struct WireEdge<'a> {
    pub(super) from: u64,
    pub(super) to: u64,
    pub(super) edge_type: &'a str,
    pub(super) presence: Vec<WireEntry<()>>,
    #[serde(borrow)]
    pub(super) attrs: Vec<WireRegister<'a>>,
}

#[derive(Serialize, Deserialize, Debug, Clone)]
pub(super) struct WireRegister<'a> {
    #[serde(borrow)]
    pub(super) name: WireName<'a>,
    pub(super) values: Vec<WireEntry<Value>>,
}

#[derive(Serialize, Deserialize, Debug, Clone)]
pub(super) enum WireName<'a> {
    Builtin(u16),
    Text(&'a str),
}

#[derive(Serialize, Deserialize, Debug, Clone)]
pub(super) struct WireEntry<T> {
    pub(super) dot: WireDot,
    pub(super) stamp: [u8; 8],
    pub(super) value: T,
}

fn wire_dot(dot: Dot, origin: Option<Origin>) -> WireDot {
    match origin {
        Some(o) if o.replica == dot.replica => WireDot::Same(dot.counter.wrapping_sub(o.first) as i64),
        _ => WireDot::Other(dot.replica.0, dot.counter),
    }
}

fn to_wire<'d>(delta: &DeltaParts<'d>) -> WireDelta<'d> {
    let origin = delta.origin;
    let generated =
        |dot: &Dot| origin.is_some_and(|o| o.replica == dot.replica && (o.first..=o.last).contains(&dot.counter));
    // The generated dots are implied by `origin`; the rest of the context travels explicitly.
    let mut vv = Vec::new();
    let mut cloud = Vec::new();
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
    for dot in delta.ctx.cloud() {
        if !generated(dot) {
            cloud.push(wire_dot(*dot, origin));
        }
    }
    let entries = |register: &Register<Value>| -> Vec<WireEntry<Value>> {
        register
            .values
            .iter()
            .map(|e| WireEntry { dot: wire_dot(e.dot, origin), stamp: e.stamp.0.to_le_bytes(), value: e.value.clone() })
            .collect()
    };
    fn attrs<'d>(
        attrs: &'d Attrs,
        entries: &dyn Fn(&Register<Value>) -> Vec<WireEntry<Value>>,
    ) -> Vec<WireRegister<'d>> {
        attrs
            .iter()
            .map(|(name, register)| WireRegister {
                name: match Dictionary::builtin_attr_code(name) {
                    Some(code) => WireName::Builtin(code),
                    None => WireName::Text(name.as_str()),
                },
                values: entries(register),
            })
            .collect()
    }
    WireDelta {
        origin: origin.map(|o| (o.replica.0, o.first, (o.last - o.first + 1) as u32)),
        vv,
        cloud,
        tombstones: delta.store.tombstones.iter().map(|id| id.0).collect(),
        nodes: delta
            .store
            .nodes
            .iter()
            .map(|(id, node)| WireNode {
                id: id.0,
                core: node
                    .core
                    .values
                    .iter()
                    .map(|e| WireEntry {
                        dot: wire_dot(e.dot, origin),
                        stamp: e.stamp.0.to_le_bytes(),
                        value: (e.value.node_type.as_str(), e.value.name.as_str()),
                    })
                    .collect(),
                attrs: attrs(&node.attrs, &entries),
            })
            .collect(),
        edges: delta
            .store
            .edges
            .iter()
            .map(|(key, edge)| WireEdge {
                from: key.from.0,
                to: key.to.0,
                edge_type: key.edge_type.as_str(),
                presence: edge
                    .presence
                    .values
                    .iter()
                    .map(|e| WireEntry { dot: wire_dot(e.dot, origin), stamp: e.stamp.0.to_le_bytes(), value: () })
                    .collect(),
                attrs: attrs(&edge.attrs, &entries),
            })
            .collect(),
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

/// Turns wire structures back into a delta, checking them; knows the delta's origin and context.
struct Decoder {
    origin: Option<Origin>,
    ctx: CausalContext,
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

    fn entries<T>(&self, entries: Vec<WireEntry<T>>, place: &dyn Fn() -> String) -> Result<Register<T>, DeltaError> {
        check_len(place, entries.len())?;
        let mut values: SmallVec<[Entry<T>; 1]> = SmallVec::with_capacity(entries.len());
        for (index, entry) in entries.into_iter().enumerate() {
            let entry_place = || format!("{} value {index}", place());
            let dot = self.stored_dot(entry.dot, &entry_place)?;
            if values.iter().any(|e| e.dot == dot) {
                return Err(limit(entry_place(), format!("dot {dot} listed twice")));
            }
            values.push(Entry { dot, stamp: Stamp(u64::from_le_bytes(entry.stamp)), value: entry.value });
        }
        values.sort_unstable_by_key(|entry| entry.dot);
        Ok(Register { values })
    }

    fn attrs(&self, registers: Vec<WireRegister<'_>>, owner: &dyn Fn() -> String) -> Result<Attrs, DeltaError> {
        check_len(owner, registers.len())?;
        let mut attrs = Attrs::new();
        for register in registers {
            let name = match register.name {
                WireName::Builtin(code) => crate::dictionary::interned_attr(code)
                    .ok_or_else(|| invalid(owner(), format!("unknown built-in attribute code {code}")))?,
                WireName::Text(text) => {
                    check_type_name(|| format!("{} attribute {text:?}", owner()), "attribute name", text)?;
                    Name::new(text)
                }
            };
            let place = || format!("{} attribute {name:?}", owner());
            let values = self.entries(register.values, &place)?;
            if attrs.insert(name.clone(), values).is_some() {
                return Err(limit(place(), "attribute listed twice"));
            }
        }
        Ok(attrs)
    }

    fn node(&self, node: WireNode<'_>) -> Result<(NodeId, NodeEntry), DeltaError> {
        let id = node.id;
        if id == 0 {
            return Err(invalid("node list", "node id 0"));
        }
        let owner = || format!("node {id}");
        let mut core = Register::default();
        check_len(owner, node.core.len())?;
        for (index, entry) in node.core.into_iter().enumerate() {
            let place = || format!("node {id} core value {index}");
            let dot = self.stored_dot(entry.dot, &place)?;
            let (node_type, name) = entry.value;
            check_type_name(place, "node type", node_type)?;
            if !crate::ids::valid_node_name(name) {
                return Err(DeltaError::InvalidNodeName { place: place(), name: name.chars().take(64).collect() });
            }
            if core.values.iter().any(|e: &Entry<NodeCore>| e.dot == dot) {
                return Err(limit(place(), format!("dot {dot} listed twice")));
            }
            core.values.push(Entry {
                dot,
                stamp: Stamp(u64::from_le_bytes(entry.stamp)),
                value: NodeCore { node_type: crate::dictionary::intern_type(node_type), name: Name::new(name) },
            });
        }
        core.values.sort_unstable_by_key(|entry| entry.dot);
        let attrs = self.attrs(node.attrs, &owner)?;
        Ok((NodeId(id), NodeEntry { core, attrs }))
    }

    fn edge(&self, edge: WireEdge<'_>) -> Result<(EdgeKey, EdgeEntry), DeltaError> {
        let place = || format!("edge {}->{}", edge.from, edge.to);
        if edge.from == 0 || edge.to == 0 {
            return Err(invalid(place(), "node id 0"));
        }
        check_type_name(place, "edge type", edge.edge_type)?;
        let key = EdgeKey {
            from: NodeId(edge.from),
            to: NodeId(edge.to),
            edge_type: crate::dictionary::intern_type(edge.edge_type),
        };
        let owner = || format!("edge {key}");
        let presence = self.entries(edge.presence, &|| format!("edge {key} presence"))?;
        let attrs = self.attrs(edge.attrs, &owner)?;
        Ok((key, EdgeEntry { presence, attrs }))
    }
}

fn from_wire(
    wire: WireDelta<'_>,
    complete: bool,
    clock: Option<[u8; 8]>,
    applied: Option<WireContext>,
) -> Result<Delta, DeltaError> {
    let origin = Decoder::origin(wire.origin)?;
    let mut decoder = Decoder { origin, ctx: CausalContext::default() };
    check_len(|| "context", wire.vv.len().saturating_add(wire.cloud.len()))?;
    let mut vv = Vec::with_capacity(wire.vv.len());
    for (replica, counter) in &wire.vv {
        if *replica == 0 {
            return Err(invalid("context version vector", "replica id 0"));
        }
        vv.push((ReplicaId(*replica), *counter));
    }
    let mut cloud = Vec::with_capacity(wire.cloud.len());
    for (index, wire_dot) in wire.cloud.iter().enumerate() {
        cloud.push(decoder.dot(*wire_dot, &|| format!("context dot {index}"))?);
    }
    decoder.ctx = CausalContext::from_parts(vv, cloud);
    if let Some(o) = origin {
        for generated in o.dots() {
            decoder.ctx.insert(generated);
        }
    }

    let mut store = Store::default();
    check_len(|| "tombstones", wire.tombstones.len())?;
    for id in &wire.tombstones {
        if *id == 0 {
            return Err(invalid("tombstones", "node id 0"));
        }
        store.tombstones.insert(NodeId(*id));
    }
    check_len(|| "nodes", wire.nodes.len())?;
    for node in wire.nodes {
        let (id, entry) = decoder.node(node)?;
        if store.nodes.insert(id, entry).is_some() {
            return Err(limit(format!("node {id}"), "node listed twice"));
        }
    }
    check_len(|| "edges", wire.edges.len())?;
    for edge in wire.edges {
        let (key, entry) = decoder.edge(edge)?;
        if store.edges.contains_key(&key) {
            return Err(limit(format!("edge {key}"), "edge listed twice"));
        }
        store.edges.insert(key, entry);
    }
    let applied = match applied {
        None => CausalContext::default(),
        Some((vv, cloud)) => {
            check_len(|| "applied operations", vv.len().saturating_add(cloud.len()))?;
            if vv.iter().chain(&cloud).any(|(replica, _)| *replica == 0) {
                return Err(invalid("applied operations", "replica id 0"));
            }
            if cloud.iter().any(|(_, counter)| *counter == 0) {
                return Err(invalid("applied operations", "dot counter 0"));
            }
            CausalContext::from_parts(
                vv.into_iter().map(|(r, c)| (ReplicaId(r), c)).collect(),
                cloud.into_iter().map(|(r, c)| Dot::new(ReplicaId(r), c)).collect(),
            )
        }
    };
    let mut delta = Delta {
        origin,
        complete,
        clock: Stamp(0),
        ctx: decoder.ctx,
        applied,
        store,
        plant: crate::mutants::Plant::NONE,
    };
    delta.clock = match clock {
        Some(bytes) => Stamp(u64::from_le_bytes(bytes)),
        None => max_value_stamp(&delta.borrowed()),
    };
    Ok(delta)
}
