//! In-process replay: the bridge's replica and N receiver replicas joined by a deterministic in-memory delivery.
//!
//! The bridge publishes the deltas of each message through a [`Sink`]. [`InProcNetwork`] is the sink used in
//! process: it encodes each delta once (the real wire format, so byte counts are real), queues one copy per
//! receiver, and delivers queued copies in an order drawn from a seeded generator while more than `window` are in
//! flight, so receivers see deltas reordered (and, for big windows, interleaved across messages) but every run with
//! the same seed is identical. [`InProcNetwork::flush`] delivers the rest. A real transport (the agents' RTPS
//! transport) plugs in by implementing [`Sink`]. A caller that measures (for instance `cortex replay --out`) hears
//! of every delivery through [`InProcNetwork::on_delivery`]; the library itself still reads no clock.
//!
//! [`drive`] is the replay loop: it takes paced messages, lets the caller wait until each is due (the library never
//! sleeps), feeds the bridge and publishes the deltas. The replica's operation time is the message's log time plus
//! the loop shift, so the graph (and its digest) does not depend on the wall clock.

use std::sync::Arc;

use dsr::{Delta, DeltaError, Dictionary, Digest, Replica, ReplicaId};

use crate::bridge::Bridge;
use crate::pace::Paced;

/// Why deltas could not be delivered.
#[derive(Debug, thiserror::Error)]
pub enum SinkError {
    /// A receiver refused a delta.
    #[error("receiver {receiver} refused delta {index}: {error}")]
    Refused {
        /// Index of the receiver.
        receiver: usize,
        /// Index of the delta among those published.
        index: u64,
        /// The replica's error.
        error: DeltaError,
    },
    /// The transport failed.
    #[error("transport: {0}")]
    Transport(String),
}

/// Where the bridge's deltas go.
pub trait Sink {
    /// Sends the deltas of one message to the other agents.
    ///
    /// # Errors
    /// [`SinkError`] if they cannot be sent or are refused.
    fn publish(&mut self, deltas: &[Arc<Delta>]) -> Result<(), SinkError>;

    /// Delivers whatever is still in flight (called once at the end of a replay).
    ///
    /// # Errors
    /// [`SinkError`] as for [`Sink::publish`].
    fn flush(&mut self) -> Result<(), SinkError>;
}

/// Counters of an [`InProcNetwork`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct NetworkStats {
    /// Deltas published.
    pub deltas: u64,
    /// Bytes of their encodings (each encoded once).
    pub encoded_bytes: u64,
    /// Deliveries to receivers (deltas × receivers once flushed).
    pub deliveries: u64,
}

/// One delta applied at one receiver, as told to the hook of [`InProcNetwork::on_delivery`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Delivery {
    /// Index of the receiver in [`InProcNetwork::receivers`].
    pub receiver: usize,
    /// Index of the delta among those published (0 for the first).
    pub index: u64,
}

/// The hook called after each delivery.
struct DeliveryHook(Box<dyn FnMut(Delivery) + Send>);

impl std::fmt::Debug for DeliveryHook {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("DeliveryHook")
    }
}

/// A seeded in-memory delivery to N receiver replicas.
#[derive(Debug)]
pub struct InProcNetwork {
    receivers: Vec<Replica>,
    pending: Vec<(usize, u64, Arc<[u8]>)>,
    window: usize,
    rng: u64,
    stats: NetworkStats,
    on_delivery: Option<DeliveryHook>,
}

impl InProcNetwork {
    /// `receivers` replicas with ids `first_id`, `first_id + 1`, … sharing `dictionary`; delivery order drawn from
    /// `seed`, with up to `window` copies in flight (0 delivers each delta at once, in publication order).
    pub fn new(receivers: u32, first_id: u32, dictionary: &Dictionary, seed: u64, window: usize) -> Self {
        let receivers =
            (0..receivers).map(|i| Replica::with_dictionary(ReplicaId(first_id + i), dictionary.clone())).collect();
        InProcNetwork {
            receivers,
            pending: Vec::new(),
            window,
            rng: seed,
            stats: NetworkStats::default(),
            on_delivery: None,
        }
    }

    /// Calls `hook` after each delta is decoded and applied at a receiver (replacing an earlier hook). The hook runs
    /// inside [`Sink::publish`] and [`Sink::flush`], so it should be quick: stamp a clock, push to a queue.
    pub fn on_delivery(&mut self, hook: impl FnMut(Delivery) + Send + 'static) {
        self.on_delivery = Some(DeliveryHook(Box::new(hook)));
    }

    /// The receiver replicas.
    pub fn receivers(&self) -> &[Replica] {
        &self.receivers
    }

    /// The counters.
    pub fn stats(&self) -> NetworkStats {
        self.stats
    }

    /// SplitMix64: small, seeded, and the same on every platform.
    fn next_random(&mut self) -> u64 {
        self.rng = self.rng.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.rng;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    fn deliver_one(&mut self) -> Result<(), SinkError> {
        let pick = (self.next_random() % self.pending.len() as u64) as usize;
        let (receiver, index, bytes) = self.pending.swap_remove(pick);
        let refused = |error| SinkError::Refused { receiver, index, error };
        let delta = Delta::decode(&bytes).map_err(refused)?;
        self.receivers[receiver].apply(&delta).map_err(refused)?;
        self.stats.deliveries += 1;
        if let Some(hook) = &mut self.on_delivery {
            (hook.0)(Delivery { receiver, index });
        }
        Ok(())
    }
}

impl Sink for InProcNetwork {
    fn publish(&mut self, deltas: &[Arc<Delta>]) -> Result<(), SinkError> {
        for delta in deltas {
            let bytes: Arc<[u8]> = Arc::from(delta.encode());
            self.stats.encoded_bytes += bytes.len() as u64;
            for receiver in 0..self.receivers.len() {
                self.pending.push((receiver, self.stats.deltas, bytes.clone()));
            }
            self.stats.deltas += 1;
            while self.pending.len() > self.window {
                self.deliver_one()?;
            }
        }
        Ok(())
    }

    fn flush(&mut self) -> Result<(), SinkError> {
        while !self.pending.is_empty() {
            self.deliver_one()?;
        }
        Ok(())
    }
}

/// Counters of one [`drive`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct DriveStats {
    /// Messages paced (all loops).
    pub messages: u64,
    /// Payload bytes of those messages.
    pub bytes: u64,
    /// Deltas published.
    pub deltas: u64,
    /// Passes over the log started.
    pub loops: u32,
}

/// Replays paced messages: for each, `wait(due_ns)` (the caller sleeps, or not), then the bridge writes it into
/// `replica` and the deltas go to `sink`. Ends with [`Sink::flush`].
///
/// # Errors
/// The first [`SinkError`]; what was published before it stays published.
pub fn drive<'a>(
    paced: impl IntoIterator<Item = Paced<'a>>,
    bridge: &mut Bridge,
    replica: &mut Replica,
    sink: &mut dyn Sink,
    mut wait: impl FnMut(u64),
) -> Result<DriveStats, SinkError> {
    let mut stats = DriveStats::default();
    for item in paced {
        wait(item.due_ns);
        stats.messages += 1;
        stats.bytes += item.message.data.len() as u64;
        stats.loops = stats.loops.max(item.loop_index + 1);
        let now = item.message.log_time.saturating_add(item.shift_ns);
        let deltas = bridge.ingest(replica, now, item.message, item.shift_ns);
        stats.deltas += deltas.len() as u64;
        sink.publish(&deltas)?;
    }
    sink.flush()?;
    Ok(stats)
}

/// The digests of the bridge and of every receiver, and whether they are all equal.
pub fn digests(bridge_replica: &Replica, network: &InProcNetwork) -> (Vec<Digest>, bool) {
    let mut all = vec![bridge_replica.digest()];
    all.extend(network.receivers().iter().map(Replica::digest));
    let equal = all.windows(2).all(|pair| pair[0] == pair[1]);
    (all, equal)
}
