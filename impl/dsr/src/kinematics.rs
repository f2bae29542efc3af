//! Kinematics over RT edges: the rigid transform between any two nodes of the RT tree.
//!
//! An `RT` edge from a parent to a child holds `rt_translation` (mm) and `rt_rotation_euler_xyz` (rad); the
//! child's pose in the parent's frame is `Translation · Rx · Ry · Rz` (CORTEX's convention; the legacy names
//! `translation` and `rotation_euler_xyz` of older graphs are read too). [`Replica::transform`] walks both nodes
//! up to their common ancestor and returns the isometry that maps coordinates in one frame to the other.
//!
//! There is deliberately no cache: every call reads the current state, so a local or remote change to any RT edge
//! is seen by the next call. A 10-edge chain costs about a microsecond (see `cargo bench -p dsr`). Concurrent
//! inserts can leave a node with two RT parents or an RT cycle; both are reported as errors, never a hang.

use std::collections::BTreeMap;
use std::sync::Arc;

use nalgebra::{Isometry3, Point3, Rotation3, Translation3, UnitQuaternion, Vector3};

use crate::delta::Delta;
use crate::dictionary::attrs;
use crate::error::OpError;
use crate::ids::{EdgeKey, NodeId};
use crate::replica::{EdgeRef, Replica};
use crate::value::{Numbers, Value};

/// The edge type of geometric edges.
pub const RT: &str = "RT";

/// Why a transform could not be computed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum KinematicsError {
    /// The node is not visible.
    #[error("node {0} does not exist")]
    NoSuchNode(NodeId),
    /// The two nodes are in different RT trees.
    #[error("nodes {0} and {1} have no common RT ancestor")]
    NotConnected(NodeId, NodeId),
    /// Following RT parents from a node comes back to a node already visited.
    #[error("RT cycle through nodes {0:?}")]
    Cycle(Vec<NodeId>),
    /// A node has several RT parents and its `parent` attribute names none of them.
    #[error("node {node} has {} RT parents ({parents:?}) and its `parent` attribute names none of them", parents.len())]
    SeveralParents {
        /// The node.
        node: NodeId,
        /// Its RT parents.
        parents: Vec<NodeId>,
    },
    /// An RT edge lacks an attribute or holds one of the wrong length.
    #[error("RT edge {edge}: {what}")]
    BadEdge {
        /// The edge.
        edge: EdgeKey,
        /// What is wrong.
        what: String,
    },
}

/// The pose of a child in its parent's frame: `Translation(t) · Rx(r[0]) · Ry(r[1]) · Rz(r[2])`, in mm and rad.
///
/// # Examples
/// ```
/// let pose = dsr::kinematics::rt_isometry([100.0, 0.0, 0.0], [0.0, 0.0, std::f64::consts::FRAC_PI_2]);
/// let p = pose * nalgebra::Point3::new(1.0, 0.0, 0.0);
/// assert!((p.x - 100.0).abs() < 1e-9 && (p.y - 1.0).abs() < 1e-9);
/// ```
pub fn rt_isometry(translation_mm: [f64; 3], euler_xyz_rad: [f64; 3]) -> Isometry3<f64> {
    let [a, b, c] = euler_xyz_rad;
    let rotation = Rotation3::from_axis_angle(&Vector3::x_axis(), a)
        * Rotation3::from_axis_angle(&Vector3::y_axis(), b)
        * Rotation3::from_axis_angle(&Vector3::z_axis(), c);
    Isometry3::from_parts(
        Translation3::new(translation_mm[0], translation_mm[1], translation_mm[2]),
        UnitQuaternion::from_rotation_matrix(&rotation),
    )
}

/// The Euler angles `[a, b, c]` (rad) with `rotation = Rx(a) · Ry(b) · Rz(c)`, the inverse of [`rt_isometry`]'s
/// rotation part (with `b` in `[-π/2, π/2]`).
pub fn euler_xyz(rotation: &UnitQuaternion<f64>) -> [f64; 3] {
    let m = rotation.to_rotation_matrix();
    let m = m.matrix();
    let b = m[(0, 2)].clamp(-1.0, 1.0).asin();
    if m[(0, 2)].abs() < 1.0 - 1e-12 {
        [(-m[(1, 2)]).atan2(m[(2, 2)]), b, (-m[(0, 1)]).atan2(m[(0, 0)])]
    } else {
        // Gimbal lock: only a ± c is defined; put it all in a.
        [m[(2, 1)].atan2(m[(1, 1)]), b, 0.0]
    }
}

/// The translation part of an isometry, in mm.
pub fn translation_mm(pose: &Isometry3<f64>) -> [f64; 3] {
    let t = pose.translation.vector;
    [t.x, t.y, t.z]
}

fn three(edge: &EdgeRef<'_>, names: [&str; 2]) -> Result<[f64; 3], KinematicsError> {
    let bad = |what: String| KinematicsError::BadEdge { edge: edge.key().clone(), what };
    let value = edge.attr(names[0]).or_else(|| edge.attr(names[1])).ok_or_else(|| bad(format!("no `{}`", names[0])))?;
    let floats: &[f32] = match value {
        Value::VecF32(values) => values,
        Value::F32x3(values) => values,
        other => {
            return Err(bad(format!("`{}` is {:?}, not 3 floats", names[0], other.value_type())));
        }
    };
    match floats {
        [x, y, z] if x.is_finite() && y.is_finite() && z.is_finite() => {
            Ok([f64::from(*x), f64::from(*y), f64::from(*z)])
        }
        [_, _, _] => Err(bad(format!("`{}` holds a non-finite value", names[0]))),
        _ => Err(bad(format!("`{}` has {} values, not 3", names[0], floats.len()))),
    }
}

/// The child's pose in its parent's frame, from an RT edge.
///
/// # Errors
/// [`KinematicsError::BadEdge`] if an attribute is missing, of the wrong length or not finite.
pub fn edge_pose(edge: &EdgeRef<'_>) -> Result<Isometry3<f64>, KinematicsError> {
    let translation = three(edge, [attrs::RT_TRANSLATION.name(), attrs::TRANSLATION.name()])?;
    let rotation = three(edge, [attrs::RT_ROTATION_EULER_XYZ.name(), attrs::ROTATION_EULER_XYZ.name()])?;
    Ok(rt_isometry(translation, rotation))
}

impl Replica {
    /// The RT edge from a node's parent, or `None` for a root.
    ///
    /// # Errors
    /// [`KinematicsError::NoSuchNode`], or [`KinematicsError::SeveralParents`] when concurrent inserts gave the node
    /// several RT parents and its `parent` attribute does not pick one.
    pub fn rt_parent_edge(&self, id: NodeId) -> Result<Option<EdgeRef<'_>>, KinematicsError> {
        let node = self.node(id).ok_or(KinematicsError::NoSuchNode(id))?;
        let mut parents = self.in_edges(id).filter(|edge| edge.edge_type() == RT);
        let Some(first) = parents.next() else {
            return Ok(None);
        };
        let Some(second) = parents.next() else {
            return Ok(Some(first));
        };
        let all: Vec<EdgeRef<'_>> = [first, second].into_iter().chain(parents).collect();
        let declared = node.get(attrs::PARENT).map(NodeId);
        if let Some(edge) = all.iter().find(|edge| Some(edge.from()) == declared) {
            return Ok(Some(*edge));
        }
        Err(KinematicsError::SeveralParents { node: id, parents: all.iter().map(|e| e.from()).collect() })
    }

    /// Every ancestor of `id` (itself first) with the pose of `id` in that ancestor's frame.
    fn ancestors(&self, id: NodeId) -> Result<Vec<(NodeId, Isometry3<f64>)>, KinematicsError> {
        let mut chain = vec![(id, Isometry3::identity())];
        let mut current = id;
        while let Some(edge) = self.rt_parent_edge(current)? {
            let parent = edge.from();
            if let Some(start) = chain.iter().position(|(node, _)| *node == parent) {
                let mut cycle: Vec<NodeId> = chain[start..].iter().map(|(node, _)| *node).collect();
                cycle.sort_unstable();
                return Err(KinematicsError::Cycle(cycle));
            }
            let pose_in_parent = edge_pose(&edge)? * chain.last().expect("non-empty chain").1;
            chain.push((parent, pose_in_parent));
            current = parent;
        }
        Ok(chain)
    }

    /// The isometry that maps coordinates in `from`'s frame to coordinates in `to`'s frame (mm), computed
    /// through the nodes' common RT ancestor: `pose(to)⁻¹ · pose(from)`.
    ///
    /// # Errors
    /// [`KinematicsError`] if a node is missing, the nodes are not connected, an RT edge is malformed, or the RT
    /// parents form a cycle.
    pub fn transform(&self, from: NodeId, to: NodeId) -> Result<Isometry3<f64>, KinematicsError> {
        let from_chain = self.ancestors(from)?;
        let to_chain = self.ancestors(to)?;
        let from_poses: BTreeMap<NodeId, Isometry3<f64>> = from_chain.into_iter().collect();
        for (ancestor, to_pose) in to_chain {
            if let Some(from_pose) = from_poses.get(&ancestor) {
                return Ok(to_pose.inverse() * from_pose);
            }
        }
        Err(KinematicsError::NotConnected(from, to))
    }

    /// Maps a point (mm) from `from`'s frame into `to`'s frame.
    ///
    /// # Errors
    /// As [`Replica::transform`].
    pub fn transform_point(&self, from: NodeId, to: NodeId, point_mm: [f64; 3]) -> Result<[f64; 3], KinematicsError> {
        let p = self.transform(from, to)? * Point3::new(point_mm[0], point_mm[1], point_mm[2]);
        Ok([p.x, p.y, p.z])
    }

    /// The depth of a node in its RT tree (a root is 0).
    ///
    /// # Errors
    /// As [`Replica::transform`].
    pub fn rt_depth(&self, id: NodeId) -> Result<usize, KinematicsError> {
        Ok(self.ancestors(id)?.len() - 1)
    }

    /// Places `child` under `parent` with an RT edge, or moves it if the edge exists: writes the edge's
    /// translation (mm) and rotation (rad), and the child's `parent` and `level` attributes. Returns the deltas.
    ///
    /// # Errors
    /// [`OpError`] if a node is missing.
    pub fn set_rt(
        &mut self,
        now_ns: u64,
        parent: NodeId,
        child: NodeId,
        translation_mm: [f32; 3],
        euler_xyz_rad: [f32; 3],
    ) -> Result<Vec<Arc<Delta>>, OpError> {
        let key = EdgeKey::new(parent, child, RT);
        let pose = [
            (attrs::RT_TRANSLATION.name(), Value::VecF32(Numbers::from(translation_mm))),
            (attrs::RT_ROTATION_EULER_XYZ.name(), Value::VecF32(Numbers::from(euler_xyz_rad))),
        ];
        if self.edge(&key).is_some() {
            return Ok(vec![self.set_attrs(now_ns, &key, pose)?]);
        }
        let parent_level = self.node(parent).ok_or(OpError::NoSuchNode(parent))?.get(attrs::LEVEL).unwrap_or(0);
        let attrs = pose.into_iter().map(|(name, value)| (name.to_owned(), value)).collect();
        let (_, edge) = self.insert_edge(now_ns, parent, child, RT, attrs)?;
        let placed = self.set_attrs(
            now_ns,
            child,
            [(attrs::PARENT.name(), Value::U64(parent.0)), (attrs::LEVEL.name(), Value::I32(parent_level + 1))],
        )?;
        Ok(vec![edge, placed])
    }
}
