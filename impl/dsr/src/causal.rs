//! Causal contexts: the set of dots a replica (or a delta) has seen.
//!
//! Kept compact as a version vector (every dot `1..=n` of a replica) plus a small cloud of dots seen out of order.
//! A context is the second half of every causal CRDT state: a dot that is in the context but not in the dot store
//! has been removed (or never carried a value), which is how removals travel without tombstones.

use std::collections::BTreeSet;

use serde::{Deserialize, Serialize};

use crate::ids::{Dot, ReplicaId};
use crate::mutants::{DsrMutant, Plant};

/// A set of dots: a version vector plus out-of-order dots.
///
/// # Examples
/// ```
/// use dsr::{CausalContext, Dot, ReplicaId};
/// let r = ReplicaId(7);
/// let mut ctx = CausalContext::default();
/// ctx.insert(Dot::new(r, 2));
/// assert!(!ctx.contains(Dot::new(r, 1)));
/// ctx.insert(Dot::new(r, 1));
/// assert_eq!(ctx.version(r), 2); // both compacted into the version vector
/// ```
#[derive(Clone, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct CausalContext {
    /// `(replica, n)`: every dot `(replica, 1..=n)` is in the set. Sorted by replica, no zero counters.
    vv: Vec<(ReplicaId, u64)>,
    /// Dots in the set beyond the version vector; never one the version vector already covers.
    cloud: BTreeSet<Dot>,
}

impl CausalContext {
    /// An empty context.
    pub fn new() -> Self {
        CausalContext::default()
    }

    /// A context holding exactly the given dots.
    pub fn from_dots(dots: impl IntoIterator<Item = Dot>) -> Self {
        let mut ctx = CausalContext::default();
        for dot in dots {
            ctx.insert(dot);
        }
        ctx
    }

    /// Whether the context holds no dot.
    pub fn is_empty(&self) -> bool {
        self.vv.is_empty() && self.cloud.is_empty()
    }

    /// The contiguous version of `replica`: every dot `1..=n` of it is in the set.
    pub fn version(&self, replica: ReplicaId) -> u64 {
        match self.vv.binary_search_by_key(&replica, |(r, _)| *r) {
            Ok(index) => self.vv[index].1,
            Err(_) => 0,
        }
    }

    /// The highest counter of `replica` in the set (including out-of-order dots).
    pub fn max_counter(&self, replica: ReplicaId) -> u64 {
        let cloud_max = self.cloud.range(Dot::new(replica, 0)..=Dot::new(replica, u64::MAX)).next_back();
        cloud_max.map_or(self.version(replica), |dot| dot.counter)
    }

    /// Whether the set holds `dot`.
    pub fn contains(&self, dot: Dot) -> bool {
        dot.counter <= self.version(dot.replica) || self.cloud.contains(&dot)
    }

    /// Adds a dot.
    pub fn insert(&mut self, dot: Dot) {
        if dot.counter == 0 || self.contains(dot) {
            return;
        }
        let index = match self.vv.binary_search_by_key(&dot.replica, |(r, _)| *r) {
            Ok(index) => index,
            Err(index) => {
                if dot.counter != 1 {
                    self.cloud.insert(dot);
                    return;
                }
                self.vv.insert(index, (dot.replica, 0));
                index
            }
        };
        if dot.counter == self.vv[index].1 + 1 {
            self.vv[index].1 = dot.counter;
            self.compact_replica(index);
        } else {
            self.cloud.insert(dot);
        }
    }

    /// Adds every dot of `other`.
    pub fn merge(&mut self, other: &CausalContext) {
        for &(replica, counter) in &other.vv {
            match self.vv.binary_search_by_key(&replica, |(r, _)| *r) {
                Ok(index) => {
                    if counter > self.vv[index].1 {
                        self.vv[index].1 = counter;
                        self.drop_covered_cloud(index);
                        self.compact_replica(index);
                    }
                }
                Err(index) => {
                    self.vv.insert(index, (replica, counter));
                    self.drop_covered_cloud(index);
                    self.compact_replica(index);
                }
            }
        }
        for dot in &other.cloud {
            self.insert(*dot);
        }
    }

    /// [`CausalContext::merge`], with a planted mutant of the compaction (see [`crate::mutants`]).
    pub(crate) fn merge_planted(&mut self, other: &CausalContext, plant: Plant) {
        self.merge(other);
        if plant.is(DsrMutant::ContextCompactionSkipsGap) {
            for index in 0..self.vv.len() {
                let (replica, counter) = self.vv[index];
                if self.cloud.remove(&Dot::new(replica, counter + 2)) {
                    self.vv[index].1 = counter + 2;
                    self.compact_replica(index);
                }
            }
        }
    }

    /// Whether every dot of `other` is in `self`.
    pub fn includes(&self, other: &CausalContext) -> bool {
        other.vv.iter().all(|&(replica, counter)| {
            let mine = self.version(replica);
            counter <= mine || (mine + 1..=counter).all(|c| self.cloud.contains(&Dot::new(replica, c)))
        }) && other.cloud.iter().all(|dot| self.contains(*dot))
    }

    /// The replicas with at least one dot in the set, in order.
    pub fn replicas(&self) -> impl Iterator<Item = ReplicaId> + '_ {
        let mut replicas: Vec<ReplicaId> = self.vv.iter().map(|(r, _)| *r).collect();
        replicas.extend(self.cloud.iter().map(|d| d.replica));
        replicas.sort_unstable();
        replicas.dedup();
        replicas.into_iter()
    }

    /// The dots of `self` that `other` lacks, stopping after `limit` of them; `None` when there are more.
    pub fn missing_from(&self, other: &CausalContext, limit: usize) -> Option<Vec<Dot>> {
        let mut missing = Vec::new();
        for &(replica, counter) in &self.vv {
            let theirs = other.version(replica);
            if counter > theirs {
                if (counter - theirs) as usize > limit.saturating_add(other.cloud.len()) {
                    return None;
                }
                for c in theirs + 1..=counter {
                    let dot = Dot::new(replica, c);
                    if !other.cloud.contains(&dot) {
                        missing.push(dot);
                        if missing.len() > limit {
                            return None;
                        }
                    }
                }
            }
        }
        for dot in &self.cloud {
            if !other.contains(*dot) {
                missing.push(*dot);
                if missing.len() > limit {
                    return None;
                }
            }
        }
        Some(missing)
    }

    /// Every dot in the set, in order. Meant for small contexts (deltas); a version vector entry expands to its
    /// whole range.
    pub fn dots(&self) -> impl Iterator<Item = Dot> + '_ {
        let ranges = self.vv.iter().flat_map(|&(replica, counter)| (1..=counter).map(move |c| Dot::new(replica, c)));
        let mut all: Vec<Dot> = ranges.chain(self.cloud.iter().copied()).collect();
        all.sort_unstable();
        all.into_iter()
    }

    /// The version-vector part: `(replica, n)` pairs meaning dots `1..=n`.
    pub fn version_vector(&self) -> &[(ReplicaId, u64)] {
        &self.vv
    }

    /// The out-of-order part.
    pub fn cloud(&self) -> &BTreeSet<Dot> {
        &self.cloud
    }

    /// Number of out-of-order dots (a measure of how far from causal the delivery has been).
    pub fn cloud_len(&self) -> usize {
        self.cloud.len()
    }

    /// Rebuilds a context from its two parts (as given by [`CausalContext::version_vector`] and
    /// [`CausalContext::cloud`]), normalising them: any order, duplicates, zero counters and cloud dots the
    /// version vector covers are accepted and cleaned up. Used by delta decoding and by agents that carry contexts
    /// in their own messages.
    ///
    /// # Examples
    /// ```
    /// use dsr::{CausalContext, Dot, ReplicaId};
    /// let (a, b) = (ReplicaId(1), ReplicaId(2));
    /// let ctx = CausalContext::from_parts(vec![(b, 3), (a, 0), (b, 1)], vec![Dot::new(b, 2), Dot::new(a, 5)]);
    /// assert_eq!(ctx.version_vector(), &[(b, 3)]);
    /// assert!(ctx.contains(Dot::new(a, 5)) && !ctx.contains(Dot::new(a, 4)));
    /// let again = CausalContext::from_parts(ctx.version_vector().to_vec(), ctx.cloud().iter().copied().collect());
    /// assert_eq!(again, ctx);
    /// ```
    pub fn from_parts(vv: Vec<(ReplicaId, u64)>, cloud: Vec<Dot>) -> Self {
        let mut ctx = CausalContext::default();
        let mut vv = vv;
        vv.sort_unstable();
        for (replica, counter) in vv {
            if counter > 0 {
                ctx.merge(&CausalContext { vv: vec![(replica, counter)], cloud: BTreeSet::new() });
            }
        }
        for dot in cloud {
            ctx.insert(dot);
        }
        ctx
    }

    fn drop_covered_cloud(&mut self, index: usize) {
        let (replica, counter) = self.vv[index];
        let covered: Vec<Dot> = self.cloud.range(Dot::new(replica, 0)..=Dot::new(replica, counter)).copied().collect();
        for dot in covered {
            self.cloud.remove(&dot);
        }
    }

    fn compact_replica(&mut self, index: usize) {
        let replica = self.vv[index].0;
        while self.cloud.remove(&Dot::new(replica, self.vv[index].1 + 1)) {
            self.vv[index].1 += 1;
        }
    }
}
