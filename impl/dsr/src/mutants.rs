//! The mutation switch: known bugs the model checker must catch, planted in the real code paths.
//!
//! Test-only. Without the cargo feature `mutants`, [`Plant`] is a zero-sized value whose `is` is always `false`, so
//! no mutant can be planted and the compiler removes every check. With the feature, a replica carries the mutant
//! it was given (`Replica::plant_mutant`) and passes it down explicitly: no global state, so tests that
//! plant different mutants can run side by side.

/// A bug that can be planted in the replica.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum DsrMutant {
    /// Join re-adds values whose dots this replica has already seen (and removed): not idempotent.
    JoinNotIdempotent,
    /// Removals (edge delete, attribute remove, attribute overwrite) lose their causal context.
    RemoveLosesContext,
    /// A register's winner is the value that arrived last, not the highest stamp.
    TieBreakByArrival,
    /// Deleting a node keeps its incident edges (and edges are shown without checking their endpoints).
    DeleteKeepsIncidentEdges,
    /// An edge added concurrently to a deleted node is kept and shown.
    EdgeToDeletedNodeVisible,
    /// Anti-entropy leaves out the last delta a peer is missing.
    AntiEntropySkipsLastDelta,
    /// Context compaction closes a one-dot gap: a dot that extends the version vector also absorbs an
    /// out-of-order dot two further on, so the missing dot between them counts as seen.
    ContextCompactionSkipsGap,
    /// A joined snapshot's causal context is taken as the operations its sender had applied (instead of the
    /// snapshot's own list of them), so the receiver claims operations it only saw removed, and anti-entropy, which
    /// compares applied operations, never sends them.
    SnapshotAppliedFromContext,
    /// The history is taken to reach one delta further back than it does: the oldest operation a peer lacks is
    /// counted as retained, and the answer leaves it out instead of falling back to a snapshot.
    HistoryOffByOne,
    /// An operation folded into a later one's retained delta (its values overwritten) travels without its context:
    /// what it removed stays at a peer that missed it.
    FoldDropsContext,
    /// Installing a snapshot into a fresh replica drops the snapshot's tombstones.
    InstallDropsTombstones,
    /// The wire format writes a dot of the delta's own replica after the first generated one at one less than
    /// its offset (the first dot, and every single-dot delta, unaffected).
    CodecDotOffset,
    /// A deleted node stays in the name index while other nodes share its name, so a concurrent insert of the same
    /// name keeps showing as `name#id` instead of taking the plain name back.
    NameKeptByDeletedHolder,
    /// An attribute write for a node this replica has not seen inserted is dropped instead of kept for later.
    EarlyAttrDropped,
    /// Change events leave out the edges that a node's deletion (or arrival) hides (or shows).
    IncidentEdgeEventsMissing,
    /// The hybrid logical clock takes the physical clock as the stamp when it is not behind the last stamp (`>=`
    /// instead of `>`), so a stamp can equal the one before it, a remote one included.
    StampTiesPhysicalClock,
    /// Joining a snapshot does not move the clock past the snapshot's stamps.
    SnapshotJoinKeepsClock,
    /// A register's winner is the value with the lowest (stamp, replica id, counter), not the highest: the same on
    /// every replica, so only the specification tells it from the right rule.
    WinnerLowestRank,
    /// Among visible nodes sharing a name, the latest insert (highest stamp, then id) keeps the plain name: the same
    /// on every replica, so only the specification tells it from the right rule.
    NameHeldByLatest,
}

impl DsrMutant {
    /// Every mutant.
    pub const ALL: [DsrMutant; 19] = [
        DsrMutant::JoinNotIdempotent,
        DsrMutant::RemoveLosesContext,
        DsrMutant::TieBreakByArrival,
        DsrMutant::DeleteKeepsIncidentEdges,
        DsrMutant::EdgeToDeletedNodeVisible,
        DsrMutant::AntiEntropySkipsLastDelta,
        DsrMutant::ContextCompactionSkipsGap,
        DsrMutant::SnapshotAppliedFromContext,
        DsrMutant::HistoryOffByOne,
        DsrMutant::FoldDropsContext,
        DsrMutant::InstallDropsTombstones,
        DsrMutant::CodecDotOffset,
        DsrMutant::NameKeptByDeletedHolder,
        DsrMutant::EarlyAttrDropped,
        DsrMutant::IncidentEdgeEventsMissing,
        DsrMutant::StampTiesPhysicalClock,
        DsrMutant::SnapshotJoinKeepsClock,
        DsrMutant::WinnerLowestRank,
        DsrMutant::NameHeldByLatest,
    ];
}

/// The mutant planted in one replica, if any (always none without the `mutants` feature).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct Plant {
    #[cfg(feature = "mutants")]
    mutant: Option<DsrMutant>,
}

impl Plant {
    /// No mutant.
    pub const NONE: Plant = Plant {
        #[cfg(feature = "mutants")]
        mutant: None,
    };

    /// A plant of `mutant`.
    #[cfg(feature = "mutants")]
    pub fn of(mutant: Option<DsrMutant>) -> Plant {
        Plant { mutant }
    }

    /// Whether `mutant` is planted.
    #[inline(always)]
    pub fn is(self, mutant: DsrMutant) -> bool {
        #[cfg(feature = "mutants")]
        {
            self.mutant == Some(mutant)
        }
        #[cfg(not(feature = "mutants"))]
        {
            let _ = mutant;
            false
        }
    }
}
