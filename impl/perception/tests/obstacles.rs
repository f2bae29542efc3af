//! The obstacle detector on real SICK TiM7xx scans and an Ouster cloud: its clusters equal those of an
//! independent quadratic single-linkage implementation; run as BICA components on a replica it keeps `obstacle`
//! nodes with RT edges from the laser node, deletes them when the obstacles vanish, and survives malformed scans.

use bica::prelude::*;
use dsr::{NewNode, Replica, ReplicaId, attrs};
use perception::fixtures;
use perception::graph::{self, share_replica};
use perception::obstacles::{CloudObstacleDetector, LaserObstacleDetector, ObstacleConfig};
use perception::sensors::{LaserReader, LaserScan, PointCloud, write_scan};

struct Scan {
    stamp_ns: u64,
    scan: LaserScan,
}

fn sick_scans() -> Vec<Scan> {
    let json: serde_json::Value =
        serde_json::from_slice(&fixtures::read("sick_tim7xx_scans_100_109.json").unwrap()).unwrap();
    json["scans"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| {
            let ranges: Vec<f32> =
                s["ranges"].as_array().unwrap().iter().map(|r| r.as_f64().unwrap() as f32 * 1000.0).collect();
            let (min, inc) = (s["angle_min"].as_f64().unwrap(), s["angle_increment"].as_f64().unwrap());
            let angles: Vec<f32> = (0..ranges.len()).map(|i| (min + inc * i as f64) as f32).collect();
            Scan {
                stamp_ns: s["stamp_ns"].as_u64().unwrap(),
                scan: LaserScan { dists_mm: ranges.into(), angles_rad: angles.into() },
            }
        })
        .collect()
}

/// Independent reference: union-find over all pairs within the radius, then clusters of `min` points or more,
/// as sorted lists of rounded centroids.
fn reference_centroids(points: &[[f32; 2]], radius: f32, min: usize) -> Vec<(i64, i64, usize)> {
    let mut parent: Vec<usize> = (0..points.len()).collect();
    fn find(parent: &mut [usize], mut i: usize) -> usize {
        while parent[i] != i {
            parent[i] = parent[parent[i]];
            i = parent[i];
        }
        i
    }
    for i in 0..points.len() {
        for j in i + 1..points.len() {
            let (dx, dy) = (points[i][0] - points[j][0], points[i][1] - points[j][1]);
            if dx * dx + dy * dy <= radius * radius {
                let (a, b) = (find(&mut parent, i), find(&mut parent, j));
                parent[a] = b;
            }
        }
    }
    let mut groups: std::collections::BTreeMap<usize, Vec<usize>> = Default::default();
    for i in 0..points.len() {
        let root = find(&mut parent, i);
        groups.entry(root).or_default().push(i);
    }
    let mut out: Vec<(i64, i64, usize)> = groups
        .values()
        .filter(|g| g.len() >= min)
        .map(|g| {
            let n = g.len() as f64;
            let x = g.iter().map(|&i| f64::from(points[i][0])).sum::<f64>() / n;
            let y = g.iter().map(|&i| f64::from(points[i][1])).sum::<f64>() / n;
            (x.round() as i64, y.round() as i64, g.len())
        })
        .collect();
    out.sort_unstable();
    out
}

fn detector_centroids(clusters: &[perception::obstacles::Cluster]) -> Vec<(i64, i64, usize)> {
    let mut out: Vec<(i64, i64, usize)> =
        clusters.iter().map(|c| (c.centroid_mm[0].round() as i64, c.centroid_mm[1].round() as i64, c.points)).collect();
    out.sort_unstable();
    out
}

fn unused_graph() -> perception::graph::SharedGraph {
    share_replica(Replica::new(ReplicaId(9))).1
}

#[test]
fn laser_clusters_match_an_independent_implementation_on_real_scans() {
    let config = ObstacleConfig::default();
    let detector = LaserObstacleDetector::new(unused_graph(), config.clone());
    let scans = sick_scans();
    assert_eq!(scans.len(), 10);
    for scan in &scans {
        let points: Vec<[f32; 2]> = scan
            .scan
            .dists_mm
            .iter()
            .zip(scan.scan.angles_rad.iter())
            .filter(|(d, _)| d.is_finite() && **d >= config.min_range_mm && **d <= config.max_range_mm)
            .map(|(d, a)| [d * a.cos(), d * a.sin()])
            .collect();
        let expected = reference_centroids(&points, config.cluster_radius_mm, config.min_cluster_points);
        assert!(expected.len() >= 2, "a real scan has several clusters, got {}", expected.len());
        assert_eq!(detector_centroids(&detector.cluster(&scan.scan)), expected);
    }
}

#[test]
fn cloud_clusters_match_an_independent_implementation_on_a_real_ouster_cloud() {
    let config =
        ObstacleConfig { cluster_radius_mm: 300.0, z_min_mm: -5000.0, z_max_mm: 5000.0, ..ObstacleConfig::default() };
    let detector = CloudObstacleDetector::new(unused_graph(), config.clone());
    // The first 4 of the 16 rings keep the quadratic reference quick.
    let points_m = &fixtures::ouster_points_m().unwrap()[..4 * 1024];
    let mm: Vec<[f32; 3]> = points_m.iter().map(|p| p.map(|v| v * 1000.0)).collect();
    let cloud = PointCloud {
        x_mm: mm.iter().map(|p| p[0]).collect::<Vec<_>>().into(),
        y_mm: mm.iter().map(|p| p[1]).collect::<Vec<_>>().into(),
        z_mm: mm.iter().map(|p| p[2]).collect::<Vec<_>>().into(),
    };
    let kept: Vec<[f32; 2]> = mm
        .iter()
        .filter(|p| p[2] >= config.z_min_mm && p[2] <= config.z_max_mm && (p[0] != 0.0 || p[1] != 0.0))
        .map(|p| [p[0], p[1]])
        .collect();
    let expected = reference_centroids(&kept, config.cluster_radius_mm, config.min_cluster_points);
    assert!(expected.len() >= 2, "a real cloud has several clusters, got {}", expected.len());
    assert_eq!(detector_centroids(&detector.cluster(&cloud)), expected);
}

#[test]
fn detector_component_keeps_obstacle_nodes_in_the_graph_and_survives_malformed_scans() {
    let (replica, graph) = share_replica(Replica::new(ReplicaId(1)));
    let (world, laser) = {
        let mut g = graph.borrow_mut();
        graph::declare_perception_attrs(&mut *g).unwrap();
        let world = g.insert_node(1, NewNode::new("world", "world")).unwrap();
        let laser = g.insert_node(2, NewNode::new("laser", "laser")).unwrap();
        g.set_rt(3, world, laser, [0.0, 0.0, 300.0], [0.0; 3]).unwrap();
        (world, laser)
    };
    let clock = VirtualClock::new(0);
    let mut runtime = Runtime::new(RuntimeConfig::default(), clock.clone());
    runtime.register(LaserReader::new(graph.clone(), "laser"), 50_000_000).unwrap();
    runtime.register(LaserObstacleDetector::new(graph.clone(), ObstacleConfig::default()), 50_000_000).unwrap();
    runtime.activate::<LaserObstacleDetector>().unwrap();
    let scans = sick_scans();
    let mut now = 10_000_000u64;
    for (sequence, scan) in scans.iter().enumerate() {
        write_scan(&mut *graph.borrow_mut(), now, laser, &scan.scan, scan.stamp_ns, sequence as u64).unwrap();
        now += 66_000_000;
        runtime.run_until(now).unwrap();
    }
    assert_eq!(runtime.step_failures(), 0);
    let detector = runtime.registry().get::<LaserObstacleDetector>().unwrap();
    let confirmed: Vec<u64> = detector.tracker().confirmed().map(|t| t.id).collect();
    assert!(confirmed.len() >= 2, "static scene: clusters are confirmed, got {confirmed:?}");
    {
        let r = replica.borrow();
        let obstacles: Vec<_> = r.nodes().filter(|n| n.node_type() == "obstacle").collect();
        assert_eq!(obstacles.len(), confirmed.len());
        for node in &obstacles {
            let track_id = node.get(graph::attrs::TRACK_ID).unwrap();
            assert_eq!(node.name(), format!("obstacle_laser_{track_id}"));
            let edge = r.rt_parent_edge(node.id()).unwrap().unwrap();
            assert_eq!(edge.from(), laser);
            let track = detector.tracker().tracks().iter().find(|t| t.id == track_id).unwrap();
            let in_world = r.transform_point(node.id(), world, [0.0; 3]).unwrap();
            let p = track.filter.position_mm();
            assert!(
                (in_world[0] - p[0]).abs() < 1.0
                    && (in_world[1] - p[1]).abs() < 1.0
                    && (in_world[2] - 300.0).abs() < 1e-3
            );
            assert!(node.get(graph::attrs::TRACK_COVARIANCE_MM2).unwrap().iter().all(|v| v.is_finite()));
        }
    }
    // Malformed scans: mismatched lengths, then NaN angles. Warnings, no failure, nodes untouched.
    let before = replica.borrow().node_count();
    for (i, (dists, angles)) in
        [(vec![1000.0f32; 5], vec![0.0f32; 4]), (vec![1000.0; 3], vec![0.0, f32::NAN, 0.1])].into_iter().enumerate()
    {
        graph
            .borrow_mut()
            .set_node_attrs(
                now,
                laser,
                vec![(attrs::LASER_DISTS.name(), dists.into()), (attrs::LASER_ANGLES.name(), angles.into())],
            )
            .unwrap();
        now += 66_000_000;
        runtime.run_until(now).unwrap();
        assert_eq!(runtime.registry().get::<LaserReader>().unwrap().malformed(), i as u64 + 1);
    }
    assert_eq!(runtime.step_failures(), 0);
    assert_eq!(replica.borrow().node_count(), before);
    // The obstacles vanish (no returns): the confirmed tracks die after their allowed misses and their nodes go.
    let empty = LaserScan { dists_mm: vec![0.0f32; 811].into(), angles_rad: scans[0].scan.angles_rad.clone() };
    for k in 0..8u64 {
        write_scan(&mut *graph.borrow_mut(), now, laser, &empty, scans[9].stamp_ns + (k + 1) * 66_000_000, 100 + k)
            .unwrap();
        now += 66_000_000;
        runtime.run_until(now).unwrap();
    }
    let r = replica.borrow();
    assert_eq!(r.nodes().filter(|n| n.node_type() == "obstacle").count(), 0);
    assert!(r.node(laser).is_some());
}
