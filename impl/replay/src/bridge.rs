//! The bridge: decoded log messages become graph operations on a [`dsr::Replica`].
//!
//! Mapping (units as the dictionary documents them):
//!
//! - every topic gets one node named after the topic (`/cam0/image_raw`), typed by its message: `camera` (Image,
//!   CompressedImage, CameraInfo), `lidar` (PointCloud2), `laser` (LaserScan), `imu`, `gps` (NavSatFix), `pose`
//!   (PoseStamped), `odometry`, or `topic` for opaque payloads. When its first message has a `frame_id`, the node
//!   hangs under a node of that frame (type `transform`, named after the frame) by an identity RT edge;
//! - each message writes the node's attributes in one delta: `cam_rgb` (the pixels, not copied; rows repacked only
//!   when padded), `cam_rgb_width/height/depth/encoding`; `laser_dists` (m → mm), `laser_angles` (rad),
//!   `laser_intensities`; `lidar_points_x/y/z` (m → mm), `lidar_intensity`; `imu_*`; `gps_*`;
//!   `pose_translation` (m → mm) and `pose_rotation`; `odom_linear_velocity` (m/s → mm/s), `odom_angular_velocity`;
//!   camera info as `cam_rgb_width/height/focalx/focaly`; plus `stamp_ns` (the header stamp) and `sequence` (the
//!   message's index on its topic);
//! - `tf2_msgs/TFMessage` (on `/tf` or `/tf_static`) becomes RT edges between frame nodes with
//!   [`Replica::set_rt`]: translation m → mm, quaternion → Euler x-y-z ([`dsr::kinematics::euler_xyz`]). A frame
//!   that moves to another parent loses its old RT edge first; a transform that would close an RT cycle is refused
//!   and counted.
//!
//! Known types are decoded from CDR (ROS 2) or ROS 1 serialization alike ([`ros2::decode_as`]), under either name
//! a type goes by (`sensor_msgs/LaserScan`, `sensor_msgs/msg/LaserScan`). A message of another type whose log carries
//! its definition (`ros1msg`/`ros2msg`) is decoded from it ([`generic`]) into attributes of a `topic` node named after
//! the topic (`RadarScan.targets.0.range`, …; its header's frame and stamp as for the known types), counted in
//! [`BridgeStats::described`]. Messages of other types (no definition, another encoding), and with
//! [`BridgeOptions::opaque`] every message of a type the bridge has no decoder for, are counted as unknown, and carried
//! as an opaque `opaque_payload` attribute on a `topic` node if [`BridgeOptions::opaque`] is set. Malformed payloads,
//! definitions that do not parse and refused graph operations are counted per topic, with the first few messages
//! kept; they never stop a replay and never panic.
//!
//! The names a log defines (a described message's fields, the `topic` node type and the opaque attributes) join the
//! graph's dictionary as the bridge writes them, as a CORTEX file's names do: any replica works, the built-in one of
//! a `cortex agent` included, and replicas that receive the deltas learn the names from them. [`dictionary`] is the
//! same set declared up front, for callers that want it.

use std::collections::{BTreeMap, HashMap};
use std::sync::Arc;

use bytes::Bytes;
use dsr::{Delta, Dictionary, DictionaryError, EdgeKey, NewNode, NodeId, Numbers, OpError, Replica, Value, attrs};
use nalgebra::{Quaternion, UnitQuaternion};

use crate::generic::{self, GenericError};
use crate::log::{Message, Schema};
use crate::msgdef::{DefinitionError, Definitions, ros2_type_name};
use crate::ros2::{self, Encoding, Header, Ros2Message};

/// Node type of opaque topics.
pub const OPAQUE_NODE_TYPE: &str = "topic";
/// Attribute holding an opaque payload (bytes).
pub const OPAQUE_PAYLOAD: &str = "opaque_payload";
/// Attribute holding the type name of an opaque payload (string).
pub const OPAQUE_TYPE: &str = "opaque_type";
/// Node type of TF frames.
pub const FRAME_NODE_TYPE: &str = "transform";
/// How many error messages [`BridgeStats::first_errors`] keeps.
pub const KEPT_ERRORS: usize = 10;

/// A dictionary for the bridge's replica declared up front: the built-in one, accepting unknown attribute names
/// (those of messages decoded from their definitions), plus the opaque topic node type and its two attributes. (The
/// bridge teaches any replica these names as it writes them; this is for callers that want them declared first.)
///
/// # Errors
/// Only if the built-in dictionary already gives these names other types.
pub fn dictionary() -> Result<Dictionary, DictionaryError> {
    let mut dictionary = Dictionary::permissive();
    dictionary.declare_node_type(OPAQUE_NODE_TYPE)?;
    dictionary.declare_attr(OPAQUE_PAYLOAD, dsr::ValueType::Bytes)?;
    dictionary.declare_attr(OPAQUE_TYPE, dsr::ValueType::String)?;
    Ok(dictionary)
}

/// What the bridge does with messages.
#[derive(Debug, Clone, Default)]
pub struct BridgeOptions {
    /// Only these topics (all if `None`); other messages are counted as filtered.
    pub topics: Option<Vec<String>>,
    /// Carry messages of types without a decoder as opaque bytes, instead of decoding them from the definitions their
    /// log carries (or skipping them when it carries none).
    pub opaque: bool,
}

/// What the bridge has seen and done.
#[derive(Debug, Clone, Default, PartialEq, Eq, serde::Serialize)]
pub struct BridgeStats {
    /// Messages offered.
    pub messages: u64,
    /// Payload bytes of the messages offered.
    pub bytes: u64,
    /// Messages decoded and written, by type.
    pub decoded: BTreeMap<String, u64>,
    /// Messages of types without a decoder, decoded from the definitions their log carries, by type (ROS 2 name).
    pub described: BTreeMap<String, u64>,
    /// Values of described messages read but not kept (over the attribute or unrolling limits of [`generic::Limits`]).
    pub described_dropped: u64,
    /// Messages of unknown types (carried or skipped), by type (ROS 2 name; with the encoding when it is neither
    /// `cdr` nor `ros1`).
    pub unknown: BTreeMap<String, u64>,
    /// Unknown messages carried as opaque bytes.
    pub opaque: u64,
    /// Messages on topics not selected.
    pub filtered: u64,
    /// Messages that failed (bad payload or refused graph operation), by topic.
    pub errors: BTreeMap<String, u64>,
    /// The first few error messages.
    pub first_errors: Vec<String>,
    /// TF transforms refused because they would close an RT cycle or name one frame as its own parent.
    pub tf_refused: u64,
    /// Deltas produced.
    pub deltas: u64,
}

impl BridgeStats {
    /// Total messages that failed.
    pub fn error_count(&self) -> u64 {
        self.errors.values().sum()
    }
}

/// Why one message could not be written.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
enum Failure {
    #[error("{0}")]
    Decode(#[from] ros2::DecodeError),
    #[error("graph refused an operation: {0}")]
    Graph(#[from] OpError),
    #[error("{0}")]
    Definition(#[from] DefinitionError),
    #[error("{0}")]
    Described(#[from] GenericError),
    #[error("a name of the log cannot be held: {0}")]
    Name(#[from] DictionaryError),
}

/// Teaches the replica's dictionary the topic node type and the attribute names (with their types) a message of a
/// type without a built-in decoder writes: names the log defines join the graph's dictionary, as those of a CORTEX
/// file do (`dsr::json`), so an agent whose dictionary is the built-in one (every `cortex agent`) writes them, and
/// every replica that receives them learns them too.
fn learn_log_names(replica: &mut Replica, values: &[(&str, Value)]) -> Result<(), DictionaryError> {
    replica.learn_names(values.iter().map(|(name, value)| (*name, value.value_type())), [OPAQUE_NODE_TYPE])
}

/// A topic's parsed definitions, kept with the schema they were parsed from.
type CachedDefinitions = (Arc<Schema>, Result<Arc<Definitions>, DefinitionError>);

/// Maps messages to graph operations; holds the topic and frame nodes it created.
#[derive(Debug, Default)]
pub struct Bridge {
    options: BridgeOptions,
    topics: HashMap<String, NodeId>,
    frames: HashMap<String, NodeId>,
    sequences: HashMap<String, u64>,
    definitions: HashMap<String, CachedDefinitions>,
    stats: BridgeStats,
}

impl Bridge {
    /// A bridge with `options`.
    pub fn new(options: BridgeOptions) -> Self {
        Bridge { options, ..Bridge::default() }
    }

    /// What the bridge has seen and done so far.
    pub fn stats(&self) -> &BridgeStats {
        &self.stats
    }

    /// The node of a topic, once its first message has been written.
    pub fn topic_node(&self, topic: &str) -> Option<NodeId> {
        self.topics.get(topic).copied()
    }

    /// The node of a TF frame, once it has been met.
    pub fn frame_node(&self, frame: &str) -> Option<NodeId> {
        self.frames.get(frame).copied()
    }

    /// Writes one message into `replica` at `now_ns` and returns the deltas to send. `shift_ns` is added to the
    /// header stamp (used when a log is looped, so stamps keep growing). Failures are counted in [`Self::stats`].
    pub fn ingest(&mut self, replica: &mut Replica, now_ns: u64, message: &Message, shift_ns: u64) -> Vec<Arc<Delta>> {
        let topic = message.channel.topic.as_str();
        self.stats.messages += 1;
        self.stats.bytes += message.data.len() as u64;
        if let Some(topics) = &self.options.topics
            && !topics.iter().any(|selected| selected == topic)
        {
            self.stats.filtered += 1;
            return Vec::new();
        }
        let mut deltas = Vec::new();
        let outcome = self.write(replica, now_ns, message, shift_ns, &mut deltas);
        if let Err(failure) = outcome {
            *self.stats.errors.entry(topic.to_owned()).or_default() += 1;
            if self.stats.first_errors.len() < KEPT_ERRORS {
                let where_ = format!("topic {topic}, message at log time {} ns", message.log_time);
                self.stats.first_errors.push(format!("{where_}: {failure}"));
            }
        }
        self.stats.deltas += deltas.len() as u64;
        deltas
    }

    fn write(
        &mut self,
        replica: &mut Replica,
        now: u64,
        message: &Message,
        shift_ns: u64,
        deltas: &mut Vec<Arc<Delta>>,
    ) -> Result<(), Failure> {
        let channel = &message.channel;
        let type_name = channel.type_name();
        let encoding = Encoding::from_message_encoding(&channel.message_encoding);
        let decoded = match encoding {
            Some(encoding) => ros2::decode_as(type_name, encoding, &message.data)?,
            None => None,
        };
        let Some(decoded) = decoded else {
            if let Some(encoding) = encoding
                && !self.options.opaque
                && let Some(definitions) = self.definitions_for(message)?
            {
                return self.write_described(replica, now, message, shift_ns, encoding, &definitions, deltas);
            }
            return self.write_unknown(replica, now, message, shift_ns, deltas);
        };
        let canonical = ros2::known_type(type_name).unwrap_or("unknown");
        let sequence = self.next_sequence(&channel.topic);
        let stamp = |header: &Header| Value::U64(header.stamp_ns().saturating_add(shift_ns));
        let mut values: Vec<(&str, Value)> = Vec::with_capacity(8);
        let (node_type, header) = match &decoded {
            Ros2Message::Tf(transforms) => {
                for transform in transforms {
                    self.write_tf(replica, now, transform, deltas)?;
                }
                *self.stats.decoded.entry(canonical.to_owned()).or_default() += 1;
                return Ok(());
            }
            Ros2Message::Image(image) => {
                let channels = image.channels();
                let row = image.width as usize * channels as usize;
                let pixels = if image.step as usize > row && image.encoding.ends_with('8') {
                    repack_rows(&image.data, image.step as usize, row, image.height as usize)
                } else {
                    image.data.clone()
                };
                values.push((attrs::CAM_RGB.name(), Value::Bytes(pixels)));
                values.push((attrs::CAM_RGB_WIDTH.name(), Value::I32(saturating_i32(image.width))));
                values.push((attrs::CAM_RGB_HEIGHT.name(), Value::I32(saturating_i32(image.height))));
                values.push((attrs::CAM_RGB_DEPTH.name(), Value::I32(saturating_i32(channels))));
                values.push((attrs::CAM_RGB_ENCODING.name(), Value::String(Arc::from(image.encoding.as_str()))));
                ("camera", &image.header)
            }
            Ros2Message::CompressedImage(image) => {
                values.push((attrs::CAM_RGB.name(), Value::Bytes(image.data.clone())));
                values.push((attrs::CAM_RGB_ENCODING.name(), Value::String(Arc::from(image.format.as_str()))));
                ("camera", &image.header)
            }
            Ros2Message::CameraInfo(info) => {
                values.push((attrs::CAM_RGB_WIDTH.name(), Value::I32(saturating_i32(info.width))));
                values.push((attrs::CAM_RGB_HEIGHT.name(), Value::I32(saturating_i32(info.height))));
                values.push((attrs::CAM_RGB_FOCALX.name(), Value::I32(info.k[0].round() as i32)));
                values.push((attrs::CAM_RGB_FOCALY.name(), Value::I32(info.k[4].round() as i32)));
                ("camera", &info.header)
            }
            Ros2Message::PointCloud2(cloud) => {
                let columns = cloud.columns(1000.0)?;
                values.push((attrs::LIDAR_POINTS_X.name(), Value::VecF32(Numbers::from(columns.x))));
                values.push((attrs::LIDAR_POINTS_Y.name(), Value::VecF32(Numbers::from(columns.y))));
                values.push((attrs::LIDAR_POINTS_Z.name(), Value::VecF32(Numbers::from(columns.z))));
                if let Some(intensity) = columns.intensity {
                    values.push((attrs::LIDAR_INTENSITY.name(), Value::VecF32(Numbers::from(intensity))));
                }
                ("lidar", &cloud.header)
            }
            Ros2Message::LaserScan(scan) => {
                let dists: Arc<[f32]> = scan.ranges.iter().map(|range| range * 1000.0).collect();
                let angles: Arc<[f32]> = (0..scan.ranges.len())
                    .map(|i| (f64::from(scan.angle_min) + i as f64 * f64::from(scan.angle_increment)) as f32)
                    .collect();
                values.push((attrs::LASER_DISTS.name(), Value::VecF32(dists.into())));
                values.push((attrs::LASER_ANGLES.name(), Value::VecF32(angles.into())));
                if !scan.intensities.is_empty() {
                    values.push((
                        attrs::LASER_INTENSITIES.name(),
                        Value::VecF32(Numbers::from(scan.intensities.as_slice())),
                    ));
                }
                ("laser", &scan.header)
            }
            Ros2Message::Imu(imu) => {
                values.push((attrs::IMU_ORIENTATION.name(), Value::F32x4(f32s(imu.orientation, 1.0))));
                values.push((attrs::IMU_ANGULAR_VELOCITY.name(), Value::F32x3(f32s(imu.angular_velocity, 1.0))));
                values.push((attrs::IMU_LINEAR_ACCELERATION.name(), Value::F32x3(f32s(imu.linear_acceleration, 1.0))));
                ("imu", &imu.header)
            }
            Ros2Message::NavSatFix(fix) => {
                values.push((attrs::GPS_LATITUDE.name(), Value::F64(fix.latitude)));
                values.push((attrs::GPS_LONGITUDE.name(), Value::F64(fix.longitude)));
                values.push((attrs::GPS_ALTITUDE.name(), Value::F64(fix.altitude)));
                ("gps", &fix.header)
            }
            Ros2Message::PoseStamped(pose) => {
                values.push((attrs::POSE_TRANSLATION.name(), Value::F32x3(f32s(pose.pose.position, 1000.0))));
                values.push((attrs::POSE_ROTATION.name(), Value::F32x4(f32s(pose.pose.orientation, 1.0))));
                ("pose", &pose.header)
            }
            Ros2Message::Odometry(odometry) => {
                values.push((attrs::POSE_TRANSLATION.name(), Value::F32x3(f32s(odometry.pose.position, 1000.0))));
                values.push((attrs::POSE_ROTATION.name(), Value::F32x4(f32s(odometry.pose.orientation, 1.0))));
                values.push((attrs::ODOM_LINEAR_VELOCITY.name(), Value::F32x3(f32s(odometry.linear, 1000.0))));
                values.push((attrs::ODOM_ANGULAR_VELOCITY.name(), Value::F32x3(f32s(odometry.angular, 1.0))));
                ("odometry", &odometry.header)
            }
        };
        values.push((attrs::STAMP_NS.name(), stamp(header)));
        values.push((attrs::SEQUENCE.name(), Value::U64(sequence)));
        let node = self.topic_node_for(replica, now, &channel.topic, node_type, &header.frame_id, deltas)?;
        deltas.push(replica.set_attrs(now, node, values)?);
        *self.stats.decoded.entry(canonical.to_owned()).or_default() += 1;
        Ok(())
    }

    /// A message of an unknown type: counted, and carried as opaque bytes if asked.
    fn write_unknown(
        &mut self,
        replica: &mut Replica,
        now: u64,
        message: &Message,
        shift_ns: u64,
        deltas: &mut Vec<Arc<Delta>>,
    ) -> Result<(), Failure> {
        let channel = &message.channel;
        let type_name = channel.type_name();
        let key = match Encoding::from_message_encoding(&channel.message_encoding) {
            Some(_) => ros2_type_name(type_name),
            None => format!("{type_name} ({})", channel.message_encoding),
        };
        *self.stats.unknown.entry(key).or_default() += 1;
        if self.options.opaque {
            let values = vec![
                (OPAQUE_PAYLOAD, Value::Bytes(message.data.clone())),
                (OPAQUE_TYPE, Value::String(Arc::from(type_name))),
                (attrs::STAMP_NS.name(), Value::U64(message.log_time.saturating_add(shift_ns))),
            ];
            learn_log_names(replica, &values)?;
            let node = self.topic_node_for(replica, now, &channel.topic, OPAQUE_NODE_TYPE, "", deltas)?;
            deltas.push(replica.set_attrs(now, node, values)?);
            self.stats.opaque += 1;
        }
        Ok(())
    }

    /// The parsed definitions of a message's type, if its log carries them (`None` if it does not); parsed once per
    /// topic and schema.
    fn definitions_for(&mut self, message: &Message) -> Result<Option<Arc<Definitions>>, Failure> {
        let Some(schema) = &message.channel.schema else { return Ok(None) };
        if !generic::is_msg_definition(&schema.encoding) || schema.data.is_empty() {
            return Ok(None);
        }
        let topic = &message.channel.topic;
        let cached = self.definitions.get(topic).filter(|(parsed_from, _)| Arc::ptr_eq(parsed_from, schema));
        let parsed = match cached {
            Some((_, parsed)) => parsed.clone(),
            None => {
                let text = String::from_utf8_lossy(&schema.data);
                let parsed = Definitions::parse(&schema.name, &text).map(Arc::new);
                self.definitions.insert(topic.clone(), (schema.clone(), parsed.clone()));
                parsed
            }
        };
        Ok(Some(parsed?))
    }

    /// A message decoded from its definition: its attributes on the topic's node, under its header's frame.
    #[allow(clippy::too_many_arguments)]
    fn write_described(
        &mut self,
        replica: &mut Replica,
        now: u64,
        message: &Message,
        shift_ns: u64,
        encoding: Encoding,
        definitions: &Definitions,
        deltas: &mut Vec<Arc<Delta>>,
    ) -> Result<(), Failure> {
        let decoded = generic::decode(definitions, encoding, &message.data, generic::Limits::default())?;
        let topic = &message.channel.topic;
        let sequence = self.next_sequence(topic);
        let stamp_ns = decoded.stamp_ns.unwrap_or(message.log_time).saturating_add(shift_ns);
        let frame = decoded.frame_id.as_deref().unwrap_or("");
        let mut values: Vec<(&str, Value)> = Vec::with_capacity(decoded.values.len() + 2);
        values.extend(decoded.values.iter().map(|(name, value)| (name.as_str(), value.clone())));
        values.push((attrs::STAMP_NS.name(), Value::U64(stamp_ns)));
        values.push((attrs::SEQUENCE.name(), Value::U64(sequence)));
        learn_log_names(replica, &values)?;
        let node = self.topic_node_for(replica, now, topic, OPAQUE_NODE_TYPE, frame, deltas)?;
        deltas.push(replica.set_attrs(now, node, values)?);
        *self.stats.described.entry(ros2_type_name(definitions.root())).or_default() += 1;
        self.stats.described_dropped += decoded.dropped;
        Ok(())
    }

    /// The index of the next message on `topic`.
    fn next_sequence(&mut self, topic: &str) -> u64 {
        let counter = self.sequences.entry(topic.to_owned()).or_default();
        *counter += 1;
        *counter - 1
    }

    /// The node of `topic`, created (under its frame, if any) on first use.
    fn topic_node_for(
        &mut self,
        replica: &mut Replica,
        now: u64,
        topic: &str,
        node_type: &str,
        frame: &str,
        deltas: &mut Vec<Arc<Delta>>,
    ) -> Result<NodeId, Failure> {
        if let Some(&id) = self.topics.get(topic)
            && replica.node(id).is_some()
        {
            return Ok(id);
        }
        let id = match replica.node_by_name(topic) {
            Some(node) => node.id(),
            None => {
                let (id, delta) = replica.insert_node(now, NewNode::new(node_type, topic))?;
                deltas.push(delta);
                if !frame.is_empty() {
                    let parent = self.frame_for(replica, now, frame, deltas)?;
                    deltas.extend(replica.set_rt(now, parent, id, [0.0; 3], [0.0; 3])?);
                }
                id
            }
        };
        self.topics.insert(topic.to_owned(), id);
        Ok(id)
    }

    /// The node of a TF frame, created on first use.
    fn frame_for(
        &mut self,
        replica: &mut Replica,
        now: u64,
        frame: &str,
        deltas: &mut Vec<Arc<Delta>>,
    ) -> Result<NodeId, Failure> {
        if let Some(&id) = self.frames.get(frame)
            && replica.node(id).is_some()
        {
            return Ok(id);
        }
        let id = match replica.node_by_name(frame) {
            Some(node) => node.id(),
            None => {
                let (id, delta) = replica.insert_node(now, NewNode::new(FRAME_NODE_TYPE, frame))?;
                deltas.push(delta);
                id
            }
        };
        self.frames.insert(frame.to_owned(), id);
        Ok(id)
    }

    fn write_tf(
        &mut self,
        replica: &mut Replica,
        now: u64,
        transform: &ros2::TransformStamped,
        deltas: &mut Vec<Arc<Delta>>,
    ) -> Result<(), Failure> {
        let (parent_name, child_name) = (transform.header.frame_id.as_str(), transform.child_frame_id.as_str());
        let Some(euler) = euler_from_quaternion(transform.rotation) else {
            return Err(Failure::Decode(ros2::DecodeError {
                type_name: "tf2_msgs/msg/TFMessage",
                field: "transform.rotation",
                offset: 0,
                what: format!("{parent_name} -> {child_name}: not a rotation: {:?}", transform.rotation),
            }));
        };
        if parent_name.is_empty() || child_name.is_empty() || parent_name == child_name {
            self.stats.tf_refused += 1;
            return Ok(());
        }
        let parent = self.frame_for(replica, now, parent_name, deltas)?;
        let child = self.frame_for(replica, now, child_name, deltas)?;
        if is_rt_ancestor(replica, child, parent) {
            self.stats.tf_refused += 1;
            return Ok(());
        }
        let old_parents: Vec<EdgeKey> = replica
            .in_edges(child)
            .filter(|edge| edge.edge_type() == dsr::kinematics::RT && edge.from() != parent)
            .map(|edge| edge.key().clone())
            .collect();
        for key in old_parents {
            deltas.push(replica.delete_edge(now, &key)?);
        }
        let translation = f32s(transform.translation, 1000.0);
        deltas.extend(replica.set_rt(now, parent, child, translation, euler)?);
        Ok(())
    }
}

/// Whether `ancestor` is `node` or one of its RT ancestors (bounded walk; a broken tree counts as "no").
fn is_rt_ancestor(replica: &Replica, ancestor: NodeId, node: NodeId) -> bool {
    let mut current = node;
    for _ in 0..=replica.node_count() {
        if current == ancestor {
            return true;
        }
        match replica.rt_parent_edge(current) {
            Ok(Some(edge)) => current = edge.from(),
            _ => return false,
        }
    }
    false
}

/// Euler x-y-z angles (rad) of a quaternion `[x, y, z, w]`, or `None` if it is not a rotation (zero or not finite).
pub fn euler_from_quaternion([x, y, z, w]: [f64; 4]) -> Option<[f32; 3]> {
    let q = Quaternion::new(w, x, y, z);
    let norm = q.norm();
    if !norm.is_finite() || norm < 1e-9 {
        return None;
    }
    let [a, b, c] = dsr::kinematics::euler_xyz(&UnitQuaternion::from_quaternion(q));
    Some([a as f32, b as f32, c as f32])
}

fn f32s<const N: usize>(values: [f64; N], scale: f64) -> [f32; N] {
    values.map(|value| (value * scale) as f32)
}

fn saturating_i32(value: u32) -> i32 {
    i32::try_from(value).unwrap_or(i32::MAX)
}

/// Copies `height` rows of `row` bytes out of rows of `step` bytes (drops row padding); short data gives fewer rows.
fn repack_rows(data: &Bytes, step: usize, row: usize, height: usize) -> Bytes {
    let mut out = Vec::with_capacity(row * height);
    for chunk in data.chunks(step).take(height) {
        out.extend_from_slice(&chunk[..row.min(chunk.len())]);
    }
    Bytes::from(out)
}
