//! Anti-entropy: asking a peer for missing operations (on an announce that shows them, or a gap in a writer's
//! deltas) and answering such requests with retained deltas in bounded batches or a snapshot.

use std::sync::Arc;

use bytes::Bytes;
use dsr::{CausalContext, Delta, Missing};

use super::{AgentCore, Dest, Event, Output, SNAPSHOT_IF_SMALLER_ABOVE_BYTES};
use crate::AgentId;
use crate::envelope::{MAX_BATCH, Message};
use crate::mutants::ProtocolMutant;

impl AgentCore {
    pub(super) fn answered_by(&mut self, from: AgentId) {
        if self.pending_ask.is_some_and(|(peer, _)| peer == from)
            && !self.config.plant.is(ProtocolMutant::PendingAskNeverExpires)
        {
            self.pending_ask = None;
        }
    }

    /// Whether a missing-request is still outstanding: an answer clears it, and one unanswered for half an
    /// announce period no longer counts (a lost request or answer is asked again at the next evidence).
    fn asked_recently(&self, now_ns: u64) -> bool {
        let expiry = if self.config.plant.is(ProtocolMutant::PendingAskNeverExpires) {
            u64::MAX
        } else {
            self.config.announce_period_ns / 2
        };
        self.pending_ask.is_some_and(|(_, at)| now_ns.saturating_sub(at) < expiry)
    }

    pub(super) fn ask(&mut self, peer: AgentId, full: bool, now_ns: u64, out: &mut Output) {
        let Some(replica) = &self.replica else { return };
        let request =
            Message::MissingRequest { from: self.config.id, to: peer, applied: replica.applied().clone(), full };
        out.send(request, Dest::All);
        self.pending_ask = Some((peer, now_ns));
    }

    /// Asks the writer of `delta` at once for its operations before it that were not joined (a lost sample, or
    /// one overtaken in flight), unless a request is outstanding.
    pub(super) fn gap_request(&mut self, from: AgentId, delta: &Delta, now_ns: u64, out: &mut Output) {
        if self.config.plant.is(ProtocolMutant::NoGapRequest) {
            return;
        }
        let (Some(origin), Some(replica)) = (delta.origin(), &self.replica) else { return };
        if replica.applied().version(origin.replica).saturating_add(1) >= origin.first || self.asked_recently(now_ns) {
            return;
        }
        out.events.push(Event::GapRequest { peer: from });
        self.ask(from, false, now_ns, out);
    }

    pub(super) fn on_announce(
        &mut self,
        from: AgentId,
        applied: &CausalContext,
        digest: Option<[u8; 32]>,
        now_ns: u64,
        out: &mut Output,
    ) {
        if self.replica.is_none() || self.asked_recently(now_ns) {
            return;
        }
        let lacks = self.replica.as_ref().is_some_and(|r| !r.applied().includes(applied));
        if lacks {
            return self.ask(from, false, now_ns, out);
        }
        let same_ops = self.replica.as_ref().is_some_and(|r| r.applied() == applied);
        if same_ops
            && let Some(digest) = digest
            && self.digest().map(|d| d.0) != Some(digest)
        {
            // The same operations joined, yet another graph: a bug in the replica. Repair with whole states.
            out.events.push(Event::DigestMismatch { peer: from });
            self.ask(from, true, now_ns, out);
        }
    }

    pub(super) fn answer_missing(&mut self, from: AgentId, applied: &CausalContext, full: bool, out: &mut Output) {
        if self.config.read_only {
            return; // It may not publish answers; a writer of the graph answers.
        }
        let missing = match &self.replica {
            Some(replica) if !full => replica.missing_for(applied),
            _ => Missing::UpToDate,
        };
        let snapshot = match missing {
            Missing::UpToDate => {
                if full {
                    self.snapshot_bytes()
                } else {
                    None
                }
            }
            Missing::Deltas(deltas) => match self.smaller_snapshot(&deltas) {
                Some(snapshot) => Some(snapshot),
                None => {
                    self.batches(from, &deltas, out);
                    None
                }
            },
            Missing::Snapshot => self.snapshot_bytes(),
        };
        if let Some((snapshot, _)) = snapshot {
            out.send(Message::Snapshot { from: self.config.id, to: from, snapshot }, Dest::Sender);
        }
    }

    /// The encoded snapshot, if `deltas` carry more than [`SNAPSHOT_IF_SMALLER_ABOVE_BYTES`] of payload and the
    /// snapshot is smaller than that payload.
    fn smaller_snapshot(&mut self, deltas: &[Arc<Delta>]) -> Option<(Bytes, bool)> {
        let payload: usize = deltas.iter().map(|d| d.payload_bytes()).sum();
        if payload <= SNAPSHOT_IF_SMALLER_ABOVE_BYTES {
            return None;
        }
        self.snapshot_bytes().filter(|(snapshot, _)| snapshot.len() < payload)
    }

    /// The encoded snapshot (cached per causal context), and whether it came from the cache.
    pub(super) fn snapshot_bytes(&mut self) -> Option<(Bytes, bool)> {
        let replica = self.replica.as_ref()?;
        if let Some((ctx, bytes)) = &self.caches.0.snapshot
            && ctx == replica.context()
        {
            return Some((bytes.clone(), true));
        }
        let bytes = Bytes::from(replica.encode_snapshot());
        self.caches.0.snapshot = Some((replica.context().clone(), bytes.clone()));
        Some((bytes, false))
    }

    /// Splits retained deltas into answer messages of bounded size.
    fn batches(&self, to: AgentId, deltas: &[Arc<Delta>], out: &mut Output) {
        let me = self.config.id;
        let mut batch = Vec::new();
        let mut bytes = 0;
        for delta in deltas {
            let encoded = Bytes::from(delta.encode());
            if !batch.is_empty() && (bytes + encoded.len() > self.config.max_batch_bytes || batch.len() >= MAX_BATCH) {
                out.send(Message::Deltas { from: me, to, deltas: std::mem::take(&mut batch) }, Dest::Sender);
                bytes = 0;
            }
            bytes += encoded.len();
            batch.push(encoded);
        }
        if !batch.is_empty() {
            out.send(Message::Deltas { from: me, to, deltas: batch }, Dest::Sender);
        }
    }
}
