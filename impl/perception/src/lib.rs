//! CORTEX perception and attention as BICA components over the DSR_d graph.
//!
//! The components read sensor data from, and write what they find to, the shared graph through the
//! [`graph::GraphAccess`] trait, so they run on a bare [`dsr::Replica`] in tests and on an agent's replica in the
//! role processes:
//!
//! - [`sensors`]: readers of the latest camera image, laser scan, point cloud, IMU sample and pose of a sensor
//!   node (and the writers a bridge uses);
//! - [`labelling`]: colour labelling of camera images through lookup tables;
//! - [`ekf`]: a constant-velocity extended Kalman filter and a multi-target tracker with gating and track
//!   birth, confirmation and death;
//! - [`blobs`] and [`obstacles`]: detectors on labelled images and on laser scans / point clouds that track
//!   what they find and keep it in the graph as `blob` / `obstacle` nodes with RT edges from the sensor;
//! - [`attention`]: picks the stimulus that governs attention from the behaviours' requirements and drives the
//!   [`attention::Head`], which writes the gaze target into the graph;
//! - [`behaviour`]: a search/track FSM that changes which components are active at run time;
//! - [`roles`]: one function per agent role that registers its BICA tree given a graph handle;
//! - [`agent_graph`]: the graph handle of a role process, over a running DSR_d agent.
//!
//! Units follow the graph: mm and rad.

pub mod agent_graph;
pub mod attention;
pub mod behaviour;
pub mod blobs;
pub mod clusters;
pub mod detections;
pub mod ekf;
pub mod fixtures;
pub mod graph;
pub mod labelling;
pub mod obstacles;
pub mod roles;
pub mod sensors;
