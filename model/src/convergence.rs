//! The CRDT convergence model: N replicas holding real [`dsr::Replica`] values exchange real encoded deltas over
//! Stateright's networks, while the checker chooses every replica's operations, clock advances and anti-entropy.
//!
//! All replicas start from the same seed graph (nodes `x` and `y`, an edge `x -[in]-> y`, `level` attributes). The
//! checker picks operations from a menu that reaches every conflict and the whole operation set: insert a node `n`
//! with an attribute (two dots; every replica uses the same name, so concurrent inserts conflict and one shows as
//! `n#id`), delete `x` or any inserted node (the delete removes incident edges), insert and delete `in` edges
//! between the seed nodes and between two inserted nodes, insert an `RT` edge from `x` to an inserted node with its
//! translation and rotation (three dots), move it (write its translation) and delete it, write and remove `level`
//! on seed and inserted elements.
//! `--ops K` is the total operation budget shared by all replicas (the checker decides who spends it). With
//! `--ticks T` (default 1) the checker may also advance a replica's physical clock (by [`TICK_NS`]) just before one
//! of its operations, so clocks skew between replicas and hybrid-logical-clock stamps, not only counters, decide the
//! winners (an advance changes nothing until the replica's next operation reads the clock, so the model takes the
//! two as one step: the states "advanced, not yet operated" would differ from others only in an unread clock); with
//! `--syncs S` a replica may
//! announce its applied operations to a peer, which answers with the deltas it lacks or, when its small history
//! (`--history`) does not reach back far enough, a snapshot.
//!
//! Bytes on the wire: every delta and snapshot travels encoded ([`Delta::encode`], [`Replica::encode_snapshot`])
//! and is decoded ([`Delta::decode`]) on delivery. A duplicating network also carries a truncated copy of every
//! delta, which must be refused with the replica unchanged.
//!
//! Networks: unordered duplicating (every message may be delivered any number of times), unordered
//! non-duplicating, and lossy (non-duplicating, and any message may be dropped). With loss, convergence is the job
//! of anti-entropy: the quiescent-state properties first run reliable rounds of the replicas' own anti-entropy
//! (`Replica::missing_for` and joins) and then require convergence.
//!
//! Properties on every state: the replica invariants; strong eventual consistency (replicas that applied the same
//! operations show equal graphs and digests); each replica's state (store, causal context, applied operations,
//! clock) and visible graph equal those of a fresh replica that joins the deltas of the operations it applied, in
//! two orders, and that graph equals the reference specification's ([`crate::spec`]) for those operations; a fresh
//! replica that installs a replica's snapshot equals it (the late join); every change event stream turns the
//! previous visible graph into the current one; replicas that applied the same operations compute the same
//! transforms ([`dsr::kinematics`]) between every two nodes, and each `RT` edge's transform is its shown translation
//! and rotation; stamps follow causality; no delta is refused and no damaged one is accepted. The fresh replicas and the specification are computed once per set of deltas (a cache), since many
//! states share one.
//!
//! Symmetry reduction does not apply: replica ids break ties between concurrent writes and name conflicts, so no
//! permutation of replicas other than the identity preserves the behaviours.

use std::borrow::Cow;
use std::collections::BTreeSet;
use std::hash::{Hash, Hasher};
use std::sync::Arc;

use bytes::Bytes;
use dsr::{
    CausalContext, Delta, EdgeKey, Element, Missing, Name, NewNode, NodeId, OpError, Replica, ReplicaId, Value,
    VisibleGraph, attrs,
};
use serde::Serialize;
use stateright::actor::{Actor, ActorModel, ActorModelAction, ActorModelState, Id, LossyNetwork, Network, Out};
use stateright::{Model, Property};

use crate::report::{CheckOptions, CheckReport, run_check};
use crate::spec::{OpId, OpKind, OpRecord};

mod events;
pub mod properties;

use events::check_change_events;
use properties::{
    Setup, change_events_complete, conflicts_happen, damaged_refused, equal_to_fresh_join, invariants_hold,
    kinematics_agree, late_joiner_equals, matches_spec_everywhere, no_delta_refused, quiescent_end_reached,
    quiescent_replicas_converge, quiescent_replicas_match_spec, rt_moved, same_ops_same_graph, snapshot_answered,
    stamps_follow_causality,
};

/// How the network treats messages.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum NetworkKind {
    /// Unordered; every message may be delivered any number of times (and every delta has a truncated copy).
    UnorderedDuplicating,
    /// Unordered; every message is delivered at most once.
    UnorderedNonduplicating,
    /// Unordered, at most once, and any message may be lost; anti-entropy recovers.
    Lossy,
}

impl std::str::FromStr for NetworkKind {
    type Err = String;
    fn from_str(text: &str) -> Result<Self, String> {
        match text {
            "unordered-duplicating" => Ok(NetworkKind::UnorderedDuplicating),
            "unordered-nonduplicating" => Ok(NetworkKind::UnorderedNonduplicating),
            "lossy" => Ok(NetworkKind::Lossy),
            other => Err(format!(
                "unknown network {other:?} (expected unordered-duplicating, unordered-nonduplicating or lossy)"
            )),
        }
    }
}

/// Configuration of the convergence model.
#[derive(Clone, Debug, PartialEq, Eq, Hash, Serialize)]
pub struct ConvergenceConfig {
    /// Number of replicas.
    pub replicas: usize,
    /// Total operation budget, shared by all replicas.
    pub ops: usize,
    /// Clock advances of [`TICK_NS`], shared by all replicas, each taken just before one of the replica's
    /// operations.
    pub ticks: usize,
    /// Anti-entropy announces (a replica's applied operations to one peer), shared by all replicas.
    pub syncs: usize,
    /// Deltas each replica keeps for anti-entropy (when there is loss or there are announces); a gap wider than
    /// this is answered with a snapshot.
    pub history: usize,
    /// Writes of at least this many attribute payload bytes fold the retained ones they overwrite
    /// ([`dsr::LogLimits::fold_min_payload_bytes`]). 0, the default, folds every write; 8 folds the RT edge's
    /// writes (12 and 24 B) and keeps the `level` writes (4 B) apart, as the replica's default of 1 KiB does with
    /// frames and poses.
    pub fold_min_payload_bytes: usize,
    /// The network.
    pub network: NetworkKind,
    /// A planted bug (with the `mutants` feature).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mutant: Option<String>,
    /// The planted bug itself (set with [`ConvergenceConfig::with_mutant`]).
    #[serde(skip)]
    #[cfg(feature = "mutants")]
    pub planted: Option<dsr::DsrMutant>,
}

impl Default for ConvergenceConfig {
    fn default() -> Self {
        ConvergenceConfig {
            replicas: 3,
            ops: 3,
            ticks: 1,
            syncs: 0,
            history: 1,
            fold_min_payload_bytes: 0,
            network: NetworkKind::UnorderedNonduplicating,
            mutant: None,
            #[cfg(feature = "mutants")]
            planted: None,
        }
    }
}

impl ConvergenceConfig {
    /// The same configuration with a planted mutant.
    #[cfg(feature = "mutants")]
    pub fn with_mutant(mut self, mutant: dsr::DsrMutant) -> Self {
        self.mutant = Some(format!("{mutant:?}"));
        self.planted = Some(mutant);
        self
    }

    /// Whether replicas keep a history for anti-entropy.
    fn keeps_history(&self) -> bool {
        self.network == NetworkKind::Lossy || self.syncs > 0
    }
}

/// How far one clock advance moves a replica's physical clock, ns (far past every stamp a few counters reach).
pub const TICK_NS: u64 = 100;
/// Replica id of the seed graph's author (not one of the modelled replicas).
const SEED_REPLICA: ReplicaId = ReplicaId(1000);
/// Name of the nodes the replicas may insert (the same for all, so concurrent inserts conflict).
const NEW_NODE_NAME: &str = "n";
/// Type of the edges between plain nodes.
const IN: &str = "in";
/// Type of the transform edges.
const RT: &str = "RT";
/// The key of the replicas' choices in Stateright's actions (it only names them).
const CHOICE_KEY: &str = "choice";

/// The seed graph every replica starts from, with the operations that built it.
#[derive(Clone, Debug)]
pub struct Seed {
    /// The seed graph as a snapshot.
    pub snapshot: Arc<Delta>,
    /// The operations that built it (issued by the seed replica, seen by everyone).
    pub ops: Vec<Arc<OpRecord>>,
    /// Node `x`.
    pub x: NodeId,
    /// Node `y`.
    pub y: NodeId,
}

impl Seed {
    fn build() -> Seed {
        let mut replica = Replica::new(SEED_REPLICA);
        let mut ops = Vec::new();
        let record = |replica: &Replica, delta: &Delta, kind: OpKind, ops: &mut Vec<Arc<OpRecord>>| {
            let origin = delta.origin().expect("local deltas have an origin");
            let past = ops.iter().map(|op: &Arc<OpRecord>| op.id).collect();
            ops.push(Arc::new(OpRecord {
                id: dsr::Dot::new(origin.replica, origin.first),
                replica: origin.replica,
                stamp: replica.clock(),
                past,
                kind,
            }));
        };
        let level = |v: i32| vec![(Name::new("level"), Value::I32(v))];
        let node = |replica: &mut Replica, name: &str, ops: &mut Vec<Arc<OpRecord>>| {
            let (id, delta) = replica.insert_node(0, NewNode::new("object", name).with_attr("level", 0)).unwrap();
            let kind =
                OpKind::InsertNode { id, node_type: Name::new("object"), name: Name::new(name), attrs: level(0) };
            record(replica, &delta, kind, ops);
            id
        };
        let x = node(&mut replica, "x", &mut ops);
        let y = node(&mut replica, "y", &mut ops);
        let (key, delta) = replica.insert_edge(0, x, y, IN, vec![("level".into(), Value::I32(0))]).unwrap();
        record(&replica, &delta, OpKind::InsertEdge { key, attrs: level(0) }, &mut ops);
        Seed { snapshot: Arc::new(replica.snapshot()), ops, x, y }
    }
}

/// An operation the checker may choose for a replica.
#[derive(Clone, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum OpChoice {
    /// Insert a node named `n` with a `level` attribute (two dots).
    InsertNode,
    /// Delete a node (and, with it, its incident edges).
    DeleteNode(NodeId),
    /// Insert an edge `from -[in]-> to`.
    InsertEdge(NodeId, NodeId),
    /// Insert an edge `from -[RT]-> to` with a translation and a rotation (three dots).
    InsertRt(NodeId, NodeId),
    /// Delete an edge.
    DeleteEdge(EdgeKey),
    /// Move the child of an `RT` edge: write the edge's translation (a value of this replica's own).
    MoveRt(EdgeKey),
    /// Write the `level` attribute of a node or edge.
    SetLevel(Element),
    /// Remove the `level` attribute of a node or edge.
    RemoveLevel(Element),
}

/// What the checker may choose for a replica.
#[derive(Clone, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Choice {
    /// A local operation at the replica's current physical clock.
    Op(OpChoice),
    /// Advance the replica's physical clock by [`TICK_NS`], then perform the operation. A clock advance changes
    /// nothing but the stamps of the replica's later operations (a join reads no clock), so the model takes it
    /// only together with the operation it precedes: a separate advance action would add the states "advanced,
    /// next operation not yet made", each equal to a state already there but for the unread clock.
    AdvanceThenOp(OpChoice),
    /// Announce the replica's applied operations to the peer with this index.
    Announce(usize),
}

/// A message on the wire. Deltas and snapshots travel as their encoded bytes; the operation ids beside them are
/// the model's bookkeeping (which operations a replica has applied), never read by a replica.
#[derive(Clone, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Msg {
    /// The delta of one operation (first sent, or re-sent by anti-entropy), with any earlier operations whose
    /// values it overwrote folded in (anti-entropy only: see [`Replica::missing_for`]).
    Delta {
        /// The operation.
        op: OpId,
        /// The operations folded in.
        folded: Vec<OpId>,
        /// [`Delta::encode`]'s bytes.
        bytes: Bytes,
    },
    /// A truncated copy of a delta (duplicating network only): must be refused.
    Damaged {
        /// The operation of the intact delta.
        op: OpId,
        /// A strict prefix of its bytes.
        bytes: Bytes,
    },
    /// Anti-entropy: the sender's applied operations.
    Announce {
        /// [`Replica::applied`] of the sender, as its dots.
        applied: Vec<dsr::Dot>,
        /// The operations the sender had applied.
        seen: BTreeSet<OpId>,
    },
    /// Anti-entropy: the answerer's whole state.
    Snapshot {
        /// The operations the answerer had applied.
        seen: BTreeSet<OpId>,
        /// [`Replica::encode_snapshot`]'s bytes.
        bytes: Bytes,
    },
}

impl std::fmt::Debug for Msg {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Msg::Delta { op, folded, bytes } if folded.is_empty() => {
                write!(f, "delta of op {op} ({} bytes)", bytes.len())
            }
            Msg::Delta { op, folded, bytes } => {
                let folded: Vec<String> = folded.iter().map(|op| op.to_string()).collect();
                write!(f, "delta of op {op} with {} folded in ({} bytes)", folded.join(" "), bytes.len())
            }
            Msg::Damaged { op, bytes } => write!(f, "TRUNCATED delta of op {op} ({} bytes)", bytes.len()),
            Msg::Announce { seen, .. } => write!(f, "announce of {} applied ops", seen.len()),
            Msg::Snapshot { seen, bytes } => write!(f, "snapshot of {} ops ({} bytes)", seen.len(), bytes.len()),
        }
    }
}

/// An operation a replica issued, with its delta's bytes.
#[derive(Clone, PartialEq, Eq, Hash)]
pub struct Issued {
    /// The operation.
    pub record: Arc<OpRecord>,
    /// [`Delta::encode`] of its delta.
    pub bytes: Bytes,
    /// A hash of `bytes` (the oracle cache's key is made of these).
    pub bytes_hash: u64,
}

/// A value the model keeps beside its state but out of its identity (it follows from the hashed fields).
#[derive(Clone, Debug, Default)]
pub struct Derived<T>(pub T);

impl<T> PartialEq for Derived<T> {
    fn eq(&self, _: &Self) -> bool {
        true
    }
}
impl<T> Eq for Derived<T> {}
impl<T> Hash for Derived<T> {
    fn hash<H: Hasher>(&self, _: &mut H) {}
}

/// One replica's state in the model.
///
/// Its [`Hash`] (the checker fingerprints every state it generates, to know whether it was seen) takes the
/// replica through [`ReplicaHashes::whole`], computed once when the replica changes, rather than walking the
/// replica's maps again for every fingerprint of every state that holds it; equality still compares the replicas.
#[derive(Clone, PartialEq, Eq)]
pub struct ReplicaState {
    /// The real replica.
    pub replica: Replica,
    /// The physical clock the replica's operations read, ns.
    pub now_ns: u64,
    /// The operations this replica issued.
    pub issued: Vec<Issued>,
    /// The operations whose deltas this replica has applied (its own included).
    pub seen: BTreeSet<OpId>,
    /// Operations issued so far.
    pub ops_done: u8,
    /// Clock advances so far.
    pub ticks_done: u8,
    /// Announces sent so far.
    pub syncs_done: u8,
    /// Deltas and snapshots the replica refused (there should be none).
    pub refused: Vec<String>,
    /// Damaged deltas the replica accepted, or that changed it although refused (there should be none).
    pub damaged_accepted: Vec<String>,
    /// Steps whose change events did not turn the previous visible graph into the new one (there should be none).
    pub events_incomplete: Vec<String>,
    /// The replica's visible graph (a function of the replica).
    pub graph: Derived<Arc<VisibleGraph>>,
    /// Hashes of the replica (a function of the replica).
    pub hashes: Derived<ReplicaHashes>,
    /// The properties' findings on this replica state alone, each computed at most once.
    findings: properties::ReplicaFindings,
}

/// Hashes of a replica, computed once per change of the replica.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ReplicaHashes {
    /// [`Replica`]'s own [`Hash`]: everything it holds.
    pub whole: u64,
    /// What it replicates (`properties::crdt_fingerprint`).
    pub crdt: u64,
}

impl ReplicaHashes {
    fn of(replica: &Replica) -> ReplicaHashes {
        let crdt = properties::crdt_fingerprint(replica);
        // Beyond what it replicates, a replica holds its id (fixed by its place in the system state), the count of
        // node ids it minted (fixed by its own operations, which the state holds) and its history of deltas: with
        // no history (the configurations without loss or announces) the replicated part identifies it.
        if replica.log_len() == 0 {
            return ReplicaHashes { whole: crdt, crdt };
        }
        let mut hasher = std::collections::hash_map::DefaultHasher::new();
        replica.hash(&mut hasher);
        ReplicaHashes { whole: hasher.finish(), crdt }
    }
}

impl Hash for ReplicaState {
    fn hash<H: Hasher>(&self, state: &mut H) {
        // Every field but the replica (hashed through `hashes.whole`) and what follows from it.
        let ReplicaState {
            replica: _,
            now_ns,
            issued,
            seen,
            ops_done,
            ticks_done,
            syncs_done,
            refused,
            damaged_accepted,
            events_incomplete,
            graph: _,
            hashes,
            findings: _,
        } = self;
        hashes.0.whole.hash(state);
        (now_ns, issued, seen, ops_done, ticks_done, syncs_done).hash(state);
        (refused, damaged_accepted, events_incomplete).hash(state);
    }
}

impl std::fmt::Debug for ReplicaState {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let graph = &self.graph.0;
        writeln!(f, "replica {} (digest {}, clock {}):", self.replica.id(), graph.digest(), self.replica.clock().0)?;
        for (id, node) in &graph.nodes {
            let attrs: Vec<String> = node.attrs.iter().map(|(n, a)| format!("{n}={:?}", a.concurrent)).collect();
            writeln!(f, "  node {id} {:?} {}", node.name, attrs.join(" "))?;
        }
        for (key, edge_attrs) in &graph.edges {
            let attrs: Vec<String> = edge_attrs.iter().map(|(n, a)| format!("{n}={:?}", a.concurrent)).collect();
            writeln!(f, "  edge {key} {}", attrs.join(" "))?;
        }
        for op in &self.issued {
            writeln!(f, "  issued: {}", op.record)?;
        }
        let seen: Vec<String> = self.seen.iter().map(|op| op.to_string()).collect();
        writeln!(f, "  applied ops: {}", seen.join(" "))?;
        for finding in self.refused.iter().chain(&self.damaged_accepted).chain(&self.events_incomplete) {
            writeln!(f, "  FINDING: {finding}")?;
        }
        Ok(())
    }
}

impl ReplicaState {
    /// After the replica changed: checks that the change events it queued turn the previous visible graph into
    /// the new one, and keeps the new one and the new hashes.
    fn after_step(&mut self, step: impl FnOnce() -> String) {
        let events = self.replica.drain_changes();
        let graph = Arc::new(self.replica.visible_graph());
        if let Err(why) = check_change_events(&self.graph.0, &graph, &events) {
            self.events_incomplete.push(format!("{}: {why}", step()));
        }
        self.graph = Derived(graph);
        self.rehash();
    }

    /// Recomputes the replica's hashes: after anything that may have changed the replica (a refused join too,
    /// since a planted bug may change it anyway).
    fn rehash(&mut self) {
        self.hashes = Derived(ReplicaHashes::of(&self.replica));
    }
}

/// One modelled replica.
#[derive(Clone, Debug)]
pub struct ReplicaActor {
    index: usize,
    peers: Vec<Id>,
    seed: Seed,
    config: ConvergenceConfig,
}

impl ReplicaActor {
    fn replica_id(&self) -> ReplicaId {
        ReplicaId(self.index as u32 + 1)
    }

    /// The operations this replica may perform now (only ones its replica accepts), its clock advance and its
    /// announces.
    fn menu(&self, state: &ReplicaState) -> Vec<Choice> {
        let r = &state.replica;
        let (x, y) = (self.seed.x, self.seed.y);
        let mut menu = Vec::new();
        let inserted: Vec<NodeId> =
            r.nodes().filter(|node| node.inserted_name() == NEW_NODE_NAME).map(|node| node.id()).collect();
        if r.node_by_name(NEW_NODE_NAME).is_none() {
            menu.push(OpChoice::InsertNode);
        }
        for &id in std::iter::once(&x).chain(&inserted) {
            if r.node(id).is_some() {
                menu.push(OpChoice::DeleteNode(id));
            }
        }
        let edge = |from: NodeId, to: NodeId, edge_type: &str, menu: &mut Vec<OpChoice>| {
            let key = EdgeKey::new(from, to, edge_type);
            if r.edge(&key).is_some() {
                if edge_type == RT {
                    menu.push(OpChoice::MoveRt(key.clone()));
                }
                menu.push(OpChoice::DeleteEdge(key));
            } else if r.node(from).is_some() && r.node(to).is_some() {
                menu.push(if edge_type == RT { OpChoice::InsertRt(from, to) } else { OpChoice::InsertEdge(from, to) });
            }
        };
        edge(x, y, IN, &mut menu);
        edge(y, x, IN, &mut menu);
        for &id in &inserted {
            edge(x, id, RT, &mut menu);
        }
        if let [first, second, ..] = inserted[..] {
            edge(first, second, IN, &mut menu);
        }
        let x_to_y = Element::Edge(EdgeKey::new(x, y, IN));
        for (element, removable) in [(Element::Node(x), true), (x_to_y, true)]
            .into_iter()
            .chain(inserted.iter().map(|&id| (Element::Node(id), false)))
        {
            let has_level = match &element {
                Element::Node(id) => r.node(*id).map(|n| n.attr("level").is_some()),
                Element::Edge(key) => r.edge(key).map(|e| e.attr("level").is_some()),
            };
            match has_level {
                Some(true) => {
                    menu.push(OpChoice::SetLevel(element.clone()));
                    if removable {
                        menu.push(OpChoice::RemoveLevel(element));
                    }
                }
                Some(false) => menu.push(OpChoice::SetLevel(element)),
                None => {}
            }
        }
        let mut choices: Vec<Choice> = Vec::with_capacity(menu.len() * 2);
        if self.config.ticks > 0 {
            choices.extend(menu.iter().cloned().map(Choice::AdvanceThenOp));
        }
        choices.extend(menu.into_iter().map(Choice::Op));
        if self.config.syncs > 0 {
            choices.extend((0..self.config.replicas).filter(|&peer| peer != self.index).map(Choice::Announce));
        }
        choices
    }

    /// Performs a chosen operation on the real replica.
    fn perform(&self, state: &mut ReplicaState, choice: &OpChoice) -> Result<(Arc<Delta>, OpKind), OpError> {
        let now = state.now_ns;
        let r = &mut state.replica;
        let level = Value::I32((self.index as i32 + 1) * 10 + i32::from(state.ops_done) + 1);
        let name = || Name::new("level");
        Ok(match choice {
            OpChoice::InsertNode => {
                let new = NewNode::new("object", NEW_NODE_NAME).with_attr("level", level.clone());
                let (id, delta) = r.insert_node(now, new)?;
                let kind = OpKind::InsertNode {
                    id,
                    node_type: Name::new("object"),
                    name: Name::new(NEW_NODE_NAME),
                    attrs: vec![(name(), level)],
                };
                (delta, kind)
            }
            OpChoice::DeleteNode(id) => (r.delete_node(now, *id)?, OpKind::DeleteNode { id: *id }),
            OpChoice::InsertEdge(from, to) => {
                let (key, delta) = r.insert_edge(now, *from, *to, IN, vec![])?;
                (delta, OpKind::InsertEdge { key, attrs: Vec::new() })
            }
            OpChoice::InsertRt(from, to) => {
                let translation = Value::from(vec![(self.index as f32 + 1.0) * 100.0, 0.0, 0.0]);
                let rotation = Value::from(vec![0.0f32, 0.0, 0.5]);
                let attrs = vec![
                    (attrs::RT_TRANSLATION.name().to_owned(), translation.clone()),
                    (attrs::RT_ROTATION_EULER_XYZ.name().to_owned(), rotation.clone()),
                ];
                let (key, delta) = r.insert_edge(now, *from, *to, RT, attrs)?;
                let attrs = vec![
                    (Name::new(attrs::RT_TRANSLATION.name()), translation),
                    (Name::new(attrs::RT_ROTATION_EULER_XYZ.name()), rotation),
                ];
                (delta, OpKind::InsertEdge { key, attrs })
            }
            OpChoice::DeleteEdge(key) => (r.delete_edge(now, key)?, OpKind::DeleteEdge { key: key.clone() }),
            OpChoice::MoveRt(key) => {
                let translation = Value::from(vec![(self.index as f32 + 1.0) * 100.0, f32::from(state.ops_done), 0.0]);
                let delta = r.set_attrs(now, key, [(attrs::RT_TRANSLATION.name(), translation.clone())])?;
                let name = Name::new(attrs::RT_TRANSLATION.name());
                (delta, OpKind::SetAttr { element: Element::Edge(key.clone()), name, value: translation })
            }
            OpChoice::SetLevel(element) => {
                let delta = r.set_attrs(now, element.clone(), [(attrs::LEVEL.name(), level.clone())])?;
                (delta, OpKind::SetAttr { element: element.clone(), name: name(), value: level })
            }
            OpChoice::RemoveLevel(element) => (
                r.remove_attr(now, element.clone(), "level")?,
                OpKind::RemoveAttr { element: element.clone(), name: name() },
            ),
        })
    }

    /// Sends a delta to `to` (and, on a duplicating network, a truncated copy of it).
    fn send_delta(&self, to: Id, op: OpId, bytes: &Bytes, o: &mut Out<Self>) {
        o.send(to, Msg::Delta { op, folded: Vec::new(), bytes: bytes.clone() });
        if self.config.network == NetworkKind::UnorderedDuplicating {
            // Cut at one of three places, varying with the operation, so every part of the format is cut somewhere.
            let cut = bytes.len() * (1 + (op.counter % 3) as usize) / 4;
            o.send(to, Msg::Damaged { op, bytes: bytes.slice(..cut.min(bytes.len() - 1)) });
        }
    }

    fn operate(&self, state: &mut ReplicaState, choice: &OpChoice, o: &mut Out<Self>) {
        let past = state.seen.clone();
        let Ok((delta, kind)) = self.perform(state, choice) else { return };
        let origin = delta.origin().expect("local deltas have an origin");
        let op = Arc::new(OpRecord {
            id: dsr::Dot::new(origin.replica, origin.first),
            replica: origin.replica,
            stamp: state.replica.clock(),
            past,
            kind,
        });
        state.after_step(|| format!("local operation {op}"));
        let bytes = Bytes::from(delta.encode());
        state.seen.insert(op.id);
        state.ops_done += 1;
        for &peer in &self.peers {
            self.send_delta(peer, op.id, &bytes, o);
        }
        let mut hasher = std::collections::hash_map::DefaultHasher::new();
        bytes.hash(&mut hasher);
        state.issued.push(Issued { record: op, bytes, bytes_hash: hasher.finish() });
    }

    /// Joins received bytes (a delta or a snapshot); returns whether they were accepted.
    fn join_bytes(&self, state: &mut ReplicaState, what: &str, bytes: &[u8]) -> bool {
        let result = Delta::decode(bytes)
            .map_err(|e| e.to_string())
            .and_then(|delta| state.replica.apply_shared(Arc::new(delta)).map_err(|e| e.to_string()));
        match result {
            Ok(()) => {
                state.after_step(|| format!("joining {what}"));
                true
            }
            Err(error) => {
                state.refused.push(format!("{what}: {error}"));
                state.rehash();
                false
            }
        }
    }
}

impl Actor for ReplicaActor {
    type Msg = Msg;
    type State = ReplicaState;
    type Timer = ();
    type Random = Choice;
    type Storage = ();

    fn on_start(&self, _id: Id, _storage: &Option<()>, _o: &mut Out<Self>) -> ReplicaState {
        let mut replica = Replica::new(self.replica_id());
        let max_deltas = if self.config.keeps_history() { self.config.history } else { 0 };
        // Without loss or announces nothing is ever re-sent, so the history would only multiply states.
        let fold_min_payload_bytes = self.config.fold_min_payload_bytes;
        replica.set_log_limits(dsr::LogLimits { max_deltas, max_payload_bytes: 1 << 20, fold_min_payload_bytes });
        #[cfg(feature = "mutants")]
        replica.plant_mutant(self.config.planted);
        replica.apply(&self.seed.snapshot).expect("the seed graph applies");
        replica.set_change_tracking(true);
        let graph = Arc::new(replica.visible_graph());
        let hashes = ReplicaHashes::of(&replica);
        ReplicaState {
            replica,
            now_ns: 0,
            issued: Vec::new(),
            seen: self.seed.ops.iter().map(|op| op.id).collect(),
            ops_done: 0,
            ticks_done: 0,
            syncs_done: 0,
            refused: Vec::new(),
            damaged_accepted: Vec::new(),
            events_incomplete: Vec::new(),
            graph: Derived(graph),
            hashes: Derived(hashes),
            findings: properties::ReplicaFindings::default(),
        }
    }

    fn on_random(&self, _id: Id, state: &mut Cow<'_, ReplicaState>, choice: &Choice, o: &mut Out<Self>) {
        let state = state.to_mut();
        match choice {
            Choice::Op(op) => self.operate(state, op, o),
            Choice::AdvanceThenOp(op) => {
                state.now_ns += TICK_NS;
                state.ticks_done += 1;
                self.operate(state, op, o);
            }
            Choice::Announce(peer) => {
                state.syncs_done += 1;
                let applied = state.replica.applied().dots().collect();
                o.send(Id::from(*peer), Msg::Announce { applied, seen: state.seen.clone() });
            }
        }
    }

    fn on_msg(&self, _id: Id, state: &mut Cow<'_, ReplicaState>, src: Id, msg: Msg, o: &mut Out<Self>) {
        match msg {
            Msg::Delta { op, folded, bytes } => {
                let state = state.to_mut();
                if self.join_bytes(state, &format!("delta of op {op}"), &bytes) {
                    state.seen.insert(op);
                    state.seen.extend(folded);
                }
            }
            Msg::Damaged { op, bytes } => {
                // Refused by the decoder: nothing changes (and the state is not even copied).
                let Ok(delta) = Delta::decode(&bytes) else { return };
                let state = state.to_mut();
                let before = state.replica.clone();
                let finding = match state.replica.apply(&delta) {
                    Ok(()) => format!("a truncated copy of op {op} ({} bytes) was decoded and joined", bytes.len()),
                    Err(_) if state.replica != before => format!("a refused truncated copy of op {op} changed it"),
                    Err(_) => return,
                };
                state.damaged_accepted.push(finding);
                state.after_step(|| format!("truncated copy of op {op}"));
            }
            Msg::Announce { applied, .. } => match state.replica.missing_for(&CausalContext::from_dots(applied)) {
                Missing::UpToDate => {}
                Missing::Deltas(deltas) => {
                    for delta in deltas {
                        let origin = delta.origin().expect("retained deltas have an origin");
                        let op = dsr::Dot::new(origin.replica, origin.first);
                        let folded = state.seen.iter().copied().filter(|op| delta.applied().contains(*op)).collect();
                        o.send(src, Msg::Delta { op, folded, bytes: Bytes::from(delta.encode()) });
                    }
                }
                Missing::Snapshot => {
                    let bytes = Bytes::from(state.replica.encode_snapshot());
                    o.send(src, Msg::Snapshot { seen: state.seen.clone(), bytes });
                }
            },
            Msg::Snapshot { seen, bytes } => {
                let state = state.to_mut();
                if self.join_bytes(state, "snapshot", &bytes) {
                    state.seen.extend(seen);
                }
            }
        }
    }
}

type State = ActorModelState<ReplicaActor>;

/// The convergence model: Stateright's actor model of the replicas, with the checker's choices limited to the
/// budgets left (an operation, clock advance or announce past its budget is not even computed).
pub struct ConvergenceModel {
    inner: ActorModel<ReplicaActor, Setup>,
}

impl ConvergenceModel {
    /// The configuration, seed and caches.
    pub fn setup(&self) -> &Setup {
        &self.inner.cfg
    }
}

/// Totals spent by all replicas: operations, clock advances, announces.
fn spent(state: &State) -> (usize, usize, usize) {
    state.actor_states.iter().fold((0, 0, 0), |(ops, ticks, syncs), s| {
        (ops + usize::from(s.ops_done), ticks + usize::from(s.ticks_done), syncs + usize::from(s.syncs_done))
    })
}

impl Model for ConvergenceModel {
    type State = State;
    type Action = <ActorModel<ReplicaActor, Setup> as Model>::Action;

    fn init_states(&self) -> Vec<State> {
        self.inner.init_states()
    }

    /// The network's deliveries (Stateright's own actions: the replicas register no random choices with it),
    /// then each replica's menu within the budgets left. The menu is a function of the replica's state, so it is
    /// computed here, per state explored, rather than stored in every state and hashed with it.
    fn actions(&self, state: &State, actions: &mut Vec<Self::Action>) {
        self.inner.actions(state, actions);
        let config = &self.inner.cfg.config;
        let (ops, ticks, syncs) = spent(state);
        for (index, actor) in self.inner.actors.iter().enumerate() {
            let allowed = |choice: &Choice| match choice {
                Choice::Op(_) => ops < config.ops,
                Choice::AdvanceThenOp(_) => ops < config.ops && ticks < config.ticks,
                Choice::Announce(_) => syncs < config.syncs,
            };
            let menu = actor.menu(&state.actor_states[index]).into_iter().filter(allowed);
            actions.extend(menu.map(|random| ActorModelAction::SelectRandom {
                actor: Id::from(index),
                key: CHOICE_KEY.to_owned(),
                random,
            }));
        }
    }

    fn next_state(&self, state: &State, action: Self::Action) -> Option<State> {
        self.inner.next_state(state, action)
    }

    fn format_action(&self, action: &Self::Action) -> String {
        self.inner.format_action(action)
    }

    fn format_step(&self, state: &State, action: Self::Action) -> Option<String> {
        self.inner.format_step(state, action)
    }

    fn as_svg(&self, path: stateright::Path<State, Self::Action>) -> Option<String> {
        self.inner.as_svg(path)
    }

    fn properties(&self) -> Vec<Property<Self>> {
        vec![
            Property::always(properties::INVARIANTS, invariants_hold),
            Property::always(properties::NO_REFUSAL, no_delta_refused),
            Property::always(properties::DAMAGED, damaged_refused),
            Property::always(properties::STAMPS, stamps_follow_causality),
            Property::always(properties::SEC, same_ops_same_graph),
            Property::always(properties::FRESH, equal_to_fresh_join),
            Property::always(properties::SPEC_EVERY, matches_spec_everywhere),
            Property::always(properties::LATE_JOIN, late_joiner_equals),
            Property::always(properties::EVENTS, change_events_complete),
            Property::always(properties::KINEMATICS, kinematics_agree),
            Property::always(properties::CONVERGE, quiescent_replicas_converge),
            Property::always(properties::SPEC, quiescent_replicas_match_spec),
            Property::sometimes(properties::CONFLICTS, conflicts_happen),
            Property::sometimes(properties::SNAPSHOT, snapshot_answered),
            Property::sometimes(properties::RT_MOVED, rt_moved),
            Property::sometimes(properties::END, quiescent_end_reached),
        ]
    }
}

/// Builds the model.
pub fn model(config: &ConvergenceConfig) -> ConvergenceModel {
    let seed = Seed::build();
    let n = config.replicas;
    let actors = (0..n)
        .map(|index| ReplicaActor {
            index,
            peers: (0..n).filter(|&p| p != index).map(Id::from).collect(),
            seed: seed.clone(),
            config: config.clone(),
        })
        .collect::<Vec<_>>();
    let network = match config.network {
        NetworkKind::UnorderedDuplicating => Network::new_unordered_duplicating([]),
        NetworkKind::UnorderedNonduplicating | NetworkKind::Lossy => Network::new_unordered_nonduplicating([]),
    };
    let lossy = if config.network == NetworkKind::Lossy { LossyNetwork::Yes } else { LossyNetwork::No };
    let setup = Setup::new(config.clone(), seed);
    let inner = ActorModel::new(setup, ()).actors(actors).init_network(network).lossy_network(lossy);
    ConvergenceModel { inner }
}

/// Checks the convergence model.
pub fn check_convergence(config: &ConvergenceConfig, options: &CheckOptions) -> CheckReport {
    let configuration = serde_json::to_value(config).expect("the configuration serializes");
    run_check(model(config), "convergence", configuration, options)
}

/// The number of properties (for callers that want to check a report is complete).
pub fn property_count(config: &ConvergenceConfig) -> usize {
    model(config).properties().len()
}
