//! # Replay of robot logs into the DSR_d graph
//!
//! The harness replays real sensor recordings (ROS 2 MCAP files) into the distributed graph, so that experiments
//! run on real data rates and payloads. The path is split so that every stage can be tested alone:
//!
//! - [`log`] memory-maps an MCAP file and yields its messages in log-time order, with errors that say where a
//!   damaged file is damaged, and a recovery mode that keeps what was readable before the damage;
//! - [`ros2`] decodes the common ROS 2 message types from CDR, borrowing big payloads (images, point clouds) from
//!   the mapped file;
//! - [`bridge`] turns decoded messages into graph operations on a [`dsr::Replica`] (a sensor node per topic, TF as
//!   RT edges) and returns the deltas;
//! - [`pace`] schedules messages at the recorded timing times a rate factor (or as fast as possible) against an
//!   injected clock, looping short logs; it never sleeps;
//! - [`inproc`] joins the bridge's replica to N receiver replicas through a seeded in-memory delivery behind the
//!   [`inproc::Sink`] trait, which a real transport can implement.
//!
//! Nothing here panics on input: damaged files, malformed messages and unknown types are errors or counts.

pub mod bridge;
pub mod inproc;
pub mod log;
pub mod pace;
pub mod ros2;

pub use bridge::{Bridge, BridgeOptions, BridgeStats};
pub use log::{Channel, Damage, DamageKind, Log, LogError, Message, ReadOptions, Schema};
pub use pace::{Clock, Paced, Pacer, Rate};
