//! A reader–writer lock for data that many threads read at once and few write: a scene, which
//! every query and render reads and only edits and commits write.
//!
//! `std::sync::RwLock` counts its readers in one word. Every read takes and releases it with a
//! locked instruction, so threads reading at once on different cores pass that cache line
//! between them on every call: two threads querying a scene one ray per call spent about 8% of
//! their time there on two cores, and the cost grows with the cores. Here the readers are
//! spread over shards, each an `RwLock<()>` on its own cache line, and a thread always reads
//! through the same shard; a writer takes every shard. Readers of different shards share no
//! line, at the price of a writer's taking them all (two locked instructions per shard, and a
//! small allocation, per edit).
//!
//! As with `RwLock`, a waiting writer holds off readers that come after it: it raises `writing`
//! before it takes the shards, and a reader that sees it waits at `gate`, which the writer
//! holds until it is done. Without that, readers arriving on shards the writer had not reached
//! yet would each make it wait again (a review measured a write finishing at 150 ms where
//! `RwLock`'s finished at 100 ms).

use std::cell::{Cell, UnsafeCell};
use std::ops::{Deref, DerefMut};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Mutex, MutexGuard, RwLock, RwLockReadGuard, RwLockWriteGuard};

/// Most shards of a lock: beyond this many threads, some share one.
const MAX_SHARDS: usize = 64;

/// One shard, alone on its cache line (two lines: some processors fetch lines in pairs).
#[repr(align(128))]
#[derive(Default)]
struct Shard(RwLock<()>);

pub(crate) struct ReadMostly<T> {
    shards: Box<[Shard]>,
    /// Raised by a writer before it takes the shards, lowered when it is done: read by every
    /// reader, written only by writers, so readers do not pass its line between them.
    writing: AtomicBool,
    /// Held by a writer from before it raises `writing` until it is done.
    gate: Mutex<()>,
    value: UnsafeCell<T>,
}

// SAFETY: `value` is only reached through the guards: shared (`&T`) while a shard is held for
// reading, exclusive (`&mut T`) while every shard is held for writing, as `RwLock<T>` hands
// it out; so the same bound as `RwLock<T>`'s.
unsafe impl<T: Send + Sync> Sync for ReadMostly<T> {}

/// Numbers the threads in the order they first read a [`ReadMostly`] (never reused).
static NEXT_THREAD: AtomicUsize = AtomicUsize::new(0);

thread_local! {
    /// This thread's number (`usize::MAX` until its first read).
    static THREAD: Cell<usize> = const { Cell::new(usize::MAX) };
}

/// This thread's number: its shard is the number modulo the shard count (a power of two), so
/// the first threads to read each get their own. Numbers are not reused: where threads come
/// and go, live ones may share a shard (which costs speed, nothing else).
fn thread_number() -> usize {
    THREAD.with(|t| {
        if t.get() == usize::MAX {
            t.set(NEXT_THREAD.fetch_add(1, Ordering::Relaxed));
        }
        t.get()
    })
}

impl<T> ReadMostly<T> {
    /// One shard per processor the system reports, rounded up to a power of two (at most
    /// [`MAX_SHARDS`]).
    pub fn new(value: T) -> Self {
        let shards = std::thread::available_parallelism().map_or(1, |n| n.get());
        Self::with_shards(value, shards)
    }

    fn with_shards(value: T, shards: usize) -> Self {
        ReadMostly {
            shards: (0..shards.clamp(1, MAX_SHARDS).next_power_of_two())
                .map(|_| Shard::default())
                .collect(),
            writing: AtomicBool::new(false),
            gate: Mutex::new(()),
            value: UnsafeCell::new(value),
        }
    }

    /// Shared access; waits while a writer holds the lock or waits for it. A panic under a
    /// guard (a bug: edits validate before they change anything) does not poison it.
    pub fn read(&self) -> ReadGuard<'_, T> {
        // A mask, not `%`: a division would be the slowest instruction of a one-ray query.
        self.read_through(thread_number() & (self.shards.len() - 1))
    }

    /// [`Self::read`] through shard `shard`.
    fn read_through(&self, shard: usize) -> ReadGuard<'_, T> {
        if self.writing.load(Ordering::Relaxed) {
            // Passes once the writer is done (a reader that misses the flag only gets in
            // ahead of the writer, as one that came before it).
            drop(self.gate.lock().unwrap_or_else(|p| p.into_inner()));
        }
        let held = self.shards[shard]
            .0
            .read()
            .unwrap_or_else(|p| p.into_inner());
        ReadGuard {
            lock: self,
            _held: held,
        }
    }

    /// Exclusive access; waits for every reader and writer. Writers pass the gate one at a
    /// time, so two of them never hold part of the shards each.
    pub fn write(&self) -> WriteGuard<'_, T> {
        let gate = self.gate.lock().unwrap_or_else(|p| p.into_inner());
        self.writing.store(true, Ordering::Relaxed);
        let held = self
            .shards
            .iter()
            .map(|s| s.0.write().unwrap_or_else(|p| p.into_inner()))
            .collect();
        WriteGuard {
            lock: self,
            held,
            _gate: gate,
        }
    }
}

/// Shared access to a [`ReadMostly`]'s value. Holds the lock, not a reference to the value: a
/// guard dropped by value would otherwise pass a reference that outlives the lock's release
/// inside `drop` (why `std`'s guards hold a pointer).
pub(crate) struct ReadGuard<'a, T> {
    lock: &'a ReadMostly<T>,
    _held: RwLockReadGuard<'a, ()>,
}

impl<T> Deref for ReadGuard<'_, T> {
    type Target = T;
    fn deref(&self) -> &T {
        // SAFETY: a shard is held for reading, so no writer holds them all.
        unsafe { &*self.lock.value.get() }
    }
}

/// Exclusive access to a [`ReadMostly`]'s value (see [`ReadGuard`]).
pub(crate) struct WriteGuard<'a, T> {
    lock: &'a ReadMostly<T>,
    held: Vec<RwLockWriteGuard<'a, ()>>,
    _gate: MutexGuard<'a, ()>,
}

impl<T> Deref for WriteGuard<'_, T> {
    type Target = T;
    fn deref(&self) -> &T {
        // SAFETY: every shard is held for writing: no reader, no other writer.
        unsafe { &*self.lock.value.get() }
    }
}

impl<T> DerefMut for WriteGuard<'_, T> {
    fn deref_mut(&mut self) -> &mut T {
        // SAFETY: as for `deref`, and `&mut self` makes this the only reference through it.
        unsafe { &mut *self.lock.value.get() }
    }
}

/// Releases the shards, then lowers `writing` while still holding the gate (the next writer
/// raises it again after taking the gate), then the gate.
impl<T> Drop for WriteGuard<'_, T> {
    fn drop(&mut self) {
        self.held.clear();
        self.lock.writing.store(false, Ordering::Relaxed);
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
        let lock = ReadMostly::with_shards((0u64, 0u64), 2);
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
            let writers: Vec<_> = (0..2)
                .map(|_| {
                    s.spawn(|| {
                        for _ in 0..2000 {
                            let mut w = lock.write();
                            w.0 += 1;
                            std::hint::spin_loop();
                            w.1 += 1;
                        }
                    })
                })
                .collect();
            for w in writers {
                // A writer's panic is the scope's to report; the readers must stop either way.
                let _ = w.join();
            }
            stop.store(true, Ordering::Relaxed);
        });
        assert_eq!(*lock.read(), (4000, 4000), "a write was lost");
    }

    /// Spawns a thread that reads through `shard` until `release` is raised; returns once it
    /// holds the shard.
    fn hold_shard<'scope, T: Send + Sync>(
        s: &'scope std::thread::Scope<'scope, '_>,
        lock: &'scope ReadMostly<T>,
        shard: usize,
        release: &'scope AtomicBool,
    ) {
        let (held, holds) = std::sync::mpsc::channel();
        s.spawn(move || {
            let _r = lock.read_through(shard);
            let _ = held.send(());
            while !release.load(Ordering::SeqCst) {
                std::thread::yield_now();
            }
        });
        holds.recv().expect("the reader holds its shard");
    }

    /// A writer waits for a reader on any shard, and while it waits it holds off the readers
    /// that come after it, also on other shards, which then see its write. With the reader on
    /// the first shard, the writer holds none yet, so only its flag stops the later reader;
    /// with it on the last, the writer must have taken every shard.
    #[test]
    fn a_writer_waits_for_readers_and_goes_before_later_ones() {
        for (held, later) in [(0, 3), (3, 0)] {
            let lock = ReadMostly::with_shards(0u32, 4);
            let [release, wrote, read_in] = [(); 3].map(|_| AtomicBool::new(false));
            std::thread::scope(|s| {
                hold_shard(s, &lock, held, &release);
                let writer = s.spawn(|| {
                    *lock.write() += 1;
                    wrote.store(true, Ordering::SeqCst);
                });
                // (A writer that finished did not wait: the assertion below fails.)
                while !lock.writing.load(Ordering::SeqCst) && !writer.is_finished() {
                    std::thread::yield_now();
                }
                let later = s.spawn(|| {
                    let seen = *lock.read_through(later);
                    read_in.store(true, Ordering::SeqCst);
                    seen
                });
                std::thread::sleep(Duration::from_millis(20));
                let (waited, held_off) = (
                    !wrote.load(Ordering::SeqCst),
                    !read_in.load(Ordering::SeqCst),
                );
                release.store(true, Ordering::SeqCst);
                assert!(
                    waited,
                    "the writer did not wait for the reader on shard {held}"
                );
                assert!(held_off, "a later reader went before the waiting writer");
                let seen = later.join().ok();
                assert_eq!(seen, Some(1), "the later reader missed the write");
            });
        }
    }
}
