//! The replica: a pure state machine that takes local operations and received deltas and returns deltas to send.
//!
//! Every local operation is validated against the current state, turned into a delta, and joined into the state by
//! the same code that joins remote deltas, so there is one mutation path. The replica never reads a clock: each
//! operation takes `now_ns` as an argument and the replica turns it into a hybrid-logical-clock stamp.

use std::borrow::Cow;
use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::sync::Arc;

use smallvec::SmallVec;

use crate::causal::CausalContext;
use crate::delta::{Delta, DeltaParts, Origin};
use crate::dictionary::{AttrKey, Dictionary};
use crate::error::{DeltaError, DictionaryError, OpError};
use crate::ids::{Dot, EdgeKey, Element, Name, NodeId, ReplicaId, Stamp, valid_node_name};
use crate::mutants::{DsrMutant, Plant};
use crate::store::{Attrs, EdgeEntry, Entry, NodeCore, NodeEntry, Register, Store, drop_covered_attrs, join_attrs};
use crate::value::{AttrType, Value};

/// A node to insert.
#[derive(Clone, Debug)]
pub struct NewNode {
    /// The id to use (ids from CORTEX JSON are kept); `None` mints a fresh one.
    pub id: Option<NodeId>,
    /// Node type.
    pub node_type: String,
    /// Node name, unique among visible nodes.
    pub name: String,
    /// Initial attributes.
    pub attrs: Vec<(String, Value)>,
}

impl NewNode {
    /// A node of `node_type` called `name`, with a minted id and no attributes.
    pub fn new(node_type: &str, name: &str) -> Self {
        NewNode { id: None, node_type: node_type.to_owned(), name: name.to_owned(), attrs: Vec::new() }
    }

    /// Uses a given id.
    pub fn with_id(mut self, id: NodeId) -> Self {
        self.id = Some(id);
        self
    }

    /// Adds an attribute.
    pub fn with_attr(mut self, name: &str, value: impl Into<Value>) -> Self {
        self.attrs.push((name.to_owned(), value.into()));
        self
    }
}

/// A change to the visible graph, reported when change tracking is on ([`Replica::set_change_tracking`]).
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Change {
    /// A node became visible.
    NodeInserted {
        /// The node.
        id: NodeId,
    },
    /// A node stopped being visible (deleted).
    NodeDeleted {
        /// The node.
        id: NodeId,
    },
    /// A visible node's shown name changed: it took its plain name back (the node that held the name was deleted)
    /// or became `name#id` (a concurrent insert of the same name holds it now).
    NodeRenamed {
        /// The node.
        id: NodeId,
    },
    /// An edge became visible.
    EdgeInserted {
        /// The edge.
        key: EdgeKey,
    },
    /// An edge stopped being visible.
    EdgeDeleted {
        /// The edge.
        key: EdgeKey,
    },
    /// An attribute's winning value changed (or the attribute appeared) on a visible element.
    AttrUpdated {
        /// The element.
        element: Element,
        /// The attribute.
        name: Name,
    },
    /// An attribute disappeared from a visible element.
    AttrRemoved {
        /// The element.
        element: Element,
        /// The attribute.
        name: Name,
    },
}

/// A change together with the replica whose operation caused it (`None` for a snapshot).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ChangeEvent {
    /// What changed.
    pub change: Change,
    /// Whose operation made it.
    pub origin: Option<ReplicaId>,
}

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
struct DeltaLog {
    deltas: VecDeque<(Arc<Delta>, usize)>,
    payload_bytes: usize,
    limits: LogLimits,
}

impl DeltaLog {
    fn push(&mut self, delta: Arc<Delta>) {
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

/// The elements a join may change, for change events.
#[derive(Default)]
struct Touched {
    nodes: BTreeSet<NodeId>,
    edges: BTreeSet<EdgeKey>,
    attrs: BTreeSet<(Element, Name)>,
}

/// What is visible of the touched elements (before or after a join), for change events.
struct Visibility {
    /// `None` if invisible, else whether the node shows its plain name (not `name#id`).
    nodes: BTreeMap<NodeId, Option<bool>>,
    edges: BTreeMap<EdgeKey, bool>,
    attrs: BTreeMap<(Element, Name), Option<Dot>>,
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

    // -----------------------------------------------------------------------------------------------------------
    // Local operations.

    /// The shared name of an attribute, registering it (copy-on-write) if it is new and allowed.
    fn intern_attr(&mut self, name: &str, value_type: crate::value::ValueType) -> Result<Name, DictionaryError> {
        match self.dictionary.known_attr(name, value_type)? {
            Some(known) => Ok(known),
            None => Arc::make_mut(&mut self.dictionary).check_attr(name, value_type),
        }
    }

    fn intern_node_type(&mut self, name: &str) -> Result<Name, DictionaryError> {
        match self.dictionary.known_node_type(name) {
            Some(known) => Ok(known),
            None => Arc::make_mut(&mut self.dictionary).check_node_type(name),
        }
    }

    fn intern_edge_type(&mut self, name: &str) -> Result<Name, DictionaryError> {
        match self.dictionary.known_edge_type(name) {
            Some(known) => Ok(known),
            None => Arc::make_mut(&mut self.dictionary).check_edge_type(name),
        }
    }

    fn tick(&mut self, now_ns: u64) -> Stamp {
        if self.plant.is(DsrMutant::StampTiesPhysicalClock) && now_ns >= self.clock.0 {
            self.clock = Stamp(now_ns);
            return self.clock;
        }
        self.clock = Stamp(now_ns.max(self.clock.0.saturating_add(1)));
        self.clock
    }

    fn next_counter(&self) -> u64 {
        self.ctx.max_counter(self.id) + 1
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

    fn element_attrs(&self, element: &Element) -> Result<&Attrs, OpError> {
        match element {
            Element::Node(id) if self.node_visible(*id) => Ok(&self.store.nodes[id].attrs),
            Element::Edge(key) if self.edge_visible(key) => Ok(&self.store.edges[key].attrs),
            _ => Err(OpError::NoSuchElement(element.clone())),
        }
    }

    /// Builds the delta of a local operation from its generated dots and store, then joins it.
    fn commit(&mut self, first: u64, last: u64, mut ctx: CausalContext, store: Store) -> Arc<Delta> {
        for counter in first..=last {
            ctx.insert(Dot::new(self.id, counter));
        }
        let delta = Arc::new(Delta {
            origin: Some(Origin { replica: self.id, first, last }),
            complete: false,
            clock: self.clock,
            ctx,
            applied: CausalContext::default(),
            store,
            plant: self.plant,
        });
        self.join(&delta);
        for dot in delta.origin.iter().flat_map(Origin::dots) {
            self.applied.insert(dot);
        }
        self.log.push(Arc::clone(&delta));
        #[cfg(feature = "check-invariants")]
        self.check_invariants().expect("invariants after a local operation");
        delta
    }

    /// Inserts a node. Returns its id and the delta to send.
    ///
    /// # Errors
    /// [`OpError`] if the id is zero, in use or deleted, the name is invalid or taken, or a type or attribute is
    /// refused by the dictionary. The replica is unchanged.
    ///
    /// # Examples
    /// ```
    /// use dsr::{NewNode, Replica, ReplicaId, attrs};
    /// let mut replica = Replica::new(ReplicaId(1));
    /// let (id, _delta) = replica.insert_node(1_000, NewNode::new("world", "world").with_attr("level", 0)).unwrap();
    /// assert_eq!(replica.node(id).unwrap().get(attrs::LEVEL), Some(0));
    /// ```
    pub fn insert_node(&mut self, now_ns: u64, node: NewNode) -> Result<(NodeId, Arc<Delta>), OpError> {
        self.dictionary.peek_node_type(&node.node_type)?;
        if !valid_node_name(&node.name) {
            return Err(OpError::InvalidNodeName(node.name.chars().take(64).collect()));
        }
        if self.names.get(node.name.as_str()).is_some_and(|holders| !holders.is_empty()) {
            return Err(OpError::NameTaken(node.name));
        }
        for (name, value) in &node.attrs {
            self.dictionary.peek_attr(name, value.value_type())?;
        }
        let id = match node.id {
            Some(NodeId(0)) => return Err(OpError::ZeroId),
            Some(id) if self.id_known(id) => return Err(OpError::IdTaken(id)),
            Some(id) => id,
            None => self.mint_node_id()?,
        };
        // Validation passed: now register any new names.
        let node_type = self.intern_node_type(&node.node_type)?;
        let stamp = self.tick(now_ns);
        let first = self.next_counter();
        let mut counter = first;
        let mut entry = NodeEntry {
            core: Register::single(
                Dot::new(self.id, counter),
                stamp,
                NodeCore { node_type, name: Name::new(&node.name) },
            ),
            attrs: Attrs::new(),
        };
        for (name, value) in node.attrs {
            let name = self.intern_attr(&name, value.value_type())?;
            counter += 1;
            entry.attrs.insert(name, Register::single(Dot::new(self.id, counter), stamp, value));
        }
        if let Some(NodeId(sequence)) = node.id.filter(|id| id.0 >> 32 == u64::from(self.id.0)) {
            self.minted_nodes = self.minted_nodes.max(sequence as u32);
        }
        let mut store = Store::default();
        store.nodes.insert(id, entry);
        let delta = self.commit(first, counter, CausalContext::default(), store);
        Ok((id, delta))
    }

    fn id_known(&self, id: NodeId) -> bool {
        self.store.tombstones.contains(&id) || self.store.nodes.contains_key(&id)
    }

    fn mint_node_id(&mut self) -> Result<NodeId, OpError> {
        loop {
            let sequence = self.minted_nodes.checked_add(1).ok_or(OpError::IdSpaceExhausted)?;
            self.minted_nodes = sequence;
            let id = NodeId::minted(self.id, sequence);
            if !self.id_known(id) {
                return Ok(id);
            }
        }
    }

    /// Deletes a node and, with it, every edge from or to it. The id is never visible again.
    ///
    /// # Errors
    /// [`OpError::NoSuchNode`] if the node is not visible.
    pub fn delete_node(&mut self, now_ns: u64, id: NodeId) -> Result<Arc<Delta>, OpError> {
        if !self.node_visible(id) {
            return Err(OpError::NoSuchNode(id));
        }
        self.tick(now_ns);
        let mut ctx = CausalContext::default();
        for dot in self.store.nodes[&id].dots() {
            ctx.insert(dot);
        }
        for key in self.incident_edges(id) {
            for dot in self.store.edges[&key].dots() {
                ctx.insert(dot);
            }
        }
        let mut store = Store::default();
        store.tombstones.insert(id);
        let counter = self.next_counter();
        Ok(self.commit(counter, counter, ctx, store))
    }

    fn incident_edges(&self, id: NodeId) -> Vec<EdgeKey> {
        let outgoing = self.out_edges.get(&id).into_iter().flatten();
        let incoming = self.in_edges.get(&id).into_iter().flatten();
        let mut keys: Vec<EdgeKey> = outgoing.chain(incoming).cloned().collect();
        keys.sort_unstable();
        keys.dedup();
        keys
    }

    /// Inserts an edge with attributes. Both nodes must be visible and the edge must not exist.
    ///
    /// # Errors
    /// [`OpError`] if an endpoint is missing, the edge exists, or the dictionary refuses a name.
    pub fn insert_edge(
        &mut self,
        now_ns: u64,
        from: NodeId,
        to: NodeId,
        edge_type: &str,
        attrs: Vec<(String, Value)>,
    ) -> Result<(EdgeKey, Arc<Delta>), OpError> {
        for id in [from, to] {
            if !self.node_visible(id) {
                return Err(OpError::NoSuchNode(id));
            }
        }
        self.dictionary.peek_edge_type(edge_type)?;
        for (name, value) in &attrs {
            self.dictionary.peek_attr(name, value.value_type())?;
        }
        let edge_type = self.intern_edge_type(edge_type)?;
        let key = EdgeKey { from, to, edge_type };
        if self.edge_visible(&key) {
            return Err(OpError::EdgeExists(key));
        }
        let stamp = self.tick(now_ns);
        let first = self.next_counter();
        let mut counter = first;
        let mut entry =
            EdgeEntry { presence: Register::single(Dot::new(self.id, first), stamp, ()), attrs: Attrs::new() };
        // Leftovers of an earlier life of this edge (concurrent attribute writes) are cleared: the new edge has
        // exactly the attributes given.
        let mut ctx = CausalContext::default();
        if let Some(old) = self.store.edges.get(&key) {
            if !self.plant.is(DsrMutant::RemoveLosesContext) {
                for dot in old.dots() {
                    ctx.insert(dot);
                }
            }
            for name in old.attrs.keys() {
                entry.attrs.insert(name.clone(), Register::default());
            }
        }
        for (name, value) in attrs {
            let name = self.intern_attr(&name, value.value_type())?;
            counter += 1;
            entry.attrs.insert(name, Register::single(Dot::new(self.id, counter), stamp, value));
        }
        let mut store = Store::default();
        store.edges.insert(key.clone(), entry);
        let delta = self.commit(first, counter, ctx, store);
        Ok((key, delta))
    }

    /// Deletes an edge (add-wins: an insert of the same edge this replica has not seen survives).
    ///
    /// # Errors
    /// [`OpError::NoSuchEdge`] if the edge is not visible.
    pub fn delete_edge(&mut self, now_ns: u64, key: &EdgeKey) -> Result<Arc<Delta>, OpError> {
        if !self.edge_visible(key) {
            return Err(OpError::NoSuchEdge(key.clone()));
        }
        self.tick(now_ns);
        let old = &self.store.edges[key];
        let mut ctx = CausalContext::default();
        if !self.plant.is(DsrMutant::RemoveLosesContext) {
            for dot in old.dots() {
                ctx.insert(dot);
            }
        }
        let entry = EdgeEntry {
            presence: Register::default(),
            attrs: old.attrs.keys().map(|name| (name.clone(), Register::default())).collect(),
        };
        let mut store = Store::default();
        store.edges.insert(key.clone(), entry);
        let counter = self.next_counter();
        Ok(self.commit(counter, counter, ctx, store))
    }

    /// Writes one attribute with a typed key.
    ///
    /// # Errors
    /// As [`Replica::set_attrs`].
    pub fn set_attr<T: AttrType>(
        &mut self,
        now_ns: u64,
        element: impl Into<Element>,
        key: AttrKey<T>,
        value: impl Into<T>,
    ) -> Result<Arc<Delta>, OpError> {
        self.set_attrs(now_ns, element, [(key.name(), value.into().into_value())])
    }

    /// Writes attributes of a visible node or edge, as one delta. Each write supersedes the values this replica
    /// has seen; concurrent writes elsewhere are kept beside it until a later write sees them.
    ///
    /// # Errors
    /// [`OpError::NoSuchElement`] if the element is not visible; a dictionary error for an unknown name or a
    /// wrong type. The replica is unchanged.
    pub fn set_attrs<'n>(
        &mut self,
        now_ns: u64,
        element: impl Into<Element>,
        attrs: impl IntoIterator<Item = (&'n str, Value)>,
    ) -> Result<Arc<Delta>, OpError> {
        let element = element.into();
        let attrs: SmallVec<[(&str, Value); 2]> = attrs.into_iter().collect();
        let existing = self.element_attrs(&element)?;
        for (name, value) in &attrs {
            self.dictionary.peek_attr(name, value.value_type())?;
        }
        let mut ctx = CausalContext::default();
        if !self.plant.is(DsrMutant::RemoveLosesContext) {
            for (name, _) in &attrs {
                if let Some(register) = existing.get(*name) {
                    for dot in register.dots() {
                        ctx.insert(dot);
                    }
                }
            }
        }
        let stamp = self.tick(now_ns);
        let first = self.next_counter();
        let mut counter = first - 1;
        let mut registers = Attrs::new();
        for (name, value) in attrs {
            let name = self.intern_attr(name, value.value_type())?;
            counter += 1;
            registers.insert(name, Register::single(Dot::new(self.id, counter), stamp, value));
        }
        if counter < first {
            // Nothing to write: still a valid (empty) operation, but it needs a dot of its own.
            counter = first;
        }
        let store = element_store(&element, registers);
        Ok(self.commit(first, counter, ctx, store))
    }

    /// Removes an attribute of a visible node or edge (the values this replica has seen; a concurrent write
    /// elsewhere survives).
    ///
    /// # Errors
    /// [`OpError::NoSuchElement`] or [`OpError::NoSuchAttr`].
    pub fn remove_attr(&mut self, now_ns: u64, element: impl Into<Element>, name: &str) -> Result<Arc<Delta>, OpError> {
        let element = element.into();
        let existing = self.element_attrs(&element)?;
        let Some((name, register)) = existing.get_key_value(name) else {
            return Err(OpError::NoSuchAttr { element, name: name.to_owned() });
        };
        let name = name.clone();
        let mut ctx = CausalContext::default();
        if !self.plant.is(DsrMutant::RemoveLosesContext) {
            for dot in register.dots() {
                ctx.insert(dot);
            }
        }
        self.tick(now_ns);
        let mut registers = Attrs::new();
        registers.insert(name, Register::default());
        let store = element_store(&element, registers);
        let counter = self.next_counter();
        Ok(self.commit(counter, counter, ctx, store))
    }

    // -----------------------------------------------------------------------------------------------------------
    // Remote deltas.

    /// Joins a delta or snapshot received from another replica.
    ///
    /// # Errors
    /// [`DeltaError::Dictionary`] if it uses a name or type this replica's dictionary refuses; the replica is then
    /// unchanged. (Structural errors are caught by [`Delta::decode`].)
    pub fn apply(&mut self, delta: &Delta) -> Result<(), DeltaError> {
        if self.can_install(delta) {
            return self.install(delta.clone());
        }
        self.apply_inner(delta, || Arc::new(delta.clone()))
    }

    /// Like [`Replica::apply`], for a delta already shared: it is retained for anti-entropy without a copy (and a
    /// snapshot joined into a fresh replica is moved in without a copy when this is its only holder).
    ///
    /// # Errors
    /// As [`Replica::apply`].
    pub fn apply_shared(&mut self, delta: Arc<Delta>) -> Result<(), DeltaError> {
        if self.can_install(&delta) {
            return self.install(Arc::try_unwrap(delta).unwrap_or_else(|shared| (*shared).clone()));
        }
        self.apply_inner(&delta, || Arc::clone(&delta))
    }

    /// Whether joining `delta` can take the fast path of [`Replica::install`]: a snapshot into a replica that has
    /// never held anything (a late joiner's first graph), with no planted mutant (mutants live in the general
    /// join).
    fn can_install(&self, delta: &Delta) -> bool {
        delta.complete
            && delta.origin.is_none()
            && (self.plant == Plant::NONE || self.plant.is(DsrMutant::InstallDropsTombstones))
            && self.ctx.is_empty()
            && self.applied.is_empty()
            && self.store.nodes.is_empty()
            && self.store.edges.is_empty()
            && self.store.tombstones.is_empty()
            && self.log.deltas.is_empty()
    }

    /// The join of a snapshot into a replica that has never held anything ([`Replica::can_install`]), without the
    /// general join's per-entry work: the snapshot's store is moved in and put in the form the general join would
    /// leave (registers sorted by dot without repeated dots, tombstoned nodes and their edges dropped, empty
    /// entries dropped), the indices are built once, and the change events are the general join's, in its order.
    /// The result is exactly the general join's (a property test in `replica/install_tests.rs` checks state,
    /// indices, digest, applied operations and change events).
    fn install(&mut self, delta: Delta) -> Result<(), DeltaError> {
        debug_assert!(self.can_install(&delta));
        let new = self.new_names(&delta)?;
        names::learn_names(&mut self.dictionary, new);
        let Delta { clock, ctx, applied, store, .. } = delta;
        let Store { mut tombstones, mut nodes, mut edges } = store;
        if self.plant.is(DsrMutant::InstallDropsTombstones) {
            tombstones.clear();
        }
        nodes.retain(|id, node| {
            if tombstones.contains(id) {
                return false;
            }
            normalize_register(&mut node.core);
            normalize_attrs(&mut node.attrs);
            !node.is_empty()
        });
        edges.retain(|key, edge| {
            if tombstones.contains(&key.from) || tombstones.contains(&key.to) {
                return false;
            }
            normalize_register(&mut edge.presence);
            normalize_attrs(&mut edge.attrs);
            !edge.is_empty()
        });
        self.store = Store { tombstones, nodes, edges };
        self.ctx.merge(&ctx);
        self.clock = self.clock.max(clock);
        self.applied.merge(&applied);

        // The indices, built in one go from the sorted store (they were empty, as the replica held nothing). What
        // the general join's `reindex_edges` and `reindex_names` would leave: every edge entry under both of its
        // endpoints, and every visible node under its winning core's name and stamp.
        let node_visible: Vec<bool> = self.store.nodes.keys().map(|id| self.node_visible(*id)).collect();
        let edge_visible: Vec<bool> = self.store.edges.iter().map(|(key, e)| self.edge_entry_visible(key, e)).collect();
        debug_assert!(self.out_edges.is_empty() && self.in_edges.is_empty() && self.names.is_empty());
        self.out_edges = group_sorted(self.store.edges.keys().map(|key| (key.from, key.clone())));
        let mut by_target: Vec<(NodeId, EdgeKey)> = self.store.edges.keys().map(|key| (key.to, key.clone())).collect();
        by_target.sort_unstable();
        self.in_edges = group_sorted(by_target.into_iter());
        let mut named: Vec<(Name, (Stamp, NodeId))> = Vec::with_capacity(self.store.nodes.len());
        let mut indexed: Vec<(NodeId, (Name, Stamp))> = Vec::with_capacity(self.store.nodes.len());
        for ((&id, node), _) in self.store.nodes.iter().zip(&node_visible).filter(|(_, visible)| **visible) {
            let core = node.core.winner_planted(self.plant).expect("a visible node has a core");
            named.push((core.value.name.clone(), (core.stamp, id)));
            indexed.push((id, (core.value.name.clone(), core.stamp)));
        }
        named.sort_unstable();
        self.names = group_sorted(named.into_iter());
        self.indexed_names = indexed.into_iter().collect();

        if let Some(mut queue) = self.changes.take() {
            // Nothing was visible before: every visible node and edge is inserted, then every winning attribute
            // of a visible element is updated, in the general join's order (nodes, edges, then attributes by
            // element and name).
            let nodes = || self.store.nodes.iter().zip(&node_visible).filter(|(_, v)| **v).map(|(node, _)| node);
            let edges = || self.store.edges.iter().zip(&edge_visible).filter(|(_, v)| **v).map(|(edge, _)| edge);
            let count = nodes().map(|(_, node)| 1 + node.attrs.len()).sum::<usize>()
                + edges().map(|(_, edge)| 1 + edge.attrs.len()).sum::<usize>();
            queue.reserve(count);
            let event = |change| ChangeEvent { change, origin: None };
            queue.extend(nodes().map(|(&id, _)| event(Change::NodeInserted { id })));
            queue.extend(edges().map(|(key, _)| event(Change::EdgeInserted { key: key.clone() })));
            for (&id, node) in nodes() {
                queue.extend(
                    node.attrs
                        .keys()
                        .map(|name| event(Change::AttrUpdated { element: Element::Node(id), name: name.clone() })),
                );
            }
            for (key, edge) in edges() {
                queue.extend(edge.attrs.keys().map(|name| {
                    event(Change::AttrUpdated { element: Element::Edge(key.clone()), name: name.clone() })
                }));
            }
            self.changes = Some(queue);
        }
        #[cfg(feature = "check-invariants")]
        self.check_invariants().expect("invariants after installing a snapshot");
        Ok(())
    }

    fn apply_inner(&mut self, delta: &Delta, shared: impl FnOnce() -> Arc<Delta>) -> Result<(), DeltaError> {
        let new = self.new_names(delta)?;
        names::learn_names(&mut self.dictionary, new);
        let duplicate = delta.origin.is_some_and(|o| o.dots().all(|dot| self.applied.contains(dot)));
        self.join(delta);
        for dot in delta.origin.iter().flat_map(Origin::dots) {
            self.applied.insert(dot);
        }
        if delta.complete {
            let sender_applied =
                if self.plant.is(DsrMutant::SnapshotAppliedFromContext) { &delta.ctx } else { &delta.applied };
            self.applied.merge(sender_applied);
        }
        if !duplicate && delta.origin.is_some() && !delta.complete {
            self.log.push(shared());
        }
        #[cfg(feature = "check-invariants")]
        self.check_invariants().expect("invariants after a join");
        Ok(())
    }

    /// The join: the single mutation path for local and remote deltas alike.
    fn join(&mut self, delta: &Delta) {
        let plant = self.plant;
        let origin = delta.origin.map(|o| o.replica);
        // Change tracking looks at everything the delta may change, before and after; without it, only the
        // indices are kept up to date, for exactly the entries whose core or existence changed.
        let watched = self.changes.is_some().then(|| self.touched_by(delta));
        let before = watched.as_ref().map(|touched| self.look(touched));
        let mut names_to_reindex: SmallVec<[NodeId; 2]> = SmallVec::new();
        let mut edges_to_reindex: SmallVec<[EdgeKey; 2]> = SmallVec::new();

        // Tombstones first: a deleted node's entries and incident edges go, and nothing for it is accepted again.
        for &id in &delta.store.tombstones {
            if self.store.tombstones.insert(id) {
                self.store.nodes.remove(&id);
                names_to_reindex.push(id);
                if !plant.is(DsrMutant::DeleteKeepsIncidentEdges) {
                    for key in self.incident_edges(id) {
                        self.store.edges.remove(&key);
                        edges_to_reindex.push(key);
                    }
                }
            }
        }

        for (id, theirs) in &delta.store.nodes {
            if self.store.tombstones.contains(id) {
                continue;
            }
            let mine = self.store.nodes.entry(*id).or_default();
            if mine.core.join(&theirs.core, &self.ctx, &delta.ctx, plant) {
                names_to_reindex.push(*id);
            }
            if !(plant.is(DsrMutant::EarlyAttrDropped) && mine.core.is_empty()) {
                join_attrs(&mut mine.attrs, &theirs.attrs, &self.ctx, &delta.ctx, delta.complete, plant);
            }
            if mine.is_empty() {
                self.store.nodes.remove(id);
            }
        }
        if delta.complete {
            for (id, mine) in self.store.nodes.iter_mut() {
                if !delta.store.nodes.contains_key(id) {
                    if mine.core.drop_covered(&delta.ctx) {
                        names_to_reindex.push(*id);
                    }
                    drop_covered_attrs(&mut mine.attrs, &delta.ctx);
                }
            }
            self.store.nodes.retain(|_, node| !node.is_empty());
        }

        for (key, theirs) in &delta.store.edges {
            let dead_end = self.store.tombstones.contains(&key.from) || self.store.tombstones.contains(&key.to);
            if dead_end && !plant.is(DsrMutant::EdgeToDeletedNodeVisible) {
                continue;
            }
            let existed = self.store.edges.contains_key(key);
            let mine = self.store.edges.entry(key.clone()).or_default();
            mine.presence.join(&theirs.presence, &self.ctx, &delta.ctx, plant);
            join_attrs(&mut mine.attrs, &theirs.attrs, &self.ctx, &delta.ctx, delta.complete, plant);
            let exists = !mine.is_empty();
            if !exists {
                self.store.edges.remove(key);
            }
            if exists != existed {
                edges_to_reindex.push(key.clone());
            }
        }
        if delta.complete {
            for (key, mine) in self.store.edges.iter_mut() {
                if !delta.store.edges.contains_key(key) {
                    mine.presence.drop_covered(&delta.ctx);
                    drop_covered_attrs(&mut mine.attrs, &delta.ctx);
                    if mine.is_empty() {
                        edges_to_reindex.push(key.clone());
                    }
                }
            }
            self.store.edges.retain(|_, edge| !edge.is_empty());
        }

        self.ctx.merge_planted(&delta.ctx, plant);
        if origin != Some(self.id) && !(delta.complete && plant.is(DsrMutant::SnapshotJoinKeepsClock)) {
            // A local operation has already ticked the clock past its own stamp.
            self.clock = self.clock.max(delta.clock);
        }
        self.reindex_edges(&edges_to_reindex);
        self.reindex_names(&names_to_reindex);
        if let (Some(before), Some(watched)) = (before, watched) {
            let after = self.look(&watched);
            self.record_changes(&before, &after, origin);
        }
    }

    /// The elements a delta may change: its own entries, tombstoned nodes and their incident edges, and the
    /// attributes of all of them.
    fn touched_by(&self, delta: &Delta) -> Touched {
        let mut touched = Touched::default();
        touched.nodes.extend(delta.store.nodes.keys().copied());
        touched.nodes.extend(delta.store.tombstones.iter().copied());
        touched.edges.extend(delta.store.edges.keys().cloned());
        if delta.complete {
            touched.nodes.extend(self.store.nodes.keys().copied());
            touched.edges.extend(self.store.edges.keys().cloned());
        }
        // A node that arrives or goes may take a name from, or give it back to, the visible nodes sharing it.
        let names: BTreeSet<&Name> = touched
            .nodes
            .iter()
            .flat_map(|id| {
                let mine = self.store.nodes.get(id).map(|n| n.core.values.iter()).into_iter().flatten();
                let theirs = delta.store.nodes.get(id).map(|n| n.core.values.iter()).into_iter().flatten();
                mine.chain(theirs).map(|core| &core.value.name)
            })
            .collect();
        let sharing: Vec<NodeId> =
            names.into_iter().flat_map(|name| self.names.get(name).into_iter().flatten().map(|(_, id)| *id)).collect();
        touched.nodes.extend(sharing);
        let nodes: Vec<NodeId> = touched.nodes.iter().copied().collect();
        for id in nodes.into_iter().filter(|_| !self.plant.is(DsrMutant::IncidentEdgeEventsMissing)) {
            touched.edges.extend(self.incident_edges(id));
        }
        let mut names = |element: Element, attrs: Option<&Attrs>| {
            for name in attrs.into_iter().flat_map(|a| a.keys()) {
                touched.attrs.insert((element.clone(), name.clone()));
            }
        };
        for id in touched.nodes.clone() {
            names(Element::Node(id), self.store.nodes.get(&id).map(|n| &n.attrs));
            names(Element::Node(id), delta.store.nodes.get(&id).map(|n| &n.attrs));
        }
        for key in touched.edges.clone() {
            names(Element::Edge(key.clone()), self.store.edges.get(&key).map(|e| &e.attrs));
            names(Element::Edge(key.clone()), delta.store.edges.get(&key).map(|e| &e.attrs));
        }
        touched
    }

    fn look(&self, touched: &Touched) -> Visibility {
        let plant = self.plant;
        Visibility {
            nodes: touched.nodes.iter().map(|id| (*id, self.node(*id).map(|node| node.holds_name()))).collect(),
            edges: touched.edges.iter().map(|key| (key.clone(), self.edge_visible(key))).collect(),
            attrs: touched
                .attrs
                .iter()
                .map(|(element, name)| {
                    let visible = match element {
                        Element::Node(id) => self.node_visible(*id),
                        Element::Edge(key) => self.edge_visible(key),
                    };
                    let attrs = match element {
                        Element::Node(id) => self.store.nodes.get(id).map(|n| &n.attrs),
                        Element::Edge(key) => self.store.edges.get(key).map(|e| &e.attrs),
                    };
                    let winner = attrs
                        .filter(|_| visible)
                        .and_then(|a| a.get(name))
                        .and_then(|r| r.winner_planted(plant))
                        .map(|e| e.dot);
                    ((element.clone(), name.clone()), winner)
                })
                .collect(),
        }
    }

    fn record_changes(&mut self, before: &Visibility, after: &Visibility, origin: Option<ReplicaId>) {
        let mut events = Vec::new();
        let mut push = |change| events.push(ChangeEvent { change, origin });
        for (id, was) in &before.nodes {
            match (was, after.nodes[id]) {
                (None, Some(_)) => push(Change::NodeInserted { id: *id }),
                (Some(_), None) => push(Change::NodeDeleted { id: *id }),
                (Some(plain), Some(now)) if *plain != now => push(Change::NodeRenamed { id: *id }),
                _ => {}
            }
        }
        for (key, was) in &before.edges {
            match (was, after.edges[key]) {
                (false, true) => push(Change::EdgeInserted { key: key.clone() }),
                (true, false) => push(Change::EdgeDeleted { key: key.clone() }),
                _ => {}
            }
        }
        for ((element, name), was) in &before.attrs {
            let now = after.attrs[&(element.clone(), name.clone())];
            let change = match (was, now) {
                (_, Some(dot)) if *was != Some(dot) => {
                    Change::AttrUpdated { element: element.clone(), name: name.clone() }
                }
                (Some(_), None) => {
                    let still_visible = match element {
                        Element::Node(id) => after.nodes.get(id).is_some_and(Option::is_some),
                        Element::Edge(key) => after.edges.get(key).copied().unwrap_or(false),
                    };
                    if !still_visible {
                        continue; // the element's deletion says it all
                    }
                    Change::AttrRemoved { element: element.clone(), name: name.clone() }
                }
                _ => continue,
            };
            push(change);
        }
        if let Some(queue) = self.changes.as_mut() {
            queue.extend(events);
        }
    }

    /// Brings the edge indices up to date for edge entries that appeared or went.
    fn reindex_edges(&mut self, keys: &[EdgeKey]) {
        for key in keys {
            if self.store.edges.contains_key(key) {
                self.out_edges.entry(key.from).or_default().insert(key.clone());
                self.in_edges.entry(key.to).or_default().insert(key.clone());
            } else {
                for (index, id) in [(&mut self.out_edges, key.from), (&mut self.in_edges, key.to)] {
                    if let Some(keys) = index.get_mut(&id) {
                        keys.remove(key);
                        if keys.is_empty() {
                            index.remove(&id);
                        }
                    }
                }
            }
        }
    }

    /// Brings the name index up to date for nodes whose core changed or that were deleted.
    fn reindex_names(&mut self, ids: &[NodeId]) {
        for id in ids {
            let stale_kept = self.plant.is(DsrMutant::NameKeptByDeletedHolder)
                && self.store.tombstones.contains(id)
                && self
                    .indexed_names
                    .get(id)
                    .is_some_and(|(name, _)| self.names.get(name).is_some_and(|h| h.len() > 1));
            if let Some((name, stamp)) = self.indexed_names.remove(id)
                && !stale_kept
                && let Some(holders) = self.names.get_mut(&name)
            {
                holders.remove(&(stamp, *id));
                if holders.is_empty() {
                    self.names.remove(&name);
                }
            }
            if !self.node_visible(*id) {
                continue;
            }
            let core = self.store.nodes[id].core.winner_planted(self.plant).expect("a visible node has a core");
            let (name, stamp) = (core.value.name.clone(), core.stamp);
            self.names.entry(name.clone()).or_default().insert((stamp, *id));
            self.indexed_names.insert(*id, (name, stamp));
        }
    }

    // -----------------------------------------------------------------------------------------------------------
    // Anti-entropy and late join.

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
        parts.encode_into(&mut out);
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

    // -----------------------------------------------------------------------------------------------------------
    // Reads.

    /// A visible node.
    pub fn node(&self, id: NodeId) -> Option<NodeRef<'_>> {
        if !self.node_visible(id) {
            return None;
        }
        let entry = &self.store.nodes[&id];
        let core = entry.core.winner_planted(self.plant)?;
        Some(NodeRef { replica: self, id, entry, core })
    }

    /// Which of the visible nodes sharing a name, indexed by (insert stamp, id), holds it: the lowest (a planted
    /// mutant may change the rule).
    fn name_holder(&self, holders: &BTreeSet<(Stamp, NodeId)>) -> Option<NodeId> {
        let holder = if self.plant.is(DsrMutant::NameHeldByLatest) { holders.last() } else { holders.first() };
        holder.map(|(_, id)| *id)
    }

    /// The visible node shown under `name` (see the crate docs for renamed nodes, `name#id`).
    pub fn node_by_name(&self, name: &str) -> Option<NodeRef<'_>> {
        if let Some(holders) = self.names.get(name) {
            return self.name_holder(holders).and_then(|id| self.node(id));
        }
        let (base, id) = name.rsplit_once('#')?;
        let node = self.node(NodeId(id.parse().ok()?))?;
        (node.core.value.name.as_str() == base && node.name() == name).then_some(node)
    }

    /// Every visible node, in id order.
    pub fn nodes(&self) -> impl Iterator<Item = NodeRef<'_>> + '_ {
        self.store.nodes.keys().filter_map(|id| self.node(*id))
    }

    /// Number of visible nodes.
    pub fn node_count(&self) -> usize {
        self.nodes().count()
    }

    /// A visible edge.
    pub fn edge(&self, key: &EdgeKey) -> Option<EdgeRef<'_>> {
        let (key, entry) = self.store.edges.get_key_value(key)?;
        self.edge_entry_visible(key, entry).then_some(EdgeRef { replica: self, key, entry })
    }

    /// Every visible edge, in key order.
    pub fn edges(&self) -> impl Iterator<Item = EdgeRef<'_>> + '_ {
        self.store.edges.iter().filter(|(key, entry)| self.edge_entry_visible(key, entry)).map(|(key, entry)| EdgeRef {
            replica: self,
            key,
            entry,
        })
    }

    /// Number of visible edges.
    pub fn edge_count(&self) -> usize {
        self.edges().count()
    }

    /// Visible edges leaving `id`.
    pub fn out_edges(&self, id: NodeId) -> impl Iterator<Item = EdgeRef<'_>> + '_ {
        self.out_edges.get(&id).into_iter().flatten().filter_map(|key| self.edge(key))
    }

    /// Visible edges entering `id`.
    pub fn in_edges(&self, id: NodeId) -> impl Iterator<Item = EdgeRef<'_>> + '_ {
        self.in_edges.get(&id).into_iter().flatten().filter_map(|key| self.edge(key))
    }

    /// Whether `id` was deleted (it can never be visible again).
    pub fn is_deleted(&self, id: NodeId) -> bool {
        self.store.tombstones.contains(&id)
    }

    /// The visible graph in canonical form (what [`Replica::digest`] hashes).
    pub fn visible_graph(&self) -> VisibleGraph {
        let attrs = |attrs: &Attrs| -> BTreeMap<Name, VisibleAttr> {
            attrs
                .iter()
                .filter_map(|(name, register)| {
                    let winner = register.winner_planted(self.plant)?;
                    let mut concurrent: Vec<(Stamp, ReplicaId, Value)> =
                        register.values.iter().map(|e| (e.stamp, e.dot.replica, e.value.clone())).collect();
                    concurrent.sort_by_key(|(stamp, replica, _)| (*stamp, *replica));
                    Some((name.clone(), VisibleAttr { value: winner.value.clone(), concurrent }))
                })
                .collect()
        };
        VisibleGraph {
            nodes: self
                .nodes()
                .map(|node| {
                    let visible = VisibleNode {
                        node_type: node.core.value.node_type.clone(),
                        name: node.name().into_owned(),
                        attrs: attrs(&node.entry.attrs),
                    };
                    (node.id, visible)
                })
                .collect(),
            edges: self.edges().map(|edge| (edge.key.clone(), attrs(&edge.entry.attrs))).collect(),
        }
    }

    /// A digest of the visible graph: equal on two replicas exactly when their visible graphs are equal (up to
    /// BLAKE3 collisions). Covers every visible node, edge and attribute, including concurrent values.
    pub fn digest(&self) -> Digest {
        self.visible_graph().digest()
    }

    /// Checks the replica's invariants; a failure is a bug. Walks the whole state: for tests and debugging.
    ///
    /// # Errors
    /// A description of the first violated invariant.
    pub fn check_invariants(&self) -> Result<(), String> {
        for edge in self.edges() {
            if !self.node_visible(edge.key.from) || !self.node_visible(edge.key.to) {
                return Err(format!("dangling visible edge {}", edge.key));
            }
        }
        let mut seen = BTreeSet::new();
        for node in self.nodes() {
            if !seen.insert(node.name().into_owned()) {
                return Err(format!("two visible nodes named {:?}", node.name()));
            }
        }
        for id in &self.store.tombstones {
            if self.store.nodes.contains_key(id) {
                return Err(format!("deleted node {id} still has an entry"));
            }
        }
        for (id, node) in &self.store.nodes {
            for dot in node.dots() {
                if !self.ctx.contains(dot) {
                    return Err(format!("node {id}: dot {dot} not in the causal context"));
                }
            }
        }
        for (key, edge) in &self.store.edges {
            for dot in edge.dots() {
                if !self.ctx.contains(dot) {
                    return Err(format!("edge {key}: dot {dot} not in the causal context"));
                }
            }
            if !self.out_edges.get(&key.from).is_some_and(|keys| keys.contains(key)) {
                return Err(format!("edge {key} missing from the out-edge index"));
            }
        }
        let visible: BTreeSet<NodeId> = self.nodes().map(|n| n.id).collect();
        let indexed: BTreeSet<NodeId> = self.indexed_names.keys().copied().collect();
        if visible != indexed {
            return Err("name index out of step with visible nodes".into());
        }
        Ok(())
    }
}

/// Puts a register in the form the general join leaves when it joins the register into an empty one: sorted by
/// dot, the first of repeated dots kept.
fn normalize_register<T>(register: &mut Register<T>) {
    if register.values.windows(2).all(|pair| pair[0].dot < pair[1].dot) {
        return;
    }
    register.values.sort_by_key(|entry| entry.dot);
    register.values.dedup_by_key(|entry| entry.dot);
}

/// [`normalize_register`] for every register; empty registers go (the general join never inserts one).
fn normalize_attrs(attrs: &mut Attrs) {
    attrs.retain(|_, register| {
        normalize_register(register);
        !register.is_empty()
    });
}

/// A map of sets from `(key, item)` pairs sorted by key then item, each built in one go.
fn group_sorted<K: Ord, T: Ord>(pairs: impl Iterator<Item = (K, T)>) -> BTreeMap<K, BTreeSet<T>> {
    let mut groups: Vec<(K, Vec<T>)> = Vec::new();
    for (key, item) in pairs {
        match groups.last_mut() {
            Some((last, items)) if *last == key => items.push(item),
            _ => groups.push((key, vec![item])),
        }
    }
    groups.into_iter().map(|(key, items)| (key, items.into_iter().collect())).collect()
}

fn element_store(element: &Element, registers: Attrs) -> Store {
    let mut store = Store::default();
    match element {
        Element::Node(id) => {
            store.nodes.insert(*id, NodeEntry { core: Register::default(), attrs: registers });
        }
        Element::Edge(key) => {
            store.edges.insert(key.clone(), EdgeEntry { presence: Register::default(), attrs: registers });
        }
    }
    store
}

impl From<NodeId> for Element {
    fn from(id: NodeId) -> Self {
        Element::Node(id)
    }
}

impl From<EdgeKey> for Element {
    fn from(key: EdgeKey) -> Self {
        Element::Edge(key)
    }
}

impl From<&EdgeKey> for Element {
    fn from(key: &EdgeKey) -> Self {
        Element::Edge(key.clone())
    }
}

/// A visible attribute: the winning value and every concurrent value with its stamp and writer.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct VisibleAttr {
    /// The winner (highest stamp, then replica id).
    pub value: Value,
    /// All concurrent values, sorted by stamp then replica.
    pub concurrent: Vec<(Stamp, ReplicaId, Value)>,
}

/// A visible node in canonical form.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct VisibleNode {
    /// Node type.
    pub node_type: Name,
    /// Visible name (`name#id` for the loser of a concurrent name conflict).
    pub name: String,
    /// Attributes.
    pub attrs: BTreeMap<Name, VisibleAttr>,
}

/// The visible graph in canonical form: sorted, with derived data only.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct VisibleGraph {
    /// Visible nodes by id.
    pub nodes: BTreeMap<NodeId, VisibleNode>,
    /// Visible edges with their attributes.
    pub edges: BTreeMap<EdgeKey, BTreeMap<Name, VisibleAttr>>,
}

/// A 256-bit digest of a visible graph.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Digest(pub [u8; 32]);

impl std::fmt::Display for Digest {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        for byte in &self.0[..8] {
            write!(f, "{byte:02x}")?;
        }
        Ok(())
    }
}

impl VisibleGraph {
    /// The BLAKE3 digest of the canonical form.
    pub fn digest(&self) -> Digest {
        let mut hasher = blake3::Hasher::new();
        let text = |hasher: &mut blake3::Hasher, text: &str| {
            hasher.update(&(text.len() as u64).to_le_bytes());
            hasher.update(text.as_bytes());
        };
        let attrs = |hasher: &mut blake3::Hasher, attrs: &BTreeMap<Name, VisibleAttr>| {
            hasher.update(&(attrs.len() as u64).to_le_bytes());
            for (name, attr) in attrs {
                text(hasher, name);
                attr.value.hash_into(hasher);
                hasher.update(&(attr.concurrent.len() as u64).to_le_bytes());
                for (stamp, replica, value) in &attr.concurrent {
                    hasher.update(&stamp.0.to_le_bytes());
                    hasher.update(&replica.0.to_le_bytes());
                    value.hash_into(hasher);
                }
            }
        };
        hasher.update(&(self.nodes.len() as u64).to_le_bytes());
        for (id, node) in &self.nodes {
            hasher.update(&id.0.to_le_bytes());
            text(&mut hasher, &node.node_type);
            text(&mut hasher, &node.name);
            attrs(&mut hasher, &node.attrs);
        }
        hasher.update(&(self.edges.len() as u64).to_le_bytes());
        for (key, edge_attrs) in &self.edges {
            hasher.update(&key.from.0.to_le_bytes());
            hasher.update(&key.to.0.to_le_bytes());
            text(&mut hasher, &key.edge_type);
            attrs(&mut hasher, edge_attrs);
        }
        Digest(*hasher.finalize().as_bytes())
    }
}

/// A read-only view of a visible node.
#[derive(Clone, Copy)]
pub struct NodeRef<'a> {
    replica: &'a Replica,
    id: NodeId,
    entry: &'a NodeEntry,
    core: &'a Entry<NodeCore>,
}

impl<'a> NodeRef<'a> {
    /// The node's id.
    pub fn id(&self) -> NodeId {
        self.id
    }

    /// The node's type.
    pub fn node_type(&self) -> &'a str {
        &self.core.value.node_type
    }

    /// The name the node is shown under: its inserted name, or `name#id` if another visible node inserted
    /// concurrently with the same name holds it (the earliest stamp, then the lowest id, keeps the plain name).
    pub fn name(&self) -> Cow<'a, str> {
        let name = &self.core.value.name;
        if self.holds_name() { Cow::Borrowed(name.as_str()) } else { Cow::Owned(format!("{name}#{}", self.id)) }
    }

    /// Whether the node is shown under its plain inserted name (not `name#id`).
    pub fn holds_name(&self) -> bool {
        let holders = self.replica.names.get(&self.core.value.name);
        holders.and_then(|holders| self.replica.name_holder(holders)) == Some(self.id)
    }

    /// The name as inserted.
    pub fn inserted_name(&self) -> &'a str {
        &self.core.value.name
    }

    /// The stamp of the node's insertion.
    pub fn inserted_at(&self) -> Stamp {
        self.core.stamp
    }

    /// The node's attributes.
    pub fn attributes(&self) -> Attributes<'a> {
        Attributes { attrs: &self.entry.attrs, plant: self.replica.plant }
    }

    /// The winning value of an attribute.
    pub fn attr(&self, name: &str) -> Option<&'a Value> {
        self.attributes().attr(name)
    }

    /// The winning value of an attribute with its stamp and writer.
    pub fn attr_entry(&self, name: &str) -> Option<&'a Entry<Value>> {
        self.attributes().attr_entry(name)
    }

    /// Every concurrent value of an attribute (empty if absent).
    pub fn concurrent(&self, name: &str) -> &'a [Entry<Value>] {
        self.attributes().concurrent(name)
    }

    /// A typed attribute value (`None` if absent or of another type).
    pub fn get<T: AttrType>(&self, key: AttrKey<T>) -> Option<T> {
        self.attributes().get(key)
    }

    /// Every attribute with its winning value, in name order.
    pub fn attrs(&self) -> impl Iterator<Item = (&'a Name, &'a Value)> + 'a {
        self.attributes().winners()
    }
}

impl std::fmt::Debug for NodeRef<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Node")
            .field("id", &self.id)
            .field("type", &self.node_type())
            .field("name", &self.name())
            .finish()
    }
}

/// A read-only view of a visible edge.
#[derive(Clone, Copy)]
pub struct EdgeRef<'a> {
    replica: &'a Replica,
    key: &'a EdgeKey,
    entry: &'a EdgeEntry,
}

impl<'a> EdgeRef<'a> {
    /// The edge's key.
    pub fn key(&self) -> &'a EdgeKey {
        self.key
    }

    /// Source node.
    pub fn from(&self) -> NodeId {
        self.key.from
    }

    /// Destination node.
    pub fn to(&self) -> NodeId {
        self.key.to
    }

    /// Edge type.
    pub fn edge_type(&self) -> &'a str {
        &self.key.edge_type
    }

    /// The edge's attributes.
    pub fn attributes(&self) -> Attributes<'a> {
        Attributes { attrs: &self.entry.attrs, plant: self.replica.plant }
    }

    /// The winning value of an attribute.
    pub fn attr(&self, name: &str) -> Option<&'a Value> {
        self.attributes().attr(name)
    }

    /// The winning value of an attribute with its stamp and writer.
    pub fn attr_entry(&self, name: &str) -> Option<&'a Entry<Value>> {
        self.attributes().attr_entry(name)
    }

    /// Every concurrent value of an attribute (empty if absent).
    pub fn concurrent(&self, name: &str) -> &'a [Entry<Value>] {
        self.attributes().concurrent(name)
    }

    /// A typed attribute value (`None` if absent or of another type).
    pub fn get<T: AttrType>(&self, key: AttrKey<T>) -> Option<T> {
        self.attributes().get(key)
    }

    /// Every attribute with its winning value, in name order.
    pub fn attrs(&self) -> impl Iterator<Item = (&'a Name, &'a Value)> + 'a {
        self.attributes().winners()
    }
}

impl std::fmt::Debug for EdgeRef<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Edge({})", self.key)
    }
}

/// A read-only view of one element's attributes (what [`NodeRef`] and [`EdgeRef`] share).
#[derive(Clone, Copy)]
pub struct Attributes<'a> {
    attrs: &'a Attrs,
    plant: Plant,
}

impl<'a> Attributes<'a> {
    /// The winning value of an attribute.
    pub fn attr(&self, name: &str) -> Option<&'a Value> {
        self.attr_entry(name).map(|entry| &entry.value)
    }

    /// The winning value of an attribute with its stamp and writer.
    pub fn attr_entry(&self, name: &str) -> Option<&'a Entry<Value>> {
        self.attrs.get(name)?.winner_planted(self.plant)
    }

    /// Every concurrent value of an attribute (empty if absent).
    pub fn concurrent(&self, name: &str) -> &'a [Entry<Value>] {
        self.attrs.get(name).map_or(&[], |register| register.entries())
    }

    /// A typed attribute value (`None` if absent or of another type).
    pub fn get<T: AttrType>(&self, key: AttrKey<T>) -> Option<T> {
        self.attr(key.name()).and_then(T::from_value)
    }

    /// Every attribute with its winning value, in name order.
    pub fn winners(self) -> impl Iterator<Item = (&'a Name, &'a Value)> + 'a {
        let plant = self.plant;
        self.attrs.iter().filter_map(move |(name, register)| Some((name, &register.winner_planted(plant)?.value)))
    }

    /// Number of attributes.
    pub fn len(&self) -> usize {
        self.attrs.len()
    }

    /// Whether there is no attribute.
    pub fn is_empty(&self) -> bool {
        self.attrs.is_empty()
    }
}

mod names;

#[cfg(test)]
mod install_tests;
