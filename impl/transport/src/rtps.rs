//! RTPS through `rustdds`: the transport real agents use.
//!
//! Two DDS domain participants per agent (one for its writers, one for its readers), one non-keyed topic per
//! [`Channel`] named `{prefix}_{channel}` (plus `{prefix}_updates_large` for large updates and `{prefix}_updates_be`
//! with best-effort updates, below), every reader RELIABLE + KEEP_ALL + VOLATILE and every writer RELIABLE +
//! KEEP_LAST + VOLATILE, all with **explicit [`ResourceLimits`] (`rustdds` otherwise keeps only 64 samples per
//! reader)**. A sample travels as a CDR `sequence<octet>` (4-byte length, then the bytes), so any DDS implementation
//! can read it with a one-field IDL type.
//!
//! **Memory.** A keep-all writer of `rustdds` 0.15 keeps every sample it wrote, acknowledged or not, up to
//! [`RtpsConfig::max_samples`]; a keep-last writer still keeps every sample a matched reader has not acknowledged,
//! and its send window still comes from `max_samples`, but drops acknowledged ones beyond its depth every 6 s. So the
//! writers are keep-last (depth 1; 1,024 for the best-effort writer, whose samples are never acknowledged). A reader's
//! topic cache is another matter: `rustdds` 0.15 keeps the last `max_samples` samples a reader received whether or
//! not they were taken, and evicts by count alone, oldest first, taken or not. With the writers' 100,000 (their send
//! window, which must outlast a peer paused for a while) a stream of large samples cost each receiving process up to
//! 100,000 times the sample's size (an agent receiving 360,960-byte frames at 50 Hz grew by 17.5 MB/s, the stream's
//! rate, and so did the sending agent, through its own reader). So readers and their topics have a cache of their
//! own size, [`RtpsConfig::reader_cache_samples`] (1,024). The receiving thread takes samples as they come, so only a
//! burst of more than that many samples before it takes them loses any, the oldest (on the project's 2-core VM,
//! 20,000 small samples written at once: none lost of a 1,024 cache in one run, 31 and 10 of a 256 one in two, 109 of
//! a 64 one in one); agents repair such losses by anti-entropy. A cache of 1,024 samples of any size held 370 MB of
//! 360,960-byte frames and would hold 4 GiB of 4 MiB ones, so **large updates** (on [`Channel::Updates`], of
//! [`RtpsConfig::large_sample_bytes`] or more) travel on a topic of their own whose caches keep
//! [`RtpsConfig::large_cache_samples`] (16), each followed by a marker on the updates topic, behind which the
//! receiving thread holds its writer's later updates until the large sample has come (`large.rs`): an agent asks at
//! once for an operation a gap shows, and a small update that overtook a frame would have the frame sent again.
//! Large samples on the other channels (graph answers, repairs and snapshots on [`Channel::Sync`], which are rarer)
//! stay on their channel's topic, but the sync topic's caches keep [`RtpsConfig::sync_cache_samples`] (32): an
//! answer whose addressee's reader the writing transport does not know yet goes to every reader of the topic, and
//! with the general cache every agent kept the last 1,024 graph answers of its graph's joins, each the whole graph.
//!
//! A receiving thread waits on the readers with `mio` and moves samples into a **bounded inbox**; when the inbox is
//! full it stops taking, and the readers' caches fill. They do not push back on the writers: a `rustdds` reader
//! acknowledges a sample when it is in its cache, and past [`RtpsConfig::reader_cache_samples`] the cache evicts
//! its oldest, taken or not ("Memory", below), which agents repair by anti-entropy. Samples this transport wrote
//! itself are skipped.
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
//! writer sends one loopback copy per reader, and fragmented samples reassemble once (`examples/rtps_burst.rs` shows
//! both set-ups side by side).
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
//! **Read-only** ([`RtpsConfig::read_only`]). A transport may start with one writer, for [`Channel::Requests`],
//! and readers for every channel: what a participant whose DDS Security permissions grant publishing on the
//! requests topic alone can create (`rustdds` refuses a writer the permissions do not grant: "Not allowed to create
//! a DataWriter"). Publishing on another channel is then refused ([`TransportError::ReadOnly`]).
//!
//! A sample meant for one peer ([`Transport::publish_to`], e.g. a graph answer) is written to that participant's
//! reader alone (a directed write; the other readers get a GAP for its sequence number), so a multi-megabyte answer
//! is not copied to every reader — including this participant's own reader, which rustdds matches too.
//!
//! Discovery is observed through the participant's status events: [`RtpsTransport::discovery`] tells when the
//! first remote participant was discovered and when each channel's writer and reader matched their first remote
//! endpoint, and [`Transport::sync_matches`] counts the matches on [`Channel::Requests`] and [`Channel::Sync`] so a
//! joining agent can ask for the graph as soon as a peer can hear it. (rustdds sends a new participant's first discovery announcement 100 ms
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
//! by the agents' anti-entropy. [`TransportStats`] counts failures and rebuilds. A stop and resume *during* a build
//! (at start, or a rebuild) ends the new participants' threads before their writers and readers are handed to them,
//! and `rustdds` then deadlocks in `create_datawriter` (the hand-over fails and the new writer is dropped while its
//! publisher's lock is held): a process stopped in its first 100 ms hung for good. A build now looks at its threads
//! before each writer and reader and gives up on the first ended one ([`TransportError::EngineEnded`]). A stop that
//! lands inside a creation still deadlocks it (in `rustdds`'s own participant creation too), so a build runs on a
//! thread of its own and is given up 2 s after one of its threads ended, or after 30 s in any case (its thread and
//! participants are left behind, silent); the start builds again at once, up to five times in all, and a rebuild is
//! retried as any failed rebuild is. Peers keep the dead participant's
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

mod discovery;
mod engine;
mod generation;
mod large;
mod payload;
mod receive;
mod settings;

use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use bytes::Bytes;
use crossbeam_channel::{Receiver, bounded};
#[cfg(doc)]
use rustdds::policy::ResourceLimits;
use rustdds::{GUID, SampleIdentity, WriteOptionsBuilder};

use crate::{
    Channel, Clock, Counters, EndpointId, Sample, Sink, SystemClock, Transport, TransportError, TransportStats,
};
use discovery::{DiscoveryState, Prefix, READERS_AT};
use generation::{Generation, Participants};
use payload::Writer;
use receive::{Outlet, Rebuild, receive_loop};
use settings::best_effort_max_bytes;

pub use discovery::DiscoveryTimes;
pub use engine::EngineWatch;
pub use payload::{OctetsAdapter, OctetsDecoder, Payload, PayloadError, estimated_wire_bytes};
pub use settings::{
    Multicast, RtpsConfig, SecurityFiles, UpdateDelivery, loopback_multicast_capable, qos, routable_ipv4_addresses,
};

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
    /// Wakes the receiving thread when `stop` is set.
    bell: Arc<receive::StopBell>,
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
    /// One writer per channel (by [`Channel::index`]); `None` for a channel a read-only transport does not write
    /// ([`RtpsConfig::read_only`]).
    writers: Vec<Mutex<Option<Writer>>>,
    /// The best-effort updates writer and the largest sample it takes ([`UpdateDelivery::BestEffort`]).
    best_effort: Option<(Mutex<Writer>, usize)>,
    /// The writer of large updates (see [`large`]); `None` for a read-only transport.
    large: Mutex<Option<Writer>>,
    /// This transport's endpoint id (its publishing participant's GUID prefix, which tags its samples) and the GUID
    /// prefix of the participant holding its readers (told to peers, see [`READERS_AT`]).
    identity: Mutex<(EndpointId, Prefix)>,
    participants: Mutex<Participants>,
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
        let generation = Generation::first(&config, multicast, &discovery)?;
        discovery.times.lock().unwrap_or_else(|p| p.into_inner()).created_ns = SystemClock.now_ns();
        let Generation { writers, best_effort, large, local, reading_prefix, participants, reading } = generation;
        let shared = Arc::new(Shared {
            writers: writers.into_iter().map(Mutex::new).collect(),
            best_effort: best_effort.zip(best_effort_max_bytes(&config)).map(|(w, max)| (Mutex::new(w), max)),
            large: Mutex::new(large),
            identity: Mutex::new((local, reading_prefix)),
            participants: Mutex::new(participants),
        });
        let (sender, inbox) = bounded(config.inbox_capacity.max(1));
        let sink = Arc::new(Mutex::new(None));
        let stop = Arc::new(AtomicBool::new(false));
        let bell = Arc::new(receive::StopBell::default());
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
            let (stop, bell) = (Arc::clone(&stop), Arc::clone(&bell));
            std::thread::Builder::new()
                .name("rtps-receive".into())
                .spawn(move || receive_loop(reading, rebuild, outlet, &stop, &bell))
                .map_err(|e| TransportError::Setup { what: "receiving thread".into(), detail: e.to_string() })?
        };
        Ok(RtpsTransport {
            shared,
            inbox,
            sink,
            stop,
            bell,
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

    /// The GUID prefix of the participant holding this transport's readers (its publishing participant's, when the
    /// readers share it). Changes with a rebuild of the participants, as [`Transport::local_id`] does.
    pub fn reading_prefix(&self) -> [u8; 12] {
        self.shared.identity.lock().unwrap_or_else(|p| p.into_inner()).1
    }

    /// How many of the remote readers `channel`'s writers have matched now (the best-effort updates writer's among
    /// [`Channel::Updates`]'), as discovery reported them, have a GUID prefix that `which` accepts; at most a few
    /// thousand are remembered. Nothing is allocated: a hybrid transport asks on every publish.
    pub fn matched_readers(&self, channel: Channel, which: impl Fn(&[u8; 12]) -> bool) -> usize {
        let readers = self.discovery.readers.lock().unwrap_or_else(|p| p.into_inner());
        readers[channel.index()].iter().filter(|guid| which(&discovery::prefix_of(**guid))).count()
    }
}

impl Drop for RtpsTransport {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::SeqCst);
        self.bell.ring();
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
        if reader.is_none() {
            self.counters.unaddressed_write();
        }
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
            self.write_sample(Channel::Requests, Bytes::from(announce), None)?;
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
        if channel == Channel::Updates && reader.is_none() && size >= self.config.large_sample_bytes {
            return self.write_large(bytes);
        }
        with_writer(&self.shared.writers[channel.index()], channel, |writer| {
            self.write_reliable(writer, channel, Payload(bytes), reader)?;
            self.pace(writer, size);
            Ok(())
        })?;
        self.counters.sent(size, estimated_wire_bytes(size, true));
        Ok(())
    }

    /// A large update: on the topic of large updates, then its marker on the updates topic (see [`large`]).
    fn write_large(&self, bytes: Bytes) -> Result<(), TransportError> {
        let size = bytes.len();
        let updates = Channel::Updates;
        let written = with_writer(&self.shared.large, updates, |writer| {
            let written = self.write_reliable(writer, updates, Payload(bytes), None)?;
            self.pace(writer, size);
            Ok(written)
        })?;
        let marker = large::marker(written.sequence_number.into());
        let marker_bytes = marker.len();
        with_writer(&self.shared.writers[updates.index()], updates, |writer| {
            self.write_reliable(writer, updates, Payload(marker), None)
        })?;
        self.counters.sent(size, estimated_wire_bytes(size, true) + estimated_wire_bytes(marker_bytes, true));
        Ok(())
    }

    /// Writes `payload` reliably to every matched reader, or to `reader` alone (the others are told, by a GAP, that
    /// the sequence number is not for them). A full send window is back-pressure: the write waits for
    /// acknowledgements and tries again, for up to four times [`RtpsConfig::max_blocking`].
    fn write_reliable(
        &self,
        writer: &Writer,
        channel: Channel,
        payload: Payload,
        reader: Option<GUID>,
    ) -> Result<SampleIdentity, TransportError> {
        let deadline = Instant::now() + self.config.max_blocking * 4;
        let options = match reader {
            Some(reader) => WriteOptionsBuilder::new().to_single_reader(reader).build(),
            None => WriteOptionsBuilder::new().build(),
        };
        loop {
            match writer.write_with_options(payload.clone(), options.clone()) {
                Ok(written) => return Ok(written),
                Err(rustdds::dds::result::WriteError::WouldBlock { .. }) if Instant::now() < deadline => {
                    // The send window is full: give acknowledgements a chance, then retry.
                    let _ = writer.wait_for_acknowledgments(Duration::from_millis(100));
                }
                Err(error) => {
                    return Err(TransportError::Write { channel: channel.name(), detail: format!("{error:?}") });
                }
            }
        }
    }

    /// Pacing of large samples: after every [`RtpsConfig::pace_bytes`] of them, waits (bounded) for `writer`'s
    /// acknowledgements.
    fn pace(&self, writer: &Writer, size: usize) {
        if size >= self.config.large_sample_bytes {
            let pending = self.unpaced_large_bytes.fetch_add(size, Ordering::Relaxed) + size;
            if pending >= self.config.pace_bytes {
                self.unpaced_large_bytes.store(0, Ordering::Relaxed);
                let _ = writer.wait_for_acknowledgments(self.config.max_blocking);
            }
        }
    }
}

/// Runs `write` with the writer in `slot` (locked meanwhile), or refuses: a read-only transport has none for
/// `channel`.
fn with_writer<T>(
    slot: &Mutex<Option<Writer>>,
    channel: Channel,
    write: impl FnOnce(&Writer) -> Result<T, TransportError>,
) -> Result<T, TransportError> {
    let writer = slot.lock().unwrap_or_else(|p| p.into_inner());
    write(writer.as_ref().ok_or(TransportError::ReadOnly { channel: channel.name() })?)
}
