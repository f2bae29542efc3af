//! Large updates on a topic of their own, put back in their writer's order on receipt.
//!
//! `rustdds` 0.15 keeps a reader's last [`RtpsConfig::reader_cache_samples`] samples whatever their size (see the
//! parent module's documentation, "Memory"), so one topic for every update made a receiver of 4 MiB frames hold
//! 4 GiB. Samples on [`Channel::Updates`] of [`RtpsConfig::large_sample_bytes`] or more therefore go on a topic of
//! large updates (`{prefix}_updates_large`), whose readers keep [`RtpsConfig::large_cache_samples`]; the others stay
//! on the updates topic with its larger cache, for bursts of small samples.
//!
//! Two topics do not keep one writer's order: on loopback a run of large samples arrived well before the small
//! updates written between them, and a small update can overtake the large one written before it. An agent asks at
//! once for the operation a gap shows (a frame, sent again). So after each large sample the writer puts a
//! **marker** on the updates topic ([`MARKER`] and the large sample's RTPS sequence number), and the receiving
//! thread merges the two topics in the updates topic's order ([`Order`]): a large sample is handed on at its
//! marker's place; behind a marker whose large sample has not come, that writer's updates wait, and a large sample
//! whose marker has not come waits for it. A wait ends after [`MAX_WAIT`] (a sample evicted from a cache, a writer
//! gone), and a marker's wait also when a later large sample of the writer comes (the earlier one is lost, since one
//! writer's samples come in order); what waited is then handed on, and agents repair a loss as any other. At most
//! [`MAX_HELD`] samples wait in all; past that the oldest wait ends early.

use std::collections::{HashMap, VecDeque};
use std::time::{Duration, Instant};

use bytes::Bytes;

#[cfg(doc)]
use crate::{Channel, rtps::RtpsConfig};
use crate::{EndpointId, Sample};

/// The first bytes of a marker on the updates topic; its writer's large sample's RTPS sequence number follows (8
/// bytes, little-endian). Agents' samples start with another byte (`0xd5`); the receiving thread consumes markers.
pub(super) const MARKER: [u8; 8] = *b"\xffRTPSlg1";

/// How long a sample waits for its place in its writer's order.
pub(super) const MAX_WAIT: Duration = Duration::from_secs(1);

/// Samples that may wait, all writers together.
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
    /// Sequence number of the last marker received from it.
    marker_seen: Option<i64>,
    /// What waits, in the updates topic's order, from the first marker whose large sample has not come.
    queue: VecDeque<Entry>,
    /// Large samples whose marker has not come, with their sequence numbers and the end of their wait.
    early: VecDeque<(i64, Sample, Instant)>,
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
    fn is_idle(&self) -> bool {
        self.queue.is_empty() && self.early.is_empty()
    }

    /// When its earliest wait ends.
    fn deadline(&self) -> Option<Instant> {
        let marker = match self.queue.front() {
            Some(Entry::Awaited { until, .. }) => Some(*until),
            _ => None,
        };
        let early = self.early.front().map(|(_, _, until)| *until);
        marker.into_iter().chain(early).min()
    }
}

/// The merge's counts, borrowed beside one of its writers.
struct Counts<'a> {
    held: &'a mut usize,
    ended_waits: &'a mut u64,
}

/// The merge of the updates topic and the topic of large updates, per writer (see the module documentation).
/// Samples come in through [`Order::update`], [`Order::marker`] and [`Order::large`], and leave, in order, into
/// the vector each call is given.
#[derive(Debug, Default)]
pub(super) struct Order {
    writers: HashMap<EndpointId, Writer>,
    held: usize,
    /// Waits that ended without their sample or marker since [`Order::take_ended_waits`] last took them.
    ended_waits: u64,
}

impl Order {
    /// A sample of the updates topic (or of the best-effort one): handed on, or kept behind its writer's marker.
    pub(super) fn update(&mut self, sample: Sample, out: &mut Vec<Sample>) {
        match self.writers.get_mut(&sample.origin) {
            Some(writer) if !writer.queue.is_empty() => {
                writer.queue.push_back(Entry::Update(sample));
                self.held_one_more(out);
            }
            _ => out.push(sample),
        }
    }

    /// A marker from `origin` for its large sample `sequence`, received at `now`: the large sample's place.
    pub(super) fn marker(&mut self, origin: EndpointId, sequence: i64, now: Instant, out: &mut Vec<Sample>) {
        let writer = self.writers.entry(origin).or_default();
        writer.marker_seen = Some(writer.marker_seen.map_or(sequence, |seen| seen.max(sequence)));
        // Large samples that came before theirs: those of earlier markers, lost, go first.
        while writer.early.front().is_some_and(|(early, _, _)| *early < sequence) {
            if let Some((_, sample, _)) = writer.early.pop_front() {
                self.ended_waits += 1;
                Self::place(writer, sample, &mut self.held, out);
            }
        }
        if writer.early.front().is_some_and(|(early, _, _)| *early == sequence) {
            if let Some((_, sample, _)) = writer.early.pop_front() {
                Self::place(writer, sample, &mut self.held, out);
            }
        } else if writer.large_seen.is_none_or(|seen| seen < sequence) {
            writer.queue.push_back(Entry::Awaited { sequence, until: now + MAX_WAIT });
        }
        // Else its large sample came, waited and was handed on.
        self.forget_idle_writers(origin);
    }

    /// A sample of the topic of large updates, with its RTPS sequence number, received at `now`.
    pub(super) fn large(&mut self, sample: Sample, sequence: i64, now: Instant, out: &mut Vec<Sample>) {
        let origin = sample.origin;
        let writer = self.writers.entry(origin).or_default();
        writer.large_seen = Some(writer.large_seen.map_or(sequence, |seen| seen.max(sequence)));
        let mut sample = Some(sample);
        for entry in &mut writer.queue {
            match entry {
                Entry::Awaited { sequence: marked, .. } if *marked == sequence => {
                    *entry = sample.take().map_or(Entry::Lost, Entry::Large);
                    self.held += 1;
                    break;
                }
                // One writer's samples come in order: an earlier one that has not come is lost.
                Entry::Awaited { sequence: marked, .. } if *marked < sequence => *entry = Entry::Lost,
                _ => {}
            }
        }
        match sample {
            None => {
                Self::release(writer, None, Counts { held: &mut self.held, ended_waits: &mut self.ended_waits }, out)
            }
            // Its marker's wait has ended: its place has passed.
            Some(sample) if writer.marker_seen.is_some_and(|seen| seen >= sequence) => out.push(sample),
            Some(sample) => {
                writer.early.push_back((sequence, sample, now + MAX_WAIT));
                self.held_one_more(out);
            }
        }
        self.forget_idle_writers(origin);
    }

    /// Ends the waits due by `now`, handing on what waited.
    pub(super) fn expire(&mut self, now: Instant, out: &mut Vec<Sample>) {
        for writer in self.writers.values_mut() {
            if writer.deadline().is_some_and(|deadline| deadline <= now) {
                Self::end_waits(writer, now, Counts { held: &mut self.held, ended_waits: &mut self.ended_waits }, out);
            }
        }
    }

    /// When the earliest wait ends, if any sample waits.
    pub(super) fn next_deadline(&self) -> Option<Instant> {
        self.writers.values().filter_map(Writer::deadline).min()
    }

    /// How many waits ended without their sample or marker since the last call.
    pub(super) fn take_ended_waits(&mut self) -> u64 {
        std::mem::take(&mut self.ended_waits)
    }

    /// Samples waiting now, all writers together.
    #[cfg(test)]
    fn held(&self) -> usize {
        self.held
    }

    /// Puts an early large sample (counted in `held`) at its marker's place: handed on if nothing waits before it,
    /// else at the back of `writer`'s queue.
    fn place(writer: &mut Writer, sample: Sample, held: &mut usize, out: &mut Vec<Sample>) {
        if writer.queue.is_empty() {
            *held -= 1;
            out.push(sample);
        } else {
            writer.queue.push_back(Entry::Large(sample));
        }
    }

    /// Hands on `writer`'s entries from the front while they are ready: an update, a large sample, or (with
    /// `expired_by`) a marker whose wait ended by then.
    fn release(writer: &mut Writer, expired_by: Option<Instant>, counts: Counts<'_>, out: &mut Vec<Sample>) {
        while let Some(front) = writer.queue.front() {
            if let Entry::Awaited { until, .. } = front
                && !expired_by.is_some_and(|now| *until <= now)
            {
                break;
            }
            match writer.queue.pop_front() {
                Some(Entry::Update(sample) | Entry::Large(sample)) => {
                    *counts.held -= 1;
                    out.push(sample);
                }
                Some(Entry::Awaited { .. } | Entry::Lost) => *counts.ended_waits += 1,
                None => {}
            }
        }
    }

    /// Ends `writer`'s waits due by `now`: its markers' (what waited behind them follows) and its early large
    /// samples' (handed on out of order).
    fn end_waits(writer: &mut Writer, now: Instant, counts: Counts<'_>, out: &mut Vec<Sample>) {
        Self::release(writer, Some(now), Counts { held: counts.held, ended_waits: counts.ended_waits }, out);
        while writer.early.front().is_some_and(|(_, _, until)| *until <= now) {
            if let Some((_, sample, _)) = writer.early.pop_front() {
                *counts.held -= 1;
                *counts.ended_waits += 1;
                out.push(sample);
            }
        }
    }

    /// Counts one more waiting sample; past [`MAX_HELD`], the writer whose wait is oldest stops waiting.
    fn held_one_more(&mut self, out: &mut Vec<Sample>) {
        self.held += 1;
        if self.held <= MAX_HELD {
            return;
        }
        let oldest =
            self.writers.values_mut().filter_map(|writer| Some((writer.deadline()?, writer))).min_by_key(|(at, _)| *at);
        if let Some((deadline, writer)) = oldest {
            tracing::warn!(
                "rtps: {MAX_HELD} samples wait for their place in their writers' order; the oldest wait ends"
            );
            Self::end_waits(writer, deadline, Counts { held: &mut self.held, ended_waits: &mut self.ended_waits }, out);
        }
    }

    /// Forgets writers with nothing waiting, but `keep`, once more than [`MAX_IDLE_WRITERS`] are remembered.
    fn forget_idle_writers(&mut self, keep: EndpointId) {
        if self.writers.len() > MAX_IDLE_WRITERS {
            self.writers.retain(|origin, writer| *origin == keep || !writer.is_idle());
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
        order.marker(A, 5, now, &mut out);
        order.update(sample(A, 2), &mut out);
        order.update(sample(B, 9), &mut out);
        assert_eq!(tags(&out), [1, 9], "A's second update waits, B's does not");
        assert_eq!(order.held(), 1);
        assert_eq!(order.next_deadline(), Some(now + MAX_WAIT));
        order.large(sample(A, 50), 5, now, &mut out);
        assert_eq!(tags(&out), [1, 9, 50, 2]);
        assert_eq!((order.held(), order.next_deadline(), order.take_ended_waits()), (0, None, 0));
    }

    #[test]
    fn a_large_sample_before_its_marker_waits_for_it_and_takes_its_place() {
        let (mut order, now) = (Order::default(), Instant::now());
        let mut out = Vec::new();
        order.large(sample(A, 50), 5, now, &mut out);
        order.large(sample(A, 60), 6, now, &mut out);
        assert!(out.is_empty());
        assert_eq!((order.held(), order.next_deadline()), (2, Some(now + MAX_WAIT)));
        order.update(sample(A, 1), &mut out);
        order.marker(A, 5, now, &mut out);
        order.update(sample(A, 2), &mut out);
        assert_eq!(tags(&out), [1, 50, 2], "updates before its marker go first, those after it after");
        order.marker(A, 6, now, &mut out);
        assert_eq!(tags(&out), [1, 50, 2, 60]);
        assert_eq!((order.held(), order.next_deadline()), (0, None));
    }

    #[test]
    fn an_early_large_sample_whose_marker_does_not_come_goes_at_the_end_of_its_wait_and_the_marker_is_ignored() {
        let (mut order, now) = (Order::default(), Instant::now());
        let mut out = Vec::new();
        order.large(sample(A, 50), 5, now, &mut out);
        order.expire(now + MAX_WAIT, &mut out);
        assert_eq!(tags(&out), [50]);
        assert_eq!(order.take_ended_waits(), 1);
        order.marker(A, 5, now + MAX_WAIT, &mut out);
        order.update(sample(A, 1), &mut out);
        assert_eq!(tags(&out), [50, 1], "the late marker holds nothing back");
    }

    #[test]
    fn early_large_samples_of_markers_that_were_lost_go_before_the_next_marker_s() {
        let (mut order, now) = (Order::default(), Instant::now());
        let mut out = Vec::new();
        order.large(sample(A, 50), 5, now, &mut out);
        order.large(sample(A, 60), 6, now, &mut out);
        order.marker(A, 6, now, &mut out);
        assert_eq!(tags(&out), [50, 60]);
        assert_eq!((order.held(), order.take_ended_waits()), (0, 1), "5's marker did not come");
    }

    #[test]
    fn a_wait_ends_at_its_deadline_and_a_later_large_sample_marks_an_earlier_one_lost() {
        let (mut order, now) = (Order::default(), Instant::now());
        let mut out = Vec::new();
        order.marker(A, 5, now, &mut out);
        order.update(sample(A, 1), &mut out);
        order.expire(now + MAX_WAIT - Duration::from_millis(1), &mut out);
        assert!(out.is_empty());
        order.expire(now + MAX_WAIT, &mut out);
        assert_eq!(tags(&out), [1]);
        assert_eq!(order.take_ended_waits(), 1);
        out.clear();
        // Sample 6 never comes; 7 does: 6 was lost, and what waited behind both goes, in order.
        order.marker(A, 6, now, &mut out);
        order.update(sample(A, 2), &mut out);
        order.marker(A, 7, now, &mut out);
        order.update(sample(A, 3), &mut out);
        order.large(sample(A, 70), 7, now, &mut out);
        assert_eq!(tags(&out), [2, 70, 3]);
        assert_eq!((order.held(), order.next_deadline(), order.take_ended_waits()), (0, None, 1));
        // Sample 5, whose wait ended, comes after all: handed on at once.
        order.large(sample(A, 50), 5, now, &mut out);
        assert_eq!(tags(&out), [2, 70, 3, 50]);
        assert_eq!(order.held(), 0);
    }

    #[test]
    fn past_the_bound_the_oldest_wait_ends() {
        let (mut order, now) = (Order::default(), Instant::now());
        let mut out = Vec::new();
        order.marker(A, 5, now, &mut out);
        order.marker(B, 5, now + Duration::from_millis(1), &mut out);
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
            order.marker(EndpointId(writer), 1, now, &mut out);
            order.large(sample(EndpointId(writer), 1), 1, now, &mut out);
        }
        assert_eq!(out.len(), MAX_IDLE_WRITERS + 2);
        assert!(order.writers.len() <= MAX_IDLE_WRITERS + 1);
        order.marker(A, 1, now, &mut out);
        assert!(order.writers.contains_key(&A));
    }
}
