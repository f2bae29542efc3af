//! Obstacle detectors on laser scans and point clouds: each new reading is turned into points (mm, sensor
//! frame), clustered ([`crate::clusters`]), and the cluster centroids feed an EKF [`Tracker`]. Confirmed tracks are
//! kept in the graph as `obstacle` nodes under the sensor's node ([`DetectionNodes`]).
//!
//! Laser: beams with a finite range in `min_range_mm..=max_range_mm` become points in the scan plane; a
//! centroid is measured as range and bearing (EKF update). Point cloud: points with z in `z_min_mm..=z_max_mm`
//! are projected on the xy plane; a centroid is measured in Cartesian coordinates.
//!
//! Time between readings comes from the sensor node's `stamp_ns` (so replayed logs track in log time), else from
//! the BICA clock.

use std::marker::PhantomData;

use bica::debug::{DebugPrimitive, Debuggable, Frame, Point2, Rgba, Shape};
use bica::prelude::*;

use crate::clusters::euclidean_clusters;
use crate::detections::{DetectionNodes, TrackNode};
use crate::ekf::{Detection, Measurement, Tracker, TrackerConfig};
use crate::graph::SharedGraph;
use crate::sensors::{Laser, LaserScan, Lidar, PointCloud, Sensor, SensorReader};

/// Parameters of an obstacle detector.
#[derive(Debug, Clone, PartialEq)]
pub struct ObstacleConfig {
    /// Points closer than this are in the same cluster, mm.
    pub cluster_radius_mm: f32,
    /// Smallest cluster reported.
    pub min_cluster_points: usize,
    /// Laser beams shorter than this are no returns, mm.
    pub min_range_mm: f32,
    /// Laser beams longer than this are no returns, mm.
    pub max_range_mm: f32,
    /// Lowest point-cloud point kept, mm.
    pub z_min_mm: f32,
    /// Highest point-cloud point kept, mm.
    pub z_max_mm: f32,
    /// Range noise of a laser centroid, mm.
    pub range_sigma_mm: f64,
    /// Bearing noise of a laser centroid, rad.
    pub bearing_sigma_rad: f64,
    /// Position noise of a point-cloud centroid, mm.
    pub position_sigma_mm: f64,
    /// Tracker parameters.
    pub tracker: TrackerConfig,
}

impl Default for ObstacleConfig {
    fn default() -> Self {
        Self {
            cluster_radius_mm: 100.0,
            min_cluster_points: 3,
            min_range_mm: 50.0,
            max_range_mm: 30_000.0,
            z_min_mm: -500.0,
            z_max_mm: 1500.0,
            range_sigma_mm: 30.0,
            bearing_sigma_rad: 0.01,
            position_sigma_mm: 50.0,
            tracker: TrackerConfig::default(),
        }
    }
}

/// A sensor whose readings can be clustered into obstacles.
pub trait ClusterSource: Sensor {
    /// Points (mm, sensor frame) of a reading, with z = 0 for planar sensors.
    fn points(reading: &Self::Reading, config: &ObstacleConfig) -> Vec<[f32; 3]>;
    /// The measurement of a cluster centroid.
    fn measurement(centroid: [f64; 2], config: &ObstacleConfig) -> Measurement;
}

/// The points of a laser scan (mm) that are returns: finite range within the configured limits.
pub fn scan_points(scan: &LaserScan, min_range_mm: f32, max_range_mm: f32) -> Vec<[f32; 3]> {
    scan.dists_mm
        .iter()
        .zip(scan.angles_rad.iter())
        .filter(|(d, _)| d.is_finite() && **d >= min_range_mm && **d <= max_range_mm)
        .map(|(d, a)| [d * a.cos(), d * a.sin(), 0.0])
        .collect()
}

impl ClusterSource for Laser {
    fn points(reading: &LaserScan, config: &ObstacleConfig) -> Vec<[f32; 3]> {
        scan_points(reading, config.min_range_mm, config.max_range_mm)
    }

    fn measurement(centroid: [f64; 2], config: &ObstacleConfig) -> Measurement {
        Measurement::RangeBearing {
            range_mm: centroid[0].hypot(centroid[1]),
            bearing_rad: centroid[1].atan2(centroid[0]),
            range_sigma_mm: config.range_sigma_mm,
            bearing_sigma_rad: config.bearing_sigma_rad,
        }
    }
}

impl ClusterSource for Lidar {
    fn points(reading: &PointCloud, config: &ObstacleConfig) -> Vec<[f32; 3]> {
        let mut points = Vec::with_capacity(reading.x_mm.len());
        let mut skipped = 0usize;
        for ((x, y), z) in reading.x_mm.iter().zip(reading.y_mm.iter()).zip(reading.z_mm.iter()) {
            if !(x.is_finite() && y.is_finite() && z.is_finite()) {
                skipped += 1;
            } else if *z >= config.z_min_mm && *z <= config.z_max_mm && (*x != 0.0 || *y != 0.0) {
                points.push([*x, *y, 0.0]);
            }
        }
        if skipped > 0 {
            tracing::debug!(skipped, "point cloud has non-finite points");
        }
        points
    }

    fn measurement(centroid: [f64; 2], config: &ObstacleConfig) -> Measurement {
        let variance = config.position_sigma_mm.powi(2);
        Measurement::Cartesian { position_mm: centroid, covariance_mm2: [[variance, 0.0], [0.0, variance]] }
    }
}

/// A cluster found in the latest reading.
#[derive(Debug, Clone, PartialEq)]
pub struct Cluster {
    /// Centroid, mm (sensor frame, xy).
    pub centroid_mm: [f64; 2],
    /// Number of points.
    pub points: usize,
}

/// BICA component: clusters each new reading of `SensorReader<S>` (which it steps first) and tracks the
/// clusters; keeps `obstacle_<sensor node name>_<track id>` nodes in the graph.
pub struct ObstacleDetector<S: ClusterSource> {
    graph: SharedGraph,
    config: ObstacleConfig,
    tracker: Tracker,
    clusters: Vec<Cluster>,
    nodes: Option<DetectionNodes>,
    last_time_ns: Option<u64>,
    marker: PhantomData<fn() -> S>,
}

impl<S: ClusterSource> std::fmt::Debug for ObstacleDetector<S> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ObstacleDetector")
            .field("sensor", &S::KIND)
            .field("clusters", &self.clusters.len())
            .field("tracks", &self.tracker.tracks().len())
            .finish_non_exhaustive()
    }
}

/// Obstacles in laser scans.
pub type LaserObstacleDetector = ObstacleDetector<Laser>;
/// Obstacles in point clouds.
pub type CloudObstacleDetector = ObstacleDetector<Lidar>;

impl<S: ClusterSource> ObstacleDetector<S> {
    /// A detector writing to `graph`.
    pub fn new(graph: SharedGraph, config: ObstacleConfig) -> Self {
        let tracker = Tracker::new(config.tracker.clone());
        Self { graph, config, tracker, clusters: Vec::new(), nodes: None, last_time_ns: None, marker: PhantomData }
    }

    /// Clusters of the latest reading.
    pub fn clusters(&self) -> &[Cluster] {
        &self.clusters
    }

    /// The tracker.
    pub fn tracker(&self) -> &Tracker {
        &self.tracker
    }

    /// The graph node of each confirmed track.
    pub fn track_nodes(&self) -> Option<&DetectionNodes> {
        self.nodes.as_ref()
    }

    /// Clusters a reading (what one step does with a fresh reading, without the tracking).
    pub fn cluster(&self, reading: &S::Reading) -> Vec<Cluster> {
        let points = S::points(reading, &self.config);
        euclidean_clusters(&points, self.config.cluster_radius_mm, self.config.min_cluster_points)
            .into_iter()
            .map(|indices| {
                let n = indices.len() as f64;
                let sum = indices
                    .iter()
                    .fold([0.0f64; 2], |acc, &i| [acc[0] + f64::from(points[i][0]), acc[1] + f64::from(points[i][1])]);
                Cluster { centroid_mm: [sum[0] / n, sum[1] / n], points: indices.len() }
            })
            .collect()
    }
}

impl<S: ClusterSource> Component for ObstacleDetector<S> {
    fn step(&mut self, ctx: &mut StepContext<'_>) -> Result<(), BicaError> {
        ctx.step::<SensorReader<S>>()?;
        let reader = ctx.get::<SensorReader<S>>()?;
        let (Some(reading), Some(sensor)) = (reader.latest(), reader.node()) else { return Ok(()) };
        if !reader.is_fresh() {
            return Ok(());
        }
        let time_ns = reader.latest_stamp_ns().unwrap_or_else(|| ctx.now_ns());
        let sensor_name = reader.node_name().to_owned();
        let dt_s = self.last_time_ns.map_or(0.0, |last| time_ns.saturating_sub(last) as f64 * 1e-9);
        self.last_time_ns = Some(time_ns);
        self.clusters = self.cluster(reading);
        let detections: Vec<Detection> = self
            .clusters
            .iter()
            .map(|c| Detection { tag: 0, measurement: S::measurement(c.centroid_mm, &self.config) })
            .collect();
        self.tracker.step(dt_s, &detections);
        let tracks: Vec<TrackNode> = self
            .tracker
            .confirmed()
            .map(|t| {
                let p = t.filter.position_mm();
                let c = t.filter.position_covariance();
                let v = t.filter.velocity_mm_s();
                TrackNode {
                    track_id: t.id,
                    position_mm: [p[0] as f32, p[1] as f32, 0.0],
                    covariance: [c[(0, 0)] as f32, c[(0, 1)] as f32, c[(1, 0)] as f32, c[(1, 1)] as f32],
                    velocity: [v[0] as f32, v[1] as f32],
                    extra: Vec::new(),
                }
            })
            .collect();
        let nodes =
            self.nodes.get_or_insert_with(|| DetectionNodes::new("obstacle", format!("obstacle_{sensor_name}")));
        nodes.sync(&mut *self.graph.borrow_mut(), ctx.now_ns(), sensor, &tracks);
        Ok(())
    }

    fn as_debuggable(&self) -> Option<&dyn Debuggable> {
        Some(self)
    }
}

/// Draws, in the robot frame (metres; the sensor frame is taken as the robot's), each cluster centroid as a point
/// and each confirmed track as its 95 % position ellipse with its id.
impl<S: ClusterSource> Debuggable for ObstacleDetector<S> {
    fn debug_primitives(&self, out: &mut Vec<DebugPrimitive>) {
        let grey = Rgba { r: 160, g: 160, b: 160, a: 255 };
        let red = Rgba { r: 230, g: 40, b: 40, a: 255 };
        for cluster in &self.clusters {
            let at = Point2 { x: cluster.centroid_mm[0] / 1000.0, y: cluster.centroid_mm[1] / 1000.0 };
            out.push(DebugPrimitive::new(Frame::Robot, Shape::Point { at }, grey));
        }
        for track in self.tracker.confirmed() {
            let p = track.filter.position_mm();
            let center = Point2 { x: p[0] / 1000.0, y: p[1] / 1000.0 };
            let (major, minor, rotation_rad) = track.filter.position_ellipse(5.99);
            let shape = Shape::Ellipse { center, radius_x: major / 1000.0, radius_y: minor / 1000.0, rotation_rad };
            out.push(DebugPrimitive::new(Frame::Robot, shape, red));
            out.push(DebugPrimitive::new(
                Frame::Robot,
                Shape::Text { at: center, text: format!("#{}", track.id) },
                red,
            ));
        }
    }
}
