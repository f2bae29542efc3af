//! A demo for `cortex inspect --demo`: the `camera-detector` role of [`perception::roles`] on a BICA runtime in
//! this process, fed with the three bundled EuRoC frames in turn (10 Hz), so the Debug view shows real primitives
//! (the labelled image, blob rectangles). The role runs on a private replica, so the demo needs no other agent (a
//! role on the shared graph is `cortex agent --role camera-detector`, shown with `cortex inspect --debug-agent N`);
//! each frame is also mirrored into the inspected agent's graph as the `cam_rgb` of a `camera` node called
//! `demo_cam0`, so the Tree view shows the picture changing at camera rate.

use std::sync::Arc;

use bica::prelude::*;
use dsr::{Element, NewNode, NodeId, Replica, ReplicaId, Value, attrs};
use perception::blobs::BlobConfig;
use perception::graph::{SharedGraph, share_replica};
use perception::labelling::{ColourClass, LabelConfig, LabelTables};
use perception::sensors::{Image, write_image};

use crate::debug::RuntimeDebug;
use crate::feed::{Edit, GraphFeed};

/// Period of the demo's camera and detector, ms.
pub const PERIOD_MS: u64 = 100;

/// Why the demo could not start.
#[derive(Debug, thiserror::Error)]
pub enum DemoError {
    /// The fixtures could not be read.
    #[error("demo: {0}")]
    Fixtures(#[from] perception::fixtures::FixtureError),
    /// The role or the runtime refused something.
    #[error("demo: {0}")]
    Build(String),
}

/// Writes the frames into the role's camera node (and mirrors them into the inspected graph) one per step.
struct FramePlayer {
    graph: SharedGraph,
    camera: NodeId,
    frames: Vec<Image>,
    next: usize,
    mirror: Option<(Arc<dyn GraphFeed>, NodeId)>,
}

impl Component for FramePlayer {
    fn step(&mut self, ctx: &mut StepContext<'_>) -> Result<(), BicaError> {
        let now = ctx.now_ns();
        let Some(frame) = self.frames.get(self.next % self.frames.len().max(1)) else { return Ok(()) };
        let sequence = self.next as u64;
        self.next += 1;
        if let Err(error) = write_image(&mut *self.graph.borrow_mut(), now, self.camera, frame, now, sequence) {
            tracing::warn!(%error, "demo: writing a frame into the role's graph");
        }
        if let Some((feed, node)) = &self.mirror {
            let size = |v: usize| Value::I32(i32::try_from(v).unwrap_or(i32::MAX));
            let attrs = vec![
                (attrs::CAM_RGB.name().to_owned(), Value::Bytes(frame.data.clone())),
                (attrs::CAM_RGB_WIDTH.name().to_owned(), size(frame.width)),
                (attrs::CAM_RGB_HEIGHT.name().to_owned(), size(frame.height)),
                (attrs::CAM_RGB_DEPTH.name().to_owned(), size(frame.encoding.channels())),
                (attrs::SEQUENCE.name().to_owned(), Value::U64(sequence)),
            ];
            if let Err(error) = feed.edit(Edit::SetAttrs { element: Element::Node(*node), attrs }) {
                tracing::warn!(%error, "demo: mirroring a frame into the inspected graph");
            }
        }
        Ok(())
    }
}

/// The running demo: stop it with [`Demo::stop`] (or drop it).
#[derive(Debug)]
pub struct Demo {
    driver: Option<Driver>,
}

impl Demo {
    /// Starts the camera-detector role on the bundled frames; mirrors frames into `mirror`'s graph if given.
    ///
    /// # Errors
    /// [`DemoError`] if the fixtures are missing or the role cannot be built.
    pub fn start(mirror: Option<Arc<dyn GraphFeed>>) -> Result<(Demo, RuntimeDebug), DemoError> {
        let frames = perception::fixtures::euroc_frames()?;
        let mirror = match mirror {
            Some(feed) => {
                let found = find_node(&*feed, "demo_cam0");
                let node = match found {
                    Some(id) => id,
                    None => {
                        match feed.edit(Edit::InsertNode { node_type: "camera".into(), name: "demo_cam0".into() }) {
                            Ok(crate::feed::EditOutcome::Node(id)) => id,
                            Ok(crate::feed::EditOutcome::Done) => {
                                return Err(DemoError::Build("inserting demo_cam0 returned no id".into()));
                            }
                            Err(e) => return Err(DemoError::Build(format!("inserting demo_cam0: {e}"))),
                        }
                    }
                };
                Some((feed, node))
            }
            None => None,
        };
        let driver = Driver::spawn(RuntimeConfig::default(), move |runtime| {
            let (_replica, graph) = share_replica(Replica::new(ReplicaId(4000)));
            let camera = graph
                .borrow_mut()
                .insert_node(0, NewNode::new("camera", "cam0"))
                .map_err(|e| BicaError::StepFailed { component: "demo".into(), message: e.to_string() })?;
            let tables = LabelTables::new(LabelConfig {
                classes: vec![ColourClass {
                    name: "bright".into(),
                    min: [200; 3],
                    max: [255; 3],
                    display: [255, 255, 0],
                }],
            })
            .map_err(|e| BicaError::StepFailed { component: "demo".into(), message: e.to_string() })?;
            let config = BlobConfig { min_area_px: 200, ..BlobConfig::default() };
            perception::roles::camera_detector(runtime, graph.clone(), "cam0", tables, config, PERIOD_MS)
                .map_err(|e| BicaError::StepFailed { component: "demo".into(), message: e.to_string() })?;
            runtime.register(FramePlayer { graph, camera, frames, next: 0, mirror }, PERIOD_MS * 1_000_000)?;
            runtime.activate::<FramePlayer>()
        })
        .map_err(|e| DemoError::Build(e.to_string()))?;
        let debug = RuntimeDebug::new(driver.remote());
        Ok((Demo { driver: Some(driver) }, debug))
    }

    /// Stops the runtime thread.
    pub fn stop(&mut self) {
        if let Some(driver) = self.driver.take()
            && let Err(error) = driver.stop()
        {
            tracing::warn!(%error, "demo: stopping the runtime");
        }
    }
}

impl Drop for Demo {
    fn drop(&mut self) {
        self.stop();
    }
}

fn find_node(feed: &dyn GraphFeed, name: &str) -> Option<NodeId> {
    let mut found = None;
    feed.read(&mut |r| found = r.node_by_name(name).map(|n| n.id()));
    found
}
