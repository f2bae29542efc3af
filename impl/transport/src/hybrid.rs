//! RTPS and same-host shared memory together (issue 20): the transport `cortex agent` uses by default.
//!
//! A [`HybridTransport`] is an [`RtpsTransport`] (discovery, other hosts, DDS Security when asked) beside an
//! [`ShmTransport`] whose lanes are named after the DDS domain, the topic prefix and this process's network
//! namespace ([`same_host_prefix`]), so only agents of one graph that share the host's shared memory *and* its
//! network stack meet on them: agents in two network namespaces (two containers, or a chaos campaign's simulated
//! hosts) talk RTPS, and cutting the network between them cuts them.
//!
//! - **Who is on this host.** Every transport says hello on its lanes at once and every [`peers::HELLO_PERIOD_NS`]:
//!   its RTPS endpoint id and the GUID prefix of its RTPS readers ([`peers::Hello`]). A hello heard through a lane
//!   proves the peer shares the lane; a peer silent for [`peers::PEER_EXPIRY_NS`] is forgotten.
//! - **Sending, no double send.** A sample up to the lanes' `max_sample_bytes` goes through shared memory (written
//!   once, whatever the number of same-host readers) when some peer of this host has said hello; it goes by RTPS
//!   as well only if a matched RTPS reader of its channel is not a known same-host peer's (another host, a process
//!   without lanes, a peer not heard yet). So with every peer on this host nothing of the graph's data crosses the
//!   loopback; only RTPS's discovery does.
//!   Larger samples, and any sample when the lane fails, go by RTPS alone. A sample for one peer
//!   ([`Transport::publish_to`]) goes by the lane when that peer is on this host, else by a directed RTPS write.
//! - **Receiving, no double delivery.** An RTPS sample from a same-host peer that fits the lanes is dropped: the
//!   peer sent it through shared memory too (counted in [`TransportStats::same_host_duplicates`]). A sample taken
//!   from a lane carries its sender's RTPS endpoint id as origin once the sender has said hello, so an agent sees
//!   one origin per peer whatever the path.
//! - **Faults.** Which path a sample took does not matter to the agents' anti-entropy: a sample a stopped
//!   subscriber's full lane overwrote is a gap like a lost RTPS sample. A lane that cannot open (no usable shared
//!   memory, its ports used up) gives one warning and the transport is plain RTPS.
//!
//! Both paths hand samples to one outlet: the sink while one is set ([`Transport::set_sink`]), else a bounded inbox
//! that pushes back on both receiving threads. Threshold: shared memory carries samples of every size up to the
//! lanes' limit, since it was faster than RTPS at every size measured, small ones included (README, "Same-host
//! shared memory").

pub mod peers;

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::Duration;

use bytes::Bytes;
use crossbeam_channel::{Receiver, SendTimeoutError, Sender, bounded};

use crate::rtps::{RtpsConfig, RtpsTransport};
use crate::shm::{ShmSettings, ShmTransport};
use crate::{Channel, Clock, EndpointId, Sample, Sink, Transport, TransportError, TransportStats};
use peers::{HELLO_PERIOD_NS, Hello, Peers};

/// The name prefix of the lanes of the graph on DDS domain `domain` with topic prefix `topic_prefix`, in this
/// process's network namespace: `cortex/d<DOMAIN>/<PREFIX>/net<INODE>` (the namespace's inode from
/// `/proc/self/ns/net`; without it, `net0`).
pub fn same_host_prefix(domain: u16, topic_prefix: &str) -> String {
    let inode = std::fs::read_link("/proc/self/ns/net")
        .ok()
        .and_then(|link| {
            let link = link.to_string_lossy().into_owned();
            link.strip_prefix("net:[")?.strip_suffix(']')?.parse::<u64>().ok()
        })
        .unwrap_or(0);
    format!("cortex/d{domain}/{topic_prefix}/net{inode}")
}

/// Counters of the shared-memory side, beside the RTPS transport's own.
#[derive(Debug, Default)]
struct LaneCounters {
    /// Samples published through the lane.
    sent: AtomicU64,
    /// Of those, samples not published by RTPS too (and their bytes): the RTPS counters do not know them.
    only_sent: AtomicU64,
    only_sent_bytes: AtomicU64,
    /// Samples taken from the lane and handed on (and their bytes).
    received: AtomicU64,
    received_bytes: AtomicU64,
    /// RTPS samples dropped as copies of lane samples (and their bytes): the RTPS counters counted them received.
    duplicates: AtomicU64,
    duplicates_bytes: AtomicU64,
}

/// Where both receiving threads hand samples: the sink while one is set, else the bounded inbox.
struct Outlet {
    inbox: Sender<Sample>,
    sink: Mutex<Option<Sink>>,
    stop: AtomicBool,
}

impl Outlet {
    fn pass(&self, mut sample: Sample) {
        {
            // Held during the call, so that clearing the sink waits for the call to end.
            let sink = self.sink.lock().unwrap_or_else(|p| p.into_inner());
            if let Some(sink) = sink.as_ref() {
                sink(sample);
                return;
            }
        }
        loop {
            match self.inbox.send_timeout(sample, Duration::from_millis(50)) {
                Ok(()) | Err(SendTimeoutError::Disconnected(_)) => return,
                Err(SendTimeoutError::Timeout(back)) if !self.stop.load(Ordering::Relaxed) => sample = back,
                Err(SendTimeoutError::Timeout(_)) => return,
            }
        }
    }
}

/// What the transport and its two receiving threads share.
struct Shared {
    outlet: Outlet,
    peers: Mutex<Peers>,
    counters: LaneCounters,
    /// The largest sample the lanes carry (0 without lanes).
    lane_max_bytes: usize,
}

impl Shared {
    fn peers(&self) -> std::sync::MutexGuard<'_, Peers> {
        self.peers.lock().unwrap_or_else(|p| p.into_inner())
    }
}

/// RTPS with same-host shared memory (see the module documentation).
pub struct HybridTransport {
    rtps: Arc<RtpsTransport>,
    lane: Option<Arc<ShmTransport>>,
    shared: Arc<Shared>,
    inbox: Receiver<Sample>,
    lane_thread: Option<JoinHandle<()>>,
}

impl std::fmt::Debug for HybridTransport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("HybridTransport").field("rtps", &self.rtps).field("lane", &self.lane).finish()
    }
}

impl HybridTransport {
    /// Opens the lanes named `lane_prefix` (see [`same_host_prefix`]), joins the DDS domain of `rtps`, and starts
    /// the lane's receiving thread, which times hellos by `clock` (a clock that advances in real time: the thread
    /// sleeps until the next hello is due). Lanes that cannot open give one warning and a
    /// transport that is RTPS alone.
    ///
    /// # Errors
    /// What [`RtpsTransport::new`] returns; shared memory never fails it.
    pub fn new(
        rtps: RtpsConfig,
        lane_prefix: &str,
        settings: &ShmSettings,
        clock: Arc<dyn Clock>,
    ) -> Result<Self, TransportError> {
        // The lanes first, so any peer that finds this transport by RTPS can already reach it by shared memory.
        let lane = match ShmTransport::open(lane_prefix, crate::shm::unique_endpoint(), settings) {
            Ok(lane) => Some(Arc::new(lane)),
            Err(error) => {
                tracing::warn!(%error, "same-host shared memory unavailable; every sample goes by RTPS");
                None
            }
        };
        let inbox_capacity = rtps.inbox_capacity.max(1);
        let rtps = Arc::new(RtpsTransport::new(rtps)?);
        let (sender, inbox) = bounded(inbox_capacity);
        let shared = Arc::new(Shared {
            outlet: Outlet { inbox: sender, sink: Mutex::new(None), stop: AtomicBool::new(false) },
            peers: Mutex::new(Peers::default()),
            counters: LaneCounters::default(),
            lane_max_bytes: if lane.is_some() { settings.max_sample_bytes } else { 0 },
        });
        rtps.set_sink(Some(rtps_sink(&shared)));
        let lane_thread = match &lane {
            Some(lane) => {
                let (lane, rtps, shared) = (Arc::clone(lane), Arc::clone(&rtps), Arc::clone(&shared));
                Some(
                    std::thread::Builder::new()
                        .name("shm-receive".into())
                        .spawn(move || lane_loop(&lane, &rtps, &shared, clock.as_ref()))
                        .map_err(|e| TransportError::Setup { what: "lane thread".into(), detail: e.to_string() })?,
                )
            }
            None => None,
        };
        Ok(Self { rtps, lane, shared, inbox, lane_thread })
    }

    /// The RTPS half.
    pub fn rtps(&self) -> &RtpsTransport {
        &self.rtps
    }

    /// Whether the lanes are open (else every sample goes by RTPS).
    pub fn has_lanes(&self) -> bool {
        self.lane.is_some()
    }

    /// Whether some matched RTPS reader of `channel` is not a known same-host peer's.
    fn rtps_needed(&self, channel: Channel) -> bool {
        let peers = self.shared.peers();
        self.rtps.matched_readers(channel, |prefix| !peers.has_reader(prefix)) > 0
    }

    /// Publishes the concatenation of `pieces` through the lane; `false` (after a warning) if the lane failed, so
    /// the caller uses RTPS.
    fn through_lane(&self, lane: &ShmTransport, channel: Channel, pieces: &[&[u8]]) -> bool {
        match lane.publish_pieces(channel, pieces) {
            Ok(()) => {
                self.shared.counters.sent.fetch_add(1, Ordering::Relaxed);
                true
            }
            Err(error) => {
                tracing::warn!(%error, "shared-memory publish failed; sending by RTPS");
                false
            }
        }
    }

    fn count_lane_only(&self, len: usize) {
        self.shared.counters.only_sent.fetch_add(1, Ordering::Relaxed);
        self.shared.counters.only_sent_bytes.fetch_add(len as u64, Ordering::Relaxed);
    }

    /// The lane, if it is open, a sample of `len` bytes fits it, and some peer of this host has said hello (a sample
    /// no one reads is not copied into shared memory; a peer that has not said hello yet hears by RTPS meanwhile).
    fn lane_for(&self, len: usize) -> Option<&ShmTransport> {
        self.lane.as_deref().filter(|_| len <= self.shared.lane_max_bytes && !self.shared.peers().is_empty())
    }

    /// Publishes the concatenation of `pieces` through the lane when it can; returns whether that was all, i.e. it
    /// went through the lane and no matched RTPS reader of `channel` is outside this host's peers.
    fn lane_only(&self, channel: Channel, pieces: &[&[u8]]) -> bool {
        let len = pieces.iter().map(|piece| piece.len()).sum();
        let Some(lane) = self.lane_for(len) else { return false };
        if !self.through_lane(lane, channel, pieces) || self.rtps_needed(channel) {
            return false;
        }
        self.count_lane_only(len);
        true
    }
}

impl Drop for HybridTransport {
    fn drop(&mut self) {
        self.shared.outlet.stop.store(true, Ordering::SeqCst);
        if let Some(lane) = &self.lane {
            lane.interrupt();
        }
        self.rtps.set_sink(None);
        if let Some(thread) = self.lane_thread.take() {
            let _ = thread.join();
        }
    }
}

impl Transport for HybridTransport {
    fn local_id(&self) -> EndpointId {
        self.rtps.local_id()
    }

    fn publish(&self, channel: Channel, bytes: Bytes) -> Result<(), TransportError> {
        if self.lane_only(channel, &[&bytes]) {
            return Ok(());
        }
        self.rtps.publish(channel, bytes)
    }

    /// Through the lane, each piece copied once into shared memory; joined into one buffer only when RTPS takes the
    /// sample too.
    fn publish_pieces(&self, channel: Channel, pieces: &[&[u8]]) -> Result<(), TransportError> {
        if self.lane_only(channel, pieces) {
            return Ok(());
        }
        self.rtps.publish(channel, Bytes::from(pieces.concat()))
    }

    fn publish_to(&self, channel: Channel, bytes: Bytes, to: EndpointId) -> Result<(), TransportError> {
        if let Some(lane) = self.lane_for(bytes.len())
            && self.shared.peers().has_endpoint(to)
            && self.through_lane(lane, channel, &[&bytes])
        {
            self.count_lane_only(bytes.len());
            return Ok(());
        }
        self.rtps.publish_to(channel, bytes, to)
    }

    fn try_recv(&self) -> Option<Sample> {
        self.inbox.try_recv().ok()
    }

    fn recv_timeout(&self, timeout: Duration) -> Option<Sample> {
        self.inbox.recv_timeout(timeout).ok()
    }

    fn stats(&self) -> TransportStats {
        let rtps = self.rtps.stats();
        let c = &self.shared.counters;
        let load = |n: &AtomicU64| n.load(Ordering::Relaxed);
        TransportStats {
            samples_sent: rtps.samples_sent + load(&c.only_sent),
            payload_bytes_sent: rtps.payload_bytes_sent + load(&c.only_sent_bytes),
            samples_received: (rtps.samples_received + load(&c.received)).saturating_sub(load(&c.duplicates)),
            payload_bytes_received: (rtps.payload_bytes_received + load(&c.received_bytes))
                .saturating_sub(load(&c.duplicates_bytes)),
            shm_samples_sent: load(&c.sent),
            shm_samples_received: load(&c.received),
            shm_samples_leased: self.lane.as_ref().map_or(0, |lane| lane.stats().shm_samples_leased),
            same_host_duplicates: load(&c.duplicates),
            same_host_peers: self.shared.peers().len() as u64,
            ..rtps
        }
    }

    fn sync_matches(&self) -> u64 {
        self.rtps.sync_matches() + self.shared.peers().learned()
    }

    fn set_sink(&self, sink: Option<Sink>) -> bool {
        *self.shared.outlet.sink.lock().unwrap_or_else(|p| p.into_inner()) = sink;
        true
    }
}

/// What the RTPS receiving thread does with a sample: drops it if a same-host peer sent it through the lane too,
/// else hands it on.
fn rtps_sink(shared: &Arc<Shared>) -> Sink {
    let shared = Arc::clone(shared);
    Arc::new(move |sample: Sample| {
        let len = sample.bytes.len();
        if len <= shared.lane_max_bytes && shared.peers().has_endpoint(sample.origin) {
            shared.counters.duplicates.fetch_add(1, Ordering::Relaxed);
            shared.counters.duplicates_bytes.fetch_add(len as u64, Ordering::Relaxed);
            return;
        }
        shared.outlet.pass(sample);
    })
}

/// The lane's receiving thread: says hello on time, learns peers from theirs, and hands every other sample on
/// with its sender's RTPS endpoint id as origin.
fn lane_loop(lane: &ShmTransport, rtps: &RtpsTransport, shared: &Shared, clock: &dyn Clock) {
    let hello = || {
        let hello = Hello { writer: rtps.local_id(), readers: rtps.reading_prefix() };
        if let Err(error) = lane.publish(Channel::Sync, Bytes::from(hello.encode())) {
            tracing::warn!(%error, "shared-memory hello failed");
        }
    };
    let mut next_hello_ns = 0;
    while !shared.outlet.stop.load(Ordering::Relaxed) {
        let now_ns = clock.now_ns();
        if now_ns >= next_hello_ns {
            hello();
            shared.peers().expire(now_ns);
            next_hello_ns = now_ns + HELLO_PERIOD_NS;
        }
        // Sleeps until a sample or the next hello; a stop interrupts the wait.
        let wait = Duration::from_nanos(next_hello_ns.saturating_sub(now_ns));
        let Some(sample) = lane.recv_timeout(wait) else { continue };
        if sample.channel == Channel::Sync
            && let Some(said) = Hello::decode(&sample.bytes)
        {
            if shared.peers().heard(sample.origin, said, clock.now_ns()) {
                tracing::debug!(peer = %said.writer, "same-host peer");
                // Answer at once, so the new peer need not wait a period to know this transport.
                hello();
            }
            continue;
        }
        let origin = shared.peers().writer_of(sample.origin).unwrap_or(sample.origin);
        shared.counters.received.fetch_add(1, Ordering::Relaxed);
        shared.counters.received_bytes.fetch_add(sample.bytes.len() as u64, Ordering::Relaxed);
        shared.outlet.pass(Sample { origin, ..sample });
    }
}
