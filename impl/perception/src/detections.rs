//! Keeps a detector's confirmed tracks in the graph: one node per track (type `blob` or `obstacle`, name
//! `<prefix>_<track id>`) under the sensor's node with an RT edge holding its position (mm), plus the track's id,
//! position covariance and velocity ([`crate::graph::attrs`]). Nodes of tracks that die (or stop being reported)
//! are deleted. Graph failures are logged and retried on the next sync, never fatal.

use std::collections::BTreeMap;

use dsr::{NewNode, NodeId, Value};

use crate::graph::{GraphAccess, attrs};

/// What the graph should show for one track.
#[derive(Debug, Clone, PartialEq)]
pub struct TrackNode {
    /// Track id.
    pub track_id: u64,
    /// Position in the sensor's frame, mm.
    pub position_mm: [f32; 3],
    /// Position covariance (row-major 2x2), mm² (or px² for image tracks).
    pub covariance: [f32; 4],
    /// Velocity, mm/s (or px/s).
    pub velocity: [f32; 2],
    /// Further attributes (e.g. a blob's class).
    pub extra: Vec<(&'static str, Value)>,
}

/// The graph nodes one detector owns.
#[derive(Debug, Clone)]
pub struct DetectionNodes {
    node_type: &'static str,
    prefix: String,
    nodes: BTreeMap<u64, NodeId>,
}

impl DetectionNodes {
    /// Nodes of `node_type` named `<prefix>_<track id>`.
    pub fn new(node_type: &'static str, prefix: impl Into<String>) -> Self {
        Self { node_type, prefix: prefix.into(), nodes: BTreeMap::new() }
    }

    /// The node of each track currently in the graph.
    pub fn nodes(&self) -> &BTreeMap<u64, NodeId> {
        &self.nodes
    }

    /// The node name of a track.
    pub fn name_of(&self, track_id: u64) -> String {
        format!("{}_{track_id}", self.prefix)
    }

    /// Makes the graph show exactly `tracks` under `sensor`.
    pub fn sync(&mut self, graph: &mut dyn GraphAccess, now_ns: u64, sensor: NodeId, tracks: &[TrackNode]) {
        let gone: Vec<(u64, NodeId)> = self
            .nodes
            .iter()
            .filter(|(id, _)| !tracks.iter().any(|t| t.track_id == **id))
            .map(|(id, node)| (*id, *node))
            .collect();
        for (track_id, node) in gone {
            if graph.node_type(node).is_some()
                && let Err(error) = graph.delete_node(now_ns, node)
            {
                tracing::warn!(%error, track_id, "cannot delete the node of a dead track");
                continue;
            }
            self.nodes.remove(&track_id);
        }
        for track in tracks {
            let node = match self.nodes.get(&track.track_id) {
                Some(&node) if graph.node_type(node).is_some() => node,
                _ => {
                    let name = self.name_of(track.track_id);
                    let new = NewNode::new(self.node_type, &name).with_attr(attrs::TRACK_ID.name(), track.track_id);
                    match graph.insert_node(now_ns, new) {
                        Ok(node) => {
                            self.nodes.insert(track.track_id, node);
                            node
                        }
                        Err(error) => {
                            tracing::warn!(%error, name, "cannot insert a detection node");
                            continue;
                        }
                    }
                }
            };
            if let Err(error) = graph.set_rt(now_ns, sensor, node, track.position_mm, [0.0; 3]) {
                tracing::warn!(%error, track_id = track.track_id, "cannot place a detection node");
                continue;
            }
            let mut values = vec![
                (attrs::TRACK_COVARIANCE_MM2.name(), Value::F32x4(track.covariance)),
                (attrs::TRACK_VELOCITY_MM_S.name(), Value::F32x2(track.velocity)),
            ];
            values.extend(track.extra.iter().cloned());
            if let Err(error) = graph.set_node_attrs(now_ns, node, values) {
                tracing::warn!(%error, track_id = track.track_id, "cannot write a detection's attributes");
            }
        }
    }
}
