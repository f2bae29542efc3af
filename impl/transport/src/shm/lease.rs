//! Leases: a large received sample handed on in place, as a `Bytes` over the shared-memory chunk, instead of copied
//! out of it.
//!
//! A leased chunk stays borrowed from the writer's pool for as long as any `Bytes` over it lives. Where the agent
//! keeps values, that is while the value is the replica's current one and its anti-entropy history holds it: until
//! the next frame overwrites it, for a stream of frames (the history folds overwritten operations and drops their
//! values), but as long as the history keeps the operation when it also wrote something no later operation
//! overwrote, which can be seconds. So leases are bounded per lane: at most `budget` at once ([`LeasePolicy`]). iceoryx2's own per-subscriber borrow limit is
//! set one above it (the sample being decided on), so `receive` never fails for want of a borrow. Past the budget,
//! and below `min_bytes`, a sample is copied out as before.
//!
//! Safety of a lease held past its writer: iceoryx2 keeps a disconnected writer's connection, and its mapping, while
//! samples of it are borrowed. Its expired-connection buffer is never smaller than the borrow limit, and a lane never
//! borrows more than that in all, so a writer that exits or is killed while its samples are leased leaves them
//! readable.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};

use bytes::Bytes;
use iceoryx2::sample::Sample;
use iceoryx2::service::ipc_threadsafe;

use super::EndpointHeader;

/// When a lane leases samples instead of copying them out.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LeasePolicy {
    /// Samples of at least this many bytes may be leased; smaller ones are copied (a copy is cheaper than a held
    /// chunk of the lane's full sample size).
    pub min_bytes: usize,
    /// The most samples a lane holds leased at once (0: never lease).
    pub budget: usize,
}

impl LeasePolicy {
    /// Never lease: every sample is copied out.
    pub const NEVER: LeasePolicy = LeasePolicy { min_bytes: usize::MAX, budget: 0 };

    /// The borrow limit the lane's service needs: the budget, and one more for the sample being decided on.
    pub(super) fn max_borrowed_samples(self) -> usize {
        self.budget + 1
    }
}

impl Default for LeasePolicy {
    fn default() -> Self {
        LeasePolicy { min_bytes: 64 * 1024, budget: 24 }
    }
}

type LaneSample = Sample<ipc_threadsafe::Service, [u8], EndpointHeader>;

/// A leased chunk: the received sample, kept until the last `Bytes` over it is dropped.
struct Lease {
    sample: LaneSample,
    held: Arc<AtomicUsize>,
}

impl AsRef<[u8]> for Lease {
    fn as_ref(&self) -> &[u8] {
        self.sample.payload()
    }
}

impl Drop for Lease {
    fn drop(&mut self) {
        self.held.fetch_sub(1, Ordering::AcqRel);
    }
}

/// One lane's leases: its policy and how many are held now.
#[derive(Debug)]
pub(super) struct Leases {
    policy: LeasePolicy,
    held: Arc<AtomicUsize>,
    /// Samples leased so far.
    taken: AtomicU64,
}

impl Leases {
    pub(super) fn new(policy: LeasePolicy) -> Self {
        Leases { policy, held: Arc::new(AtomicUsize::new(0)), taken: AtomicU64::new(0) }
    }

    /// Samples leased so far.
    pub(super) fn taken(&self) -> u64 {
        self.taken.load(Ordering::Relaxed)
    }

    /// Leases held now.
    pub(super) fn held(&self) -> usize {
        self.held.load(Ordering::Acquire)
    }

    /// The sample's bytes: leased in place when the policy allows, else copied out (and the chunk returned at once).
    pub(super) fn take(&self, sample: LaneSample) -> Bytes {
        let reserved = sample.payload().len() >= self.policy.min_bytes
            && self
                .held
                .fetch_update(Ordering::AcqRel, Ordering::Acquire, |held| {
                    (held < self.policy.budget).then_some(held + 1)
                })
                .is_ok();
        if reserved {
            self.taken.fetch_add(1, Ordering::Relaxed);
            return Bytes::from_owner(Lease { sample, held: Arc::clone(&self.held) });
        }
        Bytes::copy_from_slice(sample.payload())
    }
}
