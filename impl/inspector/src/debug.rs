//! The Debug view's data: [`DebugSource`] lists a BICA runtime's components with their statistics, gives the
//! latest [`DebugFrame`] of its `DebugCollector` and marks components for debugging, through the runtime's
//! built-in named methods ([`bica::service`]), so nothing touches a component off the scheduler thread.
//! [`RuntimeDebug`] implements it for a runtime in this process (its request queue); [`RemoteDebug`] for the
//! runtime of another agent, such as a `cortex agent --role` process, called over the network. Frames go to the page as JSON with image primitives
//! replaced by a URL of the picture (served as BMP), so a camera-rate frame costs the page one small message.

use std::sync::Arc;
use std::time::Duration;

use agent::{Agent, AgentId};
use bica::debug::{DebugFrame, Shape};
use bica::remote::RemoteHandle;
use bica::service::{COMPONENTS, ComponentsReply, DEBUG_FRAME, SET_DEBUG, Service, ServiceBuilder, SetDebug};
use serde::Serialize;
use serde::de::DeserializeOwned;
use serde_json::{Value as Json, json};
use transport::Transport;

use crate::view::bmp;

/// How long a call into the runtime may take before the page is told it timed out.
pub const CALL_TIMEOUT: Duration = Duration::from_secs(2);

/// One component as the Debug view lists it.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ComponentInfo {
    /// Type name (the key for [`DebugSource::set_debug`]).
    pub name: String,
    /// Whether it is in the active list.
    pub active: bool,
    /// Whether it is marked for debugging.
    pub marked: bool,
    /// 1 / period.
    pub nominal_hz: f64,
    /// Achieved runs per second.
    pub achieved_hz: f64,
    /// Runs so far.
    pub runs: u64,
    /// Misses (lateness above tolerance).
    pub misses: u64,
    /// Releases skipped after overruns.
    pub skipped: u64,
}

/// Where the Debug view's data comes from.
pub trait DebugSource: Send + Sync + 'static {
    /// The components and their statistics.
    ///
    /// # Errors
    /// When the runtime cannot be reached.
    fn components(&self) -> Result<Vec<ComponentInfo>, String>;

    /// The latest frame of the debug collector.
    ///
    /// # Errors
    /// When the runtime cannot be reached or has no collector.
    fn latest_frame(&self) -> Result<DebugFrame, String>;

    /// Marks (`on`) or unmarks a component for debugging.
    ///
    /// # Errors
    /// When the component or the collector does not exist, or the runtime cannot be reached.
    fn set_debug(&self, component: &str, on: bool) -> Result<(), String>;
}

/// The Debug view's list from the reply of [`bica::service::COMPONENTS`].
pub fn component_infos(reply: ComponentsReply) -> Vec<ComponentInfo> {
    reply
        .statistics
        .components
        .into_iter()
        .map(|c| ComponentInfo {
            marked: reply.marked.contains(&c.name),
            name: c.name,
            active: c.active,
            nominal_hz: c.nominal_hz,
            achieved_hz: c.achieved_hz,
            runs: c.counters.runs,
            misses: c.counters.misses,
            skipped: c.counters.skipped_releases,
        })
        .collect()
}

/// A [`DebugSource`] for a BICA runtime in this process (e.g. one run by [`bica::runtime::Driver`]), through the
/// runtime's built-in named methods ([`bica::service`]) on its request queue.
#[derive(Clone, Debug)]
pub struct RuntimeDebug {
    service: Service,
}

impl RuntimeDebug {
    /// Reaches the runtime through `remote`.
    pub fn new(remote: RemoteHandle) -> Self {
        RuntimeDebug { service: ServiceBuilder::new().build(remote) }
    }

    fn call<Q: Serialize, R: DeserializeOwned>(&self, method: &str, request: &Q) -> Result<R, String> {
        self.service.call(method, request, CALL_TIMEOUT).map_err(|e| format!("debug source: {e}"))
    }
}

impl DebugSource for RuntimeDebug {
    fn components(&self) -> Result<Vec<ComponentInfo>, String> {
        self.call(COMPONENTS, &()).map(component_infos)
    }

    fn latest_frame(&self) -> Result<DebugFrame, String> {
        self.call(DEBUG_FRAME, &())
    }

    fn set_debug(&self, component: &str, on: bool) -> Result<(), String> {
        self.call(SET_DEBUG, &SetDebug { component: component.to_owned(), on })
    }
}

/// A [`DebugSource`] for the BICA runtime of another agent (a role process), called over the network through
/// the inspector's own agent ([`agent::Agent::call`] on the `Calls` channel).
pub struct RemoteDebug<T: Transport + 'static> {
    agent: Arc<Agent<T>>,
    target: AgentId,
}

impl<T: Transport + 'static> std::fmt::Debug for RemoteDebug<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RemoteDebug").field("agent", &self.agent.id()).field("target", &self.target).finish()
    }
}

impl<T: Transport + 'static> RemoteDebug<T> {
    /// Calls the runtime of agent `target` through `agent`.
    pub fn new(agent: Arc<Agent<T>>, target: AgentId) -> Self {
        RemoteDebug { agent, target }
    }

    fn call<Q: Serialize, R: DeserializeOwned>(&self, method: &str, request: &Q) -> Result<R, String> {
        self.agent.call(self.target, method, request, CALL_TIMEOUT).map_err(|e| format!("debug source: {e}"))
    }
}

impl<T: Transport + 'static> DebugSource for RemoteDebug<T> {
    fn components(&self) -> Result<Vec<ComponentInfo>, String> {
        self.call(COMPONENTS, &()).map(component_infos)
    }

    fn latest_frame(&self) -> Result<DebugFrame, String> {
        self.call(DEBUG_FRAME, &())
    }

    fn set_debug(&self, component: &str, on: bool) -> Result<(), String> {
        self.call(SET_DEBUG, &SetDebug { component: component.to_owned(), on })
    }
}

/// A frame for the page: primitives as serde gives them, except that an image's pixels are replaced by
/// `{"url": ...}` (the picture is at `/api/debug/image?i=INDEX&at=AT_NS`).
pub fn frame_json(frame: &DebugFrame) -> Json {
    let entries: Vec<Json> = frame
        .entries
        .iter()
        .enumerate()
        .map(|(index, entry)| {
            let primitive = match &entry.primitive.shape {
                Shape::Image { top_left, width_px, height_px, .. } => json!({
                    "frame": entry.primitive.frame,
                    "color": entry.primitive.color,
                    "shape": {"Image": {
                        "top_left": top_left,
                        "width_px": width_px,
                        "height_px": height_px,
                        "url": format!("/api/debug/image?i={index}&at={}", frame.at_ns),
                    }},
                }),
                _ => serde_json::to_value(&entry.primitive).unwrap_or(Json::Null),
            };
            json!({"component": entry.component, "primitive": primitive})
        })
        .collect();
    json!({"at_ns": frame.at_ns, "dropped": frame.dropped, "entries": entries})
}

/// The picture of entry `index` of `frame` as a BMP.
///
/// # Errors
/// When the entry does not exist or is not an image.
pub fn frame_image(frame: &DebugFrame, index: usize) -> Result<Vec<u8>, String> {
    match frame.entries.get(index).map(|e| &e.primitive.shape) {
        Some(Shape::Image { width_px, height_px, rgb8, .. }) => {
            bmp(*width_px as usize, *height_px as usize, 3, false, rgb8)
        }
        Some(_) => Err(format!("debug entry {index} is not an image")),
        None => Err(format!("the latest debug frame has no entry {index}")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use agent::AgentConfig;
    use bica::debug::{DebugCollector, DebugPrimitive, Debuggable, Frame, Point2, Rgba};
    use bica::prelude::*;
    use transport::SystemClock;
    use transport::inproc::Bus;

    /// A component drawing one point.
    struct Dot;

    impl Component for Dot {
        fn step(&mut self, _: &mut StepContext<'_>) -> Result<(), BicaError> {
            Ok(())
        }
        fn as_debuggable(&self) -> Option<&dyn Debuggable> {
            Some(self)
        }
    }

    impl Debuggable for Dot {
        fn debug_primitives(&self, out: &mut Vec<DebugPrimitive>) {
            let at = Point2 { x: 3.0, y: 4.0 };
            out.push(DebugPrimitive::new(Frame::Image, Shape::Point { at }, Rgba { r: 1, g: 2, b: 3, a: 255 }));
        }
    }

    fn driver() -> Driver {
        Driver::spawn(RuntimeConfig::default(), |runtime| {
            runtime.register(Dot, 5_000_000)?;
            runtime.register(DebugCollector::new(10), 5_000_000)?;
            runtime.activate::<Dot>()?;
            runtime.activate::<DebugCollector>()
        })
        .unwrap()
    }

    /// Marks `Dot` and waits (bounded) until the collector's frame shows its point.
    fn exercise(source: &dyn DebugSource) {
        let dot = std::any::type_name::<Dot>();
        let listed = source.components().unwrap();
        assert_eq!(listed.len(), 2);
        assert!(listed.iter().all(|c| !c.marked));
        assert_eq!(listed[0].name, dot);
        assert_eq!(listed[0].nominal_hz, 200.0);
        source.set_debug(dot, true).unwrap();
        assert!(source.components().unwrap()[0].marked);
        let deadline = std::time::Instant::now() + Duration::from_secs(10);
        let frame = loop {
            let frame = source.latest_frame().unwrap();
            if !frame.entries.is_empty() || std::time::Instant::now() > deadline {
                break frame;
            }
            std::thread::sleep(Duration::from_millis(10));
        };
        assert_eq!(frame.entries.len(), 1);
        assert_eq!(frame.entries[0].component, dot);
        assert!(matches!(frame.entries[0].primitive.shape, Shape::Point { at } if at.x == 3.0 && at.y == 4.0));
        let error = source.set_debug("Nope", true).unwrap_err();
        assert!(error.contains("no component called `Nope`"), "{error}");
        source.set_debug(dot, false).unwrap();
        assert!(!source.components().unwrap()[0].marked);
    }

    #[test]
    fn an_in_process_runtime_lists_marks_and_draws() {
        let driver = driver();
        exercise(&RuntimeDebug::new(driver.remote()));
        driver.stop().unwrap();
    }

    #[test]
    fn another_agents_runtime_lists_marks_and_draws_through_calls() {
        let bus = Bus::new();
        let agent = |id: u32| {
            // Both start alone at once: one graph, named (each would otherwise create its own).
            let config = AgentConfig {
                join_wait: Duration::from_millis(50),
                graph: agent::GraphId::new(0x1d),
                ..AgentConfig::new(AgentId(id))
            };
            Arc::new(Agent::start(config, bus.attach(1024), Arc::new(SystemClock)).unwrap())
        };
        let (inspector, role, plain) = (agent(1), agent(2), agent(3));
        let driver = driver();
        role.serve_calls(Arc::new(ServiceBuilder::new().build(driver.remote())));
        exercise(&RemoteDebug::new(Arc::clone(&inspector), AgentId(2)));
        let error = RemoteDebug::new(Arc::clone(&inspector), AgentId(3)).components().unwrap_err();
        assert_eq!(
            error,
            "debug source: call `runtime.components` to agent 3: no runtime: agent 3 serves no remote calls"
        );
        driver.stop().unwrap();
        for agent in [inspector, role, plain] {
            agent.shutdown();
        }
    }
}
