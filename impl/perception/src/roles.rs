//! One function per agent role, registering that role's BICA tree on a runtime given a graph handle, so a role
//! process is a thin wrapper: make the agent, wrap its replica in a [`SharedGraph`], call the function, run.
//! Each function also declares the perception attribute names ([`crate::graph::attrs`]) and registers a
//! [`DebugCollector`] with every debuggable component of the tree marked.
//!
//! The `bridge` role (replaying recorded sensor data into the graph) is not here: it needs the replay side of the
//! agents work; the writers it needs are [`crate::sensors::write_image`], [`crate::sensors::write_scan`] and
//! [`crate::sensors::write_cloud`].

use bica::clock::ns_from_ms;
use bica::debug::DebugCollector;
use bica::prelude::*;

use crate::attention::{Attention, GraphStimuli, Head, Scanner, StimulusKind};
use crate::behaviour::{SearchTrackFsm, search_track};
use crate::blobs::{BlobConfig, BlobDetector};
use crate::graph::{SharedGraph, declare_perception_attrs};
use crate::labelling::{ColourLabeller, LabelTables};
use crate::obstacles::{LaserObstacleDetector, ObstacleConfig};
use crate::sensors::{CameraReader, LaserReader};

/// The roles an agent process can run (`cortex agent --role`): the three BICA trees built here, the fixture camera
/// (a stand-in for a sensor bridge) and the log-playing bridge, which runs no BICA tree.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Role {
    /// Camera reader, colour labeller ("bright" class) and blob detector: `blob` nodes under the camera node.
    CameraDetector,
    /// Laser reader and obstacle detector: `obstacle` nodes under the laser node.
    LaserDetector,
    /// The search/track behaviour over attention, head and scanner, with blobs of class 0 as stimuli.
    Attention,
    /// Writes the bundled EuRoC frames into the camera node (inserted if missing), each frame 5 times in a row.
    FixtureCamera,
    /// Replays a robot log (MCAP, ROS 1 bag or rosbag2 directory) into the graph through the replay bridge: a node
    /// per topic, TF as RT edges.
    Bridge,
}

impl Role {
    /// Every role, in the order of their documentation.
    pub const ALL: [Role; 5] =
        [Role::CameraDetector, Role::LaserDetector, Role::Attention, Role::FixtureCamera, Role::Bridge];

    /// The role's name on command lines and in reports: `camera-detector`, `laser-detector`, `attention`,
    /// `fixture-camera`, `bridge`.
    pub fn name(self) -> &'static str {
        match self {
            Role::CameraDetector => "camera-detector",
            Role::LaserDetector => "laser-detector",
            Role::Attention => "attention",
            Role::FixtureCamera => "fixture-camera",
            Role::Bridge => "bridge",
        }
    }

    /// What the role does, in one sentence (`cortex agent --help`).
    pub fn summary(self) -> &'static str {
        match self {
            Role::CameraDetector => {
                "Camera reader, colour labeller (\"bright\" class) and blob detector: `blob` nodes under the camera node"
            }
            Role::LaserDetector => "Laser reader and obstacle detector: `obstacle` nodes under the laser node",
            Role::Attention => {
                "The search/track behaviour over attention, head and scanner, with blobs of class 0 as stimuli"
            }
            Role::FixtureCamera => {
                "Writes the bundled EuRoC frames into the camera node (inserted if missing), each frame 5 times in a row"
            }
            Role::Bridge => {
                "Replays a robot log (`--log`: MCAP, ROS 1 bag or rosbag2 directory) into the graph through the replay \
                 bridge: a node per topic, TF as RT edges"
            }
        }
    }
}

impl std::str::FromStr for Role {
    type Err = String;

    /// A role by its [`Role::name`], in any case.
    fn from_str(text: &str) -> Result<Role, String> {
        Role::ALL.into_iter().find(|role| role.name().eq_ignore_ascii_case(text)).ok_or_else(|| {
            let names: Vec<&str> = Role::ALL.iter().map(|role| role.name()).collect();
            format!("{text:?} is not a role ({})", names.join(", "))
        })
    }
}

/// Why a role could not be built.
#[derive(Debug, thiserror::Error)]
pub enum RoleError {
    /// The runtime refused a registration.
    #[error("building role `{role}`: {source}")]
    Bica {
        /// The role.
        role: &'static str,
        /// The runtime's error.
        source: BicaError,
    },
    /// The graph refused the perception names.
    #[error("building role `{role}`: {source}")]
    Graph {
        /// The role.
        role: &'static str,
        /// The graph's error.
        source: crate::graph::GraphError,
    },
}

fn prepare(role: &'static str, graph: &SharedGraph) -> Result<(), RoleError> {
    declare_perception_attrs(&mut *graph.borrow_mut()).map_err(|source| RoleError::Graph { role, source })
}

/// `camera-detector`: camera reader → colour labeller → blob detector (active), at `period_ms`.
///
/// # Errors
/// [`RoleError`] if a registration fails.
pub fn camera_detector<C: Clock>(
    runtime: &mut Runtime<C>,
    graph: SharedGraph,
    camera_node: &str,
    tables: LabelTables,
    blobs: BlobConfig,
    period_ms: u64,
) -> Result<(), RoleError> {
    let role = "camera-detector";
    prepare(role, &graph)?;
    let build = |runtime: &mut Runtime<C>| -> Result<(), BicaError> {
        runtime.register(CameraReader::new(graph.clone(), camera_node), ns_from_ms(period_ms))?;
        let labeller = runtime.register(ColourLabeller::new(tables), ns_from_ms(period_ms))?;
        let detector = runtime.register(BlobDetector::new(graph.clone(), blobs), ns_from_ms(period_ms))?;
        let mut collector = DebugCollector::new(10_000);
        collector.mark(labeller.id());
        collector.mark(detector.id());
        runtime.register(collector, ns_from_ms(period_ms.max(100)))?;
        runtime.activate::<BlobDetector>()?;
        runtime.activate::<DebugCollector>()
    };
    build(runtime).map_err(|source| RoleError::Bica { role, source })
}

/// `laser-detector`: laser reader → obstacle detector (active), at `period_ms`.
///
/// # Errors
/// [`RoleError`] if a registration fails.
pub fn laser_detector<C: Clock>(
    runtime: &mut Runtime<C>,
    graph: SharedGraph,
    laser_node: &str,
    config: ObstacleConfig,
    period_ms: u64,
) -> Result<(), RoleError> {
    let role = "laser-detector";
    prepare(role, &graph)?;
    let build = |runtime: &mut Runtime<C>| -> Result<(), BicaError> {
        runtime.register(LaserReader::new(graph.clone(), laser_node), ns_from_ms(period_ms))?;
        let detector = runtime.register(LaserObstacleDetector::new(graph.clone(), config), ns_from_ms(period_ms))?;
        let mut collector = DebugCollector::new(10_000);
        collector.mark(detector.id());
        runtime.register(collector, ns_from_ms(period_ms.max(100)))?;
        runtime.activate::<LaserObstacleDetector>()?;
        runtime.activate::<DebugCollector>()
    };
    build(runtime).map_err(|source| RoleError::Bica { role, source })
}

/// `attention`: the search/track behaviour (active) over attention, whose stimuli come from the graph's
/// detection nodes (the detectors run in other agents), the head and the scanner.
///
/// # Errors
/// [`RoleError`] if a registration fails.
pub fn attention<C: Clock>(
    runtime: &mut Runtime<C>,
    graph: SharedGraph,
    head_node: &str,
    stimulus: StimulusKind,
    period_ms: u64,
) -> Result<(), RoleError> {
    let role = "attention";
    prepare(role, &graph)?;
    let build = |runtime: &mut Runtime<C>| -> Result<(), BicaError> {
        runtime.register(GraphStimuli::new(graph.clone(), head_node), ns_from_ms(period_ms))?;
        let mut attention = Attention::new().with_source::<GraphStimuli>(StimulusKind::Obstacle);
        if stimulus != StimulusKind::Obstacle {
            attention = attention.with_source::<GraphStimuli>(stimulus);
        }
        let attention = runtime.register(attention, ns_from_ms(period_ms))?;
        let head = runtime.register(Head::new(graph.clone(), head_node), ns_from_ms(period_ms))?;
        runtime.register(Scanner::new(graph.clone(), head_node, 1.0, 0.1), ns_from_ms(period_ms))?;
        runtime.register(search_track(stimulus, 1, 1_000_000_000)?, ns_from_ms(period_ms))?;
        let mut collector = DebugCollector::new(1000);
        collector.mark(attention.id());
        collector.mark(head.id());
        runtime.register(collector, ns_from_ms(period_ms.max(100)))?;
        runtime.activate::<SearchTrackFsm>()?;
        runtime.activate::<DebugCollector>()
    };
    build(runtime).map_err(|source| RoleError::Bica { role, source })
}

#[cfg(test)]
mod tests {
    use super::Role;

    #[test]
    fn every_role_parses_from_its_name_in_any_case_and_others_are_refused() {
        for role in Role::ALL {
            assert_eq!(role.name().parse(), Ok(role));
            assert_eq!(role.name().to_uppercase().parse(), Ok(role));
        }
        let error = "painter".parse::<Role>().unwrap_err();
        assert!(error.contains("not a role") && error.contains("camera-detector, laser-detector"), "{error}");
    }
}
