//! Colour labelling on real EuRoC frames against a reference computed independently here: a per-pixel scan of
//! the class list, no tables.

use bytes::Bytes;
use perception::fixtures;
use perception::labelling::{ColourClass, LabelConfig, LabelTables};
use perception::sensors::{Encoding, Image};

fn config() -> LabelConfig {
    let class = |name: &str, min: [u8; 3], max: [u8; 3]| ColourClass {
        name: name.to_owned(),
        min,
        max,
        display: [min[0], min[1], min[2]],
    };
    LabelConfig {
        classes: vec![
            class("dark", [0, 0, 0], [40, 40, 40]),
            class("bright", [200, 200, 200], [255, 255, 255]),
            class("orange", [150, 60, 0], [255, 160, 90]),
            class("mid", [90, 90, 90], [130, 130, 130]),
            class("overlaps_mid", [100, 0, 0], [140, 255, 255]),
        ],
    }
}

/// Reference: the first class whose box holds (r, g, b), by a linear scan.
fn reference_label(config: &LabelConfig, rgb: [u8; 3]) -> u8 {
    for (index, class) in config.classes.iter().enumerate() {
        if (0..3).all(|c| class.min[c] <= rgb[c] && rgb[c] <= class.max[c]) {
            return index as u8 + 1;
        }
    }
    0
}

/// A colour image made from a grey frame so all three channels differ (real texture, synthetic hue).
fn colourise(grey: &Image, bgr: bool) -> Image {
    let mut data = Vec::with_capacity(grey.data.len() * 3);
    for &g in grey.data.iter() {
        let rgb = [g, g.wrapping_mul(3) / 2, 255 - g];
        if bgr {
            data.extend_from_slice(&[rgb[2], rgb[1], rgb[0]]);
        } else {
            data.extend_from_slice(&rgb);
        }
    }
    let encoding = if bgr { Encoding::Bgr8 } else { Encoding::Rgb8 };
    Image::new(grey.width, grey.height, encoding, Bytes::from(data)).unwrap()
}

#[test]
fn labels_of_real_frames_match_the_reference_in_every_encoding() {
    let config = config();
    let tables = LabelTables::new(config.clone()).unwrap();
    let frames = fixtures::euroc_frames().unwrap();
    assert_eq!(frames.len(), 3);
    for frame in &frames {
        assert_eq!((frame.width, frame.height), (752, 480));
        let labelled = tables.label(frame);
        let expected: Vec<u8> = frame.data.iter().map(|&g| reference_label(&config, [g, g, g])).collect();
        assert_eq!(labelled.labels, expected);
        // The frames are real scenes: several classes occur.
        let used = (0..=5u8).filter(|l| expected.contains(l)).count();
        assert!(used >= 3, "only {used} labels used");
        for bgr in [false, true] {
            let colour = colourise(frame, bgr);
            let labelled = tables.label(&colour);
            let expected: Vec<u8> = colour
                .data
                .chunks_exact(3)
                .map(|p| reference_label(&config, if bgr { [p[2], p[1], p[0]] } else { [p[0], p[1], p[2]] }))
                .collect();
            assert_eq!(labelled.labels, expected, "bgr {bgr}");
        }
    }
}
