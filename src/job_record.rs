//! What a context's last job left for `rt2_context_info`: where it ran (the GPU fallback) and
//! what AUTO chose for it, and the store that keeps it ([`LastJob`]) without making threads
//! that query one context at once wait on each other.

use std::borrow::Cow;
use std::cell::RefCell;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Mutex;

/// What one job left: why it ran on the CPU after all (an AUTO GPU context), and its choices.
#[derive(Clone, Debug, Default, PartialEq)]
pub(crate) struct JobRecord {
    pub fallback: Option<String>,
    pub auto_choice: AutoChoices,
}

/// The choices a job left to AUTO, each with its reason: a traversal, and for a GPU render its
/// path. Kept as given and put into words only when asked for ([`AutoChoices::report`]): a
/// loop of one-ray queries would otherwise format a sentence per call, which cost about a
/// sixth of such a call.
#[derive(Clone, Debug, Default, PartialEq)]
pub(crate) struct AutoChoices {
    traversal: Option<Choice>,
    mode: Option<Choice>,
    gpu_path: Option<Choice>,
}

/// One choice AUTO made: `what` = `name` because of `why`.
#[derive(Clone, Debug)]
struct Choice {
    what: &'static str,
    name: &'static str,
    why: Cow<'static, str>,
}

/// Equal words. The same static string compares by address first: a loop of one-ray queries
/// compares its records call after call, and comparing the reasons' bytes was 4% of such a
/// loop's time.
impl PartialEq for Choice {
    #[inline]
    fn eq(&self, other: &Self) -> bool {
        let same = |a: &str, b: &str| std::ptr::eq(a, b) || a == b;
        same(self.what, other.what) && same(self.name, other.name) && same(&self.why, &other.why)
    }
}

impl AutoChoices {
    /// Notes the traversal `name` that `what` ("CPU traversal", "GPU traversal") runs, if
    /// AUTO chose it (`auto`).
    pub fn traversal(
        &mut self,
        auto: bool,
        what: &'static str,
        name: &'static str,
        why: &'static str,
    ) {
        if auto {
            self.traversal = Some(Choice {
                what,
                name,
                why: why.into(),
            });
        }
    }

    /// Notes the CPU query mode `name`, if AUTO chose it (`auto`).
    pub fn mode(&mut self, auto: bool, name: &'static str, why: &'static str) {
        if auto {
            self.mode = Some(Choice {
                what: "CPU query mode",
                name,
                why: why.into(),
            });
        }
    }

    /// Notes the GPU render path `name`, if AUTO chose it (`auto`).
    pub fn gpu_path(&mut self, auto: bool, name: &'static str, why: String) {
        if auto {
            self.gpu_path = Some(Choice {
                what: "GPU render path",
                name,
                why: why.into(),
            });
        }
    }

    pub fn report(&self) -> Option<String> {
        let said: Vec<String> = [&self.traversal, &self.mode, &self.gpu_path]
            .into_iter()
            .flatten()
            .map(|c| format!("{} {}: {}", c.what, c.name, c.why))
            .collect();
        (!said.is_empty()).then(|| said.join("; "))
    }
}

/// Numbers the stores, so that a thread's [`SEEN`] never mistakes a new context for a
/// destroyed one at the same address.
static NEXT_STORE: AtomicU64 = AtomicU64::new(0);

thread_local! {
    /// The record this thread last wrote or found in a store: the store's number, its version
    /// then, and the record.
    static SEEN: RefCell<Option<(u64, u64, JobRecord)>> = const { RefCell::new(None) };
}

/// The last job's record of one context. Every job ends by setting it, but only a record that
/// differs from the stored one is written. A loop of one-ray queries leaves the same record
/// call after call, and while the store's version is the one a thread last saw with that
/// record, the thread neither locks nor writes anything other threads read: with one lock
/// taken and one record written per job, two threads querying one context per ray ran at
/// 1.0–1.3 times one thread's speed on two cores.
pub(crate) struct LastJob {
    store: u64,
    /// Counts the writes, each made under `record`'s lock.
    version: AtomicU64,
    record: Mutex<JobRecord>,
}

impl LastJob {
    pub fn new() -> Self {
        LastJob {
            store: NEXT_STORE.fetch_add(1, Ordering::Relaxed),
            version: AtomicU64::new(0),
            record: Mutex::new(JobRecord::default()),
        }
    }

    /// Records a job. A job that runs at the same time as another may leave either record:
    /// both are "the last".
    pub fn set(&self, record: JobRecord) {
        // `try_with` fails only while the thread's locals are being destroyed: then the lock.
        let known = SEEN.try_with(|seen| {
            matches!(&*seen.borrow(), Some((store, version, r))
                if *store == self.store
                    && *version == self.version.load(Ordering::Acquire)
                    && *r == record)
        });
        if known == Ok(true) {
            return;
        }
        // Nothing under the lock panics; were it poisoned, the record would still be whole.
        let mut stored = self.record.lock().unwrap_or_else(|p| p.into_inner());
        let mut version = self.version.load(Ordering::Relaxed);
        if *stored != record {
            *stored = record.clone();
            version = self.version.fetch_add(1, Ordering::Release) + 1;
        }
        drop(stored);
        let _ = SEEN.try_with(|seen| *seen.borrow_mut() = Some((self.store, version, record)));
    }

    /// The last job's fallback reason and choices, put into words.
    pub fn get(&self) -> (Option<String>, Option<String>) {
        let r = self.record.lock().unwrap_or_else(|p| p.into_inner());
        (r.fallback.clone(), r.auto_choice.report())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn chose(mode: &'static str) -> JobRecord {
        chose_for(mode, "because")
    }

    fn chose_for(mode: &'static str, why: &'static str) -> JobRecord {
        let mut auto_choice = AutoChoices::default();
        auto_choice.mode(true, mode, why);
        JobRecord {
            fallback: None,
            auto_choice,
        }
    }

    fn said(mode: &str) -> Option<String> {
        Some(format!("CPU query mode {mode}: because"))
    }

    /// The skipped writes never hide a change: each thread's latest record is the stored one
    /// when it alone runs jobs, however the records alternate between threads and stores.
    #[test]
    fn the_last_record_set_is_the_one_reported() {
        let (a, b) = (LastJob::new(), LastJob::new());
        a.set(chose("packet"));
        a.set(chose("packet"));
        assert_eq!(a.get().1, said("packet"));
        b.set(chose("stream"));
        assert_eq!(b.get().1, said("stream"));
        assert_eq!(a.get().1, said("packet"), "another store's record leaked");
        // Both stores are at version 1 and this thread last saw "stream" in `b`: not `a`'s.
        a.set(chose("stream"));
        assert_eq!(a.get().1, said("stream"));
        a.set(chose("single"));
        a.set(JobRecord::default());
        assert_eq!(a.get(), (None, None));
        a.set(chose("single"));
        assert_eq!(a.get().1, said("single"));
        std::thread::scope(|s| {
            s.spawn(|| a.set(chose("stream")));
        });
        assert_eq!(a.get().1, said("stream"));
        // This thread last saw "single" at an older version: the same record is written again.
        a.set(chose("single"));
        assert_eq!(a.get().1, said("single"));
        let fallback = JobRecord {
            fallback: Some("the GPU was lost".into()),
            ..chose("single")
        };
        a.set(fallback.clone());
        assert_eq!(a.get().0.as_deref(), Some("the GPU was lost"));
        a.set(chose("single"));
        assert_eq!(a.get().0, None);
        // The same choice for another reason is another record.
        a.set(chose_for("single", "other"));
        assert_eq!(a.get().1.as_deref(), Some("CPU query mode single: other"));
        let mut path = chose("single");
        path.auto_choice
            .gpu_path(true, "wavefront", "made at run time".to_string());
        a.set(path.clone());
        path.auto_choice
            .gpu_path(true, "wavefront", "made again".to_string());
        a.set(path);
        assert!(a
            .get()
            .1
            .is_some_and(|s| s.ends_with("wavefront: made again")));
    }

    /// Threads setting the same record write it once between them; a new record is written.
    #[test]
    fn repeated_records_are_not_written_again() {
        let a = LastJob::new();
        std::thread::scope(|s| {
            for _ in 0..2 {
                s.spawn(|| {
                    for _ in 0..1000 {
                        a.set(chose("packet"));
                    }
                });
            }
        });
        assert_eq!(a.version.load(Ordering::Relaxed), 1);
        a.set(chose("stream"));
        assert_eq!(a.version.load(Ordering::Relaxed), 2);
        assert_eq!(a.get().1, said("stream"));
    }

    /// A thread setting the record it last set, still current, does not take the lock: it
    /// finishes while another thread holds it.
    #[test]
    fn a_current_record_is_set_without_the_lock() {
        use std::sync::atomic::AtomicBool;
        let a = LastJob::new();
        let [seen, locked, release, done] = [(); 4].map(|_| AtomicBool::new(false));
        std::thread::scope(|s| {
            s.spawn(|| {
                a.set(chose("packet"));
                seen.store(true, Ordering::SeqCst);
                while !locked.load(Ordering::SeqCst) {
                    std::thread::yield_now();
                }
                a.set(chose("packet"));
                done.store(true, Ordering::SeqCst);
            });
            while !seen.load(Ordering::SeqCst) {
                std::thread::yield_now();
            }
            s.spawn(|| {
                let _held = a.record.lock();
                locked.store(true, Ordering::SeqCst);
                while !release.load(Ordering::SeqCst) {
                    std::thread::yield_now();
                }
            });
            // Long enough for a busy machine to schedule the setter; passing ends the wait early.
            let waited = std::time::Instant::now();
            while !done.load(Ordering::SeqCst) && waited.elapsed().as_secs() < 5 {
                std::thread::yield_now();
            }
            let without_lock = done.load(Ordering::SeqCst);
            release.store(true, Ordering::SeqCst);
            assert!(
                without_lock,
                "setting the current record waited for the lock"
            );
        });
    }
}
