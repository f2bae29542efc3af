//! The writes an experiment publishes, planned before the clock starts: each is an encoded delta with the time it
//! is due (nanoseconds after the run starts) and its payload class.
//!
//! Planning first keeps the measured path to what the issue asks for — from the write at the source agent (the
//! publication of its delta) to its application at each receiver — and out of it the bridge's decoding of ROS
//! messages, which is the same for every number of agents. The source replica's final digest is kept, so the run
//! can tell when every receiver equals it.

use std::path::Path;
use std::sync::Arc;

use anyhow::Context as _;
use bytes::Bytes;
use dsr::{Delta, Dictionary, Digest, NewNode, Replica, ReplicaId, Value};
use replay::log::{Log, ReadOptions};
use replay::{Bridge, BridgeOptions, Pacer, Rate};

use crate::latency::PayloadClass;

/// One planned write.
#[derive(Clone, Debug)]
pub struct PlannedWrite {
    /// When it is due, in nanoseconds after the start of the run.
    pub due_ns: u64,
    /// The payload class of the message (or synthetic write) it came from.
    pub class: PayloadClass,
    /// Bytes of the source message's payload (0 for node creation and other bookkeeping deltas).
    pub payload_bytes: u64,
    /// The encoded delta (the real wire format of a delta).
    pub delta: Bytes,
}

/// A planned sequence of writes by one source replica.
#[derive(Clone, Debug)]
pub struct Workload {
    /// What it is (a log file name, or `synthetic N B @ R Hz`).
    pub name: String,
    /// The writes in due order.
    pub writes: Vec<PlannedWrite>,
    /// The source replica's digest after every write.
    pub final_digest: Digest,
    /// The dictionary every receiver must share.
    pub dictionary: Dictionary,
}

impl Workload {
    /// Sum of the encoded deltas' sizes.
    pub fn delta_bytes(&self) -> u64 {
        self.writes.iter().map(|w| w.delta.len() as u64).sum()
    }

    /// Due time of the last write.
    pub fn span_ns(&self) -> u64 {
        self.writes.last().map_or(0, |w| w.due_ns)
    }
}

fn encode(delta: &Arc<Delta>) -> Bytes {
    Bytes::from(delta.encode())
}

/// A bundled ROS 2 log replayed through the `replay` bridge at `rate` (a factor on the recorded timing, or as fast
/// as possible), `loops` times.
///
/// # Errors
/// A file that cannot be read or is damaged; the bridge dictionary.
pub fn from_log(path: &Path, rate: Rate, loops: u32) -> anyhow::Result<Workload> {
    let log = Log::open(path, ReadOptions::default()).with_context(|| format!("cannot read {}", path.display()))?;
    let dictionary = replay::bridge::dictionary().context("bridge dictionary")?;
    let mut replica = Replica::with_dictionary(ReplicaId(1), dictionary.clone());
    let mut bridge = Bridge::new(BridgeOptions::default());
    let mut writes = Vec::new();
    for item in Pacer::new(&log.messages, rate, loops, || 0u64) {
        let schema = item.message.channel.schema.as_ref().map_or("", |s| s.name.as_str());
        let class = PayloadClass::of_schema(schema);
        let now = item.message.log_time.saturating_add(item.shift_ns);
        let deltas = bridge.ingest(&mut replica, now, item.message, item.shift_ns);
        for (i, delta) in deltas.iter().enumerate() {
            // The message's payload is counted once, on its first delta.
            let payload_bytes = if i == 0 { item.message.data.len() as u64 } else { 0 };
            writes.push(PlannedWrite { due_ns: item.due_ns, class, payload_bytes, delta: encode(delta) });
        }
    }
    let name = path.file_name().map_or_else(|| path.display().to_string(), |n| n.to_string_lossy().into_owned());
    Ok(Workload { name, writes, final_digest: replica.digest(), dictionary })
}

/// `count` writes of a byte attribute of `size` bytes at `rate_hz` (after one node creation at time 0), with
/// contents drawn from `seed`. Class: [`PayloadClass::Small`] below 1 KiB, else by size as
/// [`PayloadClass::Image`] (the class only labels; latency against size is what this workload is for).
///
/// # Errors
/// Only if the bridge dictionary cannot be built.
pub fn synthetic(size: usize, rate_hz: f64, count: usize, seed: u64) -> anyhow::Result<Workload> {
    let dictionary = replay::bridge::dictionary().context("bridge dictionary")?;
    let mut replica = Replica::with_dictionary(ReplicaId(1), dictionary.clone());
    let period_ns = (1e9 / rate_hz.max(1e-3)) as u64;
    let (node, created) = replica
        .insert_node(1, NewNode::new(replay::bridge::OPAQUE_NODE_TYPE, "synthetic"))
        .context("synthetic node")?;
    let mut writes =
        vec![PlannedWrite { due_ns: 0, class: PayloadClass::Small, payload_bytes: 0, delta: encode(&created) }];
    let class = if size < 1024 { PayloadClass::Small } else { PayloadClass::Image };
    let mut state = seed | 1;
    for i in 0..count {
        let mut payload = vec![0u8; size];
        for byte in &mut payload {
            // xorshift: cheap, seeded, incompressible enough for a transport.
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            *byte = state as u8;
        }
        let due_ns = period_ns * (i as u64 + 1);
        let delta = replica
            .set_attrs(due_ns + 1, node, [(replay::bridge::OPAQUE_PAYLOAD, Value::Bytes(Bytes::from(payload)))])
            .context("synthetic write")?;
        writes.push(PlannedWrite { due_ns, class, payload_bytes: size as u64, delta: encode(&delta) });
    }
    Ok(Workload {
        name: format!("synthetic {size} B @ {rate_hz} Hz"),
        writes,
        final_digest: replica.digest(),
        dictionary,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn synthetic_writes_are_due_at_the_rate_and_carry_the_size() {
        let workload = synthetic(1000, 100.0, 5, 7).unwrap();
        assert_eq!(workload.writes.len(), 6);
        assert_eq!(workload.writes[1].due_ns, 10_000_000);
        assert_eq!(workload.writes[5].due_ns, 50_000_000);
        assert!(workload.writes[1..].iter().all(|w| w.payload_bytes == 1000 && w.delta.len() > 1000));
        // The same seed gives the same deltas.
        let again = synthetic(1000, 100.0, 5, 7).unwrap();
        assert_eq!(again.final_digest, workload.final_digest);
    }

    #[test]
    fn a_bundled_log_plans_classes_from_its_types() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../datasets/logs/sick_tim7xx_scan_10s.mcap");
        let workload = from_log(&path, Rate::Factor(1.0), 1).unwrap();
        assert!(workload.writes.iter().any(|w| w.class == PayloadClass::Scan));
        assert!(workload.writes.windows(2).all(|w| w[0].due_ns <= w[1].due_ns));
        assert!(workload.span_ns() > 5_000_000_000, "a 10 s log at rate 1 spans {} ns", workload.span_ns());
    }
}
