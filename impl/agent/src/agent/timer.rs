//! When the agent's own thread next has periodic work, so that an idle agent sleeps until then instead of waking
//! on a fixed tick.
//!
//! The thread's periodic work is the protocol core's ([`crate::core::AgentCore::tick`]), and the core says when it
//! is next due ([`crate::core::AgentCore::next_deadline_ns`]). Every thread that runs the core (a local write, a
//! sample handled on the transport's thread, the tick itself) records that deadline here while it holds the state
//! lock; one that moves it earlier than what the agent's thread waits for rings the thread awake.

use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

use crossbeam_channel::{Receiver, Sender, bounded};

/// The longest the agent's thread sleeps with nothing due: a safety net, not a schedule.
pub(super) const IDLE_LONGEST: Duration = Duration::from_secs(1);

/// The core's next deadline (in the agent clock's nanoseconds) and the bell that wakes the thread waiting for it.
pub(super) struct Timer {
    due_ns: AtomicU64,
    bell: (Sender<()>, Receiver<()>),
}

impl Default for Timer {
    fn default() -> Self {
        // One ring is enough to wake the thread, and is kept until it waits: a ring between the thread's look at
        // the deadline and its wait makes the wait return at once.
        Timer { due_ns: AtomicU64::new(0), bell: bounded(1) }
    }
}

impl Timer {
    /// After a core operation (under the state lock): the core's next deadline is `due_ns`. Rings the thread when
    /// that is earlier than what it waits for, and says so (a thread waiting on its transport instead must be
    /// interrupted there).
    pub(super) fn schedule(&self, due_ns: u64) -> bool {
        let earlier = due_ns < self.due_ns.fetch_min(due_ns, Ordering::AcqRel);
        if earlier {
            self.ring();
        }
        earlier
    }

    /// After the thread's own tick (under the state lock): the deadline is `due_ns`, which may be later than the
    /// one it replaces.
    pub(super) fn reset(&self, due_ns: u64) {
        self.due_ns.store(due_ns, Ordering::Release);
    }

    /// How long to sleep at `now_ns`: until the deadline, at most `longest`.
    pub(super) fn wait_at(&self, now_ns: u64, longest: Duration) -> Duration {
        Duration::from_nanos(self.due_ns.load(Ordering::Acquire).saturating_sub(now_ns)).min(longest)
    }

    /// Sleeps for `wait`, or until rung.
    pub(super) fn sleep(&self, wait: Duration) {
        let _ = self.bell.1.recv_timeout(wait);
    }

    /// Wakes the waiting thread (or the next wait, if none waits).
    pub(super) fn ring(&self) {
        let _ = self.bell.0.try_send(());
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_earlier_deadline_rings_and_a_later_one_does_not() {
        let timer = Timer::default();
        timer.reset(1_000);
        assert!(!timer.schedule(5_000));
        assert!(timer.bell.1.try_recv().is_err(), "a later deadline leaves the wait as it is");
        assert_eq!(timer.wait_at(400, IDLE_LONGEST), Duration::from_nanos(600));
        assert!(timer.schedule(700));
        assert!(timer.bell.1.try_recv().is_ok(), "an earlier deadline rings");
        assert_eq!(timer.wait_at(400, IDLE_LONGEST), Duration::from_nanos(300));
        assert_eq!(timer.wait_at(900, IDLE_LONGEST), Duration::ZERO, "a passed deadline is due at once");
    }

    #[test]
    fn a_wait_is_at_most_the_longest_and_a_ring_before_it_is_kept() {
        let timer = Timer::default();
        timer.reset(u64::MAX);
        assert_eq!(timer.wait_at(0, IDLE_LONGEST), IDLE_LONGEST);
        timer.ring();
        timer.ring();
        // Kept, so this returns at once rather than after an hour; the second ring was one too many and is gone.
        timer.sleep(Duration::from_secs(3600));
        assert!(timer.bell.1.try_recv().is_err());
    }
}
