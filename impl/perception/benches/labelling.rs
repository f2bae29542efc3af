//! Colour labelling throughput on the real EuRoC 752x480 frames (target: at least 300 frames/s on one core),
//! for `mono8` and for an `rgb8` image made from the same frame.

// `criterion_group!` generates an undocumented public function.
#![allow(missing_docs)]

use bytes::Bytes;
use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use perception::fixtures;
use perception::labelling::{ColourClass, LabelConfig, LabelTables, LabelledImage};
use perception::sensors::{Encoding, Image};

fn tables() -> LabelTables {
    let class = |name: &str, min: [u8; 3], max: [u8; 3]| ColourClass {
        name: name.to_owned(),
        min,
        max,
        display: [255, 255, 255],
    };
    LabelTables::new(LabelConfig {
        classes: vec![
            class("dark", [0, 0, 0], [40, 40, 40]),
            class("bright", [200, 200, 200], [255, 255, 255]),
            class("orange", [150, 60, 0], [255, 160, 90]),
            class("mid", [90, 90, 90], [130, 130, 130]),
        ],
    })
    .expect("valid config")
}

fn bench(c: &mut Criterion) {
    let tables = tables();
    let frame = fixtures::euroc_frames().expect("fixtures present").remove(1);
    let rgb: Vec<u8> = frame.data.iter().flat_map(|&g| [g, g.wrapping_mul(3) / 2, 255 - g]).collect();
    let colour = Image::new(frame.width, frame.height, Encoding::Rgb8, Bytes::from(rgb)).expect("sizes match");
    let mut out = LabelledImage { width: 0, height: 0, labels: Vec::new() };
    let mut group = c.benchmark_group("labelling_euroc_752x480");
    group.throughput(Throughput::Elements(1));
    group.bench_function("mono8", |b| b.iter(|| tables.label_into(std::hint::black_box(&frame), &mut out)));
    group.bench_function("rgb8", |b| b.iter(|| tables.label_into(std::hint::black_box(&colour), &mut out)));
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
