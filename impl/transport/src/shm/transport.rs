//! [`ShmTransport`]: a [`Transport`] whose endpoints are all on one host, every channel an [`ShmLane`], and
//! receivers woken by an iceoryx2 event service rather than polling (the spike showed polling costs milliseconds
//! with 8 receivers on 2 cores). A publish's wake-up names its lane (event id [`lane_event`]), and a waiting
//! receiver looks only at the lanes it was told of, until a look finds one empty: an empty look at a lane costs
//! about as much as taking a sample from it (iceoryx2 goes through every publisher's connection), and looking at
//! all four lanes before and after every sample was a third of a threaded agent's instructions per received update
//! (`scripts/hop-footprint.sh`). Every publish wakes every other endpoint, and a wake-up stays pending until the
//! receiver's next wait takes it, so a sample that comes after a look is found at the next wait, at once. A wait
//! that ends with no wake-up at all (its timeout) is followed by a look at every lane, and so is the first look of
//! an endpoint: a sample whose wake-up never came (sent before this endpoint's listener existed, or a notification
//! that failed) waits at most until then. [`Transport::try_recv`] looks at every lane when none was named. It has
//! no discovery and no other-host path: it is the
//! same-host half of the hybrid transport the design describes (`ARCHITECTURE.md`, "Same-host shared memory"), usable alone by agents
//! that are known to share a host.

use std::sync::Mutex;
use std::sync::atomic::{AtomicU8, AtomicUsize, Ordering};
use std::time::{Duration, Instant};

use bytes::Bytes;
use iceoryx2::port::listener::ListenerWaitError;
use iceoryx2::prelude::*;
use iceoryx2::service::ipc_threadsafe;

use super::{ShmError, ShmLane, ShmPublish, ShmSettings};
use crate::{Channel, Counters, EndpointId, Sample, Transport, TransportError, TransportStats};

/// A transport over shared memory between the endpoints of one host (see the module documentation).
pub struct ShmTransport {
    id: EndpointId,
    lanes: [ShmLane; Channel::COUNT],
    notifier: iceoryx2::port::notifier::Notifier<ipc_threadsafe::Service>,
    listener: Mutex<iceoryx2::port::listener::Listener<ipc_threadsafe::Service>>,
    /// This endpoint's own listener, which its publishes do not wake.
    listener_id: iceoryx2::identifiers::UniqueListenerId,
    /// The lane a look starts at, so no channel starves the others.
    next_lane: AtomicUsize,
    /// Lanes that may hold a sample (bit [`Channel::index`]): named by a wake-up since a look last found them empty,
    /// or all of them, at first and after a wait that no wake-up ended. A wait's receiver looks at these alone.
    pending: AtomicU8,
    counters: Counters,
    max_sample_bytes: usize,
    _node: Node<ipc_threadsafe::Service>,
}

impl std::fmt::Debug for ShmTransport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ShmTransport").field("id", &self.id).field("lanes", &self.lanes).finish()
    }
}

impl ShmTransport {
    /// Opens the lanes `PREFIX/updates`, `PREFIX/sync`, `PREFIX/calls`, `PREFIX/requests` and the wake-up event
    /// `PREFIX/wake` for the endpoint `id`.
    ///
    /// # Errors
    /// As [`ShmLane::open`]: shared memory unusable, a name refused, or a service of another shape.
    pub fn open(prefix: &str, id: EndpointId, settings: &ShmSettings) -> Result<Self, ShmError> {
        // iceoryx2's own log goes to standard error; keep it to errors (its "no config file" warning is expected).
        iceoryx2::prelude::set_log_level(LogLevel::Error);
        let service = format!("{prefix}/wake");
        let open = |what: &'static str, reason: String| ShmError::Open { what, service: service.clone(), reason };
        let name: ServiceName = service
            .as_str()
            .try_into()
            .map_err(|e| ShmError::Name { name: service.clone(), reason: format!("{e:?}") })?;
        let node =
            NodeBuilder::new().create::<ipc_threadsafe::Service>().map_err(|e| open("node", format!("{e:?}")))?;
        // A process killed without closing its ports leaves a dead node holding them (and their shared memory);
        // reclaim those before opening, so restarts do not use up `max_endpoints`.
        let cleaned = node.try_cleanup_dead_nodes();
        if cleaned.cleanups + cleaned.failed_cleanups > 0 {
            tracing::info!(cleaned = cleaned.cleanups, failed = cleaned.failed_cleanups, "dead iceoryx2 nodes");
        }
        let lane = |channel: Channel| {
            // Only updates are leased: what the other channels carry (graph answers, calls) may be kept for long.
            let leases = if channel == Channel::Updates { settings.leases } else { super::LeasePolicy::NEVER };
            let settings = ShmSettings { leases, ..settings.clone() };
            ShmLane::open(&format!("{prefix}/{}", channel.name()), id, &settings)
        };
        let lanes = [lane(Channel::Updates)?, lane(Channel::Sync)?, lane(Channel::Calls)?, lane(Channel::Requests)?];
        let events = node
            .service_builder(&name)
            .event()
            // A wait's drain swaps every id's counter (iceoryx2's default allows 256 ids: 32 cache lines a wake-up).
            .event_id_max_value(MAX_EVENT_ID)
            .max_notifiers(settings.max_endpoints)
            .max_listeners(settings.max_endpoints)
            .max_nodes(settings.max_endpoints)
            .open_or_create()
            .map_err(|e| open("event service", format!("{e:?}")))?;
        let notifier = events.notifier_builder().create().map_err(|e| open("notifier", format!("{e:?}")))?;
        let listener = events.listener_builder().create().map_err(|e| open("listener", format!("{e:?}")))?;
        Ok(Self {
            id,
            lanes,
            notifier,
            listener_id: listener.id(),
            listener: Mutex::new(listener),
            next_lane: AtomicUsize::new(0),
            pending: AtomicU8::new(ALL_LANES),
            counters: Counters::default(),
            max_sample_bytes: settings.max_sample_bytes,
            _node: node,
        })
    }
}

/// Every lane's bit.
const ALL_LANES: u8 = (1 << Channel::COUNT) - 1;

/// The event id of [`Transport::interrupt`]'s notification.
const INTERRUPT: EventId = EventId::new(1);

/// The highest event id the wake-up service carries: [`INTERRUPT`] and one per lane.
const MAX_EVENT_ID: usize = 1 + Channel::COUNT;

/// The event id of a publish's wake-up on `channel`: 2 and up, by [`Channel::index`].
fn lane_event(channel: Channel) -> EventId {
    EventId::new(2 + channel.index())
}

/// The lane bit of a wake-up's event id (0 for an id that names no lane).
fn lane_bit(event: EventId) -> u8 {
    match event.as_value().checked_sub(2) {
        Some(index) if index < Channel::COUNT => 1 << index,
        _ => 0,
    }
}

impl ShmTransport {
    /// Wakes every endpoint's listener but this one's, naming `channel`'s lane: a publish that also woke its own
    /// process's receiving thread cost a thread switch per sample, which on two cores competed with the receivers
    /// (`cortex bench rtt --shm`: about 25 µs of round trip).
    fn wake_others(&self, channel: Channel) -> Result<(), iceoryx2::port::notifier::NotifierNotifyError> {
        let mut failed = Ok(());
        let event = lane_event(channel);
        self.notifier.for_each_listener(|listener, details| {
            if details.listener_id != self.listener_id
                && let Err(error) = listener.notify_with_custom_event_id(event)
            {
                failed = Err(error);
            }
            CallbackProgression::Continue
        });
        failed
    }

    /// The next sample on a lane of `lanes` (bits [`Channel::index`]), looked at in turn from a rotating start; a
    /// pending lane found empty is pending no longer.
    fn take_from(&self, lanes: u8) -> Option<Sample> {
        let first = self.next_lane.fetch_add(1, Ordering::Relaxed);
        for k in 0..Channel::COUNT {
            let channel = Channel::ALL[(first + k) % Channel::COUNT];
            let bit = 1 << channel.index();
            if lanes & bit == 0 {
                continue;
            }
            if let Some(sample) = self.take(channel) {
                return Some(sample);
            }
            // A sample that comes after this look has a wake-up of its own, which the listener keeps.
            self.pending.fetch_and(!bit, Ordering::Relaxed);
        }
        None
    }

    /// The next sample on a pending lane.
    fn take_pending(&self) -> Option<Sample> {
        match self.pending.load(Ordering::Relaxed) {
            0 => None,
            lanes => self.take_from(lanes),
        }
    }

    /// The next sample on `channel`'s lane, counted.
    fn take(&self, channel: Channel) -> Option<Sample> {
        match self.lanes[channel.index()].try_recv() {
            Ok(Some(sample)) => {
                self.counters.received(sample.bytes.len());
                Some(Sample { channel, origin: sample.origin, bytes: sample.bytes })
            }
            Ok(None) => None,
            Err(error) => {
                tracing::warn!(%error, "shared-memory receive failed");
                None
            }
        }
    }
}

impl Transport for ShmTransport {
    fn local_id(&self) -> EndpointId {
        self.id
    }

    fn publish(&self, channel: Channel, bytes: Bytes) -> Result<(), TransportError> {
        self.publish_pieces(channel, &[&bytes])
    }

    fn publish_pieces(&self, channel: Channel, pieces: &[&[u8]]) -> Result<(), TransportError> {
        let lane = &self.lanes[channel.index()];
        let write = |detail: String| TransportError::Write { channel: channel.name(), detail };
        let size = pieces.iter().map(|piece| piece.len()).sum();
        match lane.publish_pieces(pieces).map_err(|e| write(e.to_string()))? {
            ShmPublish::Sent { .. } => {}
            ShmPublish::TooLarge => {
                return Err(TransportError::TooLarge { channel: channel.name(), size, limit: self.max_sample_bytes });
            }
        }
        self.counters.sent(size, size);
        self.wake_others(channel).map_err(|e| write(format!("wake-up notify: {e:?}")))
    }

    /// The pending lanes first, then, if they held nothing, every lane (so a caller that never waits, as a
    /// simulation's pump, still gets every sample).
    fn try_recv(&self) -> Option<Sample> {
        self.take_pending().or_else(|| self.take_from(ALL_LANES))
    }

    /// Looks at the pending lanes, then waits for a wake-up and looks at the lanes it names; after a wait that no
    /// wake-up ended, at every lane. With a zero `timeout` it looks at the pending lanes alone (what came behind
    /// a sample just taken).
    fn recv_timeout(&self, timeout: Duration) -> Option<Sample> {
        let deadline = Instant::now() + timeout;
        loop {
            if let Some(sample) = self.take_pending() {
                return Some(sample);
            }
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return None;
            }
            // A notification sent after the look above is kept by the listener, so the wait returns at once.
            let listener = self.listener.lock().unwrap_or_else(|p| p.into_inner());
            let (mut interrupted, mut lanes) = (false, 0u8);
            let wait = listener.timed_wait(
                |event| {
                    interrupted |= event.id == INTERRUPT;
                    lanes |= lane_bit(event.id);
                },
                left,
            );
            match wait {
                // No wake-up within the wait: look at every lane, in case one was lost.
                Ok(0) => lanes = ALL_LANES,
                Ok(_) => {}
                // A signal ended the wait (SIGCONT after a pause, every time): look everywhere again.
                Err(ListenerWaitError::InterruptSignal) => lanes = ALL_LANES,
                Err(error) => {
                    tracing::warn!(?error, "shared-memory wake-up wait failed");
                    drop(listener);
                    std::thread::sleep(left.min(Duration::from_millis(1)));
                    lanes = ALL_LANES;
                }
            }
            self.pending.fetch_or(lanes, Ordering::Relaxed);
            if interrupted {
                return self.take_pending();
            }
        }
    }

    /// Notifies this endpoint's own listener (which its publishes never do) with `INTERRUPT`.
    fn interrupt(&self) -> bool {
        self.notifier.for_each_listener(|listener, details| {
            if details.listener_id == self.listener_id
                && let Err(error) = listener.notify_with_custom_event_id(INTERRUPT)
            {
                tracing::warn!(?error, "shared-memory: cannot interrupt this endpoint's own wait");
            }
            CallbackProgression::Continue
        });
        true
    }

    fn stats(&self) -> TransportStats {
        let stats = self.counters.snapshot();
        TransportStats {
            shm_samples_sent: stats.samples_sent,
            shm_samples_received: stats.samples_received,
            shm_samples_leased: self.lanes.iter().map(ShmLane::samples_leased).sum(),
            ..stats
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Endpoints `ids` on services named after `test`, with samples of at most `max_sample_bytes`.
    fn endpoints<const N: usize>(test: &str, max_sample_bytes: usize, ids: [u128; N]) -> [ShmTransport; N] {
        let prefix = format!("cortex/test/{}/{test}", std::process::id());
        let settings = ShmSettings { max_sample_bytes, ..ShmSettings::default() };
        ids.map(|id| ShmTransport::open(&prefix, EndpointId(id), &settings).expect("an endpoint"))
    }

    #[test]
    fn samples_on_every_channel_reach_the_other_endpoint_with_their_channel_and_origin() {
        let [a, b] = endpoints("transport", 1 << 16, [10, 11]);
        for channel in Channel::ALL {
            a.publish(channel, Bytes::from(vec![channel.index() as u8; 100])).expect("publish");
        }
        let mut got: Vec<Sample> = (0..Channel::COUNT).filter_map(|_| b.recv_timeout(Duration::from_secs(5))).collect();
        got.sort_by_key(|s| s.channel.index());
        assert_eq!(got.len(), Channel::COUNT);
        for (sample, channel) in got.iter().zip(Channel::ALL) {
            assert_eq!(sample.channel, channel);
            assert_eq!(sample.origin, EndpointId(10));
            assert_eq!(sample.bytes.as_ref(), &[channel.index() as u8; 100][..]);
        }
        assert_eq!(a.try_recv(), None, "an endpoint never receives its own samples");
        assert_eq!(b.stats().samples_received, Channel::COUNT as u64);
        assert_eq!(a.stats().samples_sent, Channel::COUNT as u64);
    }

    #[test]
    fn a_publish_wakes_the_other_endpoints_and_not_its_own() {
        let [a, b, c] = endpoints("wake-others", 1 << 10, [20, 21, 22]);
        a.publish(Channel::Updates, Bytes::from_static(b"wake")).expect("publish");
        let woken = |t: &ShmTransport| {
            let mut events = 0;
            t.listener.lock().unwrap().try_wait(|_| events += 1).expect("wait");
            events > 0
        };
        assert!(woken(&b) && woken(&c), "every other endpoint is woken");
        assert!(!woken(&a), "the publisher's own listener is not");
    }

    #[test]
    fn a_wake_up_names_its_lane_and_a_woken_endpoint_looks_there_first() {
        let [a, b] = endpoints("lane-events", 1 << 10, [40, 41]);
        a.publish(Channel::Updates, Bytes::from_static(b"update")).expect("publish");
        a.publish(Channel::Requests, Bytes::from_static(b"request")).expect("publish");
        let mut events = Vec::new();
        b.listener.lock().unwrap().try_wait(|event| events.push(event.id)).expect("wait");
        events.sort_by_key(|id| id.as_value());
        assert_eq!(events, [lane_event(Channel::Updates), lane_event(Channel::Requests)]);
        // Told of the requests lane alone, b takes from it first, whichever lane its turn would start at.
        b.next_lane.store(Channel::Updates.index(), Ordering::Relaxed);
        b.pending.store(lane_bit(lane_event(Channel::Requests)), Ordering::Relaxed);
        assert_eq!(b.try_recv().expect("a sample").channel, Channel::Requests);
        // A lane named but found empty is no longer pending, and `try_recv` goes on to every lane.
        assert_eq!(b.try_recv().expect("a sample").channel, Channel::Updates);
        assert_eq!(b.pending.load(Ordering::Relaxed), 0);
        assert_eq!(b.try_recv(), None);
        assert_eq!((lane_bit(INTERRUPT), lane_bit(EventId::new(2 + Channel::COUNT))), (0, 0), "names no lane");
    }

    #[test]
    fn a_receiver_looks_at_the_lanes_its_wake_ups_named_and_a_zero_wait_at_those_alone() {
        let [a, b] = endpoints("pending-lanes", 1 << 10, [50, 51]);
        // An endpoint's first look is at every lane; finding them empty, it has nothing pending.
        assert_eq!(b.recv_timeout(Duration::ZERO), None);
        assert_eq!(b.pending.load(Ordering::Relaxed), 0);
        a.publish(Channel::Calls, Bytes::from_static(b"call")).expect("publish");
        // Its wake-up is not taken yet: a zero wait does not look for it ...
        assert_eq!(b.recv_timeout(Duration::ZERO), None);
        // ... and a wait takes the wake-up at once and looks where it says.
        let started = Instant::now();
        assert_eq!(b.recv_timeout(Duration::from_secs(20)).expect("the sample").channel, Channel::Calls);
        assert!(started.elapsed() < Duration::from_secs(20), "the pending wake-up did not end the wait");
        assert_eq!(b.pending.load(Ordering::Relaxed), 1 << Channel::Calls.index(), "pending until found empty");
        assert_eq!(b.recv_timeout(Duration::ZERO), None);
        assert_eq!(b.pending.load(Ordering::Relaxed), 0);
    }

    #[test]
    fn a_sample_whose_wake_up_was_lost_is_found_when_a_wait_ends_without_one() {
        let [a, b] = endpoints("lost-wake-up", 1 << 10, [60, 61]);
        assert_eq!(b.recv_timeout(Duration::ZERO), None);
        a.publish(Channel::Sync, Bytes::from_static(b"answer")).expect("publish");
        // Someone else takes b's wake-up: b is never told of the sample.
        b.listener.lock().unwrap().try_wait(|_| {}).expect("wait");
        assert_eq!(b.recv_timeout(Duration::ZERO), None);
        // A wait that no wake-up ends looks at every lane before it returns.
        let sample = b.recv_timeout(Duration::from_millis(50)).expect("found after the wait's timeout");
        assert_eq!((sample.channel, sample.bytes.as_ref()), (Channel::Sync, &b"answer"[..]));
    }

    #[test]
    fn an_interrupt_ends_a_wait_at_once_and_only_its_own_endpoints() {
        let [a, b] = endpoints("interrupt", 1 << 10, [30, 31]);
        assert!(a.interrupt(), "shared memory can be interrupted");
        // Kept until a waits: this returns empty-handed well before its timeout (without the interrupt it would
        // return only at the timeout, and fail here rather than hang).
        let started = Instant::now();
        assert!(a.recv_timeout(Duration::from_secs(20)).is_none());
        assert!(started.elapsed() < Duration::from_secs(20), "the interrupt did not end the wait");
        // b was not interrupted: its wait runs its course.
        let started = Instant::now();
        assert!(b.recv_timeout(Duration::from_millis(50)).is_none());
        assert!(started.elapsed() >= Duration::from_millis(50), "b's wait ended early");
        // A sample that came before the interrupt is still handed out first.
        b.publish(Channel::Sync, Bytes::from_static(b"first")).expect("publish");
        a.interrupt();
        assert_eq!(a.recv_timeout(Duration::from_secs(3600)).expect("the sample").bytes.as_ref(), b"first");
    }

    #[test]
    fn a_sample_above_the_lane_size_is_a_too_large_error() {
        let [a] = endpoints("too-large-transport", 64, [1]);
        match a.publish(Channel::Updates, Bytes::from(vec![0u8; 65])) {
            Err(TransportError::TooLarge { size: 65, limit: 64, .. }) => {}
            other => panic!("expected TooLarge, got {other:?}"),
        }
    }
}
