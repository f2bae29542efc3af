//! The convergence model's properties: the property names, and the predicates the checker evaluates on every
//! state, with the oracle behind them (a fresh replica joining a state's deltas, and the reference specification),
//! cached per set of deltas since many states share one.

use std::collections::hash_map::DefaultHasher;
use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::hash::{Hash, Hasher};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, OnceLock};

use dsr::{Delta, Missing, NodeId, Replica, ReplicaId, VisibleGraph};

use super::{ConvergenceConfig, ConvergenceModel, Issued, Msg, NetworkKind, Seed, State, spent};
use crate::spec::{self, OpId, OpKind, OpRecord};

/// Invariants on every replica state.
pub const INVARIANTS: &str = "every state: no dangling edge, unique names, deleted nodes invisible";
/// No delta is refused.
pub const NO_REFUSAL: &str = "every delta and snapshot decodes and is accepted";
/// Damaged deltas are refused.
pub const DAMAGED: &str = "every truncated delta is refused and leaves the replica unchanged";
/// Stamps respect causality.
pub const STAMPS: &str = "an operation's stamp is above those it saw";
/// Strong eventual consistency on every state.
pub const SEC: &str = "every state: replicas that applied the same operations show equal graphs and digests";
/// Each replica equals the join of its deltas.
pub const FRESH: &str = "every state: each replica equals a fresh replica joining its deltas (either order)";
/// Each replica equals the specification of what it applied.
pub const SPEC_EVERY: &str =
    "every state: a replica that applied a causally closed set of operations shows their specification";
/// A late joiner installing a snapshot equals its source.
pub const LATE_JOIN: &str = "every state: a fresh replica installing a replica's snapshot equals it";
/// Kinematics agree.
pub const KINEMATICS: &str = "every state: replicas that applied the same operations compute the same transforms, \
                              and an RT edge's transform is its shown translation and rotation";
/// Change events are complete.
pub const EVENTS: &str = "every step: the change events turn the previous visible graph into the new one";
/// Convergence at quiescence.
pub const CONVERGE: &str = "quiescent, budget spent: all replicas have equal digests";
/// Agreement with the specification at quiescence.
pub const SPEC: &str = "quiescent, budget spent: every replica applied every operation and equals the specification";
/// Conflicts are explored.
pub const CONFLICTS: &str = "concurrent conflicting operations happen";
/// Anti-entropy falls back to a snapshot (with announces).
pub const SNAPSHOT: &str = "an announce is answered with a snapshot (when announces are allowed)";
/// An RT edge is moved after its insert (the kinematics property is not only about inserts).
pub const RT_MOVED: &str = "an RT edge's translation is written after its insert (with 3 operations or more)";
/// The quiescent end is reached (the quiescent properties are not vacuous).
pub const END: &str = "a quiescent state with the budget spent is reached";

/// The properties' findings on one replica state alone (its invariants, its oracle, its late join, its
/// kinematics), each computed at most once. A replica state is shared, behind an `Arc`, by every system state that
/// holds it unchanged, so these are computed once for all of them rather than once per system state. They are
/// functions of the replica state and of the deltas of the operations it has seen, which never change once issued.
/// A copy starts empty: the model copies a replica state only to change it.
#[derive(Default)]
pub(super) struct ReplicaFindings {
    invariants: OnceLock<bool>,
    oracle: OnceLock<Arc<Oracle>>,
    late_join: OnceLock<bool>,
    poses: OnceLock<bool>,
    transforms: OnceLock<Vec<Result<[f64; 3], String>>>,
}

impl Clone for ReplicaFindings {
    fn clone(&self) -> Self {
        ReplicaFindings::default()
    }
}
impl PartialEq for ReplicaFindings {
    fn eq(&self, _: &Self) -> bool {
        true
    }
}
impl Eq for ReplicaFindings {}

/// What a fresh replica that joins a set of deltas looks like, and whether the specification agrees.
#[derive(Debug)]
struct Oracle {
    /// Fingerprint of the fresh replica's replicated state (see [`crdt_fingerprint`]).
    fingerprint: u64,
    /// Its visible graph.
    graph: VisibleGraph,
    /// A delta refused, or the two join orders disagreeing.
    join_problem: Option<String>,
    /// The specification disagreeing (checked when the operations are causally closed).
    spec_problem: Option<String>,
}

/// Fresh replicas computed so far, by the deltas joined (many states share a set of deltas).
#[derive(Default)]
struct OracleCache {
    /// Keyed by the hashes of the deltas' bytes ([`Issued::bytes_hash`]), in the order the state lists them.
    by_deltas: Mutex<HashMap<Vec<u64>, Arc<Oracle>>>,
    /// Late-join checks done, by the fingerprint of the replica whose snapshot was installed.
    installs: Mutex<HashMap<u64, Option<String>>>,
    /// Whether [`conflicts_happen`] has had its witness.
    conflict_witnessed: AtomicBool,
}

/// Most entries kept in each cache before it is emptied (a bound on memory, not on correctness).
const CACHE_LIMIT: usize = 1 << 18;

impl std::fmt::Debug for OracleCache {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("OracleCache")
    }
}

/// A fingerprint of what a replica replicates: its store, causal context, applied operations and clock.
pub(super) fn crdt_fingerprint(replica: &Replica) -> u64 {
    let mut hasher = DefaultHasher::new();
    replica.store().hash(&mut hasher);
    replica.context().hash(&mut hasher);
    replica.applied().hash(&mut hasher);
    replica.clock().hash(&mut hasher);
    hasher.finish()
}

/// What the properties need besides the state: the configuration, the seed and the caches.
#[derive(Clone, Debug)]
pub struct Setup {
    /// The configuration.
    pub config: ConvergenceConfig,
    /// The seed graph.
    pub seed: Seed,
    cache: Arc<OracleCache>,
}

impl Setup {
    /// The setup of `config` from `seed`, with empty caches.
    pub(super) fn new(config: ConvergenceConfig, seed: Seed) -> Setup {
        Setup { config, seed, cache: Arc::new(OracleCache::default()) }
    }

    /// A fresh replica with the planted mutant, if any: the oracle's replicas run the same code as the model's, so
    /// a deterministic bug is the specification's to find, and the fresh join checks only order independence.
    fn fresh_replica(&self, id: ReplicaId) -> Replica {
        let replica = Replica::new(id);
        #[cfg(feature = "mutants")]
        let replica = {
            let mut replica = replica;
            replica.plant_mutant(self.config.planted);
            replica
        };
        replica
    }

    /// The oracle for the operations `seen` (their deltas found among the issued ones).
    fn oracle(&self, state: &State, seen: &BTreeSet<OpId>) -> Arc<Oracle> {
        let issued: Vec<&Issued> = state
            .actor_states
            .iter()
            .flat_map(|s| s.issued.iter())
            .filter(|issued| seen.contains(&issued.record.id))
            .collect();
        let key: Vec<u64> = issued.iter().map(|issued| issued.bytes_hash).collect();
        if let Some(found) = self.cache.by_deltas.lock().expect("cache lock").get(&key) {
            return Arc::clone(found);
        }
        let oracle = Arc::new(self.compute_oracle(&issued));
        let mut cache = self.cache.by_deltas.lock().expect("cache lock");
        if cache.len() >= CACHE_LIMIT {
            cache.clear();
        }
        cache.insert(key, Arc::clone(&oracle));
        oracle
    }

    fn compute_oracle(&self, issued: &[&Issued]) -> Oracle {
        let join = |order: &mut dyn Iterator<Item = &&Issued>| -> Result<Replica, String> {
            let mut fresh = self.fresh_replica(ReplicaId(999));
            fresh.apply(&self.seed.snapshot).expect("the seed graph applies");
            for issued in order {
                let delta = Delta::decode(&issued.bytes).map_err(|e| format!("{}: {e}", issued.record))?;
                fresh.apply(&delta).map_err(|e| format!("{}: {e}", issued.record))?;
            }
            Ok(fresh)
        };
        let (forward, backward) = match (join(&mut issued.iter()), join(&mut issued.iter().rev())) {
            (Ok(forward), Ok(backward)) => (forward, backward),
            (Err(error), _) | (_, Err(error)) => {
                let join_problem = Some(format!("a fresh replica refuses a delta: {error}"));
                return Oracle { fingerprint: 0, graph: VisibleGraph::default(), join_problem, spec_problem: None };
            }
        };
        let fingerprint = crdt_fingerprint(&forward);
        let graph = forward.visible_graph();
        let join_problem = (crdt_fingerprint(&backward) != fingerprint || backward.visible_graph() != graph)
            .then(|| "joining the deltas in reverse order gives another state".to_owned());
        let ops: Vec<OpRecord> =
            self.seed.ops.iter().map(|op| (**op).clone()).chain(issued.iter().map(|i| (*i.record).clone())).collect();
        let ids: BTreeSet<OpId> = ops.iter().map(|op| op.id).collect();
        let closed = ops.iter().all(|op| op.past.is_subset(&ids));
        let spec_problem = closed
            .then(|| spec::visible_graph(&ops))
            .filter(|expected| *expected != graph)
            .map(|expected| format!("the specification shows {expected:?}"));
        Oracle { fingerprint, graph, join_problem, spec_problem }
    }
}

/// Every operation issued so far (the seed's included).
pub(super) fn all_ops(setup: &Setup, state: &State) -> Vec<OpRecord> {
    issued_ops(setup, state).cloned().collect()
}

/// Every operation issued so far, by reference.
pub(super) fn issued_ops<'a>(setup: &'a Setup, state: &'a State) -> impl Iterator<Item = &'a OpRecord> + 'a {
    setup
        .seed
        .ops
        .iter()
        .map(|op| &**op)
        .chain(state.actor_states.iter().flat_map(|s| s.issued.iter().map(|op| &*op.record)))
}

/// Whether the operation budget is spent (clock advances and announces may be left).
pub(super) fn budgets_spent(setup: &Setup, state: &State) -> bool {
    spent(state).0 == setup.config.ops
}

/// Nothing is left to deliver that would change anything: every delta's operation and every snapshot's operations
/// were applied by the destination, and every announce's answer would bring its sender nothing it has not applied
/// by now (truncated copies change nothing). On a duplicating network every message stays deliverable, so this
/// is about what delivering them again would do.
pub(super) fn quiescent(state: &State) -> bool {
    state.network.iter_all().all(|envelope| {
        let dst = &state.actor_states[usize::from(envelope.dst)];
        match &envelope.msg {
            Msg::Delta { op, folded, .. } => dst.seen.contains(op) && folded.iter().all(|op| dst.seen.contains(op)),
            Msg::Damaged { .. } => true,
            Msg::Announce { .. } => dst.seen.is_subset(&state.actor_states[usize::from(envelope.src)].seen),
            Msg::Snapshot { seen, .. } => seen.is_subset(&dst.seen),
        }
    })
}

/// The replicas as they are, or (lossy network) after reliable rounds of their own anti-entropy.
pub(super) fn settled_replicas(setup: &Setup, state: &State) -> Vec<Replica> {
    let mut replicas: Vec<Replica> = state.actor_states.iter().map(|s| s.replica.clone()).collect();
    if setup.config.network == NetworkKind::Lossy {
        for _round in 0..2 {
            for from in 0..replicas.len() {
                for to in 0..replicas.len() {
                    if from == to {
                        continue;
                    }
                    let missing = replicas[from].missing_for(replicas[to].applied());
                    let snapshot = matches!(missing, Missing::Snapshot).then(|| replicas[from].encode_snapshot());
                    let target = &mut replicas[to];
                    match missing {
                        Missing::UpToDate => {}
                        Missing::Deltas(deltas) => {
                            for delta in deltas {
                                if let Ok(delta) = Delta::decode(&delta.encode()) {
                                    let _ = target.apply(&delta);
                                }
                            }
                        }
                        Missing::Snapshot => {
                            if let Some(Ok(snapshot)) = snapshot.map(|bytes| Delta::decode(&bytes)) {
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

pub(super) fn invariants_hold(model: &ConvergenceModel, state: &State) -> bool {
    let deleted: Vec<(OpId, NodeId)> = issued_ops(&model.inner.cfg, state)
        .filter_map(|op| match op.kind {
            OpKind::DeleteNode { id } => Some((op.id, id)),
            _ => None,
        })
        .collect();
    state.actor_states.iter().all(|s| {
        *s.findings.invariants.get_or_init(|| {
            s.replica.check_invariants().is_ok()
                && deleted.iter().all(|(op, id)| !s.seen.contains(op) || s.replica.node(*id).is_none())
        })
    })
}

pub(super) fn no_delta_refused(_: &ConvergenceModel, state: &State) -> bool {
    state.actor_states.iter().all(|s| s.refused.is_empty())
}

pub(super) fn damaged_refused(_: &ConvergenceModel, state: &State) -> bool {
    state.actor_states.iter().all(|s| s.damaged_accepted.is_empty())
}

pub(super) fn change_events_complete(_: &ConvergenceModel, state: &State) -> bool {
    state.actor_states.iter().all(|s| s.events_incomplete.is_empty())
}

pub(super) fn stamps_follow_causality(_: &ConvergenceModel, state: &State) -> bool {
    // Each replica's own operations, with every operation it had seen: those are the pairs a stamp must order.
    let stamps: BTreeMap<OpId, dsr::Stamp> =
        state.actor_states.iter().flat_map(|s| s.issued.iter().map(|op| (op.record.id, op.record.stamp))).collect();
    state
        .actor_states
        .iter()
        .flat_map(|s| s.issued.iter())
        .all(|op| op.record.past.iter().all(|earlier| stamps.get(earlier).is_none_or(|stamp| *stamp < op.record.stamp)))
}

pub(super) fn same_ops_same_graph(_: &ConvergenceModel, state: &State) -> bool {
    let replicas = &state.actor_states;
    (0..replicas.len()).all(|a| {
        (a + 1..replicas.len()).all(|b| {
            replicas[a].seen != replicas[b].seen
                || (replicas[a].graph.0 == replicas[b].graph.0
                    && replicas[a].graph.0.digest() == replicas[b].graph.0.digest())
        })
    })
}

/// The oracle of a replica state: a fresh replica joining the deltas of the operations it has seen.
fn oracle_of<'a>(model: &ConvergenceModel, state: &State, s: &'a super::ReplicaState) -> &'a Oracle {
    s.findings.oracle.get_or_init(|| model.inner.cfg.oracle(state, &s.seen))
}

pub(super) fn equal_to_fresh_join(model: &ConvergenceModel, state: &State) -> bool {
    state.actor_states.iter().all(|s| {
        let oracle = oracle_of(model, state, s);
        oracle.join_problem.is_none() && oracle.fingerprint == s.hashes.0.crdt && oracle.graph == *s.graph.0
    })
}

pub(super) fn matches_spec_everywhere(model: &ConvergenceModel, state: &State) -> bool {
    state.actor_states.iter().all(|s| {
        let oracle = oracle_of(model, state, s);
        oracle.spec_problem.is_none() && oracle.graph == *s.graph.0
    })
}

pub(super) fn late_joiner_equals(model: &ConvergenceModel, state: &State) -> bool {
    state.actor_states.iter().all(|s| *s.findings.late_join.get_or_init(|| late_joiner_verdict(model, s)))
}

/// Whether a late joiner installing `s`'s snapshot equals it, cached by the replica's fingerprint too (replica
/// states on different paths can hold one replica).
fn late_joiner_verdict(model: &ConvergenceModel, s: &super::ReplicaState) -> bool {
    let key = s.hashes.0.crdt;
    if let Some(verdict) = model.inner.cfg.cache.installs.lock().expect("cache lock").get(&key) {
        return verdict.is_none();
    }
    let verdict = late_join_problem(&model.inner.cfg, &s.replica, &s.graph.0);
    let mut cache = model.inner.cfg.cache.installs.lock().expect("cache lock");
    if cache.len() >= CACHE_LIMIT {
        cache.clear();
    }
    cache.insert(key, verdict.clone());
    verdict.is_none()
}

/// Installs `replica`'s encoded snapshot into a fresh replica (with the same planted mutant) and compares.
pub(super) fn late_join_problem(setup: &Setup, replica: &Replica, graph: &VisibleGraph) -> Option<String> {
    let snapshot = match Delta::decode(&replica.encode_snapshot()) {
        Ok(snapshot) => snapshot,
        Err(error) => return Some(format!("the snapshot does not decode: {error}")),
    };
    let mut joiner = setup.fresh_replica(ReplicaId(998));
    if let Err(error) = joiner.apply(&snapshot) {
        return Some(format!("the snapshot is refused: {error}"));
    }
    if crdt_fingerprint(&joiner) != crdt_fingerprint(replica) || joiner.visible_graph() != *graph {
        return Some("the late joiner differs".to_owned());
    }
    None
}

pub(super) fn quiescent_replicas_converge(model: &ConvergenceModel, state: &State) -> bool {
    if !(budgets_spent(&model.inner.cfg, state) && quiescent(state)) {
        return true;
    }
    let replicas = settled_replicas(&model.inner.cfg, state);
    replicas.windows(2).all(|pair| pair[0].digest() == pair[1].digest())
}

pub(super) fn quiescent_replicas_match_spec(model: &ConvergenceModel, state: &State) -> bool {
    if !(budgets_spent(&model.inner.cfg, state) && quiescent(state)) {
        return true;
    }
    let ops = all_ops(&model.inner.cfg, state);
    let expected = spec::visible_graph(&ops);
    let settled = settled_replicas(&model.inner.cfg, state);
    // Convergence means every operation was applied everywhere, not only equal graphs.
    settled.iter().all(|r| r.visible_graph() == expected && ops.iter().all(|op| r.applied().contains(op.id)))
}

/// A point (mm) the kinematics properties map between frames (off every axis, so no rotation leaves it fixed).
const PROBE_MM: [f64; 3] = [1.0, 2.0, 3.0];

/// A point in a child's frame mapped into its parent's, from the documented convention alone (the `dsr::kinematics`
/// module docs): `p' = t + Rx(a) · Ry(b) · Rz(c) · p`, in mm and rad; no `dsr::kinematics` code involved.
fn child_to_parent(translation: [f64; 3], [a, b, c]: [f64; 3], point: [f64; 3]) -> [f64; 3] {
    let rotate = |axis: usize, angle: f64, p: [f64; 3]| {
        let (sin, cos) = angle.sin_cos();
        let (i, j) = ((axis + 1) % 3, (axis + 2) % 3);
        let mut out = p;
        out[i] = cos * p[i] - sin * p[j];
        out[j] = sin * p[i] + cos * p[j];
        out
    };
    let rotated = rotate(0, a, rotate(1, b, rotate(2, c, point)));
    [rotated[0] + translation[0], rotated[1] + translation[1], rotated[2] + translation[2]]
}

/// Every visible node's frame mapped into every other's by the replica's kinematics ([`Replica::transform_point`]),
/// errors as text.
fn transforms(replica: &Replica, graph: &VisibleGraph) -> Vec<Result<[f64; 3], String>> {
    let nodes: Vec<NodeId> = graph.nodes.keys().copied().collect();
    nodes
        .iter()
        .flat_map(|&from| nodes.iter().map(move |&to| (from, to)))
        .map(|(from, to)| replica.transform_point(from, to, PROBE_MM).map_err(|e| e.to_string()))
        .collect()
}

/// Whether every visible RT edge's child maps into its parent's frame by the edge's shown (winning) translation and
/// rotation.
fn rt_edges_match_shown_poses(replica: &Replica, graph: &VisibleGraph) -> bool {
    let vector = |attrs: &BTreeMap<dsr::Name, dsr::VisibleAttr>, name: &str| match attrs.get(name).map(|a| &a.value) {
        Some(dsr::Value::VecF32(v)) if v.len() == 3 => Some([f64::from(v[0]), f64::from(v[1]), f64::from(v[2])]),
        _ => None,
    };
    graph.edges.iter().filter(|(key, _)| key.edge_type.as_str() == "RT").all(|(key, attrs)| {
        let translation = vector(attrs, dsr::attrs::RT_TRANSLATION.name());
        let rotation = vector(attrs, dsr::attrs::RT_ROTATION_EULER_XYZ.name());
        let (Some(translation), Some(rotation)) = (translation, rotation) else { return false };
        let expected = child_to_parent(translation, rotation, PROBE_MM);
        replica
            .transform_point(key.to, key.from, PROBE_MM)
            .is_ok_and(|p| p.iter().zip(expected).all(|(a, b)| (a - b).abs() < 1e-6))
    })
}

/// Every visible node's frame mapped into every other's by `s`'s replica, computed once per replica state.
fn transforms_of(s: &super::ReplicaState) -> &[Result<[f64; 3], String>] {
    s.findings.transforms.get_or_init(|| transforms(&s.replica, &s.graph.0))
}

pub(super) fn kinematics_agree(_: &ConvergenceModel, state: &State) -> bool {
    let replicas = &state.actor_states;
    let each =
        replicas.iter().all(|s| *s.findings.poses.get_or_init(|| rt_edges_match_shown_poses(&s.replica, &s.graph.0)));
    each && (0..replicas.len()).all(|a| {
        (a + 1..replicas.len())
            .all(|b| replicas[a].seen != replicas[b].seen || transforms_of(&replicas[a]) == transforms_of(&replicas[b]))
    })
}

pub(super) fn conflicts_happen(model: &ConvergenceModel, state: &State) -> bool {
    // Stateright evaluates a `sometimes` property on every state even after its first witness, and keeps the first
    // witness it was given; this one builds a causal order per state, so once witnessed it is not computed again.
    let witnessed = &model.inner.cfg.cache.conflict_witnessed;
    if witnessed.load(Ordering::Relaxed) {
        return false;
    }
    let ops = all_ops(&model.inner.cfg, state);
    let order = spec::CausalOrder::new(&ops);
    let found = ops.iter().enumerate().any(|(i, a)| {
        ops[i + 1..]
            .iter()
            .any(|b| a.replica != b.replica && order.concurrent(a.id, b.id) && spec::conflict(&a.kind, &b.kind))
    });
    if found {
        witnessed.store(true, Ordering::Relaxed);
    }
    found
}

pub(super) fn rt_moved(model: &ConvergenceModel, state: &State) -> bool {
    // A move needs three operations: the node, the RT edge to it, the move.
    model.setup().config.ops < 3
        || state.actor_states.iter().flat_map(|s| &s.issued).any(|op| {
        matches!(&op.record.kind, OpKind::SetAttr { name, .. } if name.as_str() == dsr::attrs::RT_TRANSLATION.name())
    })
}

pub(super) fn snapshot_answered(model: &ConvergenceModel, state: &State) -> bool {
    // Vacuous without announces; with them, a history too short for the gap must be seen to fall back.
    model.setup().config.syncs == 0 || state.network.iter_all().any(|e| matches!(e.msg, Msg::Snapshot { .. }))
}

pub(super) fn quiescent_end_reached(model: &ConvergenceModel, state: &State) -> bool {
    budgets_spent(&model.inner.cfg, state) && quiescent(state)
}
