//! The agent's local operations: each runs on the replica under the lock (through the core, which refuses it when
//! the agent has no graph, saw an id collision or is read-only), and its deltas are published after the lock is
//! released.

use std::sync::Arc;

use dsr::{AttrKey, AttrType, Delta, EdgeKey, Element, NewNode, NodeId, OpError, Replica, Value};
use transport::Transport;

use super::{Agent, AgentError};
use crate::core::WriteRefusal;

impl<T: Transport + 'static> Agent<T> {
    fn write<R>(
        &self,
        op: impl FnOnce(&mut Replica, u64) -> Result<(R, Arc<Delta>), OpError>,
    ) -> Result<R, AgentError> {
        self.write_deltas(|r, now| op(r, now).map(|(result, delta)| (result, vec![delta])))
    }

    /// A local operation that makes several deltas (each is published).
    fn write_deltas<R>(
        &self,
        op: impl FnOnce(&mut Replica, u64) -> Result<(R, Vec<Arc<Delta>>), OpError>,
    ) -> Result<R, AgentError> {
        let agent = self.inner.config.id;
        let now = self.inner.clock.now_ns();
        let (written, earlier) = {
            let mut locked = self.inner.lock();
            let written = locked.core.write(now, op);
            (written, self.inner.timer.schedule(locked.core.next_deadline_ns()))
        };
        let (result, written) = written.map_err(|refusal| match refusal {
            WriteRefusal::ReadOnly => AgentError::ReadOnly(agent),
            WriteRefusal::NotJoined => AgentError::NotJoined(agent),
            WriteRefusal::Collision(detail) => AgentError::IdCollision { agent, detail },
            WriteRefusal::Op(source) => AgentError::Op { agent, source },
        })?;
        // Encoded here, with the lock released.
        self.inner.publish_written(&written);
        self.inner.signal(written.changes);
        if earlier {
            // On the bell, or on the transport where the thread waits there.
            self.inner.timer.ring();
            self.inner.transport.interrupt();
        }
        Ok(result)
    }

    /// Runs several local operations at once on the agent's replica (a log bridge, a batch import) and publishes
    /// every delta `op` returns, after the lock is released. `op` gets the replica and the agent clock's `now_ns`;
    /// keep it short: it holds the lock readers wait on.
    ///
    /// # Errors
    /// [`AgentError`]: not joined, or an id collision.
    pub fn update<R>(&self, op: impl FnOnce(&mut Replica, u64) -> (R, Vec<Arc<Delta>>)) -> Result<R, AgentError> {
        self.write_deltas(|replica, now| Ok(op(replica, now)))
    }

    /// Inserts a node; returns its id.
    ///
    /// # Errors
    /// [`AgentError`]: not joined, id collision, or the replica refused it.
    pub fn insert_node(&self, node: NewNode) -> Result<NodeId, AgentError> {
        self.write(|r, now| r.insert_node(now, node))
    }

    /// Deletes a node (and hides its edges).
    ///
    /// # Errors
    /// As [`Agent::insert_node`].
    pub fn delete_node(&self, id: NodeId) -> Result<(), AgentError> {
        self.write(|r, now| r.delete_node(now, id).map(|d| ((), d)))
    }

    /// Inserts an edge with attributes; returns its key.
    ///
    /// # Errors
    /// As [`Agent::insert_node`].
    pub fn insert_edge(
        &self,
        from: NodeId,
        to: NodeId,
        edge_type: &str,
        attrs: Vec<(String, Value)>,
    ) -> Result<EdgeKey, AgentError> {
        self.write(|r, now| r.insert_edge(now, from, to, edge_type, attrs))
    }

    /// Deletes an edge.
    ///
    /// # Errors
    /// As [`Agent::insert_node`].
    pub fn delete_edge(&self, key: &EdgeKey) -> Result<(), AgentError> {
        self.write(|r, now| r.delete_edge(now, key).map(|d| ((), d)))
    }

    /// Writes one attribute with a typed key.
    ///
    /// # Errors
    /// As [`Agent::insert_node`].
    pub fn set_attr<V: AttrType>(
        &self,
        element: impl Into<Element>,
        key: AttrKey<V>,
        value: impl Into<V>,
    ) -> Result<(), AgentError> {
        self.write(|r, now| r.set_attr(now, element, key, value).map(|d| ((), d)))
    }

    /// Writes several attributes as one delta.
    ///
    /// # Errors
    /// As [`Agent::insert_node`].
    pub fn set_attrs<'n>(
        &self,
        element: impl Into<Element>,
        attrs: impl IntoIterator<Item = (&'n str, Value)>,
    ) -> Result<(), AgentError> {
        self.write(|r, now| r.set_attrs(now, element, attrs).map(|d| ((), d)))
    }

    /// Removes an attribute.
    ///
    /// # Errors
    /// As [`Agent::insert_node`].
    pub fn remove_attr(&self, element: impl Into<Element>, name: &str) -> Result<(), AgentError> {
        self.write(|r, now| r.remove_attr(now, element, name).map(|d| ((), d)))
    }

    /// Places `child` under `parent` with an RT edge (inserting or moving it): translation in mm, Euler x y z in
    /// rad (`dsr::Replica::set_rt`; its deltas are published in order).
    ///
    /// # Errors
    /// As [`Agent::insert_node`].
    pub fn set_rt(
        &self,
        parent: NodeId,
        child: NodeId,
        translation_mm: [f32; 3],
        euler_xyz_rad: [f32; 3],
    ) -> Result<(), AgentError> {
        self.write_deltas(|r, now| r.set_rt(now, parent, child, translation_mm, euler_xyz_rad).map(|d| ((), d)))
    }
}
