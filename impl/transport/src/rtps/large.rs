//! Large updates on a topic of their own, and the order of each writer's updates on receipt.
//!
//! `rustdds` 0.15 keeps a reader's last [`RtpsConfig::reader_cache_samples`] samples whatever their size (see the
//! parent module's documentation, "Memory"), so one topic for every update made a receiver of 4 MiB frames hold
//! 4 GiB. Samples on [`Channel::Updates`] of [`RtpsConfig::large_sample_bytes`] or more therefore go on a topic of
//! large updates (`{prefix}_updates_large`), whose readers keep [`RtpsConfig::large_cache_samples`]; the others stay
//! on the updates topic with its larger cache, for bursts of small samples.
//!
//! Two topics do not keep one writer's order, and an agent asks at once for the operations a gap shows. A small
//! update that overtakes the large one written before it would have the large one sent again, so after each large
//! sample the writer puts a **marker** on the updates topic ([`MARKER`] and the large sample's RTPS sequence
//! number), and the receiving thread ([`Order`]) holds a writer's updates behind a marker whose large sample has not
//! come; the large sample, when it comes, goes first and releases them. A large sample is never held: one that comes
//! before its marker is handed on at once (it may overtake small updates written before it, which an agent then asks
//! for again: small), since on loopback a run of large samples arrived well before the small updates written
//! between them, and holding the large ones for their markers made them as late as the updates topic (the report's
//! point clouds to 16 receiver processes: p50 39 ms became 188 ms). A wait ends after [`MAX_WAIT`] (a large sample
//! evicted from a cache, a writer gone), or when a later large sample of the writer comes (the earlier one is lost,
//! since one writer's samples on a topic come in order); what waited is then handed on, and agents repair a loss as
//! any other. At most [`MAX_HELD`] updates wait in all; past that the oldest wait ends early.

use std::collections::{HashMap, VecDeque};
use std::time::{Duration, Instant};

use bytes::Bytes;

#[cfg(doc)]
use crate::{Channel, rtps::RtpsConfig};
use crate::{EndpointId, Sample};

/// The first bytes of a marker on the updates topic; its writer's large sample's RTPS sequence number follows (8
/// bytes, little-endian). Agents' samples start with another byte (`0xd5`); the receiving thread consumes markers.
pub(super) const MARKER: [u8; 8] = *b"\xffRTPSlg1";

/// How long updates wait behind a marker for its large sample.
pub(super) const MAX_WAIT: Duration = Duration::from_secs(1);

/// Updates that may wait, all writers together.
pub(super) const MAX_HELD: usize = 4096;

/// Writers whose last large sample's sequence number is remembered (to know a marker that comes after its sample),
/// before those with nothing waiting are forgotten.
const MAX_WRITERS_SEEN: usize = 256;

/// The marker of the large sample with RTPS sequence number `sequence`.
pub(super) fn marker(sequence: i64) -> Bytes {
    let mut bytes = MARKER.to_vec();
    bytes.extend_from_slice(&sequence.to_le_bytes());
    Bytes::from(bytes)
}

/// The sequence number a marker names; `None` if `bytes` is not a marker.
pub(super) fn marked(bytes: &[u8]) -> Option<i64> {
    let rest = bytes.strip_prefix(&MARKER)?;
    Some(i64::from_le_bytes(rest.try_into().ok()?))
}

/// What waits for one writer, in the updates topic's order, from its first marker whose large sample has not come:
/// the front is always such a marker.
type Queue = VecDeque<Entry>;

#[derive(Debug)]
enum Entry {
    /// A marker whose large sample has not come, and the end of its wait.
    Awaited { sequence: i64, until: Instant },
    /// A marker's large sample, come after it.
    Large(Sample),
    /// A marker whose large sample is lost: a later one of its writer came first.
    Lost,
    /// An update behind a marker.
    Update(Sample),
}

/// When `queue`'s wait ends.
fn deadline(queue: &Queue) -> Option<Instant> {
    match queue.front() {
        Some(Entry::Awaited { until, .. }) => Some(*until),
        _ => None,
    }
}

/// What [`release`] handed on of a queue: updates, and waits that ended without their large sample.
#[derive(Default)]
struct Released {
    updates: usize,
    ended_waits: u64,
}

/// Hands on `queue`'s entries from the front while they are ready: an update, a large sample, or (with
/// `expired_by`) a marker whose wait ended by then.
fn release(queue: &mut Queue, expired_by: Option<Instant>, out: &mut Vec<Sample>) -> Released {
    let mut released = Released::default();
    while let Some(front) = queue.front() {
        if let Entry::Awaited { until, .. } = front
            && expired_by.is_none_or(|now| *until > now)
        {
            break;
        }
        match queue.pop_front() {
            Some(Entry::Update(sample)) => {
                released.updates += 1;
                out.push(sample);
            }
            Some(Entry::Large(sample)) => out.push(sample),
            Some(Entry::Awaited { .. } | Entry::Lost) => released.ended_waits += 1,
            None => {}
        }
    }
    released
}

/// The receiving thread's order of each writer's updates (see the module documentation). Samples come in through
/// [`Order::update`], [`Order::marker`] and [`Order::large`], and leave, in order, into the vector each call is
/// given. Only writers with something waiting are in `waiting`, so the receiving thread's look at the deadlines on
/// every round costs nothing while nothing waits.
#[derive(Debug, Default)]
pub(super) struct Order {
    waiting: HashMap<EndpointId, Queue>,
    /// The sequence number of each writer's last large sample (at most [`MAX_WRITERS_SEEN`] writers).
    large_seen: HashMap<EndpointId, i64>,
    /// Updates waiting, all writers together.
    held: usize,
    /// Waits that ended without their large sample since [`Order::take_ended_waits`] last took them.
    ended_waits: u64,
}

impl Order {
    /// A sample of the updates topic (or of the best-effort one): handed on, or kept behind its writer's marker.
    pub(super) fn update(&mut self, sample: Sample, out: &mut Vec<Sample>) {
        let Some(queue) = self.waiting.get_mut(&sample.origin) else {
            return out.push(sample);
        };
        queue.push_back(Entry::Update(sample));
        self.held += 1;
        if self.held > MAX_HELD {
            self.end_oldest_wait(out);
        }
    }

    /// A marker from `origin` for its large sample `sequence`, received at `now`: unless that sample came first,
    /// `origin`'s updates wait behind it.
    pub(super) fn marker(&mut self, origin: EndpointId, sequence: i64, now: Instant) {
        if self.large_seen.get(&origin).is_none_or(|seen| *seen < sequence) {
            self.waiting.entry(origin).or_default().push_back(Entry::Awaited { sequence, until: now + MAX_WAIT });
        }
    }

    /// A sample of the topic of large updates, with its RTPS sequence number: handed on at its marker's place if
    /// the marker waits, else at once.
    pub(super) fn large(&mut self, sample: Sample, sequence: i64, out: &mut Vec<Sample>) {
        let origin = sample.origin;
        self.remember_large(origin, sequence);
        let mut sample = Some(sample);
        if let Some(queue) = self.waiting.get_mut(&origin) {
            for entry in queue.iter_mut() {
                match entry {
                    Entry::Awaited { sequence: marked, .. } if *marked == sequence => {
                        if let Some(sample) = sample.take() {
                            *entry = Entry::Large(sample);
                        }
                        break;
                    }
                    // One writer's samples come in order: an earlier one that has not come is lost.
                    Entry::Awaited { sequence: marked, .. } if *marked < sequence => *entry = Entry::Lost,
                    _ => {}
                }
            }
            let released = release(queue, None, out);
            self.settle(origin, released);
        }
        // No marker waits for it (it came first, or its marker's wait ended): at once.
        out.extend(sample);
    }

    /// Ends the waits due by `now`, handing on what waited behind them.
    pub(super) fn expire(&mut self, now: Instant, out: &mut Vec<Sample>) {
        let due: Vec<EndpointId> = (self.waiting.iter())
            .filter(|(_, queue)| deadline(queue).is_some_and(|at| at <= now))
            .map(|(origin, _)| *origin)
            .collect();
        for origin in due {
            self.end_wait(origin, now, out);
        }
    }

    /// When the earliest wait ends, if any update waits.
    pub(super) fn next_deadline(&self) -> Option<Instant> {
        self.waiting.values().filter_map(deadline).min()
    }

    /// How many waits ended without their large sample since the last call.
    pub(super) fn take_ended_waits(&mut self) -> u64 {
        std::mem::take(&mut self.ended_waits)
    }

    /// Updates waiting now, all writers together.
    #[cfg(test)]
    fn held(&self) -> usize {
        self.held
    }

    /// Ends `origin`'s waits due by `now`.
    fn end_wait(&mut self, origin: EndpointId, now: Instant, out: &mut Vec<Sample>) {
        if let Some(queue) = self.waiting.get_mut(&origin) {
            let released = release(queue, Some(now), out);
            self.settle(origin, released);
        }
    }

    /// Counts what a release of `origin`'s queue handed on, and forgets the queue once empty.
    fn settle(&mut self, origin: EndpointId, released: Released) {
        self.held -= released.updates;
        self.ended_waits += released.ended_waits;
        if self.waiting.get(&origin).is_some_and(VecDeque::is_empty) {
            self.waiting.remove(&origin);
        }
    }

    /// Past [`MAX_HELD`]: the writer whose wait is oldest stops waiting.
    fn end_oldest_wait(&mut self, out: &mut Vec<Sample>) {
        let oldest = self.waiting.iter().filter_map(|(origin, queue)| Some((deadline(queue)?, *origin))).min();
        if let Some((deadline, origin)) = oldest {
            tracing::warn!("rtps: {MAX_HELD} updates wait for large samples; the oldest wait ends");
            self.end_wait(origin, deadline, out);
        }
    }

    /// Remembers `origin`'s last large sample; past [`MAX_WRITERS_SEEN`] writers, forgets those with nothing
    /// waiting (a marker of theirs that comes after its sample then waits, at most [`MAX_WAIT`]).
    fn remember_large(&mut self, origin: EndpointId, sequence: i64) {
        if self.large_seen.len() >= MAX_WRITERS_SEEN && !self.large_seen.contains_key(&origin) {
            let waiting = &self.waiting;
            self.large_seen.retain(|writer, _| waiting.contains_key(writer));
        }
        let seen = self.large_seen.entry(origin).or_insert(sequence);
        *seen = (*seen).max(sequence);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Channel;

    const A: EndpointId = EndpointId(1 << 100);
    const B: EndpointId = EndpointId(2 << 100);

    fn sample(origin: EndpointId, tag: u8) -> Sample {
        Sample { channel: Channel::Updates, origin, bytes: Bytes::from(vec![0xd5, tag]) }
    }

    fn tags(out: &[Sample]) -> Vec<u8> {
        out.iter().map(|sample| sample.bytes[1]).collect()
    }

    #[test]
    fn markers_round_trip_and_nothing_else_is_one() {
        assert_eq!(marked(&marker(7)), Some(7));
        assert_eq!(marked(&marker(-1)), Some(-1));
        assert_eq!(marked(&[0xd5, 3, 1, 0]), None);
        let full = marker(7);
        assert_eq!(marked(&full[..full.len() - 1]), None);
        assert_eq!(marked(&[&full[..], &[0]].concat()), None);
    }

    #[test]
    fn updates_without_a_marker_pass_at_once() {
        let mut order = Order::default();
        let mut out = Vec::new();
        order.update(sample(A, 1), &mut out);
        order.update(sample(A, 2), &mut out);
        assert_eq!(tags(&out), [1, 2]);
        assert_eq!(order.next_deadline(), None);
    }

    #[test]
    fn updates_behind_a_marker_wait_for_its_large_sample_which_goes_first() {
        let (mut order, now) = (Order::default(), Instant::now());
        let mut out = Vec::new();
        order.update(sample(A, 1), &mut out);
        order.marker(A, 5, now);
        order.update(sample(A, 2), &mut out);
        order.update(sample(B, 9), &mut out);
        assert_eq!(tags(&out), [1, 9], "A's second update waits, B's does not");
        assert_eq!(order.held(), 1);
        assert_eq!(order.next_deadline(), Some(now + MAX_WAIT));
        order.large(sample(A, 50), 5, &mut out);
        assert_eq!(tags(&out), [1, 9, 50, 2]);
        assert_eq!((order.held(), order.next_deadline(), order.take_ended_waits()), (0, None, 0));
    }

    #[test]
    fn a_large_sample_before_its_marker_is_handed_on_at_once_and_its_marker_holds_nothing() {
        let (mut order, now) = (Order::default(), Instant::now());
        let mut out = Vec::new();
        order.large(sample(A, 50), 5, &mut out);
        order.update(sample(A, 1), &mut out);
        order.marker(A, 5, now);
        order.update(sample(A, 2), &mut out);
        assert_eq!(tags(&out), [50, 1, 2]);
        assert_eq!((order.held(), order.next_deadline()), (0, None));
    }

    #[test]
    fn a_wait_ends_at_its_deadline_and_a_later_large_sample_marks_an_earlier_one_lost() {
        let (mut order, now) = (Order::default(), Instant::now());
        let mut out = Vec::new();
        order.marker(A, 5, now);
        order.update(sample(A, 1), &mut out);
        order.expire(now + MAX_WAIT - Duration::from_millis(1), &mut out);
        assert!(out.is_empty());
        order.expire(now + MAX_WAIT, &mut out);
        assert_eq!(tags(&out), [1]);
        assert_eq!(order.take_ended_waits(), 1);
        out.clear();
        // Sample 6 never comes; 7 does: 6 was lost, and what waited behind both goes, in order.
        order.marker(A, 6, now);
        order.update(sample(A, 2), &mut out);
        order.marker(A, 7, now);
        order.update(sample(A, 3), &mut out);
        order.large(sample(A, 70), 7, &mut out);
        assert_eq!(tags(&out), [2, 70, 3]);
        assert_eq!((order.held(), order.next_deadline(), order.take_ended_waits()), (0, None, 1));
        // Sample 5, whose wait ended, comes after all: handed on at once.
        order.large(sample(A, 50), 5, &mut out);
        assert_eq!(tags(&out), [2, 70, 3, 50]);
    }

    #[test]
    fn a_large_sample_whose_marker_was_overtaken_goes_after_what_waited_before_it() {
        let (mut order, now) = (Order::default(), Instant::now());
        let mut out = Vec::new();
        order.marker(A, 5, now);
        order.update(sample(A, 1), &mut out);
        // 6 comes before its marker, with 5 still awaited: 5 is lost, what waited goes, then 6.
        order.large(sample(A, 60), 6, &mut out);
        assert_eq!(tags(&out), [1, 60]);
        order.marker(A, 6, now);
        order.update(sample(A, 2), &mut out);
        assert_eq!(tags(&out), [1, 60, 2]);
        assert_eq!((order.held(), order.take_ended_waits()), (0, 1));
    }

    #[test]
    fn past_the_bound_the_oldest_wait_ends() {
        let (mut order, now) = (Order::default(), Instant::now());
        let mut out = Vec::new();
        order.marker(A, 5, now);
        order.marker(B, 5, now + Duration::from_millis(1));
        order.update(sample(B, 2), &mut out);
        for _ in 0..MAX_HELD {
            order.update(sample(A, 1), &mut out);
        }
        assert_eq!(out.len(), MAX_HELD, "A's wait, the oldest, ended and released its updates");
        assert_eq!(order.held(), 1, "B's update still waits");
        assert_eq!(order.next_deadline(), Some(now + Duration::from_millis(1) + MAX_WAIT));
    }

    #[test]
    fn a_writer_whose_wait_ended_is_forgotten_and_the_writers_seen_are_bounded() {
        let (mut order, now) = (Order::default(), Instant::now());
        let mut out = Vec::new();
        for writer in 0..=MAX_WRITERS_SEEN as u128 + 1 {
            order.marker(EndpointId(writer), 1, now);
            order.large(sample(EndpointId(writer), 1), 1, &mut out);
        }
        assert_eq!(out.len(), MAX_WRITERS_SEEN + 2);
        assert!(order.waiting.is_empty(), "nothing waits: no writer is looked at on a round");
        assert!(order.large_seen.len() <= MAX_WRITERS_SEEN);
        // A writer that waits is remembered when the others are forgotten.
        order.large(sample(A, 50), 5, &mut out);
        order.marker(A, 9, now);
        for writer in 0..=MAX_WRITERS_SEEN as u128 {
            order.large(sample(EndpointId(writer + 1000), 1), 1, &mut out);
        }
        assert_eq!((order.large_seen.get(&A), order.waiting.contains_key(&A)), (Some(&5), true));
    }
}
