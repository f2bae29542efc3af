//! # A live ROS 2 bridge for the DSR_d graph
//!
//! `cortex bridge ros2` joins a ROS 2 domain with the project's RTPS engine (`rustdds`) and a DSR_d graph as an
//! agent, and moves data both ways:
//!
//! - **In**: ROS 2 topics (DDS topic `rt/<topic>`, type `<pkg>::msg::dds_::<Type>_`, the QoS ROS 2 uses for sensor
//!   data, for the default profile and for `/tf_static`) are read as raw CDR ([`raw`]) and written into the graph by
//!   `replay`'s own [`replay::Bridge`] ([`inbound`]): one decoder set for logs and live topics. Topics, target nodes
//!   and rates come from a TOML file ([`config`]). Malformed samples are counted per topic and logged.
//! - **Out**: RT edges are published as `tf2_msgs/msg/TFMessage` on `/tf` (the static ones on `/tf_static`,
//!   transient local), image and laser nodes as `sensor_msgs/msg/Image` and `LaserScan` ([`graph_out`] reads the
//!   graph, [`encode`] writes the CDR, the inverse of `replay::ros2`'s decoders).
//!
//! The cores ([`inbound`], [`graph_out`], [`encode`], [`config`]) do no I/O and read no clock; [`runtime`] owns the
//! DDS participant and the two threads (`reader` for In, `writer` for Out), and [`status`] is what they report.

pub mod config;
pub mod encode;
pub mod graph_out;
pub mod inbound;
pub mod qos;
pub mod raw;
mod reader;
pub mod runtime;
pub mod status;
mod writer;

pub use config::BridgeConfig;
pub use runtime::{Ros2Bridge, StartError};
pub use status::BridgeStatus;

/// Locks a mutex, taking the value of a poisoned one (a panicked holder leaves counters, which stay usable).
fn lock<T>(mutex: &std::sync::Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    mutex.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
}
