//! The receiving thread of an [`RtpsTransport`](super::RtpsTransport): it takes samples from the current
//! generation's readers and records discovery, and it watches `rustdds`'s own threads of the participants and
//! rebuilds the participants, writers and readers when they have ended (see the parent module's documentation,
//! "Recovery").

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use crossbeam_channel::{SendTimeoutError, Sender};
use rustdds::StatusEvented;

use super::Shared;
use super::discovery::{DiscoveryState, endpoint_of};
use super::generation::{Generation, Participants, Reading};
use super::large::{self, Order};
use super::payload::{Payload, Reader, Writer};
use super::settings::RtpsConfig;
use crate::{Channel, Counters, EndpointId, Sample, Sink};

/// How often the receiving thread checks that `rustdds`'s threads still run (a few small `/proc` reads).
const ENGINE_CHECK_PERIOD: Duration = Duration::from_millis(500);
/// After the receiving thread's own `poll` was interrupted (EINTR: the process was stopped and resumed, or a
/// signal arrived), `rustdds`'s threads were likely interrupted too: check them this soon.
const ENGINE_CHECK_AFTER_EINTR: Duration = Duration::from_millis(50);
/// Shortest time between two rebuilds, so a generation that dies at once is not rebuilt in a tight loop.
const MIN_REBUILD_INTERVAL: Duration = Duration::from_secs(1);
/// Longest wait before another attempt when a rebuild fails.
const MAX_REBUILD_RETRY: Duration = Duration::from_secs(10);

/// Where the receiving thread puts samples: the sink once one is set, else the bounded inbox.
pub(super) struct Outlet {
    pub(super) inbox: Sender<Sample>,
    pub(super) sink: Arc<Mutex<Option<Sink>>>,
    pub(super) counters: Arc<Counters>,
}

impl Outlet {
    /// Hands `sample` on; `false` when the transport is stopping or its inbox is gone.
    fn pass(&self, mut sample: Sample, stop: &AtomicBool) -> bool {
        {
            // Held during the call, so that clearing the sink waits for the call to end.
            let sink = self.sink.lock().unwrap_or_else(|p| p.into_inner());
            if let Some(sink) = sink.as_ref() {
                self.counters.received(sample.bytes.len());
                sink(sample);
                return true;
            }
        }
        // Bounded inbox: wait (back-pressure) but notice a stop request.
        loop {
            match self.inbox.send_timeout(sample, Duration::from_millis(50)) {
                Ok(()) => return true,
                Err(SendTimeoutError::Timeout(back)) => {
                    if stop.load(Ordering::Relaxed) {
                        return false;
                    }
                    sample = back;
                }
                Err(SendTimeoutError::Disconnected(_)) => return false,
            }
        }
    }
}

/// Wakes the receiving thread out of its `poll` when the transport stops, so that the thread can sleep until it
/// has something to do (a sample, a discovery event, the engine check) instead of looking at the stop flag on a
/// short timeout.
#[derive(Default)]
pub(super) struct StopBell(Mutex<Option<rustdds::mio1::Waker>>);

/// The poll token of the [`StopBell`]'s waker.
const STOP_TOKEN: rustdds::mio1::Token = rustdds::mio1::Token(usize::MAX);

impl StopBell {
    /// Wakes the thread's current `poll` (after the stop flag is set); nothing if it has none yet, since it looks
    /// at the flag before its first.
    pub(super) fn ring(&self) {
        if let Some(waker) = self.0.lock().unwrap_or_else(|p| p.into_inner()).as_ref()
            && let Err(error) = waker.wake()
        {
            tracing::warn!("rtps receive: cannot wake the receiving thread to stop: {error}");
        }
    }

    /// Makes `poll` the one [`StopBell::ring`] wakes.
    fn arm(&self, poll: &rustdds::mio1::Poll) -> std::io::Result<()> {
        let waker = rustdds::mio1::Waker::new(poll.registry(), STOP_TOKEN)?;
        *self.0.lock().unwrap_or_else(|p| p.into_inner()) = Some(waker);
        Ok(())
    }
}

/// Why [`serve`] returned.
enum Ended {
    /// The transport is stopping (or its inbox is gone).
    Stopped,
    /// The generation can no longer receive: what happened.
    Broken(String),
}

/// The receiving thread: serves the readers of the current generation and, when `rustdds`'s threads of it have
/// ended, rebuilds the participants, writers and readers and serves the new ones.
pub(super) fn receive_loop(
    mut reading: Reading,
    mut rebuild: Rebuild,
    outlet: Outlet,
    stop: &AtomicBool,
    bell: &StopBell,
) {
    loop {
        let why = match serve(&mut reading, &outlet, stop, bell) {
            Ended::Stopped => return,
            Ended::Broken(why) => why,
        };
        outlet.counters.participant_failed();
        tracing::error!(
            "RTPS participant event loop died ({why}); this transport ({}) neither sends nor receives until it \
             is rebuilt; rebuilding its participants, writers and readers",
            reading.local
        );
        let Some((new, old)) = rebuild.run(stop) else { return };
        // The old generation goes in the order its parts depend on each other: writers, readers, participants.
        let old_reading = std::mem::replace(&mut reading, new);
        drop(old.writers);
        drop(old_reading);
        drop(old.participants);
        tracing::warn!(
            "RTPS transport rebuilt (rebuild {}): it is now {}; peers discover it anew",
            outlet.counters.snapshot().participant_rebuilds,
            reading.local
        );
    }
}

/// Takes samples from `reading`'s readers until the transport stops or `rustdds`'s threads of this generation are
/// found dead (checked every [`ENGINE_CHECK_PERIOD`], and soon after this thread's own `poll` was interrupted).
fn serve(reading: &mut Reading, outlet: &Outlet, stop: &AtomicBool, bell: &StopBell) -> Ended {
    use rustdds::mio1::{Events, Interest, Poll, Token};
    let mut poll = match Poll::new() {
        Ok(poll) => poll,
        Err(error) => return Ended::Broken(format!("cannot create a poller: {error}")),
    };
    if let Err(error) = bell.arm(&poll) {
        return Ended::Broken(format!("cannot create the poller's stop waker: {error}"));
    }
    for (index, (channel, reader)) in reading.readers.iter_mut().enumerate() {
        if let Err(error) = poll.registry().register(reader, Token(index), Interest::READABLE) {
            return Ended::Broken(format!("cannot register the {} reader: {error}", channel.name()));
        }
    }
    if let Err(error) = poll.registry().register(&mut reading.large, LARGE_TOKEN, Interest::READABLE) {
        return Ended::Broken(format!("cannot register the large updates reader: {error}"));
    }
    let first_status = reading.readers.len();
    for (i, status) in reading.watch.statuses.iter_mut().enumerate() {
        if let Err(error) =
            poll.registry().register(status.as_status_source_mio1(), Token(first_status + i), Interest::READABLE)
        {
            // Discovery times stay unknown and joiners fall back to their retry period; data still flows.
            tracing::warn!("rtps receive: cannot watch discovery events: {error}");
        }
    }
    let mut events = Events::with_capacity(16);
    let mut next_check = Instant::now() + ENGINE_CHECK_PERIOD;
    let mut taking = Taking { order: Order::default(), out: Vec::new() };
    while !stop.load(Ordering::Relaxed) {
        // Sleeps until a reader or discovery has something, the transport stops (the bell), the engine check is
        // due or a wait for a large update ends.
        let wake = taking.order.next_deadline().map_or(next_check, |deadline| deadline.min(next_check));
        match poll.poll(&mut events, Some(wake.saturating_duration_since(Instant::now()))) {
            Ok(()) => {}
            Err(error) if error.kind() == std::io::ErrorKind::Interrupted => {
                next_check = next_check.min(Instant::now() + ENGINE_CHECK_AFTER_EINTR);
            }
            Err(error) => {
                tracing::error!("rtps receive: poll failed: {error}");
                std::thread::sleep(Duration::from_millis(5));
            }
        }
        let now = Instant::now();
        if now >= next_check {
            next_check = now + ENGINE_CHECK_PERIOD;
            if let Some(dead) = reading.engine.iter().find(|thread| !thread.alive()) {
                // What waits for a large update goes on: the new generation's writers are new writers.
                taking.order.expire(Instant::now() + large::MAX_WAIT, &mut taking.out);
                if !taking.hand_on(outlet, stop) {
                    return Ended::Stopped;
                }
                return Ended::Broken(format!(
                    "rustdds thread {:?} (tid {}) has ended; rustdds 0.15 ends it on any error of its poll, e.g. \
                     EINTR when the process resumes after SIGSTOP",
                    dead.name, dead.tid
                ));
            }
        }
        reading.watch.drain();
        if !taking.take_all(reading, outlet, stop) {
            return Ended::Stopped;
        }
    }
    Ended::Stopped
}

/// The poll token of the large updates reader.
const LARGE_TOKEN: rustdds::mio1::Token = rustdds::mio1::Token(usize::MAX - 1);

/// The receiving thread's merge of the updates and large updates topics, and what it releases.
struct Taking {
    order: Order,
    out: Vec<Sample>,
}

impl Taking {
    /// Takes what every reader has (a notification may have been drained by an earlier round), the updates
    /// topic's before the large updates' so that a large sample finds its marker waiting, and hands on what is in
    /// order.
    /// `false` when the transport is stopping.
    fn take_all(&mut self, reading: &Reading, outlet: &Outlet, stop: &AtomicBool) -> bool {
        for (channel, reader) in &reading.readers {
            reader.drain_read_notifications();
            while let Some((sample, _)) = take_one(reader, *channel, reading.local, &outlet.counters) {
                if *channel == Channel::Requests
                    && reading.watch.state.learn_reading_prefix(sample.origin, &sample.bytes)
                {
                    continue;
                }
                match (*channel, large::marked(&sample.bytes)) {
                    (Channel::Updates, Some(sequence)) => self.order.marker(sample.origin, sequence, Instant::now()),
                    (Channel::Updates, None) => self.order.update(sample, &mut self.out),
                    _ => self.out.push(sample),
                }
                if !self.hand_on(outlet, stop) {
                    return false;
                }
            }
        }
        reading.large.drain_read_notifications();
        while let Some((sample, sequence)) = take_one(&reading.large, Channel::Updates, reading.local, &outlet.counters)
        {
            self.order.large(sample, sequence, &mut self.out);
            if !self.hand_on(outlet, stop) {
                return false;
            }
        }
        self.order.expire(Instant::now(), &mut self.out);
        self.hand_on(outlet, stop)
    }

    /// Passes on what the merge released, and counts its waits that ended without their sample; `false` when the
    /// transport is stopping.
    fn hand_on(&mut self, outlet: &Outlet, stop: &AtomicBool) -> bool {
        let ended = self.order.take_ended_waits();
        if ended > 0 {
            outlet.counters.large_waits_ended(ended);
        }
        self.out.drain(..).all(|sample| outlet.pass(sample, stop))
    }
}

/// The next sample of `reader` another transport wrote, with its RTPS sequence number. A sample `rustdds` could not
/// decode (a foreign type on our topic) is logged, counted and skipped; `None` when nothing is left.
fn take_one(reader: &Reader, channel: Channel, local: EndpointId, counters: &Counters) -> Option<(Sample, i64)> {
    loop {
        match reader.try_take_one() {
            Ok(Some(change)) => {
                let origin = endpoint_of(change.writer_guid());
                if origin == local {
                    continue;
                }
                let sequence = change.sequence_number.into();
                let Payload(bytes) = change.into_value();
                return Some((Sample { channel, origin, bytes }, sequence));
            }
            Ok(None) => return None,
            Err(error) => {
                tracing::warn!("rtps receive on {}: dropped an undecodable sample: {error:?}", channel.name());
                counters.dropped_full();
                return None;
            }
        }
    }
}

/// What the receiving thread needs to rebuild the transport's DDS entities.
pub(super) struct Rebuild {
    pub(super) config: RtpsConfig,
    pub(super) multicast: bool,
    pub(super) shared: Arc<Shared>,
    pub(super) discovery: Arc<DiscoveryState>,
    pub(super) counters: Arc<Counters>,
    /// When the last rebuild was done.
    pub(super) last: Option<Instant>,
}

/// What a rebuild took out of use, for the receiving thread to drop (with the old [`Reading`]) in order.
struct Replaced {
    writers: Vec<Writer>,
    participants: Participants,
}

impl Rebuild {
    /// Builds a new generation — retrying, with a growing pause, until it succeeds or the transport stops
    /// (`None`) — and puts its writers, identity and participants in use. Returns the new generation's reading
    /// part and what it replaced.
    fn run(&mut self, stop: &AtomicBool) -> Option<(Reading, Replaced)> {
        let mut pause = self.last.map_or(Duration::ZERO, |at| MIN_REBUILD_INTERVAL.saturating_sub(at.elapsed()));
        loop {
            if !sleep_unless_stopped(pause, stop) {
                return None;
            }
            match Generation::build(&self.config, self.multicast, &self.discovery) {
                Ok(generation) => return Some(self.install(generation)),
                Err(error) => {
                    pause = (pause * 2).clamp(MIN_REBUILD_INTERVAL, MAX_REBUILD_RETRY);
                    tracing::error!(
                        "RTPS transport rebuild failed: {error}; still neither sending nor receiving; trying again \
                         in {pause:?}"
                    );
                }
            }
        }
    }

    /// Swaps `generation`'s writers, identity and participants in. Each lock is held only for its swap (a write in
    /// progress on an old writer finishes first; what it wrote is lost with that writer, and agents repair it).
    fn install(&mut self, generation: Generation) -> (Reading, Replaced) {
        let Generation { writers, best_effort, large, local, reading_prefix, participants, reading } = generation;
        let mut old = Vec::new();
        for (slot, writer) in self.shared.writers.iter().zip(writers) {
            old.extend(std::mem::replace(&mut *slot.lock().unwrap_or_else(|p| p.into_inner()), writer));
        }
        if let (Some((slot, _)), Some(writer)) = (&self.shared.best_effort, best_effort) {
            old.push(std::mem::replace(&mut *slot.lock().unwrap_or_else(|p| p.into_inner()), writer));
        }
        old.extend(std::mem::replace(&mut *self.shared.large.lock().unwrap_or_else(|p| p.into_inner()), large));
        *self.shared.identity.lock().unwrap_or_else(|p| p.into_inner()) = (local, reading_prefix);
        // The readers the old writers matched are no address for the new ones; the new matches fill the lists.
        for known in self.discovery.readers.lock().unwrap_or_else(|p| p.into_inner()).iter_mut() {
            known.clear();
        }
        let participants =
            std::mem::replace(&mut *self.shared.participants.lock().unwrap_or_else(|p| p.into_inner()), participants);
        self.counters.participant_rebuilt();
        self.last = Some(Instant::now());
        (reading, Replaced { writers: old, participants })
    }
}

/// Sleeps for `pause` in short steps; `false` as soon as `stop` is set.
fn sleep_unless_stopped(pause: Duration, stop: &AtomicBool) -> bool {
    let until = Instant::now() + pause;
    loop {
        if stop.load(Ordering::Relaxed) {
            return false;
        }
        let left = until.saturating_duration_since(Instant::now());
        if left.is_zero() {
            return true;
        }
        std::thread::sleep(left.min(Duration::from_millis(50)));
    }
}
