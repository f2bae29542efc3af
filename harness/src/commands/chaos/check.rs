//! The campaign's verdict on what it recorded: the agents converged, nothing was lost, nothing unrecorded
//! appeared, and the final graph is the one the reference specification (`model::spec`) gives for the whole
//! recorded history.
//!
//! The rules, in order:
//!
//! 1. **Converged**: every agent running at the end is in the same graph, has the same digest and has applied the
//!    same operations.
//! 2. **Nothing lost**: every recorded write is among the applied operations, except a write of a killed life that
//!    no surviving life had applied when it wrote (recorded in that write's `past`): such a write may have died
//!    with its process before it left it (an agent keeps no durable log), and is counted, not failed.
//! 3. **Nothing unrecorded**: every applied dot belongs to a recorded write (a dot of nobody's write would be a
//!    resurrected or invented operation).
//! 4. **The specification's graph**: the full digest of the final graph equals the digest of
//!    `model::spec::visible_graph` over the recorded writes that were applied, each with the operations its
//!    replica had applied when it was made as its past. Stamps must also follow causality (`spec::check_stamps`).
//! 5. **Joiners served** ([`check_joins`]): no life started alone (a graph of its own, merged only by anti-entropy)
//!    while another agent had the graph, ran, was not stopped and could reach it when the life started: the
//!    agents model's "a joiner with a ready peer alive joins its graph, not alone", on real processes. Not in a
//!    secured campaign, whose DDS Security handshake outlasts the join wait.

use std::collections::{BTreeMap, BTreeSet};

use dsr::{CausalContext, Dot, EdgeKey, Name, ReplicaId, Stamp};
use model::spec::{self, OpKind, OpRecord};
use serde::{Deserialize, Serialize};

use super::protocol::{FinalState, RecordedOp, WriteRecord};
use super::record::ReadyLife;
use super::workload::value_of;

/// The verdict's figures.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Verdict {
    /// Writes recorded (and checked).
    pub writes: usize,
    /// Writes found in the final graph's applied operations.
    pub applied: usize,
    /// Writes of killed lives that never left their process (allowed).
    pub lost_with_killed_writer: usize,
    /// Agents whose final state was compared.
    pub agents_compared: usize,
    /// Visible nodes and edges of the final graph.
    pub final_nodes: usize,
    /// Visible edges of the final graph.
    pub final_edges: usize,
    /// What went wrong; empty when the campaign passed.
    pub violations: Vec<String>,
}

impl Verdict {
    /// Whether the campaign passed.
    pub fn passed(&self) -> bool {
        self.violations.is_empty()
    }
}

fn op_kind(op: &RecordedOp) -> OpKind {
    let attrs = |attrs: &[(String, super::protocol::RecordedValue)]| {
        attrs.iter().map(|(n, v)| (Name::new(n), value_of(v))).collect()
    };
    match op {
        RecordedOp::InsertNode { id, node_type, name, attrs: a } => {
            OpKind::InsertNode { id: *id, node_type: Name::new(node_type), name: Name::new(name), attrs: attrs(a) }
        }
        RecordedOp::DeleteNode { id } => OpKind::DeleteNode { id: *id },
        RecordedOp::InsertEdge { from, to, edge_type } => {
            OpKind::InsertEdge { key: EdgeKey::new(*from, *to, edge_type), attrs: Vec::new() }
        }
        RecordedOp::DeleteEdge { from, to, edge_type } => {
            OpKind::DeleteEdge { key: EdgeKey::new(*from, *to, edge_type) }
        }
        RecordedOp::SetAttr { element, name, value } => {
            OpKind::SetAttr { element: element.clone(), name: Name::new(name), value: value_of(value) }
        }
        RecordedOp::RemoveAttr { element, name } => {
            OpKind::RemoveAttr { element: element.clone(), name: Name::new(name) }
        }
    }
}

fn id_of(write: &WriteRecord) -> Dot {
    Dot::new(ReplicaId(write.replica), write.first)
}

/// The specification's operations for `writes`: each write's past is the recorded writes its replica had applied.
pub fn op_records(writes: &[&WriteRecord]) -> Vec<OpRecord> {
    writes
        .iter()
        .map(|w| OpRecord {
            id: id_of(w),
            replica: ReplicaId(w.replica),
            stamp: Stamp(w.stamp),
            past: writes.iter().map(|x| id_of(x)).filter(|id| w.past.contains(*id)).collect(),
            kind: op_kind(&w.op),
        })
        .collect()
}

fn graph_name(graph: Option<agent::GraphId>) -> String {
    graph.map_or_else(|| "none".into(), |g| g.to_string())
}

/// Checks a campaign's record; `killed` are the replica ids of lives that were killed.
pub fn check(writes: &[WriteRecord], killed: &[u32], finals: &[(usize, FinalState)]) -> Verdict {
    let mut verdict = Verdict { writes: writes.len(), agents_compared: finals.len(), ..Verdict::default() };
    let Some((first_slot, first)) = finals.first() else {
        verdict.violations.push("no agent gave a final state".into());
        return verdict;
    };
    let (Some(applied), Some(digest)) = (&first.applied, &first.full_digest) else {
        verdict.violations.push(format!("agent {first_slot} ended without a graph"));
        return verdict;
    };
    for (slot, state) in &finals[1..] {
        if state.graph != first.graph {
            verdict.violations.push(format!(
                "agent {slot} ended in graph {}, agent {first_slot} in graph {}",
                graph_name(state.graph),
                graph_name(first.graph)
            ));
        }
        if state.full_digest.as_ref() != Some(digest) || state.applied.as_ref() != Some(applied) {
            verdict.violations.push(format!(
                "agent {slot} ended with digest {} ({} nodes), agent {first_slot} with {} ({} nodes)",
                state.digest.as_deref().unwrap_or("none"),
                state.nodes,
                first.digest.as_deref().unwrap_or("none"),
                first.nodes
            ));
        }
    }
    verdict.final_nodes = first.nodes;
    verdict.final_edges = first.edges;
    lost_writes(writes, killed, applied, &mut verdict);
    unrecorded_dots(writes, applied, &mut verdict);
    let kept: Vec<&WriteRecord> = writes.iter().filter(|w| applied.contains(id_of(w))).collect();
    verdict.applied = kept.len();
    let ops = op_records(&kept);
    if let Err(error) = spec::check_stamps(&ops) {
        verdict.violations.push(format!("stamps: {error}"));
    }
    let expected = spec::visible_graph(&ops);
    let expected_digest: String = expected.digest().0.iter().map(|b| format!("{b:02x}")).collect();
    if &expected_digest != digest {
        verdict.violations.push(format!(
            "the final graph ({} nodes, {} edges, digest {}) is not the specification's for the {} applied writes \
             ({} nodes, {} edges, digest {})",
            first.nodes,
            first.edges,
            &digest[..16],
            kept.len(),
            expected.nodes.len(),
            expected.edges.len(),
            &expected_digest[..16]
        ));
    }
    verdict
}

/// Rule 5 of the module documentation, over every life that got its graph.
pub fn check_joins(lives: &[ReadyLife], verdict: &mut Verdict) {
    for life in lives.iter().filter(|life| life.alone && !life.ready_peers.is_empty()) {
        let peers: Vec<String> = life.ready_peers.iter().map(|slot| format!("a{slot}")).collect();
        verdict.violations.push(format!(
            "agent {} life {} started alone, although {} had the graph, ran and could reach it when it started",
            life.slot,
            life.life,
            peers.join(", ")
        ));
    }
}

fn lost_writes(writes: &[WriteRecord], killed: &[u32], applied: &CausalContext, verdict: &mut Verdict) {
    let killed: BTreeSet<u32> = killed.iter().copied().collect();
    for write in writes.iter().filter(|w| !applied.contains(id_of(w))) {
        let seen_by_survivor =
            writes.iter().any(|later| !killed.contains(&later.replica) && later.past.contains(id_of(write)));
        if killed.contains(&write.replica) && !seen_by_survivor {
            verdict.lost_with_killed_writer += 1;
        } else {
            verdict.violations.push(format!(
                "write {} ({} by agent {}, replica {}) is lost: {}",
                write.seq,
                write.op.kind(),
                write.agent,
                write.replica,
                if killed.contains(&write.replica) {
                    "a surviving agent had applied it"
                } else {
                    "its writer survived"
                }
            ));
        }
    }
}

fn unrecorded_dots(writes: &[WriteRecord], applied: &CausalContext, verdict: &mut Verdict) {
    let mut recorded: BTreeMap<u32, Vec<(u64, u64)>> = BTreeMap::new();
    for w in writes {
        recorded.entry(w.replica).or_default().push((w.first, w.last));
    }
    let mut unknown = 0;
    let mut example = None;
    for dot in applied.dots() {
        let known =
            recorded.get(&dot.replica.0).is_some_and(|r| r.iter().any(|(a, b)| (*a..=*b).contains(&dot.counter)));
        if !known {
            unknown += 1;
            example.get_or_insert(dot);
        }
    }
    if let Some(dot) = example {
        verdict.violations.push(format!("{unknown} applied dots belong to no recorded write (e.g. {dot})"));
    }
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use dsr::{Delta, Element, Replica};
    use transport::rng::SplitMix64;

    use super::super::serve::final_state_of;
    use super::super::workload::Workload;
    use super::*;

    /// Three replicas write with the campaign's workload; each delta reaches the others late and in a shuffled
    /// order; at the end everything is delivered. Returns the records and the replicas.
    fn simulate(seed: u64, writes: u64) -> (Vec<WriteRecord>, Vec<Replica>) {
        simulate_withholding(seed, writes, None)
    }

    /// As [`simulate`], but write `withhold` never reaches the third replica.
    fn simulate_withholding(seed: u64, writes: u64, withhold: Option<u64>) -> (Vec<WriteRecord>, Vec<Replica>) {
        let mut replicas: Vec<Replica> = (1..=3).map(|r| Replica::new(ReplicaId(r))).collect();
        let mut rng = SplitMix64::new(seed);
        let mut in_flight: Vec<(usize, Arc<Delta>)> = Vec::new();
        let mut records = Vec::new();
        for seq in 1..=writes {
            let writer = if withhold == Some(seq) { 0 } else { rng.range(0, 2) as usize };
            let workload = Workload { agent: writer as u32, image_bytes: 64 };
            let (record, delta) = workload.write(&mut replicas[writer], seq * 1_000, seq, rng.next_u64()).unwrap();
            records.push(record);
            for to in (0..3).filter(|to| *to != writer && !(withhold == Some(seq) && *to == 2)) {
                in_flight.push((to, Arc::clone(&delta)));
            }
            while !in_flight.is_empty() && rng.chance(0.6) {
                let (to, delta) = in_flight.swap_remove(rng.range(0, in_flight.len() as u64 - 1) as usize);
                replicas[to].apply(&delta).unwrap();
            }
        }
        for (to, delta) in in_flight {
            replicas[to].apply(&delta).unwrap();
        }
        (records, replicas)
    }

    fn finals(replicas: &[Replica]) -> Vec<(usize, FinalState)> {
        replicas.iter().enumerate().map(|(i, r)| (i, final_state_of(r))).collect()
    }

    #[test]
    fn a_converged_history_passes_with_every_write_checked() {
        for seed in 0..4 {
            let (records, replicas) = simulate(seed, 150);
            let verdict = check(&records, &[], &finals(&replicas));
            assert!(verdict.passed(), "seed {seed}: {:?}", verdict.violations);
            assert_eq!((verdict.writes, verdict.applied), (150, 150));
            let kinds: BTreeSet<&str> = records.iter().map(|r| r.op.kind()).collect();
            assert!(kinds.len() >= 6, "the workload makes every kind of write: {kinds:?}");
        }
    }

    #[test]
    fn a_replica_that_missed_a_write_is_caught() {
        let (records, replicas) = simulate_withholding(1, 80, Some(40));
        let verdict = check(&records, &[], &finals(&replicas));
        assert!(verdict.violations.iter().any(|v| v.contains("ended with digest")), "{:?}", verdict.violations);
    }

    /// Two agents with equal graphs in different graph ids have not converged: they refuse each other's deltas.
    #[test]
    fn equal_graphs_in_two_graph_ids_are_caught() {
        let (records, replicas) = simulate(3, 40);
        let mut states = finals(&replicas);
        for (slot, state) in &mut states {
            state.graph = Some(agent::GraphId::from_nonce(if *slot == 2 { 9 } else { 5 }));
        }
        let verdict = check(&records, &[], &states);
        assert_eq!(verdict.violations.len(), 1, "{:?}", verdict.violations);
        assert!(verdict.violations[0].starts_with("agent 2 ended in graph"), "{:?}", verdict.violations);
        states[2].1.graph = states[0].1.graph;
        assert!(check(&records, &[], &states).passed());
    }

    #[test]
    fn a_lost_write_of_a_surviving_writer_fails_and_of_a_killed_one_is_counted() {
        let (mut records, replicas) = simulate(2, 60);
        // A write nobody applied: replica 7 wrote it and the write never left.
        let mut ghost = records[0].clone();
        ghost.replica = 7;
        ghost.seq = 999;
        records.push(ghost);
        let verdict = check(&records, &[], &finals(&replicas));
        assert!(verdict.violations.iter().any(|v| v.contains("write 999") && v.contains("its writer survived")));
        let verdict = check(&records, &[7], &finals(&replicas));
        assert!(verdict.passed(), "{:?}", verdict.violations);
        assert_eq!(verdict.lost_with_killed_writer, 1);
        // Had a surviving life applied it before writing, it must have survived too.
        let ghost_dot = Dot::new(ReplicaId(7), records[0].first);
        records[10].past.insert(ghost_dot);
        let verdict = check(&records, &[7], &finals(&replicas));
        assert!(verdict.violations.iter().any(|v| v.contains("a surviving agent had applied it")), "{verdict:?}");
    }

    #[test]
    fn an_unrecorded_operation_and_a_wrong_value_are_caught() {
        let (records, replicas) = simulate(3, 60);
        let mut missing = records.clone();
        let dropped = missing.remove(20);
        let verdict = check(&missing, &[], &finals(&replicas));
        assert!(
            verdict.violations.iter().any(|v| v.contains("belong to no recorded write")),
            "dropping write {} from the history: {:?}",
            dropped.seq,
            verdict.violations
        );
        let mut changed = records.clone();
        // A write whose value the final graph shows.
        let shown = replicas[0].visible_graph();
        let at = changed
            .iter()
            .rposition(|r| match &r.op {
                RecordedOp::SetAttr { element: Element::Node(id), name, value } => shown
                    .nodes
                    .get(id)
                    .is_some_and(|n| n.attrs.get(&Name::new(name)).is_some_and(|a| a.value == value_of(value))),
                _ => false,
            })
            .unwrap();
        if let RecordedOp::SetAttr { value, .. } = &mut changed[at].op {
            *value = super::super::protocol::RecordedValue::Plain(dsr::Value::F32(-1.0));
        }
        let verdict = check(&changed, &[], &finals(&replicas));
        assert!(verdict.violations.iter().any(|v| v.contains("not the specification's")), "{:?}", verdict.violations);
    }

    #[test]
    fn agents_that_ended_apart_are_caught() {
        let (records, mut replicas) = simulate(4, 40);
        let workload = Workload { agent: 0, image_bytes: 8 };
        let (record, _delta) = workload.write(&mut replicas[0], 1 << 40, 41, 5).unwrap();
        let mut records = records;
        records.push(record);
        let verdict = check(&records, &[], &finals(&replicas));
        assert!(verdict.violations.iter().any(|v| v.contains("ended with digest")), "{:?}", verdict.violations);
    }

    #[test]
    fn a_life_that_started_alone_beside_a_reachable_ready_agent_is_caught_and_one_with_none_is_not() {
        let life = |slot, alone, ready_peers: Vec<usize>| ReadyLife { slot, life: 1, alone, ready_peers };
        let mut verdict = Verdict::default();
        // The first agents of a campaign start together, none has a graph: alone is right. A joiner that took the
        // graph is right too.
        check_joins(&[life(0, true, vec![]), life(1, true, vec![]), life(2, false, vec![0, 1])], &mut verdict);
        assert!(verdict.passed(), "{:?}", verdict.violations);
        check_joins(&[life(2, true, vec![0, 1])], &mut verdict);
        assert_eq!(
            verdict.violations,
            ["agent 2 life 1 started alone, although a0, a1 had the graph, ran and could reach it when it started"]
        );
    }
}
