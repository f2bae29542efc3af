//! Local operations: insert and delete nodes and edges, set and remove attributes. Each is validated against the
//! current state, turned into a delta stamped with the replica's hybrid logical clock, and joined by the same code
//! that joins remote deltas ([`Replica::apply`]), so there is one mutation path.

use std::sync::Arc;

use smallvec::SmallVec;

use super::Replica;
use crate::causal::CausalContext;
use crate::delta::{Delta, Origin};
use crate::dictionary::AttrKey;
use crate::error::{DictionaryError, OpError};
use crate::ids::{Dot, EdgeKey, Element, Name, NodeId, Stamp, valid_node_name};
use crate::mutants::DsrMutant;
use crate::store::{Attrs, EdgeEntry, NodeCore, NodeEntry, Register, Store};
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

impl Replica {
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
