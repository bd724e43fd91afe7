//! A reader–writer lock for data that many threads read at once and few write: a scene, which
//! every query and render reads and only edits and commits write.
//!
//! `std::sync::RwLock` counts its readers in one word. Every read takes and releases it with a
//! locked instruction, so threads reading at once on different cores pass that cache line
//! between them on every call: two threads querying a scene one ray per call spent about 8% of
//! their time there on two cores, and the cost grows with the cores. Here the readers are
//! spread over shards, each an `RwLock<()>` on its own cache line, and a thread always reads
//! through the same shard; a writer takes every shard. Readers of different shards share no
//! line, at the price of a writer's taking them all (a few dozen locked instructions per edit).

use std::cell::{Cell, UnsafeCell};
use std::ops::{Deref, DerefMut};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{RwLock, RwLockReadGuard, RwLockWriteGuard};

/// Most shards of a lock: beyond this many threads, some share one.
const MAX_SHARDS: usize = 64;

/// One shard, alone on its cache line (two lines: some processors fetch lines in pairs).
#[repr(align(128))]
#[derive(Default)]
struct Shard(RwLock<()>);

pub(crate) struct ReadMostly<T> {
    shards: Box<[Shard]>,
    value: UnsafeCell<T>,
}

// SAFETY: `value` is only reached through the guards: shared (`&T`) while a shard is held for
// reading, exclusive (`&mut T`) while every shard is held for writing, as `RwLock<T>` hands
// it out; so the same bounds as `RwLock<T>`'s.
unsafe impl<T: Send> Send for ReadMostly<T> {}
// SAFETY: as above.
unsafe impl<T: Send + Sync> Sync for ReadMostly<T> {}

/// Numbers the threads in the order they first read a [`ReadMostly`].
static NEXT_THREAD: AtomicUsize = AtomicUsize::new(0);

thread_local! {
    /// This thread's number (`usize::MAX` until its first read).
    static THREAD: Cell<usize> = const { Cell::new(usize::MAX) };
}

/// This thread's number: its shard is the number modulo the shard count, so the first threads
/// to read each get their own.
fn thread_number() -> usize {
    THREAD.with(|t| {
        if t.get() == usize::MAX {
            t.set(NEXT_THREAD.fetch_add(1, Ordering::Relaxed));
        }
        t.get()
    })
}

impl<T> ReadMostly<T> {
    /// One shard per processor the system reports (at most [`MAX_SHARDS`]).
    pub fn new(value: T) -> Self {
        let shards = std::thread::available_parallelism().map_or(1, |n| n.get());
        Self::with_shards(value, shards)
    }

    fn with_shards(value: T, shards: usize) -> Self {
        ReadMostly {
            shards: (0..shards.clamp(1, MAX_SHARDS))
                .map(|_| Shard::default())
                .collect(),
            value: UnsafeCell::new(value),
        }
    }

    /// Shared access; waits while a writer holds the lock. A panic under a guard (a bug: edits
    /// validate before they change anything) does not poison it.
    pub fn read(&self) -> ReadGuard<'_, T> {
        self.read_through(thread_number() % self.shards.len())
    }

    /// [`Self::read`] through shard `shard`.
    fn read_through(&self, shard: usize) -> ReadGuard<'_, T> {
        let held = self.shards[shard]
            .0
            .read()
            .unwrap_or_else(|p| p.into_inner());
        // SAFETY: a shard is held for reading, so no writer holds them all.
        let value = unsafe { &*self.value.get() };
        ReadGuard { _held: held, value }
    }

    /// Exclusive access; waits for every reader and writer. Shards are taken in one order, so
    /// two writers cannot hold part each and wait for the rest.
    pub fn write(&self) -> WriteGuard<'_, T> {
        let held = self
            .shards
            .iter()
            .map(|s| s.0.write().unwrap_or_else(|p| p.into_inner()))
            .collect();
        // SAFETY: every shard is held for writing: no reader, no other writer.
        let value = unsafe { &mut *self.value.get() };
        WriteGuard { _held: held, value }
    }
}

pub(crate) struct ReadGuard<'a, T> {
    _held: RwLockReadGuard<'a, ()>,
    value: &'a T,
}

impl<T> Deref for ReadGuard<'_, T> {
    type Target = T;
    fn deref(&self) -> &T {
        self.value
    }
}

pub(crate) struct WriteGuard<'a, T> {
    _held: Vec<RwLockWriteGuard<'a, ()>>,
    value: &'a mut T,
}

impl<T> Deref for WriteGuard<'_, T> {
    type Target = T;
    fn deref(&self) -> &T {
        self.value
    }
}

impl<T> DerefMut for WriteGuard<'_, T> {
    fn deref_mut(&mut self) -> &mut T {
        self.value
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::AtomicBool;
    use std::time::Duration;

    /// Readers on several threads (more than shards, so some share one) never see a write
    /// half done, and every write lands: a writer keeps both halves of a pair equal.
    #[test]
    fn readers_never_see_a_write_half_done() {
        let lock = ReadMostly::with_shards((0u64, 0u64), 3);
        let stop = AtomicBool::new(false);
        std::thread::scope(|s| {
            for _ in 0..5 {
                s.spawn(|| {
                    let mut reads = 0u64;
                    while !stop.load(Ordering::Relaxed) || reads == 0 {
                        let r = lock.read();
                        assert_eq!(r.0, r.1, "a read saw a write half done");
                        reads += 1;
                    }
                });
            }
            for _ in 0..2 {
                s.spawn(|| {
                    for _ in 0..2000 {
                        let mut w = lock.write();
                        w.0 += 1;
                        std::hint::spin_loop();
                        w.1 += 1;
                    }
                });
            }
            std::thread::sleep(Duration::from_millis(50));
            // The writers finish first (scope joins them all; readers stop when told).
            while lock.read().0 < 4000 {
                std::thread::yield_now();
            }
            stop.store(true, Ordering::Relaxed);
        });
        assert_eq!(*lock.read(), (4000, 4000), "a write was lost");
    }

    /// A writer waits for a reader on any shard (here the last one, which no writer takes
    /// first).
    #[test]
    fn a_writer_waits_for_readers_of_every_shard() {
        let lock = ReadMostly::with_shards(0u32, 4);
        let (held, release) = (AtomicBool::new(false), AtomicBool::new(false));
        let wrote = AtomicBool::new(false);
        std::thread::scope(|s| {
            s.spawn(|| {
                let _r = lock.read_through(3);
                held.store(true, Ordering::SeqCst);
                while !release.load(Ordering::SeqCst) {
                    std::thread::yield_now();
                }
                assert!(!wrote.load(Ordering::SeqCst), "a write ran under a read");
            });
            while !held.load(Ordering::SeqCst) {
                std::thread::yield_now();
            }
            s.spawn(|| {
                *lock.write() += 1;
                wrote.store(true, Ordering::SeqCst);
            });
            std::thread::sleep(Duration::from_millis(20));
            let waited = !wrote.load(Ordering::SeqCst);
            release.store(true, Ordering::SeqCst);
            assert!(waited, "the writer did not wait");
        });
        assert_eq!(*lock.read(), 1);
    }
}
