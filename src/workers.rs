//! A context's rayon pool and its worker threads, started, stopped and joined by RT2 itself.
//!
//! Joined: rayon's `ThreadPool::drop` only tells its workers to stop; joining them makes
//! `rt2_context_destroy` leave no thread behind (under valgrind, the stacks and TLS of workers
//! still exiting when a C program's `main` returned were reported as possibly lost).
//!
//! Started without `std::thread` on Unix: std's thread start and exit take a process-wide lock
//! (the map of thread stack guards its stack-overflow handler reads). A `fork` while any thread
//! of the parent holds it gives the child a copy held for good, and every `std::thread` the
//! child starts waits for it forever: a child forked while a context started or stopped its
//! workers hung in `rt2_context_create` (`tests/fork_during_calls.rs`). Workers made with
//! `pthread_create` never take that lock, in the parent or the child. The price: a stack
//! overflow in a worker is a plain SIGSEGV without std's message (C hosts never had it).
//!
//! For the same reason the one lazily made global the workers use, crossbeam-epoch's default
//! collector (rayon's deques pin it), is made when the library is loaded: made on first use
//! inside a `OnceLock`, a fork while a worker of the parent made it left the child a
//! `OnceLock` being initialised for good, and the child's workers waited for it forever (one
//! run in about a dozen of that test, once std's lock was out of the way).

use std::io;
use std::mem::ManuallyDrop;

/// Makes crossbeam-epoch's default collector at load time (before `main` for a program linked
/// with RT2, inside `dlopen` for one that loads it), when no RT2 thread exists yet.
#[cfg(target_os = "linux")]
#[used]
#[link_section = ".init_array"]
static MAKE_COLLECTOR_WHEN_LOADED: extern "C" fn() = {
    extern "C" fn make() {
        crossbeam_epoch::default_collector();
    }
    make
};

/// A context's rayon pool and its worker threads, stopped and joined in that order when
/// dropped.
pub struct Pool {
    /// Dropped by hand (`Pool::drop`), never once abandoned.
    pool: ManuallyDrop<rayon::ThreadPool>,
    threads: Vec<Thread>,
    abandoned: bool,
}

thread_local! {
    /// Set on the pools' worker threads (no destructor and no allocation, unlike
    /// `thread::current()`, whose handle a C program's main thread never frees).
    static IN_WORKER: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

impl Pool {
    /// A pool of `threads` workers (`0`: rayon's default, one per core).
    pub fn new(threads: usize) -> Result<Pool, rayon::ThreadPoolBuildError> {
        let mut started = Vec::new();
        let built = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .thread_name(|i| format!("rt2-worker-{i}"))
            .spawn_handler(|worker| {
                let name = worker.name().map(str::to_owned);
                let thread = Thread::spawn(name, worker.stack_size(), move || {
                    IN_WORKER.set(true);
                    worker.run()
                })?;
                started.push(thread);
                Ok(())
            })
            .build();
        match built {
            Ok(pool) => Ok(Pool {
                pool: ManuallyDrop::new(pool),
                threads: started,
                abandoned: false,
            }),
            Err(e) => {
                // rayon has told the workers that did start to stop.
                started.into_iter().for_each(Thread::join);
                Err(e)
            }
        }
    }

    /// Leaves the pool and its threads as they are, neither stopped nor joined (their memory
    /// leaks): in a forked child they are the parent's, and even stopping the pool would wait,
    /// since it locks each worker's sleep state, which a worker of the parent falling asleep at
    /// the fork left locked for good.
    pub fn abandon(&mut self) {
        std::mem::forget(std::mem::take(&mut self.threads));
        self.abandoned = true;
    }
}

impl std::ops::Deref for Pool {
    type Target = rayon::ThreadPool;
    fn deref(&self) -> &rayon::ThreadPool {
        &self.pool
    }
}

impl Drop for Pool {
    fn drop(&mut self) {
        if self.abandoned {
            return;
        }
        // SAFETY: dropped here only, once; nothing uses it after.
        unsafe { ManuallyDrop::drop(&mut self.pool) };
        // A worker cannot join itself (nor its siblings, which may be joining it): dropped
        // unjoined, they are detached.
        if !IN_WORKER.get() {
            self.threads.drain(..).for_each(Thread::join);
        }
    }
}

/// Stack of a worker whose pool names no size: std's default for its threads.
const DEFAULT_STACK: usize = 2 << 20;

/// One worker thread (a std thread where there is no `fork`): joined through [`Thread::join`],
/// else detached when dropped (as std's `JoinHandle` is), so that its stack is freed when it
/// exits (a context dropped on a worker of another pool cannot join its own workers).
struct Thread(
    #[cfg(unix)] libc::pthread_t,
    #[cfg(not(unix))] std::thread::JoinHandle<()>,
);

impl Thread {
    fn spawn(
        name: Option<String>,
        stack_size: Option<usize>,
        run: impl FnOnce() + Send + 'static,
    ) -> io::Result<Self> {
        let stack = stack_size.unwrap_or(DEFAULT_STACK);
        #[cfg(unix)]
        let thread = pthread::spawn(stack, move || {
            if let Some(name) = name {
                pthread::set_name(&name);
            }
            run()
        });
        #[cfg(not(unix))]
        let thread = {
            let b = std::thread::Builder::new().stack_size(stack);
            match name {
                Some(name) => b.name(name),
                None => b,
            }
            .spawn(run)
        };
        thread.map(Thread)
    }

    fn join(self) {
        #[cfg(unix)]
        {
            let thread = std::mem::ManuallyDrop::new(self);
            // SAFETY: `self` is consumed and not dropped (no detach): joined once.
            unsafe { pthread::join(thread.0) };
        }
        #[cfg(not(unix))]
        let _ = self.0.join();
    }
}

#[cfg(unix)]
impl Drop for Thread {
    fn drop(&mut self) {
        // SAFETY: a thread neither joined (`join` does not drop) nor detached before.
        unsafe { libc::pthread_detach(self.0) };
    }
}

// SAFETY: a pthread id is a handle any thread may join or detach (on musl it is a pointer,
// which is not `Send` by default).
#[cfg(unix)]
unsafe impl Send for Thread {}
#[cfg(unix)]
unsafe impl Sync for Thread {}

#[cfg(unix)]
mod pthread {
    use std::io;

    /// Starts a thread of `stack` bytes (at least the system's minimum) that runs `run`.
    pub fn spawn<F: FnOnce() + Send + 'static>(
        stack: usize,
        run: F,
    ) -> io::Result<libc::pthread_t> {
        extern "C" fn start<F: FnOnce()>(run: *mut libc::c_void) -> *mut libc::c_void {
            // SAFETY: `spawn` hands this thread alone the `Box<F>` it leaked for it.
            let run = unsafe { Box::from_raw(run.cast::<F>()) };
            // A panic must not unwind out of a C entry point (that aborts the process).
            let _ = std::panic::catch_unwind(std::panic::AssertUnwindSafe(run));
            std::ptr::null_mut()
        }
        let os = |rc: libc::c_int| match rc {
            0 => Ok(()),
            rc => Err(io::Error::from_raw_os_error(rc)),
        };
        // SAFETY: the attributes are initialised before use and destroyed once; `run` is
        // leaked to the new thread only when `pthread_create` succeeds, else taken back.
        unsafe {
            let mut attr = std::mem::MaybeUninit::<libc::pthread_attr_t>::uninit();
            os(libc::pthread_attr_init(attr.as_mut_ptr()))?;
            let mut attr = attr.assume_init();
            let mut id: libc::pthread_t = std::mem::zeroed();
            let run = Box::into_raw(Box::new(run));
            let mut rc =
                libc::pthread_attr_setstacksize(&mut attr, stack.max(libc::PTHREAD_STACK_MIN));
            if rc == 0 {
                rc = libc::pthread_create(&mut id, &attr, start::<F>, run.cast());
            }
            libc::pthread_attr_destroy(&mut attr);
            if rc != 0 {
                drop(Box::from_raw(run));
            }
            os(rc).map(|()| id)
        }
    }

    /// Waits for a thread `spawn` started.
    ///
    /// # Safety
    /// Once per thread: a joined thread's id may name another thread.
    pub unsafe fn join(thread: libc::pthread_t) {
        libc::pthread_join(thread, std::ptr::null_mut());
    }

    /// Names the calling thread (what `top -H` and debuggers show); Linux keeps 15 bytes.
    pub fn set_name(name: &str) {
        #[cfg(target_os = "linux")]
        {
            let mut end = name.len().min(15);
            while !name.is_char_boundary(end) {
                end -= 1;
            }
            if let Ok(name) = std::ffi::CString::new(&name[..end]) {
                // SAFETY: a NUL-terminated name of at most 16 bytes, for the calling thread.
                unsafe { libc::pthread_setname_np(libc::pthread_self(), name.as_ptr()) };
            }
        }
        #[cfg(not(target_os = "linux"))]
        let _ = name;
    }
}
