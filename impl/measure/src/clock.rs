//! One monotonic clock for a whole run: nanoseconds since the run's origin on `std::time::Instant`, shared by
//! every thread (and usable as a [`transport::Clock`] for the fault injector), so a send time taken on the
//! source thread and an apply time taken on a receiver thread are differences on the same clock.

use std::time::{Duration, Instant};

/// Nanoseconds since an origin on the monotonic clock. Copies share the origin.
#[derive(Clone, Copy, Debug)]
pub struct MonoClock {
    origin: Instant,
}

impl MonoClock {
    /// A clock whose origin is now.
    pub fn start() -> Self {
        MonoClock { origin: Instant::now() }
    }

    /// Nanoseconds since the origin.
    pub fn now_ns(&self) -> u64 {
        u64::try_from(self.origin.elapsed().as_nanos()).unwrap_or(u64::MAX)
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
}
