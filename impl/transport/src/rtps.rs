//! RTPS through `rustdds`: the transport real agents use.
//!
//! One DDS domain participant per agent, one non-keyed topic per [`Channel`] named `{prefix}_{channel}`, every
//! writer and reader RELIABLE + KEEP_ALL + VOLATILE with **explicit [`ResourceLimits`] (`rustdds` otherwise keeps
//! only 64 samples per reader)**. A sample travels as a CDR `sequence<octet>` (4-byte length, then the bytes), so
//! any DDS implementation can read it with a one-field IDL type.
//!
//! A receiving thread waits on the readers with `mio` and moves samples into a **bounded inbox**; when the inbox is
//! full it stops taking, the readers' caches fill, and the reliable protocol pushes back on the writers. Samples
//! this participant wrote itself are skipped. **Large samples are paced**: after every [`RtpsConfig::pace_bytes`]
//! of large samples the writer waits (bounded) for acknowledgements, so a burst of 1 MB frames is delivered rather
//! than stalled. Domain id and topic prefix are configurable so several graphs can share a host; discovery uses
//! the standard unicast locators and works on loopback without network configuration.
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
//! Wire bytes are estimated per sample as the payload plus its CDR header and length (8 B), the RTPS DATA and
//! INFO_TS submessages (36 B), and one RTPS header plus UDP/IPv4 header (48 B) per datagram of up to 64 KiB;
//! acknowledgements and heartbeats are not seen by this layer.

use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use bytes::Bytes;
use crossbeam_channel::{Receiver, SendTimeoutError, Sender, bounded};
use rustdds::no_key::{DataWriter, Decode, DefaultDecoder, DeserializerAdapter, SerializerAdapter, SimpleDataReader};
use rustdds::policy::{Durability, History, Reliability, ResourceLimits};
use rustdds::{
    DomainParticipant, DomainParticipantStatusEvent, DomainParticipantStatusListener, GUID, QosPolicies,
    QosPolicyBuilder, RTPSEntity, RepresentationIdentifier, StatusEvented, TopicKind, WriteOptionsBuilder,
};

use crate::{Channel, Clock, Counters, EndpointId, Sample, SystemClock, Transport, TransportError, TransportStats};

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

/// What the receiving thread learns from discovery, shared with the transport.
#[derive(Debug, Default)]
struct DiscoveryState {
    times: Mutex<DiscoveryTimes>,
    sync_matches: AtomicU64,
    /// The remote readers each channel's writer has matched (by [`Channel::index`]), for directed writes.
    readers: Mutex<[Vec<GUID>; 3]>,
}

impl DiscoveryState {
    /// A matched remote reader of `channel` in the participant `to`.
    fn reader_of(&self, channel: Channel, to: EndpointId) -> Option<GUID> {
        let readers = self.readers.lock().unwrap_or_else(|p| p.into_inner());
        readers[channel.index()].iter().copied().find(|guid| endpoint_of(*guid) == to)
    }
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
        }
    }
}

/// Estimated wire bytes of one sample of `payload` bytes (see the module documentation).
pub fn estimated_wire_bytes(payload: usize) -> usize {
    let datagrams = payload.div_ceil(64 << 10).max(1);
    payload + 8 + 36 + 48 * datagrams
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
    QosPolicyBuilder::new()
        .reliability(Reliability::Reliable { max_blocking_time: config.max_blocking.into() })
        .history(History::KeepAll)
        .durability(Durability::Volatile)
        .resource_limits(ResourceLimits {
            max_samples: config.max_samples,
            max_instances: 1,
            max_samples_per_instance: config.max_samples,
        })
        .build()
}

/// A DDS participant with one writer and one reader per channel.
pub struct RtpsTransport {
    // Writers before the participant, so they are dropped first.
    writers: Vec<Mutex<Writer>>,
    inbox: Receiver<Sample>,
    stop: Arc<AtomicBool>,
    receiver: Option<JoinHandle<()>>,
    counters: Arc<Counters>,
    local: EndpointId,
    unpaced_large_bytes: AtomicUsize,
    discovery: Arc<DiscoveryState>,
    config: RtpsConfig,
    _participant: DomainParticipant,
}

impl std::fmt::Debug for RtpsTransport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RtpsTransport").field("local", &self.local).field("config", &self.config).finish()
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

impl RtpsTransport {
    /// Joins the DDS domain and starts the receiving thread.
    ///
    /// # Errors
    /// [`TransportError::Setup`] if the participant, a topic, a reader or a writer cannot be created.
    pub fn new(config: RtpsConfig) -> Result<Self, TransportError> {
        let participant = DomainParticipant::new(config.domain_id).map_err(|e| TransportError::Setup {
            what: format!("participant in domain {}", config.domain_id),
            detail: format!("{e:?}"),
        })?;
        let qos = qos(&config);
        let publisher = participant.create_publisher(&qos).map_err(setup("publisher"))?;
        let subscriber = participant.create_subscriber(&qos).map_err(setup("subscriber"))?;
        let mut writers = Vec::new();
        let mut readers = Vec::new();
        let mut endpoints = Vec::new();
        for channel in Channel::ALL {
            let name = format!("{}_{}", config.topic_prefix, channel.name());
            let topic = participant
                .create_topic(name.clone(), "cortex::Envelope".into(), &qos, TopicKind::NoKey)
                .map_err(setup(format!("topic {name}")))?;
            let writer = publisher
                .create_datawriter_no_key::<Payload, OctetsAdapter>(&topic, Some(qos.clone()))
                .map_err(setup(format!("writer of {name}")))?;
            let reader = subscriber
                .create_simple_datareader_no_key::<Payload, OctetsAdapter>(&topic, Some(qos.clone()))
                .map_err(setup(format!("reader of {name}")))?;
            endpoints.push((channel, writer.guid(), reader.guid()));
            writers.push(Mutex::new(writer));
            readers.push((channel, reader));
        }
        let local = endpoint_of(participant.guid());
        let discovery = Arc::new(DiscoveryState::default());
        discovery.times.lock().unwrap_or_else(|p| p.into_inner()).created_ns = SystemClock.now_ns();
        let status = participant.status_listener();
        let (sender, inbox) = bounded(config.inbox_capacity.max(1));
        let stop = Arc::new(AtomicBool::new(false));
        let counters = Arc::new(Counters::default());
        let receiver = {
            let stop = Arc::clone(&stop);
            let counters = Arc::clone(&counters);
            let own = participant.guid();
            let watch = DiscoveryWatch { status, own, endpoints, state: Arc::clone(&discovery) };
            std::thread::Builder::new()
                .name("rtps-receive".into())
                .spawn(move || receive_loop(readers, watch, sender, stop, counters, local))
                .map_err(|e| TransportError::Setup { what: "receiving thread".into(), detail: e.to_string() })?
        };
        Ok(RtpsTransport {
            writers,
            inbox,
            stop,
            receiver: Some(receiver),
            counters,
            local,
            unpaced_large_bytes: AtomicUsize::new(0),
            discovery,
            config,
            _participant: participant,
        })
    }

    /// The settings in force.
    pub fn config(&self) -> &RtpsConfig {
        &self.config
    }

    /// When discovery found the first peer and matched each channel's writer and reader (see [`DiscoveryTimes`]).
    pub fn discovery(&self) -> DiscoveryTimes {
        *self.discovery.times.lock().unwrap_or_else(|p| p.into_inner())
    }
}

/// The receiving thread's view of discovery: the participant's status events, and which local writer and reader
/// serve which channel.
struct DiscoveryWatch {
    status: DomainParticipantStatusListener,
    /// This participant's GUID (its prefix is that of all its endpoints): rustdds also matches a participant's
    /// writers with its own readers, which is no peer.
    own: GUID,
    endpoints: Vec<(Channel, GUID, GUID)>,
    state: Arc<DiscoveryState>,
}

impl DiscoveryWatch {
    /// Records the status events waiting (a bounded number per call, so data is never starved).
    fn drain(&self) {
        for _ in 0..256 {
            let Some(event) = self.status.try_recv_status() else { return };
            let now = SystemClock.now_ns();
            let mut times = self.state.times.lock().unwrap_or_else(|p| p.into_inner());
            match event {
                DomainParticipantStatusEvent::ParticipantDiscovered { dpd } if dpd.guid.prefix != self.own.prefix => {
                    times.first_participant_ns.get_or_insert(now);
                }
                DomainParticipantStatusEvent::RemoteReaderMatched { local_writer, remote_reader }
                    if remote_reader.prefix != self.own.prefix =>
                {
                    if let Some((channel, _, _)) = self.endpoints.iter().find(|(_, w, _)| *w == local_writer) {
                        times.writer_matched_ns[channel.index()].get_or_insert(now);
                        let mut readers = self.state.readers.lock().unwrap_or_else(|p| p.into_inner());
                        let known = &mut readers[channel.index()];
                        if !known.contains(&remote_reader) && known.len() < MAX_REMEMBERED_READERS {
                            known.push(remote_reader);
                        }
                        if *channel == Channel::Sync {
                            self.state.sync_matches.fetch_add(1, Ordering::Release);
                        }
                    }
                }
                DomainParticipantStatusEvent::RemoteWriterMatched { local_reader, remote_writer }
                    if remote_writer.prefix != self.own.prefix =>
                {
                    if let Some((channel, _, _)) = self.endpoints.iter().find(|(_, _, r)| *r == local_reader) {
                        times.reader_matched_ns[channel.index()].get_or_insert(now);
                        if *channel == Channel::Sync {
                            self.state.sync_matches.fetch_add(1, Ordering::Release);
                        }
                    }
                }
                DomainParticipantStatusEvent::ReaderLost { guid, .. } => {
                    let mut readers = self.state.readers.lock().unwrap_or_else(|p| p.into_inner());
                    for known in readers.iter_mut() {
                        known.retain(|reader| *reader != guid);
                    }
                }
                DomainParticipantStatusEvent::ParticipantLost { id, .. } => {
                    let mut readers = self.state.readers.lock().unwrap_or_else(|p| p.into_inner());
                    for known in readers.iter_mut() {
                        known.retain(|reader| reader.prefix != id);
                    }
                }
                _ => {}
            }
        }
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

fn receive_loop(
    mut readers: Vec<(Channel, Reader)>,
    mut watch: DiscoveryWatch,
    sender: Sender<Sample>,
    stop: Arc<AtomicBool>,
    counters: Arc<Counters>,
    local: EndpointId,
) {
    use rustdds::mio1::{Events, Interest, Poll, Token};
    let mut poll = match Poll::new() {
        Ok(poll) => poll,
        Err(error) => {
            tracing::error!("rtps receive: cannot create a poller: {error}");
            return;
        }
    };
    for (index, (channel, reader)) in readers.iter_mut().enumerate() {
        if let Err(error) = poll.registry().register(reader, Token(index), Interest::READABLE) {
            tracing::error!("rtps receive: cannot register the {} reader: {error}", channel.name());
            return;
        }
    }
    if let Err(error) =
        poll.registry().register(watch.status.as_status_source_mio1(), Token(readers.len()), Interest::READABLE)
    {
        // Discovery times stay unknown and joiners fall back to their retry period; data still flows.
        tracing::warn!("rtps receive: cannot watch discovery events: {error}");
    }
    let mut events = Events::with_capacity(16);
    while !stop.load(Ordering::Relaxed) {
        if let Err(error) = poll.poll(&mut events, Some(Duration::from_millis(20)))
            && error.kind() != std::io::ErrorKind::Interrupted
        {
            tracing::error!("rtps receive: poll failed: {error}");
            std::thread::sleep(Duration::from_millis(5));
        }
        watch.drain();
        // Take from every reader each round: a notification may have been drained by an earlier round.
        for (channel, reader) in &readers {
            reader.drain_read_notifications();
            loop {
                match reader.try_take_one() {
                    Ok(Some(change)) => {
                        let origin = endpoint_of(change.writer_guid());
                        if origin == local {
                            continue;
                        }
                        let Payload(bytes) = change.into_value();
                        let mut sample = Sample { channel: *channel, origin, bytes };
                        // Bounded inbox: wait (back-pressure) but notice a stop request.
                        loop {
                            match sender.send_timeout(sample, Duration::from_millis(50)) {
                                Ok(()) => break,
                                Err(SendTimeoutError::Timeout(back)) => {
                                    if stop.load(Ordering::Relaxed) {
                                        return;
                                    }
                                    sample = back;
                                }
                                Err(SendTimeoutError::Disconnected(_)) => return,
                            }
                        }
                    }
                    Ok(None) => break,
                    Err(error) => {
                        // A sample rustdds could not decode (foreign type on our topic): logged and skipped.
                        tracing::warn!("rtps receive on {}: dropped an undecodable sample: {error:?}", channel.name());
                        counters.dropped_full();
                        break;
                    }
                }
            }
        }
    }
}

impl Transport for RtpsTransport {
    fn local_id(&self) -> EndpointId {
        self.local
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
}

impl RtpsTransport {
    /// Writes one sample to every matched reader of `channel`, or to `reader` alone (the others are told, by a GAP,
    /// that the sequence number is not for them), with back-pressure and pacing of large samples.
    fn write(&self, channel: Channel, bytes: Bytes, reader: Option<GUID>) -> Result<(), TransportError> {
        let size = bytes.len();
        if size > self.config.max_sample_bytes {
            return Err(TransportError::TooLarge {
                channel: channel.name(),
                size,
                limit: self.config.max_sample_bytes,
            });
        }
        let writer = self.writers[channel.index()].lock().unwrap_or_else(|p| p.into_inner());
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
        self.counters.sent(size, estimated_wire_bytes(size));
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
    fn wire_estimate_grows_with_datagrams() {
        assert_eq!(estimated_wire_bytes(40), 40 + 8 + 36 + 48);
        assert!(estimated_wire_bytes(1 << 20) > (1 << 20) + 16 * 48);
    }
}
