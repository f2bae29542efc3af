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

/// Writers remembered with nothing waiting (the sequence number of their last large sample), before they are
/// forgotten.
const MAX_IDLE_WRITERS: usize = 256;

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

/// One writer's place in the merge.
#[derive(Debug, Default)]
struct Writer {
    /// Sequence number of the last large sample received from it.
    large_seen: Option<i64>,
    /// What waits, in the updates topic's order, from the first marker whose large sample has not come.
    queue: VecDeque<Entry>,
}

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

impl Writer {
    /// When its wait ends, if it has one: the first entry of a non-empty queue is always a marker awaited.
    fn deadline(&self) -> Option<Instant> {
        match self.queue.front() {
            Some(Entry::Awaited { until, .. }) => Some(*until),
            _ => None,
        }
    }

    /// Hands on the entries from the front while they are ready: an update, a large sample, or (with
    /// `expired_by`) a marker whose wait ended by then. Returns the updates handed on and the waits ended
    /// without their large sample.
    fn release(&mut self, expired_by: Option<Instant>, out: &mut Vec<Sample>) -> (usize, u64) {
        let (mut updates, mut ended) = (0, 0);
        while let Some(front) = self.queue.front() {
            if let Entry::Awaited { until, .. } = front
                && expired_by.is_none_or(|now| *until > now)
            {
                break;
            }
            match self.queue.pop_front() {
                Some(Entry::Update(sample)) => {
                    updates += 1;
                    out.push(sample);
                }
                Some(Entry::Large(sample)) => out.push(sample),
                Some(Entry::Awaited { .. } | Entry::Lost) => ended += 1,
                None => {}
            }
        }
        (updates, ended)
    }
}

/// The receiving thread's order of each writer's updates (see the module documentation). Samples come in through
/// [`Order::update`], [`Order::marker`] and [`Order::large`], and leave, in order, into the vector each call is
/// given.
#[derive(Debug, Default)]
pub(super) struct Order {
    writers: HashMap<EndpointId, Writer>,
    /// Updates waiting, all writers together.
    held: usize,
    /// Waits that ended without their large sample since [`Order::take_ended_waits`] last took them.
    ended_waits: u64,
}

impl Order {
    /// A sample of the updates topic (or of the best-effort one): handed on, or kept behind its writer's marker.
    pub(super) fn update(&mut self, sample: Sample, out: &mut Vec<Sample>) {
        match self.writers.get_mut(&sample.origin) {
            Some(writer) if !writer.queue.is_empty() => {
                writer.queue.push_back(Entry::Update(sample));
                self.held += 1;
                if self.held > MAX_HELD {
                    self.end_oldest_wait(out);
                }
            }
            _ => out.push(sample),
        }
    }

    /// A marker from `origin` for its large sample `sequence`, received at `now`: unless that sample came first,
    /// `origin`'s updates wait behind it.
    pub(super) fn marker(&mut self, origin: EndpointId, sequence: i64, now: Instant) {
        let writer = self.writers.entry(origin).or_default();
        if writer.large_seen.is_none_or(|seen| seen < sequence) {
            writer.queue.push_back(Entry::Awaited { sequence, until: now + MAX_WAIT });
        }
        self.forget_idle_writers(origin);
    }

    /// A sample of the topic of large updates, with its RTPS sequence number: handed on at its marker's place if
    /// the marker waits, else at once.
    pub(super) fn large(&mut self, sample: Sample, sequence: i64, out: &mut Vec<Sample>) {
        let origin = sample.origin;
        let writer = self.writers.entry(origin).or_default();
        writer.large_seen = Some(writer.large_seen.map_or(sequence, |seen| seen.max(sequence)));
        let mut sample = Some(sample);
        for entry in &mut writer.queue {
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
        let (updates, ended) = writer.release(None, out);
        self.held -= updates;
        self.ended_waits += ended;
        // No marker waits for it (it came first, or its marker's wait ended): at once.
        out.extend(sample);
        self.forget_idle_writers(origin);
    }

    /// Ends the waits due by `now`, handing on what waited behind them.
    pub(super) fn expire(&mut self, now: Instant, out: &mut Vec<Sample>) {
        for writer in self.writers.values_mut() {
            if writer.deadline().is_some_and(|deadline| deadline <= now) {
                let (updates, ended) = writer.release(Some(now), out);
                self.held -= updates;
                self.ended_waits += ended;
            }
        }
    }

    /// When the earliest wait ends, if any update waits.
    pub(super) fn next_deadline(&self) -> Option<Instant> {
        self.writers.values().filter_map(Writer::deadline).min()
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

    /// Past [`MAX_HELD`]: the writer whose wait is oldest stops waiting.
    fn end_oldest_wait(&mut self, out: &mut Vec<Sample>) {
        let oldest =
            self.writers.values_mut().filter_map(|writer| Some((writer.deadline()?, writer))).min_by_key(|(at, _)| *at);
        if let Some((deadline, writer)) = oldest {
            tracing::warn!("rtps: {MAX_HELD} updates wait for large samples; the oldest wait ends");
            let (updates, ended) = writer.release(Some(deadline), out);
            self.held -= updates;
            self.ended_waits += ended;
        }
    }

    /// Forgets writers with nothing waiting, but `keep`, once more than [`MAX_IDLE_WRITERS`] are remembered.
    fn forget_idle_writers(&mut self, keep: EndpointId) {
        if self.writers.len() > MAX_IDLE_WRITERS {
            self.writers.retain(|origin, writer| *origin == keep || !writer.queue.is_empty());
        }
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
    fn idle_writers_are_forgotten_past_the_bound() {
        let (mut order, now) = (Order::default(), Instant::now());
        let mut out = Vec::new();
        for writer in 0..=MAX_IDLE_WRITERS as u128 + 1 {
            order.marker(EndpointId(writer), 1, now);
            order.large(sample(EndpointId(writer), 1), 1, &mut out);
        }
        assert_eq!(out.len(), MAX_IDLE_WRITERS + 2);
        assert!(order.writers.len() <= MAX_IDLE_WRITERS + 1);
        order.marker(A, 1, now);
        assert!(order.writers.contains_key(&A));
    }
}
