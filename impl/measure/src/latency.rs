//! Latency histograms per payload class. Values are nanoseconds in an HDR histogram (3 significant digits, 1 ns to
//! 1 hour); percentiles are read from it, so they are exact to within 0.1 %.

use std::collections::BTreeMap;

use hdrhistogram::Histogram;
use serde::{Deserialize, Serialize};

/// What kind of payload an update carries, from the ROS 2 type of the message it came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PayloadClass {
    /// Camera images (raw or compressed).
    Image,
    /// Point clouds.
    PointCloud,
    /// Laser scans.
    Scan,
    /// Everything else: poses, IMU samples, transforms, camera info, GPS fixes, node creation.
    Small,
}

impl PayloadClass {
    /// All classes, in display order.
    pub const ALL: [PayloadClass; 4] =
        [PayloadClass::Image, PayloadClass::PointCloud, PayloadClass::Scan, PayloadClass::Small];

    /// The class of a message of ROS 2 type `schema` (e.g. `sensor_msgs/msg/Image`).
    pub fn of_schema(schema: &str) -> PayloadClass {
        let name = schema.rsplit('/').next().unwrap_or(schema);
        match name {
            "Image" | "CompressedImage" => PayloadClass::Image,
            "PointCloud2" => PayloadClass::PointCloud,
            "LaserScan" => PayloadClass::Scan,
            _ => PayloadClass::Small,
        }
    }

    /// The snake-case name used in JSON and tables.
    pub fn name(self) -> &'static str {
        match self {
            PayloadClass::Image => "image",
            PayloadClass::PointCloud => "point_cloud",
            PayloadClass::Scan => "scan",
            PayloadClass::Small => "small",
        }
    }
}

/// Summary of one histogram, in nanoseconds.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Percentiles {
    /// Number of values.
    pub count: u64,
    /// Median.
    pub p50_ns: u64,
    /// 90th percentile.
    pub p90_ns: u64,
    /// 99th percentile.
    pub p99_ns: u64,
    /// 99.9th percentile.
    pub p999_ns: u64,
    /// Largest value.
    pub max_ns: u64,
    /// Mean.
    pub mean_ns: f64,
}

impl Percentiles {
    /// The summary of `histogram` (all zero when it is empty).
    pub fn of(histogram: &Histogram<u64>) -> Percentiles {
        if histogram.is_empty() {
            return Percentiles::default();
        }
        Percentiles {
            count: histogram.len(),
            p50_ns: histogram.value_at_quantile(0.50),
            p90_ns: histogram.value_at_quantile(0.90),
            p99_ns: histogram.value_at_quantile(0.99),
            p999_ns: histogram.value_at_quantile(0.999),
            max_ns: histogram.max(),
            mean_ns: histogram.mean(),
        }
    }
}

/// A new nanosecond histogram: 1 ns to 1 hour, 3 significant digits.
pub fn histogram() -> Histogram<u64> {
    Histogram::new_with_bounds(1, 3_600_000_000_000, 3).expect("constant, valid bounds")
}

/// Latencies recorded per payload class and overall.
#[derive(Clone, Debug)]
pub struct LatencyRecorder {
    by_class: BTreeMap<PayloadClass, Histogram<u64>>,
    all: Histogram<u64>,
}

impl Default for LatencyRecorder {
    fn default() -> Self {
        LatencyRecorder { by_class: BTreeMap::new(), all: histogram() }
    }
}

impl LatencyRecorder {
    /// An empty recorder.
    pub fn new() -> Self {
        LatencyRecorder::default()
    }

    /// Records one latency of `ns` nanoseconds (clamped to at least 1 ns).
    pub fn record(&mut self, class: PayloadClass, ns: u64) {
        let ns = ns.max(1);
        self.all.saturating_record(ns);
        self.by_class.entry(class).or_insert_with(histogram).saturating_record(ns);
    }

    /// Summary of every value.
    pub fn overall(&self) -> Percentiles {
        Percentiles::of(&self.all)
    }

    /// Summary per class (classes with values only).
    pub fn by_class(&self) -> BTreeMap<PayloadClass, Percentiles> {
        self.by_class.iter().map(|(class, h)| (*class, Percentiles::of(h))).collect()
    }

    /// The histogram of every value.
    pub fn histogram(&self) -> &Histogram<u64> {
        &self.all
    }

    /// Points of the cumulative distribution of every value: `(nanoseconds, fraction at or below)`, at most
    /// `points` of them, evenly spaced in quantile and always including the maximum.
    pub fn cdf(&self, points: usize) -> Vec<(u64, f64)> {
        cdf(&self.all, points)
    }
}

/// Points of the cumulative distribution of `histogram`, as [`LatencyRecorder::cdf`].
pub fn cdf(histogram: &Histogram<u64>, points: usize) -> Vec<(u64, f64)> {
    if histogram.is_empty() || points == 0 {
        return Vec::new();
    }
    let mut out: Vec<(u64, f64)> = (1..=points)
        .map(|i| {
            let q = i as f64 / points as f64;
            (histogram.value_at_quantile(q), q)
        })
        .collect();
    out.dedup_by_key(|p| p.0);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn classes_come_from_the_ros_type() {
        assert_eq!(PayloadClass::of_schema("sensor_msgs/msg/Image"), PayloadClass::Image);
        assert_eq!(PayloadClass::of_schema("sensor_msgs/msg/CompressedImage"), PayloadClass::Image);
        assert_eq!(PayloadClass::of_schema("sensor_msgs/msg/PointCloud2"), PayloadClass::PointCloud);
        assert_eq!(PayloadClass::of_schema("sensor_msgs/msg/LaserScan"), PayloadClass::Scan);
        assert_eq!(PayloadClass::of_schema("sensor_msgs/msg/Imu"), PayloadClass::Small);
    }

    #[test]
    fn percentiles_of_one_to_a_thousand() {
        let mut recorder = LatencyRecorder::new();
        for ns in 1..=1000 {
            recorder.record(if ns % 2 == 0 { PayloadClass::Image } else { PayloadClass::Small }, ns * 1000);
        }
        let all = recorder.overall();
        assert_eq!(all.count, 1000);
        assert!((499_000..=501_000).contains(&all.p50_ns), "{all:?}");
        assert!((989_000..=991_000).contains(&all.p99_ns), "{all:?}");
        assert!((999_000..=1_001_000).contains(&all.max_ns), "{all:?}");
        let by_class = recorder.by_class();
        assert_eq!(by_class[&PayloadClass::Image].count, 500);
        assert_eq!(by_class[&PayloadClass::Small].count, 500);
        assert!(!by_class.contains_key(&PayloadClass::Scan));
        let cdf = recorder.cdf(10);
        assert_eq!(cdf.last().map(|p| p.1), Some(1.0));
        assert!(cdf.windows(2).all(|w| w[0].0 < w[1].0 && w[0].1 < w[1].1));
    }
}
