//! This process's id, for the fork check every handle makes (`Context::same_process`).
//! `std::process::id()` is a system call each time (glibc stopped caching `getpid` in 2.25),
//! and two of them cost about a fifth of a one-ray `rt2_intersect`. The id is read once and
//! forgotten in the child of every `fork()`, by a `pthread_atfork` handler registered before
//! any id is kept. A child made without those handlers (a raw `clone`, or `vfork`, whose child
//! may only `exec` or `_exit`) would keep its parent's id: such a child must not call RT2.

use std::sync::atomic::{AtomicU32, Ordering};

/// The kept id; 0 (no process's id) until read, and again in a forked child.
static KEPT: AtomicU32 = AtomicU32::new(0);

/// This process's id.
pub fn id() -> u32 {
    match KEPT.load(Ordering::Relaxed) {
        0 => {
            let id = std::process::id();
            if forgotten_in_children() {
                KEPT.store(id, Ordering::Relaxed);
            }
            id
        }
        id => id,
    }
}

/// Whether a forked child forgets the kept id: registers the handler on first use. A fork
/// between the registration and the store leaves the child a copy of `KEPT` that is either
/// still 0 or cleared by the handler.
#[cfg(unix)]
fn forgotten_in_children() -> bool {
    extern "C" fn forget() {
        KEPT.store(0, Ordering::Relaxed);
    }
    static REGISTERED: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    // SAFETY: `forget` only stores to an atomic, which is async-signal-safe, as a handler
    // run in the child of a multithreaded process must be. A failed registration (ENOMEM)
    // keeps nothing: every call asks the system.
    *REGISTERED.get_or_init(|| unsafe { libc::pthread_atfork(None, None, Some(forget)) == 0 })
}

/// No `fork` elsewhere: the id is the process's for good.
#[cfg(not(unix))]
fn forgotten_in_children() -> bool {
    true
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_kept_id_is_the_systems() {
        assert_eq!(super::id(), std::process::id());
        assert_eq!(super::id(), std::process::id());
    }
}
