//! How the `cortex` process's allocator treats large buffers.
//!
//! A camera frame or a point cloud passes through a few buffers of its size on every write and every receipt (the
//! delta's encoding, the sample's envelope, the copy out of shared memory). glibc's allocator maps a buffer of a few
//! MiB afresh from the kernel and unmaps it when freed, so every such buffer pays a page fault per 4 KiB page on
//! first touch: about 1.3 ms for 4 MiB on the project's 2-core VM, more than the copies themselves (`memcpy` of 4 MiB,
//! 0.1–0.2 ms). [`keep_freed_memory`] makes the allocator serve buffers up to [`MMAP_THRESHOLD_BYTES`] from its heap
//! and keep up to [`TRIM_THRESHOLD_BYTES`] of freed memory for reuse, so the next frame lands in pages already mapped.
//! The price is resident memory held after a burst, bounded by the trim threshold per heap.

/// Buffers up to this size come from the allocator's heap, not from a fresh mapping (glibc's largest allowed value on
/// 64-bit hosts; a lane's largest sample is 8 MiB).
pub const MMAP_THRESHOLD_BYTES: usize = 32 << 20;

/// Freed memory the allocator keeps per heap before giving it back to the kernel.
pub const TRIM_THRESHOLD_BYTES: usize = 256 << 20;

/// Tells glibc's allocator to reuse freed large buffers (see the module documentation). Returns whether both settings
/// were taken; on other C libraries it does nothing and returns `false`.
#[allow(unsafe_code)] // Two calls of glibc's `mallopt`, which has no safe wrapper.
pub fn keep_freed_memory() -> bool {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    {
        let as_int = |bytes: usize| libc::c_int::try_from(bytes).unwrap_or(libc::c_int::MAX);
        // SAFETY: `mallopt` only changes the allocator's parameters; it is called before this process starts any
        // thread of its own, and glibc serialises it with allocations anyway.
        let mmap = unsafe { libc::mallopt(libc::M_MMAP_THRESHOLD, as_int(MMAP_THRESHOLD_BYTES)) };
        // SAFETY: as above.
        let trim = unsafe { libc::mallopt(libc::M_TRIM_THRESHOLD, as_int(TRIM_THRESHOLD_BYTES)) };
        mmap == 1 && trim == 1
    }
    #[cfg(not(all(target_os = "linux", target_env = "gnu")))]
    {
        false
    }
}
