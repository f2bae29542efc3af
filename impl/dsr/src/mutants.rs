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
}

impl DsrMutant {
    /// Every mutant.
    pub const ALL: [DsrMutant; 6] = [
        DsrMutant::JoinNotIdempotent,
        DsrMutant::RemoveLosesContext,
        DsrMutant::TieBreakByArrival,
        DsrMutant::DeleteKeepsIncidentEdges,
        DsrMutant::EdgeToDeletedNodeVisible,
        DsrMutant::AntiEntropySkipsLastDelta,
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
