//! Change signals: every visible change goes, after the state lock is released, to each subscription's bounded
//! channel ([`Agent::subscribe`]) and to each change callback ([`Agent::on_change`]). While there is neither, the
//! replica does not look for changes at all (a write-only agent, a camera driver, pays nothing for them).
//!
//! A subscription costs its reader a thread hand-off per change (the receiving thread wakes the reader's); a
//! callback runs on the thread that made the change visible — the transport's receiving thread for a remote
//! change, the writer's for a local one — so the application sees the change one hand-off sooner. Callbacks run
//! with no lock of the agent held: one may read the graph and write to it (its own writes call it again, with
//! [`ChangeSignal::local`] set).

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};

use crossbeam_channel::{Receiver, Sender, TrySendError, bounded};
use dsr::ReplicaId;
use smallvec::SmallVec;
use transport::Transport;

use super::{Agent, ChangeSignal};
use crate::AgentId;

/// A function called with every visible change ([`Agent::on_change`]).
type ChangeCallback = Arc<dyn Fn(&ChangeSignal) + Send + Sync>;

/// Names a callback registered with [`Agent::on_change`], to remove it with [`Agent::remove_on_change`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct CallbackId(u64);

/// Where change signals go.
#[derive(Default)]
pub(super) struct Signals {
    subscribers: Mutex<Vec<Sender<ChangeSignal>>>,
    callbacks: Mutex<Vec<(CallbackId, ChangeCallback)>>,
    next_callback: AtomicU64,
    /// Signals a full subscription could not take.
    dropped: AtomicU64,
}

impl Signals {
    /// Whether anyone listens: a subscription or a callback. Without one, a change costs no signal at all.
    pub(super) fn listened(&self) -> bool {
        !self.subscribers.lock().unwrap_or_else(|p| p.into_inner()).is_empty()
            || !self.callbacks.lock().unwrap_or_else(|p| p.into_inner()).is_empty()
    }

    /// Signals a full subscription could not take, so far.
    pub(super) fn dropped(&self) -> u64 {
        self.dropped.load(Ordering::Relaxed)
    }

    /// Hands every change to the subscriptions and then to the callbacks; `mine` is this agent's replica, to tell
    /// local changes from remote ones.
    pub(super) fn deliver(&self, mine: Option<ReplicaId>, changes: Vec<dsr::ChangeEvent>) {
        // Copied out, so that a callback may register, remove or write (which signals again) without a deadlock.
        // Held in place for the few callbacks and changes of a usual write (no allocation on the way to them).
        let callbacks: SmallVec<[ChangeCallback; 4]> =
            self.callbacks.lock().unwrap_or_else(|p| p.into_inner()).iter().map(|(_, f)| Arc::clone(f)).collect();
        let count = changes.len();
        let signals: SmallVec<[ChangeSignal; 2]> = changes
            .into_iter()
            .enumerate()
            .map(|(index, event)| ChangeSignal {
                origin: event.origin.map(AgentId::of_replica),
                local: event.origin.is_some() && event.origin == mine,
                change: event.change,
                last_together: index + 1 == count,
            })
            .collect();
        {
            let mut subscribers = self.subscribers.lock().unwrap_or_else(|p| p.into_inner());
            for signal in &signals {
                subscribers.retain(|sender| match sender.try_send(signal.clone()) {
                    Ok(()) => true,
                    Err(TrySendError::Full(_)) => {
                        self.dropped.fetch_add(1, Ordering::Relaxed);
                        true
                    }
                    Err(TrySendError::Disconnected(_)) => false,
                });
            }
        }
        for signal in &signals {
            for callback in &callbacks {
                callback(signal);
            }
        }
    }
}

impl<T: Transport + 'static> Agent<T> {
    /// A new subscription to change signals, holding up to `capacity` undelivered signals (a full subscription
    /// drops the newest and counts it in [`crate::AgentStatus::signals_dropped`]).
    pub fn subscribe(&self, capacity: usize) -> Receiver<ChangeSignal> {
        let (sender, receiver) = bounded(capacity.max(1));
        self.inner.signals.subscribers.lock().unwrap_or_else(|p| p.into_inner()).push(sender);
        self.inner.track_changes_if_listened();
        receiver
    }

    /// Calls `callback` with every visible change from now on, on the thread that made it visible, with no lock
    /// of the agent held (see the module documentation): it may read and write the graph, and may run on several
    /// threads at once. A callback that takes long delays the samples behind the one it was called for; hand long
    /// work to a thread of your own, or use [`Agent::subscribe`]. A callback that uses the agent holds it by
    /// [`std::sync::Weak`] (an `Arc` inside would keep the agent alive through its own callback list).
    ///
    /// ```
    /// # use std::sync::Arc;
    /// # use agent::{Agent, AgentConfig, AgentId};
    /// # use transport::{inproc::Bus, ManualClock};
    /// let bus = Bus::new();
    /// let agent = Arc::new(Agent::new(AgentConfig::new(AgentId(1)), bus.attach(64), Arc::new(ManualClock::new(0))).unwrap());
    /// let weak = Arc::downgrade(&agent);
    /// let id = agent.on_change(move |signal| {
    ///     if let Some(agent) = weak.upgrade().filter(|_| !signal.local) {
    ///         let _nodes = agent.status().nodes; // reads (and writes) are allowed here
    ///     }
    /// });
    /// assert!(agent.remove_on_change(id));
    /// ```
    pub fn on_change(&self, callback: impl Fn(&ChangeSignal) + Send + Sync + 'static) -> CallbackId {
        let id = CallbackId(self.inner.signals.next_callback.fetch_add(1, Ordering::Relaxed));
        self.inner.signals.callbacks.lock().unwrap_or_else(|p| p.into_inner()).push((id, Arc::new(callback)));
        self.inner.track_changes_if_listened();
        id
    }

    /// Stops calling the callback `id`; says whether it was registered. A call already under way finishes.
    pub fn remove_on_change(&self, id: CallbackId) -> bool {
        let removed = {
            let mut callbacks = self.inner.signals.callbacks.lock().unwrap_or_else(|p| p.into_inner());
            let before = callbacks.len();
            callbacks.retain(|(registered, _)| *registered != id);
            callbacks.len() != before
        };
        self.inner.track_changes_if_listened();
        removed
    }
}
