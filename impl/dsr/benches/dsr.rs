//! Criterion benchmarks of the replica's hot paths, against the targets of the DSR issue (one core):
//! ≥ 1 M local small-attribute updates/s, ≥ 1 M delta joins/s, an encoded f32 delta ≤ 40 bytes (pinned by a test),
//! plus a write of a series with a full history, snapshot + join of a 10k-node graph and a transform over a 10-edge
//! chain.
//!
//! Run: `cargo bench -p dsr`. Each figure is per operation; throughput is reported in elements/s.

// criterion_group! generates an undocumented public function.
#![allow(missing_docs)]

use std::hint::black_box;
use std::sync::Arc;
use std::time::{Duration, Instant};

use criterion::{BatchSize, Criterion, Throughput, criterion_group, criterion_main};
use dsr::{Delta, LogLimits, NewNode, NodeId, Replica, ReplicaId, Value, attrs};

const T0: u64 = 1_800_000_000_000_000_000;

/// A replica holding `n` nodes, each with 6 attributes and an RT edge from its parent (a tree of fan-out 10).
fn graph(replica: ReplicaId, n: usize) -> (Replica, Vec<NodeId>) {
    let mut r = Replica::new(replica);
    let mut ids = Vec::with_capacity(n);
    let mut t = T0;
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
            let parent = ids[(i - 1) / 10];
            r.set_rt(t, parent, id, [10.0, 20.0, 30.0], [0.0, 0.0, 0.1]).unwrap();
        }
        ids.push(id);
    }
    (r, ids)
}

fn local_update(c: &mut Criterion) {
    let (mut r, ids) = graph(ReplicaId(1), 1000);
    let mut group = c.benchmark_group("local_update");
    group.throughput(Throughput::Elements(1));
    let mut t = T0 + 1_000_000;
    let mut i = 0usize;
    group.bench_function("f32_attr_1000_node_graph", |b| {
        b.iter(|| {
            t += 1;
            i += 1;
            black_box(r.set_attr(t, ids[i % ids.len()], attrs::POS_X, i as f32).unwrap())
        })
    });
    // One attribute written over and over, as a camera or a pose stream writes it, with every write folding the one
    // before (which holds every earlier write of the series the history keeps, 4,096 once it is full), as writes of
    // 1 KiB and more do by default.
    group.bench_function("f32_attr_series_on_one_node_full_history", |b| {
        r.set_log_limits(LogLimits { fold_min_payload_bytes: 0, ..LogLimits::default() });
        let node = ids[0];
        for _ in 0..5_000 {
            t += 1;
            r.set_attr(t, node, attrs::POS_X, 0.0f32).unwrap();
        }
        b.iter(|| {
            t += 1;
            i += 1;
            black_box(r.set_attr(t, node, attrs::POS_X, i as f32).unwrap())
        })
    });
    group.finish();
}

fn encode_decode(c: &mut Criterion) {
    let (mut r, ids) = graph(ReplicaId(1), 100);
    let delta = r.set_attr(T0 + 10_000, ids[42], attrs::POS_X, 1.5).unwrap();
    let bytes = delta.encode();
    eprintln!("encoded f32 attribute delta: {} bytes", bytes.len());
    let mut group = c.benchmark_group("delta_wire");
    group.throughput(Throughput::Elements(1));
    let mut buffer = Vec::with_capacity(64);
    group.bench_function("encode_f32_delta", |b| {
        b.iter(|| {
            buffer.clear();
            delta.encode_into(&mut buffer);
            black_box(buffer.len())
        })
    });
    group.bench_function("decode_f32_delta", |b| b.iter(|| black_box(Delta::decode(black_box(&bytes)).unwrap())));
    let image = r.set_attr(T0 + 10_001, ids[7], attrs::CAM_RGB, bytes::Bytes::from(vec![7u8; 360_960])).unwrap();
    let image_bytes = image.encode();
    group.throughput(Throughput::Bytes(image_bytes.len() as u64));
    group.bench_function("decode_752x480_mono8_image_delta", |b| {
        b.iter(|| black_box(Delta::decode(black_box(&image_bytes)).unwrap()))
    });
    group.finish();
}

fn delta_join(c: &mut Criterion) {
    // Replica 1 writes; replica 2, which holds the same graph, joins the deltas (each a new write, never a repeat).
    let (mut writer, ids) = graph(ReplicaId(1), 1000);
    let base = writer.snapshot();
    let mut reader = Replica::new(ReplicaId(2));
    reader.apply(&base).unwrap();
    let mut t = T0 + 1_000_000;
    let mut group = c.benchmark_group("delta_join");
    group.throughput(Throughput::Elements(1));
    group.bench_function("f32_attr_1000_node_graph", |b| {
        b.iter_custom(|iters| {
            let mut elapsed = Duration::ZERO;
            let mut left = iters;
            while left > 0 {
                let chunk = left.min(10_000);
                let deltas: Vec<Arc<Delta>> = (0..chunk)
                    .map(|k| {
                        t += 1;
                        writer.set_attr(t, ids[(t as usize) % ids.len()], attrs::POS_X, k as f32).unwrap()
                    })
                    .collect();
                let start = Instant::now();
                for delta in &deltas {
                    reader.apply_shared(Arc::clone(delta)).unwrap();
                }
                elapsed += start.elapsed();
                left -= chunk;
            }
            elapsed
        })
    });
    group.finish();
}

fn snapshot_join(c: &mut Criterion) {
    let (r, _) = graph(ReplicaId(1), 10_000);
    let snapshot = r.snapshot();
    let bytes = snapshot.encode();
    eprintln!("10k-node snapshot: {} bytes ({} per node)", bytes.len(), bytes.len() / 10_000);
    let mut group = c.benchmark_group("snapshot_10k_nodes");
    group.sample_size(10);
    group.bench_function("take_snapshot", |b| b.iter(|| black_box(r.snapshot())));
    group.bench_function("encode", |b| b.iter(|| black_box(snapshot.encode())));
    // What an agent sends a joiner: the same bytes, encoded from the replica's state without copying it.
    group.bench_function("encode_snapshot_from_replica", |b| b.iter(|| black_box(r.encode_snapshot())));
    group.bench_function("decode", |b| b.iter(|| black_box(Delta::decode(&bytes).unwrap())));
    // `apply` of a borrowed snapshot copies it before installing it into the fresh replica.
    group.bench_function("join_into_empty_replica", |b| {
        b.iter_batched(
            || Replica::new(ReplicaId(2)),
            |mut joiner| {
                joiner.apply(&snapshot).unwrap();
                joiner
            },
            BatchSize::LargeInput,
        )
    });
    // An agent's path: the decoded snapshot is moved in (no copy), with change tracking on (the joiner signals
    // every inserted node, edge and attribute).
    group.bench_function("install_owned_snapshot_with_change_tracking", |b| {
        b.iter_batched(
            || {
                let mut joiner = Replica::new(ReplicaId(2));
                joiner.set_change_tracking(true);
                (joiner, Arc::new(Delta::decode(&bytes).unwrap()))
            },
            |(mut joiner, decoded)| {
                joiner.apply_shared(decoded).unwrap();
                let changes = joiner.drain_changes();
                (joiner, changes)
            },
            BatchSize::LargeInput,
        )
    });
    group.bench_function("decode_and_join_end_to_end", |b| {
        b.iter(|| {
            let mut joiner = Replica::new(ReplicaId(2));
            joiner.apply_shared(Arc::new(Delta::decode(&bytes).unwrap())).unwrap();
            joiner
        })
    });
    group.finish();
}

fn transform_chain(c: &mut Criterion) {
    let mut r = Replica::new(ReplicaId(1));
    let mut chain = Vec::new();
    for i in 0..11 {
        let (id, _) = r.insert_node(T0 + i, NewNode::new("transform", &format!("link{i}"))).unwrap();
        if let Some(parent) = chain.last() {
            r.set_rt(T0 + i, *parent, id, [100.0, 0.0, 5.0], [0.01, 0.02, 0.3]).unwrap();
        }
        chain.push(id);
    }
    let (root, tip) = (chain[0], chain[10]);
    let mut group = c.benchmark_group("kinematics");
    group.bench_function("transform_10_edge_chain", |b| b.iter(|| black_box(r.transform(tip, root).unwrap())));
    group.finish();
    let _ = Value::I32(0);
}

criterion_group! {
    name = benches;
    config = Criterion::default().measurement_time(Duration::from_secs(3)).warm_up_time(Duration::from_secs(1));
    targets = local_update, encode_decode, delta_join, snapshot_join, transform_chain
}
criterion_main!(benches);
