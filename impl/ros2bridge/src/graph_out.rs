//! The Out direction's core: what of the graph becomes ROS 2 messages, read from a [`Replica`] with no I/O.
//!
//! - RT edges become `geometry_msgs/TransformStamped`: header `frame_id` = the parent node's name,
//!   `child_frame_id` = the child node's name, translation m from the edge's mm, rotation the quaternion of the
//!   edge's Euler x-y-z angles as [`dsr::kinematics::rt_isometry`] composes them (`Rx · Ry · Rz`). Edges whose child
//!   is listed as static go to `/tf_static`, the others to `/tf`.
//! - A node's `cam_rgb` (with `cam_rgb_width/height/depth/encoding`) becomes a `sensor_msgs/Image`; its
//!   `laser_dists` (mm → m) and `laser_angles` a `sensor_msgs/LaserScan` (evenly spaced beams: `angle_min` the first
//!   angle, `angle_increment` the mean spacing). The header's frame is the node's RT parent (none: empty), its stamp
//!   the node's `stamp_ns` (none: the time given).
//!
//! Each message comes with the [`Dot`] of the attribute write it shows, so a caller sends it only when that changed.

use dsr::kinematics::{RT, edge_pose};
use dsr::{Dot, NodeRef, Replica, Value, attrs};
use replay::ros2::{Image, LaserScan, TransformStamped};

use crate::encode::header_at;

/// Why a node cannot be published as the message asked for (counted per output, never a panic).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("node {node:?}: {what}")]
pub struct OutError {
    /// The node.
    pub node: String,
    /// What is wrong.
    pub what: String,
}

/// The RT edges as transforms, split into (dynamic, static) by the child's name; edges that are not valid RT
/// edges (missing or non-finite attributes) are skipped and counted in the third value.
pub fn rt_transforms(
    replica: &Replica,
    static_frames: &[String],
    stamp_ns: u64,
) -> (Vec<TransformStamped>, Vec<TransformStamped>, u64) {
    let (mut dynamic, mut fixed, mut bad) = (Vec::new(), Vec::new(), 0);
    for edge in replica.edges().filter(|edge| edge.edge_type() == RT) {
        let (Some(parent), Some(child)) = (replica.node(edge.from()), replica.node(edge.to())) else { continue };
        let Ok(pose) = edge_pose(&edge) else {
            bad += 1;
            continue;
        };
        let t = pose.translation.vector / 1000.0;
        let q = pose.rotation;
        let child_name = child.name().into_owned();
        let transform = TransformStamped {
            header: header_at(stamp_ns, &parent.name()),
            translation: [t.x, t.y, t.z],
            rotation: [q.i, q.j, q.k, q.w],
            child_frame_id: child_name,
        };
        if static_frames.contains(&transform.child_frame_id) {
            fixed.push(transform);
        } else {
            dynamic.push(transform);
        }
    }
    let order = |a: &TransformStamped, b: &TransformStamped| a.child_frame_id.cmp(&b.child_frame_id);
    dynamic.sort_by(order);
    fixed.sort_by(order);
    (dynamic, fixed, bad)
}

/// The name of a node's RT parent, or `""`.
fn parent_frame(replica: &Replica, node: &NodeRef<'_>) -> String {
    match replica.rt_parent_edge(node.id()) {
        Ok(Some(edge)) => replica.node(edge.from()).map(|parent| parent.name().into_owned()).unwrap_or_default(),
        _ => String::new(),
    }
}

fn int_attr(node: &NodeRef<'_>, name: &'static str, node_name: &str) -> Result<u32, OutError> {
    match node.attr(name) {
        Some(Value::I32(value)) if *value >= 0 => Ok(*value as u32),
        Some(Value::U32(value)) => Ok(*value),
        other => Err(OutError { node: node_name.into(), what: format!("`{name}` is {other:?}, not a size") }),
    }
}

fn stamp_of(node: &NodeRef<'_>, now_ns: u64) -> u64 {
    match node.attr(attrs::STAMP_NS.name()) {
        Some(Value::U64(stamp)) => *stamp,
        _ => now_ns,
    }
}

/// The image of node `name` and the dot of its `cam_rgb` write; `Ok(None)` while there is no such node or it has
/// no `cam_rgb` (a sensor node appears with its first message).
///
/// # Errors
/// [`OutError`]: sizes missing, or pixels that do not fill `width × height × depth` bytes.
pub fn image(replica: &Replica, name: &str, now_ns: u64) -> Result<Option<(Dot, Image)>, OutError> {
    let Some(node) = replica.node_by_name(name) else { return Ok(None) };
    let Some(entry) = node.attr_entry(attrs::CAM_RGB.name()) else { return Ok(None) };
    let Value::Bytes(data) = &entry.value else {
        return Err(OutError { node: name.into(), what: "`cam_rgb` does not hold bytes".into() });
    };
    let width = int_attr(&node, attrs::CAM_RGB_WIDTH.name(), name)?;
    let height = int_attr(&node, attrs::CAM_RGB_HEIGHT.name(), name)?;
    let depth = int_attr(&node, attrs::CAM_RGB_DEPTH.name(), name)?;
    let encoding = match node.attr(attrs::CAM_RGB_ENCODING.name()) {
        Some(Value::String(encoding)) => encoding.to_string(),
        _ if depth == 1 => "mono8".into(),
        _ => "rgb8".into(),
    };
    let step = width.checked_mul(depth);
    let expected = step.and_then(|step| step.checked_mul(height));
    if expected != Some(data.len() as u32) || data.len() > u32::MAX as usize {
        return Err(OutError {
            node: name.into(),
            what: format!("`cam_rgb` has {} bytes, not {width} × {height} × {depth}", data.len()),
        });
    }
    let image = Image {
        header: header_at(stamp_of(&node, now_ns), &parent_frame(replica, &node)),
        height,
        width,
        encoding,
        is_bigendian: false,
        step: step.unwrap_or(0),
        data: data.clone(),
    };
    Ok(Some((entry.dot, image)))
}

/// The laser scan of node `name` and the dot of its `laser_dists` write; `Ok(None)` while there is no such node or
/// it has no `laser_dists`.
///
/// # Errors
/// [`OutError`]: distances and angles of different lengths.
pub fn laser_scan(
    replica: &Replica,
    name: &str,
    range_m: (f32, f32),
    now_ns: u64,
) -> Result<Option<(Dot, LaserScan)>, OutError> {
    let Some(node) = replica.node_by_name(name) else { return Ok(None) };
    let Some(entry) = node.attr_entry(attrs::LASER_DISTS.name()) else { return Ok(None) };
    let fail = |what: String| OutError { node: name.into(), what };
    let Value::VecF32(dists_mm) = &entry.value else { return Err(fail("`laser_dists` is not a float vector".into())) };
    let angles: &[f32] = match node.attr(attrs::LASER_ANGLES.name()) {
        Some(Value::VecF32(angles)) => angles,
        other => return Err(fail(format!("`laser_angles` is {other:?}, not a float vector"))),
    };
    if angles.len() != dists_mm.len() {
        return Err(fail(format!("{} distances but {} angles", dists_mm.len(), angles.len())));
    }
    let intensities = match node.attr(attrs::LASER_INTENSITIES.name()) {
        Some(Value::VecF32(values)) if values.len() == dists_mm.len() => values.to_vec(),
        _ => Vec::new(),
    };
    let (first, last) = (angles.first().copied().unwrap_or(0.0), angles.last().copied().unwrap_or(0.0));
    let increment = if angles.len() > 1 { (last - first) / (angles.len() - 1) as f32 } else { 0.0 };
    let scan = LaserScan {
        header: header_at(stamp_of(&node, now_ns), &parent_frame(replica, &node)),
        angle_min: first,
        angle_max: last,
        angle_increment: increment,
        time_increment: 0.0,
        scan_time: 0.0,
        range_min: range_m.0,
        range_max: range_m.1,
        ranges: dists_mm.iter().map(|mm| mm / 1000.0).collect(),
        intensities,
    };
    Ok(Some((entry.dot, scan)))
}

#[cfg(test)]
mod tests {
    use dsr::Numbers;

    use bytes::Bytes;
    use dsr::{NewNode, ReplicaId};

    use super::*;

    fn world() -> Replica {
        let mut replica = Replica::new(ReplicaId(1));
        let (root, _) = replica.insert_node(1, NewNode::new("world", "world")).unwrap();
        let (base, _) = replica.insert_node(1, NewNode::new("transform", "base_link")).unwrap();
        let (laser, _) = replica.insert_node(1, NewNode::new("laser", "laser")).unwrap();
        replica.set_rt(2, root, base, [1000.0, -500.0, 0.0], [0.0, 0.0, std::f32::consts::FRAC_PI_2]).unwrap();
        replica.set_rt(2, base, laser, [100.0, 0.0, 300.0], [0.1, 0.2, 0.3]).unwrap();
        replica
    }

    #[test]
    fn rt_edges_become_transforms_in_metres_with_the_edge_rotation() {
        let replica = world();
        let (dynamic, fixed, bad) = rt_transforms(&replica, &["laser".to_owned()], 7);
        assert_eq!((dynamic.len(), fixed.len(), bad), (1, 1, 0));
        let base = &dynamic[0];
        assert_eq!((base.header.frame_id.as_str(), base.child_frame_id.as_str()), ("world", "base_link"));
        assert!((base.translation[0] - 1.0).abs() < 1e-9 && (base.translation[1] + 0.5).abs() < 1e-9);
        let half = std::f64::consts::FRAC_PI_4;
        assert!((base.rotation[2] - half.sin()).abs() < 1e-6 && (base.rotation[3] - half.cos()).abs() < 1e-6);
        // Back through replay's conversion: the same Euler angles.
        let euler = replay::bridge::euler_from_quaternion(fixed[0].rotation).unwrap();
        for (got, want) in euler.iter().zip([0.1f32, 0.2, 0.3]) {
            assert!((got - want).abs() < 1e-5, "{euler:?}");
        }
    }

    #[test]
    fn a_laser_node_becomes_a_scan_in_metres_under_its_parent_frame() {
        let mut replica = world();
        let laser = replica.node_by_name("laser").unwrap().id();
        replica
            .set_attrs(
                3,
                laser,
                vec![
                    (attrs::LASER_DISTS.name(), Value::VecF32(Numbers::from([1000.0f32, 2500.0, 500.0]))),
                    (attrs::LASER_ANGLES.name(), Value::VecF32(Numbers::from([-0.5f32, 0.0, 0.5]))),
                    (attrs::STAMP_NS.name(), Value::U64(42)),
                ],
            )
            .unwrap();
        let (_, scan) = laser_scan(&replica, "laser", (0.1, 20.0), 9).unwrap().unwrap();
        assert_eq!(scan.ranges, vec![1.0, 2.5, 0.5]);
        assert_eq!((scan.angle_min, scan.angle_max, scan.angle_increment), (-0.5, 0.5, 0.5));
        assert_eq!((scan.header.frame_id.as_str(), scan.header.stamp_ns()), ("base_link", 42));
        assert!(laser_scan(&replica, "base_link", (0.0, 1.0), 0).unwrap().is_none());
        assert!(laser_scan(&replica, "nobody", (0.0, 1.0), 0).unwrap().is_none());
    }

    #[test]
    fn an_image_whose_pixels_do_not_fill_its_size_is_an_error() {
        let mut replica = world();
        let laser = replica.node_by_name("laser").unwrap().id();
        let mut set = |bytes: usize| {
            replica
                .set_attrs(
                    3,
                    laser,
                    vec![
                        (attrs::CAM_RGB.name(), Value::Bytes(Bytes::from(vec![7u8; bytes]))),
                        (attrs::CAM_RGB_WIDTH.name(), Value::I32(4)),
                        (attrs::CAM_RGB_HEIGHT.name(), Value::I32(2)),
                        (attrs::CAM_RGB_DEPTH.name(), Value::I32(3)),
                    ],
                )
                .unwrap();
            image(&replica, "laser", 5)
        };
        let (_, good) = set(24).unwrap().unwrap();
        assert_eq!((good.width, good.height, good.step, good.encoding.as_str()), (4, 2, 12, "rgb8"));
        assert!(set(23).unwrap_err().what.contains("23 bytes"));
    }
}
