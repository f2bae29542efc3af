//! Kinematics against hand-computed transforms.

use std::f64::consts::FRAC_PI_2;

use approx::assert_relative_eq;
use dsr::kinematics::{euler_xyz, rt_isometry};
use dsr::{Delta, KinematicsError, NewNode, NodeId, Replica, ReplicaId};

fn node(replica: &mut Replica, t: u64, node_type: &str, name: &str) -> NodeId {
    replica.insert_node(t, NewNode::new(node_type, name)).unwrap().0
}

/// world → robot (1000 mm along x, turned 90° about z) → camera (500 mm up); robot → laser (200 mm along x).
fn robot_world() -> (Replica, [NodeId; 4]) {
    let mut r = Replica::new(ReplicaId(1));
    let world = node(&mut r, 1, "world", "world");
    let robot = node(&mut r, 2, "omnirobot", "robot");
    let camera = node(&mut r, 3, "rgbd", "camera");
    let laser = node(&mut r, 4, "laser", "laser");
    r.set_rt(5, world, robot, [1000.0, 0.0, 0.0], [0.0, 0.0, FRAC_PI_2 as f32]).unwrap();
    r.set_rt(6, robot, camera, [0.0, 0.0, 500.0], [0.0, 0.0, 0.0]).unwrap();
    r.set_rt(7, robot, laser, [200.0, 0.0, 0.0], [0.0, 0.0, 0.0]).unwrap();
    (r, [world, robot, camera, laser])
}

fn close(actual: [f64; 3], expected: [f64; 3]) {
    for (a, e) in actual.iter().zip(expected) {
        assert_relative_eq!(*a, e, epsilon = 1e-3);
    }
}

#[test]
fn camera_point_in_world_matches_hand_computation() {
    let (r, [world, _, camera, _]) = robot_world();
    // (1,0,0) in camera → (1,0,500) in robot → Rz(90°)·(1,0,500) + (1000,0,0) = (1000,1,500) in world.
    close(r.transform_point(camera, world, [1.0, 0.0, 0.0]).unwrap(), [1000.0, 1.0, 500.0]);
}

#[test]
fn inverse_direction_undoes_the_transform() {
    let (r, [world, _, camera, _]) = robot_world();
    close(r.transform_point(world, camera, [1000.0, 1.0, 500.0]).unwrap(), [1.0, 0.0, 0.0]);
    let there = r.transform(camera, world).unwrap();
    let back = r.transform(world, camera).unwrap();
    let identity = there * back;
    assert_relative_eq!(identity.translation.vector.norm(), 0.0, epsilon = 1e-9);
}

#[test]
fn siblings_go_through_their_common_ancestor() {
    let (r, [_, _, camera, laser]) = robot_world();
    // Camera origin is (0,0,500) in the robot frame, the laser sits at (200,0,0): (-200,0,500) in the laser frame.
    close(r.transform_point(camera, laser, [0.0, 0.0, 0.0]).unwrap(), [-200.0, 0.0, 500.0]);
    assert_eq!(r.rt_depth(camera).unwrap(), 2);
}

#[test]
fn euler_angles_compose_as_rx_ry_rz() {
    let pose = rt_isometry([0.0; 3], [FRAC_PI_2, FRAC_PI_2, 0.0]);
    // Ry(90°)·(1,0,0) = (0,0,-1); Rx(90°)·(0,0,-1) = (0,1,0).
    let p = pose * nalgebra::Point3::new(1.0, 0.0, 0.0);
    close([p.x, p.y, p.z], [0.0, 1.0, 0.0]);
    let angles = [0.3, -0.7, 1.1];
    let recovered = euler_xyz(&rt_isometry([0.0; 3], angles).rotation);
    close(recovered, angles);
}

#[test]
fn remote_change_on_the_path_is_seen_by_the_next_transform() {
    let (mut a, [world, robot, camera, _]) = robot_world();
    let mut b = Replica::new(ReplicaId(2));
    b.apply(&a.snapshot()).unwrap();
    close(b.transform_point(camera, world, [0.0; 3]).unwrap(), [1000.0, 0.0, 500.0]);
    for delta in a.set_rt(10, world, robot, [0.0, 2000.0, 0.0], [0.0, 0.0, 0.0]).unwrap() {
        b.apply(&Delta::decode(&delta.encode()).unwrap()).unwrap();
    }
    close(b.transform_point(camera, world, [0.0; 3]).unwrap(), [0.0, 2000.0, 500.0]);
    // And a local change on the path too.
    b.set_rt(11, robot, camera, [0.0, 0.0, 100.0], [0.0, 0.0, 0.0]).unwrap();
    close(b.transform_point(camera, world, [0.0; 3]).unwrap(), [0.0, 2000.0, 100.0]);
}

#[test]
fn concurrent_inserts_forming_a_cycle_give_an_error_not_a_hang() {
    let mut a = Replica::new(ReplicaId(1));
    let x = node(&mut a, 1, "transform", "x");
    let y = node(&mut a, 2, "transform", "y");
    let mut b = Replica::new(ReplicaId(2));
    b.apply(&a.snapshot()).unwrap();
    let from_a = a.set_rt(3, x, y, [0.0; 3], [0.0; 3]).unwrap();
    let from_b = b.set_rt(3, y, x, [0.0; 3], [0.0; 3]).unwrap();
    for d in from_b {
        a.apply(&d).unwrap();
    }
    for d in from_a {
        b.apply(&d).unwrap();
    }
    assert_eq!(a.digest(), b.digest());
    match a.transform(x, y) {
        Err(KinematicsError::Cycle(nodes)) => assert_eq!(nodes, vec![x, y]),
        other => panic!("expected a cycle, got {other:?}"),
    }
}

#[test]
fn several_parents_are_resolved_by_the_parent_attribute_or_reported() {
    let mut a = Replica::new(ReplicaId(1));
    let p1 = node(&mut a, 1, "transform", "p1");
    let p2 = node(&mut a, 2, "transform", "p2");
    let c = node(&mut a, 3, "object", "c");
    let mut b = Replica::new(ReplicaId(2));
    b.apply(&a.snapshot()).unwrap();
    let from_a = a.set_rt(4, p1, c, [1.0, 0.0, 0.0], [0.0; 3]).unwrap();
    let from_b = b.set_rt(4, p2, c, [2.0, 0.0, 0.0], [0.0; 3]).unwrap();
    for d in from_b {
        a.apply(&d).unwrap();
    }
    // Both wrote `parent` at the same stamp: replica 2's value (p2) wins the register, so p2 is the parent.
    close(a.transform_point(c, p2, [0.0; 3]).unwrap(), [2.0, 0.0, 0.0]);
    a.remove_attr(5, c, "parent").unwrap();
    assert!(matches!(a.transform(c, p1), Err(KinematicsError::SeveralParents { .. })));
    let _ = from_a;
}

#[test]
fn malformed_rt_edges_and_unconnected_nodes_are_errors() {
    let mut r = Replica::new(ReplicaId(1));
    let x = node(&mut r, 1, "transform", "x");
    let y = node(&mut r, 2, "transform", "y");
    let z = node(&mut r, 3, "transform", "z");
    r.insert_edge(4, x, y, "RT", vec![("rt_translation".into(), vec![1.0f32, 2.0].into())]).unwrap();
    assert!(matches!(r.transform(y, x), Err(KinematicsError::BadEdge { .. })));
    assert_eq!(r.transform(x, z), Err(KinematicsError::NotConnected(x, z)));
    assert_eq!(r.transform(x, NodeId(999)), Err(KinematicsError::NoSuchNode(NodeId(999))));
}
