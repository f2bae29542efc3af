//! # The transport boundary of DSR_d agents
//!
//! An agent hands opaque byte samples to a [`Transport`] on one of a few [`Channel`]s and takes the samples
//! other endpoints published, each tagged with the [`EndpointId`] it came from. The agent never sees sockets,
//! discovery or QoS; the transport never sees graphs. Three implementations:
//!
//! - [`rtps::RtpsTransport`]: RTPS through the `rustdds` DDS implementation (the default for real agents): reliable,
//!   keep-all, explicit resource limits on every reader and writer, readers in a participant apart from the writers',
//!   a bounded inbox, pacing of large samples.
//! - [`inproc::Bus`] / [`inproc::InProcTransport`]: an in-process bus for tests and deterministic simulation.
//! - [`hybrid::HybridTransport`]: RTPS for discovery and other hosts, same-host shared memory ([`shm`]) for
//!   samples between the agents of one host (the default of `cortex agent`).
//! - [`fault::FaultInjector`]: seeded loss, duplication, reordering, delay and partitions, wrapped around either.
//!
//! **Every queue is bounded**: a full inbox drops (in process), and the drop is counted in [`TransportStats`], or
//! holds back the receiving thread (RTPS), whose readers' caches then evict their oldest samples past
//! [`rtps::RtpsConfig::reader_cache_samples`] (or [`rtps::RtpsConfig::large_cache_samples`] for large updates),
//! uncounted (`rustdds` does not say). **A transport never delivers an
//! endpoint's own samples back to it.**
//! Time comes from an injected [`Clock`], so the in-process bus and the fault injector are deterministic given a
//! seed and a [`ManualClock`].

use std::fmt;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

use bytes::Bytes;

pub mod fault;
pub mod hybrid;
pub mod inproc;
pub mod rng;
pub mod rtps;
pub mod shm;

/// A logical stream of samples. Each channel is its own topic on RTPS, so a large snapshot on [`Channel::Sync`]
/// never delays a small update on [`Channel::Updates`].
///
/// What may be written on a channel is what DDS Security's permissions grant per topic: a read-only participant
/// (an inspector) may publish on [`Channel::Requests`] alone, which carries only messages that ask and can never
/// change a graph, and subscribe to every channel ([`rtps::RtpsConfig::read_only`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Channel {
    /// Deltas of local operations, as they happen.
    Updates,
    /// Answers of anti-entropy and late join: missing deltas, snapshots, graph answers.
    Sync,
    /// Remote component calls: requests and replies.
    Calls,
    /// Asking only: graph requests, announces of the operations one has applied, missing-requests. Nothing on it
    /// can change a graph; an agent refuses anything else that arrives on it.
    Requests,
}

impl Channel {
    /// How many channels there are (the length of per-channel arrays).
    pub const COUNT: usize = 4;

    /// All channels, in index order.
    pub const ALL: [Channel; Channel::COUNT] = [Channel::Updates, Channel::Sync, Channel::Calls, Channel::Requests];

    /// A small index (0 to [`Channel::COUNT`] − 1) for arrays of per-channel things.
    pub fn index(self) -> usize {
        match self {
            Channel::Updates => 0,
            Channel::Sync => 1,
            Channel::Calls => 2,
            Channel::Requests => 3,
        }
    }

    /// The lower-case name used in topic names and logs.
    pub fn name(self) -> &'static str {
        match self {
            Channel::Updates => "updates",
            Channel::Sync => "sync",
            Channel::Calls => "calls",
            Channel::Requests => "requests",
        }
    }
}

/// Who published a sample: an in-process endpoint number, or the 12-byte RTPS GUID prefix of a participant.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct EndpointId(pub u128);

impl fmt::Display for EndpointId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.0 <= u64::MAX as u128 { write!(f, "ep{}", self.0) } else { write!(f, "rtps:{:024x}", self.0) }
    }
}

/// One received sample.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Sample {
    /// The channel it was published on.
    pub channel: Channel,
    /// Who published it (as the transport saw it; the agent envelope names the agent).
    pub origin: EndpointId,
    /// The bytes, exactly as published.
    pub bytes: Bytes,
}

/// Errors of a transport. Messages say what failed and where.
#[derive(Debug, thiserror::Error)]
pub enum TransportError {
    /// The DDS engine refused to create something.
    #[error("rtps setup: {what}: {detail}")]
    Setup {
        /// What was being created.
        what: String,
        /// The engine's message.
        detail: String,
    },
    /// The DDS engine refused a write.
    #[error("rtps write on channel {channel}: {detail}")]
    Write {
        /// The channel name.
        channel: &'static str,
        /// The engine's message.
        detail: String,
    },
    /// A sample is larger than the configured maximum.
    #[error("sample of {size} bytes on channel {channel} exceeds the limit of {limit} bytes")]
    TooLarge {
        /// The channel name.
        channel: &'static str,
        /// Sample size.
        size: usize,
        /// The limit.
        limit: usize,
    },
    /// The transport was started read-only ([`rtps::RtpsConfig::read_only`]): it has no writer for this channel.
    #[error("channel {channel} is not writable: this transport is read-only (it writes on requests only)")]
    ReadOnly {
        /// The channel name.
        channel: &'static str,
    },
    /// One of the DDS engine's threads ended while the transport built its participants, writers and readers
    /// (`rustdds` 0.15 ends a participant's event loop when its `poll` fails, as it does when the process resumes
    /// after a SIGSTOP); the build was abandoned before asking the ended thread for anything.
    #[error("rtps setup: rustdds's {thread} ended while the transport was being built (a SIGSTOP/SIGCONT?)")]
    EngineEnded {
        /// Which thread: its name (quoted), or how many of a new participant's threads were gone before they were
        /// seen.
        thread: String,
    },
    /// The transport was closed.
    #[error("transport closed")]
    Closed,
}

/// Moves samples between agents. Implementations are thread-safe: an agent publishes from its callers' threads and
/// receives on its own thread.
pub trait Transport: Send + Sync {
    /// This endpoint's id, as others see it in [`Sample::origin`].
    fn local_id(&self) -> EndpointId;

    /// Publishes `bytes` to every other endpoint on `channel`. May block briefly for back-pressure (pacing of
    /// large samples); never waits on a remote reply.
    ///
    /// # Errors
    /// [`TransportError`] when the sample cannot be handed to the network.
    fn publish(&self, channel: Channel, bytes: Bytes) -> Result<(), TransportError>;

    /// Publishes `bytes` on `channel` for the endpoint `to` alone, when the transport can address one endpoint (RTPS:
    /// a write directed to that participant's reader, so a large answer is not copied to every reader); otherwise,
    /// and by default, to every other endpoint like [`Transport::publish`]. Receivers must therefore still check
    /// whom a sample is for (the agent envelope names it).
    ///
    /// # Errors
    /// As [`Transport::publish`].
    fn publish_to(&self, channel: Channel, bytes: Bytes, to: EndpointId) -> Result<(), TransportError> {
        let _ = to;
        self.publish(channel, bytes)
    }

    /// Publishes the concatenation of `pieces` as one sample, like [`Transport::publish`]. A transport that writes
    /// samples into memory of its own (a shared-memory chunk) copies each piece there once; by default the pieces
    /// are first joined into one buffer (one copy), which is what every transport needs that hands a contiguous
    /// buffer on (RTPS, the in-process bus). An agent publishes a local delta this way, with its large values as
    /// pieces of their own (`dsr::Delta::encode_pieces`).
    ///
    /// # Errors
    /// As [`Transport::publish`].
    fn publish_pieces(&self, channel: Channel, pieces: &[&[u8]]) -> Result<(), TransportError> {
        self.publish(channel, Bytes::from(pieces.concat()))
    }

    /// The next received sample, if one is waiting.
    fn try_recv(&self) -> Option<Sample>;

    /// The next received sample, waiting up to `timeout` for one.
    fn recv_timeout(&self, timeout: Duration) -> Option<Sample>;

    /// Counters of what went through this endpoint.
    fn stats(&self) -> TransportStats;

    /// A number that grows whenever discovery matches this endpoint with a new remote endpoint on
    /// [`Channel::Requests`] or [`Channel::Sync`] (a peer that can now hear a graph request, or be heard answering).
    /// Transports without discovery return 0 forever. A joining agent repeats its graph request when it grows,
    /// rather than waiting for its retry period: a request published before the match reaches nobody.
    fn sync_matches(&self) -> u64 {
        0
    }

    /// Asks the transport to hand every sample it receives from now on to `sink`, called on the transport's own
    /// receiving thread in arrival order, instead of queueing it for [`Transport::try_recv`]: a receiver that
    /// handles samples at once saves a thread hand-off per sample. `sink` must not block for long (the transport
    /// reads nothing else meanwhile). `None` goes back to queueing; it returns once no call of the old sink is
    /// running, so whatever the sink holds can be released safely afterwards. Returns `false`, changing nothing,
    /// when the transport has no receiving thread of its own (the in-process bus; the fault injector, which times
    /// deliveries itself): the caller then keeps polling. Samples queued before the call stay queued.
    fn set_sink(&self, sink: Option<Sink>) -> bool {
        let _ = sink;
        false
    }

    /// Makes a [`Transport::recv_timeout`] that is waiting return at once (empty-handed unless a sample came), or
    /// the next one if none waits, where the transport can; returns whether it can (by default it cannot, and a
    /// caller that needs waking keeps its waits short). A thread that waits on the transport for samples and also
    /// has other work is woken for that work this way (an agent's thread, when a write brings its next announce
    /// closer).
    fn interrupt(&self) -> bool {
        false
    }
}

/// A receiver of samples, called on a transport's receiving thread (see [`Transport::set_sink`]).
pub type Sink = Arc<dyn Fn(Sample) + Send + Sync>;

impl<T: Transport + ?Sized> Transport for Arc<T> {
    fn local_id(&self) -> EndpointId {
        (**self).local_id()
    }
    fn publish(&self, channel: Channel, bytes: Bytes) -> Result<(), TransportError> {
        (**self).publish(channel, bytes)
    }
    fn publish_to(&self, channel: Channel, bytes: Bytes, to: EndpointId) -> Result<(), TransportError> {
        (**self).publish_to(channel, bytes, to)
    }
    fn publish_pieces(&self, channel: Channel, pieces: &[&[u8]]) -> Result<(), TransportError> {
        (**self).publish_pieces(channel, pieces)
    }
    fn try_recv(&self) -> Option<Sample> {
        (**self).try_recv()
    }
    fn recv_timeout(&self, timeout: Duration) -> Option<Sample> {
        (**self).recv_timeout(timeout)
    }
    fn stats(&self) -> TransportStats {
        (**self).stats()
    }
    fn sync_matches(&self) -> u64 {
        (**self).sync_matches()
    }
    fn set_sink(&self, sink: Option<Sink>) -> bool {
        (**self).set_sink(sink)
    }
    fn interrupt(&self) -> bool {
        (**self).interrupt()
    }
}

/// A snapshot of a transport's counters (serde: so a process can report them to another).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct TransportStats {
    /// Samples published.
    pub samples_sent: u64,
    /// Bytes of samples published (the agent's envelopes).
    pub payload_bytes_sent: u64,
    /// Bytes that publishing put on the wire as the transport accounts for them: payload plus per-sample
    /// encapsulation and protocol headers (RTPS: an estimate from the submessage layout, see [`rtps`]).
    pub wire_bytes_sent: u64,
    /// Samples received and handed to the agent.
    pub samples_received: u64,
    /// Bytes of samples received.
    pub payload_bytes_received: u64,
    /// Samples dropped because a bounded queue was full.
    pub dropped_full: u64,
    /// Samples dropped on purpose (fault injection: loss and partitions).
    pub dropped_injected: u64,
    /// Extra copies delivered on purpose (fault injection: duplication).
    pub duplicated_injected: u64,
    /// Times the transport found its DDS engine dead (RTPS: `rustdds`'s threads of its participants ended, see
    /// [`rtps`], "Recovery"). From then until the matching rebuild it neither sends nor receives.
    #[serde(default)]
    pub participant_failures: u64,
    /// Times the transport rebuilt its participants, writers and readers after such a failure. Fewer rebuilds
    /// than failures: a rebuild is under way (or failing, which the log says).
    #[serde(default)]
    pub participant_rebuilds: u64,
    /// Of the samples published, those that went through same-host shared memory ([`hybrid`], [`shm`]).
    #[serde(default)]
    pub shm_samples_sent: u64,
    /// Of the samples received, those that came through same-host shared memory.
    #[serde(default)]
    pub shm_samples_received: u64,
    /// Of the samples received through shared memory, those taken in place rather than copied out ([`shm::lease`]).
    #[serde(default)]
    pub shm_samples_leased: u64,
    /// RTPS copies of samples a same-host peer also sent through shared memory, dropped on arrival ([`hybrid`]).
    #[serde(default)]
    pub same_host_duplicates: u64,
    /// Same-host peers reachable through shared memory now ([`hybrid`]; a gauge, not a counter).
    #[serde(default)]
    pub same_host_peers: u64,
    /// Waits of the RTPS receiving thread for a large update, behind its marker, that ended without it (see
    /// [`rtps`], "Memory"): it was lost (evicted from a full cache, or its writer gone), and the updates that waited
    /// went on. Agents repair the loss.
    #[serde(default)]
    pub large_waits_ended: u64,
    /// Samples meant for one peer ([`Transport::publish_to`]) that went to every reader instead, because the
    /// transport did not know that peer's reader yet (RTPS, see [`rtps`], "Memory"; on a volatile topic a reader
    /// matched after the write never gets it). Answers to joiners are whole graphs: this says how often every agent
    /// received one it had not asked for.
    #[serde(default)]
    pub unaddressed_writes: u64,
}

/// Atomic counters behind [`TransportStats`].
#[derive(Debug, Default)]
pub struct Counters {
    samples_sent: AtomicU64,
    payload_bytes_sent: AtomicU64,
    wire_bytes_sent: AtomicU64,
    samples_received: AtomicU64,
    payload_bytes_received: AtomicU64,
    dropped_full: AtomicU64,
    participant_failures: AtomicU64,
    participant_rebuilds: AtomicU64,
    large_waits_ended: AtomicU64,
    unaddressed_writes: AtomicU64,
}

impl Counters {
    /// Counts one published sample of `payload` bytes that cost `wire` bytes.
    pub fn sent(&self, payload: usize, wire: usize) {
        self.samples_sent.fetch_add(1, Ordering::Relaxed);
        self.payload_bytes_sent.fetch_add(payload as u64, Ordering::Relaxed);
        self.wire_bytes_sent.fetch_add(wire as u64, Ordering::Relaxed);
    }

    /// Counts `n` waits for a large update that ended without it ([`TransportStats::large_waits_ended`]).
    pub fn large_waits_ended(&self, n: u64) {
        self.large_waits_ended.fetch_add(n, Ordering::Relaxed);
    }

    /// Counts one sample meant for one peer that went to every reader ([`TransportStats::unaddressed_writes`]).
    pub fn unaddressed_write(&self) {
        self.unaddressed_writes.fetch_add(1, Ordering::Relaxed);
    }

    /// Counts one received sample.
    pub fn received(&self, payload: usize) {
        self.samples_received.fetch_add(1, Ordering::Relaxed);
        self.payload_bytes_received.fetch_add(payload as u64, Ordering::Relaxed);
    }

    /// Takes a sample from an inbox (waiting up to `timeout`, or not at all), counting it: the receive path every
    /// transport shares.
    pub fn take(&self, inbox: &crossbeam_channel::Receiver<Sample>, timeout: Option<Duration>) -> Option<Sample> {
        let sample = match timeout {
            None => inbox.try_recv().ok()?,
            Some(timeout) => inbox.recv_timeout(timeout).ok()?,
        };
        self.received(sample.bytes.len());
        Some(sample)
    }

    /// Counts one sample dropped at a full queue.
    pub fn dropped_full(&self) {
        self.dropped_full.fetch_add(1, Ordering::Relaxed);
    }

    /// Counts one failure of the transport's DDS engine ([`TransportStats::participant_failures`]).
    pub fn participant_failed(&self) {
        self.participant_failures.fetch_add(1, Ordering::Relaxed);
    }

    /// Counts one rebuild of the transport's DDS entities ([`TransportStats::participant_rebuilds`]).
    pub fn participant_rebuilt(&self) {
        self.participant_rebuilds.fetch_add(1, Ordering::Relaxed);
    }

    /// The current values.
    pub fn snapshot(&self) -> TransportStats {
        TransportStats {
            samples_sent: self.samples_sent.load(Ordering::Relaxed),
            payload_bytes_sent: self.payload_bytes_sent.load(Ordering::Relaxed),
            wire_bytes_sent: self.wire_bytes_sent.load(Ordering::Relaxed),
            samples_received: self.samples_received.load(Ordering::Relaxed),
            payload_bytes_received: self.payload_bytes_received.load(Ordering::Relaxed),
            dropped_full: self.dropped_full.load(Ordering::Relaxed),
            dropped_injected: 0,
            duplicated_injected: 0,
            participant_failures: self.participant_failures.load(Ordering::Relaxed),
            participant_rebuilds: self.participant_rebuilds.load(Ordering::Relaxed),
            large_waits_ended: self.large_waits_ended.load(Ordering::Relaxed),
            unaddressed_writes: self.unaddressed_writes.load(Ordering::Relaxed),
            ..TransportStats::default()
        }
    }
}

/// A source of time in nanoseconds. Agents stamp operations with it and time their periodic work by it; the
/// fault injector times delays by it.
pub trait Clock: Send + Sync + fmt::Debug {
    /// Nanoseconds on this clock.
    fn now_ns(&self) -> u64;
}

/// Wall-clock time since the Unix epoch: what real agents use, so stamps of different processes are comparable.
#[derive(Clone, Copy, Debug, Default)]
pub struct SystemClock;

impl Clock for SystemClock {
    fn now_ns(&self) -> u64 {
        std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX))
    }
}

/// A clock that moves only when told: the basis of deterministic simulations. Clones share the time.
#[derive(Clone, Debug, Default)]
pub struct ManualClock(Arc<AtomicU64>);

impl ManualClock {
    /// A clock reading `start_ns`.
    pub fn new(start_ns: u64) -> Self {
        ManualClock(Arc::new(AtomicU64::new(start_ns)))
    }

    /// Moves the clock forward by `ns`.
    pub fn advance(&self, ns: u64) {
        self.0.fetch_add(ns, Ordering::SeqCst);
    }

    /// Sets the clock (never backwards: a smaller value is ignored).
    pub fn set(&self, ns: u64) {
        self.0.fetch_max(ns, Ordering::SeqCst);
    }
}

impl Clock for ManualClock {
    fn now_ns(&self) -> u64 {
        self.0.load(Ordering::SeqCst)
    }
}
