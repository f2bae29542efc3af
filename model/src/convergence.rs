//! The CRDT convergence model: N replicas holding real [`dsr::Replica`] values exchange real deltas over
//! Stateright's networks, while the checker chooses every replica's operations.
//!
//! All replicas start from the same seed graph (nodes `x` and `y`, an edge `x -[in]-> y`, `level` attributes), so
//! a small operation budget already reaches the interesting conflicts: concurrent writes of one attribute, a delete
//! racing a write or an edge insert, an edge re-inserted while it is being deleted, two nodes inserted concurrently
//! under the same name. `--ops K` is the total budget shared by all replicas (the checker decides who spends it).
//!
//! Networks: unordered duplicating (every message may be delivered any number of times), unordered
//! non-duplicating, and lossy (non-duplicating, and any message may be dropped). With loss, convergence is the job
//! of anti-entropy: the quiescent-state properties first run reliable rounds of the replicas' own anti-entropy
//! (`Replica::missing_for` and joins) and then require convergence.
//!
//! Symmetry reduction does not apply: replica ids break ties between concurrent writes, so replicas are not
//! interchangeable.

use std::borrow::Cow;
use std::collections::{BTreeMap, BTreeSet};
use std::sync::Arc;

use dsr::{Delta, EdgeKey, Element, Missing, Name, NewNode, NodeId, OpError, Replica, ReplicaId, Value, attrs};
use serde::Serialize;
use stateright::actor::{Actor, ActorModel, ActorModelState, Id, LossyNetwork, Network, Out};
use stateright::{Expectation, Model};

use crate::report::{CheckOptions, CheckReport, run_check};
use crate::spec::{self, OpId, OpKind, OpRecord};

/// How the network treats messages.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum NetworkKind {
    /// Unordered; every message may be delivered any number of times.
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
}

/// Replica id of the seed graph's author (not one of the modelled replicas).
const SEED_REPLICA: ReplicaId = ReplicaId(1000);
/// Name of the nodes the replicas may insert (the same for all, so concurrent inserts conflict).
const NEW_NODE_NAME: &str = "n";

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
        let (key, delta) = replica.insert_edge(0, x, y, "in", vec![("level".into(), Value::I32(0))]).unwrap();
        record(&replica, &delta, OpKind::InsertEdge { key, attrs: level(0) }, &mut ops);
        Seed { snapshot: Arc::new(replica.snapshot()), ops, x, y }
    }
}

/// An operation the checker may choose for a replica.
#[derive(Clone, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum OpChoice {
    /// Insert a node named `n`.
    InsertNode,
    /// Delete a node.
    DeleteNode(NodeId),
    /// Insert an edge `from -[in]-> to`.
    InsertEdge(NodeId, NodeId),
    /// Delete an edge `from -[in]-> to`.
    DeleteEdge(NodeId, NodeId),
    /// Write the `level` attribute of a node or edge.
    SetLevel(Element),
    /// Remove the `level` attribute of a node or edge.
    RemoveLevel(Element),
}

/// A delta on the wire, with the operation it carries (its identity: one operation, one delta).
#[derive(Clone)]
pub struct DeltaMsg {
    /// The operation.
    pub op: Arc<OpRecord>,
    /// Its delta.
    pub delta: Arc<Delta>,
}

impl PartialEq for DeltaMsg {
    fn eq(&self, other: &Self) -> bool {
        self.op.id == other.op.id
    }
}
impl Eq for DeltaMsg {}
impl PartialOrd for DeltaMsg {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for DeltaMsg {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        self.op.id.cmp(&other.op.id)
    }
}
impl std::hash::Hash for DeltaMsg {
    fn hash<H: std::hash::Hasher>(&self, state: &mut H) {
        self.op.id.hash(state);
    }
}
impl std::fmt::Debug for DeltaMsg {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "delta of ({})", self.op)
    }
}

/// One replica's state in the model.
#[derive(Clone, PartialEq, Eq, Hash)]
pub struct ReplicaState {
    /// The real replica.
    pub replica: Replica,
    /// The operations this replica issued.
    pub issued: Vec<Arc<OpRecord>>,
    /// The operations whose deltas this replica has applied (its own included).
    pub seen: BTreeSet<OpId>,
    /// Operations issued so far.
    pub ops_done: u8,
    /// Deltas the replica refused (there should be none).
    pub refused: Vec<String>,
}

impl std::fmt::Debug for ReplicaState {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let graph = self.replica.visible_graph();
        writeln!(f, "replica {} (digest {}):", self.replica.id(), self.replica.digest())?;
        for (id, node) in &graph.nodes {
            let attrs: Vec<String> = node.attrs.iter().map(|(n, a)| format!("{n}={:?}", a.concurrent)).collect();
            writeln!(f, "  node {id} {:?} {}", node.name, attrs.join(" "))?;
        }
        for (key, edge_attrs) in &graph.edges {
            let attrs: Vec<String> = edge_attrs.iter().map(|(n, a)| format!("{n}={:?}", a.concurrent)).collect();
            writeln!(f, "  edge {key} {}", attrs.join(" "))?;
        }
        for op in &self.issued {
            writeln!(f, "  issued: {op}")?;
        }
        for refusal in &self.refused {
            writeln!(f, "  REFUSED: {refusal}")?;
        }
        Ok(())
    }
}

/// One modelled replica.
#[derive(Clone, Debug)]
pub struct ReplicaActor {
    index: usize,
    peers: Vec<Id>,
    seed: Seed,
    keep_history: bool,
    #[cfg(feature = "mutants")]
    planted: Option<dsr::DsrMutant>,
}

impl ReplicaActor {
    fn replica_id(&self) -> ReplicaId {
        ReplicaId(self.index as u32 + 1)
    }

    /// The operations this replica may perform now (only ones its replica accepts).
    fn menu(&self, state: &ReplicaState) -> Vec<OpChoice> {
        let r = &state.replica;
        let (x, y) = (self.seed.x, self.seed.y);
        let mut menu = Vec::new();
        if r.node_by_name(NEW_NODE_NAME).is_none() {
            menu.push(OpChoice::InsertNode);
        }
        for id in [x, y] {
            if r.node(id).is_some() {
                menu.push(OpChoice::DeleteNode(id));
            }
        }
        for (from, to) in [(x, y), (y, x)] {
            let key = EdgeKey::new(from, to, "in");
            if r.edge(&key).is_some() {
                menu.push(OpChoice::DeleteEdge(from, to));
            } else if r.node(from).is_some() && r.node(to).is_some() {
                menu.push(OpChoice::InsertEdge(from, to));
            }
        }
        let x_to_y = Element::Edge(EdgeKey::new(x, y, "in"));
        for element in [Element::Node(x), x_to_y] {
            let has_level = match &element {
                Element::Node(id) => r.node(*id).map(|n| n.attr("level").is_some()),
                Element::Edge(key) => r.edge(key).map(|e| e.attr("level").is_some()),
            };
            match has_level {
                Some(true) => {
                    menu.push(OpChoice::SetLevel(element.clone()));
                    menu.push(OpChoice::RemoveLevel(element));
                }
                Some(false) => menu.push(OpChoice::SetLevel(element)),
                None => {}
            }
        }
        menu
    }

    fn offer(&self, state: &ReplicaState, o: &mut Out<Self>) {
        o.choose_random("op", self.menu(state));
    }

    /// Performs a chosen operation on the real replica.
    fn perform(&self, state: &mut ReplicaState, choice: &OpChoice) -> Result<(Arc<Delta>, OpKind), OpError> {
        let r = &mut state.replica;
        let level = Value::I32((self.index as i32 + 1) * 10 + i32::from(state.ops_done) + 1);
        let name = || Name::new("level");
        Ok(match choice {
            OpChoice::InsertNode => {
                let (id, delta) = r.insert_node(0, NewNode::new("object", NEW_NODE_NAME))?;
                let kind = OpKind::InsertNode {
                    id,
                    node_type: Name::new("object"),
                    name: Name::new(NEW_NODE_NAME),
                    attrs: Vec::new(),
                };
                (delta, kind)
            }
            OpChoice::DeleteNode(id) => (r.delete_node(0, *id)?, OpKind::DeleteNode { id: *id }),
            OpChoice::InsertEdge(from, to) => {
                let (key, delta) = r.insert_edge(0, *from, *to, "in", vec![])?;
                (delta, OpKind::InsertEdge { key, attrs: Vec::new() })
            }
            OpChoice::DeleteEdge(from, to) => {
                let key = EdgeKey::new(*from, *to, "in");
                (r.delete_edge(0, &key)?, OpKind::DeleteEdge { key })
            }
            OpChoice::SetLevel(element) => {
                let delta = r.set_attrs(0, element.clone(), [(attrs::LEVEL.name(), level.clone())])?;
                (delta, OpKind::SetAttr { element: element.clone(), name: name(), value: level })
            }
            OpChoice::RemoveLevel(element) => (
                r.remove_attr(0, element.clone(), "level")?,
                OpKind::RemoveAttr { element: element.clone(), name: name() },
            ),
        })
    }
}

impl Actor for ReplicaActor {
    type Msg = DeltaMsg;
    type State = ReplicaState;
    type Timer = ();
    type Random = OpChoice;
    type Storage = ();

    fn on_start(&self, _id: Id, _storage: &Option<()>, o: &mut Out<Self>) -> ReplicaState {
        let mut replica = Replica::new(self.replica_id());
        if !self.keep_history {
            // Without loss nothing is ever re-sent, so the history would only multiply states.
            replica.set_log_limits(dsr::LogLimits { max_deltas: 0, max_payload_bytes: 0 });
        }
        #[cfg(feature = "mutants")]
        replica.plant_mutant(self.planted);
        replica.apply(&self.seed.snapshot).expect("the seed graph applies");
        let state = ReplicaState {
            replica,
            issued: Vec::new(),
            seen: self.seed.ops.iter().map(|op| op.id).collect(),
            ops_done: 0,
            refused: Vec::new(),
        };
        self.offer(&state, o);
        state
    }

    fn on_random(&self, _id: Id, state: &mut Cow<'_, ReplicaState>, choice: &OpChoice, o: &mut Out<Self>) {
        let state = state.to_mut();
        let past = state.seen.clone();
        if let Ok((delta, kind)) = self.perform(state, choice) {
            let origin = delta.origin().expect("local deltas have an origin");
            let op = Arc::new(OpRecord {
                id: dsr::Dot::new(origin.replica, origin.first),
                replica: origin.replica,
                stamp: state.replica.clock(),
                past,
                kind,
            });
            state.seen.insert(op.id);
            state.issued.push(Arc::clone(&op));
            state.ops_done += 1;
            o.broadcast(&self.peers, &DeltaMsg { op, delta });
        }
        self.offer(state, o);
    }

    fn on_msg(&self, _id: Id, state: &mut Cow<'_, ReplicaState>, _src: Id, msg: DeltaMsg, o: &mut Out<Self>) {
        let state = state.to_mut();
        if let Err(error) = state.replica.apply_shared(Arc::clone(&msg.delta)) {
            state.refused.push(format!("{}: {error}", msg.op));
        }
        state.seen.insert(msg.op.id);
        self.offer(state, o);
    }
}

/// What the properties need besides the state: the configuration and the seed.
#[derive(Clone, Debug)]
pub struct Setup {
    /// The configuration.
    pub config: ConvergenceConfig,
    /// The seed graph.
    pub seed: Seed,
}

type State = ActorModelState<ReplicaActor>;

/// Every operation issued so far (the seed's included).
fn all_ops(setup: &Setup, state: &State) -> Vec<OpRecord> {
    issued_ops(setup, state).cloned().collect()
}

/// Every operation issued so far, by reference.
fn issued_ops<'a>(setup: &'a Setup, state: &'a State) -> impl Iterator<Item = &'a OpRecord> + 'a {
    setup.seed.ops.iter().map(|op| &**op).chain(state.actor_states.iter().flat_map(|s| s.issued.iter().map(|op| &**op)))
}

fn ops_spent(setup: &Setup, state: &State) -> bool {
    state.actor_states.iter().map(|s| usize::from(s.ops_done)).sum::<usize>() == setup.config.ops
}

/// Nothing is left to deliver: the network is empty, or (duplicating) every message reached its destination.
fn quiescent(setup: &Setup, state: &State) -> bool {
    match setup.config.network {
        NetworkKind::UnorderedDuplicating => state
            .network
            .iter_all()
            .all(|envelope| state.actor_states[usize::from(envelope.dst)].seen.contains(&envelope.msg.op.id)),
        NetworkKind::UnorderedNonduplicating | NetworkKind::Lossy => state.network.len() == 0,
    }
}

/// The replicas as they are, or (lossy network) after reliable rounds of their own anti-entropy.
fn settled_replicas(setup: &Setup, state: &State) -> Vec<Replica> {
    let mut replicas: Vec<Replica> = state.actor_states.iter().map(|s| s.replica.clone()).collect();
    if setup.config.network == NetworkKind::Lossy {
        for _round in 0..2 {
            for from in 0..replicas.len() {
                for to in 0..replicas.len() {
                    if from == to {
                        continue;
                    }
                    let missing = replicas[from].missing_for(replicas[to].applied());
                    let snapshot = matches!(missing, Missing::Snapshot).then(|| replicas[from].snapshot());
                    let target = &mut replicas[to];
                    match missing {
                        Missing::UpToDate => {}
                        Missing::Deltas(deltas) => {
                            for delta in deltas {
                                let _ = target.apply_shared(delta);
                            }
                        }
                        Missing::Snapshot => {
                            if let Some(snapshot) = snapshot {
                                let _ = target.apply(&snapshot);
                            }
                        }
                    }
                }
            }
        }
    }
    replicas
}

fn invariants_hold(model: &ActorModel<ReplicaActor, Setup>, state: &State) -> bool {
    let deleted: Vec<(OpId, NodeId)> = issued_ops(&model.cfg, state)
        .filter_map(|op| match op.kind {
            OpKind::DeleteNode { id } => Some((op.id, id)),
            _ => None,
        })
        .collect();
    state.actor_states.iter().all(|s| {
        s.replica.check_invariants().is_ok()
            && deleted.iter().all(|(op, id)| !s.seen.contains(op) || s.replica.node(*id).is_none())
    })
}

fn no_delta_refused(_: &ActorModel<ReplicaActor, Setup>, state: &State) -> bool {
    state.actor_states.iter().all(|s| s.refused.is_empty())
}

fn stamps_follow_causality(_: &ActorModel<ReplicaActor, Setup>, state: &State) -> bool {
    // Each replica's own operations, with every operation it had seen: those are the pairs a stamp must order.
    let stamps: BTreeMap<OpId, dsr::Stamp> =
        state.actor_states.iter().flat_map(|s| s.issued.iter().map(|op| (op.id, op.stamp))).collect();
    state
        .actor_states
        .iter()
        .flat_map(|s| s.issued.iter())
        .all(|op| op.past.iter().all(|earlier| stamps.get(earlier).is_none_or(|stamp| *stamp < op.stamp)))
}

fn quiescent_replicas_converge(model: &ActorModel<ReplicaActor, Setup>, state: &State) -> bool {
    if !(ops_spent(&model.cfg, state) && quiescent(&model.cfg, state)) {
        return true;
    }
    let replicas = settled_replicas(&model.cfg, state);
    replicas.windows(2).all(|pair| pair[0].digest() == pair[1].digest())
}

fn quiescent_replicas_match_spec(model: &ActorModel<ReplicaActor, Setup>, state: &State) -> bool {
    if !(ops_spent(&model.cfg, state) && quiescent(&model.cfg, state)) {
        return true;
    }
    let expected = spec::visible_graph(&all_ops(&model.cfg, state));
    settled_replicas(&model.cfg, state).iter().all(|r| r.visible_graph() == expected)
}

fn conflicts_happen(model: &ActorModel<ReplicaActor, Setup>, state: &State) -> bool {
    let ops = all_ops(&model.cfg, state);
    let order = spec::CausalOrder::new(&ops);
    ops.iter().enumerate().any(|(i, a)| {
        ops[i + 1..]
            .iter()
            .any(|b| a.replica != b.replica && order.concurrent(a.id, b.id) && spec::conflict(&a.kind, &b.kind))
    })
}

fn quiescent_end_reached(model: &ActorModel<ReplicaActor, Setup>, state: &State) -> bool {
    ops_spent(&model.cfg, state) && quiescent(&model.cfg, state)
}

/// The property names, for tests and the mutant check.
pub mod properties {
    /// Invariants on every replica state.
    pub const INVARIANTS: &str = "every state: no dangling edge, unique names, deleted nodes invisible";
    /// No delta is refused.
    pub const NO_REFUSAL: &str = "every delta is accepted";
    /// Stamps respect causality.
    pub const STAMPS: &str = "an operation's stamp is above those it saw";
    /// Convergence at quiescence.
    pub const CONVERGE: &str = "quiescent, budget spent: all replicas have equal digests";
    /// Agreement with the specification at quiescence.
    pub const SPEC: &str = "quiescent, budget spent: every replica equals the reference specification";
    /// Conflicts are explored.
    pub const CONFLICTS: &str = "concurrent conflicting operations happen";
    /// The quiescent end is reached (the quiescent properties are not vacuous).
    pub const END: &str = "a quiescent state with the budget spent is reached";
}

/// Builds the model.
pub fn model(config: &ConvergenceConfig) -> ActorModel<ReplicaActor, Setup> {
    let seed = Seed::build();
    let n = config.replicas;
    let actors = (0..n)
        .map(|index| ReplicaActor {
            index,
            peers: (0..n).filter(|&p| p != index).map(Id::from).collect(),
            seed: seed.clone(),
            keep_history: config.network == NetworkKind::Lossy,
            #[cfg(feature = "mutants")]
            planted: config.planted,
        })
        .collect::<Vec<_>>();
    let network = match config.network {
        NetworkKind::UnorderedDuplicating => Network::new_unordered_duplicating([]),
        NetworkKind::UnorderedNonduplicating | NetworkKind::Lossy => Network::new_unordered_nonduplicating([]),
    };
    let lossy = if config.network == NetworkKind::Lossy { LossyNetwork::Yes } else { LossyNetwork::No };
    ActorModel::new(Setup { config: config.clone(), seed }, ())
        .actors(actors)
        .init_network(network)
        .lossy_network(lossy)
        .property(Expectation::Always, properties::INVARIANTS, invariants_hold)
        .property(Expectation::Always, properties::NO_REFUSAL, no_delta_refused)
        .property(Expectation::Always, properties::STAMPS, stamps_follow_causality)
        .property(Expectation::Always, properties::CONVERGE, quiescent_replicas_converge)
        .property(Expectation::Always, properties::SPEC, quiescent_replicas_match_spec)
        .property(Expectation::Sometimes, properties::CONFLICTS, conflicts_happen)
        .property(Expectation::Sometimes, properties::END, quiescent_end_reached)
        .within_boundary(|setup, state| {
            state.actor_states.iter().map(|s| usize::from(s.ops_done)).sum::<usize>() <= setup.config.ops
        })
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
