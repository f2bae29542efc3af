//! The Debug view's data: [`DebugSource`] lists a BICA runtime's components with their statistics, gives the
//! latest [`DebugFrame`] of its [`DebugCollector`] and marks components for debugging. [`RuntimeDebug`]
//! implements it for a runtime in this process through its remote-call queue ([`bica::remote::RemoteHandle`]),
//! so nothing touches a component off the scheduler thread. Frames go to the page as JSON with image primitives
//! replaced by a URL of the picture (served as BMP), so a camera-rate frame costs the page one small message.

use std::time::{Duration, Instant};

use bica::debug::{DebugCollector, DebugFrame, Shape};
use bica::remote::{Control, RemoteHandle};
use serde::Serialize;
use serde_json::{Value as Json, json};

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

/// A [`DebugSource`] for a BICA runtime in this process (e.g. one run by [`bica::runtime::Driver`]).
#[derive(Clone, Debug)]
pub struct RuntimeDebug {
    remote: RemoteHandle,
}

impl RuntimeDebug {
    /// Reaches the runtime through `remote`.
    pub fn new(remote: RemoteHandle) -> Self {
        RuntimeDebug { remote }
    }

    fn call<R: Send + 'static>(&self, f: impl FnOnce(&mut Control<'_>) -> R + Send + 'static) -> Result<R, String> {
        let pending = self.remote.submit(f).map_err(|e| format!("debug source: {e}"))?;
        let deadline = Instant::now() + CALL_TIMEOUT;
        loop {
            if let Some(reply) = pending.try_take() {
                return Ok(reply);
            }
            if Instant::now() >= deadline {
                return Err(format!("debug source: the runtime did not answer within {CALL_TIMEOUT:?}"));
            }
            std::thread::sleep(Duration::from_millis(2));
        }
    }
}

impl DebugSource for RuntimeDebug {
    fn components(&self) -> Result<Vec<ComponentInfo>, String> {
        self.call(|control| {
            let marked: Vec<u32> =
                control.get::<DebugCollector>().map(|c| c.marked().iter().map(|id| id.0).collect()).unwrap_or_default();
            control
                .statistics()
                .components
                .into_iter()
                .enumerate()
                .map(|(index, c)| ComponentInfo {
                    marked: marked.iter().any(|&m| m as usize == index),
                    name: c.name,
                    active: c.active,
                    nominal_hz: c.nominal_hz,
                    achieved_hz: c.achieved_hz,
                    runs: c.counters.runs,
                    misses: c.counters.misses,
                    skipped: c.counters.skipped_releases,
                })
                .collect()
        })
    }

    fn latest_frame(&self) -> Result<DebugFrame, String> {
        self.call(|control| control.get::<DebugCollector>().map(|c| c.latest().clone()).map_err(|e| e.to_string()))?
            .map_err(|e| format!("debug source: {e}"))
    }

    fn set_debug(&self, component: &str, on: bool) -> Result<(), String> {
        let name = component.to_owned();
        self.call(move |control| {
            let index = control
                .statistics()
                .components
                .iter()
                .position(|c| c.name == name)
                .ok_or_else(|| format!("no component called `{name}`"))?;
            let id = bica::core::ComponentId(u32::try_from(index).map_err(|_| "component index overflow".to_owned())?);
            let collector = control.get_mut::<DebugCollector>().map_err(|e| e.to_string())?;
            if on {
                collector.mark(id);
            } else {
                collector.unmark(id);
            }
            Ok(())
        })?
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
