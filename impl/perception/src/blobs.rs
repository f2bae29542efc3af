//! Blob detector on the labelled image: 4-connected regions of one colour class with at least `min_area_px`
//! pixels, tracked in image coordinates by an EKF [`Tracker`] (Cartesian measurements in px, tag = class).
//! Confirmed tracks are kept in the graph as `blob` nodes `blob_<camera node name>_<track id>` under the camera
//! node. A monocular camera gives no depth, so a blob's 3-D position is its pixel ray at `nominal_depth_mm` in
//! the optical frame (x right, y down, z forward; focal length from `cam_rgb_focalx`/`cam_rgb_focaly`, else the
//! config). Covariance and velocity attributes of blob nodes are in px² and px/s.

use bica::debug::{DebugPrimitive, Debuggable, Frame, Point2, Rgba, Shape};
use bica::prelude::*;
use dsr::{Value, attrs as dsr_attrs};

use crate::detections::{DetectionNodes, TrackNode};
use crate::ekf::{Detection, Measurement, Tracker, TrackerConfig};
use crate::graph::{SharedGraph, attrs};
use crate::labelling::{ColourLabeller, LabelledImage};
use crate::sensors::CameraReader;

/// A region of one class.
#[derive(Debug, Clone, PartialEq)]
pub struct Blob {
    /// Colour class index (label - 1).
    pub class: u32,
    /// Pixels.
    pub area_px: u32,
    /// Centroid (x, y), px.
    pub centroid_px: [f64; 2],
    /// Bounding box min (x, y), px.
    pub min_px: [usize; 2],
    /// Bounding box max (x, y), px, inclusive.
    pub max_px: [usize; 2],
}

/// Parameters of the blob detector.
#[derive(Debug, Clone, PartialEq)]
pub struct BlobConfig {
    /// Smallest blob reported, px.
    pub min_area_px: u32,
    /// Classes to detect (empty: all).
    pub classes: Vec<u32>,
    /// Centroid noise, px.
    pub centroid_sigma_px: f64,
    /// Depth assumed for the 3-D position, mm.
    pub nominal_depth_mm: f64,
    /// Focal length used when the camera node has none, px.
    pub default_focal_px: f64,
    /// Tracker parameters (positions in px).
    pub tracker: TrackerConfig,
}

impl Default for BlobConfig {
    fn default() -> Self {
        Self {
            min_area_px: 50,
            classes: Vec::new(),
            centroid_sigma_px: 3.0,
            nominal_depth_mm: 2000.0,
            default_focal_px: 460.0,
            tracker: TrackerConfig { process_noise: 20_000.0, ..TrackerConfig::default() },
        }
    }
}

/// Finds the 4-connected regions of equal non-zero label with at least `min_area_px` pixels, in raster order of
/// their first pixel.
pub fn find_blobs(labelled: &LabelledImage, min_area_px: u32) -> Vec<Blob> {
    let (w, h) = (labelled.width, labelled.height);
    if labelled.labels.len() != w * h {
        tracing::warn!(w, h, len = labelled.labels.len(), "labelled image size mismatch; no blobs");
        return Vec::new();
    }
    let mut seen = vec![false; w * h];
    let mut stack = Vec::new();
    let mut blobs = Vec::new();
    for start in 0..w * h {
        let label = labelled.labels[start];
        if label == 0 || seen[start] {
            continue;
        }
        seen[start] = true;
        stack.push(start);
        let (mut area, mut sx, mut sy) = (0u64, 0u64, 0u64);
        let (mut min, mut max) = ([usize::MAX; 2], [0usize; 2]);
        while let Some(i) = stack.pop() {
            let (x, y) = (i % w, i / w);
            area += 1;
            sx += x as u64;
            sy += y as u64;
            min = [min[0].min(x), min[1].min(y)];
            max = [max[0].max(x), max[1].max(y)];
            let mut visit = |j: usize| {
                if !seen[j] && labelled.labels[j] == label {
                    seen[j] = true;
                    stack.push(j);
                }
            };
            if x > 0 {
                visit(i - 1);
            }
            if x + 1 < w {
                visit(i + 1);
            }
            if y > 0 {
                visit(i - w);
            }
            if y + 1 < h {
                visit(i + w);
            }
        }
        if area >= u64::from(min_area_px) {
            blobs.push(Blob {
                class: u32::from(label - 1),
                area_px: u32::try_from(area).unwrap_or(u32::MAX),
                centroid_px: [sx as f64 / area as f64, sy as f64 / area as f64],
                min_px: min,
                max_px: max,
            });
        }
    }
    blobs
}

/// BICA component: finds blobs in each new labelled image of the [`ColourLabeller`] (stepped first), tracks them
/// and keeps `blob` nodes in the graph. Debug: each blob's box and each confirmed track's 95 % ellipse (px).
#[derive(Debug)]
pub struct BlobDetector {
    graph: SharedGraph,
    config: BlobConfig,
    tracker: Tracker,
    blobs: Vec<Blob>,
    nodes: Option<DetectionNodes>,
    last_time_ns: Option<u64>,
    areas: Vec<(u64, u32)>,
}

impl BlobDetector {
    /// A detector writing to `graph`.
    pub fn new(graph: SharedGraph, config: BlobConfig) -> Self {
        let tracker = Tracker::new(config.tracker.clone());
        Self { graph, config, tracker, blobs: Vec::new(), nodes: None, last_time_ns: None, areas: Vec::new() }
    }

    /// Blobs of the latest labelled image.
    pub fn blobs(&self) -> &[Blob] {
        &self.blobs
    }

    /// The tracker (positions in px).
    pub fn tracker(&self) -> &Tracker {
        &self.tracker
    }

    /// The graph node of each confirmed track.
    pub fn track_nodes(&self) -> Option<&DetectionNodes> {
        self.nodes.as_ref()
    }

    /// The last matched area of a track, px.
    pub fn track_area(&self, track_id: u64) -> Option<u32> {
        self.areas.iter().find(|(id, _)| *id == track_id).map(|(_, a)| *a)
    }
}

impl Component for BlobDetector {
    fn step(&mut self, ctx: &mut StepContext<'_>) -> Result<(), BicaError> {
        ctx.step::<ColourLabeller>()?;
        let labeller = ctx.get::<ColourLabeller>()?;
        let Some(labelled) = labeller.latest().filter(|_| labeller.is_fresh()).cloned() else { return Ok(()) };
        let camera = ctx.get::<CameraReader>()?;
        let Some(sensor) = camera.node() else { return Ok(()) };
        let time_ns = camera.latest_stamp_ns().unwrap_or_else(|| ctx.now_ns());
        let camera_name = camera.node_name().to_owned();
        let dt_s = self.last_time_ns.map_or(0.0, |last| time_ns.saturating_sub(last) as f64 * 1e-9);
        self.last_time_ns = Some(time_ns);
        self.blobs = find_blobs(&labelled, self.config.min_area_px);
        self.blobs.retain(|b| self.config.classes.is_empty() || self.config.classes.contains(&b.class));
        let variance = self.config.centroid_sigma_px.powi(2);
        let detections: Vec<Detection> = self
            .blobs
            .iter()
            .map(|b| Detection {
                tag: b.class,
                measurement: Measurement::Cartesian {
                    position_mm: b.centroid_px,
                    covariance_mm2: [[variance, 0.0], [0.0, variance]],
                },
            })
            .collect();
        self.tracker.step(dt_s, &detections);
        let mut graph = self.graph.borrow_mut();
        let focal_x = graph.get(sensor, dsr_attrs::CAM_RGB_FOCALX).map_or(self.config.default_focal_px, f64::from);
        let focal_y = graph.get(sensor, dsr_attrs::CAM_RGB_FOCALY).map_or(focal_x, f64::from);
        let (cx, cy) = (labelled.width as f64 / 2.0, labelled.height as f64 / 2.0);
        let depth = self.config.nominal_depth_mm;
        self.areas.clear();
        let mut tracks = Vec::new();
        for t in self.tracker.confirmed() {
            let [u, v] = t.filter.position_mm();
            let area = self
                .blobs
                .iter()
                .filter(|b| b.class == t.tag)
                .min_by(|a, b| {
                    let d = |b: &Blob| (b.centroid_px[0] - u).hypot(b.centroid_px[1] - v);
                    d(a).total_cmp(&d(b))
                })
                .map_or(0, |b| b.area_px);
            self.areas.push((t.id, area));
            let c = t.filter.position_covariance();
            let vel = t.filter.velocity_mm_s();
            tracks.push(TrackNode {
                track_id: t.id,
                position_mm: [((u - cx) / focal_x * depth) as f32, ((v - cy) / focal_y * depth) as f32, depth as f32],
                covariance: [c[(0, 0)] as f32, c[(0, 1)] as f32, c[(1, 0)] as f32, c[(1, 1)] as f32],
                velocity: [vel[0] as f32, vel[1] as f32],
                extra: vec![
                    (attrs::BLOB_CLASS.name(), Value::U32(t.tag)),
                    (attrs::BLOB_AREA_PX.name(), Value::U32(area)),
                ],
            });
        }
        let nodes = self.nodes.get_or_insert_with(|| DetectionNodes::new("blob", format!("blob_{camera_name}")));
        nodes.sync(&mut *graph, ctx.now_ns(), sensor, &tracks);
        Ok(())
    }

    fn as_debuggable(&self) -> Option<&dyn Debuggable> {
        Some(self)
    }
}

impl Debuggable for BlobDetector {
    fn debug_primitives(&self, out: &mut Vec<DebugPrimitive>) {
        let yellow = Rgba { r: 250, g: 220, b: 0, a: 255 };
        let green = Rgba { r: 0, g: 220, b: 80, a: 255 };
        for blob in &self.blobs {
            let min = Point2 { x: blob.min_px[0] as f64, y: blob.min_px[1] as f64 };
            let max = Point2 { x: blob.max_px[0] as f64, y: blob.max_px[1] as f64 };
            out.push(DebugPrimitive::new(Frame::Image, Shape::Rectangle { min, max }, yellow));
        }
        for track in self.tracker.confirmed() {
            let [x, y] = track.filter.position_mm();
            let (radius_x, radius_y, rotation_rad) = track.filter.position_ellipse(5.99);
            let center = Point2 { x, y };
            out.push(DebugPrimitive::new(
                Frame::Image,
                Shape::Ellipse { center, radius_x, radius_y, rotation_rad },
                green,
            ));
            out.push(DebugPrimitive::new(
                Frame::Image,
                Shape::Text { at: center, text: format!("#{}", track.id) },
                green,
            ));
        }
    }
}
