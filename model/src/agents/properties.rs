//! The agents model's property names.

/// No replica id twice.
pub const UNIQUE_LIVES: &str = "no two lives take one replica id (no dot or node id minted twice)";
/// Bounded buffers.
pub const BOUNDED: &str = "every buffer stays within its limit";
/// Invariants.
pub const INVARIANTS: &str = "every replica's invariants hold and every message decodes and is accepted";
/// Gap requests.
pub const GAP_ASKED: &str = "a delta after a gap in its writer's operations is asked for at once";
/// Early deltas.
pub const EARLY_KEPT: &str = "a delta received while joining is joined when the life becomes ready";
/// Bounded liveness.
pub const SETTLES: &str = "faults stop here => within 6 timer rounds all live agents ready, in one graph, equal, equal to the specification, no live write lost";
/// Joiners.
pub const JOINER_SERVED: &str = "faults stop here => a joiner with a ready peer alive joins its graph, not alone";
/// Witness.
pub const W_JOINED: &str = "a joiner becomes ready from a peer's graph";
/// Witness.
pub const W_RESTART: &str = "a restarted agent's new life becomes ready";
/// Witness.
pub const W_GAP: &str = "a gap request goes out";
/// Witness.
pub const W_SNAPSHOT: &str = "a missing-request is answered with a snapshot";
/// Witness.
pub const W_FORGOTTEN: &str = "an agent forgets a silent peer";
/// Witness, with [`super::AgentsConfig::unnamed`] and 6 ticks or more.
pub const W_MOVED: &str = "a life whose graph is unnamed moves to another graph";
/// Witness.
pub const W_ALONE: &str = "a life starts alone while another agent is ready";
/// Witness.
pub const W_ALL_FAULTS: &str = "every budget is spent on one path";
/// Witness (with a stop in the budgets).
pub const W_STOPPED_JOINED: &str = "a joiner stopped while it joins takes a peer's graph when resumed";
