//! The fast path of a late joiner's first snapshot ([`Replica::install`]) against the general join (and
//! [`Replica::encode_snapshot`] against encoding a copied snapshot): random
//! histories on three replicas with partial delivery (so snapshots hold concurrent values, deletions and
//! tombstones), snapshots perturbed into shapes the general join must tidy (repeated or unsorted dots, tombstoned
//! nodes still listed, empty cores, presences and registers), joined both ways into fresh replicas with change
//! tracking on or off. Everything must be equal: the replicated state, the derived indices, the digest, the applied
//! operations, the change events and the invariant verdict.

use std::sync::Arc;

use proptest::prelude::*;

use super::*;
use crate::delta::Delta;
use crate::ids::Element;
use crate::store::Register;
use crate::value::Value;

/// One operation or delivery of a random history. Indices are reduced modulo what exists when it runs.
#[derive(Clone, Debug)]
pub(super) enum Step {
    InsertNode { replica: usize, name: usize },
    DeleteNode { replica: usize, pick: usize },
    InsertEdge { replica: usize, from: usize, to: usize },
    DeleteEdge { replica: usize, pick: usize },
    SetAttr { replica: usize, pick: usize, on_edge: bool, value: i32 },
    RemoveAttr { replica: usize, pick: usize },
    Deliver { pick: usize },
}

pub(super) fn step() -> impl Strategy<Value = Step> {
    let r = 0..3usize;
    prop_oneof![
        3 => (r.clone(), 0..5usize).prop_map(|(replica, name)| Step::InsertNode { replica, name }),
        1 => (r.clone(), any::<usize>()).prop_map(|(replica, pick)| Step::DeleteNode { replica, pick }),
        3 => (r.clone(), any::<usize>(), any::<usize>()).prop_map(|(replica, from, to)| Step::InsertEdge {
            replica,
            from,
            to
        }),
        1 => (r.clone(), any::<usize>()).prop_map(|(replica, pick)| Step::DeleteEdge { replica, pick }),
        4 => (r.clone(), any::<usize>(), any::<bool>(), -3..3i32)
            .prop_map(|(replica, pick, on_edge, value)| Step::SetAttr { replica, pick, on_edge, value }),
        1 => (r, any::<usize>()).prop_map(|(replica, pick)| Step::RemoveAttr { replica, pick }),
        5 => any::<usize>().prop_map(|pick| Step::Deliver { pick }),
    ]
}

/// A change to a snapshot that a decoder accepts or a sender could produce, which the join must tidy.
#[derive(Clone, Debug)]
enum Perturb {
    RepeatValue { pick: usize },
    ReverseValues { pick: usize },
    TombstoneListedNode { pick: usize },
    ClearCore { pick: usize },
    ClearPresence { pick: usize },
    EmptyRegister { pick: usize },
}

fn perturb() -> impl Strategy<Value = Perturb> {
    prop_oneof![
        any::<usize>().prop_map(|pick| Perturb::RepeatValue { pick }),
        any::<usize>().prop_map(|pick| Perturb::ReverseValues { pick }),
        any::<usize>().prop_map(|pick| Perturb::TombstoneListedNode { pick }),
        any::<usize>().prop_map(|pick| Perturb::ClearCore { pick }),
        any::<usize>().prop_map(|pick| Perturb::ClearPresence { pick }),
        any::<usize>().prop_map(|pick| Perturb::EmptyRegister { pick }),
    ]
}

fn run(steps: &[Step]) -> Vec<Replica> {
    run_with(steps, |_, _| {})
}

/// Runs a random history; `delivering` sees each delivery's receiver and delta just before the join.
pub(super) fn run_with(steps: &[Step], mut delivering: impl FnMut(&Replica, &Delta)) -> Vec<Replica> {
    let mut replicas: Vec<Replica> = (1..=3).map(|id| Replica::new(ReplicaId(id))).collect();
    let mut in_flight: Vec<(usize, Arc<Delta>)> = Vec::new();
    for (now, step) in (1u64..).zip(steps) {
        // Slow time, so stamps tie and the replica-id tie-break is exercised.
        let now = now / 3;
        let node = |r: &Replica, pick: usize| {
            let ids: Vec<NodeId> = r.nodes().map(|n| n.id()).collect();
            (!ids.is_empty()).then(|| ids[pick % ids.len()])
        };
        let edge = |r: &Replica, pick: usize| {
            let keys: Vec<EdgeKey> = r.edges().map(|e| e.key().clone()).collect();
            (!keys.is_empty()).then(|| keys[pick % keys.len()].clone())
        };
        let made: Option<(usize, Arc<Delta>)> = match *step {
            Step::InsertNode { replica, name } => replicas[replica]
                .insert_node(now, NewNode::new("object", &format!("n{name}")).with_attr("level", 1))
                .ok()
                .map(|(_, d)| (replica, d)),
            Step::DeleteNode { replica, pick } => node(&replicas[replica], pick)
                .and_then(|id| replicas[replica].delete_node(now, id).ok())
                .map(|d| (replica, d)),
            Step::InsertEdge { replica, from, to } => {
                match (node(&replicas[replica], from), node(&replicas[replica], to)) {
                    (Some(from), Some(to)) => replicas[replica]
                        .insert_edge(now, from, to, "RT", vec![("level".to_owned(), Value::I32(7))])
                        .ok()
                        .map(|(_, d)| (replica, d)),
                    _ => None,
                }
            }
            Step::DeleteEdge { replica, pick } => edge(&replicas[replica], pick)
                .and_then(|key| replicas[replica].delete_edge(now, &key).ok())
                .map(|d| (replica, d)),
            Step::SetAttr { replica, pick, on_edge, value } => {
                let element = if on_edge {
                    edge(&replicas[replica], pick).map(Element::Edge)
                } else {
                    node(&replicas[replica], pick).map(Element::Node)
                };
                element
                    .and_then(|e| replicas[replica].set_attrs(now, e, [("pos_x", Value::F32(value as f32))]).ok())
                    .map(|d| (replica, d))
            }
            Step::RemoveAttr { replica, pick } => node(&replicas[replica], pick)
                .and_then(|id| replicas[replica].remove_attr(now, id, "level").ok())
                .map(|d| (replica, d)),
            Step::Deliver { pick } => {
                if !in_flight.is_empty() {
                    let (to, delta) = in_flight.swap_remove(pick % in_flight.len());
                    delivering(&replicas[to], &delta);
                    replicas[to].apply(&delta).expect("our own deltas apply");
                }
                None
            }
        };
        if let Some((from, delta)) = made {
            for to in (0..3).filter(|to| *to != from) {
                in_flight.push((to, Arc::clone(&delta)));
            }
        }
    }
    replicas
}

fn apply_perturbation(snapshot: &mut Delta, perturbation: &Perturb) {
    let store = &mut snapshot.store;
    let node_ids: Vec<NodeId> = store.nodes.keys().copied().collect();
    let edge_keys: Vec<EdgeKey> = store.edges.keys().cloned().collect();
    let pick_node = |pick: usize| (!node_ids.is_empty()).then(|| node_ids[pick % node_ids.len()]);
    let pick_edge = |pick: usize| (!edge_keys.is_empty()).then(|| edge_keys[pick % edge_keys.len()].clone());
    match *perturbation {
        Perturb::RepeatValue { pick } => {
            if let Some(id) = pick_node(pick)
                && let Some(register) = store.nodes.get_mut(&id).and_then(|n| n.attrs.values_mut().next())
                && let Some(first) = register.values.first().cloned()
            {
                register.values.push(first);
            }
        }
        Perturb::ReverseValues { pick } => {
            if let Some(id) = pick_node(pick)
                && let Some(node) = store.nodes.get_mut(&id)
            {
                node.core.values.reverse();
                for register in node.attrs.values_mut() {
                    register.values.reverse();
                }
            }
        }
        Perturb::TombstoneListedNode { pick } => {
            if let Some(id) = pick_node(pick) {
                store.tombstones.insert(id);
            }
        }
        Perturb::ClearCore { pick } => {
            if let Some(id) = pick_node(pick)
                && let Some(node) = store.nodes.get_mut(&id)
            {
                node.core.values.clear();
            }
        }
        Perturb::ClearPresence { pick } => {
            if let Some(key) = pick_edge(pick)
                && let Some(edge) = store.edges.get_mut(&key)
            {
                edge.presence.values.clear();
            }
        }
        Perturb::EmptyRegister { pick } => {
            if let Some(id) = pick_node(pick)
                && let Some(node) = store.nodes.get_mut(&id)
            {
                node.attrs.insert(Name::from("pos_y"), Register::default());
            }
        }
    }
}

/// Joins `snapshot` into fresh replicas through the fast path and through the general join, and checks that
/// everything observable is equal.
fn assert_same_join(snapshot: &Delta, tracking: bool, shared: bool) -> Result<(), TestCaseError> {
    let fresh = || {
        let mut replica = Replica::new(ReplicaId(9));
        replica.set_change_tracking(tracking);
        replica
    };
    let mut general = fresh();
    prop_assert!(general.can_install(snapshot), "a fresh replica takes the fast path for a snapshot");
    let general_result = general.apply_inner(snapshot, || Arc::new(snapshot.clone())).map_err(|e| e.to_string());
    let mut fast = fresh();
    let fast_result = if shared { fast.apply_shared(Arc::new(snapshot.clone())) } else { fast.apply(snapshot) }
        .map_err(|e| e.to_string());
    prop_assert_eq!(&fast_result, &general_result);
    prop_assert_eq!(&fast, &general);
    prop_assert_eq!(&fast.store, &general.store);
    prop_assert_eq!(&fast.ctx, &general.ctx);
    prop_assert_eq!(&fast.applied, &general.applied);
    prop_assert_eq!(fast.clock, general.clock);
    prop_assert_eq!(&fast.out_edges, &general.out_edges);
    prop_assert_eq!(&fast.in_edges, &general.in_edges);
    prop_assert_eq!(&fast.names, &general.names);
    prop_assert_eq!(&fast.indexed_names, &general.indexed_names);
    prop_assert_eq!(fast.digest(), general.digest());
    prop_assert_eq!(fast.visible_graph(), general.visible_graph());
    prop_assert_eq!(fast.check_invariants(), general.check_invariants());
    prop_assert_eq!(fast.drain_changes(), general.drain_changes());
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 256, ..ProptestConfig::default() })]

    /// Installing a snapshot into a fresh replica gives exactly the general join's replica, for snapshots of
    /// random histories, as sent and after a wire round trip.
    #[test]
    fn install_equals_the_general_join(
        steps in prop::collection::vec(step(), 1..60),
        from in 0..3usize,
        tracking in any::<bool>(),
        shared in any::<bool>(),
    ) {
        let replicas = run(&steps);
        let snapshot = replicas[from].snapshot();
        prop_assert_eq!(replicas[from].encode_snapshot(), snapshot.encode(), "the snapshot encodes the same without a copy");
        assert_same_join(&snapshot, tracking, shared)?;
        let decoded = Delta::decode(&snapshot.encode()).expect("our own snapshots decode");
        assert_same_join(&decoded, tracking, shared)?;
    }

    /// The same holds for snapshots with repeated or unsorted dots, tombstoned nodes still listed, and empty
    /// cores, presences and registers.
    #[test]
    fn install_equals_the_general_join_on_untidy_snapshots(
        steps in prop::collection::vec(step(), 1..60),
        from in 0..3usize,
        perturbations in prop::collection::vec(perturb(), 1..6),
        tracking in any::<bool>(),
    ) {
        let replicas = run(&steps);
        let mut snapshot = replicas[from].snapshot();
        for perturbation in &perturbations {
            apply_perturbation(&mut snapshot, perturbation);
        }
        assert_same_join(&snapshot, tracking, false)?;
    }
}

/// A replica that holds anything, or a delta that is not a snapshot, goes through the general join.
#[test]
fn only_a_fresh_replica_and_a_snapshot_take_the_fast_path() {
    let mut writer = Replica::new(ReplicaId(1));
    let (_, delta) = writer.insert_node(1, NewNode::new("world", "w")).unwrap();
    let fresh = Replica::new(ReplicaId(2));
    assert!(fresh.can_install(&writer.snapshot()));
    assert!(!fresh.can_install(&delta), "a delta of one operation is no snapshot");
    let mut used = Replica::new(ReplicaId(2));
    used.apply(&delta).unwrap();
    assert!(!used.can_install(&writer.snapshot()), "a replica that holds something joins the general way");
}

/// The network is not refused for names or types: a known name with another type or an unknown node type, late
/// in a snapshot, is learned the same way by the fast path and the general join; a name that cannot be held (a
/// control character) is refused by both, and the replica is unchanged.
#[test]
fn names_of_a_snapshot_are_learned_or_refused_alike_on_both_paths() {
    for case in 0..3 {
        let mut writer = Replica::new(ReplicaId(1));
        let mut last = NodeId(0);
        for (i, name) in ["a", "b", "c"].into_iter().enumerate() {
            let node = NewNode::new("object", name).with_attr("pos_x", i as f32);
            last = writer.insert_node(i as u64 + 1, node).unwrap().0;
        }
        let mut snapshot = writer.snapshot();
        let node = snapshot.store.nodes.get_mut(&last).unwrap();
        match case {
            0 => node.attrs.get_mut("pos_x").unwrap().values[0].value = Value::I32(7),
            1 => node.core.values[0].value.node_type = Name::from("no_such_type"),
            _ => node.core.values[0].value.node_type = Name::from("bad\ntype"),
        }
        let mut general = Replica::new(ReplicaId(2));
        let general_result = general.apply_inner(&snapshot, || Arc::new(snapshot.clone()));
        let mut fast = Replica::new(ReplicaId(2));
        let fast_result = fast.apply(&snapshot);
        assert_eq!(fast_result, general_result, "case {case}");
        assert_eq!(fast.digest(), general.digest(), "case {case}");
        match case {
            0 => assert_eq!(fast.dictionary().learned_types("pos_x"), [crate::value::ValueType::I32]),
            1 => assert!(fast.dictionary().known_node_type("no_such_type").is_some()),
            _ => {
                let error = fast_result.unwrap_err().to_string();
                assert!(error.contains(&format!("node {last}")), "{error}");
                assert_eq!(fast, Replica::new(ReplicaId(2)), "the replica is unchanged");
            }
        }
    }
}
