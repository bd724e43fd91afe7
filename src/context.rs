//! The context: the thread pool, the backend decision every operation goes through and, when
//! tracing runs on the GPU, the devices.

use crate::camera::Camera;
use crate::cpu;
use crate::cpu::traverse::TraverseOptions;
use crate::dispatch::{self, BackendRequest, Decision};
use crate::error::{Error, Result};
use crate::frame::Frame;
use crate::geometry::{Hit, Ray, TraversalStats};
use crate::gpu::{self, Gpu, GpuOptions, GpuResult};
use crate::precision::{Intersector, OffsetMode};
use crate::render::RenderOptions;
use crate::scene::Committed;
use std::sync::Mutex;

pub struct Context {
    pool: rayon::ThreadPool,
    decision: Decision,
    /// The devices, when tracing runs on the GPU.
    gpu: Option<Gpu>,
    /// Why the last job of an AUTO context ran on the CPU after all (device limits, out of
    /// memory, a lost device).
    fallback: Mutex<Option<String>>,
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
    /// global rayon pool is never touched. GPU adapters follow `RT2_ADAPTER` and
    /// `RT2_GPU_DEVICES` (see [`GpuOptions::from_env`]).
    pub fn new(request: BackendRequest, threads: u32) -> Result<Self> {
        Self::with_gpu_options(request, threads, &GpuOptions::from_env())
    }

    /// [`Context::new`] with explicit GPU options (tests force two logical devices this way).
    pub fn with_gpu_options(
        request: BackendRequest,
        threads: u32,
        gpu_opts: &GpuOptions,
    ) -> Result<Self> {
        let env = std::env::var("RT2_BACKEND").ok();
        let (decision, gpu) = dispatch::decide_backend(request, env.as_deref(), gpu_opts)?;
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
            gpu,
            fallback: Mutex::new(None),
            _workers: workers,
        })
    }

    pub fn decision(&self) -> &Decision {
        &self.decision
    }

    /// The GPU devices, when tracing runs there.
    pub fn gpu(&self) -> Option<&Gpu> {
        self.gpu.as_ref()
    }

    /// Why the last job of an AUTO GPU context ran on the CPU instead (`None`: it did not).
    /// The C API reports it as `rt2_context_properties.fallback`.
    pub fn last_fallback(&self) -> Option<String> {
        self.fallback.lock().ok().and_then(|f| f.clone())
    }

    pub fn threads(&self) -> usize {
        self.pool.current_num_threads()
    }

    /// Runs `f` inside the context's thread pool.
    pub fn install<R: Send>(&self, f: impl FnOnce() -> R + Send) -> R {
        self.pool.install(f)
    }

    /// Runs `job` on the GPU when tracing runs there. `Ok(None)`: the CPU must do the job,
    /// because the backend is the CPU, or because AUTO chose the GPU and the job exceeds its
    /// limits, ran out of device memory or found the device lost (the reason is kept for
    /// [`Context::last_fallback`]).
    /// `unsupported` says why the kernels cannot do this job (a precision mode they lack): an
    /// AUTO context then runs it on the CPU, a context asked for the GPU fails.
    fn gpu_job<T>(
        &self,
        unsupported: Option<&str>,
        job: impl FnOnce(&Gpu) -> GpuResult<T>,
    ) -> Result<Option<T>> {
        let Some(g) = &self.gpu else {
            return Ok(None);
        };
        let result = match unsupported {
            Some(why) if self.decision.auto => Err(gpu::GpuError::Limits(why.to_string())),
            Some(why) => return Err(Error::unsupported(format!("the GPU backend: {why}"))),
            None => job(g),
        };
        let (out, why) = match result {
            Ok(v) => (Ok(Some(v)), None),
            Err(e) => match e.fallback_reason() {
                Some(why) if self.decision.auto => {
                    (Ok(None), Some(format!("{why}, so this job ran on the CPU")))
                }
                _ => (Err(e.into_error()), None),
            },
        };
        if let Ok(mut f) = self.fallback.lock() {
            *f = why;
        }
        out
    }

    pub fn render(
        &self,
        scene: &Committed,
        camera: &Camera,
        opts: &RenderOptions,
        frame: &mut Frame,
    ) -> Result<()> {
        cpu::whitted::check_schedule(opts)?;
        let done = self.gpu_job(gpu_lacks(opts.intersector, opts.offset_mode), |g| {
            let (traversal, _) = dispatch::choose_gpu_traversal(scene, opts.traversal);
            let (path, _) = dispatch::choose_gpu_path(scene, opts);
            gpu::render(g, scene, camera, opts, traversal, path, frame)
        })?;
        if done.is_none() {
            let (traversal, _why) = dispatch::choose_traversal(scene, opts.traversal);
            self.install(|| cpu::whitted::render(scene, camera, opts, traversal, frame));
        }
        Ok(())
    }

    /// Closest hits of a batch of rays; the traversal is the caller's or AUTO's choice.
    pub fn intersect(
        &self,
        scene: &Committed,
        rays: &[Ray],
        hits: &mut [Hit],
        q: &QueryOptions,
    ) -> Result<TraversalStats> {
        check_query(q)?;
        let on_gpu = self.gpu_job(gpu_lacks(q.intersector, OffsetMode::Epsilon), |g| {
            let (how, _) = dispatch::choose_gpu_traversal(scene, q.traversal);
            gpu::intersect(g, scene, rays, hits, how, q.short_stack_size)
        })?;
        if let Some(stats) = on_gpu {
            return Ok(stats);
        }
        let (how, opts) = self.query_setup(scene, q);
        Ok(self.install(|| cpu::query::intersect(scene, rays, hits, how, &opts, q.mode)))
    }

    /// Any-hit queries for a batch of rays.
    pub fn occluded(
        &self,
        scene: &Committed,
        rays: &[Ray],
        out: &mut [bool],
        q: &QueryOptions,
    ) -> Result<TraversalStats> {
        check_query(q)?;
        let on_gpu = self.gpu_job(gpu_lacks(q.intersector, OffsetMode::Epsilon), |g| {
            let (how, _) = dispatch::choose_gpu_traversal(scene, q.traversal);
            gpu::occluded(g, scene, rays, out, how, q.short_stack_size)
        })?;
        if let Some(stats) = on_gpu {
            return Ok(stats);
        }
        let (how, opts) = self.query_setup(scene, q);
        Ok(self.install(|| cpu::query::occluded(scene, rays, out, how, &opts, q.mode)))
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

/// Why the GPU kernels cannot run a job with these precision modes (`None`: they can). They
/// implement Möller–Trumbore and the fixed epsilon offset only.
fn gpu_lacks(intersector: Intersector, offset: OffsetMode) -> Option<&'static str> {
    if intersector != Intersector::MollerTrumbore {
        Some("the GPU kernels test triangles with Möller–Trumbore only (no watertight test)")
    } else if offset != OffsetMode::Epsilon {
        Some("the GPU kernels offset secondary rays by the fixed epsilon only")
    } else {
        None
    }
}

/// Packets and streams test triangles with Möller–Trumbore (their SIMD test); the watertight
/// test runs one ray at a time.
fn check_query(q: &QueryOptions) -> Result<()> {
    if q.mode != cpu::query::QueryMode::Single && q.intersector != Intersector::MollerTrumbore {
        return Err(Error::unsupported(
            "packet and stream queries test triangles with Möller–Trumbore only: use single-ray \
             mode for the watertight test",
        ));
    }
    Ok(())
}

/// Options of batch ray queries.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct QueryOptions {
    /// `None` lets the library choose (AUTO).
    pub traversal: Option<crate::cpu::traverse::Traversal>,
    pub short_stack_size: usize,
    /// One ray at a time, packets or streams (same hits; see [`cpu::query::QueryMode`]).
    pub mode: cpu::query::QueryMode,
    /// The ray–triangle test (`crate::precision`).
    pub intersector: crate::precision::Intersector,
}

impl Default for QueryOptions {
    fn default() -> Self {
        QueryOptions {
            traversal: None,
            short_stack_size: 3,
            mode: cpu::query::QueryMode::Single,
            intersector: crate::precision::Intersector::MollerTrumbore,
        }
    }
}
