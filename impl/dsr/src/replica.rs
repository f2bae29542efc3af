//! The replica: a pure state machine that takes local operations and received deltas and returns deltas to send.
//!
//! Every local operation is validated against the current state, turned into a delta, and joined into the state by
//! the same code that joins remote deltas, so there is one mutation path. The replica never reads a clock: each
//! operation takes `now_ns` as an argument and the replica turns it into a hybrid-logical-clock stamp.

mod changes;
mod digest;
mod history;
mod invariants;
mod join;
mod names;
mod operations;
mod reads;
mod views;

use std::collections::{BTreeMap, BTreeSet};
use std::sync::Arc;

use crate::causal::CausalContext;
use crate::dictionary::Dictionary;
use crate::ids::{EdgeKey, Name, NodeId, ReplicaId, Stamp};
use crate::mutants::{DsrMutant, Plant};
use crate::store::{EdgeEntry, Store};

pub use changes::{Change, ChangeEvent};
pub use digest::{Digest, VisibleAttr, VisibleGraph, VisibleNode};
use history::DeltaLog;
pub use history::{LogLimits, Missing};
pub use operations::NewNode;
pub use views::{Attributes, EdgeRef, NodeRef};

/// One replica of the DSR_d graph. See the crate documentation for the semantics it implements.
#[derive(Clone, Debug)]
pub struct Replica {
    id: ReplicaId,
    /// Shared copy-on-write: replicas are cloned often (the model checker clones one per state) and the dictionary
    /// changes only when an unknown name is registered.
    dictionary: Arc<Dictionary>,
    ctx: CausalContext,
    /// The operations whose deltas this replica has joined (their generated dots), and everything a joined
    /// snapshot's sender had joined. Anti-entropy compares these, not causal contexts: a delta's context also holds
    /// the dots it removed, so a context can cover an operation whose own delta (and what it removed) never came.
    applied: CausalContext,
    store: Store,
    clock: Stamp,
    minted_nodes: u32,
    out_edges: BTreeMap<NodeId, BTreeSet<EdgeKey>>,
    in_edges: BTreeMap<NodeId, BTreeSet<EdgeKey>>,
    names: BTreeMap<Name, BTreeSet<(Stamp, NodeId)>>,
    indexed_names: BTreeMap<NodeId, (Name, Stamp)>,
    log: DeltaLog,
    changes: Option<Vec<ChangeEvent>>,
    plant: Plant,
}

impl PartialEq for Replica {
    /// Replicas are equal when their replicated state, clock, minting counter and history are; the dictionary and
    /// the derived indices are not compared (indices follow from the state).
    fn eq(&self, other: &Replica) -> bool {
        self.id == other.id
            && self.ctx == other.ctx
            && self.applied == other.applied
            && self.store == other.store
            && self.clock == other.clock
            && self.minted_nodes == other.minted_nodes
            && self.log == other.log
            && self.plant == other.plant
    }
}

impl Eq for Replica {}

impl std::hash::Hash for Replica {
    fn hash<H: std::hash::Hasher>(&self, state: &mut H) {
        self.id.hash(state);
        self.ctx.hash(state);
        self.applied.hash(state);
        self.store.hash(state);
        self.clock.hash(state);
        self.minted_nodes.hash(state);
        self.log.hash(state);
    }
}

impl Replica {
    /// An empty replica with the built-in dictionary.
    ///
    /// # Panics
    /// If `id` is zero (replica id zero is reserved).
    pub fn new(id: ReplicaId) -> Self {
        Replica::with_dictionary(id, Dictionary::builtin())
    }

    /// An empty replica with the given dictionary.
    ///
    /// # Panics
    /// If `id` is zero (replica id zero is reserved).
    pub fn with_dictionary(id: ReplicaId, dictionary: Dictionary) -> Self {
        assert!(id.0 != 0, "replica id 0 is reserved");
        Replica {
            id,
            dictionary: Arc::new(dictionary),
            ctx: CausalContext::default(),
            applied: CausalContext::default(),
            store: Store::default(),
            clock: Stamp(0),
            minted_nodes: 0,
            out_edges: BTreeMap::new(),
            in_edges: BTreeMap::new(),
            names: BTreeMap::new(),
            indexed_names: BTreeMap::new(),
            log: DeltaLog::default(),
            changes: None,
            plant: Plant::NONE,
        }
    }

    /// Sets the limits of the history kept for anti-entropy.
    pub fn set_log_limits(&mut self, limits: LogLimits) {
        self.log.limits = limits;
    }

    /// Plants a known bug (test-only; see [`crate::mutants`]).
    #[cfg(feature = "mutants")]
    pub fn plant_mutant(&mut self, mutant: Option<DsrMutant>) {
        self.plant = Plant::of(mutant);
    }

    /// This replica's id.
    pub fn id(&self) -> ReplicaId {
        self.id
    }

    /// The dictionary (to declare names).
    pub fn dictionary_mut(&mut self) -> &mut Dictionary {
        Arc::make_mut(&mut self.dictionary)
    }

    /// The dictionary.
    pub fn dictionary(&self) -> &Dictionary {
        &self.dictionary
    }

    /// The causal context: every dot this replica has seen, as added or as removed.
    pub fn context(&self) -> &CausalContext {
        &self.ctx
    }

    /// The operations whose deltas this replica has joined (their generated dots): what anti-entropy exchanges
    /// ([`Replica::missing_for`]). Usually a plain version vector.
    pub fn applied(&self) -> &CausalContext {
        &self.applied
    }

    /// The last hybrid-logical-clock stamp this replica produced or saw.
    pub fn clock(&self) -> Stamp {
        self.clock
    }

    /// The dot store (for inspection and tests).
    pub fn store(&self) -> &Store {
        &self.store
    }

    /// Turns change tracking on or off; while on, every change to the visible graph is queued for
    /// [`Replica::drain_changes`].
    pub fn set_change_tracking(&mut self, on: bool) {
        self.changes = if on { Some(self.changes.take().unwrap_or_default()) } else { None };
    }

    /// Takes the queued changes.
    pub fn drain_changes(&mut self) -> Vec<ChangeEvent> {
        self.changes.as_mut().map(std::mem::take).unwrap_or_default()
    }

    fn node_visible(&self, id: NodeId) -> bool {
        !self.store.tombstones.contains(&id) && self.store.nodes.get(&id).is_some_and(|n| !n.core.is_empty())
    }

    fn edge_visible(&self, key: &EdgeKey) -> bool {
        self.store.edges.get(key).is_some_and(|e| self.edge_entry_visible(key, e))
    }

    fn edge_entry_visible(&self, key: &EdgeKey, entry: &EdgeEntry) -> bool {
        if entry.presence.is_empty() {
            return false;
        }
        if self.plant.is(DsrMutant::DeleteKeepsIncidentEdges) || self.plant.is(DsrMutant::EdgeToDeletedNodeVisible) {
            return true;
        }
        self.node_visible(key.from) && self.node_visible(key.to)
    }

    fn incident_edges(&self, id: NodeId) -> Vec<EdgeKey> {
        let outgoing = self.out_edges.get(&id).into_iter().flatten();
        let incoming = self.in_edges.get(&id).into_iter().flatten();
        let mut keys: Vec<EdgeKey> = outgoing.chain(incoming).cloned().collect();
        keys.sort_unstable();
        keys.dedup();
        keys
    }
}

#[cfg(test)]
mod changes_tests;
#[cfg(test)]
mod install_tests;
