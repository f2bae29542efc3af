//! The bounded update stream. One hub thread takes the agent's change signals (a bounded subscription) and marks
//! the changed elements in each connected client's **pending set**; a client's set holds element ids only, so a
//! thousand writes to one attribute are one entry (coalesced, latest value read when sent). Each client's writer
//! sends at most one message per [`MIN_INTERVAL`], reading the current values of its pending elements; a set that
//! grows past [`MAX_PENDING`] is dropped for a full snapshot (counted as a resync). If the agent reports dropped
//! signals, every client resyncs. So memory per client is bounded by [`MAX_PENDING`] ids, the message rate by
//! [`MIN_INTERVAL`], and a message's size by the graph's size — whatever the update rate.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::time::{Duration, Instant};

use crate::feed::{GraphFeed, Next};
use crate::view::Dirty;

/// Shortest time between two messages to one client (so at most 10 per second).
pub const MIN_INTERVAL: Duration = Duration::from_millis(100);
/// Most pending element ids per client before it is sent a snapshot instead.
pub const MAX_PENDING: usize = 4096;
/// Most streaming clients at once.
pub const MAX_CLIENTS: usize = 8;
/// Capacity of the inspector's subscription to the agent's change signals.
pub const SIGNAL_CAPACITY: usize = 8192;

/// What one client still has to be sent.
#[derive(Debug, Default)]
pub struct Pending {
    /// Elements changed since the last message.
    pub dirty: Dirty,
    /// Send a whole snapshot next.
    pub resync: bool,
}

/// Counters of one client, shown in the page's status line.
#[derive(Debug, Default, serde::Serialize, Clone, Copy, PartialEq, Eq)]
pub struct ClientCounters {
    /// Messages sent.
    pub messages: u64,
    /// Changes folded into an element already pending.
    pub coalesced: u64,
    /// Pending sets dropped for a snapshot.
    pub resyncs: u64,
}

/// One streaming client's pending set.
#[derive(Debug, Default)]
pub struct Client {
    pending: Mutex<Pending>,
    wake: Condvar,
    counters: Mutex<ClientCounters>,
    closed: AtomicBool,
}

fn lock<T>(mutex: &Mutex<T>) -> MutexGuard<'_, T> {
    mutex.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
}

impl Client {
    fn mark(&self, changes: &[dsr::Change]) {
        let mut pending = lock(&self.pending);
        if !pending.resync {
            let before = pending.dirty.len();
            for change in changes {
                pending.dirty.add(change);
            }
            let added = pending.dirty.len() - before;
            let mut counters = lock(&self.counters);
            counters.coalesced += (changes.len() - added) as u64;
            if pending.dirty.len() > MAX_PENDING {
                pending.dirty = Dirty::default();
                pending.resync = true;
                counters.resyncs += 1;
            }
        }
        self.wake.notify_all();
    }

    fn resync(&self) {
        let mut pending = lock(&self.pending);
        pending.dirty = Dirty::default();
        if !pending.resync {
            pending.resync = true;
            lock(&self.counters).resyncs += 1;
        }
        self.wake.notify_all();
    }

    /// Waits until something is pending or `timeout` passes, then takes what is pending.
    pub fn wait_take(&self, timeout: Duration) -> Pending {
        let deadline = Instant::now() + timeout;
        let mut pending = lock(&self.pending);
        while !pending.resync && pending.dirty.is_empty() {
            let now = Instant::now();
            if now >= deadline || self.closed.load(Ordering::Relaxed) {
                break;
            }
            pending = self.wake.wait_timeout(pending, deadline - now).unwrap_or_else(|p| p.into_inner()).0;
        }
        std::mem::take(&mut *pending)
    }

    /// Whether something is pending.
    pub fn has_pending(&self) -> bool {
        let pending = lock(&self.pending);
        pending.resync || !pending.dirty.is_empty()
    }

    /// Counts a message sent.
    pub fn sent(&self) {
        lock(&self.counters).messages += 1;
    }

    /// The counters.
    pub fn counters(&self) -> ClientCounters {
        *lock(&self.counters)
    }
}

/// The clients and the thread that feeds them.
#[derive(Debug, Default)]
pub struct Hub {
    clients: Mutex<Vec<Arc<Client>>>,
    stop: AtomicBool,
    signals: AtomicU64,
}

impl Hub {
    /// Registers a client, or `None` when [`MAX_CLIENTS`] are connected.
    pub fn join(&self) -> Option<Arc<Client>> {
        let mut clients = lock(&self.clients);
        if clients.len() >= MAX_CLIENTS {
            return None;
        }
        let client = Arc::new(Client::default());
        clients.push(Arc::clone(&client));
        Some(client)
    }

    /// Unregisters a client.
    pub fn leave(&self, client: &Arc<Client>) {
        client.closed.store(true, Ordering::Relaxed);
        lock(&self.clients).retain(|c| !Arc::ptr_eq(c, client));
    }

    /// Clients connected.
    pub fn client_count(&self) -> usize {
        lock(&self.clients).len()
    }

    /// Change signals received so far.
    pub fn signals(&self) -> u64 {
        self.signals.load(Ordering::Relaxed)
    }

    /// Marks `changes` pending for every client.
    pub fn mark(&self, changes: &[dsr::Change]) {
        self.signals.fetch_add(changes.len() as u64, Ordering::Relaxed);
        for client in lock(&self.clients).iter() {
            client.mark(changes);
        }
    }

    /// Makes every client resync.
    pub fn resync_all(&self) {
        for client in lock(&self.clients).iter() {
            client.resync();
        }
    }

    /// Asks the hub thread to stop.
    pub fn stop(&self) {
        self.stop.store(true, Ordering::SeqCst);
    }

    /// The hub thread's loop: change signals to pending sets until [`Hub::stop`] or the feed closes.
    pub fn run(&self, feed: &dyn GraphFeed) {
        let stream = feed.changes(SIGNAL_CAPACITY);
        let mut dropped = feed.status().signals_dropped;
        let mut checked = Instant::now();
        let mut batch = Vec::new();
        while !self.stop.load(Ordering::SeqCst) {
            match stream.next(Duration::from_millis(100)) {
                Next::Change(change) => {
                    batch.push(change);
                    while batch.len() < 1024 {
                        let Some(change) = stream.try_next() else { break };
                        batch.push(change);
                    }
                    self.mark(&batch);
                    batch.clear();
                }
                Next::Timeout => {}
                Next::Closed => break,
            }
            if checked.elapsed() >= Duration::from_secs(1) {
                checked = Instant::now();
                let now_dropped = feed.status().signals_dropped;
                if now_dropped > dropped {
                    dropped = now_dropped;
                    self.resync_all();
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use dsr::{Change, Element, Name, NodeId};

    fn attr(id: u64) -> Change {
        Change::AttrUpdated { element: Element::Node(NodeId(id)), name: Name::new("x") }
    }

    #[test]
    fn repeated_changes_coalesce_and_a_flood_becomes_one_resync() {
        let hub = Hub::default();
        let client = hub.join().unwrap();
        hub.mark(&vec![attr(1); 1000]);
        assert_eq!(client.counters().coalesced, 999);
        let pending = client.wait_take(Duration::ZERO);
        assert_eq!(pending.dirty.len(), 1);
        assert!(!pending.resync);
        let flood: Vec<Change> = (0..MAX_PENDING as u64 + 10).map(attr).collect();
        hub.mark(&flood);
        hub.mark(&flood);
        let pending = client.wait_take(Duration::ZERO);
        assert!(pending.resync);
        assert!(pending.dirty.is_empty(), "a resync holds no ids");
        assert_eq!(client.counters().resyncs, 1);
        assert!(!client.has_pending());
    }

    #[test]
    fn the_number_of_clients_is_bounded() {
        let hub = Hub::default();
        let clients: Vec<_> = (0..MAX_CLIENTS).map(|_| hub.join().unwrap()).collect();
        assert!(hub.join().is_none());
        hub.leave(&clients[0]);
        assert!(hub.join().is_some());
    }
}
