//! # Replay of robot logs into the DSR_d graph
//!
//! The harness replays real sensor recordings into the distributed graph, so that experiments run on real data rates
//! and payloads. The path is split so that every stage can be tested alone:
//!
//! - containers: [`log`] detects a log's container from its content and yields the same [`Log`] for each — messages
//!   in log-time order with their topic, type, encoding and definition — with errors that say where a damaged file
//!   is damaged, and a recovery mode that keeps what was readable before the damage. [`mcap`] reads MCAP files,
//!   [`bag`] ROS 1 bags (v2.0, bz2 and lz4 chunks), [`rosbag2`] rosbag2 directories (sqlite3 or MCAP storage);
//! - encodings and types: [`ros2`] decodes the common message types from CDR or ROS 1 serialization, borrowing big
//!   payloads (images, point clouds) from the mapped file; [`msgdef`] parses the `.msg` definitions files carry and
//!   [`generic`] decodes any message from its definition into flat attributes;
//! - [`bridge`] turns decoded messages into graph operations on a [`dsr::Replica`] (a sensor node per topic, TF as
//!   RT edges) and returns the deltas;
//! - [`pace`] schedules messages at the recorded timing times a rate factor (or as fast as possible) against an
//!   injected clock, looping short logs; it never sleeps;
//! - [`inproc`] joins the bridge's replica to N receiver replicas through a seeded in-memory delivery behind the
//!   [`inproc::Sink`] trait, which a real transport can implement.
//!
//! Nothing here panics on input: damaged files, malformed messages and unknown types are errors or counts.

pub mod bag;
pub mod bridge;
pub mod contents;
pub mod generic;
pub mod inproc;
pub mod log;
pub mod mcap;
pub mod msgdef;
pub mod pace;
pub mod ros2;
pub mod rosbag2;

pub use bridge::{Bridge, BridgeOptions, BridgeStats};
pub use log::{Channel, Container, Damage, DamageKind, Log, LogError, Message, ReadOptions, Schema};
pub use pace::{Clock, Paced, Pacer, Rate};
