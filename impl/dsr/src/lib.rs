//! # DSR_d: a distributed working memory as a delta-state CRDT
//!
//! A directed graph of typed nodes and edges with typed attributes, replicated among agents. Each agent owns a
//! [`Replica`]: a pure state machine that takes local operations and received [`Delta`]s and returns deltas to
//! send. It opens no socket, spawns no thread, reads no clock and touches no file: timestamps come in as arguments
//! (`now_ns`). Transports, threads and files are adapters around it, so the same code runs under the Stateright
//! model checker, in a seeded simulator and over DDS.
//!
//! ```
//! use dsr::{NewNode, Replica, ReplicaId, attrs};
//!
//! let mut a = Replica::new(ReplicaId(1));
//! let mut b = Replica::new(ReplicaId(2));
//! let (world, d1) = a.insert_node(1, NewNode::new("world", "world")).unwrap();
//! let (robot, d2) = a.insert_node(2, NewNode::new("omnirobot", "robot")).unwrap();
//! let (rt, d3) = a
//!     .insert_edge(3, world, robot, "RT", vec![
//!         ("rt_translation".into(), vec![1000.0f32, 0.0, 0.0].into()),
//!         ("rt_rotation_euler_xyz".into(), vec![0.0f32, 0.0, 0.0].into()),
//!     ])
//!     .unwrap();
//! // Deltas may arrive in any order, any number of times.
//! for delta in [&d3, &d1, &d2, &d1] {
//!     b.apply(&dsr::Delta::decode(&delta.encode()).unwrap()).unwrap();
//! }
//! assert_eq!(a.digest(), b.digest());
//! let p = b.transform_point(robot, world, [0.0, 0.0, 0.0]).unwrap();
//! assert_eq!(p, [1000.0, 0.0, 0.0]);
//! # let _ = (rt, attrs::LEVEL);
//! ```
//!
//! # Specification
//!
//! This is what the code does and what the model (`model/`) checks. "Visible" means returned by the read API.
//!
//! **State.** A replica state is a causal CRDT: a dot store ([`store::Store`]) plus a causal context
//! ([`CausalContext`]), the set of dots (replica id, counter) it has seen. A dot in the context but not in the store
//! has been removed. Deleted node ids form a separate grow-only set of tombstones.
//!
//! **Join.** A value survives a join if both sides hold its dot, or one side holds it and the other side's context
//! has not seen it; contexts and tombstones are joined by union. Entries of tombstoned nodes, and edges from or to
//! them, are dropped on join. Join is commutative, associative and idempotent.
//!
//! **Ids.** A replica id names one life of one agent and is never reused (a restarted agent takes a new one). Node
//! ids are `u64`: minted ones are `replica_id << 32 | sequence`, skipping any id already known; ids from CORTEX
//! JSON are kept. Node id 0 is invalid.
//!
//! **Nodes.** Inserting a node writes its immutable core (type and name) with a fresh dot. A node is visible iff
//! its core has a value and its id is not tombstoned. **Remove wins for nodes**: deleting a node tombstones its id
//! forever; a concurrent attribute write or edge insert involving it never resurrects it, and the id cannot be
//! inserted again.
//!
//! **Edges.** At most one edge per `(from, to, type)`. Presence is an **add-wins** set of insert dots: a delete
//! removes the insert dots it has seen, so a concurrent insert survives it. An edge is visible iff its presence set
//! is non-empty **and both endpoints are visible**; so no replica ever shows a dangling edge, deleting a node hides
//! its edges at once, and an edge added concurrently to a deleted node never becomes visible. Inserting an edge
//! gives it exactly the attributes given (leftover attribute values it had seen are removed).
//!
//! **Attributes.** Each (element, attribute) is a multi-value register: a write supersedes the values its replica
//! has seen; concurrent writes are all kept. Reads return one deterministic winner: the causally latest of the kept
//! values (the one no other kept value's write happened after), or among several concurrent ones the highest
//! (stamp, replica id, counter), which, since stamps follow causality, is the kept value with the highest (stamp,
//! replica id, counter); [`NodeRef::concurrent`] exposes the others. Removing an attribute removes the
//! values seen; a concurrent write survives. Writing to an invisible element is refused locally; remote writes to an
//! element not yet visible are kept and show once it is. "Seen" means applied by that replica: deltas are not
//! delivered causally, so a write that a replica only knows of through a third replica's unrelated operation is not
//! superseded by it and stays listed among the concurrent values. The winner is still the causally latest write,
//! because stamps follow causality transitively (below). (Found and pinned by the model in `model/`.)
//!
//! **Stamps.** Each replica keeps a hybrid logical clock: a local operation at `now_ns` gets stamp
//! `max(now_ns, last + 1)`, and every joined delta raises `last` to its highest stamp. A write that has seen another
//! therefore has a higher stamp, so the winner is never a value the writer had overwritten.
//!
//! **Names.** Node names are unique among visible nodes. A local insert with a name already visible is refused.
//! Two agents that concurrently insert different nodes with the same name both succeed; among visible nodes sharing a
//! name, every replica then shows the causally first insert (or among concurrent ones the lowest (insert stamp,
//! id); since stamps follow causality, the lowest (insert stamp, id) of all) under the plain name and the others as
//! `name#id`. Node names may not
//! contain `#`. If the holder is deleted, the other takes the plain name back. A node whose shown name changes
//! either way is reported by a [`Change::NodeRenamed`] event (found by the model).
//!
//! **Delivery.** Deltas may arrive in any order and more than once. One that refers to something not yet seen (an
//! edge before its nodes, an attribute before its node) is kept and becomes visible when the rest arrives.
//!
//! **Causal consistency: not provided; what a reader may see instead.** A replica joins each delta when it
//! arrives; it does not hold a delta back until the operations its writer had applied have arrived (that would need
//! every delta to carry its writer's applied version vector, and one lost best-effort update would hold back every
//! later delta of everyone who had seen it until a repair). What is guaranteed: the visibility rules above give
//! the robot's read order for free — an attribute never shows before its node, an edge never before both of its
//! nodes, and nothing of a deleted node shows once the delete has arrived; two replicas that have applied the same
//! operations show the same graph, whatever the order (strong eventual consistency); and a replica whose applied
//! operations include everything each of them had seen shows exactly what the reference specification says. What a
//! reader may see while an operation has arrived without an earlier one its writer had seen (until that one
//! arrives, which anti-entropy and the agent's gap requests see to): a value an overwrite had already superseded,
//! listed beside the overwrite among the concurrent values (the winner is still the causally latest write); and an
//! edge re-inserted after a delete that has not arrived yet showing the attribute values of the edge's earlier
//! life, which the re-insert had cleared. (Both found by the model in `model/`, which checks all of this on every
//! state.)
//!
//! **Anti-entropy and late join.** [`Replica::snapshot`] is the whole state as a delta. [`Replica::missing_for`]
//! takes a peer's context and returns the retained deltas it lacks, or a snapshot when the bounded history
//! ([`LogLimits`]) does not cover the gap. The history keeps no value that a later retained write of 1 KiB or more
//! (a camera frame, a scan) has overwritten: such an operation is folded into the later one, and the two travel as
//! one delta.
//! [`Replica::digest`] is a BLAKE3 hash of the canonical visible graph ([`VisibleGraph`]), equal on two replicas
//! exactly when their visible graphs are.
//!
//! **Bad input.** [`Delta::decode`] and [`Replica::apply`] return errors that say what and where; a refused delta
//! leaves the replica unchanged. Nothing that comes from outside panics.
//!
//! **Types.** The [`Dictionary`] types every attribute name; [`attrs`] has typed keys for the built-in ones, so a
//! value of the wrong type does not compile. Local operations are checked against the dictionary; remote deltas
//! are not refused for their names or types (only for names that cannot be held): a replica learns every name and
//! attribute type a delta brings, so that what it accepts never depends on the order things arrived in, and real
//! graphs whose files store a name with another type than today's (see [`json`]) travel between agents.

pub mod causal;
pub mod delta;
pub mod dictionary;
pub mod error;
pub mod ids;
pub mod json;
pub mod kinematics;
pub mod mutants;
pub mod replica;
pub mod store;
pub mod value;

pub use causal::CausalContext;
pub use delta::{Delta, LargeValues, Origin, Pieces};
pub use dictionary::{AttrKey, Dictionary, attrs};
pub use error::{DeltaError, DictionaryError, OpError};
pub use ids::{Dot, EdgeKey, Element, Name, NodeId, ReplicaId, Stamp};
pub use kinematics::KinematicsError;
pub use mutants::DsrMutant;
pub use replica::{
    Attributes, Change, ChangeEvent, Digest, EdgeRef, LogLimits, Missing, NewNode, NodeRef, Replica, VisibleAttr,
    VisibleGraph, VisibleNode,
};
pub use value::{AttrType, Numbers, Value, ValueType};

/// The README's Rust examples, compiled and run as doctests so the README stays true.
#[cfg(doctest)]
#[doc = include_str!("../../../README.md")]
pub struct ReadmeDoctests;
