//! What one partition run of [`crate::partition`] measured.

use serde::Serialize;

/// What one partition run measured.
#[derive(Clone, Debug, Serialize)]
pub struct PartitionResult {
    /// `inproc` or `rtps`.
    pub transport: String,
    /// Agents.
    pub agents: u32,
    /// Seed.
    pub seed: u64,
    /// Partition length, ms.
    pub partition_ms: u64,
    /// Announce period, ms.
    pub announce_period_ms: u64,
    /// Writes made during the partition (both sides).
    pub writes: u64,
    /// Samples the injector dropped (the partition's cuts).
    pub dropped: u64,
    /// Nanoseconds from the heal to equal digests everywhere, or `None` if not within the timeout.
    pub reconverge_ns: Option<u64>,
}
