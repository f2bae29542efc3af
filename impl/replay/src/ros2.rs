//! Decoders for the common ROS message types, from the CDR bytes of a ROS 2 message or the serialized bytes of a
//! ROS 1 message.
//!
//! A ROS 2 payload is a 4-byte encapsulation header (`00 01` little-endian CDR, `00 00` big-endian) followed by
//! the message's fields in declaration order, each primitive aligned to its size counted from the end of the
//! header; strings and sequences carry a `u32` length (strings include their NUL). A ROS 1 payload is the same fields
//! little-endian with no header, no alignment and no NUL; its `std_msgs/Header` starts with a `u32 seq` (read and
//! ignored) and its `time` is two `u32`s. The layouts below follow the `.msg` definitions of `std_msgs`,
//! `sensor_msgs`, `geometry_msgs`, `nav_msgs` and `tf2_msgs`, which have the same fields in ROS 1 and ROS 2, matched by
//! the schema name of the channel under both names a type goes by (`sensor_msgs/msg/Image`, or the ROS 1 style
//! `sensor_msgs/Image`).
//!
//! Byte arrays (image pixels, point cloud data) are returned as [`Bytes`] views of the message's buffer, so they
//! are not copied; numeric arrays are converted to native values (one copy). Every length is checked against the
//! bytes left before anything is allocated, and every error names the message type, the field and the byte offset.

use bytes::Bytes;

/// A payload that does not decode as the message type its channel declares.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{type_name}: field `{field}` at byte {offset}: {what}")]
pub struct DecodeError {
    /// The message type.
    pub type_name: &'static str,
    /// The field being read.
    pub field: &'static str,
    /// Byte offset in the payload (including the 4-byte encapsulation header).
    pub offset: usize,
    /// What is wrong.
    pub what: String,
}

/// `std_msgs/Header`: time stamp and coordinate frame.
#[derive(Debug, Clone, PartialEq)]
pub struct Header {
    /// Seconds of the stamp.
    pub sec: i32,
    /// Nanoseconds of the stamp.
    pub nanosec: u32,
    /// Coordinate frame of the data.
    pub frame_id: String,
}

impl Header {
    /// The stamp in ns since the epoch; stamps before the epoch give 0.
    pub fn stamp_ns(&self) -> u64 {
        let ns = i64::from(self.sec) * 1_000_000_000 + i64::from(self.nanosec);
        u64::try_from(ns).unwrap_or(0)
    }
}

/// `sensor_msgs/Image`.
#[derive(Debug, Clone, PartialEq)]
pub struct Image {
    /// Header.
    pub header: Header,
    /// Rows.
    pub height: u32,
    /// Columns.
    pub width: u32,
    /// Pixel encoding (`mono8`, `rgb8`, …).
    pub encoding: String,
    /// Whether multi-byte pixels are big-endian.
    pub is_bigendian: bool,
    /// Bytes per row.
    pub step: u32,
    /// Pixels, a view of the message buffer.
    pub data: Bytes,
}

impl Image {
    /// Channels per pixel for the usual encodings, or bytes per pixel (`step / width`) otherwise.
    pub fn channels(&self) -> u32 {
        match self.encoding.as_str() {
            "mono8" | "mono16" | "8UC1" | "16UC1" | "32FC1" => 1,
            "rgb8" | "bgr8" | "rgb16" | "bgr16" | "8UC3" => 3,
            "rgba8" | "bgra8" | "8UC4" => 4,
            _ => self.step.checked_div(self.width).unwrap_or(0),
        }
    }
}

/// `sensor_msgs/CompressedImage`.
#[derive(Debug, Clone, PartialEq)]
pub struct CompressedImage {
    /// Header.
    pub header: Header,
    /// Format (`jpeg`, `png`, …).
    pub format: String,
    /// Compressed bytes, a view of the message buffer.
    pub data: Bytes,
}

/// `sensor_msgs/CameraInfo` (the fields a graph uses; the rest is read and checked).
#[derive(Debug, Clone, PartialEq)]
pub struct CameraInfo {
    /// Header.
    pub header: Header,
    /// Image rows.
    pub height: u32,
    /// Image columns.
    pub width: u32,
    /// Distortion model name.
    pub distortion_model: String,
    /// Distortion coefficients.
    pub d: Vec<f64>,
    /// Intrinsic matrix, row-major.
    pub k: [f64; 9],
    /// Projection matrix, row-major.
    pub p: [f64; 12],
}

/// One field of a point cloud's points.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PointField {
    /// Field name (`x`, `intensity`, …).
    pub name: String,
    /// Byte offset in a point.
    pub offset: u32,
    /// Data type code (1 int8 … 8 float64).
    pub datatype: u8,
    /// Number of elements.
    pub count: u32,
}

/// `sensor_msgs/PointCloud2`.
#[derive(Debug, Clone, PartialEq)]
pub struct PointCloud2 {
    /// Header.
    pub header: Header,
    /// Rows (1 for unorganized clouds).
    pub height: u32,
    /// Points per row.
    pub width: u32,
    /// Point layout.
    pub fields: Vec<PointField>,
    /// Whether values are big-endian.
    pub is_bigendian: bool,
    /// Bytes per point.
    pub point_step: u32,
    /// Bytes per row.
    pub row_step: u32,
    /// The points, a view of the message buffer.
    pub data: Bytes,
    /// Whether there are no invalid points.
    pub is_dense: bool,
}

/// Columns of a point cloud, converted to `f32`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct PointColumns {
    /// x of every point, in the cloud's unit times the scale asked for.
    pub x: Vec<f32>,
    /// y of every point.
    pub y: Vec<f32>,
    /// z of every point.
    pub z: Vec<f32>,
    /// The `intensity` field, if the cloud has one (not scaled).
    pub intensity: Option<Vec<f32>>,
}

impl PointCloud2 {
    /// Number of points the header announces.
    pub fn len(&self) -> usize {
        self.height as usize * self.width as usize
    }

    /// Whether the cloud has no points.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Reads `x`, `y`, `z` (multiplied by `scale`, e.g. 1000 for m → mm) and `intensity` of every point.
    ///
    /// # Errors
    /// A missing coordinate field, an unsupported data type, or points that do not fit in `data`.
    pub fn columns(&self, scale: f32) -> Result<PointColumns, DecodeError> {
        let fail = |field: &'static str, what: String| DecodeError {
            type_name: "sensor_msgs/msg/PointCloud2",
            field,
            offset: 0,
            what,
        };
        let step = self.point_step as usize;
        let rows = self.height as usize;
        let width = self.width as usize;
        let row_step = self.row_step as usize;
        let row_bytes = width as u64 * step as u64;
        if rows > 1 && (row_step as u64) < row_bytes {
            return Err(fail(
                "row_step",
                format!("row_step {row_step} is shorter than {width} points of {step} bytes"),
            ));
        }
        let needed = if rows == 0 || width == 0 { 0 } else { (rows as u64 - 1) * row_step as u64 + row_bytes };
        if needed > self.data.len() as u64 {
            return Err(fail(
                "data",
                format!("{rows}x{width} points of {step} bytes need {needed} bytes, {} present", self.data.len()),
            ));
        }
        let reader = |name: &'static str| -> Result<Option<(usize, u8)>, DecodeError> {
            let Some(field) = self.fields.iter().find(|field| field.name == name) else { return Ok(None) };
            let size = datatype_size(field.datatype)
                .ok_or_else(|| fail("fields", format!("field `{name}` has unknown datatype {}", field.datatype)))?;
            if field.offset as usize + size > step {
                return Err(fail(
                    "fields",
                    format!("field `{name}` at offset {} does not fit a {step}-byte point", field.offset),
                ));
            }
            Ok(Some((field.offset as usize, field.datatype)))
        };
        let mut coordinates = Vec::with_capacity(3);
        for name in ["x", "y", "z"] {
            coordinates.push(reader(name)?.ok_or_else(|| fail("fields", format!("no `{name}` field")))?);
        }
        let intensity = reader("intensity")?;
        let n = rows * width;
        let mut out = PointColumns {
            x: Vec::with_capacity(n),
            y: Vec::with_capacity(n),
            z: Vec::with_capacity(n),
            intensity: intensity.map(|_| Vec::with_capacity(n)),
        };
        let big = self.is_bigendian;
        for row in 0..rows {
            for column in 0..width {
                let point = &self.data[row * row_step + column * step..row * row_step + (column + 1) * step];
                out.x.push(read_scalar(point, coordinates[0], big) as f32 * scale);
                out.y.push(read_scalar(point, coordinates[1], big) as f32 * scale);
                out.z.push(read_scalar(point, coordinates[2], big) as f32 * scale);
                if let (Some(values), Some(field)) = (out.intensity.as_mut(), intensity) {
                    values.push(read_scalar(point, field, big) as f32);
                }
            }
        }
        Ok(out)
    }
}

fn datatype_size(datatype: u8) -> Option<usize> {
    match datatype {
        1 | 2 => Some(1),
        3 | 4 => Some(2),
        5..=7 => Some(4),
        8 => Some(8),
        _ => None,
    }
}

/// Reads one scalar of a point (offset and type already checked to fit).
fn read_scalar(point: &[u8], (offset, datatype): (usize, u8), big: bool) -> f64 {
    fn bytes<const N: usize>(point: &[u8], offset: usize, big: bool) -> [u8; N] {
        let mut out = [0u8; N];
        out.copy_from_slice(&point[offset..offset + N]);
        if big {
            out.reverse();
        }
        out
    }
    match datatype {
        1 => f64::from(point[offset] as i8),
        2 => f64::from(point[offset]),
        3 => f64::from(i16::from_le_bytes(bytes(point, offset, big))),
        4 => f64::from(u16::from_le_bytes(bytes(point, offset, big))),
        5 => f64::from(i32::from_le_bytes(bytes(point, offset, big))),
        6 => f64::from(u32::from_le_bytes(bytes(point, offset, big))),
        7 => f64::from(f32::from_le_bytes(bytes(point, offset, big))),
        _ => f64::from_le_bytes(bytes(point, offset, big)),
    }
}

/// `sensor_msgs/LaserScan`.
#[derive(Debug, Clone, PartialEq)]
pub struct LaserScan {
    /// Header.
    pub header: Header,
    /// Angle of the first beam, rad.
    pub angle_min: f32,
    /// Angle of the last beam, rad.
    pub angle_max: f32,
    /// Angle between beams, rad.
    pub angle_increment: f32,
    /// Time between beams, s.
    pub time_increment: f32,
    /// Time between scans, s.
    pub scan_time: f32,
    /// Minimum valid range, m.
    pub range_min: f32,
    /// Maximum valid range, m.
    pub range_max: f32,
    /// Ranges, m.
    pub ranges: Vec<f32>,
    /// Intensities (may be empty).
    pub intensities: Vec<f32>,
}

/// `geometry_msgs/Quaternion` as `[x, y, z, w]`.
pub type Quaternion = [f64; 4];

/// `sensor_msgs/Imu` (covariances read and dropped).
#[derive(Debug, Clone, PartialEq)]
pub struct Imu {
    /// Header.
    pub header: Header,
    /// Orientation `[x, y, z, w]`.
    pub orientation: Quaternion,
    /// Angular velocity, rad/s.
    pub angular_velocity: [f64; 3],
    /// Linear acceleration, m/s².
    pub linear_acceleration: [f64; 3],
}

/// `sensor_msgs/NavSatFix` (covariance read and dropped).
#[derive(Debug, Clone, PartialEq)]
pub struct NavSatFix {
    /// Header.
    pub header: Header,
    /// Fix status (-1 no fix … 2 ground-based augmentation).
    pub status: i8,
    /// Latitude, degrees.
    pub latitude: f64,
    /// Longitude, degrees.
    pub longitude: f64,
    /// Altitude, m.
    pub altitude: f64,
}

/// `geometry_msgs/Pose`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pose {
    /// Position, m.
    pub position: [f64; 3],
    /// Orientation `[x, y, z, w]`.
    pub orientation: Quaternion,
}

/// `geometry_msgs/PoseStamped`.
#[derive(Debug, Clone, PartialEq)]
pub struct PoseStamped {
    /// Header.
    pub header: Header,
    /// The pose.
    pub pose: Pose,
}

/// `nav_msgs/Odometry` (covariances read and dropped).
#[derive(Debug, Clone, PartialEq)]
pub struct Odometry {
    /// Header (the pose's frame).
    pub header: Header,
    /// Frame of the twist.
    pub child_frame_id: String,
    /// Pose, m.
    pub pose: Pose,
    /// Linear velocity, m/s.
    pub linear: [f64; 3],
    /// Angular velocity, rad/s.
    pub angular: [f64; 3],
}

/// `geometry_msgs/TransformStamped`.
#[derive(Debug, Clone, PartialEq)]
pub struct TransformStamped {
    /// Header: the parent frame.
    pub header: Header,
    /// The child frame.
    pub child_frame_id: String,
    /// Translation, m.
    pub translation: [f64; 3],
    /// Rotation `[x, y, z, w]`.
    pub rotation: Quaternion,
}

/// A decoded message.
#[derive(Debug, Clone, PartialEq)]
pub enum Ros2Message {
    /// `sensor_msgs/Image`.
    Image(Image),
    /// `sensor_msgs/CompressedImage`.
    CompressedImage(CompressedImage),
    /// `sensor_msgs/CameraInfo`.
    CameraInfo(CameraInfo),
    /// `sensor_msgs/PointCloud2`.
    PointCloud2(PointCloud2),
    /// `sensor_msgs/LaserScan`.
    LaserScan(LaserScan),
    /// `sensor_msgs/Imu`.
    Imu(Imu),
    /// `sensor_msgs/NavSatFix`.
    NavSatFix(NavSatFix),
    /// `geometry_msgs/PoseStamped`.
    PoseStamped(PoseStamped),
    /// `nav_msgs/Odometry`.
    Odometry(Odometry),
    /// `tf2_msgs/TFMessage`.
    Tf(Vec<TransformStamped>),
}

/// The message types [`decode`] knows, by their ROS 2 schema names.
pub const KNOWN_TYPES: &[&str] = &[
    "sensor_msgs/msg/Image",
    "sensor_msgs/msg/CompressedImage",
    "sensor_msgs/msg/CameraInfo",
    "sensor_msgs/msg/PointCloud2",
    "sensor_msgs/msg/LaserScan",
    "sensor_msgs/msg/Imu",
    "sensor_msgs/msg/NavSatFix",
    "geometry_msgs/msg/PoseStamped",
    "nav_msgs/msg/Odometry",
    "tf2_msgs/msg/TFMessage",
];

/// The canonical ROS 2 name of a known type (`sensor_msgs/Image` and `sensor_msgs/msg/Image` are the same).
pub fn known_type(schema_name: &str) -> Option<&'static str> {
    let (package, name) = schema_name.split_once('/')?;
    let name = name.strip_prefix("msg/").unwrap_or(name);
    KNOWN_TYPES.iter().copied().find(|known| {
        known
            .split_once("/msg/")
            .is_some_and(|(known_package, known_name)| known_package == package && known_name == name)
    })
}

/// How a message's bytes are serialized.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Encoding {
    /// ROS 2: CDR behind a 4-byte encapsulation header (MCAP message encoding `cdr`).
    Cdr,
    /// ROS 1 serialization (MCAP message encoding `ros1`, and every ROS 1 bag).
    Ros1,
}

impl Encoding {
    /// The encoding an MCAP channel (or a rosbag2 topic's serialization format) names, if it is one of these.
    pub fn from_message_encoding(name: &str) -> Option<Encoding> {
        match name {
            "cdr" => Some(Encoding::Cdr),
            "ros1" => Some(Encoding::Ros1),
            _ => None,
        }
    }
}

/// Decodes a CDR payload whose channel declares `schema_name`; `Ok(None)` for a type this module does not know.
///
/// # Errors
/// [`DecodeError`] if the payload does not decode as that type.
pub fn decode(schema_name: &str, data: &Bytes) -> Result<Option<Ros2Message>, DecodeError> {
    decode_as(schema_name, Encoding::Cdr, data)
}

/// Decodes a payload of `encoding` whose channel declares `schema_name`; `Ok(None)` for a type this module does not
/// know.
///
/// # Errors
/// [`DecodeError`] if the payload does not decode as that type.
pub fn decode_as(schema_name: &str, encoding: Encoding, data: &Bytes) -> Result<Option<Ros2Message>, DecodeError> {
    let Some(type_name) = known_type(schema_name) else { return Ok(None) };
    let mut cdr = Wire::new(type_name, encoding, data)?;
    let message = match type_name {
        "sensor_msgs/msg/Image" => {
            let header = cdr.header()?;
            Ros2Message::Image(Image {
                header,
                height: cdr.u32("height")?,
                width: cdr.u32("width")?,
                encoding: cdr.string("encoding")?,
                is_bigendian: cdr.u8("is_bigendian")? != 0,
                step: cdr.u32("step")?,
                data: cdr.byte_sequence("data")?,
            })
        }
        "sensor_msgs/msg/CompressedImage" => Ros2Message::CompressedImage(CompressedImage {
            header: cdr.header()?,
            format: cdr.string("format")?,
            data: cdr.byte_sequence("data")?,
        }),
        "sensor_msgs/msg/CameraInfo" => {
            let header = cdr.header()?;
            let height = cdr.u32("height")?;
            let width = cdr.u32("width")?;
            let distortion_model = cdr.string("distortion_model")?;
            let d = cdr.f64_sequence("d")?;
            let k = cdr.f64_array::<9>("k")?;
            cdr.f64_array::<9>("r")?;
            let p = cdr.f64_array::<12>("p")?;
            cdr.u32("binning_x")?;
            cdr.u32("binning_y")?;
            for field in ["roi.x_offset", "roi.y_offset", "roi.height", "roi.width"] {
                cdr.u32(field)?;
            }
            cdr.u8("roi.do_rectify")?;
            Ros2Message::CameraInfo(CameraInfo { header, height, width, distortion_model, d, k, p })
        }
        "sensor_msgs/msg/PointCloud2" => {
            let header = cdr.header()?;
            let height = cdr.u32("height")?;
            let width = cdr.u32("width")?;
            let count = cdr.length("fields", 9)?;
            let mut fields = Vec::with_capacity(count);
            for _ in 0..count {
                fields.push(PointField {
                    name: cdr.string("fields.name")?,
                    offset: cdr.u32("fields.offset")?,
                    datatype: cdr.u8("fields.datatype")?,
                    count: cdr.u32("fields.count")?,
                });
            }
            Ros2Message::PointCloud2(PointCloud2 {
                header,
                height,
                width,
                fields,
                is_bigendian: cdr.u8("is_bigendian")? != 0,
                point_step: cdr.u32("point_step")?,
                row_step: cdr.u32("row_step")?,
                data: cdr.byte_sequence("data")?,
                is_dense: cdr.u8("is_dense")? != 0,
            })
        }
        "sensor_msgs/msg/LaserScan" => Ros2Message::LaserScan(LaserScan {
            header: cdr.header()?,
            angle_min: cdr.f32("angle_min")?,
            angle_max: cdr.f32("angle_max")?,
            angle_increment: cdr.f32("angle_increment")?,
            time_increment: cdr.f32("time_increment")?,
            scan_time: cdr.f32("scan_time")?,
            range_min: cdr.f32("range_min")?,
            range_max: cdr.f32("range_max")?,
            ranges: cdr.f32_sequence("ranges")?,
            intensities: cdr.f32_sequence("intensities")?,
        }),
        "sensor_msgs/msg/Imu" => {
            let header = cdr.header()?;
            let orientation = cdr.f64_array::<4>("orientation")?;
            cdr.f64_array::<9>("orientation_covariance")?;
            let angular_velocity = cdr.f64_array::<3>("angular_velocity")?;
            cdr.f64_array::<9>("angular_velocity_covariance")?;
            let linear_acceleration = cdr.f64_array::<3>("linear_acceleration")?;
            cdr.f64_array::<9>("linear_acceleration_covariance")?;
            Ros2Message::Imu(Imu { header, orientation, angular_velocity, linear_acceleration })
        }
        "sensor_msgs/msg/NavSatFix" => {
            let header = cdr.header()?;
            let status = cdr.u8("status.status")? as i8;
            cdr.u16("status.service")?;
            let latitude = cdr.f64("latitude")?;
            let longitude = cdr.f64("longitude")?;
            let altitude = cdr.f64("altitude")?;
            cdr.f64_array::<9>("position_covariance")?;
            cdr.u8("position_covariance_type")?;
            Ros2Message::NavSatFix(NavSatFix { header, status, latitude, longitude, altitude })
        }
        "geometry_msgs/msg/PoseStamped" => {
            Ros2Message::PoseStamped(PoseStamped { header: cdr.header()?, pose: cdr.pose()? })
        }
        "nav_msgs/msg/Odometry" => {
            let header = cdr.header()?;
            let child_frame_id = cdr.string("child_frame_id")?;
            let pose = cdr.pose()?;
            cdr.f64_array::<36>("pose.covariance")?;
            let linear = cdr.f64_array::<3>("twist.linear")?;
            let angular = cdr.f64_array::<3>("twist.angular")?;
            cdr.f64_array::<36>("twist.covariance")?;
            Ros2Message::Odometry(Odometry { header, child_frame_id, pose, linear, angular })
        }
        _ => {
            // tf2_msgs/msg/TFMessage: a sequence of TransformStamped (at least a header and a child frame each).
            let count = cdr.length("transforms", 24)?;
            let mut transforms = Vec::with_capacity(count);
            for _ in 0..count {
                transforms.push(TransformStamped {
                    header: cdr.header()?,
                    child_frame_id: cdr.string("child_frame_id")?,
                    translation: cdr.f64_array::<3>("transform.translation")?,
                    rotation: cdr.f64_array::<4>("transform.rotation")?,
                });
            }
            Ros2Message::Tf(transforms)
        }
    };
    Ok(Some(message))
}

/// A reader over one payload, CDR or ROS 1: the primitives both share, with CDR's alignment and byte order.
pub(crate) struct Wire<'a> {
    type_name: &'static str,
    data: &'a Bytes,
    pos: usize,
    little: bool,
    encoding: Encoding,
}

/// Size of the encapsulation header; alignment counts from its end.
const ENCAPSULATION: usize = 4;

impl<'a> Wire<'a> {
    pub(crate) fn new(type_name: &'static str, encoding: Encoding, data: &'a Bytes) -> Result<Self, DecodeError> {
        let mut cdr = Wire { type_name, data, pos: 0, little: true, encoding };
        if encoding == Encoding::Ros1 {
            return Ok(cdr);
        }
        if data.len() < ENCAPSULATION {
            return Err(
                cdr.error("encapsulation", format!("payload of {} bytes has no encapsulation header", data.len()))
            );
        }
        cdr.little = match (data[0], data[1]) {
            (0, 0) => false,
            (0, 1) => true,
            (a, b) => {
                return Err(cdr
                    .error("encapsulation", format!("unsupported representation {a:#04x} {b:#04x} (plain CDR only)")));
            }
        };
        cdr.pos = ENCAPSULATION;
        Ok(cdr)
    }

    pub(crate) fn error(&self, field: &'static str, what: String) -> DecodeError {
        DecodeError { type_name: self.type_name, field, offset: self.pos, what }
    }

    /// Byte offset in the payload.
    pub(crate) fn pos(&self) -> usize {
        self.pos
    }

    /// Bytes left after the current position.
    pub(crate) fn left(&self) -> usize {
        self.data.len().saturating_sub(self.pos)
    }

    pub(crate) fn align(&mut self, size: usize) {
        if self.encoding == Encoding::Ros1 {
            return;
        }
        let relative = self.pos - ENCAPSULATION;
        self.pos = ENCAPSULATION + relative.div_ceil(size) * size;
    }

    pub(crate) fn take(&mut self, field: &'static str, n: usize) -> Result<&'a [u8], DecodeError> {
        let left = self.data.len().saturating_sub(self.pos);
        if n > left {
            return Err(self.error(field, format!("needs {n} bytes, {left} left")));
        }
        let data: &'a [u8] = self.data;
        let out = &data[self.pos..self.pos + n];
        self.pos += n;
        Ok(out)
    }

    pub(crate) fn primitive<const N: usize>(&mut self, field: &'static str) -> Result<[u8; N], DecodeError> {
        self.align(N);
        let mut out = [0u8; N];
        out.copy_from_slice(self.take(field, N)?);
        if !self.little {
            out.reverse();
        }
        Ok(out)
    }

    pub(crate) fn u8(&mut self, field: &'static str) -> Result<u8, DecodeError> {
        Ok(self.primitive::<1>(field)?[0])
    }

    pub(crate) fn u16(&mut self, field: &'static str) -> Result<u16, DecodeError> {
        Ok(u16::from_le_bytes(self.primitive(field)?))
    }

    pub(crate) fn u32(&mut self, field: &'static str) -> Result<u32, DecodeError> {
        Ok(u32::from_le_bytes(self.primitive(field)?))
    }

    pub(crate) fn i32(&mut self, field: &'static str) -> Result<i32, DecodeError> {
        Ok(i32::from_le_bytes(self.primitive(field)?))
    }

    pub(crate) fn f32(&mut self, field: &'static str) -> Result<f32, DecodeError> {
        Ok(f32::from_le_bytes(self.primitive(field)?))
    }

    pub(crate) fn f64(&mut self, field: &'static str) -> Result<f64, DecodeError> {
        Ok(f64::from_le_bytes(self.primitive(field)?))
    }

    /// A sequence length whose elements take at least `min_element` bytes each: checked against the bytes left.
    pub(crate) fn length(&mut self, field: &'static str, min_element: usize) -> Result<usize, DecodeError> {
        let len = self.u32(field)? as usize;
        let left = self.data.len().saturating_sub(self.pos);
        if len.saturating_mul(min_element) > left {
            return Err(self.error(field, format!("sequence of {len} elements cannot fit in the {left} bytes left")));
        }
        Ok(len)
    }

    pub(crate) fn string(&mut self, field: &'static str) -> Result<String, DecodeError> {
        let len = self.length(field, 1)?;
        let raw = self.take(field, len)?;
        let raw = match self.encoding {
            Encoding::Cdr => raw.strip_suffix(&[0]).unwrap_or(raw),
            Encoding::Ros1 => raw,
        };
        String::from_utf8(raw.to_vec()).map_err(|_| self.error(field, "string is not valid UTF-8".to_owned()))
    }

    pub(crate) fn byte_sequence(&mut self, field: &'static str) -> Result<Bytes, DecodeError> {
        let len = self.length(field, 1)?;
        let start = self.pos;
        self.take(field, len)?;
        Ok(self.data.slice(start..start + len))
    }

    pub(crate) fn f32_sequence(&mut self, field: &'static str) -> Result<Vec<f32>, DecodeError> {
        let len = self.length(field, 4)?;
        (0..len).map(|_| self.f32(field)).collect()
    }

    pub(crate) fn f64_sequence(&mut self, field: &'static str) -> Result<Vec<f64>, DecodeError> {
        let len = self.length(field, 8)?;
        (0..len).map(|_| self.f64(field)).collect()
    }

    pub(crate) fn f64_array<const N: usize>(&mut self, field: &'static str) -> Result<[f64; N], DecodeError> {
        let mut out = [0.0; N];
        for value in &mut out {
            *value = self.f64(field)?;
        }
        Ok(out)
    }

    fn header(&mut self) -> Result<Header, DecodeError> {
        if self.encoding == Encoding::Ros1 {
            self.u32("header.seq")?;
            let sec = self.u32("header.stamp.secs")?;
            return Ok(Header {
                sec: i32::try_from(sec).unwrap_or(i32::MAX),
                nanosec: self.u32("header.stamp.nsecs")?,
                frame_id: self.string("header.frame_id")?,
            });
        }
        Ok(Header {
            sec: self.i32("header.stamp.sec")?,
            nanosec: self.u32("header.stamp.nanosec")?,
            frame_id: self.string("header.frame_id")?,
        })
    }

    fn pose(&mut self) -> Result<Pose, DecodeError> {
        Ok(Pose {
            position: self.f64_array::<3>("pose.position")?,
            orientation: self.f64_array::<4>("pose.orientation")?,
        })
    }
}
