//! One monotonic clock for a whole run: nanoseconds since the run's origin on the host's `CLOCK_MONOTONIC`, shared
//! by every thread and every process of the run (and usable as a [`transport::Clock`] for the fault injector), so
//! a send time taken by the source and an apply time taken by a receiver — another thread or another process on
//! the same host — are differences on the same clock.
//!
//! The origin is an absolute `CLOCK_MONOTONIC` reading ([`MonoClock::origin_ns`]); a receiver process is given it
//! and rebuilds the same clock with [`MonoClock::with_origin`].

use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

/// Nanoseconds since an origin on the host's monotonic clock. Copies share the origin.
#[derive(Clone, Copy, Debug)]
pub struct MonoClock {
    origin: u64,
}

/// `CLOCK_MONOTONIC` in nanoseconds: the same clock in every process of the host.
#[allow(unsafe_code)]
fn monotonic_ns() -> u64 {
    let mut ts = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: `ts` is a valid, writable timespec; CLOCK_MONOTONIC is always supported on Linux.
    let rc = unsafe { libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts) };
    debug_assert_eq!(rc, 0);
    (ts.tv_sec as u64).saturating_mul(1_000_000_000).saturating_add(ts.tv_nsec as u64)
}

/// A number distinguishing runs of this process (topic names of RTPS runs).
pub(crate) fn run_number() -> u64 {
    static NEXT: AtomicU64 = AtomicU64::new(0);
    NEXT.fetch_add(1, Ordering::Relaxed)
}

impl MonoClock {
    /// A clock whose origin is now.
    pub fn start() -> Self {
        MonoClock { origin: monotonic_ns() }
    }

    /// The clock of another process of the same run: `origin_ns` is that run's [`MonoClock::origin_ns`].
    pub fn with_origin(origin_ns: u64) -> Self {
        MonoClock { origin: origin_ns }
    }

    /// The origin as an absolute `CLOCK_MONOTONIC` reading, to hand to other processes of the run.
    pub fn origin_ns(&self) -> u64 {
        self.origin
    }

    /// Nanoseconds since the origin.
    pub fn now_ns(&self) -> u64 {
        monotonic_ns().saturating_sub(self.origin)
    }

    /// Sleeps until `due_ns` on this clock (returns at once if it has passed).
    pub fn sleep_until(&self, due_ns: u64) {
        let now = self.now_ns();
        if due_ns > now {
            std::thread::sleep(Duration::from_nanos(due_ns - now));
        }
    }
}

impl transport::Clock for MonoClock {
    fn now_ns(&self) -> u64 {
        MonoClock::now_ns(self)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn copies_share_the_origin_and_time_never_goes_back() {
        let a = MonoClock::start();
        let b = a;
        let first = a.now_ns();
        a.sleep_until(first + 1_000_000);
        let second = b.now_ns();
        assert!(second >= first + 1_000_000, "{first} then {second}");
    }

    #[test]
    fn a_clock_rebuilt_from_the_origin_reads_the_same_time() {
        let a = MonoClock::start();
        a.sleep_until(2_000_000);
        let b = MonoClock::with_origin(a.origin_ns());
        let (x, y, z) = (a.now_ns(), b.now_ns(), a.now_ns());
        assert!(x <= y && y <= z, "{x} {y} {z}");
    }
}
