//! `signals.connect(g, signals.UPDATE_NODE, callback)`: the graph's change signals delivered to Python callbacks.
//!
//! The agent reports every visible change, local or remote, to a bounded subscription
//! (`agent::Agent::subscribe`; a subscriber that falls behind loses signals, counted by the agent, and never blocks
//! it). One dispatcher thread per graph, started by the first `connect`, takes the changes off that channel,
//! groups consecutive attribute changes of one element into one call (as pydsr passes a list of names), looks up
//! what a signal needs (a node's type) through the agent's read path with the GIL released, and only then takes
//! the GIL to call the callbacks. No lock of the agent or of the callback list is held while Python runs, so a
//! callback may read or write the graph. An exception in a callback is printed and the dispatcher goes on.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::Duration;

use agent::{Agent, ChangeSignal};
use crossbeam_channel::RecvTimeoutError;
use dsr::{Change, EdgeKey, Element, NodeId};
use pyo3::exceptions::PyTypeError;
use pyo3::prelude::*;
use transport::Transport;

/// Most undelivered changes kept per graph for the dispatcher (beyond it the agent drops and counts them).
const SIGNAL_QUEUE: usize = 65_536;

/// Most changes the dispatcher takes per round (one GIL acquisition).
const BATCH: usize = 1024;

/// pydsr's signal kinds (`signals.UPDATE_NODE`, ...), plus the removal of an attribute.
#[pyclass(module = "cortex_dsr.signals", name = "signal_type", eq, eq_int, frozen)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SignalType {
    /// A node was inserted (or its shown name changed): `callback(id: int, type: str)`.
    #[pyo3(name = "UPDATE_NODE")]
    UpdateNode,
    /// Attributes of a node changed: `callback(id: int, names: list[str])`.
    #[pyo3(name = "UPDATE_NODE_ATTR")]
    UpdateNodeAttr,
    /// An edge was inserted: `callback(from: int, to: int, type: str)`.
    #[pyo3(name = "UPDATE_EDGE")]
    UpdateEdge,
    /// Attributes of an edge changed: `callback(from: int, to: int, type: str, names: list[str])`.
    #[pyo3(name = "UPDATE_EDGE_ATTR")]
    UpdateEdgeAttr,
    /// An edge was deleted: `callback(from: int, to: int, type: str)`.
    #[pyo3(name = "DELETE_EDGE")]
    DeleteEdge,
    /// A node was deleted: `callback(id: int)`.
    #[pyo3(name = "DELETE_NODE")]
    DeleteNode,
    /// Attributes of a node were removed: `callback(id: int, names: list[str])` (not in pydsr's list).
    #[pyo3(name = "DELETE_NODE_ATTR")]
    DeleteNodeAttr,
    /// Attributes of an edge were removed: `callback(from: int, to: int, type: str, names: list[str])` (not in
    /// pydsr's list).
    #[pyo3(name = "DELETE_EDGE_ATTR")]
    DeleteEdgeAttr,
}

impl SignalType {
    /// Every kind, for the module's constants.
    pub const ALL: [(SignalType, &'static str); 8] = [
        (SignalType::UpdateNode, "UPDATE_NODE"),
        (SignalType::UpdateNodeAttr, "UPDATE_NODE_ATTR"),
        (SignalType::UpdateEdge, "UPDATE_EDGE"),
        (SignalType::UpdateEdgeAttr, "UPDATE_EDGE_ATTR"),
        (SignalType::DeleteEdge, "DELETE_EDGE"),
        (SignalType::DeleteNode, "DELETE_NODE"),
        (SignalType::DeleteNodeAttr, "DELETE_NODE_ATTR"),
        (SignalType::DeleteEdgeAttr, "DELETE_EDGE_ATTR"),
    ];
}

/// One callback's arguments, computed without the GIL.
#[derive(Clone, Debug, PartialEq)]
enum Event {
    Node { kind: SignalType, id: u64, node_type: String },
    NodeDeleted { id: u64 },
    NodeAttrs { kind: SignalType, id: u64, names: Vec<String> },
    Edge { kind: SignalType, key: EdgeKey },
    EdgeAttrs { kind: SignalType, key: EdgeKey, names: Vec<String> },
}

impl Event {
    fn kind(&self) -> SignalType {
        match self {
            Event::Node { kind, .. }
            | Event::NodeAttrs { kind, .. }
            | Event::Edge { kind, .. }
            | Event::EdgeAttrs { kind, .. } => *kind,
            Event::NodeDeleted { .. } => SignalType::DeleteNode,
        }
    }

    fn arguments<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, pyo3::types::PyTuple>> {
        match self {
            Event::Node { id, node_type, .. } => (*id, node_type.as_str()).into_pyobject(py),
            Event::NodeDeleted { id } => (*id,).into_pyobject(py),
            Event::NodeAttrs { id, names, .. } => (*id, names.clone()).into_pyobject(py),
            Event::Edge { key, .. } => (key.from.0, key.to.0, key.edge_type.as_str()).into_pyobject(py),
            Event::EdgeAttrs { key, names, .. } => {
                (key.from.0, key.to.0, key.edge_type.as_str(), names.clone()).into_pyobject(py)
            }
        }
    }
}

/// Turns a batch of changes into callback events: consecutive attribute changes of one element and kind become
/// one event with every name, preceded, as in pydsr, by the element's `UPDATE_NODE` / `UPDATE_EDGE` (once per
/// element in the batch: an insert's own signal stands for it). Node types are read from `agent` (the GIL is not
/// held here).
fn events<T: Transport>(agent: &Agent<T>, batch: Vec<ChangeSignal>) -> Vec<Event> {
    let node_type = |id: NodeId| agent.read(|r| r.node(id).map(|n| n.node_type().to_owned())).flatten();
    let mut out: Vec<Event> = Vec::with_capacity(batch.len());
    for signal in batch {
        let event = match signal.change {
            Change::NodeInserted { id } | Change::NodeRenamed { id } => {
                let Some(node_type) = node_type(id) else { continue };
                Event::Node { kind: SignalType::UpdateNode, id: id.0, node_type }
            }
            Change::NodeDeleted { id } => Event::NodeDeleted { id: id.0 },
            Change::EdgeInserted { key } => Event::Edge { kind: SignalType::UpdateEdge, key },
            Change::EdgeDeleted { key } => Event::Edge { kind: SignalType::DeleteEdge, key },
            change @ (Change::AttrUpdated { .. } | Change::AttrRemoved { .. }) => {
                let removed = matches!(change, Change::AttrRemoved { .. });
                let (Change::AttrUpdated { element, name } | Change::AttrRemoved { element, name }) = change else {
                    continue;
                };
                let name = name.to_string();
                let grouped = match (out.last_mut(), &element) {
                    (Some(Event::NodeAttrs { kind, id, names }), Element::Node(node))
                        if *id == node.0 && (*kind == SignalType::DeleteNodeAttr) == removed =>
                    {
                        names.push(name.clone());
                        true
                    }
                    (Some(Event::EdgeAttrs { kind, key, names }), Element::Edge(edge))
                        if key == edge && (*kind == SignalType::DeleteEdgeAttr) == removed =>
                    {
                        names.push(name.clone());
                        true
                    }
                    _ => false,
                };
                if grouped {
                    continue;
                }
                // pydsr signals the element's update with its attribute update (`update_node_signal` and
                // `update_node_attr_signal`, likewise for edges): once per element per dispatch round here.
                match element {
                    Element::Node(id) => {
                        let announced = out.iter().any(|e| matches!(e, Event::Node { id: n, .. } if *n == id.0));
                        if !announced && let Some(node_type) = node_type(id) {
                            out.push(Event::Node { kind: SignalType::UpdateNode, id: id.0, node_type });
                        }
                        Event::NodeAttrs {
                            kind: if removed { SignalType::DeleteNodeAttr } else { SignalType::UpdateNodeAttr },
                            id: id.0,
                            names: vec![name],
                        }
                    }
                    Element::Edge(key) => {
                        let announced = out
                            .iter()
                            .any(|e| matches!(e, Event::Edge { kind: SignalType::UpdateEdge, key: k } if *k == key));
                        if !announced {
                            out.push(Event::Edge { kind: SignalType::UpdateEdge, key: key.clone() });
                        }
                        Event::EdgeAttrs {
                            kind: if removed { SignalType::DeleteEdgeAttr } else { SignalType::UpdateEdgeAttr },
                            key,
                            names: vec![name],
                        }
                    }
                }
            }
        };
        out.push(event);
    }
    out
}

/// Set at interpreter exit (`atexit`): dispatchers stop before Python finalizes.
static EXITING: AtomicBool = AtomicBool::new(false);

/// The dispatcher threads of this process, joined at exit.
static DISPATCHERS: Mutex<Vec<JoinHandle<()>>> = Mutex::new(Vec::new());

/// The callbacks of one graph and its dispatcher's stop flag.
#[derive(Default)]
pub struct SignalHub {
    callbacks: Mutex<Vec<(SignalType, Py<PyAny>)>>,
    started: AtomicBool,
    stop: Arc<AtomicBool>,
}

impl SignalHub {
    /// Drops every callback (the caller holds the GIL).
    pub fn clear_callbacks(&self) {
        let callbacks = std::mem::take(&mut *self.callbacks.lock().unwrap_or_else(|p| p.into_inner()));
        drop(callbacks);
    }

    /// Visits the callbacks for Python's garbage collector; skips them if the list is busy (the dispatcher is
    /// copying it), as a traversal must not block.
    pub fn traverse(&self, visit: &pyo3::PyVisit<'_>) -> Result<(), pyo3::PyTraverseError> {
        if let Ok(callbacks) = self.callbacks.try_lock() {
            for (_, callback) in callbacks.iter() {
                visit.call(callback)?;
            }
        }
        Ok(())
    }

    /// Asks the dispatcher to stop (it ends within its 50 ms poll).
    pub fn stop(&self) {
        self.stop.store(true, Ordering::SeqCst);
    }

    /// Adds `callback` for changes of `kind` and starts the dispatcher of `agent`'s changes if it is not running.
    ///
    /// # Errors
    /// A Python `TypeError` if `callback` is not callable; an error if the dispatcher thread cannot start.
    pub fn connect<T: Transport>(
        self: &Arc<Self>,
        agent: Arc<Agent<T>>,
        kind: SignalType,
        callback: Bound<'_, PyAny>,
    ) -> PyResult<()> {
        if !callback.is_callable() {
            return Err(PyTypeError::new_err("the callback must be callable"));
        }
        self.callbacks.lock().unwrap_or_else(|p| p.into_inner()).push((kind, callback.unbind()));
        self.start(agent)
    }

    fn start<T: Transport>(self: &Arc<Self>, agent: Arc<Agent<T>>) -> PyResult<()> {
        if self.started.swap(true, Ordering::SeqCst) {
            return Ok(());
        }
        let receiver = agent.subscribe(SIGNAL_QUEUE);
        let hub = Arc::clone(self);
        let handle = std::thread::Builder::new()
            .name(format!("cortex-dsr-signals-{}", agent.id().0))
            .spawn(move || {
                let stopping = || hub.stop.load(Ordering::SeqCst) || EXITING.load(Ordering::SeqCst);
                while !stopping() {
                    let first = match receiver.recv_timeout(Duration::from_millis(50)) {
                        Ok(signal) => signal,
                        Err(RecvTimeoutError::Timeout) => continue,
                        Err(RecvTimeoutError::Disconnected) => break,
                    };
                    let mut batch = vec![first];
                    batch.extend(receiver.try_iter().take(BATCH - 1));
                    // The changes of one write reach the queue one by one: read on to the last of them, so that
                    // they group into one event (bounded: a change dropped at a full queue may have been the last).
                    while batch.last().is_some_and(|s| !s.last_together) && batch.len() < BATCH {
                        let Ok(next) = receiver.recv_timeout(Duration::from_millis(50)) else { break };
                        batch.push(next);
                        batch.extend(receiver.try_iter().take(BATCH - batch.len()));
                    }
                    let events = events(&agent, batch);
                    if events.is_empty() || stopping() {
                        continue;
                    }
                    Python::attach(|py| {
                        if EXITING.load(Ordering::SeqCst) {
                            return;
                        }
                        let callbacks: Vec<(SignalType, Py<PyAny>)> = hub
                            .callbacks
                            .lock()
                            .unwrap_or_else(|p| p.into_inner())
                            .iter()
                            .map(|(kind, callback)| (*kind, callback.clone_ref(py)))
                            .collect();
                        for event in &events {
                            for (_, callback) in callbacks.iter().filter(|(kind, _)| *kind == event.kind()) {
                                let called = event.arguments(py).and_then(|args| callback.call1(py, args));
                                if let Err(error) = called {
                                    error.print(py);
                                }
                            }
                        }
                    });
                }
            })
            .map_err(|e| pyo3::exceptions::PyRuntimeError::new_err(format!("cannot start the signal thread: {e}")))?;
        let mut dispatchers = DISPATCHERS.lock().unwrap_or_else(|p| p.into_inner());
        dispatchers.retain(|handle| !handle.is_finished());
        dispatchers.push(handle);
        Ok(())
    }
}

/// Stops every dispatcher and waits for them (registered with `atexit`), so none calls into a finalizing
/// interpreter.
#[pyfunction]
pub fn _shutdown(py: Python<'_>) {
    EXITING.store(true, Ordering::SeqCst);
    let handles = std::mem::take(&mut *DISPATCHERS.lock().unwrap_or_else(|p| p.into_inner()));
    py.detach(|| {
        for handle in handles {
            let _ = handle.join();
        }
    });
}
