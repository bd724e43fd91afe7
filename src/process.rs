//! This process's id, for the fork check every handle makes (`Context::same_process`).
//! `std::process::id()` is a system call each time (glibc stopped caching `getpid` in 2.25),
//! and two of them cost about a fifth of a one-ray `rt2_intersect`. On Linux the id is kept
//! in a page of its own marked `MADV_WIPEONFORK` (Linux 4.14): the kernel hands the child of
//! every fork a zeroed copy, whatever made it (`fork`, `_Fork`, which runs no `pthread_atfork`
//! handler, a raw `clone` or `syscall(SYS_fork)`), so a child never sees its parent's id. A
//! `vfork` child shares the parent's memory and may only `exec` or `_exit`. Nothing here waits
//! for another thread: a fork that copies a thread halfway through the first call leaves the
//! child a state it can go on from (a lock or `Once` held by that thread would be held in the
//! child for good). Where the page cannot be had (another OS, an older kernel, no memory),
//! every call asks the system.

#[cfg(target_os = "linux")]
use std::sync::atomic::{AtomicU32, AtomicUsize, Ordering};

/// This process's id.
pub fn id() -> u32 {
    #[cfg(target_os = "linux")]
    if let Some(kept) = kept() {
        return match kept.load(Ordering::Relaxed) {
            0 => {
                // A thread of a parent that is forked between this read and the store leaves
                // the child a wiped page: it reads the id again.
                let id = std::process::id();
                kept.store(id, Ordering::Relaxed);
                id
            }
            id => id,
        };
    }
    std::process::id()
}

/// The wipe-on-fork word that keeps the id (0: not read yet in this process), made on first
/// use; `None` where it cannot be had.
#[cfg(target_os = "linux")]
fn kept() -> Option<&'static AtomicU32> {
    /// The page's address; 0 before the first call, `UNAVAILABLE` once it failed. Not in the
    /// page: a child keeps the mapping (wiped), so the address stays right.
    static PAGE: AtomicUsize = AtomicUsize::new(0);
    const UNAVAILABLE: usize = 1;
    let page = match PAGE.load(Ordering::Acquire) {
        0 => {
            let made = wipe_on_fork_page().unwrap_or(UNAVAILABLE);
            // Two threads' first calls may race: one page is kept, the other unmapped.
            match PAGE.compare_exchange(0, made, Ordering::AcqRel, Ordering::Acquire) {
                Ok(_) => made,
                Err(first) => {
                    if made != UNAVAILABLE {
                        // SAFETY: `made` is the page this call mapped, never published.
                        unsafe { libc::munmap(made as *mut libc::c_void, PAGE_LEN) };
                    }
                    first
                }
            }
        }
        p => p,
    };
    // SAFETY: a published page is mapped for good, readable and writable, page-aligned, and
    // holds nothing but this word.
    (page != UNAVAILABLE).then(|| unsafe { &*(page as *const AtomicU32) })
}

#[cfg(target_os = "linux")]
const PAGE_LEN: usize = 4096;

/// A zeroed private page that the kernel zeroes again in every forked child, as an address.
#[cfg(target_os = "linux")]
fn wipe_on_fork_page() -> Option<usize> {
    // SAFETY: a fresh anonymous mapping, given back on failure; nothing else refers to it.
    unsafe {
        let p = libc::mmap(
            std::ptr::null_mut(),
            PAGE_LEN,
            libc::PROT_READ | libc::PROT_WRITE,
            libc::MAP_PRIVATE | libc::MAP_ANONYMOUS,
            -1,
            0,
        );
        if p == libc::MAP_FAILED {
            return None;
        }
        if libc::madvise(p, PAGE_LEN, libc::MADV_WIPEONFORK) != 0 {
            libc::munmap(p, PAGE_LEN);
            return None;
        }
        Some(p as usize)
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_kept_id_is_the_systems() {
        assert_eq!(super::id(), std::process::id());
        assert_eq!(super::id(), std::process::id());
    }
}
