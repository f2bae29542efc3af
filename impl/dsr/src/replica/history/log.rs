//! The retained history itself: recent operations' deltas, bounded by [`LogLimits`], with overwritten operations
//! folded into the operation that overwrote them.
//!
//! **Folding.** A camera frame written at 20 Hz overwrites the one before; keeping every frame's delta kept every
//! frame's bytes (64 MiB of frames nobody can see any more, and, where the frames came through shared memory, a
//! held chunk each). So when a new operation's delta, of at least [`LogLimits::fold_min_payload_bytes`] (1 KiB by
//! default), overwrites *everything* an earlier retained delta of that size holds, the earlier one is not kept as
//! a delta: its origin and causal context join the new entry's `earlier` list, and its values go. The entry
//! stands for the join of all its operations, which is the newest delta's store under the union of their contexts
//! ([`Entry::delta_from`]); a peer lacking any of them gets that one delta.
//!
//! **Why a threshold.** Finding what a write overwrites reads the earlier delta, written thousands of operations
//! before and cold in the cache, and an index of the foldable entries. For a small value that doubled the cost of
//! a received delta's join (`cargo bench -p dsr`'s `delta_join`) and saved a few bytes; smaller writes are kept
//! apart, unindexed, until the limits drop them, as before folding existed.
//!
//! An earlier delta `e` is overwritten by a new delta `n` when `e` deletes no node, every register `e` lists
//! (node cores, edge presences, attributes, empty ones included) is listed by `n` too, and every dot of `e`'s
//! values is in `n`'s context. Then, for any state `x`, `x ⊔ e ⊔ n = x ⊔ (n.store, e.ctx ∪ n.ctx)`: at `e`'s
//! registers `n`'s context removes what `e` added, and `e`'s context holds no dot of any register `e` does not
//! list. The same holds for any suffix of an entry's operations, since each one is overwritten by the next or by
//! the newest; so the count limit drops an entry's oldest folded operations first, and an answer carries only the
//! suffix from the oldest operation the peer lacks.

use std::collections::{BTreeMap, VecDeque};
use std::sync::Arc;

use smallvec::SmallVec;

use super::LogLimits;
use crate::causal::CausalContext;
use crate::delta::{Delta, Origin};
use crate::ids::Dot;
use crate::mutants::{DsrMutant, Plant};
use crate::store::{Attrs, Register};

/// Contexts larger than this are not searched for the deltas they overwrite (a delete of many edges): folding
/// is a saving, not a duty, and its lookup should cost an operation little.
const MAX_SEARCHED_DOTS: usize = 64;

/// The same for a folded delta received from a peer (an answer, rare), whose context holds its operations' own.
const MAX_SEARCHED_DOTS_FOLDED: usize = 8192;

/// One retained entry: the newest delta and the operations folded into it.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub(in crate::replica) struct Entry {
    /// The newest operation's delta, as joined.
    delta: Arc<Delta>,
    /// Its attribute payload bytes.
    payload_bytes: usize,
    /// Operations the newest delta carries as applied ones (a folded delta received from a peer).
    carried: usize,
    /// Whether later operations may fold this one in ([`LogLimits::fold_min_payload_bytes`]), and so the index
    /// finds it.
    foldable: bool,
    /// Folded operations, oldest first: their origins and contexts (their values are all overwritten).
    earlier: VecDeque<(Origin, FoldedCtx)>,
}

/// A folded operation's causal context. Most are a write's own dot and the dots of the values it overwrote, held
/// in place: as a `CausalContext` each held a heap node, which its eviction, thousands of writes later, freed from
/// cold memory (a tenth of a scattered local update's time in `cargo bench -p dsr`).
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
enum FoldedCtx {
    /// A context of at most three dots and no version vector.
    Dots(SmallVec<[Dot; 3]>),
    /// Any other context.
    Full(CausalContext),
}

impl FoldedCtx {
    fn new(ctx: CausalContext) -> Self {
        if ctx.version_vector().is_empty() && ctx.cloud_len() <= 3 {
            FoldedCtx::Dots(ctx.cloud().iter().copied().collect())
        } else {
            FoldedCtx::Full(ctx)
        }
    }

    /// Adds these dots to `into`.
    fn merge_into(&self, into: &mut CausalContext) {
        match self {
            FoldedCtx::Dots(dots) => dots.iter().for_each(|&dot| into.insert(dot)),
            FoldedCtx::Full(ctx) => into.merge(ctx),
        }
    }
}

impl Entry {
    /// Operations this entry stands for.
    fn operations(&self) -> usize {
        1 + self.carried + self.earlier.len()
    }

    /// The delta a peer whose operations are `peer` needs from this entry, if it lacks any of them: the newest
    /// delta alone when it lacks no folded one, else the join of the suffix from the oldest folded operation it
    /// lacks (the newest store, the suffix's contexts, and the suffix's operations as applied ones).
    pub(in crate::replica) fn delta_from(&self, peer: &CausalContext, plant: Plant) -> Option<Arc<Delta>> {
        let lacks = |o: &Origin| o.dots().any(|dot| !peer.contains(dot));
        let Some(first) = self.earlier.iter().position(|(o, _)| lacks(o)) else {
            let newest = self.delta.origin.is_some_and(|o| lacks(&o)) || !peer.includes(&self.delta.applied);
            return newest.then(|| Arc::clone(&self.delta));
        };
        let newest = &self.delta;
        let mut delta = Delta {
            origin: newest.origin,
            complete: false,
            clock: newest.clock,
            ctx: newest.ctx.clone(),
            applied: newest.applied.clone(),
            store: newest.store.clone(),
            plant: newest.plant,
        };
        for (origin, ctx) in self.earlier.iter().skip(first) {
            // Mutant: a folded operation's context is left out, so what it removed stays at the peer.
            if !plant.is(DsrMutant::FoldDropsContext) {
                ctx.merge_into(&mut delta.ctx);
            }
            origin.dots().for_each(|dot| delta.applied.insert(dot));
        }
        Some(Arc::new(delta))
    }
}

/// The retained history: entries by sequence number (oldest first), bounded by [`LogLimits`] in operations and
/// in the payload bytes of the values still held. Two logs are equal when their entries, in order, and limits are:
/// the sequence numbers, the index and the totals follow from them (the model checker compares replicas, so
/// equal histories must not differ by how they were numbered).
///
/// Entries sit in a ring of slots, slot `i` holding sequence number `first_seq + i`: every write appends its
/// entry and eviction pops the front, and a folding write takes the entry it overwrites from the middle, each in
/// O(1). Only foldable entries are indexed, so a small write touches no map.
#[derive(Clone, Debug, Default)]
pub(in crate::replica) struct DeltaLog {
    /// Entries by sequence number from `first_seq`; `None` where one was taken (folded into a later entry).
    slots: VecDeque<Option<Entry>>,
    first_seq: u64,
    /// Entries in `slots` that are not `None`.
    live: usize,
    /// The foldable entry whose newest delta generated each dot range, by the range's last dot (to find what a new
    /// delta overwrites).
    by_last_dot: BTreeMap<Dot, u64>,
    operations: usize,
    payload_bytes: usize,
    pub(in crate::replica) limits: LogLimits,
}

impl PartialEq for DeltaLog {
    fn eq(&self, other: &DeltaLog) -> bool {
        self.limits == other.limits && self.entries().eq(other.entries())
    }
}

impl Eq for DeltaLog {}

impl std::hash::Hash for DeltaLog {
    fn hash<H: std::hash::Hasher>(&self, state: &mut H) {
        self.limits.hash(state);
        self.live.hash(state);
        self.entries().for_each(|entry| entry.hash(state));
    }
}

impl DeltaLog {
    /// Whether nothing is retained.
    pub(in crate::replica) fn is_empty(&self) -> bool {
        self.live == 0
    }

    /// Entries retained (folded operations count once with the delta that overwrote them).
    pub(in crate::replica) fn len(&self) -> usize {
        self.live
    }

    /// Operations retained, folded ones included.
    pub(in crate::replica) fn operations(&self) -> usize {
        self.operations
    }

    /// Attribute payload bytes held.
    pub(in crate::replica) fn payload_bytes(&self) -> usize {
        self.payload_bytes
    }

    /// The entries, oldest first.
    pub(in crate::replica) fn entries(&self) -> impl Iterator<Item = &Entry> {
        self.slots.iter().flatten()
    }

    /// The entry of sequence number `seq`, if retained.
    fn get(&self, seq: u64) -> Option<&Entry> {
        let index = usize::try_from(seq.checked_sub(self.first_seq)?).ok()?;
        self.slots.get(index)?.as_ref()
    }

    /// Retains a joined delta of one operation, folding in the retained deltas it overwrites, then applies the
    /// limits.
    pub(in crate::replica) fn push(&mut self, delta: Arc<Delta>) {
        if self.limits.max_deltas == 0 {
            return;
        }
        let payload_bytes = delta.payload_bytes();
        let foldable = payload_bytes >= self.limits.fold_min_payload_bytes;
        let overwritten = if foldable { self.overwritten_by(&delta) } else { SmallVec::new() };
        let mut earlier = VecDeque::new();
        for seq in overwritten {
            let entry = self.take(seq);
            // Usually one entry is overwritten (the last frame, which holds every frame before it): take its
            // list whole rather than copy it, which cost a write O(history) (4,096 operations by default).
            if earlier.is_empty() {
                earlier = entry.earlier;
            } else {
                earlier.extend(entry.earlier);
            }
            let origin = entry.delta.origin.expect("retained deltas have an origin");
            // A folded delta from a peer: the operations it carries come first, one dot each, and its context
            // (theirs too) goes with its own operation. A suffix from one of them is then the join of more
            // operations than it names as applied: still a join of real deltas, each overwritten by the newest.
            let carried = entry.delta.applied.dots().map(|dot| {
                (
                    Origin { replica: dot.replica, first: dot.counter, last: dot.counter },
                    FoldedCtx::Dots(SmallVec::new()),
                )
            });
            earlier.extend(carried);
            let ctx = Arc::try_unwrap(entry.delta).map_or_else(|shared| shared.ctx.clone(), |delta| delta.ctx);
            earlier.push_back((origin, FoldedCtx::new(ctx)));
        }
        let carried = delta.applied.dots().count();
        let entry = Entry { payload_bytes, carried, foldable, delta, earlier };
        self.insert(entry);
        self.evict();
        self.compact();
    }

    /// The retained entries whose deltas `delta` overwrites wholly (see the module documentation), oldest first.
    fn overwritten_by(&self, delta: &Delta) -> SmallVec<[u64; 4]> {
        let Some(origin) = delta.origin else { return SmallVec::new() };
        let ctx = &delta.ctx;
        let small = ctx.cloud_len() + ctx.version_vector().iter().map(|(_, n)| *n as usize).sum::<usize>();
        let limit = if delta.applied.is_empty() { MAX_SEARCHED_DOTS } else { MAX_SEARCHED_DOTS_FOLDED };
        if small > limit {
            return SmallVec::new();
        }
        let ranges = ctx.version_vector().iter().flat_map(|&(r, n)| (1..=n).map(move |c| Dot::new(r, c)));
        let mut found: SmallVec<[u64; 4]> = ranges
            .chain(ctx.cloud().iter().copied())
            .filter(|dot| dot.replica != origin.replica || !(origin.first..=origin.last).contains(&dot.counter))
            .filter_map(|dot| self.generated(dot))
            .collect();
        found.sort_unstable();
        found.dedup();
        found.retain(|seq| self.get(*seq).is_some_and(|entry| overwrites(delta, &entry.delta)));
        found
    }

    /// The entry whose newest delta generated `dot`.
    fn generated(&self, dot: Dot) -> Option<u64> {
        let (_, seq) = self.by_last_dot.range(dot..=Dot::new(dot.replica, u64::MAX)).next()?;
        let origin = self.get(*seq)?.delta.origin?;
        (origin.first <= dot.counter).then_some(*seq)
    }

    /// Adds an entry; a foldable one replaces a foldable entry of the same operation (the replica does not
    /// retain an operation it has applied, so neither occurs in its use).
    fn insert(&mut self, entry: Entry) {
        if entry.foldable {
            let last = last_dot(&entry.delta);
            if let Some(&same) = self.by_last_dot.get(&last) {
                self.take(same);
            }
            self.by_last_dot.insert(last, self.first_seq + self.slots.len() as u64);
        }
        self.operations += entry.operations();
        self.payload_bytes += entry.payload_bytes;
        self.slots.push_back(Some(entry));
        self.live += 1;
    }

    fn take(&mut self, seq: u64) -> Entry {
        let index = usize::try_from(seq - self.first_seq).expect("a retained entry's slot");
        let entry = self.slots[index].take().expect("a retained entry");
        if entry.foldable {
            self.by_last_dot.remove(&last_dot(&entry.delta));
        }
        self.live -= 1;
        self.operations -= entry.operations();
        self.payload_bytes -= entry.payload_bytes;
        self.trim();
        entry
    }

    /// Drops the slots of taken entries from the front (numbers stay valid).
    fn trim(&mut self) {
        while let Some(None) = self.slots.front() {
            self.slots.pop_front();
            self.first_seq += 1;
        }
    }

    /// Renumbers the entries when taken ones are most of the ring (a history whose oldest entry outlives thousands
    /// of folded writes, under a large count limit). Only between operations: a write holds the numbers of the
    /// entries it folds until it has taken them all.
    fn compact(&mut self) {
        if self.slots.len() <= 2 * self.live + 64 {
            return;
        }
        self.slots.retain(Option::is_some);
        let first_seq = self.first_seq;
        let foldable = self.entries().enumerate().filter(|(_, entry)| entry.foldable);
        self.by_last_dot = foldable.map(|(index, entry)| (last_dot(&entry.delta), first_seq + index as u64)).collect();
    }

    /// Drops the oldest operations (an entry's folded ones before the entry) while over the limits. The newest entry
    /// stays, unless it alone carries more operations than the limit (a folded answer from a peer).
    fn evict(&mut self) {
        while self.operations > self.limits.max_deltas
            || (self.payload_bytes > self.limits.max_payload_bytes && self.live > 1)
        {
            let seq = self.first_seq;
            let oldest = self.slots.front_mut().and_then(Option::as_mut).expect("a trimmed, non-empty log");
            if self.operations > self.limits.max_deltas && oldest.earlier.pop_front().is_some() {
                self.operations -= 1;
            } else {
                self.take(seq);
            }
        }
    }
}

/// The last dot a retained delta's own operation generated: its key in the index.
fn last_dot(delta: &Delta) -> Dot {
    let origin = delta.origin.expect("retained deltas have an origin");
    Dot::new(origin.replica, origin.last)
}

/// Whether `new` overwrites everything `old` holds (see the module documentation).
fn overwrites(new: &Delta, old: &Delta) -> bool {
    let attrs_covered = |mine: &Attrs, theirs: &Attrs| {
        mine.iter().all(|(name, register)| theirs.contains_key(name) && covered(register, &new.ctx))
    };
    old.store.tombstones.is_empty()
        && old.store.nodes.iter().all(|(id, entry)| {
            new.store
                .nodes
                .get(id)
                .is_some_and(|n| covered(&entry.core, &new.ctx) && attrs_covered(&entry.attrs, &n.attrs))
        })
        && old.store.edges.iter().all(|(key, entry)| {
            let presence = covered(&entry.presence, &new.ctx);
            new.store.edges.get(key).is_some_and(|n| presence && attrs_covered(&entry.attrs, &n.attrs))
        })
}

/// Whether `ctx` holds every dot of `register`'s values.
fn covered<T: Clone>(register: &Register<T>, ctx: &CausalContext) -> bool {
    register.dots().all(|dot| ctx.contains(dot))
}

#[cfg(test)]
mod tests {
    use super::last_dot;
    use crate::{LogLimits, NewNode, Replica, ReplicaId, Value, attrs};

    /// Taken entries leave holes in the ring; behind an entry that outlives a long stream of folded writes (a
    /// count limit larger than the stream), the ring is renumbered before the holes outgrow the live entries, and
    /// the index still finds every entry.
    #[test]
    fn the_ring_stays_near_the_live_entries_behind_an_old_one() {
        let mut replica = Replica::new(ReplicaId(1));
        replica.set_log_limits(LogLimits {
            max_deltas: 100_000,
            max_payload_bytes: 1 << 20,
            fold_min_payload_bytes: 0,
        });
        replica.insert_node(1, NewNode::new("object", "x")).unwrap();
        let (y, _) = replica.insert_node(2, NewNode::new("object", "y")).unwrap();
        for i in 0..10_000u64 {
            replica.set_attr(3 + i, y, attrs::POS_X, i as f32).unwrap();
            let log = &replica.log;
            assert!(
                log.slots.len() <= 2 * log.live + 64,
                "write {i}: {} slots for {} entries",
                log.slots.len(),
                log.live
            );
            assert_eq!(log.live, 3, "write {i}");
            assert!(log.slots.front().is_some_and(Option::is_some), "the front slot holds the oldest entry");
        }
        assert_indexed_at_their_slots(&replica.log);
    }

    /// Writes of random subsets of three attributes take none, one, two or three entries each, over several
    /// renumberings of the ring: every operation stays retained, the ring stays near its live entries, and the
    /// index finds every foldable entry at its slot.
    #[test]
    fn writes_of_random_attribute_subsets_fold_what_they_overwrite_across_renumberings() {
        let mut replica = Replica::new(ReplicaId(1));
        replica.set_log_limits(LogLimits {
            max_deltas: 100_000,
            max_payload_bytes: 1 << 20,
            fold_min_payload_bytes: 0,
        });
        let (n, _) = replica.insert_node(1, NewNode::new("object", "x")).unwrap();
        let mut seed = 7u64;
        for t in 2..20_000u64 {
            seed = seed.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1_442_695_040_888_963_407);
            let subset = (seed >> 33) % 7 + 1;
            let names = ["pos_x", "pos_y", "base_target_x"].into_iter().enumerate();
            let writes =
                names.filter(|(bit, _)| subset & (1 << bit) != 0).map(|(_, name)| (name, Value::F32(t as f32)));
            replica.set_attrs(t, n, writes).unwrap();
            let log = &replica.log;
            assert_eq!(log.live, log.entries().count(), "write {t}");
            assert_eq!(log.operations, t as usize, "write {t}: every operation retained");
            assert!(log.slots.len() <= 2 * log.live + 64, "write {t}: {} slots for {}", log.slots.len(), log.live);
        }
        assert_indexed_at_their_slots(&replica.log);
    }

    /// A write that overwrites several entries holds their numbers until it has taken them all, so the ring is
    /// renumbered only after the write. A stream of single writes brings the ring near its renumbering, and then
    /// one write overwrites two entries; for some stream length between 0 and 100 the first take alone would have
    /// crossed the bound (renumbering there once left the second number pointing past the ring).
    #[test]
    fn a_write_overwriting_two_entries_folds_both_when_the_first_take_would_renumber_the_ring() {
        for stream in 0..100u64 {
            let mut replica = Replica::new(ReplicaId(1));
            let limits = LogLimits { max_deltas: 100_000, max_payload_bytes: 1 << 20, fold_min_payload_bytes: 0 };
            replica.set_log_limits(limits);
            let (n, _) = replica.insert_node(1, NewNode::new("object", "x")).unwrap();
            replica.set_attr(2, n, attrs::POS_Y, 0.0).unwrap();
            for t in 0..stream {
                replica.set_attr(3 + t, n, attrs::POS_X, t as f32).unwrap();
            }
            replica.set_attrs(1_000, n, [("pos_x", Value::F32(1.0)), ("pos_y", Value::F32(1.0))]).unwrap();
            let log = &replica.log;
            assert_eq!((log.live, log.operations), (2, 3 + stream as usize), "stream of {stream}");
            assert_indexed_at_their_slots(log);
        }
    }

    fn assert_indexed_at_their_slots(log: &super::DeltaLog) {
        for (index, entry) in log.slots.iter().enumerate() {
            let Some(entry) = entry.as_ref().filter(|entry| entry.foldable) else { continue };
            let seq = log.by_last_dot.get(&last_dot(&entry.delta)).copied();
            assert_eq!(seq, Some(log.first_seq + index as u64), "entry {index} indexed at its slot");
        }
    }
}
