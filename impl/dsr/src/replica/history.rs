//! The retained history for anti-entropy: recent deltas bounded by [`LogLimits`], what a peer lacks
//! ([`Missing`]), and the snapshot that stands in when the history does not cover it.

use std::collections::{BTreeSet, VecDeque};
use std::sync::Arc;

use super::Replica;
use crate::causal::CausalContext;
use crate::delta::{Delta, DeltaParts};
use crate::mutants::{DsrMutant, Plant};

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
    /// Most deltas kept.
    pub max_deltas: usize,
    /// Most attribute payload bytes kept.
    pub max_payload_bytes: usize,
}

impl Default for LogLimits {
    fn default() -> Self {
        LogLimits { max_deltas: 4096, max_payload_bytes: 64 << 20 }
    }
}

/// The retained history: recent deltas (own and received) with their payload sizes, bounded by [`LogLimits`].
#[derive(Clone, Debug, Default, PartialEq, Eq, Hash)]
pub(super) struct DeltaLog {
    pub(super) deltas: VecDeque<(Arc<Delta>, usize)>,
    pub(super) payload_bytes: usize,
    pub(super) limits: LogLimits,
}

impl DeltaLog {
    pub(super) fn push(&mut self, delta: Arc<Delta>) {
        if self.limits.max_deltas == 0 {
            return;
        }
        let size = delta.payload_bytes();
        self.payload_bytes += size;
        self.deltas.push_back((delta, size));
        while self.deltas.len() > self.limits.max_deltas
            || (self.payload_bytes > self.limits.max_payload_bytes && self.deltas.len() > 1)
        {
            let (_, evicted) = self.deltas.pop_front().expect("non-empty log");
            self.payload_bytes -= evicted;
        }
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
    pub fn missing_for(&self, peer: &CausalContext) -> Missing {
        let Some(missing) = self.applied.missing_from(peer, self.log.deltas.len().max(1) * 4) else {
            return Missing::Snapshot;
        };
        if missing.is_empty() {
            return Missing::UpToDate;
        }
        let mut selected: Vec<Arc<Delta>> = Vec::new();
        let mut covered = BTreeSet::new();
        for (delta, _) in &self.log.deltas {
            let origin = delta.origin.expect("logged deltas have an origin");
            if origin.dots().any(|dot| !peer.contains(dot)) {
                covered.extend(origin.dots());
                selected.push(Arc::clone(delta));
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

    /// Number of deltas retained for anti-entropy.
    pub fn log_len(&self) -> usize {
        self.log.deltas.len()
    }
}
