//! The graph access the perception components need, as a trait, so the same components run on a bare
//! [`dsr::Replica`] in tests and on an agent's thread-safe replica (which also broadcasts the deltas) in the role
//! processes. Components hold a [`SharedGraph`]: they run on the single BICA scheduler thread, so an
//! `Rc<RefCell<_>>` is enough; an agent implements [`GraphAccess`] on a small adapter that locks its replica and
//! sends the resulting deltas ([`crate::agent_graph::AgentGraph`]).
//!
//! Units follow the dictionary: translations in mm, angles in rad.

use std::cell::RefCell;
use std::rc::Rc;

use dsr::{AttrKey, AttrType, Dictionary, Dot, NewNode, NodeId, Replica, Value, ValueType};

/// Why a graph operation failed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GraphError {
    /// The replica refused a local operation.
    #[error("graph operation `{operation}` failed: {message}")]
    Op {
        /// Which operation (e.g. `insert_node obstacle_3`).
        operation: String,
        /// What the replica said.
        message: String,
    },
    /// A transform between two nodes could not be computed.
    #[error("no transform from node {from:?} to node {to:?}: {message}")]
    Transform {
        /// Source frame.
        from: NodeId,
        /// Target frame.
        to: NodeId,
        /// What the kinematics said.
        message: String,
    },
    /// A name could not be declared in the dictionary.
    #[error("cannot declare attribute `{name}`: {message}")]
    Declare {
        /// The attribute name.
        name: String,
        /// What the dictionary said.
        message: String,
    },
}

/// What perception components read from and write to the shared graph. Every write takes the caller's time
/// (`now_ns`, from the BICA clock), as [`dsr::Replica`] does.
///
/// Implementations for a networked agent must send the deltas each write produces; reads see the local replica.
pub trait GraphAccess {
    /// The id of the visible node called `name`.
    fn find_node(&self, name: &str) -> Option<NodeId>;

    /// The winning value of attribute `name` of node `node` (cheap: buffers are shared).
    fn node_attr(&self, node: NodeId, name: &str) -> Option<Value>;

    /// The dot of the winning write of attribute `name` of node `node`: it changes with every write, so readers
    /// use it to tell a new reading from the same one read again.
    fn node_attr_dot(&self, node: NodeId, name: &str) -> Option<Dot>;

    /// The type of node `node`, if visible.
    fn node_type(&self, node: NodeId) -> Option<String>;

    /// Visible nodes of type `node_type`, with their names, in id order.
    fn nodes_of_type(&self, node_type: &str) -> Vec<(NodeId, String)>;

    /// Inserts a node.
    ///
    /// # Errors
    /// [`GraphError::Op`] if the replica refuses it (name taken, unknown type or attribute).
    fn insert_node(&mut self, now_ns: u64, node: NewNode) -> Result<NodeId, GraphError>;

    /// Deletes a node and its edges.
    ///
    /// # Errors
    /// [`GraphError::Op`] if the node is not visible.
    fn delete_node(&mut self, now_ns: u64, node: NodeId) -> Result<(), GraphError>;

    /// Writes attributes of a node as one operation.
    ///
    /// # Errors
    /// [`GraphError::Op`] if the node is not visible or the dictionary refuses a name or type.
    fn set_node_attrs(
        &mut self,
        now_ns: u64,
        node: NodeId,
        attrs: Vec<(&'static str, Value)>,
    ) -> Result<(), GraphError>;

    /// Places `child` under `parent` with an RT edge (or moves it): translation in mm, Euler x y z in rad.
    ///
    /// # Errors
    /// [`GraphError::Op`] if a node is missing.
    fn set_rt(
        &mut self,
        now_ns: u64,
        parent: NodeId,
        child: NodeId,
        translation_mm: [f32; 3],
        euler_xyz_rad: [f32; 3],
    ) -> Result<(), GraphError>;

    /// Maps a point (mm) from `from`'s frame to `to`'s frame through the RT tree.
    ///
    /// # Errors
    /// [`GraphError::Transform`] if the nodes are not connected or an RT edge is malformed.
    fn transform_point(&self, from: NodeId, to: NodeId, point_mm: [f64; 3]) -> Result<[f64; 3], GraphError>;

    /// Declares an attribute name outside the built-in dictionary. Every agent exchanging deltas must declare
    /// the same names (see [`declare_perception_attrs`]).
    ///
    /// # Errors
    /// [`GraphError::Declare`] if the name is known with another type.
    fn declare_attr(&mut self, name: &str, value_type: ValueType) -> Result<(), GraphError>;
}

impl dyn GraphAccess + '_ {
    /// Reads a typed attribute; `None` if missing or of another type.
    pub fn get<T: AttrType>(&self, node: NodeId, key: AttrKey<T>) -> Option<T> {
        self.node_attr(node, key.name()).and_then(|value| T::from_value(&value))
    }
}

impl std::fmt::Debug for dyn GraphAccess + '_ {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("GraphAccess")
    }
}

/// A graph handle shared by the components of one BICA runtime (all on the scheduler thread).
pub type SharedGraph = Rc<RefCell<dyn GraphAccess>>;

/// Wraps a replica into a [`SharedGraph`], returning the typed handle too so tests can inspect the replica.
pub fn share_replica(replica: Replica) -> (Rc<RefCell<Replica>>, SharedGraph) {
    let typed = Rc::new(RefCell::new(replica));
    let shared: SharedGraph = typed.clone();
    (typed, shared)
}

fn op_error(operation: impl Into<String>, error: impl std::fmt::Display) -> GraphError {
    GraphError::Op { operation: operation.into(), message: error.to_string() }
}

/// A bare replica: deltas are produced and dropped (there is nobody to send them to). Used in-process by tests
/// and by single-process simulations.
impl GraphAccess for Replica {
    fn find_node(&self, name: &str) -> Option<NodeId> {
        self.node_by_name(name).map(|node| node.id())
    }

    fn node_attr(&self, node: NodeId, name: &str) -> Option<Value> {
        self.node(node).and_then(|node| node.attr(name).cloned())
    }

    fn node_attr_dot(&self, node: NodeId, name: &str) -> Option<Dot> {
        self.node(node).and_then(|node| node.attr_entry(name).map(|entry| entry.dot))
    }

    fn node_type(&self, node: NodeId) -> Option<String> {
        self.node(node).map(|node| node.node_type().to_owned())
    }

    fn nodes_of_type(&self, node_type: &str) -> Vec<(NodeId, String)> {
        let mut found: Vec<(NodeId, String)> = self
            .nodes()
            .filter(|node| node.node_type() == node_type)
            .map(|node| (node.id(), node.name().into_owned()))
            .collect();
        found.sort_by_key(|(id, _)| *id);
        found
    }

    fn insert_node(&mut self, now_ns: u64, node: NewNode) -> Result<NodeId, GraphError> {
        let operation = format!("insert_node {}", node.name);
        Replica::insert_node(self, now_ns, node).map(|(id, _)| id).map_err(|error| op_error(operation, error))
    }

    fn delete_node(&mut self, now_ns: u64, node: NodeId) -> Result<(), GraphError> {
        Replica::delete_node(self, now_ns, node)
            .map(drop)
            .map_err(|error| op_error(format!("delete_node {node:?}"), error))
    }

    fn set_node_attrs(
        &mut self,
        now_ns: u64,
        node: NodeId,
        attrs: Vec<(&'static str, Value)>,
    ) -> Result<(), GraphError> {
        self.set_attrs(now_ns, node, attrs).map(drop).map_err(|error| op_error(format!("set_attrs {node:?}"), error))
    }

    fn set_rt(
        &mut self,
        now_ns: u64,
        parent: NodeId,
        child: NodeId,
        translation_mm: [f32; 3],
        euler_xyz_rad: [f32; 3],
    ) -> Result<(), GraphError> {
        Replica::set_rt(self, now_ns, parent, child, translation_mm, euler_xyz_rad)
            .map(drop)
            .map_err(|error| op_error(format!("set_rt {parent:?} -> {child:?}"), error))
    }

    fn transform_point(&self, from: NodeId, to: NodeId, point_mm: [f64; 3]) -> Result<[f64; 3], GraphError> {
        Replica::transform_point(self, from, to, point_mm).map_err(|error| GraphError::Transform {
            from,
            to,
            message: error.to_string(),
        })
    }

    fn declare_attr(&mut self, name: &str, value_type: ValueType) -> Result<(), GraphError> {
        self.dictionary_mut()
            .declare_attr(name, value_type)
            .map_err(|error| GraphError::Declare { name: name.to_owned(), message: error.to_string() })
    }
}

/// The detection and track attributes the perception components write. They are part of the built-in dictionary of
/// `dsr`, so every agent agrees on their types without declaring them.
pub mod attrs {
    pub use dsr::attrs::{BLOB_AREA_PX, BLOB_CLASS, TRACK_COVARIANCE_MM2, TRACK_ID, TRACK_VELOCITY_MM_S};
}

/// Declares the names in [`attrs`] in a dictionary (for agents that build their replica themselves).
///
/// # Errors
/// [`GraphError::Declare`] if a name is already known with another type.
pub fn declare_in_dictionary(dictionary: &mut Dictionary) -> Result<(), GraphError> {
    for (name, value_type) in perception_attr_types() {
        dictionary
            .declare_attr(name, value_type)
            .map_err(|error| GraphError::Declare { name: name.to_owned(), message: error.to_string() })?;
    }
    Ok(())
}

/// Declares the names in [`attrs`] through a graph handle.
///
/// # Errors
/// As [`declare_in_dictionary`].
pub fn declare_perception_attrs(graph: &mut dyn GraphAccess) -> Result<(), GraphError> {
    for (name, value_type) in perception_attr_types() {
        graph.declare_attr(name, value_type)?;
    }
    Ok(())
}

fn perception_attr_types() -> [(&'static str, ValueType); 5] {
    [
        (attrs::TRACK_COVARIANCE_MM2.name(), attrs::TRACK_COVARIANCE_MM2.value_type()),
        (attrs::TRACK_VELOCITY_MM_S.name(), attrs::TRACK_VELOCITY_MM_S.value_type()),
        (attrs::TRACK_ID.name(), attrs::TRACK_ID.value_type()),
        (attrs::BLOB_CLASS.name(), attrs::BLOB_CLASS.value_type()),
        (attrs::BLOB_AREA_PX.name(), attrs::BLOB_AREA_PX.value_type()),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;
    use dsr::ReplicaId;

    #[test]
    fn replica_implements_the_trait_and_declares_names() {
        let (replica, graph) = share_replica(Replica::new(ReplicaId(1)));
        let mut g = graph.borrow_mut();
        declare_perception_attrs(&mut *g).unwrap();
        let world = g.insert_node(1, NewNode::new("world", "world")).unwrap();
        let obstacle = g.insert_node(2, NewNode::new("obstacle", "obstacle_1")).unwrap();
        g.set_rt(3, world, obstacle, [1000.0, 0.0, 0.0], [0.0; 3]).unwrap();
        g.set_node_attrs(4, obstacle, vec![(attrs::TRACK_ID.name(), Value::U64(7))]).unwrap();
        assert_eq!(g.get(obstacle, attrs::TRACK_ID), Some(7));
        assert_eq!(g.find_node("obstacle_1"), Some(obstacle));
        assert_eq!(g.nodes_of_type("obstacle"), vec![(obstacle, "obstacle_1".to_owned())]);
        assert_eq!(g.transform_point(obstacle, world, [0.0; 3]).unwrap(), [1000.0, 0.0, 0.0]);
        assert!(g.set_node_attrs(5, obstacle, vec![("no_such_attribute", Value::U64(1))]).is_err());
        g.delete_node(6, obstacle).unwrap();
        drop(g);
        assert!(replica.borrow().node(obstacle).is_none());
    }
}
