//! Remote access: other threads (and later the network) call a component's modulation and
//! result methods by sending a closure through a bounded queue. The scheduler thread runs
//! queued closures between steps, so the step path itself takes no lock and a component is
//! never touched by two threads at once. Replies come back through a one-shot channel.

use std::sync::mpsc::{Receiver, SyncSender, TrySendError, sync_channel};

use crate::component::{Component, Registry};
use crate::component_id::ComponentId;
use crate::core::SchedulerCore;
use crate::error::BicaError;
use crate::stats::{Statistics, StatisticsReport};

/// What a remote closure can reach, on the scheduler thread, between two steps.
pub struct Control<'a> {
    pub(crate) registry: &'a mut Registry,
    pub(crate) core: &'a mut SchedulerCore,
    pub(crate) stats: &'a Statistics,
    pub(crate) now_ns: u64,
}

impl Control<'_> {
    /// Reads component `T`.
    pub fn get<T: Component>(&self) -> Result<&T, BicaError> {
        self.registry.get::<T>()
    }

    /// Mutably reaches component `T` (set a modulation).
    pub fn get_mut<T: Component>(&mut self) -> Result<&mut T, BicaError> {
        self.registry.get_mut::<T>()
    }

    /// Adds `T` to the end of the active list.
    pub fn activate<T: Component>(&mut self) -> Result<(), BicaError> {
        let id = self.registry.handle::<T>()?.id();
        self.core.activate(id, self.now_ns)
    }

    /// Removes `T` from the active list.
    pub fn deactivate<T: Component>(&mut self) -> Result<(), BicaError> {
        let id = self.registry.handle::<T>()?.id();
        self.core.deactivate(id, self.now_ns)
    }

    /// The active list in stepping order, as type names.
    pub fn active_names(&self) -> Vec<&'static str> {
        self.core.active().iter().map(|&id: &ComponentId| self.registry.name(id).unwrap_or("?")).collect()
    }

    /// Current statistics.
    pub fn statistics(&self) -> StatisticsReport {
        self.stats.report(|id| self.registry.name(id).ok(), self.core, self.now_ns)
    }
}

/// A unit of work for the scheduler thread.
pub(crate) enum Request {
    /// Run this closure between steps.
    Run(Box<dyn FnOnce(&mut Control<'_>) + Send>),
    /// Stop the driver loop.
    Stop,
}

/// Cloneable, `Send` handle to a runtime's request queue.
#[derive(Clone)]
pub struct RemoteHandle {
    sender: SyncSender<Request>,
    capacity: usize,
}

impl std::fmt::Debug for RemoteHandle {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RemoteHandle").field("capacity", &self.capacity).finish()
    }
}

/// A reply that has not necessarily arrived yet.
#[derive(Debug)]
pub struct PendingReply<R> {
    receiver: Receiver<R>,
}

impl<R> PendingReply<R> {
    /// Blocks until the scheduler thread has run the request.
    pub fn wait(self) -> Result<R, BicaError> {
        self.receiver.recv().map_err(|_| BicaError::SchedulerStopped)
    }

    /// Returns the reply if it has arrived.
    pub fn try_take(&self) -> Option<R> {
        self.receiver.try_recv().ok()
    }
}

pub(crate) fn request_queue(capacity: usize) -> (RemoteHandle, Receiver<Request>) {
    let (sender, receiver) = sync_channel(capacity);
    (RemoteHandle { sender, capacity }, receiver)
}

impl RemoteHandle {
    fn send(&self, request: Request) -> Result<(), BicaError> {
        self.sender.try_send(request).map_err(|error| match error {
            TrySendError::Full(_) => BicaError::QueueFull { capacity: self.capacity },
            TrySendError::Disconnected(_) => BicaError::SchedulerStopped,
        })
    }

    /// Queues `f` to run on the scheduler thread between steps; does not wait.
    pub fn submit<R: Send + 'static>(
        &self,
        f: impl FnOnce(&mut Control<'_>) -> R + Send + 'static,
    ) -> Result<PendingReply<R>, BicaError> {
        let (reply_sender, receiver) = sync_channel(1);
        self.send(Request::Run(Box::new(move |control| {
            // The caller may have given up waiting; a lost reply is fine then.
            let _ = reply_sender.send(f(control));
        })))?;
        Ok(PendingReply { receiver })
    }

    /// Runs `f` on component `T` on the scheduler thread and waits for its result.
    /// Do not call this from the scheduler thread itself (it would wait forever); use
    /// [`submit`](Self::submit) there.
    pub fn call<T: Component, R: Send + 'static>(
        &self,
        f: impl FnOnce(&mut T) -> R + Send + 'static,
    ) -> Result<R, BicaError> {
        self.submit(move |control| control.get_mut::<T>().map(f))?.wait()?
    }

    /// Asks the driver loop to stop after the current step.
    pub fn stop(&self) -> Result<(), BicaError> {
        self.send(Request::Stop)
    }
}
