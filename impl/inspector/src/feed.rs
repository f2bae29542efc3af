//! The inspector's only contact with the agent API: [`GraphFeed`], implemented for [`agent::Agent`] over any
//! transport. Everything else in the crate reads the graph, receives change signals and makes edits through this
//! trait, so a change of the agent API touches this file alone.

use std::time::Duration;

use agent::{Agent, ChangeSignal};
use crossbeam_channel::{Receiver, RecvTimeoutError};
use dsr::{Change, EdgeKey, Element, NewNode, NodeId, Replica, Value};
use transport::Transport;

/// One edit requested from the page; applied through the normal agent API, so it replicates like any other.
#[derive(Clone, Debug, PartialEq)]
pub enum Edit {
    /// Write one attribute of a node or an edge.
    SetAttr {
        /// The element.
        element: Element,
        /// The attribute name.
        name: String,
        /// The new value.
        value: Value,
    },
    /// Write several attributes of one element as one operation.
    SetAttrs {
        /// The element.
        element: Element,
        /// Names and values.
        attrs: Vec<(String, Value)>,
    },
    /// Remove one attribute.
    RemoveAttr {
        /// The element.
        element: Element,
        /// The attribute name.
        name: String,
    },
    /// Insert a node.
    InsertNode {
        /// Its type.
        node_type: String,
        /// Its name.
        name: String,
    },
    /// Delete a node (and its edges).
    DeleteNode {
        /// The node.
        id: NodeId,
    },
    /// Insert an edge without attributes.
    InsertEdge {
        /// The edge.
        key: EdgeKey,
    },
    /// Delete an edge.
    DeleteEdge {
        /// The edge.
        key: EdgeKey,
    },
}

/// What an accepted edit created, if anything.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum EditOutcome {
    /// Done; nothing new to name.
    Done,
    /// A node was inserted with this id.
    Node(NodeId),
}

/// What the next change signal is.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Next {
    /// A visible change.
    Change(Change),
    /// Nothing arrived within the timeout.
    Timeout,
    /// The feed has gone (the agent was dropped).
    Closed,
}

/// A subscription to change signals (bounded; a subscriber that falls behind loses signals, counted by the agent).
#[derive(Debug)]
pub struct ChangeStream(Receiver<ChangeSignal>);

impl ChangeStream {
    /// Waits up to `timeout` for the next change.
    pub fn next(&self, timeout: Duration) -> Next {
        match self.0.recv_timeout(timeout) {
            Ok(signal) => Next::Change(signal.change),
            Err(RecvTimeoutError::Timeout) => Next::Timeout,
            Err(RecvTimeoutError::Disconnected) => Next::Closed,
        }
    }

    /// The next change if one is waiting.
    pub fn try_next(&self) -> Option<Change> {
        self.0.try_recv().ok().map(|signal| signal.change)
    }
}

/// A short summary of the agent for the page's header.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct FeedStatus {
    /// "agent N".
    pub agent: String,
    /// Whether the agent has its graph.
    pub ready: bool,
    /// The graph id (16 hex digits), once known.
    pub graph: Option<String>,
    /// Messages of other graphs on the same domain and prefix refused.
    pub foreign_refused: u64,
    /// Visible nodes.
    pub nodes: usize,
    /// Visible edges.
    pub edges: usize,
    /// Peers heard from.
    pub peers: Vec<u32>,
    /// Change signals the agent dropped because a subscriber was full (all subscribers).
    pub signals_dropped: u64,
    /// An id collision, if any.
    pub collision: Option<String>,
}

/// The graph as the inspector sees it: reads under the agent's short lock, change signals, edits.
pub trait GraphFeed: Send + Sync + 'static {
    /// Runs `f` on the replica; returns false (without calling `f`) before the agent has its graph.
    fn read(&self, f: &mut dyn FnMut(&Replica)) -> bool;

    /// A new subscription holding at most `capacity` undelivered signals.
    fn changes(&self, capacity: usize) -> ChangeStream;

    /// Applies an edit through the agent API.
    ///
    /// # Errors
    /// The agent's error, as text (it names the agent and what the replica refused).
    fn edit(&self, edit: Edit) -> Result<EditOutcome, String>;

    /// Status for the page header.
    fn status(&self) -> FeedStatus;
}

impl<T: Transport + 'static> GraphFeed for Agent<T> {
    fn read(&self, f: &mut dyn FnMut(&Replica)) -> bool {
        Agent::read(self, |replica| f(replica)).is_some()
    }

    fn changes(&self, capacity: usize) -> ChangeStream {
        ChangeStream(self.subscribe(capacity))
    }

    fn edit(&self, edit: Edit) -> Result<EditOutcome, String> {
        let result = match edit {
            Edit::SetAttr { element, name, value } => {
                self.set_attrs(element, [(name.as_str(), value)]).map(|()| EditOutcome::Done)
            }
            Edit::SetAttrs { element, attrs } => {
                self.set_attrs(element, attrs.iter().map(|(n, v)| (n.as_str(), v.clone()))).map(|()| EditOutcome::Done)
            }
            Edit::RemoveAttr { element, name } => self.remove_attr(element, &name).map(|()| EditOutcome::Done),
            Edit::InsertNode { node_type, name } => {
                self.insert_node(NewNode::new(&node_type, &name)).map(EditOutcome::Node)
            }
            Edit::DeleteNode { id } => self.delete_node(id).map(|()| EditOutcome::Done),
            Edit::InsertEdge { key } => {
                self.insert_edge(key.from, key.to, key.edge_type.as_str(), Vec::new()).map(|_| EditOutcome::Done)
            }
            Edit::DeleteEdge { key } => self.delete_edge(&key).map(|()| EditOutcome::Done),
        };
        result.map_err(|error| error.to_string())
    }

    fn status(&self) -> FeedStatus {
        let status = Agent::status(self);
        FeedStatus {
            agent: status.id.to_string(),
            ready: status.ready,
            graph: status.graph.map(|graph| graph.to_string()),
            foreign_refused: status.foreign_refused,
            nodes: status.nodes,
            edges: status.edges,
            peers: status.peers.iter().map(|p| p.0).collect(),
            signals_dropped: status.signals_dropped,
            collision: status.collision,
        }
    }
}
