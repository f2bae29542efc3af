//! Presentation conversions: the one place where a duration or a byte count becomes the floating-point number a
//! table or a figure shows. Measurements are kept as integers with their unit in the name (`latency_ns`,
//! `partition_ms`) or as [`std::time::Duration`]; these functions turn them into milliseconds, seconds or MB for
//! display, never the other way round, and nothing converts units anywhere else in the crate.

use std::time::Duration;

/// Nanoseconds as fractional milliseconds: `ms_from_ns(1_500_000) == 1.5`.
///
/// # Examples
/// ```
/// assert_eq!(measure::units::ms_from_ns(1_500_000), 1.5);
/// ```
pub fn ms_from_ns(ns: u64) -> f64 {
    ns as f64 / 1e6
}

/// Nanoseconds as fractional microseconds: `us_from_ns(1_500) == 1.5`.
pub fn us_from_ns(ns: u64) -> f64 {
    ns as f64 / 1e3
}

/// A mean (or any fractional count) of nanoseconds as fractional microseconds.
pub fn us_from_ns_f64(ns: f64) -> f64 {
    ns / 1e3
}

/// A mean (or any fractional count) of nanoseconds as fractional milliseconds.
pub fn ms_from_ns_f64(ns: f64) -> f64 {
    ns / 1e6
}

/// Milliseconds as fractional seconds (figure axes in seconds of experiments set in ms).
pub fn s_from_ms(ms: u64) -> f64 {
    ms as f64 / 1e3
}

/// Nanoseconds as fractional seconds.
pub fn s_from_ns(ns: u64) -> f64 {
    ns as f64 / 1e9
}

/// A duration as fractional milliseconds.
///
/// # Examples
/// ```
/// use std::time::Duration;
/// assert_eq!(measure::units::ms_from_duration(Duration::from_micros(2_500)), 2.5);
/// ```
pub fn ms_from_duration(duration: Duration) -> f64 {
    duration.as_secs_f64() * 1e3
}

/// Bytes (or bytes per second) as megabytes (10^6), the unit of the report's bandwidth figures.
pub fn mb_from_bytes(bytes: f64) -> f64 {
    bytes / 1e6
}

/// Bytes as mebibytes (2^20), the unit of the report's memory figures.
pub fn mib_from_bytes(bytes: u64) -> f64 {
    bytes as f64 / (1u64 << 20) as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn conversions_scale_by_their_unit() {
        assert_eq!(ms_from_ns(2_000_000), 2.0);
        assert_eq!(us_from_ns(2_500), 2.5);
        assert_eq!(us_from_ns_f64(1.5e3), 1.5);
        assert_eq!(s_from_ns(3_000_000_000), 3.0);
        assert_eq!(ms_from_ns_f64(1.5e6), 1.5);
        assert_eq!(s_from_ms(2_500), 2.5);
        assert_eq!(ms_from_duration(Duration::from_millis(7)), 7.0);
        assert_eq!(mb_from_bytes(5e6), 5.0);
        assert_eq!(mib_from_bytes(3 << 20), 3.0);
    }
}
