//! `DSRGraph`: a live DSR_d agent on RTPS (`agent::Agent<RtpsTransport>`, as `cortex agent` runs one) behind
//! pydsr's graph API.
//!
//! Every call converts its Python arguments first, then releases the GIL while it works on the agent (a read
//! under the agent's short lock, or a write and its publish), then builds the Python result: the agent's lock and
//! the GIL are never held together, so signal callbacks that read the graph cannot deadlock with a writer.

use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::Duration;

use agent::{Agent, AgentConfig, AgentId};
use dsr::{EdgeKey, EdgeRef, Element, NewNode, NodeId, NodeRef, OpError, Replica, Value};
use pyo3::exceptions::{PyRuntimeError, PyTypeError};
use pyo3::prelude::*;
use pyo3::types::PyString;
use transport::SystemClock;
use transport::rtps::{RtpsConfig, RtpsTransport};

use crate::objects::{AttrMap, Attribute, Edge, EdgeMap, LOCAL_AGENT_ID, Node};
use crate::signals::{SignalHub, SignalType};

/// An edge to insert with a node: destination, type, attributes.
type EdgeToInsert = (u64, String, Vec<(String, Value)>);

/// The agent type behind a `DSRGraph`.
pub type GraphAgent = Agent<RtpsTransport>;

/// One attribute read from the replica: winning value, its stamp and writer.
#[derive(Clone, Debug)]
pub struct AttrCopy {
    name: String,
    value: Value,
    stamp_ns: u64,
    agent: u32,
}

/// One edge read from the replica.
#[derive(Clone, Debug)]
pub struct EdgeCopy {
    key: EdgeKey,
    attrs: Vec<AttrCopy>,
}

/// One node read from the replica, with its outgoing edges.
#[derive(Clone, Debug)]
pub struct NodeCopy {
    id: NodeId,
    node_type: String,
    name: String,
    attrs: Vec<AttrCopy>,
    edges: Vec<EdgeCopy>,
}

fn attr_copies(
    names: impl Iterator<Item = String>,
    entry: impl Fn(&str) -> Option<(Value, u64, u32)>,
) -> Vec<AttrCopy> {
    names
        .filter_map(|name| entry(&name).map(|(value, stamp_ns, agent)| AttrCopy { name, value, stamp_ns, agent }))
        .collect()
}

/// A copy of an edge's winning attributes.
pub fn edge_copy(edge: &EdgeRef<'_>) -> EdgeCopy {
    let attrs = attr_copies(edge.attrs().map(|(name, _)| name.to_string()), |name| {
        edge.attr_entry(name).map(|e| (e.value.clone(), e.stamp.0, AgentId::of_replica(e.dot.replica).0))
    });
    EdgeCopy { key: edge.key().clone(), attrs }
}

/// A copy of a node, its winning attributes and its outgoing edges.
pub fn node_copy(replica: &Replica, node: &NodeRef<'_>) -> NodeCopy {
    let attrs = attr_copies(node.attrs().map(|(name, _)| name.to_string()), |name| {
        node.attr_entry(name).map(|e| (e.value.clone(), e.stamp.0, AgentId::of_replica(e.dot.replica).0))
    });
    NodeCopy {
        id: node.id(),
        node_type: node.node_type().to_owned(),
        name: node.name().into_owned(),
        attrs,
        edges: replica.out_edges(node.id()).map(|edge| edge_copy(&edge)).collect(),
    }
}

/// The agent of the latest write among `attrs` (0 without attributes).
fn last_writer(attrs: &[AttrCopy]) -> u32 {
    attrs.iter().max_by_key(|a| a.stamp_ns).map_or(0, |a| a.agent)
}

fn attr_map(py: Python<'_>, attrs: Vec<AttrCopy>) -> PyResult<AttrMap> {
    let mut map = AttrMap::default();
    for attr in attrs {
        let attribute = Attribute { value: attr.value, timestamp: attr.stamp_ns, agent_id: attr.agent };
        map.entries.insert(attr.name, Py::new(py, attribute)?);
    }
    Ok(map)
}

/// The Python `Edge` of a copy.
pub fn edge_object(py: Python<'_>, edge: EdgeCopy) -> PyResult<Py<Edge>> {
    let agent = last_writer(&edge.attrs);
    let key = edge.key;
    Py::new(py, Edge::build(py, key.from.0, key.to.0, key.edge_type.to_string(), agent, attr_map(py, edge.attrs)?)?)
}

/// The Python `Node` of a copy.
pub fn node_object(py: Python<'_>, node: NodeCopy) -> PyResult<Py<Node>> {
    let agent = last_writer(&node.attrs);
    let mut edges = EdgeMap::default();
    for edge in node.edges {
        edges.entries.insert((edge.key.to.0, edge.key.edge_type.to_string()), edge_object(py, edge)?);
    }
    Py::new(py, Node::build(py, node.id.0, node.node_type, node.name, agent, attr_map(py, node.attrs)?, edges)?)
}

fn runtime_error(error: impl std::fmt::Display) -> PyErr {
    PyRuntimeError::new_err(error.to_string())
}

/// Whether a refused operation means "no such thing" (pydsr answers `False`/`None`) rather than a misuse
/// (`RuntimeError`).
fn is_absence(error: &OpError) -> bool {
    matches!(
        error,
        OpError::NoSuchNode(_)
            | OpError::NoSuchEdge(_)
            | OpError::NoSuchElement(_)
            | OpError::NoSuchAttr { .. }
            | OpError::NameTaken(_)
            | OpError::IdTaken(_)
    )
}

/// A replica refusal as `Ok(false)` for absence, else a `RuntimeError`.
fn absent_is_false(result: Result<bool, OpError>) -> PyResult<bool> {
    result.or_else(|error| if is_absence(&error) { Ok(false) } else { Err(runtime_error(error)) })
}

/// An agent error as `Ok(false)` for absence, else a `RuntimeError`.
fn absent_or_error(error: agent::AgentError) -> PyResult<bool> {
    match &error {
        agent::AgentError::Op { source, .. } if is_absence(source) => Ok(false),
        _ => Err(runtime_error(error)),
    }
}

/// A node id or name argument.
pub enum NodeRefArg {
    /// By id.
    Id(NodeId),
    /// By name.
    Name(String),
}

impl NodeRefArg {
    /// An `int` or `str` argument.
    pub fn extract(object: &Bound<'_, PyAny>) -> PyResult<NodeRefArg> {
        if let Ok(name) = object.cast::<PyString>() {
            return Ok(NodeRefArg::Name(name.to_str()?.to_owned()));
        }
        // Any integer, numpy's included (`__index__`); not a float.
        if !object.is_instance_of::<pyo3::types::PyFloat>()
            && let Ok(id) = object.extract::<u64>()
        {
            return Ok(NodeRefArg::Id(NodeId(id)));
        }
        Err(PyTypeError::new_err(format!(
            "a node is given by its id (an int from 0 to 2^64-1) or its name (str), not {}",
            object.repr().map_or_else(|_| "this".to_owned(), |r| r.to_string())
        )))
    }

    /// The id of the visible node this names.
    pub fn resolve(&self, replica: &Replica) -> Option<NodeId> {
        match self {
            NodeRefArg::Id(id) => replica.node(*id).map(|n| n.id()),
            NodeRefArg::Name(name) => replica.node_by_name(name).map(|n| n.id()),
        }
    }
}

/// The key of the edge between two visible nodes given by id or name (the edge itself may not exist).
fn edge_key(replica: &Replica, from: &NodeRefArg, to: &NodeRefArg, edge_type: &str) -> Option<EdgeKey> {
    Some(EdgeKey::new(from.resolve(replica)?, to.resolve(replica)?, edge_type))
}

/// `DSRGraph(root, name, id, dsr_input_file="", all_same_host=True)`: a DSR_d agent of this process, joined to
/// the agents of its DDS domain and topic prefix, or started from the JSON file when none answers.
///
/// Frozen (no `&mut self` method): a signal callback may be inside a method of the graph on the dispatcher thread,
/// with the GIL released, while the script's thread calls `close`; an exclusive borrow would then fail ("Already
/// borrowed"). The agent sits behind a mutex instead, taken only to clone or take the `Arc`.
#[pyclass(module = "cortex_dsr", name = "DSRGraph", weakref, frozen)]
pub struct DsrGraph {
    agent: std::sync::Mutex<Option<Arc<GraphAgent>>>,
    /// The signal callbacks and their dispatcher.
    pub hub: Arc<SignalHub>,
    agent_name: String,
}

/// Settings read from the environment when not given as keywords.
fn env_or<T: std::str::FromStr>(key: &str, default: T) -> T {
    std::env::var(key).ok().and_then(|v| v.parse().ok()).unwrap_or(default)
}

/// Starts an agent on RTPS with the real clock, as `cortex agent` does, and waits (up to its join wait plus 10 s)
/// until it has a graph: a running agent's, or the seed's.
fn start_agent(id: u32, seed: Option<&Path>, rtps: RtpsConfig, join_wait: Duration) -> Result<Arc<GraphAgent>, String> {
    if id >= AgentId::LIMIT {
        return Err(format!("agent id {id} is out of range (0..{})", AgentId::LIMIT));
    }
    let mut config = AgentConfig::new(AgentId(id));
    config.join_wait = join_wait;
    if let Some(path) = seed {
        let bytes = std::fs::read(path).map_err(|e| format!("cannot read {}: {e}", path.display()))?;
        // Read leniently, as `cortex agent` and the C++ loader do (`dsr::json` states the rules); what was
        // converted, skipped or learnt is printed on standard error with its place in the file.
        let reading =
            dsr::json::read(&bytes, dsr::json::Strictness::Lenient).map_err(|e| format!("{}: {e}", path.display()))?;
        // The agent imports its seed only if no peer answers, and then only logs a refusal; check it now on a
        // scratch replica (the agent's own kind: `Replica::new`, the built-in dictionary) so that a file the graph
        // would refuse raises here, as pydsr raises for a bad file, instead of leaving an empty graph.
        let report = reading
            .graph
            .import_into(&mut Replica::new(dsr::ReplicaId(1)), 0)
            .map_err(|e| format!("{} cannot seed the graph: {e}", path.display()))?;
        for warning in reading.warnings.iter().chain(&report.warnings) {
            eprintln!("warning: {}: {warning}", path.display());
        }
        config.seed = Some(reading.graph);
    }
    let transport = RtpsTransport::new(rtps).map_err(|e| format!("cannot join the DDS domain: {e}"))?;
    let agent = Agent::start(config, transport, Arc::new(SystemClock)).map_err(|e| e.to_string())?;
    if !agent.wait_ready(join_wait + Duration::from_secs(10)) {
        return Err(format!("agent {id} got no graph within {} ms", (join_wait + Duration::from_secs(10)).as_millis()));
    }
    Ok(Arc::new(agent))
}

impl DsrGraph {
    /// The agent (an error after `close`).
    pub fn agent(&self) -> PyResult<Arc<GraphAgent>> {
        let agent = self.agent.lock().unwrap_or_else(|p| p.into_inner()).clone();
        agent.ok_or_else(|| PyRuntimeError::new_err("the DSRGraph was closed"))
    }

    /// Takes the agent out (closing); `None` if already closed.
    fn take_agent(&self) -> Option<Arc<GraphAgent>> {
        self.agent.lock().unwrap_or_else(|p| p.into_inner()).take()
    }

    /// Runs `f` on the replica with the GIL released.
    pub fn read<R: Send>(&self, py: Python<'_>, f: impl FnOnce(&Replica) -> R + Send) -> PyResult<R> {
        let agent = self.agent()?;
        py.detach(|| agent.read(f)).ok_or_else(|| PyRuntimeError::new_err("the agent has no graph"))
    }

    /// Runs local operations on the replica with the GIL released and publishes their deltas.
    fn write<R: Send>(
        &self,
        py: Python<'_>,
        op: impl FnOnce(&mut Replica, u64, &mut Vec<Arc<dsr::Delta>>) -> R + Send,
    ) -> PyResult<R> {
        let agent = self.agent()?;
        py.detach(|| {
            agent.update(|replica, now| {
                let mut deltas = Vec::new();
                let result = op(replica, now, &mut deltas);
                (result, deltas)
            })
        })
        .map_err(runtime_error)
    }

    fn node_by(&self, py: Python<'_>, which: NodeRefArg) -> PyResult<Option<Py<Node>>> {
        let copy = self.read(py, |r| which.resolve(r).and_then(|id| r.node(id)).map(|n| node_copy(r, &n)))?;
        copy.map(|c| node_object(py, c)).transpose()
    }

    fn nodes_where(
        &self,
        py: Python<'_>,
        keep: impl Fn(&NodeRef<'_>) -> bool + Send + Sync,
    ) -> PyResult<Vec<Py<Node>>> {
        let copies = self.read(py, |r| r.nodes().filter(|n| keep(n)).map(|n| node_copy(r, &n)).collect::<Vec<_>>())?;
        copies.into_iter().map(|c| node_object(py, c)).collect()
    }

    fn edges_where(
        &self,
        py: Python<'_>,
        keep: impl Fn(&EdgeRef<'_>) -> bool + Send + Sync,
    ) -> PyResult<Vec<Py<Edge>>> {
        let copies = self.read(py, |r| r.edges().filter(|e| keep(e)).map(|e| edge_copy(&e)).collect::<Vec<_>>())?;
        copies.into_iter().map(|c| edge_object(py, c)).collect()
    }

    /// Registers the attribute names of `attrs` the graph's dictionary does not know yet, each with the type of its
    /// first value, as pydsr (the C++ API's run-time type check) does on a first write; a known name keeps its
    /// types (another is refused by the write). Node and edge types are not registered: an unknown one is refused,
    /// as in pydsr.
    fn register_attr_names<S: AsRef<str>>(replica: &mut Replica, attrs: &[(S, Value)]) -> Result<(), OpError> {
        let dictionary = replica.dictionary();
        let unknown: Vec<(&str, dsr::ValueType)> = (attrs.iter())
            .map(|(name, value)| (name.as_ref(), value.value_type()))
            .filter(|(name, _)| dictionary.attr_type(name).is_none())
            .collect();
        Ok(replica.learn_names(unknown, [])?)
    }

    /// Writes `attrs` to `element` where they differ from what it holds and removes the attributes it holds that
    /// `attrs` lacks: pydsr's update of a node or edge from its copy. `Ok(false)` if the element is not visible.
    fn sync_attrs(
        replica: &mut Replica,
        now: u64,
        element: Element,
        attrs: Vec<(String, Value)>,
        deltas: &mut Vec<Arc<dsr::Delta>>,
    ) -> Result<bool, OpError> {
        let current: Vec<(String, Value)> = match &element {
            Element::Node(id) => match replica.node(*id) {
                Some(node) => node.attrs().map(|(k, v)| (k.to_string(), v.clone())).collect(),
                None => return Ok(false),
            },
            Element::Edge(key) => match replica.edge(key) {
                Some(edge) => edge.attrs().map(|(k, v)| (k.to_string(), v.clone())).collect(),
                None => return Ok(false),
            },
        };
        let changed: Vec<(&str, Value)> = attrs
            .iter()
            .filter(|(name, value)| !current.iter().any(|(k, v)| k == name && v == value))
            .map(|(name, value)| (name.as_str(), value.clone()))
            .collect();
        if !changed.is_empty() {
            Self::register_attr_names(replica, &changed)?;
            deltas.push(replica.set_attrs(now, element.clone(), changed)?);
        }
        for (name, _) in current.iter().filter(|(k, _)| !attrs.iter().any(|(name, _)| name == k)) {
            deltas.push(replica.remove_attr(now, element.clone(), name)?);
        }
        Ok(true)
    }
}

impl Drop for DsrGraph {
    fn drop(&mut self) {
        self.hub.stop();
        if let Some(agent) = self.take_agent() {
            // The agent's threads never need the GIL; let other Python threads run while they stop.
            Python::attach(|py| py.detach(move || agent.shutdown()));
        }
    }
}

static GENERATED_NAMES: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);

#[pymethods]
impl DsrGraph {
    /// Starts the agent. `domain`, `topic_prefix` and `join_wait_ms` (keywords, not in pydsr) default to the
    /// environment's `CORTEX_DSR_DOMAIN`, `CORTEX_DSR_TOPIC_PREFIX`, `CORTEX_DSR_JOIN_WAIT_MS`, else to `cortex
    /// agent`'s 0, `dsr` and 2000 ms. `all_same_host` is accepted and ignored (RTPS finds same-host peers itself).
    #[new]
    #[pyo3(signature = (root, name, id, dsr_input_file = String::new(), all_same_host = true, *, domain = None, topic_prefix = None, join_wait_ms = None))]
    #[allow(clippy::too_many_arguments)]
    fn py_new(
        py: Python<'_>,
        root: i64,
        name: String,
        id: u32,
        dsr_input_file: String,
        all_same_host: bool,
        domain: Option<u16>,
        topic_prefix: Option<String>,
        join_wait_ms: Option<u64>,
    ) -> PyResult<Self> {
        let _ = (root, all_same_host);
        let rtps = RtpsConfig {
            domain_id: domain.unwrap_or_else(|| env_or("CORTEX_DSR_DOMAIN", 0)),
            topic_prefix: topic_prefix.unwrap_or_else(|| env_or("CORTEX_DSR_TOPIC_PREFIX", "dsr".to_owned())),
            ..RtpsConfig::default()
        };
        let join_wait = Duration::from_millis(join_wait_ms.unwrap_or_else(|| env_or("CORTEX_DSR_JOIN_WAIT_MS", 2000)));
        let seed = (!dsr_input_file.is_empty()).then(|| Path::new(&dsr_input_file).to_owned());
        let agent = py.detach(|| start_agent(id, seed.as_deref(), rtps, join_wait)).map_err(PyRuntimeError::new_err)?;
        LOCAL_AGENT_ID.store(id, Ordering::Relaxed);
        // pydsr accepts in `Node(...)`/`Edge(...)` the types its graph's file declared: so do we.
        let types: Vec<(bool, String)> = py.detach(|| {
            agent
                .read(|r| {
                    let nodes = r.nodes().map(|n| (true, n.node_type().to_owned()));
                    nodes.chain(r.edges().map(|e| (false, e.edge_type().to_owned()))).collect()
                })
                .unwrap_or_default()
        });
        for (is_node, name) in types {
            crate::objects::learn_type(is_node, &name);
        }
        Ok(DsrGraph {
            agent: std::sync::Mutex::new(Some(agent)),
            hub: Arc::new(SignalHub::default()),
            agent_name: name,
        })
    }

    /// `get_node(id)` or `get_node(name)`: a copy of the node, or `None`.
    fn get_node(&self, py: Python<'_>, id: &Bound<'_, PyAny>) -> PyResult<Option<Py<Node>>> {
        self.node_by(py, NodeRefArg::extract(id)?)
    }

    /// Every node.
    fn get_nodes(&self, py: Python<'_>) -> PyResult<Vec<Py<Node>>> {
        self.nodes_where(py, |_| true)
    }

    /// The nodes of a type.
    fn get_nodes_by_type(&self, py: Python<'_>, r#type: String) -> PyResult<Vec<Py<Node>>> {
        self.nodes_where(py, move |n| n.node_type() == r#type)
    }

    /// The node named `root` (else the first of type `root` or `world`).
    fn get_node_root(&self, py: Python<'_>) -> PyResult<Option<Py<Node>>> {
        let copy = self.read(py, |r| {
            r.node_by_name("root")
                .or_else(|| r.nodes().find(|n| n.node_type() == "root"))
                .or_else(|| r.nodes().find(|n| n.node_type() == "world"))
                .map(|n| node_copy(r, &n))
        })?;
        copy.map(|c| node_object(py, c)).transpose()
    }

    /// The name of node `id`, or `None`.
    fn get_name_from_id(&self, py: Python<'_>, id: u64) -> PyResult<Option<String>> {
        self.read(py, |r| r.node(NodeId(id)).map(|n| n.name().into_owned()))
    }

    /// The id of the node called `name`, or `None`.
    fn get_id_from_name(&self, py: Python<'_>, name: String) -> PyResult<Option<u64>> {
        self.read(py, move |r| r.node_by_name(&name).map(|n| n.id().0))
    }

    /// Inserts a node with its attributes (and its edges to existing nodes); returns the new id (also set on
    /// `node`), or `None` if its id or name is taken. A node without a name gets `type_N`.
    fn insert_node(&self, py: Python<'_>, node: &Bound<'_, Node>) -> PyResult<Option<u64>> {
        let (mut new_node, edges) = {
            let n = node.borrow();
            let name = if n.name.is_empty() {
                format!("{}_{}", n.node_type, GENERATED_NAMES.fetch_add(1, Ordering::Relaxed) + 1)
            } else {
                n.name.clone()
            };
            let mut new_node = NewNode::new(&n.node_type, &name);
            new_node.id = (n.id != 0).then_some(NodeId(n.id));
            new_node.attrs = n.attrs.borrow(py).to_values(py);
            let edges: Vec<EdgeToInsert> = n
                .edges
                .borrow(py)
                .entries
                .values()
                .map(|e| {
                    let e = e.borrow(py);
                    (e.to, e.edge_type.clone(), e.attrs.borrow(py).to_values(py))
                })
                .collect();
            (new_node, edges)
        };
        let generated = node.borrow().name.is_empty();
        let inserted = self.write(py, move |replica, now, deltas| {
            Self::register_attr_names(replica, &new_node.attrs)?;
            for (_, _, attrs) in &edges {
                Self::register_attr_names(replica, attrs)?;
            }
            let mut attempt = 0;
            let id = loop {
                match replica.insert_node(now, new_node.clone()) {
                    Ok((id, delta)) => {
                        deltas.push(delta);
                        break Ok(id);
                    }
                    Err(OpError::NameTaken(_)) if generated && attempt < 64 => {
                        attempt += 1;
                        new_node.name =
                            format!("{}_{}", new_node.node_type, GENERATED_NAMES.fetch_add(1, Ordering::Relaxed) + 1);
                    }
                    Err(error) => break Err(error),
                }
            }?;
            for (to, edge_type, attrs) in edges {
                if replica.node(NodeId(to)).is_some() {
                    let (_, delta) = replica.insert_edge(now, id, NodeId(to), &edge_type, attrs)?;
                    deltas.push(delta);
                }
            }
            Ok((id, new_node.name))
        })?;
        match inserted {
            Ok((id, name)) => {
                let mut n = node.borrow_mut();
                n.id = id.0;
                n.name = name;
                Ok(Some(id.0))
            }
            Err(error) if is_absence(&error) => Ok(None),
            Err(error) => Err(runtime_error(error)),
        }
    }

    /// Writes the node's attributes that changed and removes those it no longer has; `False` if the node does
    /// not exist (by id), `RuntimeError` for a name or type the graph refuses.
    fn update_node(&self, py: Python<'_>, node: PyRef<'_, Node>) -> PyResult<bool> {
        let (id, attrs) = (NodeId(node.id), node.attrs.borrow(py).to_values(py));
        drop(node);
        let result = self
            .write(py, move |replica, now, deltas| Self::sync_attrs(replica, now, Element::Node(id), attrs, deltas))?;
        absent_is_false(result)
    }

    /// `delete_node(id)` or `delete_node(name)`: deletes the node and its edges; `False` if there is none.
    fn delete_node(&self, py: Python<'_>, id: &Bound<'_, PyAny>) -> PyResult<bool> {
        let which = NodeRefArg::extract(id)?;
        let agent = self.agent()?;
        py.detach(|| match agent.read(|r| which.resolve(r)).flatten() {
            Some(id) => agent.delete_node(id).map(|()| true).or_else(absent_or_error),
            None => Ok(false),
        })
    }

    /// `get_edge(from, to, type)` with ids or names: a copy of the edge, or `None`.
    #[pyo3(signature = (r#from, to, r#type))]
    fn get_edge(
        &self,
        py: Python<'_>,
        r#from: &Bound<'_, PyAny>,
        to: &Bound<'_, PyAny>,
        r#type: String,
    ) -> PyResult<Option<Py<Edge>>> {
        let (from, to) = (NodeRefArg::extract(r#from)?, NodeRefArg::extract(to)?);
        let copy = self.read(py, move |r| {
            let key = edge_key(r, &from, &to, &r#type)?;
            r.edge(&key).map(|e| edge_copy(&e))
        })?;
        copy.map(|c| edge_object(py, c)).transpose()
    }

    /// Inserts the edge, or writes its changed attributes and removes those it no longer has; `False` if an end
    /// node does not exist.
    fn insert_or_assign_edge(&self, py: Python<'_>, edge: PyRef<'_, Edge>) -> PyResult<bool> {
        let key = EdgeKey::new(NodeId(edge.from), NodeId(edge.to), &edge.edge_type);
        let attrs = edge.attrs.borrow(py).to_values(py);
        drop(edge);
        let result = self.write(py, move |replica, now, deltas| {
            if replica.edge(&key).is_some() {
                return Self::sync_attrs(replica, now, Element::Edge(key), attrs, deltas);
            }
            Self::register_attr_names(replica, &attrs)?;
            let (_, delta) = replica.insert_edge(now, key.from, key.to, &key.edge_type, attrs)?;
            deltas.push(delta);
            Ok(true)
        })?;
        absent_is_false(result)
    }

    /// `delete_edge(from, to, type)` with ids or names; `False` if there is no such edge.
    #[pyo3(signature = (r#from, to, r#type))]
    fn delete_edge(
        &self,
        py: Python<'_>,
        r#from: &Bound<'_, PyAny>,
        to: &Bound<'_, PyAny>,
        r#type: String,
    ) -> PyResult<bool> {
        let (from, to) = (NodeRefArg::extract(r#from)?, NodeRefArg::extract(to)?);
        let agent = self.agent()?;
        py.detach(|| {
            let key = agent.read(|r| edge_key(r, &from, &to, &r#type)).flatten();
            match key {
                Some(key) => agent.delete_edge(&key).map(|()| true).or_else(absent_or_error),
                None => Ok(false),
            }
        })
    }

    /// The edges of a type.
    fn get_edges_by_type(&self, py: Python<'_>, r#type: String) -> PyResult<Vec<Py<Edge>>> {
        self.edges_where(py, move |e| e.edge_type() == r#type)
    }

    /// The edges that end at node `id`.
    fn get_edges_to_id(&self, py: Python<'_>, id: u64) -> PyResult<Vec<Py<Edge>>> {
        let copies = self.read(py, |r| r.in_edges(NodeId(id)).map(|e| edge_copy(&e)).collect::<Vec<_>>())?;
        copies.into_iter().map(|c| edge_object(py, c)).collect()
    }

    /// Writes the graph as CORTEX JSON (`skip_atts` is accepted and ignored: every attribute is written).
    #[pyo3(signature = (file, skip_atts = Vec::new()))]
    fn write_to_json_file(&self, py: Python<'_>, file: String, skip_atts: Vec<String>) -> PyResult<()> {
        let _ = skip_atts;
        let json = self.read(py, dsr::json::export)?.map_err(runtime_error)?;
        py.detach(|| std::fs::write(&file, json)).map_err(|e| PyRuntimeError::new_err(format!("writing {file}: {e}")))
    }

    /// This agent's id.
    fn get_agent_id(&self) -> PyResult<u32> {
        Ok(self.agent()?.id().0)
    }

    /// The graph's digest (BLAKE3 of the visible graph, hex), as `cortex agent`'s status line shows it: two
    /// agents with equal digests show the same graph. (Not in pydsr.)
    fn digest(&self, py: Python<'_>) -> PyResult<String> {
        self.read(py, |r| r.digest().to_string())
    }

    /// The name given to the constructor.
    fn get_agent_name(&self) -> String {
        self.agent_name.clone()
    }

    /// Stops the signal dispatcher and the agent and drops the callbacks (also done when the object is
    /// collected).
    fn close(&self, py: Python<'_>) {
        self.hub.stop();
        self.hub.clear_callbacks();
        if let Some(agent) = self.take_agent() {
            py.detach(move || agent.shutdown());
        }
    }

    /// Shows Python's garbage collector the callbacks this graph holds: a callback that refers to the graph (the
    /// usual `lambda id, t: g.get_node(id)`) makes a cycle the collector can then break.
    fn __traverse__(&self, visit: pyo3::PyVisit<'_>) -> Result<(), pyo3::PyTraverseError> {
        self.hub.traverse(&visit)
    }

    fn __clear__(&self) {
        self.hub.stop();
        self.hub.clear_callbacks();
    }

    fn __enter__(slf: Py<Self>) -> Py<Self> {
        slf
    }

    fn __exit__(&self, py: Python<'_>, _a: Py<PyAny>, _b: Py<PyAny>, _c: Py<PyAny>) {
        self.close(py);
    }
}

/// The agent behind a graph object, for the rt and inner APIs and the signals.
pub fn agent_of(graph: &Bound<'_, DsrGraph>) -> PyResult<Arc<GraphAgent>> {
    graph.get().agent()
}

/// `signals.connect(g, kind, callback)`: calls `callback` on the agent's signal thread for every change of that
/// kind (see [`crate::signals`]).
#[pyfunction(name = "connect")]
pub fn connect_signal(graph: &Bound<'_, DsrGraph>, kind: SignalType, callback: Bound<'_, PyAny>) -> PyResult<()> {
    let agent = agent_of(graph)?;
    Arc::clone(&graph.get().hub).connect(agent, kind, callback)
}
