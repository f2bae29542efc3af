//! Dot stores: the data half of the causal CRDT. A replica's state and every delta share these types.
//!
//! - [`Register`] is a multi-value register (a *DotFun*): values tagged with the dot and stamp of their write.
//! - [`NodeEntry`] holds a node's core (type and name) and its attribute registers; [`EdgeEntry`] an edge's presence
//!   dots (an add-wins set) and its attribute registers.
//! - [`Store`] maps node ids and edge keys to entries, next to the grow-only set of deleted node ids.
//!
//! The one join rule (Almeida et al., "Delta state replicated data types"): a dot survives a join if both sides
//! hold it, or one side holds it and the other side's causal context has not seen it.

use std::collections::{BTreeMap, BTreeSet};

use smallvec::SmallVec;

use crate::causal::CausalContext;
use crate::ids::{Dot, EdgeKey, Name, NodeId, Stamp};
use crate::mutants::{DsrMutant, Plant};
use crate::value::Value;

/// One value of a register, tagged with the dot and stamp of the write that produced it.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct Entry<T> {
    /// The write's dot.
    pub dot: Dot,
    /// The write's hybrid-logical-clock stamp.
    pub stamp: Stamp,
    /// The value written.
    pub value: T,
}

impl<T> Entry<T> {
    /// The order that picks a register's winner: highest stamp, then highest replica id, then highest counter.
    pub(crate) fn rank(&self) -> (Stamp, crate::ids::ReplicaId, u64) {
        (self.stamp, self.dot.replica, self.dot.counter)
    }
}

/// A multi-value register: every concurrent write is kept until a later write (or removal) that has seen it.
/// Values are kept sorted by dot.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct Register<T> {
    pub(crate) values: SmallVec<[Entry<T>; 1]>,
}

impl<T> Default for Register<T> {
    fn default() -> Self {
        Register { values: SmallVec::new() }
    }
}

impl<T: Clone> Register<T> {
    /// A register holding one value.
    pub(crate) fn single(dot: Dot, stamp: Stamp, value: T) -> Self {
        let mut values = SmallVec::new();
        values.push(Entry { dot, stamp, value });
        Register { values }
    }

    /// Whether the register holds no value.
    pub fn is_empty(&self) -> bool {
        self.values.is_empty()
    }

    /// The concurrent values, in no particular order.
    pub fn entries(&self) -> &[Entry<T>] {
        &self.values
    }

    /// The deterministic winner: the highest `(stamp, replica, counter)`.
    pub fn winner(&self) -> Option<&Entry<T>> {
        self.values.iter().max_by_key(|entry| entry.rank())
    }

    /// The winner as the replica reads it (a planted mutant may change the rule).
    pub(crate) fn winner_planted(&self, plant: Plant) -> Option<&Entry<T>> {
        if plant.is(DsrMutant::TieBreakByArrival) {
            return self.values.last();
        }
        if plant.is(DsrMutant::WinnerLowestRank) {
            return self.values.iter().min_by_key(|entry| entry.rank());
        }
        self.winner()
    }

    /// The dots of the values.
    pub(crate) fn dots(&self) -> impl Iterator<Item = Dot> + '_ {
        self.values.iter().map(|entry| entry.dot)
    }

    /// Joins `other` (with context `other_ctx`) into `self` (with context `self_ctx`). Returns whether `self` changed.
    pub(crate) fn join(
        &mut self,
        other: &Register<T>,
        self_ctx: &CausalContext,
        other_ctx: &CausalContext,
        plant: Plant,
    ) -> bool {
        let before = self.values.len();
        self.values
            .retain(|mine| other.values.iter().any(|theirs| theirs.dot == mine.dot) || !other_ctx.contains(mine.dot));
        let mut changed = self.values.len() != before;
        for theirs in &other.values {
            // Mutant: a value this replica has seen and since removed comes back.
            let seen = self_ctx.contains(theirs.dot) && !plant.is(DsrMutant::JoinNotIdempotent);
            if seen {
                continue;
            }
            // Values stay sorted by dot, so equal states are equal structurally (the model checker relies on
            // it). The arrival-order mutant keeps arrival order instead.
            match self.values.binary_search_by_key(&theirs.dot, |mine| mine.dot) {
                Ok(_) => {}
                Err(_) if plant.is(DsrMutant::TieBreakByArrival) => {
                    if !self.values.iter().any(|mine| mine.dot == theirs.dot) {
                        self.values.push(theirs.clone());
                        changed = true;
                    }
                }
                Err(index) => {
                    self.values.insert(index, theirs.clone());
                    changed = true;
                }
            }
        }
        changed
    }

    /// Drops the values whose dots `ctx` has seen (the join with an absent entry of a complete state).
    pub(crate) fn drop_covered(&mut self, ctx: &CausalContext) -> bool {
        let before = self.values.len();
        self.values.retain(|mine| !ctx.contains(mine.dot));
        self.values.len() != before
    }
}

/// The immutable core of a node: its type and name, written once when the node is inserted.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct NodeCore {
    /// Node type.
    pub node_type: Name,
    /// Node name as inserted (see the crate docs for how concurrent name conflicts are shown).
    pub name: Name,
}

/// Attribute registers by name.
pub type Attrs = BTreeMap<Name, Register<Value>>;

/// A node's entry in a dot store.
#[derive(Clone, Debug, Default, PartialEq, Eq, Hash)]
pub struct NodeEntry {
    /// Type and name; empty until the insert has been seen.
    pub core: Register<NodeCore>,
    /// Attribute registers (an empty register in a delta means "remove the dots my context holds").
    pub attrs: Attrs,
}

/// An edge's entry in a dot store.
#[derive(Clone, Debug, Default, PartialEq, Eq, Hash)]
pub struct EdgeEntry {
    /// Add-wins presence: the dots of the inserts not yet removed.
    pub presence: Register<()>,
    /// Attribute registers.
    pub attrs: Attrs,
}

/// Dot store of a whole graph (or of a delta's part of it).
#[derive(Clone, Debug, Default, PartialEq, Eq, Hash)]
pub struct Store {
    /// Deleted node ids: grow-only, never to be visible again.
    pub tombstones: BTreeSet<NodeId>,
    /// Node entries.
    pub nodes: BTreeMap<NodeId, NodeEntry>,
    /// Edge entries.
    pub edges: BTreeMap<EdgeKey, EdgeEntry>,
}

impl NodeEntry {
    pub(crate) fn is_empty(&self) -> bool {
        self.core.is_empty() && self.attrs.is_empty()
    }

    pub(crate) fn dots(&self) -> impl Iterator<Item = Dot> + '_ {
        self.core.dots().chain(self.attrs.values().flat_map(Register::dots))
    }
}

impl EdgeEntry {
    pub(crate) fn is_empty(&self) -> bool {
        self.presence.is_empty() && self.attrs.is_empty()
    }

    pub(crate) fn dots(&self) -> impl Iterator<Item = Dot> + '_ {
        self.presence.dots().chain(self.attrs.values().flat_map(Register::dots))
    }
}

/// Joins attribute registers; `complete` says `other` lists every register it has (a full state), so registers
/// missing from it are joined with an empty register too.
pub(crate) fn join_attrs(
    mine: &mut Attrs,
    theirs: &Attrs,
    self_ctx: &CausalContext,
    other_ctx: &CausalContext,
    complete: bool,
    plant: Plant,
) {
    for (name, register) in theirs {
        // The common case (the register exists) costs no name clone.
        let emptied = match mine.get_mut(name) {
            Some(slot) => {
                slot.join(register, self_ctx, other_ctx, plant);
                slot.is_empty()
            }
            None => {
                let mut slot = Register::default();
                slot.join(register, self_ctx, other_ctx, plant);
                if !slot.is_empty() {
                    mine.insert(name.clone(), slot);
                }
                false
            }
        };
        if emptied {
            mine.remove(name);
        }
    }
    if complete {
        mine.retain(|name, register| {
            if !theirs.contains_key(name) {
                register.drop_covered(other_ctx);
            }
            !register.is_empty()
        });
    }
}

/// Drops every dot `ctx` covers from attribute registers (the join with an absent entry of a full state).
pub(crate) fn drop_covered_attrs(mine: &mut Attrs, ctx: &CausalContext) {
    mine.retain(|_, register| {
        register.drop_covered(ctx);
        !register.is_empty()
    });
}
