//! The protocol's mutation switch: known bugs of the agent protocol that the agents model must catch, planted in
//! [`crate::core::AgentCore`]'s real code paths.
//!
//! Test-only. Without the cargo feature `mutants`, [`Plant`] is a zero-sized value whose `is` is always `false`, so
//! no mutant can be planted and the compiler removes every check. With it, a core carries the mutant of its
//! [`crate::core::ProtocolConfig`]: no global state.

/// A bug that can be planted in the agent protocol.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum ProtocolMutant {
    /// A delta that shows a gap in its writer's operations asks for nothing (the loss waits for an announce).
    NoGapRequest,
    /// A new life's incarnation counts only what peers showed: a life that starts alone reuses an earlier id.
    IncarnationForgotten,
    /// A delta received while joining is dropped instead of buffered for the graph to come.
    DropEarlyDelta,
    /// After the first announce, the announce timer is never set again.
    AnnounceTimerLost,
    /// A joiner sends its graph request once and never repeats it.
    JoinRequestOnce,
    /// An unanswered missing-request stays outstanding for ever, so no later request goes out.
    PendingAskNeverExpires,
    /// A joining life counts the time its process was stopped against its join wait: resumed, it starts alone at
    /// once beside peers it had no chance to hear (the join wait's discount, `AgentCore::joining_since_ns`, lost).
    JoinWaitCountsAbsence,
    /// A life whose graph is unnamed never moves to the graph of an announce it hears: an agent that started alone
    /// beside peers it could not hear keeps a graph of its own for good.
    UnnamedGraphNeverMoves,
}

impl ProtocolMutant {
    /// Every mutant.
    pub const ALL: [ProtocolMutant; 8] = [
        ProtocolMutant::NoGapRequest,
        ProtocolMutant::IncarnationForgotten,
        ProtocolMutant::DropEarlyDelta,
        ProtocolMutant::AnnounceTimerLost,
        ProtocolMutant::JoinRequestOnce,
        ProtocolMutant::PendingAskNeverExpires,
        ProtocolMutant::JoinWaitCountsAbsence,
        ProtocolMutant::UnnamedGraphNeverMoves,
    ];
}

/// The mutant planted in one core, if any (always none without the `mutants` feature).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct Plant {
    #[cfg(feature = "mutants")]
    mutant: Option<ProtocolMutant>,
}

impl Plant {
    /// No mutant.
    pub const NONE: Plant = Plant {
        #[cfg(feature = "mutants")]
        mutant: None,
    };

    /// A plant of `mutant`.
    #[cfg(feature = "mutants")]
    pub fn of(mutant: Option<ProtocolMutant>) -> Plant {
        Plant { mutant }
    }

    /// Whether `mutant` is planted.
    #[inline(always)]
    pub fn is(self, mutant: ProtocolMutant) -> bool {
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
