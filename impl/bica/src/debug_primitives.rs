//! Debug primitives: components that can be debugged ([`Debuggable`]) return points, lines, arrows, circles,
//! ellipses, rectangles, boxes, text and images in image, robot-relative or world coordinates, gathered with the
//! name of their component into a bounded [`DebugFrame`]. Everything serializes with serde, so a remote viewer can
//! draw it. The component that gathers them, `DebugCollector`, is in [`crate::debug`]; these types live apart so
//! that [`crate::component`] can name [`Debuggable`] without depending on a component.

use serde::{Deserialize, Serialize};

use crate::error::BicaError;

/// Largest image payload accepted in a primitive.
pub const MAX_IMAGE_BYTES: usize = 4 << 20;

/// The coordinate frame a primitive is drawn in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum Frame {
    /// Pixels of a camera image (x right, y down).
    Image,
    /// Metres relative to the robot (x forward, y left, z up).
    Robot,
    /// Metres in the world frame.
    World,
}

/// A 2-D point.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Point2 {
    /// Horizontal coordinate.
    pub x: f64,
    /// Vertical coordinate.
    pub y: f64,
}

/// An 8-bit RGBA colour.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct Rgba {
    /// Red.
    pub r: u8,
    /// Green.
    pub g: u8,
    /// Blue.
    pub b: u8,
    /// Opacity.
    pub a: u8,
}

/// The geometry of a primitive.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum Shape {
    /// A point.
    Point {
        /// Position.
        at: Point2,
    },
    /// A line segment.
    Line {
        /// Start.
        from: Point2,
        /// End.
        to: Point2,
    },
    /// An arrow from `from` pointing at `to`.
    Arrow {
        /// Tail.
        from: Point2,
        /// Head.
        to: Point2,
    },
    /// A circle.
    Circle {
        /// Centre.
        center: Point2,
        /// Radius.
        radius: f64,
    },
    /// An ellipse.
    Ellipse {
        /// Centre.
        center: Point2,
        /// Half-axis along the rotated x axis.
        radius_x: f64,
        /// Half-axis along the rotated y axis.
        radius_y: f64,
        /// Rotation, counter-clockwise.
        rotation_rad: f64,
    },
    /// An axis-aligned rectangle.
    Rectangle {
        /// Corner with the smallest coordinates.
        min: Point2,
        /// Corner with the largest coordinates.
        max: Point2,
    },
    /// A 3-D box (robot or world frame).
    Box3 {
        /// Centre `[x, y, z]`.
        center: [f64; 3],
        /// Size `[x, y, z]`.
        size: [f64; 3],
        /// Rotation about z.
        yaw_rad: f64,
    },
    /// A text label.
    Text {
        /// Anchor.
        at: Point2,
        /// The text.
        text: String,
    },
    /// An RGB image placed with its top-left corner at `top_left`.
    Image {
        /// Placement.
        top_left: Point2,
        /// Width in pixels.
        width_px: u32,
        /// Height in pixels.
        height_px: u32,
        /// Row-major RGB8 pixels (`width_px * height_px * 3` bytes).
        rgb8: Vec<u8>,
    },
}

/// One thing to draw.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DebugPrimitive {
    /// Coordinate frame.
    pub frame: Frame,
    /// Geometry.
    pub shape: Shape,
    /// Colour.
    pub color: Rgba,
}

impl DebugPrimitive {
    /// A primitive with the given frame, shape and colour.
    pub fn new(frame: Frame, shape: Shape, color: Rgba) -> Self {
        Self { frame, shape, color }
    }

    /// An image primitive, checking the pixel buffer matches its size.
    pub fn image(
        frame: Frame,
        top_left: Point2,
        width_px: u32,
        height_px: u32,
        rgb8: Vec<u8>,
    ) -> Result<Self, BicaError> {
        let expected = (width_px as usize).checked_mul(height_px as usize).and_then(|p| p.checked_mul(3));
        match expected {
            Some(expected) if expected == rgb8.len() && expected <= MAX_IMAGE_BYTES => Ok(Self {
                frame,
                shape: Shape::Image { top_left, width_px, height_px, rgb8 },
                color: Rgba { r: 255, g: 255, b: 255, a: 255 },
            }),
            _ => Err(BicaError::InvalidPrimitive {
                reason: format!(
                    "image {width_px}x{height_px} needs {expected:?} rgb8 bytes (at most {MAX_IMAGE_BYTES}), got {}",
                    rgb8.len()
                ),
            }),
        }
    }
}

/// Components that can be debugged draw themselves with primitives.
pub trait Debuggable {
    /// Appends this component's current primitives to `out`.
    fn debug_primitives(&self, out: &mut Vec<DebugPrimitive>);
}

/// A primitive with the component that drew it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DebugEntry {
    /// Type name of the component.
    pub component: String,
    /// What it drew.
    pub primitive: DebugPrimitive,
}

/// Everything gathered in one step of the collector.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct DebugFrame {
    /// When it was gathered.
    pub at_ns: u64,
    /// The primitives.
    pub entries: Vec<DebugEntry>,
    /// Primitives dropped because the frame was full.
    pub dropped: u64,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn image_with_wrong_byte_count_is_rejected() {
        let origin = Point2 { x: 0.0, y: 0.0 };
        assert!(DebugPrimitive::image(Frame::Image, origin, 2, 2, vec![0; 11]).is_err());
        assert!(DebugPrimitive::image(Frame::Image, origin, 2, 2, vec![0; 12]).is_ok());
        assert!(DebugPrimitive::image(Frame::Image, origin, u32::MAX, u32::MAX, vec![]).is_err());
    }

    #[test]
    fn every_primitive_round_trips_through_json() {
        let p = Point2 { x: 1.0, y: -2.5 };
        let c = Rgba { r: 1, g: 2, b: 3, a: 4 };
        let shapes = vec![
            Shape::Point { at: p },
            Shape::Line { from: p, to: p },
            Shape::Arrow { from: p, to: p },
            Shape::Circle { center: p, radius: 1.0 },
            Shape::Ellipse { center: p, radius_x: 1.0, radius_y: 2.0, rotation_rad: 0.5 },
            Shape::Rectangle { min: p, max: p },
            Shape::Box3 { center: [1.0, 2.0, 3.0], size: [1.0, 1.0, 1.0], yaw_rad: 0.1 },
            Shape::Text { at: p, text: "ball".to_owned() },
        ];
        for (shape, frame) in shapes.into_iter().zip([Frame::Image, Frame::Robot, Frame::World].into_iter().cycle()) {
            let primitive = DebugPrimitive::new(frame, shape, c);
            let json = serde_json::to_string(&primitive).unwrap();
            assert_eq!(serde_json::from_str::<DebugPrimitive>(&json).unwrap(), primitive);
        }
        let image = DebugPrimitive::image(Frame::Image, p, 1, 1, vec![9, 8, 7]).unwrap();
        let json = serde_json::to_string(&image).unwrap();
        assert_eq!(serde_json::from_str::<DebugPrimitive>(&json).unwrap(), image);
    }
}
