//! Attention and the head.
//!
//! Behaviour components state their perceptual requirements ([`Attention::require`]: which stimulus kind they
//! need, with a priority). Each step, [`Attention`] steps the detector in charge of each required kind (its
//! *sources*, registered with [`Attention::with_source`]), asks it for its stimuli, and picks the one that
//! governs attention by these rules:
//!
//! 1. only stimuli of a required kind are candidates;
//! 2. the kind with the highest requirement priority that has a stimulus wins; equal priorities go to the kind
//!    required first;
//! 3. within that kind, the stimulus attended in the previous step is kept while it exists (no flicker);
//!    otherwise the most salient one (largest blob, nearest obstacle), ties to the lowest track id.
//!
//! When there is a target, Attention sends its 3-D point to the [`Head`] and steps it; the head writes the gaze
//! target into the graph as a `gaze_target` node under the head node (RT translation = the point in the head's
//! frame, mm). Without a target Attention leaves the head alone (a [`Scanner`] may drive it).

use bica::debug::{DebugPrimitive, Debuggable, Frame, Point2, Rgba, Shape};
use bica::prelude::*;
use dsr::{NewNode, NodeId};

use crate::blobs::BlobDetector;
use crate::graph::{SharedGraph, attrs};
use crate::obstacles::{ClusterSource, ObstacleDetector};

/// A kind of stimulus a behaviour can require.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum StimulusKind {
    /// A blob of a colour class.
    Blob {
        /// Class index.
        class: u32,
    },
    /// An obstacle.
    Obstacle,
}

/// One candidate target.
#[derive(Debug, Clone, PartialEq)]
pub struct Stimulus {
    /// Its kind.
    pub kind: StimulusKind,
    /// Track id in its detector (or node id for graph stimuli).
    pub track_id: u64,
    /// The node whose frame `point_mm` is in.
    pub frame: NodeId,
    /// The 3-D point, mm.
    pub point_mm: [f64; 3],
    /// Larger is more salient.
    pub salience: f64,
}

/// A component that can report stimuli (a detector in charge of some kinds).
pub trait StimulusSource {
    /// The current stimuli of `kind` (empty if it has none or is not in charge of that kind).
    fn stimuli(&self, kind: StimulusKind) -> Vec<Stimulus>;
}

impl StimulusSource for BlobDetector {
    fn stimuli(&self, kind: StimulusKind) -> Vec<Stimulus> {
        let StimulusKind::Blob { class } = kind else { return Vec::new() };
        let Some(nodes) = self.track_nodes() else { return Vec::new() };
        self.tracker()
            .confirmed()
            .filter(|t| t.tag == class)
            .filter_map(|t| {
                // The point is the blob node's origin; the head maps it through the graph.
                let node = *nodes.nodes().get(&t.id)?;
                let salience = f64::from(self.track_area(t.id).unwrap_or(0));
                Some(Stimulus { kind, track_id: t.id, frame: node, point_mm: [0.0; 3], salience })
            })
            .collect()
    }
}

impl<S: ClusterSource> StimulusSource for ObstacleDetector<S> {
    fn stimuli(&self, kind: StimulusKind) -> Vec<Stimulus> {
        if kind != StimulusKind::Obstacle {
            return Vec::new();
        }
        let Some(nodes) = self.track_nodes() else { return Vec::new() };
        self.tracker()
            .confirmed()
            .filter_map(|t| {
                let node = *nodes.nodes().get(&t.id)?;
                let [x, y] = t.filter.position_mm();
                Some(Stimulus { kind, track_id: t.id, frame: node, point_mm: [0.0; 3], salience: -x.hypot(y) })
            })
            .collect()
    }
}

/// Stimuli read from the graph's `blob` and `obstacle` nodes, for an attention agent whose detectors run in
/// other agents. Salience: a blob's `blob_area_px`; an obstacle's negated distance to the `reference` node.
#[derive(Debug)]
pub struct GraphStimuli {
    graph: SharedGraph,
    reference: String,
    blobs: Vec<Stimulus>,
    obstacles: Vec<Stimulus>,
}

impl GraphStimuli {
    /// Reads detection nodes, measuring obstacle distances from the node called `reference` (e.g. the head).
    pub fn new(graph: SharedGraph, reference: impl Into<String>) -> Self {
        Self { graph, reference: reference.into(), blobs: Vec::new(), obstacles: Vec::new() }
    }
}

impl Component for GraphStimuli {
    fn step(&mut self, _ctx: &mut StepContext<'_>) -> Result<(), BicaError> {
        let graph = self.graph.borrow();
        let reference = graph.find_node(&self.reference);
        self.blobs = graph
            .nodes_of_type("blob")
            .into_iter()
            .filter_map(|(node, _)| {
                let class = graph.get(node, attrs::BLOB_CLASS)?;
                let area = graph.get(node, attrs::BLOB_AREA_PX).unwrap_or(0);
                Some(Stimulus {
                    kind: StimulusKind::Blob { class },
                    track_id: node.0,
                    frame: node,
                    point_mm: [0.0; 3],
                    salience: f64::from(area),
                })
            })
            .collect();
        self.obstacles = graph
            .nodes_of_type("obstacle")
            .into_iter()
            .filter_map(|(node, _)| {
                let p = graph.transform_point(node, reference?, [0.0; 3]).ok()?;
                let distance = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
                Some(Stimulus {
                    kind: StimulusKind::Obstacle,
                    track_id: node.0,
                    frame: node,
                    point_mm: [0.0; 3],
                    salience: -distance,
                })
            })
            .collect();
        Ok(())
    }
}

impl StimulusSource for GraphStimuli {
    fn stimuli(&self, kind: StimulusKind) -> Vec<Stimulus> {
        let list = match kind {
            StimulusKind::Obstacle => &self.obstacles,
            StimulusKind::Blob { .. } => &self.blobs,
        };
        list.iter().filter(|s| s.kind == kind).cloned().collect()
    }
}

type Query = fn(&mut StepContext<'_>, StimulusKind) -> Result<Vec<Stimulus>, BicaError>;

fn query<T: Component + StimulusSource>(
    ctx: &mut StepContext<'_>,
    kind: StimulusKind,
) -> Result<Vec<Stimulus>, BicaError> {
    ctx.step::<T>()?;
    Ok(ctx.get::<T>()?.stimuli(kind))
}

/// A behaviour's perceptual requirement.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Requirement {
    /// Who needs it.
    pub requester: &'static str,
    /// What it needs.
    pub kind: StimulusKind,
    /// Higher wins.
    pub priority: u8,
}

/// The attention component (rules in the module docs).
pub struct Attention {
    sources: Vec<(StimulusKind, Query, &'static str)>,
    requirements: Vec<Requirement>,
    target: Option<Stimulus>,
    steps_without_target: u64,
}

impl std::fmt::Debug for Attention {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Attention")
            .field("sources", &self.sources.iter().map(|s| (s.0, s.2)).collect::<Vec<_>>())
            .field("requirements", &self.requirements)
            .field("target", &self.target)
            .finish_non_exhaustive()
    }
}

impl Default for Attention {
    fn default() -> Self {
        Self::new()
    }
}

impl Attention {
    /// Attention with no sources and no requirements.
    pub fn new() -> Self {
        Self { sources: Vec::new(), requirements: Vec::new(), target: None, steps_without_target: 0 }
    }

    /// Puts component `T` in charge of stimuli of `kind`.
    pub fn with_source<T: Component + StimulusSource>(mut self, kind: StimulusKind) -> Self {
        self.sources.push((kind, query::<T>, std::any::type_name::<T>()));
        self
    }

    /// States (or updates) `requester`'s need for `kind`.
    pub fn require(&mut self, requester: &'static str, kind: StimulusKind, priority: u8) {
        match self.requirements.iter_mut().find(|r| r.requester == requester && r.kind == kind) {
            Some(existing) => existing.priority = priority,
            None => self.requirements.push(Requirement { requester, kind, priority }),
        }
    }

    /// Withdraws all of `requester`'s requirements.
    pub fn release(&mut self, requester: &'static str) {
        self.requirements.retain(|r| r.requester != requester);
    }

    /// The current requirements, in the order they were first stated.
    pub fn requirements(&self) -> &[Requirement] {
        &self.requirements
    }

    /// The stimulus that governs attention now.
    pub fn target(&self) -> Option<&Stimulus> {
        self.target.as_ref()
    }

    /// Consecutive steps without a target.
    pub fn steps_without_target(&self) -> u64 {
        self.steps_without_target
    }

    /// Applies rules 2 and 3 to the stimuli found for each required kind (`found` in requirement order).
    pub fn choose(&self, found: &[(Requirement, Vec<Stimulus>)]) -> Option<Stimulus> {
        let mut best: Option<&(Requirement, Vec<Stimulus>)> = None;
        for entry in found.iter().filter(|(_, s)| !s.is_empty()) {
            if best.is_none_or(|b| entry.0.priority > b.0.priority) {
                best = Some(entry);
            }
        }
        let (_, stimuli) = best?;
        if let Some(previous) = &self.target
            && let Some(same) = stimuli.iter().find(|s| s.kind == previous.kind && s.track_id == previous.track_id)
        {
            return Some(same.clone());
        }
        stimuli.iter().max_by(|a, b| a.salience.total_cmp(&b.salience).then(b.track_id.cmp(&a.track_id))).cloned()
    }
}

impl Component for Attention {
    fn step(&mut self, ctx: &mut StepContext<'_>) -> Result<(), BicaError> {
        let mut found: Vec<(Requirement, Vec<Stimulus>)> = Vec::new();
        let mut kinds: Vec<StimulusKind> = Vec::new();
        for requirement in &self.requirements {
            // One entry per kind: its highest priority, at its first position.
            if let Some(entry) = found.iter_mut().find(|(r, _)| r.kind == requirement.kind) {
                entry.0.priority = entry.0.priority.max(requirement.priority);
                continue;
            }
            found.push((requirement.clone(), Vec::new()));
            kinds.push(requirement.kind);
        }
        for (index, kind) in kinds.iter().enumerate() {
            for (source_kind, query, _) in &self.sources {
                if source_kind == kind {
                    let stimuli = query(ctx, *kind)?;
                    found[index].1.extend(stimuli);
                }
            }
        }
        self.target = self.choose(&found);
        match &self.target {
            Some(target) => {
                self.steps_without_target = 0;
                if ctx.registry().contains::<Head>() {
                    ctx.get_mut::<Head>()?
                        .set_target(Some(GazeTarget { frame: target.frame, point_mm: target.point_mm }));
                    ctx.step::<Head>()?;
                }
            }
            None => self.steps_without_target += 1,
        }
        Ok(())
    }

    fn as_debuggable(&self) -> Option<&dyn Debuggable> {
        Some(self)
    }
}

/// Draws the attention target as text (its kind and track).
impl Debuggable for Attention {
    fn debug_primitives(&self, out: &mut Vec<DebugPrimitive>) {
        let Some(target) = &self.target else { return };
        let text = format!("attention: {:?} #{}", target.kind, target.track_id);
        let colour = Rgba { r: 255, g: 0, b: 255, a: 255 };
        out.push(DebugPrimitive::new(Frame::Robot, Shape::Text { at: Point2 { x: 0.0, y: 0.0 }, text }, colour));
    }
}

/// Where to look: a point (mm) in some node's frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GazeTarget {
    /// The frame.
    pub frame: NodeId,
    /// The point, mm.
    pub point_mm: [f64; 3],
}

/// The head: writes its modulated gaze target into the graph as node `gaze_target` (type `gaze_target`) under the
/// head node, translated to the target expressed in the head's frame (mm).
#[derive(Debug)]
pub struct Head {
    graph: SharedGraph,
    head_name: String,
    target: Option<GazeTarget>,
    written_mm: Option<[f64; 3]>,
    gaze_node: Option<NodeId>,
}

impl Head {
    /// A head whose node is called `head_name`.
    pub fn new(graph: SharedGraph, head_name: impl Into<String>) -> Self {
        Self { graph, head_name: head_name.into(), target: None, written_mm: None, gaze_node: None }
    }

    /// Modulation: where to look.
    pub fn set_target(&mut self, target: Option<GazeTarget>) {
        self.target = target;
    }

    /// The last target written, in the head's frame, mm.
    pub fn written_mm(&self) -> Option<[f64; 3]> {
        self.written_mm
    }
}

impl Component for Head {
    fn step(&mut self, ctx: &mut StepContext<'_>) -> Result<(), BicaError> {
        let Some(target) = self.target else { return Ok(()) };
        let mut graph = self.graph.borrow_mut();
        let Some(head) = graph.find_node(&self.head_name) else {
            tracing::warn!(head = %self.head_name, "no head node; gaze target not written");
            return Ok(());
        };
        let point = match graph.transform_point(target.frame, head, target.point_mm) {
            Ok(point) => point,
            Err(error) => {
                tracing::warn!(%error, "cannot express the gaze target in the head's frame");
                return Ok(());
            }
        };
        let now_ns = ctx.now_ns();
        let gaze =
            match self.gaze_node.filter(|n| graph.node_type(*n).is_some()).or_else(|| graph.find_node("gaze_target")) {
                Some(node) => node,
                None => match graph.insert_node(now_ns, NewNode::new("gaze_target", "gaze_target")) {
                    Ok(node) => node,
                    Err(error) => {
                        tracing::warn!(%error, "cannot insert the gaze target node");
                        return Ok(());
                    }
                },
            };
        self.gaze_node = Some(gaze);
        match graph.set_rt(now_ns, head, gaze, point.map(|v| v as f32), [0.0; 3]) {
            Ok(()) => self.written_mm = Some(point),
            Err(error) => tracing::warn!(%error, "cannot place the gaze target"),
        }
        Ok(())
    }

    fn as_debuggable(&self) -> Option<&dyn Debuggable> {
        Some(self)
    }
}

/// Draws the gaze target (robot frame, metres, head taken at the origin) as an arrow from the head.
impl Debuggable for Head {
    fn debug_primitives(&self, out: &mut Vec<DebugPrimitive>) {
        let Some(p) = self.written_mm else { return };
        let to = Point2 { x: p[0] / 1000.0, y: p[1] / 1000.0 };
        let colour = Rgba { r: 0, g: 160, b: 255, a: 255 };
        out.push(DebugPrimitive::new(Frame::Robot, Shape::Arrow { from: Point2 { x: 0.0, y: 0.0 }, to }, colour));
    }
}

/// Sweeps the head's gaze left and right (a point 1 m ahead, pan ±`amplitude_rad`, one step of `step_rad` per
/// run) while searching.
#[derive(Debug)]
pub struct Scanner {
    head_name: String,
    graph: SharedGraph,
    pan_rad: f64,
    step_rad: f64,
    amplitude_rad: f64,
    runs: u64,
}

impl Scanner {
    /// A scanner of the head node `head_name`.
    pub fn new(graph: SharedGraph, head_name: impl Into<String>, amplitude_rad: f64, step_rad: f64) -> Self {
        Self { head_name: head_name.into(), graph, pan_rad: 0.0, step_rad, amplitude_rad, runs: 0 }
    }

    /// Times it has run.
    pub fn runs(&self) -> u64 {
        self.runs
    }
}

impl Component for Scanner {
    fn step(&mut self, ctx: &mut StepContext<'_>) -> Result<(), BicaError> {
        self.runs += 1;
        self.pan_rad += self.step_rad;
        if self.pan_rad.abs() > self.amplitude_rad {
            self.step_rad = -self.step_rad;
            self.pan_rad = self.pan_rad.clamp(-self.amplitude_rad, self.amplitude_rad);
        }
        let head = self.graph.borrow().find_node(&self.head_name);
        let Some(head) = head else { return Ok(()) };
        let point_mm = [1000.0 * self.pan_rad.cos(), 1000.0 * self.pan_rad.sin(), 0.0];
        ctx.get_mut::<Head>()?.set_target(Some(GazeTarget { frame: head, point_mm }));
        ctx.step::<Head>()?;
        Ok(())
    }
}
