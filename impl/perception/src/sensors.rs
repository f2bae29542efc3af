//! Graph sensor readers: BICA components that read the latest camera image, laser scan, point cloud, IMU
//! sample or pose from a sensor node of the graph (attribute names of the type dictionary) and publish it as
//! their result, plus the matching writers a bridge uses to inject sensor data.
//!
//! A reading whose attributes are missing is simply absent. A malformed one (sizes that disagree, NaNs where
//! numbers are needed, an unknown encoding) is logged with `tracing::warn!`, counted and skipped: the reader
//! keeps publishing the previous good reading and reports it as not fresh.

use std::marker::PhantomData;
use std::sync::Arc;

use bica::prelude::*;
use bytes::Bytes;
use dsr::{Dot, NodeId, Numbers, Value, attrs};

use crate::graph::{GraphAccess, GraphError, SharedGraph};

/// Why a sensor attribute set was rejected.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SensorError {
    /// Sizes or values that do not fit together.
    #[error("malformed {sensor} reading on node {node:?}: {reason}")]
    Malformed {
        /// Sensor kind (`camera`, `laser`, ...).
        sensor: &'static str,
        /// The sensor node.
        node: NodeId,
        /// What is wrong.
        reason: String,
    },
}

/// Pixel layout of an [`Image`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Encoding {
    /// One byte of grey per pixel.
    Mono8,
    /// Red, green, blue bytes per pixel.
    Rgb8,
    /// Blue, green, red bytes per pixel.
    Bgr8,
}

impl Encoding {
    /// Parses a ROS-style encoding name.
    pub fn parse(name: &str) -> Option<Self> {
        match name {
            "mono8" => Some(Self::Mono8),
            "rgb8" => Some(Self::Rgb8),
            "bgr8" => Some(Self::Bgr8),
            _ => None,
        }
    }

    /// The name written in `cam_rgb_encoding`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Mono8 => "mono8",
            Self::Rgb8 => "rgb8",
            Self::Bgr8 => "bgr8",
        }
    }

    /// Bytes per pixel.
    pub fn channels(self) -> usize {
        match self {
            Self::Mono8 => 1,
            Self::Rgb8 | Self::Bgr8 => 3,
        }
    }
}

/// A camera image (row-major, no padding).
#[derive(Debug, Clone, PartialEq)]
pub struct Image {
    /// Width, px.
    pub width: usize,
    /// Height, px.
    pub height: usize,
    /// Pixel layout.
    pub encoding: Encoding,
    /// `width * height * channels` bytes.
    pub data: Bytes,
}

impl Image {
    /// An image, checking the buffer size.
    ///
    /// # Errors
    /// A message naming the sizes if `data` does not hold exactly `width * height * channels` bytes.
    pub fn new(width: usize, height: usize, encoding: Encoding, data: Bytes) -> Result<Self, String> {
        let expected = width.checked_mul(height).and_then(|p| p.checked_mul(encoding.channels()));
        if expected != Some(data.len()) || width == 0 || height == 0 {
            return Err(format!("{width}x{height} {} needs {expected:?} bytes, got {}", encoding.name(), data.len()));
        }
        Ok(Self { width, height, encoding, data })
    }
}

/// A planar laser scan in the sensor's frame.
#[derive(Debug, Clone, PartialEq)]
pub struct LaserScan {
    /// Range of each beam, mm (non-finite or non-positive: no return).
    pub dists_mm: Numbers<f32>,
    /// Angle of each beam, rad (counter-clockwise from x).
    pub angles_rad: Numbers<f32>,
}

/// A 3-D point cloud in the sensor's frame, mm.
#[derive(Debug, Clone, PartialEq)]
pub struct PointCloud {
    /// x coordinates.
    pub x_mm: Numbers<f32>,
    /// y coordinates.
    pub y_mm: Numbers<f32>,
    /// z coordinates.
    pub z_mm: Numbers<f32>,
}

/// One IMU sample.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ImuSample {
    /// rad/s.
    pub angular_velocity: [f32; 3],
    /// m/s².
    pub linear_acceleration: [f32; 3],
    /// Quaternion x, y, z, w (if the IMU gives one).
    pub orientation: Option<[f32; 4]>,
}

/// A pose.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pose {
    /// mm.
    pub translation_mm: [f32; 3],
    /// Quaternion x, y, z, w.
    pub rotation: [f32; 4],
}

/// A kind of sensor the generic [`SensorReader`] can read.
pub trait Sensor: 'static {
    /// What one reading is.
    type Reading: std::fmt::Debug + 'static;
    /// Sensor kind for messages.
    const KIND: &'static str;
    /// Reads the node's attributes: `Ok(None)` when the reading's attributes are absent.
    ///
    /// # Errors
    /// [`SensorError::Malformed`] when they are present but inconsistent.
    fn read(graph: &dyn GraphAccess, node: NodeId) -> Result<Option<Self::Reading>, SensorError>;
    /// The attributes `read` uses: a write to any of them makes a new reading.
    const ATTRS: &'static [&'static str];
}

fn malformed(sensor: &'static str, node: NodeId, reason: impl Into<String>) -> SensorError {
    SensorError::Malformed { sensor, node, reason: reason.into() }
}

/// Marker: camera images (`cam_rgb`, `cam_rgb_width`, `cam_rgb_height`, `cam_rgb_depth`, `cam_rgb_encoding`).
#[derive(Debug)]
pub struct Camera;

impl Sensor for Camera {
    type Reading = Image;
    const KIND: &'static str = "camera";
    const ATTRS: &'static [&'static str] = &[
        attrs::CAM_RGB.name(),
        attrs::CAM_RGB_WIDTH.name(),
        attrs::CAM_RGB_HEIGHT.name(),
        attrs::CAM_RGB_DEPTH.name(),
        attrs::CAM_RGB_ENCODING.name(),
    ];

    fn read(graph: &dyn GraphAccess, node: NodeId) -> Result<Option<Image>, SensorError> {
        let Some(data) = graph.get(node, attrs::CAM_RGB) else { return Ok(None) };
        let bad = |reason: String| malformed(Self::KIND, node, reason);
        let width = graph.get(node, attrs::CAM_RGB_WIDTH).ok_or_else(|| bad("no cam_rgb_width".into()))?;
        let height = graph.get(node, attrs::CAM_RGB_HEIGHT).ok_or_else(|| bad("no cam_rgb_height".into()))?;
        let depth = graph.get(node, attrs::CAM_RGB_DEPTH);
        let encoding = match graph.get(node, attrs::CAM_RGB_ENCODING) {
            Some(name) => Encoding::parse(&name).ok_or_else(|| bad(format!("unknown cam_rgb_encoding `{name}`")))?,
            None => match depth {
                Some(1) => Encoding::Mono8,
                Some(3) => Encoding::Rgb8,
                other => return Err(bad(format!("no cam_rgb_encoding and cam_rgb_depth {other:?}"))),
            },
        };
        if let Some(depth) = depth
            && usize::try_from(depth).ok() != Some(encoding.channels())
        {
            return Err(bad(format!("cam_rgb_depth {depth} disagrees with encoding {}", encoding.name())));
        }
        let (Ok(width), Ok(height)) = (usize::try_from(width), usize::try_from(height)) else {
            return Err(bad(format!("negative size {width}x{height}")));
        };
        Image::new(width, height, encoding, data).map(Some).map_err(bad)
    }
}

/// Marker: laser scans (`laser_dists` in mm, `laser_angles` in rad).
#[derive(Debug)]
pub struct Laser;

impl Sensor for Laser {
    type Reading = LaserScan;
    const KIND: &'static str = "laser";
    const ATTRS: &'static [&'static str] = &[attrs::LASER_DISTS.name(), attrs::LASER_ANGLES.name()];

    fn read(graph: &dyn GraphAccess, node: NodeId) -> Result<Option<LaserScan>, SensorError> {
        let Some(dists_mm) = graph.get(node, attrs::LASER_DISTS) else { return Ok(None) };
        let angles_rad = graph
            .get(node, attrs::LASER_ANGLES)
            .ok_or_else(|| malformed(Self::KIND, node, "laser_dists without laser_angles"))?;
        if dists_mm.len() != angles_rad.len() {
            return Err(malformed(
                Self::KIND,
                node,
                format!("{} laser_dists but {} laser_angles", dists_mm.len(), angles_rad.len()),
            ));
        }
        if let Some(index) = angles_rad.iter().position(|a| !a.is_finite()) {
            return Err(malformed(Self::KIND, node, format!("laser_angles[{index}] is not finite")));
        }
        Ok(Some(LaserScan { dists_mm, angles_rad }))
    }
}

/// Marker: point clouds (`lidar_points_x/y/z`, mm).
#[derive(Debug)]
pub struct Lidar;

impl Sensor for Lidar {
    type Reading = PointCloud;
    const KIND: &'static str = "lidar";
    const ATTRS: &'static [&'static str] =
        &[attrs::LIDAR_POINTS_X.name(), attrs::LIDAR_POINTS_Y.name(), attrs::LIDAR_POINTS_Z.name()];

    fn read(graph: &dyn GraphAccess, node: NodeId) -> Result<Option<PointCloud>, SensorError> {
        let Some(x_mm) = graph.get(node, attrs::LIDAR_POINTS_X) else { return Ok(None) };
        let y_mm = graph.get(node, attrs::LIDAR_POINTS_Y);
        let z_mm = graph.get(node, attrs::LIDAR_POINTS_Z);
        let (Some(y_mm), Some(z_mm)) = (y_mm, z_mm) else {
            return Err(malformed(Self::KIND, node, "lidar_points_x without lidar_points_y and lidar_points_z"));
        };
        if x_mm.len() != y_mm.len() || x_mm.len() != z_mm.len() {
            return Err(malformed(
                Self::KIND,
                node,
                format!("point arrays of different lengths: x {}, y {}, z {}", x_mm.len(), y_mm.len(), z_mm.len()),
            ));
        }
        Ok(Some(PointCloud { x_mm, y_mm, z_mm }))
    }
}

/// Marker: IMU samples (`imu_angular_velocity`, `imu_linear_acceleration`, optional `imu_orientation`).
#[derive(Debug)]
pub struct Imu;

fn finite<const N: usize>(values: &[f32; N]) -> bool {
    values.iter().all(|v| v.is_finite())
}

impl Sensor for Imu {
    type Reading = ImuSample;
    const KIND: &'static str = "imu";
    const ATTRS: &'static [&'static str] =
        &[attrs::IMU_ANGULAR_VELOCITY.name(), attrs::IMU_LINEAR_ACCELERATION.name(), attrs::IMU_ORIENTATION.name()];

    fn read(graph: &dyn GraphAccess, node: NodeId) -> Result<Option<ImuSample>, SensorError> {
        let angular = graph.get(node, attrs::IMU_ANGULAR_VELOCITY);
        let linear = graph.get(node, attrs::IMU_LINEAR_ACCELERATION);
        let (Some(angular_velocity), Some(linear_acceleration)) = (angular, linear) else { return Ok(None) };
        let orientation = graph.get(node, attrs::IMU_ORIENTATION);
        if !finite(&angular_velocity) || !finite(&linear_acceleration) || !orientation.as_ref().is_none_or(finite) {
            return Err(malformed(Self::KIND, node, "non-finite imu value"));
        }
        Ok(Some(ImuSample { angular_velocity, linear_acceleration, orientation }))
    }
}

/// Marker: poses (`pose_translation` in mm, `pose_rotation` quaternion).
#[derive(Debug)]
pub struct PoseSensor;

impl Sensor for PoseSensor {
    type Reading = Pose;
    const KIND: &'static str = "pose";
    const ATTRS: &'static [&'static str] = &[attrs::POSE_TRANSLATION.name(), attrs::POSE_ROTATION.name()];

    fn read(graph: &dyn GraphAccess, node: NodeId) -> Result<Option<Pose>, SensorError> {
        let translation = graph.get(node, attrs::POSE_TRANSLATION);
        let rotation = graph.get(node, attrs::POSE_ROTATION);
        let (Some(translation_mm), Some(rotation)) = (translation, rotation) else { return Ok(None) };
        if !finite(&translation_mm) || !finite(&rotation) {
            return Err(malformed(Self::KIND, node, "non-finite pose value"));
        }
        Ok(Some(Pose { translation_mm, rotation }))
    }
}

/// A BICA component that reads one sensor node of the graph each step and publishes the latest good reading.
///
/// A new reading is told from the previous one by the dots of the attributes it is made of ([`Sensor::ATTRS`]):
/// any write to one of them is a new reading, an unchanged set is the same reading read again.
pub struct SensorReader<S: Sensor> {
    graph: SharedGraph,
    node_name: String,
    node: Option<NodeId>,
    latest: Option<Arc<S::Reading>>,
    latest_stamp_ns: Option<u64>,
    version: Vec<Option<Dot>>,
    fresh: bool,
    readings: u64,
    malformed: u64,
    marker: PhantomData<fn() -> S>,
}

impl<S: Sensor> std::fmt::Debug for SensorReader<S> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SensorReader")
            .field("sensor", &S::KIND)
            .field("node_name", &self.node_name)
            .field("readings", &self.readings)
            .field("malformed", &self.malformed)
            .finish_non_exhaustive()
    }
}

/// Reads camera images.
pub type CameraReader = SensorReader<Camera>;
/// Reads laser scans.
pub type LaserReader = SensorReader<Laser>;
/// Reads point clouds.
pub type LidarReader = SensorReader<Lidar>;
/// Reads IMU samples.
pub type ImuReader = SensorReader<Imu>;
/// Reads poses.
pub type PoseReader = SensorReader<PoseSensor>;

impl<S: Sensor> SensorReader<S> {
    /// A reader of the node called `node_name`.
    pub fn new(graph: SharedGraph, node_name: impl Into<String>) -> Self {
        Self {
            graph,
            node_name: node_name.into(),
            node: None,
            latest: None,
            latest_stamp_ns: None,
            version: Vec::new(),
            fresh: false,
            readings: 0,
            malformed: 0,
            marker: PhantomData,
        }
    }

    /// The latest good reading.
    pub fn latest(&self) -> Option<&Arc<S::Reading>> {
        self.latest.as_ref()
    }

    /// The `stamp_ns` attribute of the sensor node when the latest reading was taken, if it had one.
    pub fn latest_stamp_ns(&self) -> Option<u64> {
        self.latest_stamp_ns
    }

    /// Whether the last step found a new good reading.
    pub fn is_fresh(&self) -> bool {
        self.fresh
    }

    /// The sensor node, once found.
    pub fn node(&self) -> Option<NodeId> {
        self.node
    }

    /// The name of the sensor node.
    pub fn node_name(&self) -> &str {
        &self.node_name
    }

    /// Good readings seen.
    pub fn readings(&self) -> u64 {
        self.readings
    }

    /// Malformed readings skipped.
    pub fn malformed(&self) -> u64 {
        self.malformed
    }

    /// Reads the graph once: what one step does.
    pub fn poll(&mut self) {
        self.fresh = false;
        let graph = self.graph.borrow();
        let node = match self.node.filter(|id| graph.node_type(*id).is_some()) {
            Some(node) => node,
            None => match graph.find_node(&self.node_name) {
                Some(node) => node,
                None => {
                    self.node = None;
                    return;
                }
            },
        };
        self.node = Some(node);
        let version: Vec<Option<Dot>> = S::ATTRS.iter().map(|name| graph.node_attr_dot(node, name)).collect();
        if version == self.version {
            return;
        }
        self.version = version;
        match S::read(&*graph, node) {
            Ok(Some(reading)) => {
                self.latest = Some(Arc::new(reading));
                self.latest_stamp_ns = graph.get(node, attrs::STAMP_NS);
                self.fresh = true;
                self.readings += 1;
            }
            Ok(None) => {}
            Err(error) => {
                self.malformed += 1;
                tracing::warn!(node = %self.node_name, %error, "skipping malformed sensor reading");
            }
        }
    }
}

impl<S: Sensor> Component for SensorReader<S> {
    fn step(&mut self, _ctx: &mut StepContext<'_>) -> Result<(), BicaError> {
        self.poll();
        Ok(())
    }
}

/// Writes an image into a camera node's attributes (what a bridge does), with its stamp and sequence.
///
/// # Errors
/// As [`GraphAccess::set_node_attrs`].
pub fn write_image(
    graph: &mut dyn GraphAccess,
    now_ns: u64,
    node: NodeId,
    image: &Image,
    stamp_ns: u64,
    sequence: u64,
) -> Result<(), GraphError> {
    let size = |v: usize| Value::I32(i32::try_from(v).unwrap_or(i32::MAX));
    graph.set_node_attrs(
        now_ns,
        node,
        vec![
            (attrs::CAM_RGB.name(), Value::Bytes(image.data.clone())),
            (attrs::CAM_RGB_WIDTH.name(), size(image.width)),
            (attrs::CAM_RGB_HEIGHT.name(), size(image.height)),
            (attrs::CAM_RGB_DEPTH.name(), size(image.encoding.channels())),
            (attrs::CAM_RGB_ENCODING.name(), Value::from(image.encoding.name())),
            (attrs::STAMP_NS.name(), Value::U64(stamp_ns)),
            (attrs::SEQUENCE.name(), Value::U64(sequence)),
        ],
    )
}

/// Writes a laser scan (mm, rad) into a laser node's attributes.
///
/// # Errors
/// As [`GraphAccess::set_node_attrs`].
pub fn write_scan(
    graph: &mut dyn GraphAccess,
    now_ns: u64,
    node: NodeId,
    scan: &LaserScan,
    stamp_ns: u64,
    sequence: u64,
) -> Result<(), GraphError> {
    graph.set_node_attrs(
        now_ns,
        node,
        vec![
            (attrs::LASER_DISTS.name(), Value::VecF32(scan.dists_mm.clone())),
            (attrs::LASER_ANGLES.name(), Value::VecF32(scan.angles_rad.clone())),
            (attrs::STAMP_NS.name(), Value::U64(stamp_ns)),
            (attrs::SEQUENCE.name(), Value::U64(sequence)),
        ],
    )
}

/// Writes a point cloud (mm) into a lidar node's attributes.
///
/// # Errors
/// As [`GraphAccess::set_node_attrs`].
pub fn write_cloud(
    graph: &mut dyn GraphAccess,
    now_ns: u64,
    node: NodeId,
    cloud: &PointCloud,
    stamp_ns: u64,
    sequence: u64,
) -> Result<(), GraphError> {
    graph.set_node_attrs(
        now_ns,
        node,
        vec![
            (attrs::LIDAR_POINTS_X.name(), Value::VecF32(cloud.x_mm.clone())),
            (attrs::LIDAR_POINTS_Y.name(), Value::VecF32(cloud.y_mm.clone())),
            (attrs::LIDAR_POINTS_Z.name(), Value::VecF32(cloud.z_mm.clone())),
            (attrs::STAMP_NS.name(), Value::U64(stamp_ns)),
            (attrs::SEQUENCE.name(), Value::U64(sequence)),
        ],
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::graph::share_replica;
    use dsr::{NewNode, Replica, ReplicaId};

    #[test]
    fn camera_reader_publishes_new_images_and_skips_malformed_ones() {
        let (_replica, graph) = share_replica(Replica::new(ReplicaId(1)));
        let camera = graph.borrow_mut().insert_node(1, NewNode::new("camera", "cam")).unwrap();
        let mut reader = CameraReader::new(graph.clone(), "cam");
        reader.poll();
        assert!(reader.latest().is_none());
        let image = Image::new(4, 2, Encoding::Mono8, Bytes::from(vec![7u8; 8])).unwrap();
        write_image(&mut *graph.borrow_mut(), 2, camera, &image, 100, 1).unwrap();
        reader.poll();
        assert!(reader.is_fresh());
        assert_eq!(**reader.latest().unwrap(), image);
        reader.poll();
        assert!(!reader.is_fresh(), "the same reading read again is not fresh");
        // Wrong size: warned, counted, skipped; the previous image stays.
        graph.borrow_mut().set_node_attrs(3, camera, vec![(attrs::CAM_RGB_WIDTH.name(), Value::I32(5))]).unwrap();
        reader.poll();
        assert!(!reader.is_fresh());
        assert_eq!(reader.malformed(), 1);
        assert_eq!(**reader.latest().unwrap(), image);
    }

    #[test]
    fn laser_reader_rejects_mismatched_lengths_and_nan_angles() {
        let (_replica, graph) = share_replica(Replica::new(ReplicaId(1)));
        let laser = graph.borrow_mut().insert_node(1, NewNode::new("laser", "laser")).unwrap();
        let mut reader = LaserReader::new(graph.clone(), "laser");
        let set = |now: u64, dists: Vec<f32>, angles: Vec<f32>| {
            graph
                .borrow_mut()
                .set_node_attrs(
                    now,
                    laser,
                    vec![(attrs::LASER_DISTS.name(), dists.into()), (attrs::LASER_ANGLES.name(), angles.into())],
                )
                .unwrap();
        };
        set(2, vec![1.0, 2.0], vec![0.0]);
        reader.poll();
        assert_eq!((reader.readings(), reader.malformed()), (0, 1));
        set(3, vec![1.0, 2.0], vec![0.0, f32::NAN]);
        reader.poll();
        assert_eq!((reader.readings(), reader.malformed()), (0, 2));
        set(4, vec![1.0, f32::NAN], vec![0.0, 0.1]);
        reader.poll();
        assert_eq!((reader.readings(), reader.malformed()), (1, 2), "NaN ranges are no-returns, not malformed");
    }
}
