//! CDR encoders for the messages the bridge publishes — `tf2_msgs/msg/TFMessage`, `sensor_msgs/msg/Image` and
//! `sensor_msgs/msg/LaserScan` — the inverse of `replay::ros2`'s decoders for the same types.
//!
//! A payload is the 4-byte encapsulation header `00 01 00 00` (little-endian plain CDR) followed by the fields in
//! declaration order, each primitive aligned to its size counted from the end of the header; strings carry a `u32`
//! length that includes their terminating NUL, sequences a `u32` element count. The round trip through
//! `replay::ros2::decode` is tested below, so the encoder and the decoder cannot drift apart.

use bytes::Bytes;
use replay::ros2::{Header, Image, LaserScan, TransformStamped};

/// The encapsulation header of little-endian plain CDR.
pub const CDR_LE_HEADER: [u8; 4] = [0x00, 0x01, 0x00, 0x00];

/// A little-endian CDR writer; alignment counts from the end of the encapsulation header.
#[derive(Debug)]
pub struct CdrWriter {
    out: Vec<u8>,
}

impl Default for CdrWriter {
    fn default() -> Self {
        CdrWriter::with_capacity(64)
    }
}

impl CdrWriter {
    /// A writer holding only the encapsulation header, with room for `capacity_bytes` more.
    pub fn with_capacity(capacity_bytes: usize) -> Self {
        let mut out = Vec::with_capacity(capacity_bytes + CDR_LE_HEADER.len());
        out.extend_from_slice(&CDR_LE_HEADER);
        CdrWriter { out }
    }

    fn align(&mut self, size: usize) {
        let relative = self.out.len() - CDR_LE_HEADER.len();
        let padded = relative.next_multiple_of(size);
        self.out.resize(CDR_LE_HEADER.len() + padded, 0);
    }

    /// One byte.
    pub fn u8(&mut self, value: u8) {
        self.out.push(value);
    }

    /// A `u32`, aligned to 4.
    pub fn u32(&mut self, value: u32) {
        self.align(4);
        self.out.extend_from_slice(&value.to_le_bytes());
    }

    /// An `i32`, aligned to 4.
    pub fn i32(&mut self, value: i32) {
        self.align(4);
        self.out.extend_from_slice(&value.to_le_bytes());
    }

    /// An `f32`, aligned to 4.
    pub fn f32(&mut self, value: f32) {
        self.align(4);
        self.out.extend_from_slice(&value.to_le_bytes());
    }

    /// An `f64`, aligned to 8.
    pub fn f64(&mut self, value: f64) {
        self.align(8);
        self.out.extend_from_slice(&value.to_le_bytes());
    }

    /// A sequence length. Lengths over `u32::MAX` cannot be sent; callers bound their data well below.
    fn length(&mut self, len: usize) {
        self.u32(u32::try_from(len).unwrap_or(u32::MAX));
    }

    /// A string: length including the NUL, the bytes, the NUL.
    pub fn string(&mut self, value: &str) {
        self.length(value.len() + 1);
        self.out.extend_from_slice(value.as_bytes());
        self.out.push(0);
    }

    /// A `sequence<uint8>`.
    pub fn bytes(&mut self, value: &[u8]) {
        self.length(value.len());
        self.out.extend_from_slice(value);
    }

    /// A `sequence<float32>`.
    pub fn f32_sequence(&mut self, values: &[f32]) {
        self.length(values.len());
        for &value in values {
            self.f32(value);
        }
    }

    /// A `std_msgs/Header`: stamp (`int32` sec, `uint32` nanosec) and frame id.
    pub fn header(&mut self, header: &Header) {
        self.i32(header.sec);
        self.u32(header.nanosec);
        self.string(&header.frame_id);
    }

    /// The payload written so far, header included.
    pub fn finish(self) -> Bytes {
        Bytes::from(self.out)
    }
}

/// The header of a stamp in ns since the epoch (seconds saturate at `i32::MAX`, after 2038).
pub fn header_at(stamp_ns: u64, frame_id: &str) -> Header {
    let sec = i32::try_from(stamp_ns / 1_000_000_000).unwrap_or(i32::MAX);
    Header { sec, nanosec: (stamp_ns % 1_000_000_000) as u32, frame_id: frame_id.to_owned() }
}

/// `tf2_msgs/msg/TFMessage`: a sequence of `geometry_msgs/TransformStamped`.
pub fn tf_message(transforms: &[TransformStamped]) -> Bytes {
    let mut cdr = CdrWriter::with_capacity(transforms.len() * 112 + 8);
    cdr.length(transforms.len());
    for transform in transforms {
        cdr.header(&transform.header);
        cdr.string(&transform.child_frame_id);
        for value in transform.translation.iter().chain(&transform.rotation) {
            cdr.f64(*value);
        }
    }
    cdr.finish()
}

/// `sensor_msgs/msg/Image`.
pub fn image(image: &Image) -> Bytes {
    let mut cdr = CdrWriter::with_capacity(image.data.len() + 64 + image.header.frame_id.len());
    cdr.header(&image.header);
    cdr.u32(image.height);
    cdr.u32(image.width);
    cdr.string(&image.encoding);
    cdr.u8(u8::from(image.is_bigendian));
    cdr.u32(image.step);
    cdr.bytes(&image.data);
    cdr.finish()
}

/// `sensor_msgs/msg/LaserScan`.
pub fn laser_scan(scan: &LaserScan) -> Bytes {
    let mut cdr = CdrWriter::with_capacity(4 * (scan.ranges.len() + scan.intensities.len()) + 64);
    cdr.header(&scan.header);
    for value in [
        scan.angle_min,
        scan.angle_max,
        scan.angle_increment,
        scan.time_increment,
        scan.scan_time,
        scan.range_min,
        scan.range_max,
    ] {
        cdr.f32(value);
    }
    cdr.f32_sequence(&scan.ranges);
    cdr.f32_sequence(&scan.intensities);
    cdr.finish()
}

#[cfg(test)]
mod tests {
    use proptest::prelude::*;
    use replay::ros2::{Ros2Message, decode};

    use super::*;

    fn transform(parent: &str, child: &str, translation: [f64; 3], rotation: [f64; 4]) -> TransformStamped {
        TransformStamped {
            header: header_at(1_700_000_000_123_456_789, parent),
            child_frame_id: child.to_owned(),
            translation,
            rotation,
        }
    }

    #[test]
    fn a_tf_message_decodes_to_the_transforms_encoded() {
        let transforms = vec![
            transform("world", "base_link", [1.0, -2.5, 0.25], [0.0, 0.0, 0.38268343, 0.92387953]),
            transform("base_link", "laser", [0.1, 0.0, 0.3], [0.0, 0.0, 0.0, 1.0]),
        ];
        let bytes = tf_message(&transforms);
        assert_eq!(&bytes[..4], &CDR_LE_HEADER);
        let decoded = decode("tf2_msgs/msg/TFMessage", &bytes).unwrap();
        assert_eq!(decoded, Some(Ros2Message::Tf(transforms)));
    }

    #[test]
    fn the_header_keeps_seconds_and_nanoseconds() {
        let header = header_at(12_000_000_345, "f");
        assert_eq!((header.sec, header.nanosec), (12, 345));
        assert_eq!(header.stamp_ns(), 12_000_000_345);
    }

    #[test]
    fn every_cut_of_an_encoded_scan_is_a_decode_error_not_a_panic() {
        let scan = LaserScan {
            header: header_at(5, "laser"),
            angle_min: -1.0,
            angle_max: 1.0,
            angle_increment: 0.5,
            time_increment: 0.0,
            scan_time: 0.1,
            range_min: 0.05,
            range_max: 30.0,
            ranges: vec![1.0, 2.0, 3.0, 4.0, 5.0],
            intensities: vec![],
        };
        let bytes = laser_scan(&scan);
        for cut in 0..bytes.len() {
            assert!(decode("sensor_msgs/msg/LaserScan", &bytes.slice(..cut)).is_err(), "cut at {cut}");
        }
    }

    proptest! {
        #[test]
        fn an_image_round_trips(
            frame in "[a-z_/]{0,12}",
            encoding in prop::sample::select(vec!["mono8", "rgb8", "bgr8"]),
            height in 0u32..6,
            width in 0u32..6,
            stamp_ns in 0u64..4_000_000_000_000_000_000,
            big in any::<bool>(),
        ) {
            let channels = if encoding == "mono8" { 1 } else { 3 };
            let data: Vec<u8> = (0..height * width * channels).map(|i| i as u8).collect();
            let image = Image {
                header: header_at(stamp_ns, &frame),
                height,
                width,
                encoding: encoding.to_owned(),
                is_bigendian: big,
                step: width * channels,
                data: Bytes::from(data),
            };
            let decoded = decode("sensor_msgs/msg/Image", &super::image(&image)).unwrap();
            prop_assert_eq!(decoded, Some(Ros2Message::Image(image)));
        }

        #[test]
        fn a_laser_scan_round_trips(
            frame in "[a-z_]{0,10}",
            ranges in prop::collection::vec(0.0f32..100.0, 0..40),
            intensities in prop::collection::vec(0.0f32..1000.0, 0..3),
            angles in prop::array::uniform7(-4.0f32..4.0),
        ) {
            let scan = LaserScan {
                header: header_at(1_000_000_007, &frame),
                angle_min: angles[0],
                angle_max: angles[1],
                angle_increment: angles[2],
                time_increment: angles[3],
                scan_time: angles[4],
                range_min: angles[5],
                range_max: angles[6],
                ranges,
                intensities,
            };
            let decoded = decode("sensor_msgs/msg/LaserScan", &laser_scan(&scan)).unwrap();
            prop_assert_eq!(decoded, Some(Ros2Message::LaserScan(scan)));
        }
    }
}
