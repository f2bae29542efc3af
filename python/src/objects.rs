//! The value objects of pydsr: `Attribute`, `Node`, `Edge`, and the mutable mappings `Node.attrs`,
//! `Edge.attrs` (name → `Attribute`) and `Node.edges` ((to, type) → `Edge`).
//!
//! They are plain copies, detached from the graph, as in pydsr: `g.get_node` returns a copy, a script changes it
//! (`node.attrs["pos_x"].value = 1.0`) and hands it back with `g.update_node(node)`. A mapping returns the object
//! it holds, so a change through `attrs[k]` changes the mapping's entry; storing (`attrs[k] = a`) stores a copy,
//! as pydsr's `std::map` does.

use std::collections::{BTreeMap, BTreeSet};
use std::sync::Mutex;
use std::sync::atomic::{AtomicU32, Ordering};
use std::time::{SystemTime, UNIX_EPOCH};

use dsr::Value;
use dsr::dictionary::{BUILTIN_EDGE_TYPES, BUILTIN_NODE_TYPES};
use pyo3::exceptions::{PyKeyError, PyRuntimeError, PyTypeError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};

use crate::values;

/// The agent id that `Attribute.value = ...` stamps (pydsr: the id of the last `DSRGraph` made in the process).
pub static LOCAL_AGENT_ID: AtomicU32 = AtomicU32::new(0);

/// Wall-clock nanoseconds, the stamp of an attribute made or changed in Python.
pub fn now_ns() -> u64 {
    SystemTime::now().duration_since(UNIX_EPOCH).map_or(0, |d| d.as_nanos() as u64)
}

/// `Attribute(value, timestamp, agent_id)` or `Attribute(value, agent_id)`: a typed value with the time and the
/// agent of its last write.
#[pyclass(module = "cortex_dsr", name = "Attribute")]
#[derive(Clone)]
pub struct Attribute {
    /// The value (its type fixed at creation).
    pub value: Value,
    /// Nanoseconds of the last write.
    pub timestamp: u64,
    /// The agent of the last write.
    pub agent_id: u32,
}

#[pymethods]
impl Attribute {
    #[new]
    #[pyo3(signature = (value, timestamp = None, agent_id = None))]
    fn new(value: &Bound<'_, PyAny>, timestamp: Option<u64>, agent_id: Option<u32>) -> PyResult<Self> {
        let (timestamp, agent_id) = match (timestamp, agent_id) {
            (Some(timestamp), Some(agent_id)) => (timestamp, agent_id),
            // The two-argument form: `Attribute(value, agent_id)`.
            (Some(agent_id), None) => {
                let agent_id = u32::try_from(agent_id)
                    .map_err(|_| PyTypeError::new_err(format!("agent id {agent_id} does not fit u32")))?;
                (now_ns(), agent_id)
            }
            (None, Some(agent_id)) => (now_ns(), agent_id),
            (None, None) => return Err(PyTypeError::new_err("Attribute(value, agent_id) needs an agent id")),
        };
        Ok(Attribute { value: values::infer(value)?, timestamp, agent_id })
    }

    /// The value: `str`, `int`, `float`, `bool`, or a numpy array for vectors and byte vectors (a copy).
    #[getter]
    fn get_value<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        values::to_python(py, &self.value)
    }

    /// Sets the value (same type only, else `TypeError`); stamps the time and this process's agent id.
    #[setter]
    fn set_value(&mut self, value: &Bound<'_, PyAny>) -> PyResult<()> {
        self.value = values::assign(value, self.value.value_type())?;
        self.timestamp = now_ns();
        self.agent_id = LOCAL_AGENT_ID.load(Ordering::Relaxed);
        Ok(())
    }

    /// The agent of the last write (read-only).
    #[getter]
    fn agent_id(&self) -> u32 {
        self.agent_id
    }

    /// Nanoseconds of the last write (read-only).
    #[getter]
    fn timestamp(&self) -> u64 {
        self.timestamp
    }

    fn __repr__(&self) -> String {
        format!(
            " < {} ({}) by agent {} at {} > ",
            preview(&self.value),
            values::type_name(self.value.value_type()),
            self.agent_id,
            self.timestamp
        )
    }
}

/// A short text form of a value (first elements of a vector).
fn preview(value: &Value) -> String {
    let text = format!("{value:?}");
    match text.char_indices().nth(77) {
        Some((cut, _)) if text.len() > 80 => format!("{}...", &text[..cut]),
        _ => text,
    }
}

/// `Node.attrs` / `Edge.attrs`: a mutable mapping from attribute names to `Attribute`s, in name order.
#[pyclass(module = "cortex_dsr", name = "MapStringAttribute")]
#[derive(Default)]
pub struct AttrMap {
    /// The entries.
    pub entries: BTreeMap<String, Py<Attribute>>,
}

impl AttrMap {
    /// A deep copy (new attribute objects).
    pub fn copy(&self, py: Python<'_>) -> PyResult<AttrMap> {
        let mut entries = BTreeMap::new();
        for (name, attribute) in &self.entries {
            entries.insert(name.clone(), Py::new(py, attribute.borrow(py).clone())?);
        }
        Ok(AttrMap { entries })
    }

    /// The names and values, for a graph write.
    pub fn to_values(&self, py: Python<'_>) -> Vec<(String, Value)> {
        self.entries.iter().map(|(name, attribute)| (name.clone(), attribute.borrow(py).value.clone())).collect()
    }

    /// Stores a copy of `attribute` under `name`, narrowed to the name's type (pydsr's `__setitem__`).
    fn store(&mut self, py: Python<'_>, name: String, attribute: &Attribute) -> PyResult<()> {
        let held = self.entries.get(&name).map(|held| held.borrow(py).value.value_type());
        let value = values::fit_to_name(&name, &attribute.value, held).ok_or_else(|| {
            PyTypeError::new_err(format!(
                "Invalid type for attribute [{name}]. Selected type is: {}",
                values::type_name(attribute.value.value_type())
            ))
        })?;
        let stored = Attribute { value, ..attribute.clone() };
        self.entries.insert(name, Py::new(py, stored)?);
        Ok(())
    }

    /// An attribute map made from a Python mapping of names to `Attribute`s (another map or a dict).
    pub fn from_mapping(py: Python<'_>, mapping: &Bound<'_, PyAny>) -> PyResult<AttrMap> {
        if let Ok(map) = mapping.cast::<AttrMap>() {
            return map.borrow().copy(py);
        }
        let dict = mapping
            .cast::<PyDict>()
            .map_err(|_| PyTypeError::new_err("attrs must be a mapping of str to Attribute"))?;
        let mut map = AttrMap::default();
        for (name, attribute) in dict.iter() {
            let attribute = attribute.cast::<Attribute>()?.borrow();
            map.store(py, name.extract()?, &attribute)?;
        }
        Ok(map)
    }
}

/// The `#[pymethods]` of a mapping class: the methods both maps share (pydsr's bound `std::map`: `[]`, `in`,
/// `len`, `del`, iteration over keys, `keys`, `values`, `items`, `get`, `clear`; `KeyError` for a missing key),
/// then the class's own (`__new__`, `__setitem__`, ...).
macro_rules! mapping_methods {
    ($map:ty, $key:ty, $value:ty, { $($own:tt)* }) => {
        #[pymethods]
        impl $map {
            fn __getitem__(&self, py: Python<'_>, key: $key) -> PyResult<Py<$value>> {
                self.entries.get(&key).map(|v| v.clone_ref(py)).ok_or_else(|| PyKeyError::new_err(key))
            }

            fn __delitem__(&mut self, key: $key) -> PyResult<()> {
                self.entries.remove(&key).map(drop).ok_or_else(|| PyKeyError::new_err(key))
            }

            fn __contains__(&self, key: $key) -> bool {
                self.entries.contains_key(&key)
            }

            fn __len__(&self) -> usize {
                self.entries.len()
            }

            fn __iter__<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
                self.keys(py)?.try_iter().map(Bound::into_any)
            }

            fn keys<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyList>> {
                PyList::new(py, self.entries.keys())
            }

            fn values<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyList>> {
                PyList::new(py, self.entries.values().map(|v| v.clone_ref(py)))
            }

            fn items<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyList>> {
                PyList::new(py, self.entries.iter().map(|(k, v)| (k.clone(), v.clone_ref(py))))
            }

            #[pyo3(signature = (key, default = None))]
            fn get(&self, py: Python<'_>, key: $key, default: Option<Py<PyAny>>) -> Option<Py<PyAny>> {
                self.entries.get(&key).map(|v| v.clone_ref(py).into_any()).or(default)
            }

            fn clear(&mut self) {
                self.entries.clear();
            }

            $($own)*
        }
    };
}

mapping_methods!(AttrMap, String, Attribute, {
    #[new]
    fn py_new() -> Self {
        AttrMap::default()
    }

    fn __setitem__(&mut self, py: Python<'_>, name: String, attribute: PyRef<'_, Attribute>) -> PyResult<()> {
        self.store(py, name, &attribute)
    }

    fn __repr__(&self, py: Python<'_>) -> String {
        self.entries.iter().map(|(k, a)| format!("      [{k}] -- {}\n", a.borrow(py).__repr__())).collect()
    }
});

/// `Edge(to, from, type, agent_id)` (pydsr's argument order): an edge copy with its attributes.
#[pyclass(module = "cortex_dsr", name = "Edge")]
pub struct Edge {
    /// Destination node.
    pub to: u64,
    /// Source node.
    pub from: u64,
    /// Edge type.
    pub edge_type: String,
    /// The agent of the last write.
    #[pyo3(get, set)]
    pub agent_id: u32,
    /// Its attributes (a live mapping: changes to it change this object).
    #[pyo3(get)]
    pub attrs: Py<AttrMap>,
}

/// Node and edge types met in the graphs of this process beyond the built-in ones (a CORTEX file may bring its
/// own), so that `Node(...)` and `Edge(...)` accept every type a graph of the process holds.
static GRAPH_TYPES: Mutex<BTreeSet<(bool, String)>> = Mutex::new(BTreeSet::new());

/// Records a node (`is_node`) or edge type that a graph holds.
pub fn learn_type(is_node: bool, name: &str) {
    let known = if is_node { BUILTIN_NODE_TYPES } else { BUILTIN_EDGE_TYPES };
    if !known.contains(&name) {
        GRAPH_TYPES.lock().unwrap_or_else(|p| p.into_inner()).insert((is_node, name.to_owned()));
    }
}

/// Refuses a node or edge type that is neither built in nor held by a graph of this process, as pydsr's
/// constructors refuse unregistered types.
fn check_type(is_node: bool, name: &str) -> PyResult<()> {
    let known = if is_node { BUILTIN_NODE_TYPES } else { BUILTIN_EDGE_TYPES };
    if known.contains(&name)
        || GRAPH_TYPES.lock().unwrap_or_else(|p| p.into_inner()).contains(&(is_node, name.to_owned()))
    {
        return Ok(());
    }
    let what = if is_node { "node" } else { "edge" };
    Err(PyRuntimeError::new_err(format!("Error, \"{name}\" is not a valid {what} type")))
}

impl Edge {
    /// An edge object with the given attributes.
    pub fn build(
        py: Python<'_>,
        from: u64,
        to: u64,
        edge_type: String,
        agent_id: u32,
        attrs: AttrMap,
    ) -> PyResult<Edge> {
        Ok(Edge { to, from, edge_type, agent_id, attrs: Py::new(py, attrs)? })
    }

    /// A deep copy.
    pub fn copy(&self, py: Python<'_>) -> PyResult<Edge> {
        Edge::build(py, self.from, self.to, self.edge_type.clone(), self.agent_id, self.attrs.borrow(py).copy(py)?)
    }
}

#[pymethods]
impl Edge {
    #[new]
    #[pyo3(signature = (to, r#from, r#type, agent_id))]
    fn py_new(py: Python<'_>, to: u64, r#from: u64, r#type: String, agent_id: u32) -> PyResult<Self> {
        check_type(false, &r#type)?;
        Edge::build(py, r#from, to, r#type, agent_id, AttrMap::default())
    }

    /// The edge type (read-only).
    #[getter(r#type)]
    fn edge_type(&self) -> &str {
        &self.edge_type
    }

    /// The source node id (read-only).
    #[getter]
    fn origin(&self) -> u64 {
        self.from
    }

    /// The destination node id (read-only).
    #[getter]
    fn destination(&self) -> u64 {
        self.to
    }

    #[setter]
    fn set_attrs(&mut self, py: Python<'_>, attrs: &Bound<'_, PyAny>) -> PyResult<()> {
        self.attrs = Py::new(py, AttrMap::from_mapping(py, attrs)?)?;
        Ok(())
    }

    fn __repr__(&self, py: Python<'_>) -> String {
        format!(
            "------------------------------------\nType: {} from: {} to: {}\n{}------------------------------------\n",
            self.edge_type,
            self.from,
            self.to,
            self.attrs.borrow(py).__repr__(py)
        )
    }
}

/// `Node.edges`: a mutable mapping from `(to, type)` to the node's outgoing `Edge`s.
#[pyclass(module = "cortex_dsr", name = "MapStringEdge")]
#[derive(Default)]
pub struct EdgeMap {
    /// The entries.
    pub entries: BTreeMap<(u64, String), Py<Edge>>,
}

impl EdgeMap {
    /// A deep copy.
    pub fn copy(&self, py: Python<'_>) -> PyResult<EdgeMap> {
        let mut entries = BTreeMap::new();
        for (key, edge) in &self.entries {
            entries.insert(key.clone(), Py::new(py, edge.borrow(py).copy(py)?)?);
        }
        Ok(EdgeMap { entries })
    }

    fn from_mapping(py: Python<'_>, mapping: &Bound<'_, PyAny>) -> PyResult<EdgeMap> {
        if let Ok(map) = mapping.cast::<EdgeMap>() {
            return map.borrow().copy(py);
        }
        let dict = mapping
            .cast::<PyDict>()
            .map_err(|_| PyTypeError::new_err("edges must be a mapping of (to, type) to Edge"))?;
        let mut map = EdgeMap::default();
        for (key, edge) in dict.iter() {
            map.entries.insert(key.extract()?, Py::new(py, edge.cast::<Edge>()?.borrow().copy(py)?)?);
        }
        Ok(map)
    }
}

mapping_methods!(EdgeMap, (u64, String), Edge, {
    #[new]
    fn py_new() -> Self {
        EdgeMap::default()
    }

    fn __setitem__(&mut self, py: Python<'_>, key: (u64, String), edge: PyRef<'_, Edge>) -> PyResult<()> {
        self.entries.insert(key, Py::new(py, edge.copy(py)?)?);
        Ok(())
    }
});

/// `Node(agent_id, type, name="")`: a node copy with its attributes and outgoing edges.
#[pyclass(module = "cortex_dsr", name = "Node")]
pub struct Node {
    /// Its id (0 until inserted).
    pub id: u64,
    /// Node type.
    pub node_type: String,
    /// Node name ("" lets `insert_node` choose one).
    pub name: String,
    /// The agent of the last write.
    #[pyo3(get, set)]
    pub agent_id: u32,
    /// Its attributes (a live mapping: changes to it change this object).
    #[pyo3(get)]
    pub attrs: Py<AttrMap>,
    /// Its outgoing edges, keyed by `(to, type)` (a live mapping).
    #[pyo3(get)]
    pub edges: Py<EdgeMap>,
}

impl Node {
    /// A node object with the given contents.
    pub fn build(
        py: Python<'_>,
        id: u64,
        node_type: String,
        name: String,
        agent_id: u32,
        attrs: AttrMap,
        edges: EdgeMap,
    ) -> PyResult<Node> {
        Ok(Node { id, node_type, name, agent_id, attrs: Py::new(py, attrs)?, edges: Py::new(py, edges)? })
    }
}

#[pymethods]
impl Node {
    #[new]
    #[pyo3(signature = (agent_id, r#type, name = String::new()))]
    fn py_new(py: Python<'_>, agent_id: u32, r#type: String, name: String) -> PyResult<Self> {
        check_type(true, &r#type)?;
        Node::build(py, 0, r#type, name, agent_id, AttrMap::default(), EdgeMap::default())
    }

    /// The node id (read-only; set by `insert_node`).
    #[getter]
    fn id(&self) -> u64 {
        self.id
    }

    /// The node name (read-only).
    #[getter]
    fn name(&self) -> &str {
        &self.name
    }

    /// The node type (read-only).
    #[getter(r#type)]
    fn node_type(&self) -> &str {
        &self.node_type
    }

    #[setter]
    fn set_attrs(&mut self, py: Python<'_>, attrs: &Bound<'_, PyAny>) -> PyResult<()> {
        self.attrs = Py::new(py, AttrMap::from_mapping(py, attrs)?)?;
        Ok(())
    }

    #[setter]
    fn set_edges(&mut self, py: Python<'_>, edges: &Bound<'_, PyAny>) -> PyResult<()> {
        self.edges = Py::new(py, EdgeMap::from_mapping(py, edges)?)?;
        Ok(())
    }

    fn __repr__(&self, py: Python<'_>) -> String {
        let mut out = format!(
            "------------------------------------\nNode: {}\n  Type: {}\n  Name: {}\n  Agent id: {}\n  ATTRIBUTES: [\n",
            self.id, self.node_type, self.name, self.agent_id
        );
        out.push_str(&self.attrs.borrow(py).__repr__(py));
        out.push_str("   ]\n  EDGES: [\n");
        for edge in self.edges.borrow(py).entries.values() {
            let edge = edge.borrow(py);
            out.push_str(&format!("          Edge type: {} from: {} to: {}\n", edge.edge_type, edge.from, edge.to));
        }
        out.push_str("          ]\n------------------------------------\n");
        out
    }
}
