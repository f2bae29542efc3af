//! The receiving side of a run, shared by receiver threads ([`crate::run`]) and receiver processes
//! ([`crate::process`]): a sample's sequence number and delta decoded, applied, and the first application of every
//! write stamped; and what a receiver reports when it stops.

use bytes::Bytes;
use dsr::{Delta, Digest, Replica};
use transport::TransportStats;

use crate::results::AgentCost;

/// What one receiver (thread or process) reports at the end of a run.
#[derive(Clone, Debug)]
pub(crate) struct ReceiverOutcome {
    /// Apply time of every write on the run's clock, [`NOT_APPLIED`] if never applied.
    pub applied_at: Vec<u64>,
    /// Samples that could not be decoded or applied.
    pub refused: u64,
    /// The receiver's transport counters.
    pub stats: TransportStats,
    /// The receiver's final graph digest.
    pub digest: Digest,
    /// Bytes of probes received (not part of the workload).
    pub probe_bytes: u64,
    /// CPU and memory of the receiver.
    pub cost: AgentCost,
}

/// Apply time of a write never applied.
pub(crate) const NOT_APPLIED: u64 = u64::MAX;
/// Sequence number of the probes sent until every receiver hears the source (RTPS discovery).
pub(crate) const PROBE: u64 = u64::MAX;

/// What a sample was to a receiver.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Received {
    /// A discovery probe.
    Probe,
    /// A write applied for the first time.
    Applied,
    /// A write applied before (a duplicate).
    Again,
    /// Bytes that are not a write of this run, or a delta the replica refused.
    Refused,
}

/// The receiving side of a run, shared by receiver threads and receiver processes: decodes a sample's sequence
/// number and delta, applies it, and stamps the first application of every write.
pub(crate) struct Receiving {
    pub replica: Replica,
    pub applied_at: Vec<u64>,
    pub applied: u64,
    pub refused: u64,
    pub probe_bytes: u64,
}

impl Receiving {
    pub fn new(replica: Replica, writes: usize) -> Self {
        Receiving { replica, applied_at: vec![NOT_APPLIED; writes], applied: 0, refused: 0, probe_bytes: 0 }
    }

    /// Handles one sample; `now` is read after the delta is applied. The delta is decoded as an agent decodes it
    /// ([`Delta::decode_shared`]): its large values are slices of the sample's buffer, which in process is the one
    /// buffer every receiver was handed.
    pub fn on_sample(&mut self, bytes: &Bytes, now: impl FnOnce() -> u64) -> Received {
        let Some((header, _)) = bytes.split_first_chunk::<8>() else {
            self.refused += 1;
            return Received::Refused;
        };
        let seq = u64::from_le_bytes(*header);
        if seq == PROBE {
            self.probe_bytes += bytes.len() as u64;
            return Received::Probe;
        }
        let ok =
            Delta::decode_shared(&bytes.slice(8..)).ok().and_then(|delta| self.replica.apply(&delta).ok()).is_some();
        let now = now();
        match usize::try_from(seq).ok().and_then(|seq| self.applied_at.get_mut(seq)) {
            Some(slot) if ok => {
                if *slot == NOT_APPLIED {
                    *slot = now;
                    self.applied += 1;
                    Received::Applied
                } else {
                    Received::Again
                }
            }
            _ => {
                self.refused += 1;
                Received::Refused
            }
        }
    }

    pub fn all_applied(&self) -> bool {
        self.applied == self.applied_at.len() as u64
    }
}
