//! What discovery tells the transport: when it reached each step ([`DiscoveryTimes`]), the remote readers matched
//! per channel, and which participant holds each peer's readers (learnt from its [`READERS_AT`] samples), so that
//! a directed write reaches that peer's reader alone; and the receiving thread's recording of the participants'
//! status events into them ([`DiscoveryWatch`]).

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};

use rustdds::{DomainParticipantStatusEvent, DomainParticipantStatusListener, GUID, StatusEvented};

#[cfg(doc)]
use crate::Transport;
use crate::{Channel, Clock, EndpointId, SystemClock};

/// Per-channel values, by [`Channel::index`].
type PerChannel<T> = [T; Channel::COUNT];

/// When discovery reached each step, in wall-clock nanoseconds since the Unix epoch ([`SystemClock`], so times of
/// different processes on one host compare); `None` until it happens.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct DiscoveryTimes {
    /// The participant, its topics, writers and readers were created.
    pub created_ns: u64,
    /// The first remote participant was discovered.
    pub first_participant_ns: Option<u64>,
    /// Per channel (by [`Channel::index`]): this participant's writer matched its first remote reader.
    pub writer_matched_ns: PerChannel<Option<u64>>,
    /// Per channel (by [`Channel::index`]): this participant's reader matched its first remote writer.
    pub reader_matched_ns: PerChannel<Option<u64>>,
}

/// Most remote readers remembered per channel for directed writes (past it, [`Transport::publish_to`] of an
/// unremembered peer falls back to a write to every reader), and most peers' reader participants remembered.
pub(super) const MAX_REMEMBERED_READERS: usize = 4096;

/// A participant's GUID prefix (the first 12 bytes of every GUID of its entities).
pub(super) type Prefix = [u8; 12];

/// The GUID prefix of `guid`.
pub(super) fn prefix_of(guid: GUID) -> Prefix {
    let bytes = guid.to_bytes();
    let mut prefix = [0; 12];
    prefix.copy_from_slice(&bytes[..12]);
    prefix
}

/// First 8 bytes of a transport's own control sample on the `Requests` topic (the one every transport, a read-only
/// one too, writes, and the one asking is done on), which tells peers the GUID prefix of its readers' participant
/// (12 bytes follow). Samples are tagged with the writing participant's prefix, and the readers live in another
/// participant, so without it a peer could not address an answer to this transport's reader alone.
/// The receiving thread consumes these samples; they never reach the inbox.
pub(super) const READERS_AT: [u8; 8] = *b"\xffRTPSrd1";

/// What the receiving thread learns from discovery, shared with the transport.
#[derive(Debug, Default)]
pub(super) struct DiscoveryState {
    pub(super) times: Mutex<DiscoveryTimes>,
    pub(super) sync_matches: AtomicU64,
    /// The remote readers each channel's writer has matched (by [`Channel::index`]), for directed writes.
    pub(super) readers: Mutex<PerChannel<Vec<GUID>>>,
    /// Peers' readers' participants, learnt from their [`READERS_AT`] samples: at most [`MAX_REMEMBERED_READERS`],
    /// the oldest forgotten first. Not forgotten when discovery loses a participant: a peer sends its sample again
    /// only when a reader newly matches its writer, and a loss seen by one side alone (a one-way cut past the
    /// lease) would leave that peer unaddressable.
    pub(super) reading_prefixes: Mutex<Vec<(EndpointId, Prefix)>>,
    /// A new remote reader matched this transport's requests writer: tell it where this transport's readers are,
    /// before the next sample this transport publishes.
    pub(super) announce_pending: AtomicBool,
}

impl DiscoveryState {
    /// A matched remote reader of `channel` of the transport `to`.
    pub(super) fn reader_of(&self, channel: Channel, to: EndpointId) -> Option<GUID> {
        let prefix = self
            .reading_prefixes
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .iter()
            .find(|(peer, _)| *peer == to)
            .map(|(_, prefix)| *prefix);
        let readers = self.readers.lock().unwrap_or_else(|p| p.into_inner());
        readers[channel.index()]
            .iter()
            .copied()
            .find(|guid| prefix.map_or_else(|| endpoint_of(*guid) == to, |prefix| prefix_of(*guid) == prefix))
    }

    /// Records a peer's [`READERS_AT`] sample; `false` if `bytes` is not one.
    pub(super) fn learn_reading_prefix(&self, origin: EndpointId, bytes: &[u8]) -> bool {
        let Some(prefix) = bytes.strip_prefix(&READERS_AT).and_then(|rest| <[u8; 12]>::try_from(rest).ok()) else {
            return false;
        };
        let mut known = self.reading_prefixes.lock().unwrap_or_else(|p| p.into_inner());
        known.retain(|(peer, _)| *peer != origin);
        if known.len() >= MAX_REMEMBERED_READERS {
            // The oldest goes: peers come and go, and a graph of long-lived agents sees a new one at every restart.
            known.remove(0);
        }
        known.push((origin, prefix));
        true
    }
}

/// The endpoint id of a participant or writer: its 12-byte GUID prefix.
pub(super) fn endpoint_of(guid: rustdds::GUID) -> EndpointId {
    let bytes = guid.to_bytes();
    let mut wide = [0u8; 16];
    wide[4..].copy_from_slice(&bytes[..12]);
    EndpointId(u128::from_be_bytes(wide))
}

/// The receiving thread's view of discovery: the participant's status events, and which local writer and reader
/// serve which channel.
pub(super) struct DiscoveryWatch {
    /// The status events of the transport's participants (one or two).
    pub(super) statuses: Vec<DomainParticipantStatusListener>,
    /// The GUID prefixes of this transport's participants: rustdds also matches a transport's writers with its own
    /// readers (in the same participant or the other), which is no peer.
    pub(super) own: Vec<Prefix>,
    /// Per channel: the local writer (none for a channel a read-only transport does not write) and reader.
    pub(super) endpoints: Vec<(Channel, Option<GUID>, GUID)>,
    pub(super) state: Arc<DiscoveryState>,
}

impl DiscoveryWatch {
    /// Records the status events waiting (a bounded number per call, so data is never starved).
    pub(super) fn drain(&self) {
        for status in &self.statuses {
            self.drain_one(status);
        }
    }

    fn drain_one(&self, status: &DomainParticipantStatusListener) {
        for _ in 0..256 {
            let Some(event) = status.try_recv_status() else { return };
            let now = SystemClock.now_ns();
            let mut times = self.state.times.lock().unwrap_or_else(|p| p.into_inner());
            match event {
                DomainParticipantStatusEvent::ParticipantDiscovered { dpd }
                    if !self.own.contains(&prefix_of(dpd.guid)) =>
                {
                    times.first_participant_ns.get_or_insert(now);
                }
                DomainParticipantStatusEvent::RemoteReaderMatched { local_writer, remote_reader }
                    if !self.own.contains(&prefix_of(remote_reader)) =>
                {
                    if let Some((channel, _, _)) = self.endpoints.iter().find(|(_, w, _)| *w == Some(local_writer)) {
                        times.writer_matched_ns[channel.index()].get_or_insert(now);
                        let mut readers = self.state.readers.lock().unwrap_or_else(|p| p.into_inner());
                        let known = &mut readers[channel.index()];
                        if !known.contains(&remote_reader) && known.len() < MAX_REMEMBERED_READERS {
                            known.push(remote_reader);
                        }
                        if matches!(channel, Channel::Sync | Channel::Requests) {
                            self.state.sync_matches.fetch_add(1, Ordering::Release);
                        }
                        if *channel == Channel::Requests {
                            self.state.announce_pending.store(true, Ordering::Release);
                        }
                    }
                }
                DomainParticipantStatusEvent::RemoteWriterMatched { local_reader, remote_writer }
                    if !self.own.contains(&prefix_of(remote_writer)) =>
                {
                    if let Some((channel, _, _)) = self.endpoints.iter().find(|(_, _, r)| *r == local_reader) {
                        times.reader_matched_ns[channel.index()].get_or_insert(now);
                        if matches!(channel, Channel::Sync | Channel::Requests) {
                            self.state.sync_matches.fetch_add(1, Ordering::Release);
                        }
                    }
                }
                DomainParticipantStatusEvent::ReaderLost { guid, .. } => {
                    let mut readers = self.state.readers.lock().unwrap_or_else(|p| p.into_inner());
                    for known in readers.iter_mut() {
                        known.retain(|reader| *reader != guid);
                    }
                }
                DomainParticipantStatusEvent::ParticipantLost { id, .. } => {
                    let mut readers = self.state.readers.lock().unwrap_or_else(|p| p.into_inner());
                    for known in readers.iter_mut() {
                        known.retain(|reader| reader.prefix != id);
                    }
                }
                _ => {}
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn readers_at(prefix: Prefix) -> Vec<u8> {
        [READERS_AT.as_slice(), prefix.as_slice()].concat()
    }

    #[test]
    fn past_the_limit_the_oldest_reader_participant_is_forgotten_and_the_newest_remembered() {
        let state = DiscoveryState::default();
        let prefix = |n: usize| -> Prefix {
            let mut prefix = [0; 12];
            prefix[..8].copy_from_slice(&(n as u64).to_le_bytes());
            prefix
        };
        for n in 0..=MAX_REMEMBERED_READERS {
            assert!(state.learn_reading_prefix(EndpointId(n as u128), &readers_at(prefix(n))));
        }
        let known = |n: usize| state.reading_prefixes.lock().unwrap().contains(&(EndpointId(n as u128), prefix(n)));
        assert!(!known(0), "past the limit the oldest goes");
        assert!(known(1) && known(MAX_REMEMBERED_READERS), "the newest are kept");
        assert_eq!(state.reading_prefixes.lock().unwrap().len(), MAX_REMEMBERED_READERS);
        // A peer that sends its sample again is the newest: it outlives the others.
        assert!(state.learn_reading_prefix(EndpointId(1), &readers_at(prefix(1))));
        assert!(state.learn_reading_prefix(EndpointId(9999), &readers_at(prefix(9999))));
        assert!(known(1) && !known(2));
        assert!(!state.learn_reading_prefix(EndpointId(1), b"not a readers-at sample"));
    }
}
