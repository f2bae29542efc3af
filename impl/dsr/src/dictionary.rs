//! The type dictionary: node types, edge types and attribute names with their value types.
//!
//! One table (the `builtin_attributes!` table below) is the single source of truth. It generates the typed keys in
//! [`attrs`] — so `replica.set_attr(now, node, attrs::RT_TRANSLATION, "text")` does not compile — and the run-time
//! table that checks the names of local operations. A [`Dictionary`] starts from the built-in table and *learns*
//! the names of the graph it holds: every node type, edge type and attribute name (with its value type) that
//! arrives in a remote delta or a lenient JSON import ([`crate::json`]) joins it. A local operation may use a
//! name only if the built-in table or the graph knows it (unless the user allows unknown names, in which case an
//! unknown attribute name is registered with the type it is first written with).
//!
//! An attribute name has one *declared* type (the built-in one, or the type it was first learned with) and may
//! have been learned with other types too: real CORTEX files of different eras store, say, `parent` as u32 or
//! u64. A value of a learned type is accepted under that name like one of the declared type; any other type is a
//! [`DictionaryError::AttrTypeConflict`].
//!
//! Remote deltas are never refused for their names or types (only for malformed names): what a replica accepts
//! from the network does not depend on what it happened to learn first, which keeps the join order-independent.

use std::collections::{HashMap, HashSet};
use std::marker::PhantomData;
use std::sync::Arc;

use bytes::Bytes;

use crate::error::DictionaryError;
pub use crate::ids::MAX_NAME_LEN;
use crate::ids::Name;
use crate::value::{AttrType, Numbers, ValueType};

/// A typed attribute key: the name plus, in the type parameter, the Rust type of its values.
///
/// # Examples
/// ```
/// use dsr::attrs;
/// assert_eq!(attrs::LEVEL.name(), "level");
/// assert_eq!(attrs::LEVEL.value_type(), dsr::ValueType::I32);
/// ```
///
/// A value of the wrong type does not compile:
/// ```compile_fail
/// use dsr::{NewNode, Replica, ReplicaId, attrs};
/// let mut replica = Replica::new(ReplicaId(1));
/// let (id, _) = replica.insert_node(0, NewNode::new("world", "world")).unwrap();
/// replica.set_attr(1, id, attrs::RT_TRANSLATION, "not a vector").unwrap();
/// ```
/// while the right one does:
/// ```
/// use dsr::{NewNode, Numbers, Replica, ReplicaId, attrs};
/// let mut replica = Replica::new(ReplicaId(1));
/// let (id, _) = replica.insert_node(0, NewNode::new("world", "world")).unwrap();
/// let translation: Numbers<f32> = Numbers::from([0.0f32, 0.0, 100.0]);
/// replica.set_attr(1, id, attrs::RT_TRANSLATION, translation).unwrap();
/// ```
pub struct AttrKey<T> {
    name: &'static str,
    _type: PhantomData<fn() -> T>,
}

impl<T> Clone for AttrKey<T> {
    fn clone(&self) -> Self {
        *self
    }
}

impl<T> Copy for AttrKey<T> {}

impl<T> std::fmt::Debug for AttrKey<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "AttrKey({})", self.name)
    }
}

impl<T: AttrType> AttrKey<T> {
    /// A typed key for `name`. Keys of names outside the built-in table must be declared in the replica's
    /// dictionary ([`Dictionary::declare_attr`]) before use.
    pub const fn new(name: &'static str) -> Self {
        AttrKey { name, _type: PhantomData }
    }

    /// The attribute name.
    pub const fn name(&self) -> &'static str {
        self.name
    }

    /// The value type.
    pub const fn value_type(&self) -> ValueType {
        T::TYPE
    }
}

macro_rules! builtin_attributes {
    ($( $konst:ident : $rust:ty = $name:literal, $doc:literal; )*) => {
        /// Typed keys for every built-in attribute name.
        pub mod attrs {
            #[allow(unused_imports)]
            use super::*;
            $(
                #[doc = $doc]
                pub const $konst: AttrKey<$rust> = AttrKey::new($name);
            )*
        }

        /// The built-in attribute table: name and value type. Its index is the name's wire code.
        pub(crate) const BUILTIN_ATTRIBUTES: &[(&str, ValueType)] = &[
            $( ($name, <$rust as AttrType>::TYPE), )*
        ];
    };
}

builtin_attributes! {
    // Geometry (RT edges and the kinematic tree).
    RT_TRANSLATION: Numbers<f32> = "rt_translation", "Translation of an RT edge, parent to child, in mm (3 values).";
    RT_ROTATION_EULER_XYZ: Numbers<f32> = "rt_rotation_euler_xyz", "Rotation of an RT edge as Euler angles x, y, z in rad, applied as Rx·Ry·Rz (3 values).";
    TRANSLATION: Numbers<f32> = "translation", "Legacy name of `rt_translation` (older CORTEX graphs).";
    ROTATION_EULER_XYZ: Numbers<f32> = "rotation_euler_xyz", "Legacy name of `rt_rotation_euler_xyz` (older CORTEX graphs).";
    PARENT: u64 = "parent", "Id of the node's parent in the RT tree (0: none).";
    LEVEL: i32 = "level", "Depth of the node in the RT tree (the root is 0).";
    POS_X: f32 = "pos_x", "X position of the node in graph drawings.";
    POS_Y: f32 = "pos_y", "Y position of the node in graph drawings.";
    COLOR: Arc<str> = "color", "Colour of the node in graph drawings.";
    // World description.
    OUTER_REGION_BOTTOM: i32 = "OuterRegionBottom", "Bottom of the world's outer region, mm.";
    OUTER_REGION_LEFT: i32 = "OuterRegionLeft", "Left of the world's outer region, mm.";
    OUTER_REGION_RIGHT: i32 = "OuterRegionRight", "Right of the world's outer region, mm.";
    OUTER_REGION_TOP: i32 = "OuterRegionTop", "Top of the world's outer region, mm.";
    WIDTH: i32 = "width", "Width of a body, mm.";
    HEIGHT: i32 = "height", "Height of a body, mm.";
    DEPTH: i32 = "depth", "Depth of a body, mm.";
    MASS: i32 = "mass", "Mass of a body.";
    SCALEX: i32 = "scalex", "Mesh scale along x.";
    SCALEY: i32 = "scaley", "Mesh scale along y.";
    SCALEZ: i32 = "scalez", "Mesh scale along z.";
    PATH: Arc<str> = "path", "Path of a mesh file.";
    TEXTURE: Arc<str> = "texture", "Texture of a plane.";
    REPEAT: i32 = "repeat", "Texture repetitions of a plane.";
    RENDER: Arc<str> = "render", "Render mode of a mesh.";
    ENGINE: Arc<str> = "engine", "Physics engine of a body.";
    COLLIDABLE: bool = "collidable", "Whether the body collides.";
    COLLIDE: bool = "collide", "Whether the body takes part in collision checks.";
    // Robot base.
    BASE_TARGET_X: f32 = "base_target_x", "Target x of the robot base.";
    BASE_TARGET_Y: f32 = "base_target_y", "Target y of the robot base.";
    REF_ADV_SPEED: f32 = "ref_adv_speed", "Reference advance speed.";
    REF_ROT_SPEED: f32 = "ref_rot_speed", "Reference rotation speed.";
    REF_SIDE_SPEED: f32 = "ref_side_speed", "Reference side speed.";
    ROBOT_REF_ADV_SPEED: f32 = "robot_ref_adv_speed", "Reference advance speed of the robot.";
    ROBOT_REF_ROT_SPEED: f32 = "robot_ref_rot_speed", "Reference rotation speed of the robot.";
    ROBOT_REF_SIDE_SPEED: f32 = "robot_ref_side_speed", "Reference side speed of the robot.";
    ROBOT_LOCAL_LINEAR_VELOCITY: Numbers<f32> = "robot_local_linear_velocity", "Linear velocity of the robot in its own frame.";
    ROBOT_CURRENT_LINEAR_SPEED: Numbers<f32> = "robot_current_linear_speed", "Current linear speed of the robot (on its RT edge).";
    ROBOT_CURRENT_ANGULAR_SPEED: Numbers<f32> = "robot_current_angular_speed", "Current angular speed of the robot (on its RT edge).";
    LINEAR_SPEED: Numbers<f32> = "linear_speed", "Legacy name of `robot_current_linear_speed`.";
    ANGULAR_SPEED: Numbers<f32> = "angular_speed", "Legacy name of `robot_current_angular_speed`.";
    BATTERY_LOAD: i32 = "battery_load", "Battery load, percent.";
    PLAN_TARGET_NODE_ID: i32 = "plan_target_node_id", "Node the current plan targets.";
    VIRIATO_HEAD_PAN_TILT_NOSE_TARGET: Numbers<f32> = "viriato_head_pan_tilt_nose_target", "Gaze target of Viriato's pan-tilt head.";
    VIRIATO_PAN_TILT_NOSE_TARGET: Numbers<f32> = "viriato_pan_tilt_nose_target", "Legacy gaze target of Viriato's pan-tilt head.";
    VIRIATO_LEFT_ARM_TARGET: Numbers<f32> = "viriato_left_arm_target", "Target of Viriato's left arm.";
    // Devices and agents.
    PORT: i32 = "port", "Network port of a device's driver.";
    IFCONFIG: Arc<str> = "ifconfig", "Network interface of a device's driver.";
    NOISE: i32 = "noise", "Noise of a simulated sensor.";
    FOCAL: i32 = "focal", "Focal length of a camera, px.";
    ANGLE: f32 = "angle", "Field of view of a sensor, rad.";
    MIN: i32 = "min", "Minimum range of a sensor.";
    MAX: i32 = "max", "Maximum range of a sensor.";
    MEASURES: i32 = "measures", "Number of measures of a laser.";
    ALIVETIME: i32 = "alivetime", "Time the device has been alive.";
    NAME: Arc<str> = "name", "A free-form name attribute (distinct from the node's name).";
    AGENT_ID: u32 = "agent_id", "Id of an agent.";
    AGENT_NAME: Arc<str> = "agent_name", "Name of an agent.";
    AGENT_DESCRIPTION: Arc<str> = "agent_description", "Description of an agent.";
    CPU_USAGE: f32 = "cpu_usage", "CPU usage of an agent, percent.";
    MEMORY_USAGE: u32 = "memory_usage", "Memory usage of an agent.";
    NUM_PROCS: u32 = "num_procs", "Number of processes of an agent.";
    TIMESTAMP_AGENT: u64 = "timestamp_agent", "Time stamp written by an agent.";
    TIMESTAMP_ALIVETIME: u64 = "timestamp_alivetime", "Time stamp of an agent's last sign of life.";
    TIMESTAMP_CREATION: u64 = "timestamp_creation", "Creation time stamp.";
    // Cameras.
    CAM_RGB: Bytes = "cam_rgb", "Colour (or mono) camera image, row-major pixels.";
    CAM_RGB_WIDTH: i32 = "cam_rgb_width", "Width of `cam_rgb`, px.";
    CAM_RGB_HEIGHT: i32 = "cam_rgb_height", "Height of `cam_rgb`, px.";
    CAM_RGB_DEPTH: i32 = "cam_rgb_depth", "Channels per pixel of `cam_rgb` (1 mono, 3 colour).";
    CAM_RGB_ENCODING: Arc<str> = "cam_rgb_encoding", "Pixel encoding of `cam_rgb` (`mono8`, `rgb8`, `bgr8`).";
    CAM_RGB_CAMERAID: i32 = "cam_rgb_cameraID", "Camera id of `cam_rgb`.";
    CAM_RGB_FOCALX: i32 = "cam_rgb_focalx", "Focal length along x of the colour camera, px.";
    CAM_RGB_FOCALY: i32 = "cam_rgb_focaly", "Focal length along y of the colour camera, px.";
    CAM_RGB_ALIVETIME: i32 = "cam_rgb_alivetime", "Time the colour camera has been alive.";
    CAM_DEPTH: Bytes = "cam_depth", "Depth image, row-major.";
    CAM_DEPTH_WIDTH: i32 = "cam_depth_width", "Width of `cam_depth`, px.";
    CAM_DEPTH_HEIGHT: i32 = "cam_depth_height", "Height of `cam_depth`, px.";
    CAM_DEPTH_FACTOR: f32 = "cam_depthFactor", "Scale from depth pixel to mm.";
    CAM_DEPTH_CAMERAID: i32 = "cam_depth_cameraID", "Camera id of `cam_depth`.";
    CAM_DEPTH_FOCALX: i32 = "cam_depth_focalx", "Focal length along x of the depth camera, px.";
    CAM_DEPTH_FOCALY: i32 = "cam_depth_focaly", "Focal length along y of the depth camera, px.";
    CAM_DEPTH_ALIVETIME: i32 = "cam_depth_alivetime", "Time the depth camera has been alive.";
    // Lasers and point clouds.
    LASER_DISTS: Numbers<f32> = "laser_dists", "Laser ranges, mm, one per beam.";
    LASER_ANGLES: Numbers<f32> = "laser_angles", "Laser beam angles, rad, one per beam.";
    LASER_INTENSITIES: Numbers<f32> = "laser_intensities", "Laser intensities, one per beam.";
    LIDAR_POINTS_X: Numbers<f32> = "lidar_points_x", "Point cloud x coordinates in the sensor frame, mm.";
    LIDAR_POINTS_Y: Numbers<f32> = "lidar_points_y", "Point cloud y coordinates in the sensor frame, mm.";
    LIDAR_POINTS_Z: Numbers<f32> = "lidar_points_z", "Point cloud z coordinates in the sensor frame, mm.";
    LIDAR_INTENSITY: Numbers<f32> = "lidar_intensity", "Point cloud intensities.";
    // Inertial, odometry, pose and satellite positioning.
    IMU_ANGULAR_VELOCITY: [f32; 3] = "imu_angular_velocity", "IMU angular velocity, rad/s.";
    IMU_LINEAR_ACCELERATION: [f32; 3] = "imu_linear_acceleration", "IMU linear acceleration, m/s².";
    IMU_ORIENTATION: [f32; 4] = "imu_orientation", "IMU orientation quaternion (x, y, z, w).";
    ODOM_LINEAR_VELOCITY: [f32; 3] = "odom_linear_velocity", "Odometry linear velocity, mm/s.";
    ODOM_ANGULAR_VELOCITY: [f32; 3] = "odom_angular_velocity", "Odometry angular velocity, rad/s.";
    POSE_TRANSLATION: [f32; 3] = "pose_translation", "Pose translation in its frame, mm.";
    POSE_ROTATION: [f32; 4] = "pose_rotation", "Pose rotation quaternion (x, y, z, w).";
    GPS_LATITUDE: f64 = "gps_latitude", "Latitude, degrees.";
    GPS_LONGITUDE: f64 = "gps_longitude", "Longitude, degrees.";
    GPS_ALTITUDE: f64 = "gps_altitude", "Altitude, m.";
    STAMP_NS: u64 = "stamp_ns", "Time of the measurement a sensor attribute holds, ns.";
    SEQUENCE: u64 = "sequence", "Sequence number of the measurement a sensor attribute holds.";
    // Detections and tracks (perception). New names go at the end: a name's index is its wire code.
    TRACK_COVARIANCE_MM2: [f32; 4] = "track_covariance_mm2", "Position covariance of a tracked detection in its sensor's frame, mm² (row-major 2x2).";
    TRACK_VELOCITY_MM_S: [f32; 2] = "track_velocity_mm_s", "Estimated velocity of a tracked detection in its sensor's frame, mm/s (x, y).";
    TRACK_ID: u64 = "track_id", "Id of the track behind a detection node (unique per detector).";
    BLOB_CLASS: u32 = "blob_class", "Colour class (index into the labelling configuration) of a blob detection.";
    BLOB_AREA_PX: u32 = "blob_area_px", "Area of a blob detection, px.";
}

/// Built-in node types: those of the CORTEX graphs, plus the sensors and percepts the harness uses.
pub const BUILTIN_NODE_TYPES: &[&str] = &[
    "world",
    "root",
    "transform",
    "plane",
    "mesh",
    "glass",
    "omnirobot",
    "differentialrobot",
    "laser",
    "rgbd",
    "ultrasound",
    "pan_tilt",
    "left_hand",
    "agent",
    "camera",
    "lidar",
    "imu",
    "gps",
    "odometry",
    "pose",
    "object",
    "person",
    "blob",
    "obstacle",
    "head",
    "gaze_target",
];

/// Built-in edge types.
pub const BUILTIN_EDGE_TYPES: &[&str] = &["RT", "has", "in", "sees", "looking_at", "detects"];

/// The table of names a replica accepts, with attribute value types.
#[derive(Clone, Debug)]
pub struct Dictionary {
    attrs: HashMap<Name, ValueType>,
    /// Types other than the declared one that a name was learned with, by name (rare, so a short list each).
    learned_types: HashMap<Name, Vec<ValueType>>,
    node_types: HashSet<Name>,
    edge_types: HashSet<Name>,
    allow_unknown: bool,
}

impl Default for Dictionary {
    fn default() -> Self {
        Dictionary::builtin()
    }
}

impl Dictionary {
    /// The built-in table; unknown names are rejected.
    pub fn builtin() -> Self {
        Dictionary {
            attrs: BUILTIN_ATTRIBUTES.iter().map(|(name, ty)| (Name::new(name), *ty)).collect(),
            learned_types: HashMap::new(),
            node_types: BUILTIN_NODE_TYPES.iter().map(|name| Name::new(name)).collect(),
            edge_types: BUILTIN_EDGE_TYPES.iter().map(|name| Name::new(name)).collect(),
            allow_unknown: false,
        }
    }

    /// The built-in table, accepting unknown names: an unknown attribute takes the type it is first seen with.
    pub fn permissive() -> Self {
        Dictionary { allow_unknown: true, ..Dictionary::builtin() }
    }

    /// Whether unknown names are accepted.
    pub fn allows_unknown(&self) -> bool {
        self.allow_unknown
    }

    /// Declares an attribute name with its type.
    ///
    /// # Errors
    /// [`DictionaryError::AttrTypeConflict`] if the name is already known with another type.
    pub fn declare_attr(&mut self, name: &str, value_type: ValueType) -> Result<(), DictionaryError> {
        match self.attrs.get(name) {
            Some(known) if *known != value_type => {
                Err(DictionaryError::AttrTypeConflict { name: name.to_owned(), known: *known, found: value_type })
            }
            Some(_) => Ok(()),
            None => {
                validate_name("attribute name", name)?;
                self.attrs.insert(Name::new(name), value_type);
                Ok(())
            }
        }
    }

    /// Declares a node type.
    ///
    /// # Errors
    /// [`DictionaryError::InvalidName`] for an empty or over-long name.
    pub fn declare_node_type(&mut self, name: &str) -> Result<(), DictionaryError> {
        validate_name("node type", name)?;
        self.node_types.insert(Name::new(name));
        Ok(())
    }

    /// Declares an edge type.
    ///
    /// # Errors
    /// [`DictionaryError::InvalidName`] for an empty or over-long name.
    pub fn declare_edge_type(&mut self, name: &str) -> Result<(), DictionaryError> {
        validate_name("edge type", name)?;
        self.edge_types.insert(Name::new(name));
        Ok(())
    }

    /// The declared value type of an attribute name, if known.
    pub fn attr_type(&self, name: &str) -> Option<ValueType> {
        self.attrs.get(name).copied()
    }

    /// The types other than the declared one that `name` was learned with (empty for most names).
    pub fn learned_types(&self, name: &str) -> &[ValueType] {
        self.learned_types.get(name).map_or(&[], Vec::as_slice)
    }

    /// Whether a known name accepts values of `value_type`: its declared type or one it was learned with.
    fn accepts(&self, known: ValueType, name: &str, value_type: ValueType) -> bool {
        known == value_type || self.learned_types(name).contains(&value_type)
    }

    /// Whether `name` is known and accepts values of `value_type` (nothing to learn).
    pub fn knows_attr(&self, name: &str, value_type: ValueType) -> bool {
        self.attr_type(name).is_some_and(|known| self.accepts(known, name, value_type))
    }

    /// Learns an attribute name with a value type from the graph (a remote delta or a file): an unknown name is
    /// declared with that type, a known name of another type accepts that type from now on. Returns the shared
    /// name.
    ///
    /// # Errors
    /// [`DictionaryError::InvalidName`] for an empty, over-long or control-character name.
    pub fn learn_attr(&mut self, name: &str, value_type: ValueType) -> Result<Name, DictionaryError> {
        let Some((known_name, known)) = self.attrs.get_key_value(name) else {
            validate_name("attribute name", name)?;
            let interned = Name::new(name);
            self.attrs.insert(interned.clone(), value_type);
            return Ok(interned);
        };
        let known_name = known_name.clone();
        if !self.accepts(*known, name, value_type) {
            self.learned_types.entry(known_name.clone()).or_default().push(value_type);
        }
        Ok(known_name)
    }

    /// Learns a node type from the graph; returns the shared name.
    ///
    /// # Errors
    /// [`DictionaryError::InvalidName`].
    pub fn learn_node_type(&mut self, name: &str) -> Result<Name, DictionaryError> {
        check_type(&mut self.node_types, true, name, "node type")
    }

    /// Learns an edge type from the graph; returns the shared name.
    ///
    /// # Errors
    /// [`DictionaryError::InvalidName`].
    pub fn learn_edge_type(&mut self, name: &str) -> Result<Name, DictionaryError> {
        check_type(&mut self.edge_types, true, name, "edge type")
    }

    /// Checks an attribute name and value type, registering an unknown name when allowed; returns the shared name.
    ///
    /// # Errors
    /// [`DictionaryError::UnknownAttr`] or [`DictionaryError::AttrTypeConflict`].
    pub fn check_attr(&mut self, name: &str, value_type: ValueType) -> Result<Name, DictionaryError> {
        if let Some((known_name, known)) = self.attrs.get_key_value(name) {
            return if self.accepts(*known, name, value_type) {
                Ok(known_name.clone())
            } else {
                Err(DictionaryError::AttrTypeConflict { name: name.to_owned(), known: *known, found: value_type })
            };
        }
        if !self.allow_unknown {
            return Err(DictionaryError::UnknownAttr { name: name.to_owned(), found: value_type });
        }
        validate_name("attribute name", name)?;
        let interned = Name::new(name);
        self.attrs.insert(interned.clone(), value_type);
        Ok(interned)
    }

    /// Checks an attribute name and type without registering anything.
    ///
    /// # Errors
    /// As [`Dictionary::check_attr`].
    pub fn peek_attr(&self, name: &str, value_type: ValueType) -> Result<(), DictionaryError> {
        match self.attrs.get(name) {
            Some(known) if self.accepts(*known, name, value_type) => Ok(()),
            Some(known) => {
                Err(DictionaryError::AttrTypeConflict { name: name.to_owned(), known: *known, found: value_type })
            }
            None if self.allow_unknown => validate_name("attribute name", name),
            None => Err(DictionaryError::UnknownAttr { name: name.to_owned(), found: value_type }),
        }
    }

    /// Checks a node type, registering it when unknown names are allowed; returns the shared name.
    ///
    /// # Errors
    /// [`DictionaryError::UnknownType`].
    pub fn check_node_type(&mut self, name: &str) -> Result<Name, DictionaryError> {
        check_type(&mut self.node_types, self.allow_unknown, name, "node type")
    }

    /// Checks an edge type, registering it when unknown names are allowed; returns the shared name.
    ///
    /// # Errors
    /// [`DictionaryError::UnknownType`].
    pub fn check_edge_type(&mut self, name: &str) -> Result<Name, DictionaryError> {
        check_type(&mut self.edge_types, self.allow_unknown, name, "edge type")
    }

    /// The shared name of a known attribute of type `value_type`: `Ok(None)` if the name is unknown.
    ///
    /// # Errors
    /// [`DictionaryError::AttrTypeConflict`] if it is known with another type.
    pub fn known_attr(&self, name: &str, value_type: ValueType) -> Result<Option<Name>, DictionaryError> {
        match self.attrs.get_key_value(name) {
            Some((known_name, known)) if self.accepts(*known, name, value_type) => Ok(Some(known_name.clone())),
            Some((_, known)) => {
                Err(DictionaryError::AttrTypeConflict { name: name.to_owned(), known: *known, found: value_type })
            }
            None => Ok(None),
        }
    }

    /// The shared name of a known node type.
    pub fn known_node_type(&self, name: &str) -> Option<Name> {
        self.node_types.get(name).cloned()
    }

    /// The shared name of a known edge type.
    pub fn known_edge_type(&self, name: &str) -> Option<Name> {
        self.edge_types.get(name).cloned()
    }

    /// Checks a node type without registering it.
    ///
    /// # Errors
    /// As [`Dictionary::check_node_type`].
    pub fn peek_node_type(&self, name: &str) -> Result<(), DictionaryError> {
        peek_type(&self.node_types, self.allow_unknown, name, "node type")
    }

    /// Checks an edge type without registering it.
    ///
    /// # Errors
    /// As [`Dictionary::check_edge_type`].
    pub fn peek_edge_type(&self, name: &str) -> Result<(), DictionaryError> {
        peek_type(&self.edge_types, self.allow_unknown, name, "edge type")
    }

    /// The wire code of a built-in attribute name (a hash lookup: every write's encoding asks, and a walk through
    /// the table read a cache line per name before `cam_rgb`'s).
    pub(crate) fn builtin_attr_code(name: &str) -> Option<u16> {
        INTERNED.codes.get(name).copied()
    }
}

/// Shared copies of the built-in names, so decoding a delta does not allocate a string per built-in name it meets,
/// and the wire codes of the built-in attribute names.
struct Interned {
    attrs: Vec<Name>,
    codes: HashMap<&'static str, u16>,
    types: HashMap<&'static str, Name>,
}

static INTERNED: std::sync::LazyLock<Interned> = std::sync::LazyLock::new(|| Interned {
    attrs: BUILTIN_ATTRIBUTES.iter().map(|(name, _)| Name::new(name)).collect(),
    // Each name is listed once (a test below holds the table to it).
    codes: BUILTIN_ATTRIBUTES.iter().enumerate().map(|(code, (name, _))| (*name, code as u16)).collect(),
    types: BUILTIN_NODE_TYPES.iter().chain(BUILTIN_EDGE_TYPES).map(|name| (*name, Name::new(name))).collect(),
});

/// The shared name of a built-in attribute's wire code.
pub(crate) fn interned_attr(code: u16) -> Option<Name> {
    INTERNED.attrs.get(usize::from(code)).cloned()
}

/// The shared name of a built-in node or edge type, or a new name for any other text.
pub(crate) fn intern_type(text: &str) -> Name {
    INTERNED.types.get(text).cloned().unwrap_or_else(|| Name::new(text))
}

/// Checks that a name can be held: 1 to [`MAX_NAME_LEN`] bytes, no control characters.
pub(crate) fn validate_name(what: &'static str, name: &str) -> Result<(), DictionaryError> {
    if name.is_empty() || name.len() > MAX_NAME_LEN || name.chars().any(char::is_control) {
        return Err(DictionaryError::InvalidName { what, name: name.chars().take(64).collect() });
    }
    Ok(())
}

fn check_type(
    known: &mut HashSet<Name>,
    allow_unknown: bool,
    name: &str,
    what: &'static str,
) -> Result<Name, DictionaryError> {
    if let Some(found) = known.get(name) {
        return Ok(found.clone());
    }
    peek_type(known, allow_unknown, name, what)?;
    let interned = Name::new(name);
    known.insert(interned.clone());
    Ok(interned)
}

fn peek_type(
    known: &HashSet<Name>,
    allow_unknown: bool,
    name: &str,
    what: &'static str,
) -> Result<(), DictionaryError> {
    if known.contains(name) {
        return Ok(());
    }
    if !allow_unknown {
        return Err(DictionaryError::UnknownType { what, name: name.chars().take(64).collect() });
    }
    validate_name(what, name)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_built_in_attribute_name_is_listed_once_and_its_wire_code_names_it() {
        let names: HashSet<&str> = BUILTIN_ATTRIBUTES.iter().map(|(name, _)| *name).collect();
        assert_eq!(names.len(), BUILTIN_ATTRIBUTES.len(), "a built-in attribute name is listed twice");
        for (code, (name, _)) in BUILTIN_ATTRIBUTES.iter().enumerate() {
            assert_eq!(Dictionary::builtin_attr_code(name), Some(code as u16), "{name}");
            assert_eq!(interned_attr(code as u16).as_deref(), Some(*name));
        }
        assert_eq!(Dictionary::builtin_attr_code("not_a_built_in_name"), None);
    }
}
