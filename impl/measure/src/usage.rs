//! What the operating system says a run cost: CPU time of a thread, of the process or of another process, peak resident memory, and
//! the loopback interface's transmitted bytes. Linux `/proc` and `getrusage`; `None` where unreadable.

/// CPU time of the calling thread in nanoseconds, from `/proc/thread-self/schedstat` (Linux).
pub fn thread_cpu_ns() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/thread-self/schedstat").ok()?;
    text.split_whitespace().next()?.parse().ok()
}

/// CPU time of every thread of this process (user + system) in nanoseconds, from `getrusage`.
#[allow(unsafe_code)]
pub fn process_cpu_ns() -> Option<u64> {
    // SAFETY: an all-zero rusage is a valid value of this plain C struct.
    let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
    // SAFETY: `usage` is a valid, writable rusage; RUSAGE_SELF is always supported.
    if unsafe { libc::getrusage(libc::RUSAGE_SELF, &mut usage) } != 0 {
        return None;
    }
    let ns = |t: libc::timeval| (t.tv_sec as u64) * 1_000_000_000 + (t.tv_usec as u64) * 1_000;
    Some(ns(usage.ru_utime) + ns(usage.ru_stime))
}

/// CPU time of every live thread of process `pid` in nanoseconds: the sum of `/proc/PID/task/*/schedstat` (Linux;
/// a thread that has exited no longer counts). `None` when the process is gone or nothing could be read.
pub fn process_cpu_ns_of(pid: u32) -> Option<u64> {
    let tasks = std::fs::read_dir(format!("/proc/{pid}/task")).ok()?;
    let mut total = None;
    for task in tasks.flatten() {
        let Ok(text) = std::fs::read_to_string(task.path().join("schedstat")) else { continue };
        if let Some(ns) = text.split_whitespace().next().and_then(|field| field.parse::<u64>().ok()) {
            total = Some(total.unwrap_or(0) + ns);
        }
    }
    total
}

/// Transmitted bytes of the loopback interface of this process's network namespace (Linux; see
/// [`crate::netns::LoopbackCounters`], which reads `/proc/self/net/dev` because `/sys/class/net` shows the
/// namespace that mounted `/sys`).
pub fn loopback_tx_bytes() -> Option<u64> {
    crate::netns::LoopbackCounters::read().ok().map(|counters| counters.tx_bytes)
}

/// Peak resident memory of this process in bytes (`VmHWM` in `/proc/self/status`).
pub fn peak_rss_bytes() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = text.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024)
}
