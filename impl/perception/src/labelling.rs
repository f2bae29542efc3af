//! Colour labelling (the DSR_d paper's Camera component): each pixel gets the colour class whose range
//! contains it, through lookup tables built once from a small config of colour ranges.
//!
//! A class is an axis-aligned box in RGB (`min..=max` per channel); the first class in the config that contains
//! a pixel wins; label 0 means "no class", label `i + 1` is class `i`. A grey (`mono8`) pixel `g` is the colour
//! `(g, g, g)`, so one config serves mono and colour cameras.
//!
//! Tables: for `mono8` a 256-entry table of labels. For `rgb8`/`bgr8`, one 256-entry table of class bitmasks per
//! channel: a pixel's candidate classes are `R[r] & G[g] & B[b]` and its label is the lowest set bit. Because the
//! classes are boxes this is exact (no quantisation, unlike a 32x32x32 table) and the tables take 3 KB, which
//! stay in L1 cache. At most [`MAX_CLASSES`] classes.

use std::sync::Arc;

use bica::debug::{DebugPrimitive, Debuggable, Frame, Point2};
use bica::prelude::*;
use serde::{Deserialize, Serialize};

use crate::sensors::{CameraReader, Encoding, Image};

/// Most classes a config can hold (one bit each in a `u32` mask, labels `1..=32`).
pub const MAX_CLASSES: usize = 32;

/// One colour class: an RGB box and the colour it is drawn with.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct ColourClass {
    /// Name (e.g. `ball`).
    pub name: String,
    /// Smallest red, green, blue (inclusive).
    pub min: [u8; 3],
    /// Largest red, green, blue (inclusive).
    pub max: [u8; 3],
    /// Colour used to draw the class in debug images.
    pub display: [u8; 3],
}

/// The labelling config: classes in priority order.
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct LabelConfig {
    /// The classes; the first that contains a pixel wins.
    pub classes: Vec<ColourClass>,
}

/// Why a labelling config was refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum LabelConfigError {
    /// More than [`MAX_CLASSES`] classes.
    #[error("labelling config has {0} classes, at most {MAX_CLASSES} are supported")]
    TooManyClasses(usize),
    /// A class whose minimum exceeds its maximum on some channel.
    #[error("labelling class `{name}` has min {min:?} above max {max:?} on some channel")]
    EmptyRange {
        /// The class.
        name: String,
        /// Its minimum.
        min: [u8; 3],
        /// Its maximum.
        max: [u8; 3],
    },
}

/// A labelled image: one label per pixel (0: none, `i + 1`: class `i`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LabelledImage {
    /// Width, px.
    pub width: usize,
    /// Height, px.
    pub height: usize,
    /// Row-major labels.
    pub labels: Vec<u8>,
}

/// The lookup tables built from a [`LabelConfig`].
#[derive(Debug, Clone)]
pub struct LabelTables {
    config: LabelConfig,
    mono: [u8; 256],
    /// Class bitmasks indexed by red, green and blue value.
    rgb: [[u32; 256]; 3],
}

impl LabelTables {
    /// Builds the tables.
    ///
    /// # Errors
    /// [`LabelConfigError`] for too many classes or an empty range.
    pub fn new(config: LabelConfig) -> Result<Self, LabelConfigError> {
        if config.classes.len() > MAX_CLASSES {
            return Err(LabelConfigError::TooManyClasses(config.classes.len()));
        }
        let mut rgb = [[0u32; 256]; 3];
        for (index, class) in config.classes.iter().enumerate() {
            if (0..3).any(|c| class.min[c] > class.max[c]) {
                return Err(LabelConfigError::EmptyRange { name: class.name.clone(), min: class.min, max: class.max });
            }
            for (channel, table) in rgb.iter_mut().enumerate() {
                for value in class.min[channel]..=class.max[channel] {
                    table[usize::from(value)] |= 1 << index;
                }
            }
        }
        let mut mono = [0u8; 256];
        for (grey, label) in mono.iter_mut().enumerate() {
            *label = label_of_mask(rgb[0][grey] & rgb[1][grey] & rgb[2][grey]);
        }
        Ok(Self { config, mono, rgb })
    }

    /// The config the tables were built from.
    pub fn config(&self) -> &LabelConfig {
        &self.config
    }

    /// Labels an image into `out` (resized as needed).
    pub fn label_into(&self, image: &Image, out: &mut LabelledImage) {
        out.width = image.width;
        out.height = image.height;
        out.labels.resize(image.width * image.height, 0);
        let data = &image.data[..];
        match image.encoding {
            Encoding::Mono8 => {
                for (label, &grey) in out.labels.iter_mut().zip(data) {
                    *label = self.mono[usize::from(grey)];
                }
            }
            Encoding::Rgb8 => self.label_colour(data, &mut out.labels, [0, 1, 2]),
            Encoding::Bgr8 => self.label_colour(data, &mut out.labels, [2, 1, 0]),
        }
    }

    /// Labels an image into a new buffer.
    pub fn label(&self, image: &Image) -> LabelledImage {
        let mut out = LabelledImage { width: 0, height: 0, labels: Vec::new() };
        self.label_into(image, &mut out);
        out
    }

    /// `order[k]` is the RGB channel stored at byte `k` of each pixel.
    fn label_colour(&self, data: &[u8], labels: &mut [u8], order: [usize; 3]) {
        let [t0, t1, t2] = [&self.rgb[order[0]], &self.rgb[order[1]], &self.rgb[order[2]]];
        for (label, pixel) in labels.iter_mut().zip(data.chunks_exact(3)) {
            let mask = t0[usize::from(pixel[0])] & t1[usize::from(pixel[1])] & t2[usize::from(pixel[2])];
            *label = label_of_mask(mask);
        }
    }

    /// Renders labels as RGB with each class's display colour (black for none), every `scale`-th pixel.
    pub fn render(&self, labelled: &LabelledImage, scale: usize) -> (usize, usize, Vec<u8>) {
        let scale = scale.max(1);
        let (width, height) = (labelled.width.div_ceil(scale), labelled.height.div_ceil(scale));
        let mut rgb = Vec::with_capacity(width * height * 3);
        for y in (0..labelled.height).step_by(scale) {
            for x in (0..labelled.width).step_by(scale) {
                let label = labelled.labels[y * labelled.width + x];
                let colour = match label {
                    0 => [0, 0, 0],
                    l => self.config.classes[usize::from(l) - 1].display,
                };
                rgb.extend_from_slice(&colour);
            }
        }
        (width, height, rgb)
    }
}

fn label_of_mask(mask: u32) -> u8 {
    if mask == 0 { 0 } else { (mask.trailing_zeros() + 1) as u8 }
}

/// BICA component: labels each new image of the [`CameraReader`] (which it steps first) and publishes the
/// labelled image. Debug: the labelled image, downscaled by `debug_scale`, in image coordinates.
#[derive(Debug)]
pub struct ColourLabeller {
    tables: LabelTables,
    latest: Option<Arc<LabelledImage>>,
    fresh: bool,
    frames: u64,
    debug_scale: usize,
}

impl ColourLabeller {
    /// A labeller with the given tables; debug images are downscaled by 2.
    pub fn new(tables: LabelTables) -> Self {
        Self { tables, latest: None, fresh: false, frames: 0, debug_scale: 2 }
    }

    /// The latest labelled image.
    pub fn latest(&self) -> Option<&Arc<LabelledImage>> {
        self.latest.as_ref()
    }

    /// Whether the last step labelled a new image.
    pub fn is_fresh(&self) -> bool {
        self.fresh
    }

    /// Frames labelled so far.
    pub fn frames(&self) -> u64 {
        self.frames
    }

    /// The tables (and config).
    pub fn tables(&self) -> &LabelTables {
        &self.tables
    }
}

impl Component for ColourLabeller {
    fn step(&mut self, ctx: &mut StepContext<'_>) -> Result<(), BicaError> {
        ctx.step::<CameraReader>()?;
        let camera = ctx.get::<CameraReader>()?;
        self.fresh = false;
        if camera.is_fresh()
            && let Some(image) = camera.latest()
        {
            // Reuse the previous buffer when nobody else holds it.
            let mut out = self.latest.take().and_then(|arc| Arc::try_unwrap(arc).ok()).unwrap_or(LabelledImage {
                width: 0,
                height: 0,
                labels: Vec::new(),
            });
            self.tables.label_into(image, &mut out);
            self.latest = Some(Arc::new(out));
            self.fresh = true;
            self.frames += 1;
        }
        Ok(())
    }

    fn as_debuggable(&self) -> Option<&dyn Debuggable> {
        Some(self)
    }
}

impl Debuggable for ColourLabeller {
    fn debug_primitives(&self, out: &mut Vec<DebugPrimitive>) {
        let Some(labelled) = &self.latest else { return };
        let (width, height, rgb) = self.tables.render(labelled, self.debug_scale);
        let (Ok(width), Ok(height)) = (u32::try_from(width), u32::try_from(height)) else { return };
        match DebugPrimitive::image(Frame::Image, Point2 { x: 0.0, y: 0.0 }, width, height, rgb) {
            Ok(primitive) => out.push(primitive),
            Err(error) => tracing::warn!(%error, "labelled image too large to draw"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use bytes::Bytes;

    fn class(name: &str, min: [u8; 3], max: [u8; 3]) -> ColourClass {
        ColourClass { name: name.to_owned(), min, max, display: [255, 255, 255] }
    }

    #[test]
    fn first_containing_class_wins_and_channels_follow_the_encoding() {
        let config = LabelConfig {
            classes: vec![class("red", [200, 0, 0], [255, 60, 60]), class("bright", [150, 150, 150], [255, 255, 255])],
        };
        let tables = LabelTables::new(config).unwrap();
        let rgb = Image::new(3, 1, Encoding::Rgb8, Bytes::from(vec![220, 10, 10, 10, 10, 220, 250, 250, 250])).unwrap();
        assert_eq!(tables.label(&rgb).labels, vec![1, 0, 2]);
        let bgr = Image::new(3, 1, Encoding::Bgr8, Bytes::from(vec![220, 10, 10, 10, 10, 220, 250, 250, 250])).unwrap();
        assert_eq!(tables.label(&bgr).labels, vec![0, 1, 2]);
        let mono = Image::new(3, 1, Encoding::Mono8, Bytes::from(vec![100, 150, 255])).unwrap();
        assert_eq!(tables.label(&mono).labels, vec![0, 2, 2]);
    }

    #[test]
    fn bad_configs_are_refused() {
        let empty = LabelConfig { classes: vec![class("x", [10, 0, 0], [5, 0, 0])] };
        assert!(matches!(LabelTables::new(empty), Err(LabelConfigError::EmptyRange { .. })));
        let many = LabelConfig { classes: (0..33).map(|i| class(&i.to_string(), [0; 3], [255; 3])).collect() };
        assert_eq!(LabelTables::new(many).unwrap_err(), LabelConfigError::TooManyClasses(33));
    }
}
