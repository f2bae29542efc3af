//! [`GraphAccess`] over a running DSR_d agent, for the role processes: the components of a BICA runtime read the
//! agent's replica under its short read lock (never waiting for the network) and write through the agent's own
//! operations, so every write is stamped by the agent's clock, joined locally and broadcast as deltas to the other
//! agents. The adapter holds only an `Arc` of the agent; [`share_agent`] makes the [`SharedGraph`] a role builder
//! of [`crate::roles`] takes.
//!
//! The `now_ns` the components pass with a write is not used: the agent stamps its operations with its own
//! injected clock, the one its peers' stamps are compared with.

use std::cell::RefCell;
use std::rc::Rc;
use std::sync::Arc;

use agent::{Agent, AgentError};
use dsr::{Dot, NewNode, NodeId, Value, ValueType};
use transport::Transport;

use crate::graph::{GraphAccess, GraphError, SharedGraph};

/// A [`GraphAccess`] adapter over a shared agent.
pub struct AgentGraph<T: Transport + 'static> {
    agent: Arc<Agent<T>>,
}

impl<T: Transport + 'static> std::fmt::Debug for AgentGraph<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("AgentGraph").field("agent", &self.agent.id()).finish()
    }
}

impl<T: Transport + 'static> AgentGraph<T> {
    /// The adapter over `agent`.
    pub fn new(agent: Arc<Agent<T>>) -> Self {
        AgentGraph { agent }
    }

    /// The agent.
    pub fn agent(&self) -> &Arc<Agent<T>> {
        &self.agent
    }
}

/// Wraps an agent into the [`SharedGraph`] the components of one runtime share (build it on the scheduler
/// thread, e.g. inside `bica::Driver::spawn`'s build closure).
pub fn share_agent<T: Transport + 'static>(agent: Arc<Agent<T>>) -> SharedGraph {
    Rc::new(RefCell::new(AgentGraph::new(agent)))
}

fn op_error(operation: impl Into<String>, error: AgentError) -> GraphError {
    GraphError::Op { operation: operation.into(), message: error.to_string() }
}

impl<T: Transport + 'static> GraphAccess for AgentGraph<T> {
    fn find_node(&self, name: &str) -> Option<NodeId> {
        self.agent.read(|r| GraphAccess::find_node(r, name)).flatten()
    }

    fn node_attr(&self, node: NodeId, name: &str) -> Option<Value> {
        self.agent.read(|r| GraphAccess::node_attr(r, node, name)).flatten()
    }

    fn node_attr_dot(&self, node: NodeId, name: &str) -> Option<Dot> {
        self.agent.read(|r| GraphAccess::node_attr_dot(r, node, name)).flatten()
    }

    fn node_type(&self, node: NodeId) -> Option<String> {
        self.agent.read(|r| GraphAccess::node_type(r, node)).flatten()
    }

    fn nodes_of_type(&self, node_type: &str) -> Vec<(NodeId, String)> {
        self.agent.read(|r| GraphAccess::nodes_of_type(r, node_type)).unwrap_or_default()
    }

    fn insert_node(&mut self, _now_ns: u64, node: NewNode) -> Result<NodeId, GraphError> {
        let operation = format!("insert_node {}", node.name);
        self.agent.insert_node(node).map_err(|error| op_error(operation, error))
    }

    fn delete_node(&mut self, _now_ns: u64, node: NodeId) -> Result<(), GraphError> {
        self.agent.delete_node(node).map_err(|error| op_error(format!("delete_node {node:?}"), error))
    }

    fn set_node_attrs(
        &mut self,
        _now_ns: u64,
        node: NodeId,
        attrs: Vec<(&'static str, Value)>,
    ) -> Result<(), GraphError> {
        self.agent.set_attrs(node, attrs).map_err(|error| op_error(format!("set_attrs {node:?}"), error))
    }

    fn set_rt(
        &mut self,
        _now_ns: u64,
        parent: NodeId,
        child: NodeId,
        translation_mm: [f32; 3],
        euler_xyz_rad: [f32; 3],
    ) -> Result<(), GraphError> {
        self.agent
            .set_rt(parent, child, translation_mm, euler_xyz_rad)
            .map_err(|error| op_error(format!("set_rt {parent:?} -> {child:?}"), error))
    }

    fn transform_point(&self, from: NodeId, to: NodeId, point_mm: [f64; 3]) -> Result<[f64; 3], GraphError> {
        self.agent.read(|r| GraphAccess::transform_point(r, from, to, point_mm)).unwrap_or_else(|| {
            Err(GraphError::Transform { from, to, message: format!("{} has not joined a graph yet", self.agent.id()) })
        })
    }

    /// Agents exchanging deltas must agree on the dictionary, so a running agent's dictionary is not changed: the
    /// name must already be known with this type (the perception names are built in) or unknown names allowed.
    fn declare_attr(&mut self, name: &str, value_type: ValueType) -> Result<(), GraphError> {
        let declare = |message: String| GraphError::Declare { name: name.to_owned(), message };
        match self.agent.read(|r| r.dictionary().peek_attr(name, value_type).map_err(|error| error.to_string())) {
            Some(result) => result.map_err(declare),
            None => Err(declare(format!("{} has not joined a graph yet", self.agent.id()))),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::graph::{attrs, declare_perception_attrs};
    use agent::{AgentConfig, AgentId};
    use std::time::Duration;
    use transport::inproc::Bus;
    use transport::{Clock, ManualClock};

    /// Two hand-pumped agents: the components' writes through one appear in the other, reads see the replica.
    #[test]
    fn writes_through_the_adapter_reach_the_other_agent_and_reads_see_the_replica() {
        let bus = Bus::new();
        let clock = ManualClock::new(1_000_000_000);
        let agent = |id: u32| {
            let config = AgentConfig {
                join_wait: Duration::from_millis(10),
                nonce: Some(u64::from(id)),
                // Both start alone at once: one graph, named (each would otherwise create its own).
                graph: agent::GraphId::new(0x9e),
                ..AgentConfig::new(AgentId(id))
            };
            Arc::new(Agent::new(config, bus.attach(1024), Arc::new(clock.clone()) as Arc<dyn Clock>).unwrap())
        };
        let (a, b) = (agent(1), agent(2));
        let pump = || {
            for _ in 0..40 {
                clock.advance(1_000_000);
                a.pump();
                b.pump();
            }
        };
        let graph = share_agent(Arc::clone(&a));
        assert!(graph.borrow().find_node("world").is_none(), "no graph before joining");
        assert!(declare_perception_attrs(&mut *graph.borrow_mut()).is_err(), "not joined yet");
        pump();
        assert!(a.is_ready() && b.is_ready());
        let mut g = graph.borrow_mut();
        declare_perception_attrs(&mut *g).unwrap();
        assert!(g.declare_attr(attrs::TRACK_ID.name(), ValueType::String).is_err(), "type conflict");
        let world = g.insert_node(0, NewNode::new("world", "world")).unwrap();
        let blob = g.insert_node(0, NewNode::new("blob", "blob_1")).unwrap();
        g.set_rt(0, world, blob, [1000.0, 0.0, 0.0], [0.0; 3]).unwrap();
        g.set_node_attrs(0, blob, vec![(attrs::TRACK_ID.name(), Value::U64(7))]).unwrap();
        let dot = g.node_attr_dot(blob, attrs::TRACK_ID.name()).unwrap();
        g.set_node_attrs(0, blob, vec![(attrs::TRACK_ID.name(), Value::U64(8))]).unwrap();
        assert_ne!(g.node_attr_dot(blob, attrs::TRACK_ID.name()), Some(dot), "a new write has a new dot");
        assert_eq!(g.nodes_of_type("blob"), vec![(blob, "blob_1".to_owned())]);
        assert_eq!(g.node_type(blob).as_deref(), Some("blob"));
        assert_eq!(g.transform_point(blob, world, [0.0; 3]).unwrap(), [1000.0, 0.0, 0.0]);
        assert!(g.set_node_attrs(0, blob, vec![("no_such_attribute", Value::U64(1))]).is_err());
        drop(g);
        pump();
        let seen = b.node_by_name("blob_1").expect("the other agent sees the node");
        assert_eq!(seen.attrs.get(attrs::TRACK_ID.name()), Some(&Value::U64(8)));
        assert_eq!(b.read(|r| r.transform_point(blob, world, [0.0; 3]).unwrap()), Some([1000.0, 0.0, 0.0]));
        graph.borrow_mut().delete_node(0, blob).unwrap();
        pump();
        assert!(b.node(blob).is_none());
        assert_eq!(a.digest(), b.digest());
    }
}
