//! Shared memory between agents on one host (issue 20): one iceoryx2 publish-subscribe service per channel and
//! graph, which the same-host agents open by name.
//!
//! This module is the same-host path: [`ShmLane`] moves one channel's samples between the endpoints of one host
//! through shared memory, and [`ShmTransport`] makes every channel a [`crate::Transport`] (used by
//! `cortex agent --transport shm`, and the same-host half of [`crate::hybrid`], the default); [`limit`] is the raw
//! iceoryx2 limit they are measured against (`cortex bench payload`).
//!
//! Shape of a lane sample: the sample's bytes as the transport was given them, as an iceoryx2 `[u8]` payload, with
//! the sender's [`EndpointId`] in the sample's user header (`[u64; 2]`). iceoryx2 records the payload and header
//! types in the service's static configuration, so a segment of another shape under the same name is refused when
//! the lane opens ([`ShmError::Open`]), never read; the bytes themselves are checked by the agent's decoder, as
//! samples from RTPS are.
//!
//! Copies: the sender writes the sample once, into the loaned shared-memory chunk (the publisher's loan is sized
//! for `max_sample_bytes`; a larger sample is not sent and [`ShmPublish::TooLarge`] tells the caller to use RTPS).
//! A receiver takes a large sample in place, as a `Bytes` over the chunk, while its lane holds fewer leases than
//! its [`LeasePolicy`] allows ([`lease`]); any other sample it copies once out of shared memory, so that chunk goes
//! back to the publisher at once. [`ShmTransport`] leases on the updates lane alone: a graph answer or a call would
//! hold its chunk for as long as the replica keeps what it carried.

use bytes::Bytes;
use iceoryx2::prelude::*;
use iceoryx2::service::ipc_threadsafe;

use crate::EndpointId;

pub mod lease;
pub mod limit;
mod transport;
pub use lease::LeasePolicy;
pub use transport::ShmTransport;

/// An endpoint id no other life of any process shares, for a lane of this process: the process id in the top 32
/// bits beside the start time in nanoseconds (RTPS endpoint ids, 12-byte GUID prefixes, leave the top 32 bits zero).
pub fn unique_endpoint() -> EndpointId {
    let now_ns = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_nanos());
    EndpointId((u128::from(std::process::id()) << 96) | (now_ns & ((1 << 96) - 1)) | 1 << 127)
}

/// The user header of every lane sample: the sender's [`EndpointId`] as two little-endian halves (low, high).
type EndpointHeader = [u64; 2];

fn endpoint_header(id: EndpointId) -> EndpointHeader {
    [id.0 as u64, (id.0 >> 64) as u64]
}

fn endpoint_from_header(header: EndpointHeader) -> EndpointId {
    EndpointId(u128::from(header[0]) | (u128::from(header[1]) << 64))
}

/// Errors of the shared-memory lane.
#[derive(Debug, thiserror::Error)]
pub enum ShmError {
    /// The service name is not one iceoryx2 accepts.
    #[error("shared memory: service name {name:?} is invalid: {reason}")]
    Name {
        /// The name that was refused.
        name: String,
        /// iceoryx2's reason.
        reason: String,
    },
    /// iceoryx2 could not create or open a node, service or port (no usable shared memory, a segment of another
    /// shape under the same name, too many ports).
    #[error("shared memory: cannot open {what} of service {service:?}: {reason}")]
    Open {
        /// Which part failed (node, service, publisher, subscriber).
        what: &'static str,
        /// The service name.
        service: String,
        /// iceoryx2's reason.
        reason: String,
    },
    /// A loan, send or receive failed.
    #[error("shared memory: {op} on service {service:?} failed: {reason}")]
    Io {
        /// The operation (loan, send, receive).
        op: &'static str,
        /// The service name.
        service: String,
        /// iceoryx2's reason.
        reason: String,
    },
}

/// Settings of a lane.
#[derive(Debug, Clone)]
pub struct ShmSettings {
    /// The largest sample (without the lane header) the lane carries; larger ones go by RTPS.
    pub max_sample_bytes: usize,
    /// How many endpoints of one host may open the lane.
    pub max_endpoints: usize,
    /// Samples a subscriber queues before the oldest is overwritten (the anti-entropy repairs what is lost).
    pub buffer_samples: usize,
    /// Which received samples are taken in place rather than copied out ([`ShmTransport`] applies it to the updates
    /// lane alone).
    pub leases: LeasePolicy,
}

impl Default for ShmSettings {
    fn default() -> Self {
        Self {
            max_sample_bytes: 8 * 1024 * 1024,
            max_endpoints: 16,
            buffer_samples: 16,
            leases: LeasePolicy::default(),
        }
    }
}

/// What [`ShmLane::publish`] did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ShmPublish {
    /// The sample went into shared memory for this many subscribers (the publisher's own included).
    Sent {
        /// Subscribers the sample was delivered to.
        subscribers: usize,
    },
    /// The sample is larger than the lane's `max_sample_bytes`; nothing was sent.
    TooLarge,
}

/// One sample received through shared memory.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ShmSample {
    /// The endpoint that published it.
    pub origin: EndpointId,
    /// Its bytes: leased in place or copied once out of shared memory ([`lease`]).
    pub bytes: Bytes,
}

/// One channel's shared-memory lane on this host: a publisher and a subscriber of one iceoryx2 service.
pub struct ShmLane {
    service: String,
    origin: EndpointId,
    max_sample_bytes: usize,
    leases: lease::Leases,
    publisher: iceoryx2::port::publisher::Publisher<ipc_threadsafe::Service, [u8], EndpointHeader>,
    subscriber: iceoryx2::port::subscriber::Subscriber<ipc_threadsafe::Service, [u8], EndpointHeader>,
    _node: Node<ipc_threadsafe::Service>,
}

impl std::fmt::Debug for ShmLane {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ShmLane").field("service", &self.service).field("origin", &self.origin).finish()
    }
}

impl ShmLane {
    /// Opens (or creates) the lane named `service` for the endpoint `origin`.
    ///
    /// # Errors
    /// [`ShmError::Name`] for a name iceoryx2 refuses, [`ShmError::Open`] when shared memory is unusable or the
    /// service exists with another shape (then the caller keeps RTPS).
    pub fn open(service: &str, origin: EndpointId, settings: &ShmSettings) -> Result<Self, ShmError> {
        iceoryx2::prelude::set_log_level(LogLevel::Error);
        let open = |what: &'static str, reason: String| ShmError::Open { what, service: service.to_owned(), reason };
        let name: ServiceName =
            service.try_into().map_err(|e| ShmError::Name { name: service.to_owned(), reason: format!("{e:?}") })?;
        let node =
            NodeBuilder::new().create::<ipc_threadsafe::Service>().map_err(|e| open("node", format!("{e:?}")))?;
        let factory = node
            .service_builder(&name)
            .publish_subscribe::<[u8]>()
            .user_header::<EndpointHeader>()
            // A payload starts 8-aligned, so a numeric vector a delta placed aligned is read in place when leased.
            .payload_alignment(Alignment::ALIGN_8)
            .max_publishers(settings.max_endpoints)
            .max_subscribers(settings.max_endpoints)
            .max_nodes(settings.max_endpoints)
            .subscriber_max_buffer_size(settings.buffer_samples)
            .subscriber_max_borrowed_samples(settings.leases.max_borrowed_samples())
            .history_size(0)
            .enable_safe_overflow(true)
            .open_or_create()
            .map_err(|e| open("service", format!("{e:?}")))?;
        let publisher = factory
            .publisher_builder()
            .initial_max_slice_len(settings.max_sample_bytes)
            .create()
            .map_err(|e| open("publisher", format!("{e:?}")))?;
        let subscriber = factory.subscriber_builder().create().map_err(|e| open("subscriber", format!("{e:?}")))?;
        Ok(Self {
            service: service.to_owned(),
            origin,
            max_sample_bytes: settings.max_sample_bytes,
            leases: lease::Leases::new(settings.leases),
            publisher,
            subscriber,
            _node: node,
        })
    }

    /// The service name.
    pub fn service(&self) -> &str {
        &self.service
    }

    /// Received samples this lane holds leased now.
    pub fn leases_held(&self) -> usize {
        self.leases.held()
    }

    /// Received samples this lane has leased so far.
    pub fn samples_leased(&self) -> u64 {
        self.leases.taken()
    }

    /// Publishes `bytes` to every subscriber of the lane on this host, written once into shared memory.
    ///
    /// # Errors
    /// [`ShmError::Io`] when the loan or the send fails.
    pub fn publish(&self, bytes: &[u8]) -> Result<ShmPublish, ShmError> {
        self.publish_pieces(&[bytes])
    }

    /// Publishes the concatenation of `pieces` as one sample, each piece copied once, straight into the shared-memory
    /// chunk (an agent's delta whose camera frame is a piece of its own is copied once on its way, not twice).
    ///
    /// # Errors
    /// As [`ShmLane::publish`].
    #[allow(unsafe_code)] // One `assume_init` of a chunk this function has just filled, byte for byte.
    pub fn publish_pieces(&self, pieces: &[&[u8]]) -> Result<ShmPublish, ShmError> {
        let len: usize = pieces.iter().map(|piece| piece.len()).sum();
        if len > self.max_sample_bytes {
            return Ok(ShmPublish::TooLarge);
        }
        let io = |op: &'static str, reason: String| ShmError::Io { op, service: self.service.clone(), reason };
        let mut sample = self.publisher.loan_slice_uninit(len).map_err(|e| io("loan", format!("{e:?}")))?;
        *sample.user_header_mut() = endpoint_header(self.origin);
        let mut chunk = sample.payload_mut();
        for piece in pieces {
            let (head, rest) = chunk.split_at_mut(piece.len());
            // The compiler makes this a loop of 16-byte moves, not a call of `memcpy`; a `memcpy` here was no faster
            // at 4 MiB (agents' p50 1,196 against 1,220 us, medians of five alternated runs of `cortex bench payload`,
            // 2026-12-04), so the copy stays free of `unsafe`. `write_copy_of_slice` is newer than the MSRV.
            for (byte, &value) in head.iter_mut().zip(*piece) {
                byte.write(value);
            }
            chunk = rest;
        }
        debug_assert!(chunk.is_empty());
        // SAFETY: the loan is `len` bytes long, the pieces' lengths sum to `len`, and they were copied one after
        // the other from its start, so every byte of the payload is initialised.
        let sample = unsafe { sample.assume_init() };
        let subscribers = sample.send().map_err(|e| io("send", format!("{e:?}")))?;
        Ok(ShmPublish::Sent { subscribers })
    }

    /// The next sample another endpoint published, if one is waiting (the lane's own samples are skipped).
    ///
    /// # Errors
    /// [`ShmError::Io`] when receiving fails.
    pub fn try_recv(&self) -> Result<Option<ShmSample>, ShmError> {
        loop {
            let Some(sample) = self.subscriber.receive().map_err(|e| ShmError::Io {
                op: "receive",
                service: self.service.clone(),
                reason: format!("{e:?}"),
            })?
            else {
                return Ok(None);
            };
            let origin = endpoint_from_header(*sample.user_header());
            if origin == self.origin {
                continue;
            }
            return Ok(Some(ShmSample { origin, bytes: self.leases.take(sample) }));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn unique(name: &str) -> String {
        format!("cortex/test/{}/{name}", std::process::id())
    }

    #[test]
    fn a_sample_published_on_a_lane_reaches_the_other_endpoint_intact_and_not_its_sender() {
        let service = unique("intact");
        let settings = ShmSettings { max_sample_bytes: 1 << 20, ..ShmSettings::default() };
        let a = ShmLane::open(&service, EndpointId(1), &settings).expect("lane a");
        let b = ShmLane::open(&service, EndpointId(2), &settings).expect("lane b");
        let frame: Vec<u8> = (0..(1 << 20)).map(|i| (i % 251) as u8).collect();
        assert_eq!(a.publish(&frame).expect("publish"), ShmPublish::Sent { subscribers: 2 });
        let got = b.try_recv().expect("receive").expect("a sample");
        assert_eq!(got.origin, EndpointId(1));
        assert_eq!(got.bytes.as_ref(), frame.as_slice());
        assert_eq!(got.bytes.as_ptr().align_offset(8), 0, "a payload starts 8-aligned");
        assert_eq!(a.try_recv().expect("receive"), None, "a lane skips its own samples");
        assert_eq!(b.try_recv().expect("receive"), None);
    }

    #[test]
    fn pieces_published_as_one_sample_arrive_as_their_concatenation() {
        let service = unique("pieces");
        let settings = ShmSettings { max_sample_bytes: 1 << 16, ..ShmSettings::default() };
        let a = ShmLane::open(&service, EndpointId(1), &settings).expect("lane a");
        let b = ShmLane::open(&service, EndpointId(2), &settings).expect("lane b");
        let frame: Vec<u8> = (0..40_000).map(|i| (i % 249) as u8).collect();
        let pieces: [&[u8]; 4] = [b"envelope", &frame, &[], b"tail"];
        assert_eq!(a.publish_pieces(&pieces).expect("publish"), ShmPublish::Sent { subscribers: 2 });
        assert_eq!(b.try_recv().expect("receive").expect("a sample").bytes, pieces.concat());
        let too_large: [&[u8]; 2] = [&frame, &frame];
        assert_eq!(a.publish_pieces(&too_large).expect("publish"), ShmPublish::TooLarge, "the pieces' sum counts");
        assert_eq!(b.try_recv().expect("receive"), None);
    }

    fn leasing(budget: usize) -> ShmSettings {
        ShmSettings {
            max_sample_bytes: 1 << 20,
            leases: LeasePolicy { min_bytes: 1024, budget },
            ..ShmSettings::default()
        }
    }

    #[test]
    fn a_large_sample_is_leased_in_place_until_its_last_bytes_are_dropped_and_a_small_one_is_copied() {
        let service = unique("lease");
        let a = ShmLane::open(&service, EndpointId(1), &leasing(4)).expect("lane a");
        let b = ShmLane::open(&service, EndpointId(2), &leasing(4)).expect("lane b");
        let frame: Vec<u8> = (0..(1 << 16)).map(|i| (i % 253) as u8).collect();
        a.publish(&frame).expect("publish");
        a.publish(&[9u8; 100]).expect("publish");
        let large = b.try_recv().expect("receive").expect("a sample");
        assert_eq!(b.leases_held(), 1);
        let small = b.try_recv().expect("receive").expect("a sample");
        assert_eq!(b.leases_held(), 1, "a sample below min_bytes is copied");
        assert_eq!((large.bytes.as_ref(), small.bytes.as_ref()), (frame.as_slice(), &[9u8; 100][..]));
        let slice = large.bytes.slice(10..20);
        drop(large);
        assert_eq!(b.leases_held(), 1, "a slice keeps the lease");
        assert_eq!(slice.as_ref(), &frame[10..20]);
        drop(slice);
        assert_eq!(b.leases_held(), 0);
        assert_eq!(b.samples_leased(), 1);
    }

    #[test]
    fn past_the_budget_samples_are_copied_and_receiving_never_fails() {
        let service = unique("lease-budget");
        let a = ShmLane::open(&service, EndpointId(1), &leasing(2)).expect("lane a");
        let b = ShmLane::open(&service, EndpointId(2), &leasing(2)).expect("lane b");
        let mut kept = Vec::new();
        for round in 0..6u8 {
            a.publish(&[round; 4096]).expect("publish");
            let got = b.try_recv().expect("receive never fails").expect("a sample");
            assert_eq!(got.bytes.as_ref(), &[round; 4096][..]);
            kept.push(got);
            assert_eq!(b.leases_held(), kept.len().min(2), "at most the budget is leased");
        }
        kept.truncate(1);
        a.publish(&[7u8; 4096]).expect("publish");
        let again = b.try_recv().expect("receive").expect("a sample");
        assert_eq!(b.leases_held(), 2, "a freed slot is leased again");
        assert_eq!(again.bytes.as_ref(), &[7u8; 4096][..]);
    }

    #[test]
    fn a_leased_sample_stays_readable_after_its_writer_has_gone() {
        let service = unique("lease-writer-gone");
        let b = ShmLane::open(&service, EndpointId(2), &leasing(4)).expect("lane b");
        let frame: Vec<u8> = (0..(1 << 18)).map(|i| (i % 241) as u8).collect();
        let leased = {
            let a = ShmLane::open(&service, EndpointId(1), &leasing(4)).expect("lane a");
            a.publish(&frame).expect("publish");
            b.try_recv().expect("receive").expect("a sample")
        };
        // The writer's lane and node are gone; the next receive sees the disconnection.
        assert_eq!(b.try_recv().expect("receive"), None);
        assert_eq!(leased.bytes.as_ref(), frame.as_slice());
        let again = ShmLane::open(&service, EndpointId(3), &leasing(4)).expect("a new writer");
        again.publish(&frame[..2048]).expect("publish");
        assert_eq!(b.try_recv().expect("receive").expect("a sample").bytes.as_ref(), &frame[..2048]);
        assert_eq!(leased.bytes.as_ref(), frame.as_slice(), "still intact beside the new writer");
    }

    #[test]
    fn a_sample_above_the_lane_size_is_not_sent_and_says_so() {
        let service = unique("too-large");
        let settings = ShmSettings { max_sample_bytes: 1024, ..ShmSettings::default() };
        let a = ShmLane::open(&service, EndpointId(1), &settings).expect("lane a");
        let b = ShmLane::open(&service, EndpointId(2), &settings).expect("lane b");
        assert_eq!(a.publish(&[7u8; 1025]).expect("publish"), ShmPublish::TooLarge);
        assert_eq!(b.try_recv().expect("receive"), None);
    }

    #[test]
    fn a_service_of_another_shape_under_the_lane_name_is_refused_with_an_error_not_a_panic() {
        let service = unique("other-shape");
        // Someone else's service under the lane's name: bytes without the lane's endpoint header.
        let node = NodeBuilder::new().create::<ipc_threadsafe::Service>().expect("node");
        let name: ServiceName = service.as_str().try_into().expect("name");
        let _other = node.service_builder(&name).publish_subscribe::<[u8]>().create().expect("service");
        match ShmLane::open(&service, EndpointId(2), &ShmSettings::default()) {
            Err(ShmError::Open { what: "service", .. }) => {}
            other => panic!("expected the lane to refuse the service, got {other:?}"),
        }
    }
}
