//! Named remote methods of a runtime: a typed, serializable call surface over [`RemoteHandle`], so another
//! thread — or another process, through an agent's `Calls` channel — can call components by name with bytes.
//!
//! A [`Service`] is a fixed table of methods built once with a [`ServiceBuilder`]. Each method decodes its
//! request from `postcard` bytes, runs on the scheduler thread between two steps (as a closure queued on the
//! runtime's bounded request queue, so the step path takes no lock), and encodes its response with `postcard`.
//! [`Service::dispatch`] never blocks: it queues the work and the reply arrives later through a callback, which
//! runs on the scheduler thread and must not block either. Every builder starts with the built-in methods
//! [`COMPONENTS`], [`DEBUG_FRAME`], [`SET_DEBUG`] and [`METHODS`]; users add component methods with
//! [`ServiceBuilder::method`] under names like `"BlobDetector.set_min_area"`.
//!
//! ```
//! use bica::prelude::*;
//! use bica::service::{ServiceBuilder, ServiceError};
//!
//! #[derive(Default)]
//! struct Walk { speed: f64 }
//! impl Component for Walk {
//!     fn step(&mut self, _: &mut StepContext<'_>) -> Result<(), BicaError> { Ok(()) }
//! }
//!
//! let mut runtime = Runtime::new(RuntimeConfig::default(), VirtualClock::new(0));
//! runtime.register(Walk::default(), 10_000_000).unwrap();
//! let service = ServiceBuilder::new()
//!     .method("Walk.set_speed", |walk: &mut Walk, speed: f64| { walk.speed = speed; })
//!     .build(runtime.remote());
//! let (tx, rx) = std::sync::mpsc::channel();
//! let request = postcard::to_allocvec(&1.5f64).unwrap();
//! service.dispatch("Walk.set_speed", request, move |reply| tx.send(reply).unwrap());
//! runtime.serve_requests(); // the scheduler thread serves it between steps
//! assert_eq!(rx.recv().unwrap(), Ok(Vec::new())); // `()` encodes as no bytes
//! assert_eq!(runtime.registry().get::<Walk>().unwrap().speed, 1.5);
//!
//! let (tx, rx) = std::sync::mpsc::channel();
//! service.dispatch("Walk.fly", Vec::new(), move |reply| tx.send(reply).unwrap());
//! assert!(matches!(rx.recv().unwrap(), Err(ServiceError::UnknownMethod { .. })));
//! ```

use std::collections::BTreeMap;
use std::sync::Arc;

use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};

use crate::component::Component;
use crate::component_id::ComponentId;
use crate::debug::DebugCollector;
use crate::error::BicaError;
use crate::remote::{Control, RemoteHandle};
use crate::stats::StatisticsReport;

/// Built-in method: `()` → [`ComponentsReply`] (every component with its statistics and debug mark).
pub const COMPONENTS: &str = "runtime.components";
/// Built-in method: `()` → [`DebugFrame`](crate::debug::DebugFrame) (the latest frame of the runtime's [`DebugCollector`]).
pub const DEBUG_FRAME: &str = "runtime.debug_frame";
/// Built-in method: [`SetDebug`] → `()` (mark or unmark a component, by type name, for debugging).
pub const SET_DEBUG: &str = "runtime.set_debug";
/// Built-in method: `()` → `Vec<String>` (the names of every method of the service).
pub const METHODS: &str = "runtime.methods";

/// Why a call could not give a response. Messages say which method and what went wrong.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error, Serialize, Deserialize)]
pub enum ServiceError {
    /// No method of that name.
    #[error("unknown method `{method}`")]
    UnknownMethod {
        /// The name asked for.
        method: String,
    },
    /// The request bytes do not decode as the method's request type.
    #[error("bad request for `{method}`: {detail}")]
    BadRequest {
        /// The method.
        method: String,
        /// What the decoder said.
        detail: String,
    },
    /// The method ran and failed (e.g. its component is not registered).
    #[error("`{method}` failed: {detail}")]
    Failed {
        /// The method.
        method: String,
        /// Why.
        detail: String,
    },
    /// The runtime's request queue is full; nothing was run.
    #[error("`{method}` refused: {detail}")]
    Busy {
        /// The method.
        method: String,
        /// The queue's error.
        detail: String,
    },
    /// The runtime has stopped.
    #[error("`{method}`: the runtime has stopped")]
    Stopped {
        /// The method.
        method: String,
    },
}

/// One component as [`COMPONENTS`] lists it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ComponentsReply {
    /// Statistics of every registered component, in id order.
    pub statistics: StatisticsReport,
    /// Type names of the components marked for debugging (empty without a [`DebugCollector`]).
    pub marked: Vec<String>,
}

/// The request of [`SET_DEBUG`].
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct SetDebug {
    /// Type name of the component, as [`COMPONENTS`] lists it.
    pub component: String,
    /// Mark (`true`) or unmark.
    pub on: bool,
}

type Method = Arc<dyn Fn(&mut Control<'_>, &[u8]) -> Result<Vec<u8>, ServiceError> + Send + Sync>;

/// Builds the method table of a [`Service`].
pub struct ServiceBuilder {
    methods: BTreeMap<String, Method>,
}

impl std::fmt::Debug for ServiceBuilder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ServiceBuilder").field("methods", &self.methods.keys().collect::<Vec<_>>()).finish()
    }
}

impl Default for ServiceBuilder {
    fn default() -> Self {
        Self::new()
    }
}

fn encode<R: Serialize>(method: &str, response: &R) -> Result<Vec<u8>, ServiceError> {
    postcard::to_allocvec(response)
        .map_err(|e| ServiceError::Failed { method: method.to_owned(), detail: format!("encoding the response: {e}") })
}

fn decode<Q: DeserializeOwned>(method: &str, bytes: &[u8]) -> Result<Q, ServiceError> {
    match postcard::take_from_bytes::<Q>(bytes) {
        Ok((request, [])) => Ok(request),
        Ok((_, rest)) => Err(ServiceError::BadRequest {
            method: method.to_owned(),
            detail: format!("{} trailing bytes after the request", rest.len()),
        }),
        Err(e) => Err(ServiceError::BadRequest {
            method: method.to_owned(),
            detail: format!("{e} ({} request bytes)", bytes.len()),
        }),
    }
}

/// Components by id with their type names, and the marked ones' names.
fn marked_names(control: &Control<'_>, report: &StatisticsReport) -> Vec<String> {
    let Ok(collector) = control.get::<DebugCollector>() else { return Vec::new() };
    collector.marked().iter().filter_map(|id| report.components.get(id.0 as usize).map(|c| c.name.clone())).collect()
}

impl ServiceBuilder {
    /// A table holding the built-in methods ([`COMPONENTS`], [`DEBUG_FRAME`], [`SET_DEBUG`], [`METHODS`]).
    pub fn new() -> Self {
        let builder = ServiceBuilder { methods: BTreeMap::new() };
        builder
            .control_method(COMPONENTS, |control, (): ()| {
                let statistics = control.statistics();
                let marked = marked_names(control, &statistics);
                Ok(ComponentsReply { statistics, marked })
            })
            .control_method(DEBUG_FRAME, |control, (): ()| {
                control.get::<DebugCollector>().map(|c| c.latest().clone()).map_err(|e| e.to_string())
            })
            .control_method(SET_DEBUG, |control, request: SetDebug| {
                let index = control
                    .statistics()
                    .components
                    .iter()
                    .position(|c| c.name == request.component)
                    .ok_or_else(|| format!("no component called `{}`", request.component))?;
                let id = ComponentId(u32::try_from(index).map_err(|_| "component index overflow".to_owned())?);
                let collector = control.get_mut::<DebugCollector>().map_err(|e| e.to_string())?;
                if request.on {
                    collector.mark(id);
                } else {
                    collector.unmark(id);
                }
                Ok(())
            })
    }

    /// Adds a method on component `T`: `f` gets the component and the decoded request; its result is the
    /// response. A method of the same name is replaced.
    pub fn method<T, Q, R>(self, name: &str, f: impl Fn(&mut T, Q) -> R + Send + Sync + 'static) -> Self
    where
        T: Component,
        Q: DeserializeOwned,
        R: Serialize,
    {
        self.control_method(name, move |control, request: Q| {
            control.get_mut::<T>().map(|component| f(component, request)).map_err(|e: BicaError| e.to_string())
        })
    }

    /// Adds a method that reaches the whole runtime through [`Control`] and may fail with a message.
    pub fn control_method<Q, R>(
        mut self,
        name: &str,
        f: impl Fn(&mut Control<'_>, Q) -> Result<R, String> + Send + Sync + 'static,
    ) -> Self
    where
        Q: DeserializeOwned,
        R: Serialize,
    {
        let method = name.to_owned();
        let run: Method = Arc::new(move |control, bytes| {
            let request = decode::<Q>(&method, bytes)?;
            let response =
                f(control, request).map_err(|detail| ServiceError::Failed { method: method.clone(), detail })?;
            encode(&method, &response)
        });
        self.methods.insert(name.to_owned(), run);
        self
    }

    /// The service over `remote`, the runtime's request queue.
    pub fn build(mut self, remote: RemoteHandle) -> Service {
        let names: Vec<String> = self.methods.keys().cloned().chain([METHODS.to_owned()]).collect();
        let listed = names.clone();
        self = self.control_method(METHODS, move |_, (): ()| Ok(listed.clone()));
        Service { remote, methods: Arc::new(self.methods) }
    }
}

/// A runtime's named methods. Cloneable and `Send + Sync`: any thread may dispatch.
#[derive(Clone)]
pub struct Service {
    remote: RemoteHandle,
    methods: Arc<BTreeMap<String, Method>>,
}

impl std::fmt::Debug for Service {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Service").field("methods", &self.methods.keys().collect::<Vec<_>>()).finish()
    }
}

impl Service {
    /// The names of the methods, sorted.
    pub fn methods(&self) -> Vec<&str> {
        self.methods.keys().map(String::as_str).collect()
    }

    /// Queues `method` with the `postcard` request bytes `request` on the runtime; never blocks. `reply` gets the
    /// response bytes or the error: at once (unknown method, full queue, stopped runtime) on this thread, or later
    /// on the scheduler thread, where it must not block.
    pub fn dispatch(
        &self,
        method: &str,
        request: impl AsRef<[u8]> + Send + 'static,
        reply: impl FnOnce(Result<Vec<u8>, ServiceError>) + Send + 'static,
    ) {
        let Some(run) = self.methods.get(method).cloned() else {
            return reply(Err(ServiceError::UnknownMethod { method: method.to_owned() }));
        };
        // The reply callback moves into the queued closure; if queuing fails it comes back through this slot.
        let slot = Arc::new(std::sync::Mutex::new(Some(Box::new(reply) as Box<dyn FnOnce(_) + Send>)));
        let queued = Arc::clone(&slot);
        let submitted = self.remote.submit(move |control| {
            let result = run(control, request.as_ref());
            if let Some(reply) = queued.lock().unwrap_or_else(|p| p.into_inner()).take() {
                reply(result);
            }
        });
        if let Err(error) = submitted {
            let error = match error {
                BicaError::SchedulerStopped => ServiceError::Stopped { method: method.to_owned() },
                other => ServiceError::Busy { method: method.to_owned(), detail: other.to_string() },
            };
            if let Some(reply) = slot.lock().unwrap_or_else(|p| p.into_inner()).take() {
                reply(Err(error));
            }
        }
    }

    /// Calls `method` from a thread other than the scheduler's and waits (up to `timeout`) for the typed response.
    ///
    /// # Errors
    /// [`ServiceError`]; a timeout is [`ServiceError::Busy`].
    pub fn call<Q: Serialize, R: DeserializeOwned>(
        &self,
        method: &str,
        request: &Q,
        timeout: std::time::Duration,
    ) -> Result<R, ServiceError> {
        let bytes = postcard::to_allocvec(request).map_err(|e| ServiceError::BadRequest {
            method: method.to_owned(),
            detail: format!("encoding the request: {e}"),
        })?;
        let (sender, receiver) = std::sync::mpsc::sync_channel(1);
        self.dispatch(method, bytes, move |reply| {
            let _ = sender.try_send(reply);
        });
        let bytes = match receiver.recv_timeout(timeout) {
            Ok(reply) => reply?,
            Err(std::sync::mpsc::RecvTimeoutError::Timeout) => {
                return Err(ServiceError::Busy {
                    method: method.to_owned(),
                    detail: format!("no answer within {timeout:?}"),
                });
            }
            Err(std::sync::mpsc::RecvTimeoutError::Disconnected) => {
                return Err(ServiceError::Stopped { method: method.to_owned() });
            }
        };
        decode_response(method, &bytes)
    }
}

/// Decodes a method's response bytes as `R`.
///
/// # Errors
/// [`ServiceError::Failed`] when the bytes are not an `R`.
pub fn decode_response<R: DeserializeOwned>(method: &str, bytes: &[u8]) -> Result<R, ServiceError> {
    decode::<R>(method, bytes).map_err(|e| match e {
        ServiceError::BadRequest { method, detail } => {
            ServiceError::Failed { method, detail: format!("the response does not decode: {detail}") }
        }
        other => other,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::clock::VirtualClock;
    use crate::component::StepContext;
    use crate::debug::{DebugFrame, DebugPrimitive, Debuggable, Frame, Point2, Rgba, Shape};
    use crate::runtime::{Runtime, RuntimeConfig};

    #[derive(Default)]
    struct Ball {
        radius: f64,
    }

    impl Component for Ball {
        fn step(&mut self, _: &mut StepContext<'_>) -> Result<(), BicaError> {
            Ok(())
        }
        fn as_debuggable(&self) -> Option<&dyn Debuggable> {
            Some(self)
        }
    }

    impl Debuggable for Ball {
        fn debug_primitives(&self, out: &mut Vec<DebugPrimitive>) {
            let shape = Shape::Circle { center: Point2 { x: 1.0, y: 2.0 }, radius: self.radius };
            out.push(DebugPrimitive::new(Frame::World, shape, Rgba { r: 255, g: 0, b: 0, a: 255 }));
        }
    }

    fn runtime() -> (Runtime<VirtualClock>, Service) {
        let mut runtime = Runtime::new(RuntimeConfig::default(), VirtualClock::new(0));
        runtime.register(Ball { radius: 0.5 }, 10_000_000).unwrap();
        runtime.register(DebugCollector::new(10), 10_000_000).unwrap();
        runtime.activate::<DebugCollector>().unwrap();
        let service = ServiceBuilder::new()
            .method("Ball.set_radius", |ball: &mut Ball, radius: f64| ball.radius = radius)
            .method("Ball.radius", |ball: &mut Ball, (): ()| ball.radius)
            .build(runtime.remote());
        (runtime, service)
    }

    fn call(runtime: &mut Runtime<VirtualClock>, service: &Service, method: &str, request: Vec<u8>) -> Vec<u8> {
        let (tx, rx) = std::sync::mpsc::channel();
        service.dispatch(method, request, move |reply| tx.send(reply).unwrap());
        assert!(rx.try_recv().is_err(), "{method} must wait for the scheduler thread");
        runtime.serve_requests();
        rx.recv().unwrap().unwrap()
    }

    #[test]
    fn builtins_list_components_mark_them_and_return_the_frame() {
        let (mut runtime, service) = runtime();
        assert_eq!(service.methods(), ["Ball.radius", "Ball.set_radius", COMPONENTS, DEBUG_FRAME, METHODS, SET_DEBUG]);
        let request = postcard::to_allocvec(&SetDebug { component: std::any::type_name::<Ball>().into(), on: true });
        assert!(call(&mut runtime, &service, SET_DEBUG, request.unwrap()).is_empty());
        runtime.run_until(1).unwrap();
        let reply: ComponentsReply =
            decode_response(COMPONENTS, &call(&mut runtime, &service, COMPONENTS, Vec::new())).unwrap();
        assert_eq!(reply.statistics.components.len(), 2);
        assert_eq!(reply.marked, [std::any::type_name::<Ball>()]);
        let frame: DebugFrame =
            decode_response(DEBUG_FRAME, &call(&mut runtime, &service, DEBUG_FRAME, Vec::new())).unwrap();
        assert_eq!(frame.entries.len(), 1);
        assert!(matches!(frame.entries[0].primitive.shape, Shape::Circle { radius, .. } if radius == 0.5));
        let methods: Vec<String> =
            decode_response(METHODS, &call(&mut runtime, &service, METHODS, Vec::new())).unwrap();
        assert_eq!(methods.len(), 6);
    }

    #[test]
    fn user_methods_change_the_component_between_steps() {
        let (mut runtime, service) = runtime();
        let request = postcard::to_allocvec(&2.25f64).unwrap();
        call(&mut runtime, &service, "Ball.set_radius", request);
        let radius: f64 =
            decode_response("Ball.radius", &call(&mut runtime, &service, "Ball.radius", Vec::new())).unwrap();
        assert_eq!(radius, 2.25);
        assert_eq!(runtime.registry().get::<Ball>().unwrap().radius, 2.25);
    }

    #[test]
    fn bad_bytes_unknown_names_and_missing_components_are_named_errors() {
        let (mut runtime, service) = runtime();
        let (tx, rx) = std::sync::mpsc::channel();
        let reply = move |r| tx.send(r).unwrap();
        service.dispatch("Ball.set_radius", vec![1, 2], reply.clone());
        service.dispatch("Ball.radius", vec![0], reply.clone());
        let nope = postcard::to_allocvec(&SetDebug { component: "Nope".into(), on: true }).unwrap();
        service.dispatch(SET_DEBUG, nope, reply.clone());
        service.dispatch("Ball.bounce", Vec::new(), reply);
        let unknown = rx.recv().unwrap().unwrap_err();
        assert_eq!(unknown.to_string(), "unknown method `Ball.bounce`");
        runtime.serve_requests();
        let short = rx.recv().unwrap().unwrap_err();
        assert!(matches!(&short, ServiceError::BadRequest { method, .. } if method == "Ball.set_radius"), "{short}");
        let trailing = rx.recv().unwrap().unwrap_err();
        assert!(trailing.to_string().contains("1 trailing bytes"), "{trailing}");
        let missing = rx.recv().unwrap().unwrap_err();
        assert_eq!(missing.to_string(), "`runtime.set_debug` failed: no component called `Nope`");
    }

    #[test]
    fn a_full_queue_and_a_stopped_runtime_answer_at_once() {
        let config = RuntimeConfig { request_queue_capacity: 1, ..RuntimeConfig::default() };
        let runtime = Runtime::new(config, VirtualClock::new(0));
        let service = ServiceBuilder::new().build(runtime.remote());
        let (tx, rx) = std::sync::mpsc::channel();
        for _ in 0..2 {
            let tx = tx.clone();
            service.dispatch(METHODS, Vec::new(), move |r| tx.send(r).unwrap());
        }
        assert!(matches!(rx.try_recv().unwrap(), Err(ServiceError::Busy { .. })));
        drop(runtime);
        service.dispatch(METHODS, Vec::new(), move |r| tx.send(r).unwrap());
        // The queued closure was dropped with the runtime (its reply is lost); the new one is refused.
        assert!(matches!(rx.try_recv().unwrap(), Err(ServiceError::Stopped { .. })));
    }
}
