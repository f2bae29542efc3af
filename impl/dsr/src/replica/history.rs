//! The retained history for anti-entropy: recent deltas bounded by [`LogLimits`], what a peer lacks
//! ([`Missing`]), and the snapshot that stands in when the history does not cover it.

mod log;

use std::collections::BTreeSet;
use std::sync::Arc;

use super::Replica;
use crate::causal::CausalContext;
use crate::delta::{Delta, DeltaParts};
use crate::mutants::{DsrMutant, Plant};
pub(super) use log::DeltaLog;

/// What a peer lacks, given its causal context (see [`Replica::missing_for`]).
#[derive(Clone, Debug)]
pub enum Missing {
    /// The peer has seen everything this replica has.
    UpToDate,
    /// These deltas, joined in any order, give the peer everything it lacks.
    Deltas(Vec<Arc<Delta>>),
    /// The retained history does not cover what the peer lacks: send the whole state ([`Replica::snapshot`], or its
    /// bytes straight from the replica with [`Replica::encode_snapshot`]; neither is made here, so a caller that
    /// sends bytes does not pay for a copy of the store it would throw away).
    Snapshot,
}

/// Limits on the history kept for anti-entropy.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct LogLimits {
    /// Most operations kept (an operation whose values a later one overwrote counts too, though only its context
    /// is kept: see [`Replica::missing_for`]).
    pub max_deltas: usize,
    /// Most attribute payload bytes kept (of values not overwritten since).
    pub max_payload_bytes: usize,
    /// An operation writing at least this many attribute payload bytes folds in the retained operations it
    /// overwrites (0: every operation does). Folding drops overwritten values early and answers a peer that
    /// missed a stream's writes with one delta, but finding what a write overwrites costs about as much as the
    /// write of a small value itself, so smaller writes are kept apart until the limits drop them.
    pub fold_min_payload_bytes: usize,
}

impl Default for LogLimits {
    fn default() -> Self {
        LogLimits { max_deltas: 4096, max_payload_bytes: 64 << 20, fold_min_payload_bytes: 1024 }
    }
}

impl Replica {
    /// The whole state as a delta: joining it gives a replica everything this one has.
    pub fn snapshot(&self) -> Delta {
        Delta {
            origin: None,
            complete: true,
            clock: self.clock,
            ctx: self.ctx.clone(),
            applied: self.applied.clone(),
            store: self.store.clone(),
            plant: Plant::NONE,
        }
    }

    /// The encoded [`Replica::snapshot`], byte for byte, made from the replica's own state without copying it
    /// first (what an agent sends a late joiner).
    ///
    /// # Examples
    /// ```
    /// use dsr::{NewNode, Replica, ReplicaId};
    /// let mut a = Replica::new(ReplicaId(1));
    /// a.insert_node(10, NewNode::new("world", "world")).unwrap();
    /// assert_eq!(a.encode_snapshot(), a.snapshot().encode());
    /// ```
    pub fn encode_snapshot(&self) -> Vec<u8> {
        let parts = DeltaParts {
            origin: None,
            complete: true,
            clock: self.clock,
            ctx: &self.ctx,
            applied: &self.applied,
            store: &self.store,
            plant: Plant::NONE,
        };
        let mut out = Vec::new();
        parts.encode_into(&mut out, None);
        out
    }

    /// What a peer whose joined operations are `peer` (its [`Replica::applied`]) lacks: nothing, a set of retained
    /// deltas, or (when the retained history does not cover the gap) a snapshot.
    ///
    /// An operation whose values a later retained one of at least [`LogLimits::fold_min_payload_bytes`] has wholly
    /// overwritten (a camera frame and the next) is kept as its context alone, folded into the later one's entry,
    /// and the two travel as one delta: the later one's values under both contexts, with both operations as applied
    /// ones (see `history/log.rs`). So a peer that missed a hundred frames gets the current one, not a hundred.
    /// Smaller writes (a pose, a scalar) are kept one by one and answered one by one.
    pub fn missing_for(&self, peer: &CausalContext) -> Missing {
        let Some(missing) = self.applied.missing_from(peer, self.log.operations().max(1) * 4) else {
            return Missing::Snapshot;
        };
        if missing.is_empty() {
            return Missing::UpToDate;
        }
        let mut selected: Vec<Arc<Delta>> = Vec::new();
        let mut covered = BTreeSet::new();
        for entry in self.log.entries() {
            if let Some(delta) = entry.delta_from(peer, self.plant) {
                let origin = delta.origin.expect("logged deltas have an origin");
                covered.extend(origin.dots().chain(delta.applied.dots()));
                selected.push(delta);
            }
        }
        // Mutant: the oldest missing operation is taken as retained.
        let unchecked = usize::from(self.plant.is(DsrMutant::HistoryOffByOne));
        if !missing.iter().skip(unchecked).all(|dot| covered.contains(dot)) {
            return Missing::Snapshot;
        }
        if self.plant.is(DsrMutant::AntiEntropySkipsLastDelta) {
            selected.pop();
        }
        Missing::Deltas(selected)
    }

    /// Number of deltas retained for anti-entropy (an operation folded into a later one's delta is not counted).
    pub fn log_len(&self) -> usize {
        self.log.len()
    }

    /// Number of operations the retained history covers, folded ones included (at most
    /// [`LogLimits::max_deltas`]).
    pub fn log_operations(&self) -> usize {
        self.log.operations()
    }

    /// Attribute payload bytes the retained history holds (at most [`LogLimits::max_payload_bytes`], unless its
    /// newest delta alone is larger).
    pub fn log_payload_bytes(&self) -> usize {
        self.log.payload_bytes()
    }
}
