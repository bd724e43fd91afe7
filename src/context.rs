//! The context: the thread pool and the backend decision every operation goes through.

use crate::camera::Camera;
use crate::cpu;
use crate::cpu::traverse::TraverseOptions;
use crate::dispatch::{self, Backend, BackendRequest, Decision};
use crate::error::{Error, Result};
use crate::frame::Frame;
use crate::geometry::{Hit, Ray, TraversalStats};
use crate::render::RenderOptions;
use crate::scene::Committed;

pub struct Context {
    pool: rayon::ThreadPool,
    decision: Decision,
    /// Declared after `pool`, so dropped after it: waits for the workers to exit.
    _workers: Workers,
}

/// The pool's worker threads, spawned by the context itself so that it can join them. rayon's
/// `ThreadPool::drop` only tells its workers to stop; joining them makes `rt2_context_destroy`
/// leave no thread behind (under valgrind, the stacks and TLS of workers still exiting when a
/// C program's `main` returned were reported as possibly lost).
#[derive(Default)]
struct Workers {
    threads: std::sync::Arc<std::sync::Mutex<Vec<std::thread::JoinHandle<()>>>>,
}

impl Drop for Workers {
    fn drop(&mut self) {
        // A worker cannot join itself (nor its siblings, which may be joining it).
        if IN_WORKER.get() {
            return;
        }
        let threads = match self.threads.lock() {
            Ok(mut t) => std::mem::take(&mut *t),
            Err(_) => return,
        };
        for t in threads {
            let _ = t.join();
        }
    }
}

thread_local! {
    /// Set on the pools' worker threads (no destructor and no allocation, unlike
    /// `thread::current()`, whose handle a C program's main thread never frees).
    static IN_WORKER: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

impl Context {
    /// `threads == 0` uses every core. The pool is the context's own: the host program's
    /// global rayon pool is never touched.
    pub fn new(request: BackendRequest, threads: u32) -> Result<Self> {
        let env = std::env::var("RT2_BACKEND").ok();
        let decision = dispatch::decide_backend(request, env.as_deref())?;
        let workers = Workers::default();
        let handles = workers.threads.clone();
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads as usize)
            .thread_name(|i| format!("rt2-worker-{i}"))
            .spawn_handler(move |worker| {
                let mut b = std::thread::Builder::new();
                if let Some(name) = worker.name() {
                    b = b.name(name.to_owned());
                }
                if let Some(size) = worker.stack_size() {
                    b = b.stack_size(size);
                }
                let handle = b.spawn(move || {
                    IN_WORKER.set(true);
                    worker.run()
                })?;
                if let Ok(mut t) = handles.lock() {
                    t.push(handle);
                }
                Ok(())
            })
            .build()
            .map_err(|e| {
                Error::new(
                    crate::error::Rt2Status::Internal,
                    format!("cannot start threads: {e}"),
                )
            })?;
        Ok(Context {
            pool,
            decision,
            _workers: workers,
        })
    }

    pub fn decision(&self) -> &Decision {
        &self.decision
    }

    pub fn threads(&self) -> usize {
        self.pool.current_num_threads()
    }

    /// Runs `f` inside the context's thread pool.
    pub fn install<R: Send>(&self, f: impl FnOnce() -> R + Send) -> R {
        self.pool.install(f)
    }

    pub fn render(
        &self,
        scene: &Committed,
        camera: &Camera,
        opts: &RenderOptions,
        frame: &mut Frame,
    ) -> Result<()> {
        let (traversal, _why) = dispatch::choose_traversal(scene, opts.traversal);
        match self.decision.backend {
            Backend::Cpu => {
                self.install(|| cpu::whitted::render(scene, camera, opts, traversal, frame));
                Ok(())
            }
            Backend::Gpu => Err(Error::unsupported("the GPU backend is not built yet")),
        }
    }

    /// Closest hits of a batch of rays; the traversal is the caller's or AUTO's choice.
    pub fn intersect(
        &self,
        scene: &Committed,
        rays: &[Ray],
        hits: &mut [Hit],
        q: &QueryOptions,
    ) -> Result<TraversalStats> {
        let (how, opts) = self.query_setup(scene, q);
        match self.decision.backend {
            Backend::Cpu => {
                Ok(self.install(|| cpu::query::intersect(scene, rays, hits, how, &opts)))
            }
            Backend::Gpu => Err(Error::unsupported("the GPU backend is not built yet")),
        }
    }

    /// Any-hit queries for a batch of rays.
    pub fn occluded(
        &self,
        scene: &Committed,
        rays: &[Ray],
        out: &mut [bool],
        q: &QueryOptions,
    ) -> Result<TraversalStats> {
        let (how, opts) = self.query_setup(scene, q);
        match self.decision.backend {
            Backend::Cpu => Ok(self.install(|| cpu::query::occluded(scene, rays, out, how, &opts))),
            Backend::Gpu => Err(Error::unsupported("the GPU backend is not built yet")),
        }
    }

    fn query_setup(
        &self,
        scene: &Committed,
        q: &QueryOptions,
    ) -> (crate::cpu::traverse::Traversal, TraverseOptions) {
        let (how, _why) = dispatch::choose_traversal(scene, q.traversal);
        (
            how,
            TraverseOptions {
                short_stack_size: q.short_stack_size,
                intersector: q.intersector,
                ..TraverseOptions::default()
            },
        )
    }
}

/// Options of batch ray queries.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct QueryOptions {
    /// `None` lets the library choose (AUTO).
    pub traversal: Option<crate::cpu::traverse::Traversal>,
    pub short_stack_size: usize,
    /// The ray–triangle test (`crate::precision`).
    pub intersector: crate::precision::Intersector,
}

impl Default for QueryOptions {
    fn default() -> Self {
        QueryOptions {
            traversal: None,
            short_stack_size: 3,
            intersector: crate::precision::Intersector::MollerTrumbore,
        }
    }
}
