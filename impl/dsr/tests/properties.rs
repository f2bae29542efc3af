//! Property tests: lattice laws of the join, convergence under any delivery order with duplicates, the graph
//! invariants after every step, and decoding of arbitrary bytes.
//!
//! Every step of a random run walks the full invariants of every replica (`Replica::check_invariants`).

use std::sync::Arc;

use dsr::{Delta, EdgeKey, Element, NewNode, NodeId, Replica, ReplicaId, Value};
use proptest::prelude::*;
use proptest::test_runner::FileFailurePersistence;

const NAMES: [&str; 4] = ["a", "b", "c", "d"];
const EDGE_TYPES: [&str; 2] = ["in", "RT"];

/// One step of a random run. Indices are reduced modulo what exists when the step runs.
#[derive(Clone, Debug)]
enum Step {
    InsertNode { replica: usize, name: usize },
    DeleteNode { replica: usize, pick: usize },
    InsertEdge { replica: usize, from: usize, to: usize, edge_type: usize },
    DeleteEdge { replica: usize, pick: usize },
    SetAttr { replica: usize, pick: usize, on_edge: bool, attr: usize, value: i32 },
    RemoveAttr { replica: usize, pick: usize, on_edge: bool, attr: usize },
    Deliver { pick: usize },
    Duplicate { pick: usize },
}

fn step() -> impl Strategy<Value = Step> {
    let r = 0..3usize;
    prop_oneof![
        3 => (r.clone(), 0..NAMES.len()).prop_map(|(replica, name)| Step::InsertNode { replica, name }),
        1 => (r.clone(), any::<usize>()).prop_map(|(replica, pick)| Step::DeleteNode { replica, pick }),
        3 => (r.clone(), any::<usize>(), any::<usize>(), 0..2usize)
            .prop_map(|(replica, from, to, edge_type)| Step::InsertEdge { replica, from, to, edge_type }),
        1 => (r.clone(), any::<usize>()).prop_map(|(replica, pick)| Step::DeleteEdge { replica, pick }),
        4 => (r.clone(), any::<usize>(), any::<bool>(), 0..3usize, -3..3i32)
            .prop_map(|(replica, pick, on_edge, attr, value)| Step::SetAttr { replica, pick, on_edge, attr, value }),
        1 => (r, any::<usize>(), any::<bool>(), 0..3usize)
            .prop_map(|(replica, pick, on_edge, attr)| Step::RemoveAttr { replica, pick, on_edge, attr }),
        6 => any::<usize>().prop_map(|pick| Step::Deliver { pick }),
        1 => any::<usize>().prop_map(|pick| Step::Duplicate { pick }),
    ]
}

fn attr(index: usize, value: i32) -> (&'static str, Value) {
    match index {
        0 => ("level", Value::I32(value)),
        1 => ("pos_x", Value::F32(value as f32 * 0.5)),
        _ => ("color", Value::from(format!("c{value}").as_str())),
    }
}

/// Three replicas and a network of in-flight deltas (each a copy addressed to one replica).
struct World {
    replicas: Vec<Replica>,
    in_flight: Vec<(usize, Arc<Delta>)>,
    now: u64,
}

impl World {
    fn new(n: usize) -> Self {
        World {
            replicas: (1..=n as u32).map(|id| Replica::new(ReplicaId(id))).collect(),
            in_flight: Vec::new(),
            now: 0,
        }
    }

    fn broadcast(&mut self, from: usize, delta: Arc<Delta>) {
        for to in 0..self.replicas.len() {
            if to != from {
                self.in_flight.push((to, Arc::clone(&delta)));
            }
        }
    }

    fn pick_node(&self, replica: usize, pick: usize) -> Option<NodeId> {
        let ids: Vec<NodeId> = self.replicas[replica].nodes().map(|n| n.id()).collect();
        (!ids.is_empty()).then(|| ids[pick % ids.len()])
    }

    fn pick_edge(&self, replica: usize, pick: usize) -> Option<EdgeKey> {
        let keys: Vec<EdgeKey> = self.replicas[replica].edges().map(|e| e.key().clone()).collect();
        (!keys.is_empty()).then(|| keys[pick % keys.len()].clone())
    }

    fn pick_element(&self, replica: usize, pick: usize, on_edge: bool) -> Option<Element> {
        if on_edge {
            self.pick_edge(replica, pick).map(Element::Edge)
        } else {
            self.pick_node(replica, pick).map(Element::Node)
        }
    }

    fn run(&mut self, step: &Step) {
        // Time moves slowly so that stamps often tie and the replica-id tie-break is exercised.
        self.now += 1;
        let now = self.now / 3;
        let result = match *step {
            Step::InsertNode { replica, name } => {
                let node = NewNode::new("object", NAMES[name]);
                self.replicas[replica].insert_node(now, node).map(|(_, d)| (replica, d)).ok()
            }
            Step::DeleteNode { replica, pick } => self
                .pick_node(replica, pick)
                .and_then(|id| self.replicas[replica].delete_node(now, id).ok())
                .map(|d| (replica, d)),
            Step::InsertEdge { replica, from, to, edge_type } => {
                let (Some(from), Some(to)) = (self.pick_node(replica, from), self.pick_node(replica, to)) else {
                    return;
                };
                let attrs = vec![("level".to_owned(), Value::I32(7))];
                self.replicas[replica]
                    .insert_edge(now, from, to, EDGE_TYPES[edge_type], attrs)
                    .ok()
                    .map(|(_, d)| (replica, d))
            }
            Step::DeleteEdge { replica, pick } => self
                .pick_edge(replica, pick)
                .and_then(|key| self.replicas[replica].delete_edge(now, &key).ok())
                .map(|d| (replica, d)),
            Step::SetAttr { replica, pick, on_edge, attr: index, value } => self
                .pick_element(replica, pick, on_edge)
                .and_then(|element| self.replicas[replica].set_attrs(now, element, [attr(index, value)]).ok())
                .map(|d| (replica, d)),
            Step::RemoveAttr { replica, pick, on_edge, attr: index } => self
                .pick_element(replica, pick, on_edge)
                .and_then(|element| self.replicas[replica].remove_attr(now, element, attr(index, 0).0).ok())
                .map(|d| (replica, d)),
            Step::Deliver { pick } => {
                if !self.in_flight.is_empty() {
                    let (to, delta) = self.in_flight.swap_remove(pick % self.in_flight.len());
                    self.deliver(to, &delta);
                }
                None
            }
            Step::Duplicate { pick } => {
                if !self.in_flight.is_empty() {
                    let copy = self.in_flight[pick % self.in_flight.len()].clone();
                    self.in_flight.push(copy);
                }
                None
            }
        };
        if let Some((from, delta)) = result {
            self.broadcast(from, delta);
        }
        for replica in &self.replicas {
            replica.check_invariants().unwrap();
        }
    }

    fn deliver(&mut self, to: usize, delta: &Delta) {
        let decoded = Delta::decode(&delta.encode()).expect("our own deltas decode");
        assert_eq!(&decoded, delta, "wire round trip");
        self.replicas[to].apply(&decoded).expect("our own deltas apply");
    }

    fn deliver_all(&mut self, order: &[usize]) {
        let mut i = 0;
        while !self.in_flight.is_empty() {
            let pick = order.get(i).copied().unwrap_or(0);
            i += 1;
            let (to, delta) = self.in_flight.swap_remove(pick % self.in_flight.len());
            self.deliver(to, &delta);
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig {
        cases: 256,
        failure_persistence: Some(Box::new(FileFailurePersistence::Direct("tests/properties.proptest-regressions"))),
        ..ProptestConfig::default()
    })]

    /// Random operations on 3 replicas, delivered in random order with duplicates, converge to equal digests,
    /// and the invariants hold after every step.
    #[test]
    fn random_runs_converge_with_invariants_at_every_step(
        steps in prop::collection::vec(step(), 1..60),
        order in prop::collection::vec(any::<usize>(), 0..200),
    ) {
        let mut world = World::new(3);
        for step in &steps {
            world.run(step);
        }
        world.deliver_all(&order);
        let digest = world.replicas[0].digest();
        for replica in &world.replicas[1..] {
            prop_assert_eq!(replica.digest(), digest);
            prop_assert_eq!(replica.visible_graph(), world.replicas[0].visible_graph());
        }
    }

    /// Join is commutative, associative and idempotent on random states (joined as whole-state snapshots).
    #[test]
    fn join_is_commutative_associative_and_idempotent(steps in prop::collection::vec(step(), 1..50)) {
        let mut world = World::new(3);
        for step in &steps {
            world.run(step);
        }
        let [a, b, c] = [0, 1, 2].map(|i| world.replicas[i].snapshot());
        let join = |states: &[&Delta]| {
            let mut r = Replica::new(ReplicaId(99));
            for s in states {
                r.apply(s).unwrap();
            }
            (r.context().clone(), r.store().clone(), r.digest())
        };
        prop_assert_eq!(join(&[&a, &b]), join(&[&b, &a]));
        prop_assert_eq!(join(&[&a, &b, &c]), join(&[&c, &a, &b]));
        prop_assert_eq!(join(&[&a, &b, &c]), join(&[&b, &c, &a]));
        prop_assert_eq!(join(&[&a, &a, &b]), join(&[&a, &b]));
        // Joining a state into itself changes nothing.
        let mut r = world.replicas[0].clone();
        r.apply(&a).unwrap();
        prop_assert_eq!(r.store(), world.replicas[0].store());
        prop_assert_eq!(r.context(), world.replicas[0].context());
    }

    /// Anti-entropy alone (no broadcast) brings every replica to the same graph.
    #[test]
    fn anti_entropy_alone_converges(
        steps in prop::collection::vec(step(), 1..50),
        fates in prop::collection::vec(any::<bool>(), 64),
        lossy_log in any::<bool>(),
        fold_min_payload_bytes in prop::sample::select(vec![0, 8, usize::MAX]),
    ) {
        let mut world = World::new(3);
        // Every write folds, the larger ones only, or none.
        let mut limits = dsr::LogLimits { fold_min_payload_bytes, ..dsr::LogLimits::default() };
        if lossy_log {
            limits.max_deltas = 2;
        }
        for replica in &mut world.replicas {
            replica.set_log_limits(limits);
        }
        // Each broadcast copy is delivered or lost by a random fate: partial delivery is what makes a replica's
        // causal context run ahead of the operations it has joined.
        let mut fate = fates.iter().cycle();
        for step in &steps {
            world.run(step);
            for (to, delta) in std::mem::take(&mut world.in_flight) {
                if *fate.next().expect("cycled") {
                    world.deliver(to, &delta);
                }
            }
        }
        for _round in 0..2 {
            for from in 0..3 {
                for to in 0..3 {
                    if from == to {
                        continue;
                    }
                    let peer = world.replicas[to].applied().clone();
                    match world.replicas[from].missing_for(&peer) {
                        dsr::Missing::UpToDate => {}
                        dsr::Missing::Deltas(deltas) => {
                            for d in deltas {
                                world.deliver(to, &d);
                            }
                        }
                        dsr::Missing::Snapshot => {
                            let snapshot = world.replicas[from].snapshot();
                            world.deliver(to, &snapshot);
                        }
                    }
                }
            }
        }
        let digest = world.replicas[0].digest();
        for replica in &world.replicas[1..] {
            prop_assert_eq!(replica.digest(), digest);
        }
    }

    /// Decoding arbitrary bytes never panics.
    #[test]
    fn decoding_random_bytes_never_panics(bytes in prop::collection::vec(any::<u8>(), 0..256)) {
        let _ = Delta::decode(&bytes);
    }

    /// Decoding a truncated or bit-flipped real delta never panics, and whatever decodes applies or is refused
    /// without panicking.
    #[test]
    fn decoding_damaged_deltas_never_panics(
        steps in prop::collection::vec(step(), 1..20),
        cut in any::<usize>(),
        flip in any::<(usize, u8)>(),
    ) {
        let mut world = World::new(3);
        for step in &steps {
            world.run(step);
        }
        let bytes = world.replicas[0].snapshot().encode();
        let truncated = &bytes[..cut % (bytes.len() + 1)];
        if let Ok(delta) = Delta::decode(truncated) {
            let _ = world.replicas[1].apply(&delta);
        }
        let mut flipped = bytes.clone();
        let at = flip.0 % flipped.len();
        flipped[at] ^= flip.1 | 1;
        if let Ok(delta) = Delta::decode(&flipped) {
            let _ = world.replicas[2].apply(&delta);
            world.replicas[2].check_invariants().unwrap();
        }
    }
}
