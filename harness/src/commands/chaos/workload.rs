//! What a chaos agent writes: one operation per command, chosen from a seeded draw and the agent's own graph (so it
//! inserts, links, writes and deletes what that agent sees, and agents contend for the same nodes), recorded as the
//! reference specification needs it.
//!
//! The mix, by the draw: inserts of nodes (a quarter of them under one of four names every agent uses, so
//! concurrent inserts contend for a name), attribute writes on nodes and edges, edge inserts and deletes, node
//! deletes (only while more than eight nodes are visible), attribute removals, and camera frames: `cam_rgb` of the
//! agent's own camera node, [`Workload::image_bytes`] bytes generated from the draw.

use std::sync::Arc;

use dsr::{Delta, EdgeKey, Element, NewNode, NodeId, OpError, Replica, Value};
use transport::rng::SplitMix64;

use super::protocol::{RecordedOp, RecordedValue, WriteRecord};

/// Node deletes happen only while more than this many nodes are visible.
const MIN_NODES_BEFORE_DELETE: usize = 8;
/// Names every agent may insert under, so concurrent inserts contend for them.
const SHARED_NAMES: u64 = 4;

/// One agent's writer.
#[derive(Clone, Copy, Debug)]
pub struct Workload {
    /// The agent's id.
    pub agent: u32,
    /// Bytes of a camera frame.
    pub image_bytes: usize,
}

/// What the graph offers to operate on, in a deterministic order.
struct Targets {
    nodes: Vec<(NodeId, String, bool)>,
    edges: Vec<EdgeKey>,
}

impl Targets {
    fn of(replica: &Replica) -> Targets {
        let mut nodes: Vec<(NodeId, String, bool)> = replica
            .nodes()
            .map(|n| (n.id(), n.name().into_owned(), n.attrs().any(|(name, _)| name.as_str() == "pos_x")))
            .collect();
        nodes.sort();
        let mut edges: Vec<EdgeKey> = replica.edges().map(|e| e.key().clone()).collect();
        edges.sort();
        Targets { nodes, edges }
    }

    fn node(&self, rng: &mut SplitMix64) -> Option<NodeId> {
        pick(&self.nodes, rng).map(|n| n.0)
    }
}

fn pick<'a, T>(items: &'a [T], rng: &mut SplitMix64) -> Option<&'a T> {
    if items.is_empty() { None } else { items.get(rng.range(0, items.len() as u64 - 1) as usize) }
}

/// `len` bytes generated from `seed`: a camera frame's stand-in, reproducible from the history.
pub fn pattern(seed: u64, len: usize) -> Vec<u8> {
    let mut rng = SplitMix64::new(seed);
    let mut bytes = Vec::with_capacity(len + 8);
    while bytes.len() < len {
        bytes.extend_from_slice(&rng.next_u64().to_le_bytes());
    }
    bytes.truncate(len);
    bytes
}

/// A value as the replica gets it.
pub fn value_of(recorded: &RecordedValue) -> Value {
    match recorded {
        RecordedValue::Plain(value) => value.clone(),
        RecordedValue::Pattern { seed, len } => Value::Bytes(pattern(*seed, *len).into()),
    }
}

impl Workload {
    /// Makes write `seq` on `replica` at `now_ns`, chosen by `draw`: the record (with `at_ms` 0) and the delta to
    /// publish, or why nothing was written.
    ///
    /// # Errors
    /// The replica refused the chosen operation (the message names it); the replica is unchanged.
    pub fn write(
        &self,
        replica: &mut Replica,
        now_ns: u64,
        seq: u64,
        draw: u64,
    ) -> Result<(WriteRecord, Arc<Delta>), String> {
        let past = replica.applied().clone();
        let (op, delta) = self.choose(replica, now_ns, seq, draw).map_err(|e| format!("write {seq}: {e}"))?;
        let origin = delta.origin().ok_or_else(|| format!("write {seq}: a local delta without an origin"))?;
        let record = WriteRecord {
            seq,
            agent: self.agent,
            replica: replica.id().0,
            first: origin.first,
            last: origin.last,
            stamp: replica.clock().0,
            past,
            op,
            at_ms: 0.0,
        };
        Ok((record, delta))
    }

    fn choose(
        &self,
        replica: &mut Replica,
        now_ns: u64,
        seq: u64,
        draw: u64,
    ) -> Result<(RecordedOp, Arc<Delta>), OpError> {
        let mut rng = SplitMix64::new(draw);
        let targets = Targets::of(replica);
        let roll = rng.range(0, 99);
        if targets.nodes.len() < 2 || roll < 25 {
            return self.insert_node(replica, now_ns, seq, &mut rng);
        }
        match roll {
            25..50 => set_node_attr(replica, now_ns, &targets, &mut rng),
            50..60 => toggle_edge(replica, now_ns, &targets, &mut rng),
            60..66 => match pick(&targets.edges, &mut rng) {
                Some(key) => delete_edge(replica, now_ns, key.clone()),
                None => toggle_edge(replica, now_ns, &targets, &mut rng),
            },
            66..74 if targets.nodes.len() > MIN_NODES_BEFORE_DELETE => {
                let id = targets.node(&mut rng).expect("more than eight nodes");
                Ok((RecordedOp::DeleteNode { id }, replica.delete_node(now_ns, id)?))
            }
            66..74 => self.insert_node(replica, now_ns, seq, &mut rng),
            74..80 => {
                let with: Vec<_> = targets.nodes.iter().filter(|n| n.2).collect();
                match pick(&with, &mut rng) {
                    Some(node) => {
                        let element = Element::Node(node.0);
                        let delta = replica.remove_attr(now_ns, element.clone(), "pos_x")?;
                        Ok((RecordedOp::RemoveAttr { element, name: "pos_x".into() }, delta))
                    }
                    None => set_node_attr(replica, now_ns, &targets, &mut rng),
                }
            }
            80..88 => match pick(&targets.edges, &mut rng) {
                Some(key) => {
                    let value = RecordedValue::Plain(Value::I32(rng.range(0, 1000) as i32));
                    set_attr(replica, now_ns, Element::Edge(key.clone()), "level", value)
                }
                None => set_node_attr(replica, now_ns, &targets, &mut rng),
            },
            _ => self.camera_frame(replica, now_ns, &targets, draw),
        }
    }

    fn insert_node(
        &self,
        replica: &mut Replica,
        now_ns: u64,
        seq: u64,
        rng: &mut SplitMix64,
    ) -> Result<(RecordedOp, Arc<Delta>), OpError> {
        let x = RecordedValue::Plain(Value::F32(rng.range(0, 10_000) as f32 / 100.0));
        let shared = rng.chance(0.25).then(|| format!("shared_{}", rng.range(0, SHARED_NAMES - 1)));
        let own = format!("a{}_{seq}", self.agent);
        if let Some(name) = shared {
            match insert(replica, now_ns, "object", &name, vec![("pos_x".to_owned(), x.clone())]) {
                Err(OpError::NameTaken(_)) => {}
                other => return other,
            }
        }
        // The agent's own name for this write: write numbers are unique in a campaign.
        insert(replica, now_ns, "object", &own, vec![("pos_x".to_owned(), x)])
    }

    fn camera_frame(
        &self,
        replica: &mut Replica,
        now_ns: u64,
        targets: &Targets,
        draw: u64,
    ) -> Result<(RecordedOp, Arc<Delta>), OpError> {
        let name = format!("camera_{}", self.agent);
        match targets.nodes.iter().find(|n| n.1 == name) {
            Some(node) => {
                let value = RecordedValue::Pattern { seed: draw, len: self.image_bytes };
                set_attr(replica, now_ns, Element::Node(node.0), "cam_rgb", value)
            }
            None => insert(replica, now_ns, "camera", &name, Vec::new()),
        }
    }
}

fn insert(
    replica: &mut Replica,
    now_ns: u64,
    node_type: &str,
    name: &str,
    attrs: Vec<(String, RecordedValue)>,
) -> Result<(RecordedOp, Arc<Delta>), OpError> {
    let mut node = NewNode::new(node_type, name);
    node.attrs = attrs.iter().map(|(n, v)| (n.clone(), value_of(v))).collect();
    let (id, delta) = replica.insert_node(now_ns, node)?;
    Ok((RecordedOp::InsertNode { id, node_type: node_type.to_owned(), name: name.to_owned(), attrs }, delta))
}

fn set_node_attr(
    replica: &mut Replica,
    now_ns: u64,
    targets: &Targets,
    rng: &mut SplitMix64,
) -> Result<(RecordedOp, Arc<Delta>), OpError> {
    let id = targets.node(rng).ok_or(OpError::NoSuchNode(NodeId(0)))?;
    let value = RecordedValue::Plain(Value::F32(rng.range(0, 10_000) as f32 / 100.0));
    set_attr(replica, now_ns, Element::Node(id), "pos_x", value)
}

fn set_attr(
    replica: &mut Replica,
    now_ns: u64,
    element: Element,
    name: &str,
    value: RecordedValue,
) -> Result<(RecordedOp, Arc<Delta>), OpError> {
    let delta = replica.set_attrs(now_ns, element.clone(), [(name, value_of(&value))])?;
    Ok((RecordedOp::SetAttr { element, name: name.to_owned(), value }, delta))
}

/// Inserts an edge `in` between two nodes, or deletes it if it is there.
fn toggle_edge(
    replica: &mut Replica,
    now_ns: u64,
    targets: &Targets,
    rng: &mut SplitMix64,
) -> Result<(RecordedOp, Arc<Delta>), OpError> {
    let from = targets.node(rng).ok_or(OpError::NoSuchNode(NodeId(0)))?;
    let to = targets
        .nodes
        .iter()
        .map(|n| n.0)
        .filter(|id| *id != from)
        .nth(rng.range(0, 1_000) as usize % (targets.nodes.len() - 1));
    let to = to.ok_or(OpError::NoSuchNode(NodeId(0)))?;
    let key = EdgeKey::new(from, to, "in");
    if replica.edge(&key).is_some() {
        return delete_edge(replica, now_ns, key);
    }
    let (key, delta) = replica.insert_edge(now_ns, from, to, "in", Vec::new())?;
    Ok((RecordedOp::InsertEdge { from: key.from, to: key.to, edge_type: key.edge_type.to_string() }, delta))
}

fn delete_edge(replica: &mut Replica, now_ns: u64, key: EdgeKey) -> Result<(RecordedOp, Arc<Delta>), OpError> {
    let delta = replica.delete_edge(now_ns, &key)?;
    Ok((RecordedOp::DeleteEdge { from: key.from, to: key.to, edge_type: key.edge_type.to_string() }, delta))
}
