//! Injected time. The scheduler core never reads a clock: drivers pass it readings taken
//! from a [`Clock`]. [`MonotonicClock`] is the real one; [`VirtualClock`] is advanced
//! explicitly so tests and the model checker decide every duration. Times and periods are `u64` nanoseconds
//! (`_ns`); [`ns_from_ms`] is the one conversion from milliseconds.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

/// Nanoseconds in a millisecond: the scheduler's clock and periods count nanoseconds, people and command lines
/// milliseconds.
pub const NS_PER_MS: u64 = 1_000_000;

/// A duration of `ms` milliseconds in the scheduler's unit, nanoseconds (saturating at `u64::MAX`, some 584
/// years).
///
/// ```
/// assert_eq!(bica::clock::ns_from_ms(33), 33_000_000);
/// ```
pub fn ns_from_ms(ms: u64) -> u64 {
    ms.saturating_mul(NS_PER_MS)
}

/// A source of time for the runtime driver and for step measurements.
pub trait Clock {
    /// Monotonic time in nanoseconds since an arbitrary origin fixed at clock creation.
    fn now_ns(&self) -> u64;
    /// CPU time consumed by the calling thread, in nanoseconds.
    fn thread_cpu_ns(&self) -> u64;
    /// Waits until `deadline_ns` (a real clock sleeps, a virtual clock jumps there).
    fn sleep_until_ns(&self, deadline_ns: u64);
}

/// The real monotonic clock plus the thread CPU clock.
///
/// Reads the calibrated time-stamp counter through `quanta` (a few nanoseconds per read; `quanta` falls back to the
/// OS monotonic clock where the counter is not reliable). The scheduler reads the clock twice per step, and with
/// `std::time::Instant` (about 25 ns per read on this project's machines) those reads were half its overhead.
#[derive(Debug, Clone)]
pub struct MonotonicClock {
    clock: quanta::Clock,
    origin: u64,
}

impl MonotonicClock {
    /// Creates a clock whose zero is now.
    pub fn new() -> Self {
        let clock = quanta::Clock::new();
        let origin = clock.raw();
        Self { clock, origin }
    }
}

impl Default for MonotonicClock {
    fn default() -> Self {
        Self::new()
    }
}

impl Clock for MonotonicClock {
    fn now_ns(&self) -> u64 {
        // u64 nanoseconds last 584 years.
        self.clock.delta_as_nanos(self.origin, self.clock.raw())
    }

    fn thread_cpu_ns(&self) -> u64 {
        thread_cpu_time_ns()
    }

    fn sleep_until_ns(&self, deadline_ns: u64) {
        let now = self.now_ns();
        if deadline_ns > now {
            std::thread::sleep(Duration::from_nanos(deadline_ns - now));
        }
    }
}

/// CPU time of the calling thread from `CLOCK_THREAD_CPUTIME_ID`, or 0 if unavailable.
#[allow(unsafe_code)]
pub fn thread_cpu_time_ns() -> u64 {
    let mut spec = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: `spec` is a valid, exclusively borrowed timespec for the duration of the call
    // and CLOCK_THREAD_CPUTIME_ID is a clock id every supported Unix accepts.
    let rc = unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut spec) };
    if rc != 0 {
        return 0;
    }
    let secs = u64::try_from(spec.tv_sec).unwrap_or(0);
    let nanos = u64::try_from(spec.tv_nsec).unwrap_or(0);
    secs.saturating_mul(1_000_000_000).saturating_add(nanos)
}

/// A clock that only moves when told to. Clones share the same time, so a test component
/// can "spend" time inside its step by calling [`VirtualClock::advance_ns`]. Its thread CPU
/// time equals its wall time (a simulated step is all computation).
///
/// ```
/// use bica::clock::{Clock, VirtualClock};
/// let clock = VirtualClock::new(0);
/// clock.advance_ns(5);
/// clock.sleep_until_ns(20);
/// assert_eq!(clock.now_ns(), 20);
/// ```
#[derive(Debug, Clone, Default)]
pub struct VirtualClock {
    now_ns: Arc<AtomicU64>,
}

impl VirtualClock {
    /// Creates a virtual clock reading `start_ns`.
    pub fn new(start_ns: u64) -> Self {
        Self { now_ns: Arc::new(AtomicU64::new(start_ns)) }
    }

    /// Moves time forward by `duration_ns`.
    pub fn advance_ns(&self, duration_ns: u64) {
        self.now_ns.fetch_add(duration_ns, Ordering::SeqCst);
    }

    /// Sets time to `time_ns` if that is later than now (time never goes back).
    pub fn advance_to_ns(&self, time_ns: u64) {
        self.now_ns.fetch_max(time_ns, Ordering::SeqCst);
    }
}

impl Clock for VirtualClock {
    fn now_ns(&self) -> u64 {
        self.now_ns.load(Ordering::SeqCst)
    }

    fn thread_cpu_ns(&self) -> u64 {
        self.now_ns()
    }

    fn sleep_until_ns(&self, deadline_ns: u64) {
        self.advance_to_ns(deadline_ns);
    }
}
