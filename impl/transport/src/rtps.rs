//! RTPS through `rustdds`: the transport real agents use.
//!
//! Two DDS domain participants per agent (one for its writers, one for its readers), one non-keyed topic per
//! [`Channel`] named `{prefix}_{channel}` (plus `{prefix}_updates_be` with best-effort updates, below), every writer
//! and reader RELIABLE + KEEP_ALL + VOLATILE with **explicit
//! [`ResourceLimits`] (`rustdds` otherwise keeps only 64 samples per reader)**. A sample travels as a CDR
//! `sequence<octet>` (4-byte length, then the bytes), so any DDS implementation can read it with a one-field IDL
//! type.
//!
//! A receiving thread waits on the readers with `mio` and moves samples into a **bounded inbox**; when the inbox is
//! full it stops taking, the readers' caches fill, and the reliable protocol pushes back on the writers. Samples
//! this transport wrote itself are skipped.
//!
//! **The readers live in a second participant** (by default, see [`RtpsConfig::separate_reader_participant`]), so a
//! writer never has a reader of its own participant. In `rustdds` 0.15 a same-participant reader keeps the writer's
//! fallback route (multicast to the user-traffic group), while a confirmed same-host reader gets a loopback unicast
//! route, and a write goes to the union: every same-host reader, which also listens on the multicast group, gets
//! each datagram twice. A sample larger than one datagram's budget (about 1.4 KB: the budget is the smallest path
//! MTU of the reader's advertised locators, the LAN one included) goes as 256-byte DATA_FRAG fragments, and a second
//! copy whose first datagrams land in the first copy's reassembly leaves an incomplete reassembly buffer behind.
//! Those live 10 s, a reader keeps at most 128, and at the cap a reliable reader evicts the newest: every new
//! fragmented sample is then discarded until old buffers expire, and delivery stalls for seconds (issue 5; the
//! SICK log's 10–13 KB deltas at 30 Hz reach the cap after about 8 s). With no same-participant reader, a same-host
//! writer sends one loopback copy per reader, and fragmented samples reassemble once.
//!
//! **Large samples are paced**: after every [`RtpsConfig::pace_bytes`] of large samples the writer waits (bounded)
//! for acknowledgements, so a burst of 1 MB frames is delivered rather than stalled. Domain id and topic prefix are
//! configurable so several graphs can share a host; discovery uses the standard unicast locators and works on
//! loopback without network configuration.
//!
//! **Multicast** ([`RtpsConfig::multicast`]). A `rustdds` writer sends a sample meant for every matched reader
//! with "multicast preferred": one datagram per distinct route, and a reader's route is its advertised multicast
//! locator (239.255.0.1, user-traffic port) on the interface its traffic was seen on — *unless* the reader is
//! confirmed to be on this host and the participant prefers loopback for same-host peers (`rustdds`'s
//! `same_host_loopback`, on by default), in which case every reader gets its own unicast copy over loopback.
//! [`Multicast::On`] turns that preference off, so same-host readers share one multicast datagram; it needs a
//! multicast-capable interface for discovery (on one host: `ip link set lo multicast on` and a 224.0.0.0/4 route
//! on `lo`). [`Multicast::Auto`], the default, does so exactly when the loopback interface is up and
//! multicast-capable ([`loopback_multicast_capable`]).
//!
//! With multicast on, a participant **advertises only this host's addresses outside `127.0.0.0/8`**
//! ([`routable_ipv4_addresses`], passed to `rustdds`'s `with_only_networks`) when it has any. `rustdds` sends a
//! message meant for one participant (an acknowledgement, a repair) to every unicast locator that participant
//! advertises, and routes a reader per source address, so a host with two addresses (127.0.0.1 and a routable one)
//! got every acknowledgement twice and, for some readers, every sample twice: 5.5 datagrams per small update where 3
//! suffice (measured with `cortex bench rtt` in a namespace). Without multicast, `rustdds`'s same-host loopback
//! preference already picks one route, and every address is advertised as usual.
//!
//! **Best-effort updates** ([`RtpsConfig::updates`], [`UpdateDelivery`]). `rustdds` sends a heartbeat that asks for
//! an acknowledgement beside every reliable DATA, so every matched reader acknowledges every sample, and a
//! transport's own reader is one of them (`rustdds` has no way to ignore a participant): a small update costs its
//! DATA datagram plus one acknowledgement datagram per agent. With [`UpdateDelivery::BestEffort`], samples on
//! [`Channel::Updates`] up to a size go on a best-effort topic of their own and cost their DATA datagram alone;
//! larger ones, directed writes and every other channel stay reliable. Every transport reads that topic, whatever
//! its own setting, so agents of one graph may mix settings. A lost small update is then the user's to
//! repair: agents repair it by anti-entropy, and at once when a later delta of the same writer shows the gap (see
//! the `agent` crate). Reliable stays the default.
//!
//! A sample meant for one peer ([`Transport::publish_to`], e.g. a graph answer) is written to that participant's
//! reader alone (a directed write; the other readers get a GAP for its sequence number), so a multi-megabyte answer
//! is not copied to every reader — including this participant's own reader, which rustdds matches too.
//!
//! Discovery is observed through the participant's status events: [`RtpsTransport::discovery`] tells when the
//! first remote participant was discovered and when each channel's writer and reader matched their first remote
//! endpoint, and [`Transport::sync_matches`] counts the matches on [`Channel::Sync`] so a joining agent can ask for
//! the graph as soon as a peer can hear it. (rustdds sends a new participant's first discovery announcement 100 ms
//! after it is created — a constant of rustdds 0.15, not a setting — so no peer is found sooner than that.)
//!
//! **Recovery** (issue 14). `rustdds` 0.15 runs two threads per participant — its event loop
//! (`DPEventLoop::event_loop`, `rtps/dp_event_loop.rs`) and discovery (`Discovery::discovery_event_loop`,
//! `discovery/discovery.rs`) — and each returns, ending the thread, on any error of its `mio` `Poll::poll`,
//! `ErrorKind::Interrupted` included (mio 1 no longer retries EINTR itself). On Linux a thread blocked in `epoll_wait`
//! fails with EINTR when its process is resumed (SIGCONT) after a stop signal (SIGSTOP, SIGTSTP), with or without a
//! signal handler; `SA_RESTART` does not apply to `epoll_wait`, and SIGSTOP cannot be caught, blocked or ignored, so
//! nothing outside `rustdds` keeps its threads alive. Without them a participant neither sends, receives, nor answers
//! discovery, for good: a stopped and resumed agent was deaf and mute, and a new agent found nobody and started alone.
//! So the receiving thread watches those threads (found by name in `/proc/self/task` when the participants are created,
//! one at a time per process; checked with a few small reads every 500 ms, and 50 ms after its own `poll` was
//! interrupted). When one has ended it says so with an error, builds new participants with all their topics, writers
//! and readers, swaps the writers in (each lock held only for its swap), serves the new readers, and drops the old
//! ones; a failed rebuild is logged and tried again, at most one rebuild a second. The transport's endpoint id changes
//! (the new publishing participant's GUID prefix), peers discover it like a new process, [`Transport::sync_matches`]
//! grows with the new matches (a joining agent asks for the graph again), and what was written in the gap is repaired
//! by the agents' anti-entropy. [`TransportStats`] counts failures and rebuilds. Peers keep the dead participant's
//! readers matched until its lease runs out (50 s in `rustdds` 0.15), so meanwhile their pacing of large samples waits
//! in vain for those readers' acknowledgements (up to [`RtpsConfig::max_blocking`] per [`RtpsConfig::pace_bytes`]), as
//! it does for any peer that vanished without leaving. Where `/proc/self/task` does not exist (not Linux) the threads
//! are not watched, and a warning says so when the transport starts.
//!
//! Wire bytes are estimated per sample as the payload plus its CDR header and length (8 B) padded to 4, the RTPS
//! DATA submessage (24 B), for a reliable sample the heartbeat beside it (32 B), and one RTPS header plus UDP/IPv4
//! header (48 B) per datagram of up to 64 KiB ([`estimated_wire_bytes`]; exact for an unfragmented sample:
//! 132 and 164 B for a 50-byte envelope, best-effort and reliable). Readers' acknowledgements are not seen by this
//! layer, and the estimate counts one copy per sample whatever the number of readers. Exact socket-level figures come from a measurement in a fresh network
//! namespace (`measure::netns`, `cortex bench rtt|fanout`).

use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use bytes::Bytes;
use crossbeam_channel::{Receiver, SendTimeoutError, Sender, bounded};
use rustdds::no_key::{DataWriter, Decode, DefaultDecoder, DeserializerAdapter, SerializerAdapter, SimpleDataReader};
use rustdds::policy::{Durability, History, Reliability, ResourceLimits};
use rustdds::{
    DomainParticipant, DomainParticipantBuilder, DomainParticipantStatusEvent, DomainParticipantStatusListener, GUID,
    QosPolicies, QosPolicyBuilder, RTPSEntity, RepresentationIdentifier, StatusEvented, Topic, TopicKind,
    WriteOptionsBuilder,
};

use crate::{
    Channel, Clock, Counters, EndpointId, Sample, Sink, SystemClock, Transport, TransportError, TransportStats,
};

mod receive;

use receive::{CREATING_PARTICIPANTS, DiscoveryWatch, EngineThread, Outlet, Rebuild, receive_loop};

/// When discovery reached each step, in wall-clock nanoseconds since the Unix epoch ([`SystemClock`], so times of
/// different processes on one host compare); `None` until it happens.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct DiscoveryTimes {
    /// The participant, its topics, writers and readers were created.
    pub created_ns: u64,
    /// The first remote participant was discovered.
    pub first_participant_ns: Option<u64>,
    /// Per channel (by [`Channel::index`]): this participant's writer matched its first remote reader.
    pub writer_matched_ns: [Option<u64>; 3],
    /// Per channel (by [`Channel::index`]): this participant's reader matched its first remote writer.
    pub reader_matched_ns: [Option<u64>; 3],
}

/// Most remote readers remembered per channel for directed writes; past it, [`Transport::publish_to`] of an
/// unremembered peer falls back to a write to every reader.
const MAX_REMEMBERED_READERS: usize = 4096;

/// A participant's GUID prefix (the first 12 bytes of every GUID of its entities).
type Prefix = [u8; 12];

/// The GUID prefix of `guid`.
fn prefix_of(guid: GUID) -> Prefix {
    let bytes = guid.to_bytes();
    let mut prefix = [0; 12];
    prefix.copy_from_slice(&bytes[..12]);
    prefix
}

/// First 8 bytes of a transport's own control sample on the `Sync` topic, which tells peers the GUID prefix of
/// its readers' participant (12 bytes follow). Samples are tagged with the writing participant's prefix, and the
/// readers live in another participant, so without it a peer could not address this transport's reader alone.
/// The receiving thread consumes these samples; they never reach the inbox.
const READERS_AT: [u8; 8] = *b"\xffRTPSrd1";

/// What the receiving thread learns from discovery, shared with the transport.
#[derive(Debug, Default)]
struct DiscoveryState {
    times: Mutex<DiscoveryTimes>,
    sync_matches: AtomicU64,
    /// The remote readers each channel's writer has matched (by [`Channel::index`]), for directed writes.
    readers: Mutex<[Vec<GUID>; 3]>,
    /// Peers' readers' participants, learnt from their [`READERS_AT`] samples (bounded).
    reading_prefixes: Mutex<Vec<(EndpointId, Prefix)>>,
    /// A new remote reader matched this transport's sync writer: tell it where this transport's readers are,
    /// before the next sample this transport publishes.
    announce_pending: AtomicBool,
}

impl DiscoveryState {
    /// A matched remote reader of `channel` of the transport `to`.
    fn reader_of(&self, channel: Channel, to: EndpointId) -> Option<GUID> {
        let prefix = self
            .reading_prefixes
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .iter()
            .find(|(peer, _)| *peer == to)
            .map(|(_, prefix)| *prefix);
        let readers = self.readers.lock().unwrap_or_else(|p| p.into_inner());
        readers[channel.index()]
            .iter()
            .copied()
            .find(|guid| prefix.map_or_else(|| endpoint_of(*guid) == to, |prefix| prefix_of(*guid) == prefix))
    }

    /// Records a peer's [`READERS_AT`] sample; `false` if `bytes` is not one.
    fn learn_reading_prefix(&self, origin: EndpointId, bytes: &[u8]) -> bool {
        let Some(prefix) = bytes.strip_prefix(&READERS_AT).and_then(|rest| <[u8; 12]>::try_from(rest).ok()) else {
            return false;
        };
        let mut known = self.reading_prefixes.lock().unwrap_or_else(|p| p.into_inner());
        known.retain(|(peer, _)| *peer != origin);
        if known.len() < MAX_REMEMBERED_READERS {
            known.push((origin, prefix));
        }
        true
    }
}

/// Whether user data to several same-host readers goes out once, as multicast (see the module documentation).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Multicast {
    /// [`Multicast::On`] when the loopback interface is up and multicast-capable, [`Multicast::Off`] otherwise.
    #[default]
    Auto,
    /// Same-host readers share one multicast datagram (`rustdds` `same_host_loopback(false)`). Discovery then
    /// needs a multicast-capable interface, since the unicast "localhost peers" announcements are off too. Each
    /// transport runs two participants (see [`RtpsTransport::new`]); `rustdds` allows 120 participants per domain
    /// and host, so at most 60 such transports share a domain on one host.
    On,
    /// `rustdds`'s default: a reader confirmed to be on this host gets its own unicast copy over loopback.
    Off,
}

impl Multicast {
    /// Whether this setting means multicast on this host now (`Auto` asks [`loopback_multicast_capable`]).
    pub fn resolve(self) -> bool {
        match self {
            Multicast::Auto => loopback_multicast_capable(),
            Multicast::On => true,
            Multicast::Off => false,
        }
    }
}

/// Whether a loopback interface with an IPv4 address is up and multicast-capable in this network namespace,
/// as `rustdds` sees interfaces (the same `netdev` enumeration), so that it joins its multicast groups on it.
pub fn loopback_multicast_capable() -> bool {
    netdev::get_interfaces()
        .iter()
        .any(|iface| iface.is_loopback() && iface.is_up() && iface.is_multicast() && !iface.ipv4.is_empty())
}

/// This host's IPv4 addresses outside `127.0.0.0/8`, if it has any: what a multicast participant advertises.
pub fn routable_ipv4_addresses() -> Option<Vec<std::net::IpAddr>> {
    let addresses: Vec<std::net::IpAddr> = netdev::get_interfaces()
        .iter()
        .filter(|iface| iface.is_up())
        .flat_map(|iface| iface.ipv4.iter().map(|net| net.addr()))
        .filter(|addr| !addr.is_loopback())
        .map(std::net::IpAddr::V4)
        .collect();
    (!addresses.is_empty()).then_some(addresses)
}

/// Settings of an [`RtpsTransport`].
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct RtpsConfig {
    /// DDS domain id (0..=232 with the standard port mapping).
    pub domain_id: u16,
    /// Prefix of the topic names, so that several graphs can share a domain.
    pub topic_prefix: String,
    /// `ResourceLimits::max_samples` of every reader and writer.
    pub max_samples: i32,
    /// Samples the inbox holds before the receiving thread stops taking from the readers.
    pub inbox_capacity: usize,
    /// Largest sample accepted for publishing.
    pub max_sample_bytes: usize,
    /// Samples at least this large count towards pacing.
    pub large_sample_bytes: usize,
    /// After this many bytes of large samples, wait for acknowledgements before writing more.
    pub pace_bytes: usize,
    /// Longest wait for acknowledgements when pacing, and longest blocking of a write on a full send window.
    pub max_blocking: Duration,
    /// Create the readers in a second DDS participant, so that no writer has a reader in its own participant (see
    /// the module documentation: with one shared participant, fragmented samples are sent twice to same-host
    /// readers and delivery stalls). `false` keeps one participant per transport, for comparison only.
    pub separate_reader_participant: bool,
    /// One multicast datagram for all same-host readers, or one unicast copy each.
    pub multicast: Multicast,
    /// How samples on [`Channel::Updates`] travel: reliable like every other channel, or small ones best-effort.
    pub updates: UpdateDelivery,
}

/// How samples on [`Channel::Updates`] travel (see the module documentation, "Best-effort updates").
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum UpdateDelivery {
    /// Reliable, like every other channel. `rustdds` puts a heartbeat that asks for an acknowledgement beside every
    /// DATA, so every matched reader — the writer's own transport's reader included — acknowledges every sample.
    #[default]
    Reliable,
    /// Samples of at most `max_bytes` go on a best-effort topic of their own (`{prefix}_updates_be`): no heartbeat,
    /// no acknowledgement, no repair by the DDS engine. Larger samples stay reliable. Whoever uses this repairs
    /// losses itself: agents do, by anti-entropy and by asking a peer at once when a delta shows a gap.
    BestEffort {
        /// The largest sample sent best-effort (keep it below one datagram: a lost fragment loses the sample).
        max_bytes: usize,
    },
}

impl UpdateDelivery {
    /// Best-effort for samples up to 1 KB, which stay one datagram on any usual path MTU.
    pub const BEST_EFFORT_SMALL: UpdateDelivery = UpdateDelivery::BestEffort { max_bytes: 1024 };

    /// The name used on command lines and in reports: `reliable` or `best-effort`.
    pub fn name(self) -> &'static str {
        match self {
            UpdateDelivery::Reliable => "reliable",
            UpdateDelivery::BestEffort { .. } => "best-effort",
        }
    }
}

impl Default for RtpsConfig {
    fn default() -> Self {
        RtpsConfig {
            domain_id: 0,
            topic_prefix: "dsr".into(),
            max_samples: 100_000,
            inbox_capacity: 65_536,
            max_sample_bytes: 256 << 20,
            large_sample_bytes: 64 << 10,
            pace_bytes: 4 << 20,
            max_blocking: Duration::from_secs(2),
            separate_reader_participant: true,
            multicast: Multicast::Auto,
            updates: UpdateDelivery::Reliable,
        }
    }
}

/// Estimated wire bytes of one sample of `payload` bytes, written reliably (with its heartbeat) or best-effort
/// (see the module documentation).
pub fn estimated_wire_bytes(payload: usize, reliable: bool) -> usize {
    let datagrams = payload.div_ceil(64 << 10).max(1);
    let heartbeat = if reliable { 32 } else { 0 };
    (payload + 8).next_multiple_of(4) + 24 + heartbeat + 48 * datagrams
}

/// A sample as `rustdds` sees it: opaque bytes.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Payload(pub Bytes);

/// Why bytes from the network are not a CDR `sequence<octet>`.
#[derive(Debug, thiserror::Error)]
pub enum PayloadError {
    /// Fewer than 4 bytes, or a length past the end.
    #[error("sample of {got} bytes is not a cdr octet sequence (declared length {declared:?})")]
    Truncated {
        /// Bytes present.
        got: usize,
        /// The length field, if there was one.
        declared: Option<u32>,
    },
}

/// Serializes and deserializes [`Payload`] as a CDR `sequence<octet>` without going through serde per byte.
#[derive(Debug)]
pub struct OctetsAdapter;

/// The default decoder of [`OctetsAdapter`].
#[derive(Clone, Copy, Debug)]
pub struct OctetsDecoder;

impl SerializerAdapter<Payload> for OctetsAdapter {
    type Error = PayloadError;

    fn output_encoding() -> RepresentationIdentifier {
        RepresentationIdentifier::CDR_LE
    }

    fn to_bytes(value: &Payload) -> Result<Bytes, PayloadError> {
        let len = u32::try_from(value.0.len()).map_err(|_| PayloadError::Truncated { got: 0, declared: None })?;
        let mut out = Vec::with_capacity(4 + value.0.len());
        out.extend_from_slice(&len.to_le_bytes());
        out.extend_from_slice(&value.0);
        Ok(Bytes::from(out))
    }
}

const ENCODINGS: [RepresentationIdentifier; 2] = [RepresentationIdentifier::CDR_LE, RepresentationIdentifier::CDR_BE];

impl DeserializerAdapter<Payload> for OctetsAdapter {
    type Error = PayloadError;
    type Decoded = Payload;

    fn supported_encodings() -> &'static [RepresentationIdentifier] {
        &ENCODINGS
    }

    fn transform_decoded(decoded: Payload) -> Payload {
        decoded
    }
}

impl DefaultDecoder<Payload> for OctetsAdapter {
    type Decoder = OctetsDecoder;
    const DECODER: OctetsDecoder = OctetsDecoder;
}

impl<'de> Decode<'de, Payload> for OctetsDecoder {
    type Error = PayloadError;

    fn decode_bytes(self, input: &'de [u8], encoding: RepresentationIdentifier) -> Result<Payload, PayloadError> {
        let Some(head) = input.get(..4) else {
            return Err(PayloadError::Truncated { got: input.len(), declared: None });
        };
        let head = [head[0], head[1], head[2], head[3]];
        let len = if encoding == RepresentationIdentifier::CDR_BE {
            u32::from_be_bytes(head)
        } else {
            u32::from_le_bytes(head)
        };
        let body = input
            .get(4..)
            .and_then(|rest| rest.get(..len as usize))
            .ok_or(PayloadError::Truncated { got: input.len(), declared: Some(len) })?;
        Ok(Payload(Bytes::copy_from_slice(body)))
    }
}

type Writer = DataWriter<Payload, OctetsAdapter>;
type Reader = SimpleDataReader<Payload, OctetsAdapter>;

/// The QoS of every reader and writer: reliable, keep-all, volatile, explicit resource limits.
pub fn qos(config: &RtpsConfig) -> QosPolicies {
    qos_with(config, Reliability::Reliable { max_blocking_time: config.max_blocking.into() })
}

/// [`qos`] with another reliability (the best-effort updates topic).
fn qos_with(config: &RtpsConfig, reliability: Reliability) -> QosPolicies {
    QosPolicyBuilder::new()
        .reliability(reliability)
        .history(History::KeepAll)
        .durability(Durability::Volatile)
        .resource_limits(ResourceLimits {
            max_samples: config.max_samples,
            max_instances: 1,
            max_samples_per_instance: config.max_samples,
        })
        .build()
}

/// One writer and one reader per channel: the writers in a publishing DDS participant, the readers in a subscribing
/// one (the same participant if [`RtpsConfig::separate_reader_participant`] is off). If `rustdds`'s own threads
/// of these participants end, the receiving thread builds them again with new writers and readers and swaps them
/// in (see the module documentation, "Recovery").
pub struct RtpsTransport {
    /// The writers and participants in use, shared with the receiving thread, which owns the readers and swaps in
    /// new ones after a rebuild. Dropped after the receiving thread has ended.
    shared: Arc<Shared>,
    inbox: Receiver<Sample>,
    /// Where received samples go instead of the inbox, while set ([`Transport::set_sink`]); locked during a call.
    sink: Arc<Mutex<Option<Sink>>>,
    stop: Arc<AtomicBool>,
    receiver: Option<JoinHandle<()>>,
    counters: Arc<Counters>,
    unpaced_large_bytes: AtomicUsize,
    discovery: Arc<DiscoveryState>,
    config: RtpsConfig,
    multicast: bool,
}

/// The part of the DDS entities in use that publishing needs; the receiving thread replaces each of them in place
/// when it rebuilds the participants. Fields drop in order: the writers before the participants.
struct Shared {
    /// One writer per channel (by [`Channel::index`]).
    writers: Vec<Mutex<Writer>>,
    /// The best-effort updates writer and the largest sample it takes ([`UpdateDelivery::BestEffort`]).
    best_effort: Option<(Mutex<Writer>, usize)>,
    /// This transport's endpoint id (its publishing participant's GUID prefix, which tags its samples) and the GUID
    /// prefix of the participant holding its readers (told to peers, see [`READERS_AT`]).
    identity: Mutex<(EndpointId, Prefix)>,
    participants: Mutex<Participants>,
}

/// The participants of one generation of DDS entities.
struct Participants {
    _publishing: DomainParticipant,
    /// The readers' own participant (see [`RtpsTransport::new`]); `None` only when neither
    /// `separate_reader_participant` nor multicast asks for it.
    _subscribing: Option<DomainParticipant>,
}

/// A full set of DDS entities, as [`Generation::build`] makes them: at start, and at every rebuild.
/// Fields drop in order: the writers and readers before the participants.
struct Generation {
    writers: Vec<Writer>,
    best_effort: Option<Writer>,
    reading: Reading,
    local: EndpointId,
    reading_prefix: Prefix,
    participants: Participants,
}

/// What the receiving thread owns of a generation.
struct Reading {
    readers: Vec<(Channel, Reader)>,
    watch: DiscoveryWatch,
    /// The endpoint id of this generation's writers: samples from it are this transport's own.
    local: EndpointId,
    /// The threads `rustdds` runs for this generation's participants (empty where they cannot be watched).
    engine: Vec<EngineThread>,
}

impl std::fmt::Debug for RtpsTransport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RtpsTransport")
            .field("local", &self.local_id())
            .field("config", &self.config)
            .field("multicast", &self.multicast)
            .finish()
    }
}

fn setup(what: impl Into<String>) -> impl FnOnce(rustdds::dds::CreateError) -> TransportError {
    let what = what.into();
    move |e| TransportError::Setup { what, detail: format!("{e:?}") }
}

/// The endpoint id of a participant or writer: its 12-byte GUID prefix.
fn endpoint_of(guid: rustdds::GUID) -> EndpointId {
    let bytes = guid.to_bytes();
    let mut wide = [0u8; 16];
    wide[4..].copy_from_slice(&bytes[..12]);
    EndpointId(u128::from_be_bytes(wide))
}

/// The largest best-effort sample of `config`, if its updates go best-effort.
fn best_effort_max_bytes(config: &RtpsConfig) -> Option<usize> {
    match config.updates {
        UpdateDelivery::Reliable => None,
        UpdateDelivery::BestEffort { max_bytes } => Some(max_bytes),
    }
}

impl Generation {
    /// Joins the DDS domain with new participants and creates every topic, writer and reader in them (see
    /// [`RtpsTransport::new`]); `state` is where the new readers' discovery events are recorded.
    fn build(config: &RtpsConfig, multicast: bool, state: &Arc<DiscoveryState>) -> Result<Generation, TransportError> {
        let networks = if multicast { routable_ipv4_addresses() } else { None };
        let join = |role: &str| {
            let mut builder = DomainParticipantBuilder::new(config.domain_id).same_host_loopback(!multicast);
            if let Some(addresses) = networks.clone() {
                builder = builder.with_only_networks(addresses);
            }
            builder.build().map_err(|e| TransportError::Setup {
                what: format!("{role} participant in domain {}", config.domain_id),
                detail: format!("{e:?}"),
            })
        };
        let (publishing, subscribing, engine) = {
            let _creating = CREATING_PARTICIPANTS.lock().unwrap_or_else(|p| p.into_inner());
            let before = EngineThread::all();
            let publishing = join("publishing")?;
            // Multicast needs the readers apart too: rustdds never routes a writer to its own participant's
            // readers, and their fallback path would send a second copy.
            let subscribing =
                if config.separate_reader_participant || multicast { Some(join("subscribing")?) } else { None };
            let engine: Vec<EngineThread> = EngineThread::all().into_iter().filter(|t| !before.contains(t)).collect();
            (publishing, subscribing, engine)
        };
        let participants = 1 + usize::from(subscribing.is_some());
        if engine.len() != 2 * participants {
            tracing::warn!(
                "rtps: found {} rustdds threads for {participants} new participant(s), expected {}: a participant \
                 whose threads end may go unnoticed (no /proc/self/task, or participants created elsewhere in this \
                 process at the same time)",
                engine.len(),
                2 * participants
            );
        }
        let qos = qos(config);
        let publisher = publishing.create_publisher(&qos).map_err(setup("publisher"))?;
        let subscriber =
            subscribing.as_ref().unwrap_or(&publishing).create_subscriber(&qos).map_err(setup("subscriber"))?;
        let mut writers = Vec::new();
        let mut readers = Vec::new();
        let mut endpoints = Vec::new();
        // The topic of `name` in the publishing participant, and in the subscribing one (the same if none).
        let topics = |name: &str, qos: &QosPolicies| -> Result<(Topic, Topic), TransportError> {
            let topic = |participant: &DomainParticipant| {
                participant
                    .create_topic(name.to_owned(), "cortex::Envelope".into(), qos, TopicKind::NoKey)
                    .map_err(setup(format!("topic {name}")))
            };
            let written = topic(&publishing)?;
            let read = match &subscribing {
                Some(participant) => topic(participant)?,
                None => written.clone(),
            };
            Ok((written, read))
        };
        let writer = |topic: &Topic, name: &str, qos: &QosPolicies| {
            publisher
                .create_datawriter_no_key::<Payload, OctetsAdapter>(topic, Some(qos.clone()))
                .map_err(setup(format!("writer of {name}")))
        };
        let reader = |topic: &Topic, name: &str, qos: &QosPolicies| {
            subscriber
                .create_simple_datareader_no_key::<Payload, OctetsAdapter>(topic, Some(qos.clone()))
                .map_err(setup(format!("reader of {name}")))
        };
        for channel in Channel::ALL {
            let name = format!("{}_{}", config.topic_prefix, channel.name());
            let (written, read) = topics(&name, &qos)?;
            let writer = writer(&written, &name, &qos)?;
            let reader = reader(&read, &name, &qos)?;
            endpoints.push((channel, writer.guid(), reader.guid()));
            writers.push(writer);
            readers.push((channel, reader));
        }
        // Every transport reads the best-effort updates topic, so agents of one graph may mix settings; only a
        // transport set to best-effort writes on it.
        let best_effort = {
            let name = format!("{}_updates_be", config.topic_prefix);
            let qos = qos_with(config, Reliability::BestEffort);
            let (written, read) = topics(&name, &qos)?;
            let reader = reader(&read, &name, &qos)?;
            let writer = match best_effort_max_bytes(config) {
                None => None,
                Some(_) => {
                    let writer = writer(&written, &name, &qos)?;
                    endpoints.push((Channel::Updates, writer.guid(), reader.guid()));
                    Some(writer)
                }
            };
            readers.push((Channel::Updates, reader));
            writer
        };
        // Samples are tagged with their writer's GUID prefix: the publishing participant's.
        let local = endpoint_of(publishing.guid());
        // Discovery events of both participants: the writers' matches come from the publishing one, the readers'
        // from the subscribing one.
        let mut statuses = vec![publishing.status_listener()];
        statuses.extend(subscribing.as_ref().map(DomainParticipant::status_listener));
        let reading_prefix = prefix_of(subscribing.as_ref().unwrap_or(&publishing).guid());
        let own = vec![prefix_of(publishing.guid()), reading_prefix];
        let watch = DiscoveryWatch { statuses, own, endpoints, state: Arc::clone(state) };
        Ok(Generation {
            writers,
            best_effort,
            local,
            reading_prefix,
            participants: Participants { _publishing: publishing, _subscribing: subscribing },
            reading: Reading { readers, watch, local, engine },
        })
    }
}

impl RtpsTransport {
    /// Joins the DDS domain (one or two participants, see [`RtpsConfig::separate_reader_participant`]) and starts
    /// the receiving thread.
    ///
    /// With multicast ([`RtpsConfig::multicast`]) the readers always live in a second participant of their own,
    /// whatever `separate_reader_participant` says. A `rustdds` writer also sends to the readers of its own
    /// participant, and it never learns a route to its own participant (it does not record where its own traffic
    /// arrives), so that reader takes the fallback path, whose sends are de-duplicated separately from the routed
    /// ones: every sample would go to the multicast group twice. A reader in another participant is routed like
    /// any remote reader, and its multicast route is the one datagram all readers share.
    ///
    /// # Errors
    /// [`TransportError::Setup`] if a participant, a topic, a reader or a writer cannot be created.
    pub fn new(config: RtpsConfig) -> Result<Self, TransportError> {
        let multicast = config.multicast.resolve();
        let discovery = Arc::new(DiscoveryState::default());
        let generation = Generation::build(&config, multicast, &discovery)?;
        discovery.times.lock().unwrap_or_else(|p| p.into_inner()).created_ns = SystemClock.now_ns();
        let Generation { writers, best_effort, local, reading_prefix, participants, reading } = generation;
        let shared = Arc::new(Shared {
            writers: writers.into_iter().map(Mutex::new).collect(),
            best_effort: best_effort.zip(best_effort_max_bytes(&config)).map(|(w, max)| (Mutex::new(w), max)),
            identity: Mutex::new((local, reading_prefix)),
            participants: Mutex::new(participants),
        });
        let (sender, inbox) = bounded(config.inbox_capacity.max(1));
        let sink = Arc::new(Mutex::new(None));
        let stop = Arc::new(AtomicBool::new(false));
        let counters = Arc::new(Counters::default());
        let receiver = {
            let outlet = Outlet { inbox: sender, sink: Arc::clone(&sink), counters: Arc::clone(&counters) };
            let rebuild = Rebuild {
                config: config.clone(),
                multicast,
                shared: Arc::clone(&shared),
                discovery: Arc::clone(&discovery),
                counters: Arc::clone(&counters),
                last: None,
            };
            let stop = Arc::clone(&stop);
            std::thread::Builder::new()
                .name("rtps-receive".into())
                .spawn(move || receive_loop(reading, rebuild, outlet, &stop))
                .map_err(|e| TransportError::Setup { what: "receiving thread".into(), detail: e.to_string() })?
        };
        Ok(RtpsTransport {
            shared,
            inbox,
            sink,
            stop,
            receiver: Some(receiver),
            counters,
            unpaced_large_bytes: AtomicUsize::new(0),
            discovery,
            config,
            multicast,
        })
    }

    /// The settings in force.
    pub fn config(&self) -> &RtpsConfig {
        &self.config
    }

    /// Whether this participant sends to same-host readers as multicast ([`RtpsConfig::multicast`] resolved).
    pub fn multicast(&self) -> bool {
        self.multicast
    }

    /// When discovery found the first peer and matched each channel's writer and reader (see [`DiscoveryTimes`]).
    /// After a rebuild of the participants these stay the first generation's times.
    pub fn discovery(&self) -> DiscoveryTimes {
        *self.discovery.times.lock().unwrap_or_else(|p| p.into_inner())
    }
}

impl Drop for RtpsTransport {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::SeqCst);
        if let Some(handle) = self.receiver.take() {
            let _ = handle.join();
        }
    }
}

impl Transport for RtpsTransport {
    fn local_id(&self) -> EndpointId {
        self.shared.identity.lock().unwrap_or_else(|p| p.into_inner()).0
    }

    fn publish(&self, channel: Channel, bytes: Bytes) -> Result<(), TransportError> {
        self.write(channel, bytes, None)
    }

    fn publish_to(&self, channel: Channel, bytes: Bytes, to: EndpointId) -> Result<(), TransportError> {
        // A peer whose reader discovery has not reported yet gets the sample like everyone else.
        let reader = self.discovery.reader_of(channel, to);
        self.write(channel, bytes, reader)
    }

    fn try_recv(&self) -> Option<Sample> {
        self.counters.take(&self.inbox, None)
    }

    fn recv_timeout(&self, timeout: Duration) -> Option<Sample> {
        self.counters.take(&self.inbox, Some(timeout))
    }

    fn stats(&self) -> TransportStats {
        self.counters.snapshot()
    }

    fn sync_matches(&self) -> u64 {
        self.discovery.sync_matches.load(Ordering::Acquire)
    }

    fn set_sink(&self, sink: Option<Sink>) -> bool {
        *self.sink.lock().unwrap_or_else(|p| p.into_inner()) = sink;
        true
    }
}

impl RtpsTransport {
    /// Writes one sample to every matched reader of `channel`, or to `reader` alone (the others are told, by a GAP,
    /// that the sequence number is not for them), with back-pressure and pacing of large samples.
    fn write(&self, channel: Channel, bytes: Bytes, reader: Option<GUID>) -> Result<(), TransportError> {
        // A plain load first: the read-modify-write only happens in the rare case that a peer has matched.
        if self.discovery.announce_pending.load(Ordering::Relaxed)
            && self.discovery.announce_pending.swap(false, Ordering::AcqRel)
        {
            // Before this sample: peers that matched since the last one learn where this transport's readers are
            // (a peer answering a request in this sample can then address the reply to them alone).
            let reading_prefix = self.shared.identity.lock().unwrap_or_else(|p| p.into_inner()).1;
            let mut announce = READERS_AT.to_vec();
            announce.extend_from_slice(&reading_prefix);
            self.write_sample(Channel::Sync, Bytes::from(announce), None)?;
        }
        self.write_sample(channel, bytes, reader)
    }

    fn write_sample(&self, channel: Channel, bytes: Bytes, reader: Option<GUID>) -> Result<(), TransportError> {
        let size = bytes.len();
        if size > self.config.max_sample_bytes {
            return Err(TransportError::TooLarge {
                channel: channel.name(),
                size,
                limit: self.config.max_sample_bytes,
            });
        }
        if channel == Channel::Updates
            && reader.is_none()
            && let Some((writer, max_bytes)) = &self.shared.best_effort
            && size <= *max_bytes
        {
            // Best-effort never waits for acknowledgements; a full send buffer loses the sample, which the user of
            // this transport repairs.
            let writer = writer.lock().unwrap_or_else(|p| p.into_inner());
            writer
                .write(Payload(bytes), None)
                .map_err(|error| TransportError::Write { channel: channel.name(), detail: format!("{error:?}") })?;
            self.counters.sent(size, estimated_wire_bytes(size, false));
            return Ok(());
        }
        let writer = self.shared.writers[channel.index()].lock().unwrap_or_else(|p| p.into_inner());
        let deadline = Instant::now() + self.config.max_blocking * 4;
        let payload = Payload(bytes);
        loop {
            let written = match reader {
                Some(reader) => writer
                    .write_with_options(payload.clone(), WriteOptionsBuilder::new().to_single_reader(reader).build())
                    .map(|_| ()),
                None => writer.write(payload.clone(), None),
            };
            match written {
                Ok(()) => break,
                Err(rustdds::dds::result::WriteError::WouldBlock { .. }) if Instant::now() < deadline => {
                    // The send window is full: back-pressure. Give acknowledgements a chance, then retry.
                    let _ = writer.wait_for_acknowledgments(Duration::from_millis(100));
                }
                Err(error) => {
                    return Err(TransportError::Write { channel: channel.name(), detail: format!("{error:?}") });
                }
            }
        }
        if size >= self.config.large_sample_bytes {
            let pending = self.unpaced_large_bytes.fetch_add(size, Ordering::Relaxed) + size;
            if pending >= self.config.pace_bytes {
                self.unpaced_large_bytes.store(0, Ordering::Relaxed);
                let _ = writer.wait_for_acknowledgments(self.config.max_blocking);
            }
        }
        self.counters.sent(size, estimated_wire_bytes(size, true));
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn octets_round_trip_and_truncation_is_an_error() {
        let payload = Payload(Bytes::from_static(b"hello"));
        let bytes = OctetsAdapter::to_bytes(&payload).unwrap();
        assert_eq!(&bytes[..4], &5u32.to_le_bytes());
        let back = OctetsDecoder.decode_bytes(&bytes, RepresentationIdentifier::CDR_LE).unwrap();
        assert_eq!(back, payload);
        for cut in 0..bytes.len() {
            assert!(OctetsDecoder.decode_bytes(&bytes[..cut], RepresentationIdentifier::CDR_LE).is_err(), "cut {cut}");
        }
        let be = [0, 0, 0, 2, 7, 8];
        assert_eq!(&OctetsDecoder.decode_bytes(&be, RepresentationIdentifier::CDR_BE).unwrap().0[..], &[7, 8]);
    }

    #[test]
    fn the_threads_of_new_participants_are_found_and_their_end_is_seen() {
        if std::fs::read_dir("/proc/self/task").is_err() {
            return; // Not Linux: nothing to watch.
        }
        let config = RtpsConfig { domain_id: 94, topic_prefix: "engine_threads".into(), ..RtpsConfig::default() };
        let generation = Generation::build(&config, false, &Arc::new(DiscoveryState::default())).unwrap();
        let threads = generation.reading.engine.clone();
        // Two participants, each with its event loop and its discovery thread.
        assert_eq!(threads.len(), 4, "{threads:?}");
        assert_eq!(threads.iter().filter(|t| t.name.starts_with("RustDDS Partici")).count(), 2, "{threads:?}");
        assert!(threads.iter().all(EngineThread::alive));
        drop(generation);
        let deadline = Instant::now() + Duration::from_secs(5);
        while threads.iter().any(EngineThread::alive) {
            assert!(Instant::now() < deadline, "threads still running after their participants were dropped");
            std::thread::sleep(Duration::from_millis(10));
        }
    }

    #[test]
    fn wire_estimate_grows_with_datagrams() {
        // A 50-byte envelope: IPv4 + UDP + RTPS header (48), DATA (24), encapsulation and length (8), padding to 4
        // (2); reliable adds the heartbeat (32). Measured on loopback: 132 and 164 bytes per datagram.
        assert_eq!(estimated_wire_bytes(50, false), 132);
        assert_eq!(estimated_wire_bytes(50, true), 164);
        assert!(estimated_wire_bytes(1 << 20, true) > (1 << 20) + 16 * 48);
    }
}
