//! The in-process bus: every endpoint's published samples go, synchronously and in order, into the bounded inbox
//! of every other endpoint attached to the same [`Bus`]. With one thread driving several agents this is fully
//! deterministic; wrapped in a [`crate::fault::FaultInjector`] it becomes a seeded lossy network.
//!
//! **An inbox never holds more than its capacity**: a sample for a full inbox is dropped and counted (the
//! simulation treats it as loss, which anti-entropy repairs). Dropping an endpoint detaches it from the bus.

use std::collections::BTreeMap;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use bytes::Bytes;
use crossbeam_channel::{Receiver, Sender, TrySendError, bounded};

use crate::{Channel, Counters, EndpointId, Sample, Transport, TransportError, TransportStats};

/// Shared bus state: the inbox senders of the attached endpoints, by id.
#[derive(Debug, Default)]
struct BusInner {
    next_id: u64,
    inboxes: BTreeMap<EndpointId, (Sender<Sample>, Arc<Counters>)>,
}

/// An in-process bus. Cloning it gives another handle on the same bus.
#[derive(Clone, Debug, Default)]
pub struct Bus {
    inner: Arc<Mutex<BusInner>>,
}

impl Bus {
    /// An empty bus.
    pub fn new() -> Self {
        Bus::default()
    }

    /// Attaches a new endpoint whose inbox holds at most `inbox_capacity` samples. Ids are 1, 2, 3, ... in attach
    /// order, never reused on this bus.
    pub fn attach(&self, inbox_capacity: usize) -> InProcTransport {
        let (sender, receiver) = bounded(inbox_capacity.max(1));
        let counters = Arc::new(Counters::default());
        let mut inner = self.inner.lock().unwrap_or_else(|p| p.into_inner());
        inner.next_id += 1;
        let id = EndpointId(u128::from(inner.next_id));
        inner.inboxes.insert(id, (sender, Arc::clone(&counters)));
        InProcTransport { bus: self.clone(), id, inbox: receiver, counters }
    }

    /// Ids of the endpoints attached now.
    pub fn endpoints(&self) -> Vec<EndpointId> {
        self.inner.lock().unwrap_or_else(|p| p.into_inner()).inboxes.keys().copied().collect()
    }
}

/// One endpoint on a [`Bus`].
#[derive(Debug)]
pub struct InProcTransport {
    bus: Bus,
    id: EndpointId,
    inbox: Receiver<Sample>,
    counters: Arc<Counters>,
}

impl Drop for InProcTransport {
    fn drop(&mut self) {
        self.bus.inner.lock().unwrap_or_else(|p| p.into_inner()).inboxes.remove(&self.id);
    }
}

impl Transport for InProcTransport {
    fn local_id(&self) -> EndpointId {
        self.id
    }

    fn publish(&self, channel: Channel, bytes: Bytes) -> Result<(), TransportError> {
        self.counters.sent(bytes.len(), bytes.len());
        let inner = self.bus.inner.lock().unwrap_or_else(|p| p.into_inner());
        for (&id, (sender, counters)) in &inner.inboxes {
            if id == self.id {
                continue;
            }
            let sample = Sample { channel, origin: self.id, bytes: bytes.clone() };
            match sender.try_send(sample) {
                Ok(()) => {}
                Err(TrySendError::Full(_)) => counters.dropped_full(),
                Err(TrySendError::Disconnected(_)) => {}
            }
        }
        Ok(())
    }

    fn try_recv(&self) -> Option<Sample> {
        self.counters.take(&self.inbox, None)
    }

    fn recv_timeout(&self, timeout: Duration) -> Option<Sample> {
        self.counters.take(&self.inbox, Some(timeout))
    }

    fn stats(&self) -> TransportStats {
        self.counters.snapshot()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn delivers_to_others_in_order_not_to_self() {
        let bus = Bus::new();
        let a = bus.attach(8);
        let b = bus.attach(8);
        let c = bus.attach(8);
        a.publish(Channel::Updates, Bytes::from_static(b"1")).unwrap();
        a.publish(Channel::Sync, Bytes::from_static(b"2")).unwrap();
        assert!(a.try_recv().is_none());
        for endpoint in [&b, &c] {
            let first = endpoint.try_recv().unwrap();
            assert_eq!((first.channel, first.origin, &first.bytes[..]), (Channel::Updates, a.local_id(), &b"1"[..]));
            assert_eq!(&endpoint.try_recv().unwrap().bytes[..], b"2");
            assert!(endpoint.try_recv().is_none());
        }
        assert_eq!(a.stats().samples_sent, 2);
        assert_eq!(b.stats().samples_received, 2);
    }

    #[test]
    fn full_inbox_drops_and_counts_and_detach_on_drop() {
        let bus = Bus::new();
        let a = bus.attach(4);
        let b = bus.attach(2);
        for i in 0..5u8 {
            a.publish(Channel::Updates, Bytes::from(vec![i])).unwrap();
        }
        assert_eq!(b.stats().dropped_full, 3);
        assert_eq!(&b.try_recv().unwrap().bytes[..], &[0]);
        assert_eq!(&b.try_recv().unwrap().bytes[..], &[1]);
        assert!(b.try_recv().is_none());
        let b_id = b.local_id();
        drop(b);
        assert_eq!(bus.endpoints(), vec![a.local_id()]);
        let d = bus.attach(2);
        assert!(d.local_id() > b_id, "ids are never reused");
    }
}
