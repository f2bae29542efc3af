//! [`ShmTransport`]: a [`Transport`] whose endpoints are all on one host, every channel an [`ShmLane`], and
//! receivers woken by an iceoryx2 event service rather than polling (the spike showed polling costs milliseconds
//! with 8 receivers on 2 cores). A publish's wake-up names its lane (event id [`lane_event`]), and a woken receiver
//! looks at the lanes it was told of before the others; before it waits it looks at every lane, so a wake-up that
//! was lost or merged delays nothing beyond the next look. It has no discovery and no other-host path: it is the
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
    /// The lane `try_recv` looks at first, so no channel starves the others.
    next_lane: AtomicUsize,
    /// Lanes a wake-up named that have not been found empty since (bit [`Channel::index`]): where a woken
    /// receiver looks first. A hint only: every look that finds nothing there looks at every lane.
    notified: AtomicU8,
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
            notified: AtomicU8::new(0),
            counters: Counters::default(),
            max_sample_bytes: settings.max_sample_bytes,
            _node: node,
        })
    }
}

/// The event id of [`Transport::interrupt`]'s notification.
const INTERRUPT: EventId = EventId::new(1);

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

    fn try_recv(&self) -> Option<Sample> {
        let first = self.next_lane.fetch_add(1, Ordering::Relaxed);
        let notified = self.notified.load(Ordering::Relaxed);
        let order = (0..Channel::COUNT).map(|k| Channel::ALL[(first + k) % Channel::COUNT]);
        let named = |channel: &Channel| notified & 1 << channel.index() != 0;
        // The lanes a wake-up named, then the others. (A sample that comes to a named lane after its look here has
        // a wake-up of its own, which the listener keeps: the next wait returns at once.)
        let (first_looks, then) = (order.clone().filter(named), order.filter(|channel| !named(channel)));
        for channel in first_looks.chain(then) {
            if let Some(sample) = self.take(channel) {
                return Some(sample);
            }
            if named(&channel) {
                self.notified.fetch_and(!(1 << channel.index()), Ordering::Relaxed);
            }
        }
        None
    }

    fn recv_timeout(&self, timeout: Duration) -> Option<Sample> {
        let deadline = Instant::now() + timeout;
        loop {
            if let Some(sample) = self.try_recv() {
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
            self.notified.fetch_or(lanes, Ordering::Relaxed);
            match wait {
                // A signal ended the wait (SIGCONT after a pause, every time): look again.
                Ok(_) | Err(ListenerWaitError::InterruptSignal) => {}
                Err(error) => {
                    tracing::warn!(?error, "shared-memory wake-up wait failed");
                    drop(listener);
                    std::thread::sleep(left.min(Duration::from_millis(1)));
                }
            }
            if interrupted {
                return self.try_recv();
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
        b.notified.store(lane_bit(lane_event(Channel::Requests)), Ordering::Relaxed);
        assert_eq!(b.try_recv().expect("a sample").channel, Channel::Requests);
        // A lane named but found empty is no longer named, and the look goes on to every lane.
        assert_eq!(b.try_recv().expect("a sample").channel, Channel::Updates);
        assert_eq!(b.notified.load(Ordering::Relaxed), 0);
        assert_eq!(b.try_recv(), None);
        assert_eq!((lane_bit(INTERRUPT), lane_bit(EventId::new(2 + Channel::COUNT))), (0, 0), "names no lane");
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
