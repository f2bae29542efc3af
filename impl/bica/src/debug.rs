//! Debugging a running tree: a [`DebugCollector`] component gathers the debug primitives (points, lines, arrows,
//! circles, ellipses, rectangles, boxes, text and images in image, robot-relative or world coordinates; defined in
//! [`crate::debug_primitives`] and re-exported here) from the components marked for debugging into a bounded
//! [`DebugFrame`]. Everything serializes with serde, so a remote viewer can draw it.

use crate::component::{Component, StepContext};
use crate::component_id::ComponentId;
pub use crate::debug_primitives::{
    DebugEntry, DebugFrame, DebugPrimitive, Debuggable, Frame, MAX_IMAGE_BYTES, Point2, Rgba, Shape,
};
use crate::error::BicaError;

/// Component that gathers primitives from the components marked for debugging. It reads
/// their latest results; it does not step them.
///
/// ```
/// use bica::prelude::*;
/// use bica::debug::*;
///
/// struct Ball;
/// impl Component for Ball {
///     fn step(&mut self, _: &mut StepContext<'_>) -> Result<(), BicaError> { Ok(()) }
///     fn as_debuggable(&self) -> Option<&dyn Debuggable> { Some(self) }
/// }
/// impl Debuggable for Ball {
///     fn debug_primitives(&self, out: &mut Vec<DebugPrimitive>) {
///         let red = Rgba { r: 255, g: 0, b: 0, a: 255 };
///         out.push(DebugPrimitive::new(Frame::World, Shape::Circle { center: Point2 { x: 1.0, y: 2.0 }, radius: 0.1 }, red));
///     }
/// }
///
/// let mut runtime = Runtime::new(RuntimeConfig::default(), VirtualClock::new(0));
/// let ball = runtime.register(Ball, 10_000_000).unwrap();
/// let mut collector = DebugCollector::new(100);
/// collector.mark(ball.id());
/// runtime.register(collector, 10_000_000).unwrap();
/// runtime.activate::<DebugCollector>().unwrap();
/// runtime.run_until(1).unwrap();
/// let frame = runtime.registry().get::<DebugCollector>().unwrap().latest();
/// assert_eq!(frame.entries.len(), 1);
/// assert!(serde_json::to_string(frame).unwrap().contains("Circle"));
/// ```
#[derive(Debug, Clone)]
pub struct DebugCollector {
    marked: Vec<ComponentId>,
    max_primitives: usize,
    latest: DebugFrame,
    scratch: Vec<DebugPrimitive>,
}

impl DebugCollector {
    /// A collector keeping at most `max_primitives` primitives per frame.
    pub fn new(max_primitives: usize) -> Self {
        Self { marked: Vec::new(), max_primitives, latest: DebugFrame::default(), scratch: Vec::new() }
    }

    /// Marks a component for debugging (idempotent).
    pub fn mark(&mut self, id: ComponentId) {
        if !self.marked.contains(&id) {
            self.marked.push(id);
        }
    }

    /// Unmarks a component.
    pub fn unmark(&mut self, id: ComponentId) {
        self.marked.retain(|&m| m != id);
    }

    /// The components marked for debugging.
    pub fn marked(&self) -> &[ComponentId] {
        &self.marked
    }

    /// The most recently gathered frame.
    pub fn latest(&self) -> &DebugFrame {
        &self.latest
    }
}

impl Component for DebugCollector {
    fn step(&mut self, ctx: &mut StepContext<'_>) -> Result<(), BicaError> {
        let mut frame = DebugFrame { at_ns: ctx.now_ns(), entries: Vec::new(), dropped: 0 };
        for &id in &self.marked {
            let component = ctx.registry().dyn_ref(id)?;
            let Some(debuggable) = component.as_debuggable() else { continue };
            self.scratch.clear();
            debuggable.debug_primitives(&mut self.scratch);
            let name = ctx.registry().name(id)?;
            for primitive in self.scratch.drain(..) {
                if frame.entries.len() < self.max_primitives {
                    frame.entries.push(DebugEntry { component: name.to_owned(), primitive });
                } else {
                    frame.dropped += 1;
                }
            }
        }
        self.latest = frame;
        Ok(())
    }
}
