//! The wire format is frozen (version 1): these tests pin it.
//!
//! - Golden values: the exact bytes of a few small deltas, and BLAKE3 hashes of every delta and snapshot of a fixed
//!   history that uses all 14 value types, built-in and other names, concurrent values, removals, deletions and
//!   out-of-order delivery, and of the snapshot of a 1,000-node graph.
//! - The codec against [`reference`], the code it replaced: the same bytes for every delta and snapshot of random
//!   histories; the same decoded delta, or an error in both, for damaged bytes; and for arbitrary wire structures
//!   (built from the reference's own types, so they are well-formed postcard with ids, dots and names anywhere) the
//!   same result, errors included.

use std::sync::{Arc, LazyLock};

use proptest::prelude::*;

use super::reference::{self, WireDelta, WireDot, WireEdge, WireEntry, WireName, WireNode, WireRegister};
use super::*;
use crate::ids::{EdgeKey, Element};
use crate::replica::{NewNode, Replica};
use crate::value::ValueType;

/// Attribute writes covering every value type, with built-in and other names.
fn attr_value(index: usize, k: u32) -> (&'static str, Value) {
    let f = k as f32 * 0.25 - 1.0;
    match index % 17 {
        0 => ("pos_x", Value::F32(f)),
        1 => ("level", Value::I32(k as i32 - 3)),
        2 => ("color", Value::from(format!("colour {k}").as_str())),
        3 => ("rt_translation", Value::from(vec![f, 2.0, -0.0])),
        4 => ("collide", Value::Bool(k.is_multiple_of(2))),
        5 => ("cam_rgb", Value::Bytes(bytes::Bytes::from(vec![k as u8; (k as usize % 5) * 7]))),
        6 => ("agent_id", Value::U32(k)),
        7 => ("stamp_ns", Value::U64(u64::MAX - u64::from(k))),
        8 => ("gps_latitude", Value::F64(f64::from(k) * 1e-3)),
        9 => ("custom_u64s", Value::from(vec![1u64, u64::from(k), u64::MAX])),
        10 => ("track_velocity_mm_s", Value::F32x2([f, f32::NAN])),
        11 => ("imu_angular_velocity", Value::F32x3([f, 0.0, f32::INFINITY])),
        12 => ("imu_orientation", Value::F32x4([0.0, 0.0, 0.0, 1.0])),
        13 => ("custom_f32x6", Value::F32x6([1.0, 2.0, 3.0, 4.0, 5.0, f])),
        14 => ("custom_text", Value::from("")),
        // A vector too long for a small stack buffer, and an empty one.
        15 => ("laser_dists", Value::from((0..(k % 3) * 150).map(|i| i as f32 * 0.5).collect::<Vec<f32>>())),
        _ => ("lidar_points_x", Value::from(Vec::<f32>::new())),
    }
}

/// One operation or delivery of a history over three replicas; indices are reduced modulo what exists.
#[derive(Clone, Debug)]
enum Step {
    InsertNode { replica: usize, name: usize, attrs: usize },
    DeleteNode { replica: usize, pick: usize },
    InsertEdge { replica: usize, from: usize, to: usize, custom: bool },
    DeleteEdge { replica: usize, pick: usize },
    SetAttrs { replica: usize, pick: usize, on_edge: bool, attr: usize, count: usize, k: u32 },
    RemoveAttr { replica: usize, pick: usize, attr: usize },
    Deliver { pick: usize },
}

fn step() -> impl Strategy<Value = Step> {
    let r = 0..3usize;
    prop_oneof![
        3 => (r.clone(), 0..8usize, 0..4usize).prop_map(|(replica, name, attrs)| Step::InsertNode { replica, name, attrs }),
        1 => (r.clone(), any::<usize>()).prop_map(|(replica, pick)| Step::DeleteNode { replica, pick }),
        3 => (r.clone(), any::<usize>(), any::<usize>(), any::<bool>())
            .prop_map(|(replica, from, to, custom)| Step::InsertEdge { replica, from, to, custom }),
        1 => (r.clone(), any::<usize>()).prop_map(|(replica, pick)| Step::DeleteEdge { replica, pick }),
        5 => (r.clone(), any::<usize>(), any::<bool>(), 0..17usize, 1..4usize, 0..20u32).prop_map(
            |(replica, pick, on_edge, attr, count, k)| Step::SetAttrs { replica, pick, on_edge, attr, count, k }
        ),
        1 => (r, any::<usize>(), 0..17usize).prop_map(|(replica, pick, attr)| Step::RemoveAttr { replica, pick, attr }),
        5 => any::<usize>().prop_map(|pick| Step::Deliver { pick }),
    ]
}

/// Runs a history; returns the replicas and every delta made, in order.
fn run(steps: &[Step]) -> (Vec<Replica>, Vec<Arc<Delta>>) {
    let mut replicas: Vec<Replica> =
        (1..=3).map(|id| Replica::with_dictionary(ReplicaId(id), Dictionary::permissive())).collect();
    let mut in_flight: Vec<(usize, Arc<Delta>)> = Vec::new();
    let mut made_all = Vec::new();
    for (now, step) in (1u64..).zip(steps) {
        // Slow time, so stamps tie; and far from zero, so stamps take every varint length.
        let now = (now / 3) << 20;
        let node = |r: &Replica, pick: usize| {
            let ids: Vec<NodeId> = r.nodes().map(|n| n.id()).collect();
            (!ids.is_empty()).then(|| ids[pick % ids.len()])
        };
        let edge = |r: &Replica, pick: usize| {
            let keys: Vec<EdgeKey> = r.edges().map(|e| e.key().clone()).collect();
            (!keys.is_empty()).then(|| keys[pick % keys.len()].clone())
        };
        let made: Option<(usize, Arc<Delta>)> = match *step {
            Step::InsertNode { replica, name, attrs } => {
                let node_type = if name % 3 == 0 { "custom_type" } else { "transform" };
                let mut new = NewNode::new(node_type, &format!("n{name}"));
                for a in 0..attrs {
                    let (attr, value) = attr_value(name + a * 5, (name * 7 + a) as u32);
                    new = new.with_attr(attr, value);
                }
                replicas[replica].insert_node(now, new).ok().map(|(_, d)| (replica, d))
            }
            Step::DeleteNode { replica, pick } => node(&replicas[replica], pick)
                .and_then(|id| replicas[replica].delete_node(now, id).ok())
                .map(|d| (replica, d)),
            Step::InsertEdge { replica, from, to, custom } => {
                match (node(&replicas[replica], from), node(&replicas[replica], to)) {
                    (Some(from), Some(to)) => {
                        let edge_type = if custom { "custom_edge" } else { "RT" };
                        let (attr, value) = attr_value(from.0 as usize, to.0 as u32);
                        replicas[replica]
                            .insert_edge(now, from, to, edge_type, vec![(attr.to_owned(), value)])
                            .ok()
                            .map(|(_, d)| (replica, d))
                    }
                    _ => None,
                }
            }
            Step::DeleteEdge { replica, pick } => edge(&replicas[replica], pick)
                .and_then(|key| replicas[replica].delete_edge(now, &key).ok())
                .map(|d| (replica, d)),
            Step::SetAttrs { replica, pick, on_edge, attr, count, k } => {
                let element = if on_edge {
                    edge(&replicas[replica], pick).map(Element::Edge)
                } else {
                    node(&replicas[replica], pick).map(Element::Node)
                };
                let writes: Vec<(&str, Value)> = (0..count).map(|i| attr_value(attr + i, k + i as u32)).collect();
                element.and_then(|e| replicas[replica].set_attrs(now, e, writes).ok()).map(|d| (replica, d))
            }
            Step::RemoveAttr { replica, pick, attr } => node(&replicas[replica], pick)
                .and_then(|id| replicas[replica].remove_attr(now, id, attr_value(attr, 0).0).ok())
                .map(|d| (replica, d)),
            Step::Deliver { pick } => {
                if !in_flight.is_empty() {
                    let (to, delta) = in_flight.swap_remove(pick % in_flight.len());
                    replicas[to].apply(&delta).expect("our own deltas apply");
                }
                None
            }
        };
        if let Some((from, delta)) = made {
            for to in (0..3).filter(|to| *to != from) {
                in_flight.push((to, Arc::clone(&delta)));
            }
            made_all.push(delta);
        }
    }
    (replicas, made_all)
}

/// A fixed pseudo-random history (a linear congruential generator, so it needs no seed file).
fn fixed_history() -> Vec<Step> {
    let mut state = 0x2545_f491_4f6c_dd1du64;
    let mut next = move || {
        state = state.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1_442_695_040_888_963_407);
        (state >> 33) as usize
    };
    let mut steps: Vec<Step> = (0..400)
        .map(|_| {
            let replica = next() % 3;
            match next() % 19 {
                0..=2 => Step::InsertNode { replica, name: next() % 8, attrs: next() % 4 },
                3 => Step::DeleteNode { replica, pick: next() },
                4..=6 => Step::InsertEdge { replica, from: next(), to: next(), custom: next().is_multiple_of(2) },
                7 => Step::DeleteEdge { replica, pick: next() },
                8..=12 => Step::SetAttrs {
                    replica,
                    pick: next(),
                    on_edge: next().is_multiple_of(2),
                    attr: next() % 17,
                    count: 1 + next() % 3,
                    k: (next() % 20) as u32,
                },
                13 => Step::RemoveAttr { replica, pick: next(), attr: next() % 17 },
                _ => Step::Deliver { pick: next() },
            }
        })
        .collect();
    // Then every delta delivered, concurrent writes to the same registers, and every delta delivered again.
    steps.extend((0..2000).map(|_| Step::Deliver { pick: next() }));
    for pick in 0..6 {
        for replica in 0..3 {
            steps.push(Step::SetAttrs { replica, pick, on_edge: pick % 2 == 1, attr: pick, count: 2, k: pick as u32 });
        }
    }
    steps.extend((0..2000).map(|_| Step::Deliver { pick: next() }));
    // Then four writes of one replica, of which only the last reaches another (out-of-order dots).
    steps.extend((0..4).map(|k| Step::SetAttrs { replica: 0, pick: k, on_edge: false, attr: k, count: 1, k: 0 }));
    steps.push(Step::Deliver { pick: 6 });
    steps
}

/// The benchmark's graph: `n` nodes with 6 attributes each and an RT edge from a parent (a tree of fan-out 10).
fn bench_graph(n: usize) -> Replica {
    let mut r = Replica::new(ReplicaId(1));
    let mut ids = Vec::with_capacity(n);
    let mut t = 1_800_000_000_000_000_000u64;
    for i in 0..n {
        t += 1;
        let node = NewNode::new("transform", &format!("node{i}"))
            .with_attr("pos_x", i as f32)
            .with_attr("pos_y", 0.5f32)
            .with_attr("color", "SeaGreen")
            .with_attr("width", 100)
            .with_attr("height", 200)
            .with_attr("depth", 300);
        let (id, _) = r.insert_node(t, node).unwrap();
        if i > 0 {
            r.set_rt(t, ids[(i - 1) / 10], id, [10.0, 20.0, 30.0], [0.0, 0.0, 0.1]).unwrap();
        }
        ids.push(id);
    }
    r
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// BLAKE3 of a list of encodings, each prefixed by its length.
fn hash_all<'a>(encodings: impl IntoIterator<Item = &'a [u8]>) -> String {
    let mut hasher = blake3::Hasher::new();
    for bytes in encodings {
        hasher.update(&(bytes.len() as u64).to_le_bytes());
        hasher.update(bytes);
    }
    hasher.finalize().to_hex().to_string()
}

#[test]
fn small_deltas_encode_to_pinned_bytes() {
    let mut a = Replica::new(ReplicaId(3));
    let (x, insert) =
        a.insert_node(1_700_000_000_000_000_000, NewNode::new("object", "x").with_attr("level", 2)).unwrap();
    let (y, _) = a.insert_node(1_700_000_000_000_000_001, NewNode::new("object", "y")).unwrap();
    let set = a.set_attr(1_700_000_000_000_000_002, x, crate::attrs::POS_X, 1.5).unwrap();
    let (_, edge) = a.insert_edge(1_700_000_000_000_000_003, x, y, "RT", Vec::new()).unwrap();
    let delete = a.delete_node(1_700_000_000_000_000_004, y).unwrap();
    let encoded: Vec<String> = [&insert, &set, &edge, &delete].iter().map(|d| hex(&d.encode())).collect();
    let snapshot = hex(&a.encode_snapshot());
    let expected = [
        "080103010200000001818080803001000000002a36fe9c9717066f626a656374017801000501000200002a36fe9c9717010400",
        "08010304010000000181808080300001000601000002002a36fe9c9717020000c03f00",
        "080103050100000000018180808030828080803002525401000003002a36fe9c971700",
        "0a01030601000200050001018280808030000004002a36fe9c9717",
    ];
    assert_eq!(encoded, expected, "wire version 1 bytes of small deltas changed");
    assert_eq!(
        snapshot,
        "0f00010306000182808080300181808080300101030100002a36fe9c9717066f626a65637401780200050101030200002a36fe9c9717010400060101030402002a36fe9c9717020000c03f0004002a36fe9c971701030600",
        "wire version 1 bytes of a small snapshot changed"
    );
}

#[test]
fn a_fixed_history_encodes_to_pinned_bytes() {
    let (replicas, deltas) = run(&fixed_history());
    // What the history is meant to cover.
    let types: std::collections::BTreeSet<ValueType> = deltas
        .iter()
        .flat_map(|d| d.store.nodes.values().map(|n| &n.attrs).chain(d.store.edges.values().map(|e| &e.attrs)))
        .flat_map(|attrs| attrs.values().flat_map(|r| r.values.iter().map(|e| e.value.value_type())))
        .collect();
    assert_eq!(types.len(), 14, "every value type");
    assert!(replicas.iter().any(|r| r.context().cloud_len() > 0), "out-of-order dots");
    assert!(replicas.iter().any(|r| !r.store().tombstones.is_empty()), "deleted nodes");
    let concurrent = |attrs: &Attrs| attrs.values().any(|a| a.values.len() > 1);
    let store = |r: &Replica| {
        r.store().nodes.values().any(|n| n.core.values.len() > 1 || concurrent(&n.attrs))
            || r.store().edges.values().any(|e| e.presence.values.len() > 1 || concurrent(&e.attrs))
    };
    assert!(replicas.iter().any(store), "concurrent values");
    assert!(deltas.iter().any(|d| d.clock != reference::max_value_stamp(&d.borrowed())), "deltas whose clock travels");
    let delta_bytes: Vec<Vec<u8>> = deltas.iter().map(|d| d.encode()).collect();
    let snapshots: Vec<Vec<u8>> = replicas.iter().map(Replica::encode_snapshot).collect();
    let total: usize = delta_bytes.iter().map(Vec::len).sum();
    assert_eq!((deltas.len(), total), (251, 22741), "the fixed history changed");
    assert_eq!(
        hash_all(delta_bytes.iter().map(Vec::as_slice)),
        "74572464c065f60c766bb3bfbd3faef435fc080a8c8a156ee2a416df5ce3b8c9",
        "wire bytes of deltas changed"
    );
    let sizes: Vec<usize> = snapshots.iter().map(Vec::len).collect();
    assert_eq!(sizes, [2783, 2851, 2815], "the fixed history's snapshots changed");
    assert_eq!(
        hash_all(snapshots.iter().map(Vec::as_slice)),
        "15015f244d900959a56b41e29c1e9e9560ed4016f8446ecc69388eb04c341cd2",
        "wire bytes of snapshots changed"
    );
    for (bytes, delta) in delta_bytes.iter().zip(&deltas) {
        assert_eq!(&Delta::decode(bytes).unwrap(), &**delta);
    }
    for (bytes, replica) in snapshots.iter().zip(&replicas) {
        assert_eq!(Delta::decode(bytes).unwrap(), replica.snapshot());
    }
}

#[test]
fn the_bench_graph_snapshot_encodes_to_pinned_bytes() {
    let replica = bench_graph(1000);
    let bytes = replica.encode_snapshot();
    assert_eq!(bytes.len(), 278_657);
    assert_eq!(
        hash_all([bytes.as_slice()]),
        "7aeb3b819c8174eb41eb2e8efcb636d1b9f79307f7838480aeac03a6e3c9b8c1",
        "wire bytes of the graph snapshot changed"
    );
    assert_eq!(Delta::decode(&bytes).unwrap(), replica.snapshot());
}

// ---------------------------------------------------------------------------------------------------------------
// Arbitrary wire structures, for both decoders: mostly valid parts, so that decoding gets deep before it fails.

static LONG_NAME: LazyLock<String> = LazyLock::new(|| "x".repeat(256));

/// One of `valid` mostly, else one of `invalid` or a 256-byte name.
fn pick_str(
    valid: &'static [&'static str],
    invalid: &'static [&'static str],
) -> impl Strategy<Value = &'static str> + Clone {
    prop_oneof![
        8 => prop::sample::select(valid),
        1 => (0..invalid.len() + 1).prop_map(move |i| invalid.get(i).copied().unwrap_or(LONG_NAME.as_str())),
    ]
}

fn id() -> impl Strategy<Value = u64> + Clone {
    prop_oneof![8 => 1..5u64, 1 => Just(0u64)]
}

fn wire_dot() -> impl Strategy<Value = WireDot> + Clone {
    prop_oneof![
        6 => (0..3i64).prop_map(WireDot::Same),
        1 => (-3..4i64).prop_map(WireDot::Same),
        3 => (1..3u32, 1..5u64).prop_map(|(r, c)| WireDot::Other(r, c)),
        1 => (0..3u32, 0..5u64).prop_map(|(r, c)| WireDot::Other(r, c)),
    ]
}

fn wire_entry<T: std::fmt::Debug + Clone>(
    value: impl Strategy<Value = T> + Clone,
) -> impl Strategy<Value = WireEntry<T>> + Clone {
    (wire_dot(), 0..3u64, value).prop_map(|(dot, stamp, value)| WireEntry {
        dot,
        stamp: (stamp << 40).to_le_bytes(),
        value,
    })
}

fn any_value() -> impl Strategy<Value = Value> + Clone {
    (0..17usize, 0..30u32).prop_map(|(index, k)| attr_value(index, k).1)
}

fn wire_register() -> impl Strategy<Value = WireRegister<'static>> + Clone {
    let name = prop_oneof![
        4 => (0..8u16).prop_map(WireName::Builtin),
        1 => prop_oneof![80..100u16, Just(u16::MAX)].prop_map(WireName::Builtin),
        4 => pick_str(&["pos_x", "custom"], &["", "bad\u{1}"]).prop_map(WireName::Text),
    ];
    (name, prop::collection::vec(wire_entry(any_value()), 0..3))
        .prop_map(|(name, values)| WireRegister { name, values })
}

fn wire_delta() -> impl Strategy<Value = WireDelta<'static>> {
    let core =
        wire_entry((pick_str(&["transform", "other"], &[""]), pick_str(&["a", "b", "c"], &["a#1", "", "c\u{7}"])));
    let node = (id(), prop::collection::vec(core, 0..3), prop::collection::vec(wire_register(), 0..3))
        .prop_map(|(id, core, attrs)| WireNode { id, core, attrs });
    let edge = (
        id(),
        id(),
        pick_str(&["RT", "other"], &[""]),
        prop::collection::vec(wire_entry(Just(())), 0..3),
        prop::collection::vec(wire_register(), 0..2),
    )
        .prop_map(|(from, to, edge_type, presence, attrs)| WireEdge { from, to, edge_type, presence, attrs });
    let origin = prop_oneof![
        2 => Just(None),
        8 => (1..3u32, 1..4u64, 1..4u32).prop_map(Some),
        1 => (0..3u32, prop_oneof![0..3u64, Just(u64::MAX)], prop_oneof![0..3u32, Just(u32::MAX)]).prop_map(Some),
    ];
    (
        origin,
        prop::collection::vec((prop_oneof![8 => 1..3u32, 1 => Just(0u32)], 0..5u64), 0..3),
        prop::collection::vec(wire_dot(), 0..3),
        prop::collection::vec(id(), 0..3),
        prop::collection::vec(node, 0..4),
        prop::collection::vec(edge, 0..3),
    )
        .prop_map(|(origin, vv, cloud, tombstones, nodes, edges)| WireDelta {
            origin,
            vv,
            cloud,
            tombstones,
            nodes,
            edges,
        })
}

/// An arbitrary body in its frame: header, clock and applied operations consistent with the flags (mostly),
/// trailing bytes (sometimes). Also says whether the frame is consistent.
fn framed() -> impl Strategy<Value = (Vec<u8>, bool)> {
    let pairs = || prop::collection::vec((prop_oneof![8 => 1..3u32, 1 => Just(0u32)], 0..5u64), 0..3);
    (
        wire_delta(),
        any::<bool>(),
        prop::option::of(prop_oneof![Just(0u64), Just(1 << 40), any::<u64>()]),
        prop::option::of((pairs(), pairs())),
        prop_oneof![8 => Just((0u8, 0u8)), 1 => (0..8u8, 0..32u8)],
        prop_oneof![8 => Just(Vec::new()), 1 => prop::collection::vec(any::<u8>(), 1..3)],
    )
        .prop_map(|(wire, complete, clock, applied, (flip_flags, flip_version), trailing)| {
            let mut header = WIRE_VERSION << 3;
            header |= if complete { FLAG_COMPLETE } else { 0 };
            header |= if clock.is_some() { FLAG_CLOCK } else { 0 };
            header |= if applied.is_some() { FLAG_APPLIED } else { 0 };
            header ^= flip_flags | (flip_version << 3);
            let mut bytes = vec![header];
            bytes = postcard::to_extend(&wire, bytes).unwrap();
            if let Some(clock) = clock {
                bytes.extend_from_slice(&clock.to_le_bytes());
            }
            if let Some(applied) = applied {
                bytes = postcard::to_extend(&applied, bytes).unwrap();
            }
            let clean = trailing.is_empty() && flip_flags == 0;
            bytes.extend_from_slice(&trailing);
            (bytes, clean)
        })
}

/// Both decoders' verdicts on `bytes`: equal deltas, or errors in both (equal errors if `exact`).
fn same_verdict(bytes: &[u8], exact: bool) -> Result<(), TestCaseError> {
    let new = Delta::decode(bytes);
    let old = reference::decode(bytes);
    match (&new, &old) {
        (Ok(new), Ok(old)) => prop_assert_eq!(new, old),
        (Err(new), Err(old)) => {
            if exact {
                prop_assert_eq!(new, old);
            }
        }
        _ => prop_assert!(false, "decoders disagree on {}: now {:?}, before {:?}", hex(bytes), new, old),
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 256, ..ProptestConfig::default() })]

    /// Every delta and snapshot of a random history encodes to the reference's bytes, and decodes to what it was.
    #[test]
    fn encoding_matches_the_reference(steps in prop::collection::vec(step(), 1..80)) {
        let (replicas, deltas) = run(&steps);
        for delta in &deltas {
            let bytes = delta.encode();
            prop_assert_eq!(&bytes, &reference::encode(delta));
            prop_assert_eq!(&Delta::decode(&bytes).unwrap(), &**delta);
            let mut appended = vec![0xAA];
            delta.encode_into(&mut appended);
            prop_assert_eq!(&appended[1..], &bytes[..], "encode_into appends");
        }
        for replica in &replicas {
            let snapshot = replica.snapshot();
            let bytes = replica.encode_snapshot();
            prop_assert_eq!(&bytes, &reference::encode(&snapshot));
            prop_assert_eq!(&bytes, &snapshot.encode());
            prop_assert_eq!(Delta::decode(&bytes).unwrap(), snapshot);
        }
    }

    /// Truncated and bit-flipped snapshots and deltas: both decoders accept the same, and decode it the same.
    #[test]
    fn damaged_bytes_get_the_reference_verdict(
        steps in prop::collection::vec(step(), 1..60),
        pick in any::<usize>(),
        cut in any::<usize>(),
        flips in prop::collection::vec((any::<usize>(), 0..8u32), 1..4),
    ) {
        let (replicas, deltas) = run(&steps);
        let bytes = if pick % 3 == 0 || deltas.is_empty() {
            replicas[pick % 3].encode_snapshot()
        } else {
            deltas[pick % deltas.len()].encode()
        };
        same_verdict(&bytes[..cut % (bytes.len() + 1)], false)?;
        let mut flipped = bytes.clone();
        for (at, bit) in flips {
            let at = at % flipped.len();
            flipped[at] ^= 1 << bit;
        }
        same_verdict(&flipped, false)?;
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 2048, ..ProptestConfig::default() })]

    /// Arbitrary well-formed wire structures (zero ids, dots outside the context, bad names, duplicates, bad
    /// origins, inconsistent flags): the same delta or the same error as the reference. With trailing bytes, the
    /// reference reports them (and a frame inconsistent with its flags) before any problem of the body, so only the
    /// verdict is compared.
    #[test]
    fn arbitrary_wire_structures_get_the_reference_result((bytes, clean) in framed()) {
        same_verdict(&bytes, clean)?;
    }

    /// Random bytes: the same verdict as the reference.
    #[test]
    fn random_bytes_get_the_reference_verdict(bytes in prop::collection::vec(any::<u8>(), 0..64)) {
        same_verdict(&bytes, false)?;
    }
}

/// The byte value that a decoded delta holds for `name` on node `id`.
fn byte_value(delta: &Delta, id: crate::ids::NodeId, name: &str) -> bytes::Bytes {
    match &delta.store.nodes[&id].attrs[name].values[0].value {
        Value::Bytes(bytes) => bytes.clone(),
        other => panic!("not bytes: {other:?}"),
    }
}

/// Decoding from a shared buffer gives the same delta as decoding a copy; a frame in a one-operation delta is a slice
/// of the received buffer (no copy per receiver), a small value and the values of a large snapshot are copies.
#[test]
fn a_frame_decoded_from_a_shared_buffer_is_a_slice_of_it_and_small_values_are_copies() {
    let mut writer = Replica::new(ReplicaId(1));
    let (camera, _) = writer.insert_node(1, NewNode::new("camera", "cam")).unwrap();
    let frame = Value::Bytes(vec![7u8; 360_960].into());
    let delta = writer.set_attrs(2, camera, [("cam_rgb", frame)]).unwrap();
    let sample = bytes::Bytes::from(delta.encode());
    let shared = Delta::decode_shared(&sample).unwrap();
    assert_eq!(shared, Delta::decode(&sample).unwrap());
    let value = byte_value(&shared, camera, "cam_rgb");
    assert!(sample.as_ptr_range().contains(&value.as_ptr()), "the frame was copied");

    let small = writer.set_attrs(3, camera, [("cam_rgb", Value::Bytes(vec![1u8; 100].into()))]).unwrap();
    let sample = bytes::Bytes::from(small.encode());
    let value = byte_value(&Delta::decode_shared(&sample).unwrap(), camera, "cam_rgb");
    assert!(!sample.as_ptr_range().contains(&value.as_ptr()), "a small value shares the buffer");

    for i in 0..8 {
        let (other, _) = writer.insert_node(4 + i, NewNode::new("camera", &format!("cam{i}"))).unwrap();
        writer.set_attrs(20 + i, other, [("cam_rgb", Value::Bytes(vec![i as u8; 100_000].into()))]).unwrap();
    }
    let snapshot = bytes::Bytes::from(writer.snapshot().encode());
    let decoded = Delta::decode_shared(&snapshot).unwrap();
    for (_, node) in decoded.store.nodes.iter().filter(|(_, node)| node.attrs.contains_key("cam_rgb")) {
        let Value::Bytes(value) = &node.attrs["cam_rgb"].values[0].value else { panic!("not bytes") };
        assert!(!snapshot.as_ptr_range().contains(&value.as_ptr()), "a snapshot's value holds the whole snapshot");
    }
}

/// A copy of `bytes` in a buffer of its own that starts `misalign` bytes past an 8-byte boundary, as shared.
fn placed(bytes: &[u8], misalign: usize) -> bytes::Bytes {
    let mut buffer = vec![0u8; bytes.len() + 16];
    let start = buffer.as_ptr().align_offset(8) + misalign;
    buffer[start..start + bytes.len()].copy_from_slice(bytes);
    bytes::Bytes::from(buffer).slice(start..start + bytes.len())
}

/// A point cloud's columns are written at a multiple of their element's size from the start of the buffer the delta
/// is encoded into, whatever comes before the delta there (an envelope of any length): decoded from a shared buffer
/// that starts aligned, each column is a view of it (no copy per receiver); from one that does not, a copy of the
/// same values. The padding is zero groups in varints, which postcard and the reference decoder read as the same
/// numbers.
#[test]
fn point_cloud_columns_land_aligned_and_are_views_of_an_aligned_buffer() {
    let mut writer = Replica::with_dictionary(ReplicaId(1), Dictionary::permissive());
    let (lidar, _) = writer.insert_node(1, NewNode::new("lidar", "ouster")).unwrap();
    // Columns of 16 KiB and, under the 16 KiB up to which a `u64` vector is always placed aligned, 12 KiB of ids.
    let column = |k: f32| Value::VecF32((0..4_096).map(|i| i as f32 * k).collect());
    let ids = Value::VecU64((0..1_536).map(|i| i * 3).collect());
    let columns = [("x", column(1.0)), ("y", column(-0.5)), ("z", column(0.25)), ("ids", ids)];
    let delta = writer.set_attrs(2, lidar, columns.clone()).unwrap();
    for before in 0..16 {
        let mut sample = vec![0xEE; before];
        delta.encode_into(&mut sample);
        let encoded = &sample[before..];
        assert_eq!(Delta::decode(encoded).unwrap(), *delta, "{before} bytes before");
        assert_eq!(reference::decode(encoded).unwrap(), *delta, "{before} bytes before");
        for misalign in [0, 1, 4] {
            let buffer = placed(&sample, misalign);
            let decoded = Delta::decode_shared(&buffer.slice(before..)).unwrap();
            let (f32_views, u64_views) = (u64::from(misalign % 4 == 0), u64::from(misalign % 8 == 0));
            let shared = 3 * f32_views + u64_views;
            let counted = if cfg!(target_endian = "little") {
                LargeValues { shared, copied: 4 - shared }
            } else {
                LargeValues::default()
            };
            assert_eq!(decoded.large_values_in(&buffer), counted, "{before} bytes before, {misalign} past alignment");
            let attrs = &decoded.store.nodes[&lidar].attrs;
            for (name, value) in &columns {
                let got = &attrs[*name].values[0].value;
                assert_eq!(got, value, "{name}");
                let (view, align) = match got {
                    Value::VecF32(numbers) => (numbers.is_view(), 4),
                    Value::VecU64(numbers) => (numbers.is_view(), 8),
                    other => panic!("{name} is {other:?}"),
                };
                let expected = misalign % align == 0 && cfg!(target_endian = "little");
                assert_eq!(view, expected, "{name}: {before} bytes before, buffer {misalign} past alignment");
            }
        }
    }
}

/// A block's head puts the block at a multiple of its alignment (always for 4, for 8 as far as 5-byte varints
/// reach), keeps each varint within 5 bytes, and reads back as the variant and length, for lengths whose shortest
/// varints take 2 to 4 bytes.
#[test]
fn a_block_head_aligns_what_follows_within_five_byte_varints() {
    for len in [4_096usize, 16_383, 16_384, (1 << 21) - 1, 1 << 21, 1 << 27] {
        for before in 0..8 {
            for listed_apart in [0, 3] {
                for align in [1, 4, 8] {
                    let mut out = vec![0xEE; before];
                    super::aligned_head(&mut out, listed_apart, 9, len, align);
                    let head = &out[before..];
                    let at = before + listed_apart + head.len();
                    // The padding needed, and how much two 5-byte varints can give: 3 + 4, 2 + 4 or 1 + 4 bytes.
                    let canonical = 1 + super::varint_bytes(len as u64);
                    let needed = (align - (before + listed_apart + canonical) % align) % align;
                    let most = (5 - super::varint_bytes(len as u64)) + 4;
                    assert_eq!(
                        at % align == 0,
                        needed <= most,
                        "len {len}, {before}+{listed_apart} before, align {align}"
                    );
                    let (variant, rest) = postcard::take_from_bytes::<u32>(head).unwrap();
                    assert!(head.len() - rest.len() <= 5, "the variant's varint");
                    let (got, tail) = postcard::take_from_bytes::<u32>(rest).unwrap();
                    assert!(rest.len() - tail.len() <= 5 && tail.is_empty(), "the length's varint");
                    assert_eq!((variant, got as usize), (9, len));
                }
            }
        }
    }
}

/// The padded varints `aligned_head` writes are the numbers to postcard.
#[test]
fn padded_varints_read_as_their_numbers() {
    for (value, extra) in [(0u64, 0), (5, 2), (127, 1), (128, 3), (65_536, 7), (u64::from(u32::MAX), 5)] {
        let mut out = Vec::new();
        super::put_varint(&mut out, value, extra);
        assert_eq!(out.len(), super::varint_bytes(value) + extra);
        assert_eq!(postcard::from_bytes::<u64>(&out).unwrap(), value, "{out:?}");
        if out.len() <= 5 && u32::try_from(value).is_ok() {
            assert_eq!(u64::from(postcard::from_bytes::<u32>(&out).unwrap()), value, "{out:?}");
        }
    }
    let mut five = Vec::new();
    super::put_varint(&mut five, 5, 2);
    assert_eq!(five, [0x85, 0x80, 0x00]);
}

/// A delta encoded in pieces is the prefix and the encoding once concatenated, for deltas and snapshots with values
/// around the size that is shared; a value of that size or more is a piece of its own that points into the value
/// (not a copy), a smaller one is copied in.
#[test]
fn pieces_concatenate_to_the_encoding_and_refer_to_the_large_values() {
    let min = Pieces::MIN_SHARED_BYTES;
    let mut writer = Replica::with_dictionary(ReplicaId(1), Dictionary::permissive());
    let (camera, _) = writer.insert_node(1, NewNode::new("camera", "cam")).unwrap();
    let (lidar, _) = writer.insert_node(2, NewNode::new("lidar", "ouster")).unwrap();
    let (rt, _) = writer.insert_edge(3, lidar, camera, "RT", Vec::new()).unwrap();
    for (now, size) in (3..).zip([min - 1, min, min + 1, 360_960]) {
        let frame = bytes::Bytes::from(vec![size as u8; size]);
        let floats = Value::VecF32((0..size / 4).map(|i| i as f32).collect());
        let words = Value::VecU64((0..size / 8).map(|i| i as u64).collect());
        let attrs = [("cam_rgb", Value::Bytes(frame.clone())), ("level", Value::I32(3)), ("cloud_x", floats)];
        let delta = writer.set_attrs(now * 10, camera, attrs).unwrap();
        let edge = writer.set_attrs(now * 10 + 1, rt.clone(), [("ids", words)]).unwrap();
        for (delta, holds_frame) in [(delta, true), (edge, false), (Arc::new(writer.snapshot()), true)] {
            let pieces = delta.encode_pieces(b"head".to_vec());
            let mut whole = b"head".to_vec();
            delta.encode_into(&mut whole);
            assert!(pieces.to_vec() == whole, "size {size}: the pieces are the prefix and the encoding after it");
            let refers = pieces.iter().filter(|piece| piece.as_ptr() == frame.as_ptr()).count();
            let expected = usize::from(holds_frame && size >= min);
            assert_eq!(refers, expected, "size {size}: a large frame is referred to, a small one copied in");
        }
    }
}
