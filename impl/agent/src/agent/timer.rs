//! When the agent's own thread next has periodic work, so that an idle agent sleeps until then instead of waking
//! on a fixed tick.
//!
//! The thread's periodic work is the protocol core's ([`crate::core::AgentCore::tick`]), and the core says when it
//! is next due ([`crate::core::AgentCore::next_deadline_ns`]). Every thread that runs the core (a local write, a
//! sample handled on the transport's thread, the tick itself) records that deadline here while it holds the state
//! lock; one that moves it earlier than what the agent's thread waits for rings the thread awake, once it has
//! released the lock and published (the deadline is at least the quiet period away, and a thread woken at once
//! would compete with the publish for the CPU). A thread woken before its deadline only sleeps again.
//!
//! The thread wakes on a grid of its own (a tick apart, from when the agent started), at the first point at or after
//! the deadline. A deadline is often a write's time plus the quiet period, and writes come on a grid of their own
//! (a camera at 20 Hz): waking at the deadline itself would wake the thread at the moment of a later write, where
//! it competes with the writer for the CPU (a 20 Hz stream to one same-host receiver over `auto` was 70–80 µs
//! slower at p50 so, `cortex bench payload`, 2026-11-27). On its own grid it wakes at one phase of the stream,
//! as the fixed tick it replaced did.

use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

use crossbeam_channel::{Receiver, Sender, bounded};

/// The longest the agent's thread sleeps with nothing due: a safety net, not a schedule.
pub(super) const IDLE_LONGEST: Duration = Duration::from_secs(1);

/// The core's next deadline (in the agent clock's nanoseconds) and the bell that wakes the thread waiting for it.
pub(super) struct Timer {
    due_ns: AtomicU64,
    bell: (Sender<()>, Receiver<()>),
    /// The thread's grid: where it starts and its step (at least 1 ns).
    grid_ns: (u64, u64),
}

impl Timer {
    /// A timer whose thread wakes on a grid from `origin_ns`, `step` apart.
    pub(super) fn new(origin_ns: u64, step: Duration) -> Self {
        // One ring is enough to wake the thread, and is kept until it waits: a ring between the thread's look at
        // the deadline and its wait makes the wait return at once.
        let step_ns = u64::try_from(step.as_nanos()).unwrap_or(u64::MAX).max(1);
        Timer { due_ns: AtomicU64::new(0), bell: bounded(1), grid_ns: (origin_ns, step_ns) }
    }

    /// After a core operation (under the state lock): the core's next deadline is `due_ns`. Says whether that is
    /// earlier than what the thread waits for: then the caller wakes it ([`Timer::ring`], or the transport's
    /// interrupt for a thread waiting there) once it has released the lock.
    pub(super) fn schedule(&self, due_ns: u64) -> bool {
        due_ns < self.due_ns.fetch_min(due_ns, Ordering::AcqRel)
    }

    /// Whether the deadline has come at `now_ns` (a thread woken sooner has nothing to do).
    pub(super) fn is_due(&self, now_ns: u64) -> bool {
        self.due_ns.load(Ordering::Acquire) <= now_ns
    }

    /// After the thread's own tick (under the state lock): the deadline is `due_ns`, which may be later than the
    /// one it replaces.
    pub(super) fn reset(&self, due_ns: u64) {
        self.due_ns.store(due_ns, Ordering::Release);
    }

    /// How long to sleep at `now_ns`: until the first point of the grid at or after the deadline (none if the
    /// deadline has passed), at most `longest`.
    pub(super) fn wait_at(&self, now_ns: u64, longest: Duration) -> Duration {
        let due_ns = self.due_ns.load(Ordering::Acquire);
        if due_ns <= now_ns {
            return Duration::ZERO;
        }
        let (origin_ns, step_ns) = self.grid_ns;
        let on_grid_ns = due_ns.saturating_sub(origin_ns).div_ceil(step_ns).saturating_mul(step_ns);
        Duration::from_nanos(origin_ns.saturating_add(on_grid_ns).saturating_sub(now_ns)).min(longest)
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
    fn an_earlier_deadline_needs_a_wake_and_a_later_one_does_not() {
        let timer = Timer::new(0, Duration::from_nanos(1));
        timer.reset(1_000);
        assert!(!timer.schedule(5_000), "a later deadline leaves the wait as it is");
        assert_eq!(timer.wait_at(400, IDLE_LONGEST), Duration::from_nanos(600));
        assert!(timer.schedule(700), "an earlier deadline needs the thread woken");
        assert_eq!(timer.wait_at(400, IDLE_LONGEST), Duration::from_nanos(300));
        assert!(!timer.is_due(699) && timer.is_due(700));
        assert_eq!(timer.wait_at(900, IDLE_LONGEST), Duration::ZERO, "a passed deadline is due at once");
    }

    #[test]
    fn a_wait_is_at_most_the_longest_and_a_ring_before_it_is_kept() {
        let timer = Timer::new(0, Duration::from_millis(50));
        timer.reset(u64::MAX);
        assert_eq!(timer.wait_at(0, IDLE_LONGEST), IDLE_LONGEST);
        timer.ring();
        timer.ring();
        // Kept, so this returns well before its 20 s; the second ring was one too many and is gone.
        let started = std::time::Instant::now();
        timer.sleep(Duration::from_secs(20));
        assert!(started.elapsed() < Duration::from_secs(20), "the ring was not kept");
        assert!(timer.bell.1.try_recv().is_err());
    }

    #[test]
    fn the_thread_wakes_on_its_own_grid_at_or_after_the_deadline() {
        // A grid from 7 ms, 50 ms apart: 57, 107, 157, ... ms.
        let ms = 1_000_000;
        let timer = Timer::new(7 * ms, Duration::from_millis(50));
        // A write at 50 ms puts the quiet announce at 150 ms; the thread wakes at 157 ms, between the writes of a
        // 20 Hz stream (150 and 200 ms), not on one.
        timer.reset(150 * ms);
        assert_eq!(timer.wait_at(60 * ms, IDLE_LONGEST), Duration::from_millis(97));
        // A deadline on the grid is kept as it is.
        timer.reset(107 * ms);
        assert_eq!(timer.wait_at(60 * ms, IDLE_LONGEST), Duration::from_millis(47));
        // A passed deadline is due at once, off the grid.
        assert_eq!(timer.wait_at(108 * ms, IDLE_LONGEST), Duration::ZERO);
    }
}
