//! The context: the thread pool, the backend decision every operation goes through and, when
//! tracing runs on the GPU, the devices.

use crate::camera::Camera;
use crate::cpu;
use crate::cpu::query::RayAnswer;
use crate::cpu::simd::Width;
use crate::cpu::traverse::{Traversal, TraverseOptions};
use crate::dispatch::{self, BackendRequest, Decision};
use crate::error::{Error, Result};
use crate::frame::Frame;
use crate::geometry::{Hit, PrimIndex, Ray, TraversalStats};
use crate::gpu::{self, Gpu, GpuOptions, GpuResult};
use crate::job_record::{AutoChoices, JobRecord, LastJob};
use crate::precision::Intersector;
use crate::render::{GpuPathRequest, RenderOptions};
use crate::scene::Committed;
use crate::workers::Pool;

pub struct Context {
    pool: Pool,
    decision: Decision,
    /// The devices, when tracing runs on the GPU.
    gpu: Option<Gpu>,
    /// Where the last job ran and what AUTO chose for it.
    last_job: LastJob,
    /// The process that made the context. A `fork` copies the context into a child without
    /// its worker threads (or the GPU driver's): a job there would wait forever.
    pid: u32,
}

impl Drop for Context {
    /// In a forked child, the pool and the devices belong to the parent: they are left alone
    /// (their memory leaks) rather than waited for.
    fn drop(&mut self) {
        if self.pid != crate::process::id() {
            std::mem::forget(self.gpu.take());
            self.pool.abandon();
        }
    }
}

/// Most worker threads a context may ask for: far above any machine's cores, low enough that
/// a garbage count is an error rather than an attempt to start millions of threads.
pub const MAX_THREADS: u32 = 1024;

/// The workers of a context asked for 0: rayon's default count, i.e. `RAYON_NUM_THREADS` (or
/// its deprecated `RAYON_RS_NUM_CPUS`) when it holds a positive count, else one per core, and
/// never more than [`MAX_THREADS`]. Resolved here rather than by handing rayon 0, which started
/// as many workers as the variable said (2000 took 2 s, above the documented cap).
fn default_threads() -> usize {
    let from_env = |name: &str| {
        std::env::var(name)
            .ok()
            .and_then(|v| v.parse::<usize>().ok())
            .filter(|&n| n > 0)
    };
    from_env("RAYON_NUM_THREADS")
        .or_else(|| from_env("RAYON_RS_NUM_CPUS"))
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()))
        .min(MAX_THREADS as usize)
}

impl Context {
    /// `threads == 0` uses every core (`RAYON_NUM_THREADS` when set), at most [`MAX_THREADS`]
    /// (`default_threads`). The pool is the context's own:
    /// the host program's global rayon pool is never touched. GPU adapters follow
    /// `RT2_ADAPTER` and `RT2_GPU_DEVICES` (see [`GpuOptions::from_env`]).
    pub fn new(request: BackendRequest, threads: u32) -> Result<Self> {
        Self::with_gpu_options(request, threads, &GpuOptions::from_env()?)
    }

    /// [`Context::new`] with explicit GPU options (tests force two logical devices this way).
    pub fn with_gpu_options(
        request: BackendRequest,
        threads: u32,
        gpu_opts: &GpuOptions,
    ) -> Result<Self> {
        if threads > MAX_THREADS {
            return Err(Error::invalid_argument(format!(
                "threads is {threads} (at most {MAX_THREADS}; 0 uses every core)"
            )));
        }
        let env = crate::env::var("RT2_BACKEND")?;
        let (decision, gpu) = dispatch::decide_backend(request, env.as_deref(), gpu_opts)?;
        let threads = match threads {
            0 => default_threads(),
            n => n as usize,
        };
        let pool = Pool::new(threads).map_err(|e| {
            // The system refused a thread (a process or memory limit): a resource failure,
            // not a bug.
            Error::out_of_memory(format!("cannot start {threads} worker threads: {e}"))
        })?;
        Ok(Context {
            pool,
            decision,
            gpu,
            last_job: LastJob::new(),
            pid: crate::process::id(),
        })
    }

    /// An error unless this is the process that made the context (see `pid`): after a `fork`,
    /// the child makes its own context.
    pub fn same_process(&self) -> Result<()> {
        let here = crate::process::id();
        if self.pid == here {
            return Ok(());
        }
        Err(Error::invalid_operation(format!(
            "made in process {} before a fork: its worker threads do not exist in this \
             process ({here}); create a new context (and scenes) here",
            self.pid
        )))
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
        self.last_job().0
    }

    /// What the library chose for the last render or query where the caller left the choice
    /// to it (AUTO), and why, on the backend that ran the job: `"GPU traversal ropes++: …;
    /// GPU render path wavefront: …"`, or `"CPU traversal standard: …; CPU query mode
    /// packet: …"` for a query on the CPU.
    /// `None` when the caller chose everything (or no job ran yet). The C API reports it as
    /// `rt2_context_properties.auto_choice`.
    pub fn last_auto_choice(&self) -> Option<String> {
        self.last_job().1
    }

    /// [`Context::last_fallback`] and [`Context::last_auto_choice`] of the same job.
    pub fn last_job(&self) -> (Option<String>, Option<String>) {
        self.last_job.get()
    }

    pub fn threads(&self) -> usize {
        self.pool.current_num_threads()
    }

    /// Runs `f` inside the context's thread pool.
    pub fn install<R: Send>(&self, f: impl FnOnce() -> R + Send) -> R {
        self.pool.install(f)
    }

    /// Runs a job on the GPU when tracing runs there, else on the CPU, and records where it
    /// ran and what AUTO chose for it ([`Context::last_fallback`],
    /// [`Context::last_auto_choice`]). An AUTO context runs the job on the CPU after all when
    /// the GPU cannot take it: the job exceeds the device's limits, the device ran out of
    /// memory or was lost, or `unsupported` says why the kernels cannot do it (a precision mode
    /// they lack); a context asked for the GPU fails instead. Each closure notes the choices
    /// it made in [`AutoChoices`]; `out` is what the job writes (either closure may).
    fn job<O: ?Sized, T>(
        &self,
        out: &mut O,
        unsupported: Option<&str>,
        on_gpu: impl FnOnce(&Gpu, &mut O, &mut AutoChoices) -> GpuResult<T>,
        on_cpu: impl FnOnce(&mut O, &mut AutoChoices) -> T,
    ) -> Result<T> {
        let mut choices = AutoChoices::default();
        let mut fallback = None;
        let result = match &self.gpu {
            None => Ok(None),
            Some(g) => match (unsupported, self.refusal(unsupported)) {
                (_, Some(e)) => Err(gpu::GpuError::Other(e)),
                (Some(why), None) => Err(gpu::GpuError::Limits(why.to_string())),
                (None, None) => on_gpu(g, out, &mut choices).map(Some),
            },
        };
        let result = match result {
            Ok(Some(v)) => Ok(v),
            Ok(None) => Ok(on_cpu(out, &mut choices)),
            Err(e) => match e.fallback_reason() {
                Some(why) if self.decision.auto => {
                    fallback = Some(format!("{why}, so this job ran on the CPU"));
                    // What was chosen for the GPU did not run.
                    choices = AutoChoices::default();
                    Ok(on_cpu(out, &mut choices))
                }
                _ => Err(e.into_error()),
            },
        };
        self.last_job.set(JobRecord {
            fallback,
            auto_choice: choices,
        });
        result
    }

    pub fn render(
        &self,
        scene: &Committed,
        camera: &Camera,
        opts: &RenderOptions,
        frame: &mut Frame,
    ) -> Result<()> {
        opts.validate()?;
        self.job(
            frame,
            gpu_lacks(opts.intersector),
            |g, frame, choices| {
                let (traversal, why) = dispatch::choose_gpu_traversal(scene, opts.traversal);
                choices.traversal(
                    opts.traversal.is_none(),
                    "GPU traversal",
                    traversal.name(),
                    why,
                );
                let (path, why) = dispatch::choose_gpu_path(scene, opts, g.software);
                let auto = opts.gpu_path == GpuPathRequest::Auto;
                choices.gpu_path(auto, path.name(), why);
                gpu::render(g, scene, camera, opts, traversal, path, frame)
            },
            |frame, choices| {
                let (traversal, why) = dispatch::choose_traversal(scene, opts.traversal);
                choices.traversal(
                    opts.traversal.is_none(),
                    "CPU traversal",
                    traversal.name(),
                    why,
                );
                self.install(|| cpu::whitted::render(scene, camera, opts, traversal, frame))
            },
        )
    }

    /// Closest hits of a batch of rays; the traversal is the caller's or AUTO's choice.
    pub fn intersect(
        &self,
        scene: &Committed,
        rays: &[Ray],
        hits: &mut [Hit],
        q: &QueryOptions,
    ) -> Result<TraversalStats> {
        self.answer(scene, (rays, None), hits, q)
    }

    /// [`Context::intersect`] where ray `i` ignores primitive `exclude[i]` (`INVALID`: none),
    /// e.g. the one a secondary ray leaves.
    pub fn intersect_excluding(
        &self,
        scene: &Committed,
        rays: &[Ray],
        exclude: &[PrimIndex],
        hits: &mut [Hit],
        q: &QueryOptions,
    ) -> Result<TraversalStats> {
        self.answer(scene, (rays, Some(exclude)), hits, q)
    }

    /// Any-hit queries for a batch of rays.
    pub fn occluded(
        &self,
        scene: &Committed,
        rays: &[Ray],
        out: &mut [bool],
        q: &QueryOptions,
    ) -> Result<TraversalStats> {
        self.answer(scene, (rays, None), out, q)
    }

    /// [`Context::occluded`] where ray `i` ignores primitive `exclude[i]`, as
    /// [`Context::intersect_excluding`].
    pub fn occluded_excluding(
        &self,
        scene: &Committed,
        rays: &[Ray],
        exclude: &[PrimIndex],
        out: &mut [bool],
        q: &QueryOptions,
    ) -> Result<TraversalStats> {
        self.answer(scene, (rays, Some(exclude)), out, q)
    }

    /// The error of a job the GPU kernels lack (`unsupported` says why) on a context that
    /// asked for the GPU; AUTO contexts run such jobs on the CPU. [`Context::job`] refuses with
    /// it, and the C API asks first ([`Context::check_query`], [`Context::check_render`]) so
    /// that a refused call builds nothing (ropes, exact corners, lookups).
    fn refusal(&self, unsupported: Option<&str>) -> Option<Error> {
        match (&self.gpu, unsupported) {
            (Some(_), Some(why)) if !self.decision.auto => {
                Some(Error::unsupported(format!("the GPU backend: {why}")))
            }
            _ => None,
        }
    }

    /// Refuses a query this context would refuse when it runs (see `refusal`).
    pub fn check_query(&self, q: &QueryOptions) -> Result<()> {
        self.refusal(gpu_lacks(q.intersector)).map_or(Ok(()), Err)
    }

    /// Refuses a render this context would refuse when it runs (see `refusal`).
    pub fn check_render(&self, opts: &RenderOptions) -> Result<()> {
        self.refusal(gpu_lacks(opts.intersector))
            .map_or(Ok(()), Err)
    }

    /// A batch query of either answer (closest hits or occlusion) on the GPU, or on the CPU
    /// (in `q.mode`, or AUTO's choice for the batch) where the GPU cannot run it.
    fn answer<T: GpuAnswer>(
        &self,
        scene: &Committed,
        (rays, exclude): (&[Ray], Option<&[PrimIndex]>),
        out: &mut [T],
        q: &QueryOptions,
    ) -> Result<TraversalStats> {
        q.validate()?;
        check_lengths(rays, exclude, out)?;
        // Rays whose direction is far from unit length go to either backend scaled by a power
        // of two (`Ray::direction_scale`), on a copy made only when the batch holds one.
        let scaled: Option<(Vec<Option<f32>>, Vec<Ray>)> =
            rays.iter().any(|r| r.direction_scale().is_some()).then(|| {
                let scales: Vec<Option<f32>> = rays.iter().map(Ray::direction_scale).collect();
                let rays = rays.iter().zip(&scales);
                let scaled = rays.map(|(r, s)| s.map_or(*r, |s| r.scaled(s))).collect();
                (scales, scaled)
            });
        let rays = scaled.as_ref().map_or(rays, |(_, r)| r);
        let stats = self.job(
            out,
            gpu_lacks(q.intersector),
            |g, out, choices| {
                let how = gpu_query_traversal(scene, q, choices);
                T::GPU(g, scene, (rays, exclude), out, how, q.short_stack_size)
            },
            |out, choices| {
                let (how, opts) = self.query_setup(scene, q, choices);
                let (mode, why) = dispatch::choose_query_mode(rays, q.mode, how);
                choices.mode(q.mode.is_none(), mode.name(), why);
                let width = Width::best();
                let mut trace =
                    || cpu::query::trace(scene, (rays, exclude), out, how, &opts, mode, width);
                // One chunk runs on one thread wherever it runs: on the caller's, it skips the
                // hand-off to the pool, which cost about 15 µs a call (over 100 rays' worth on
                // the bunny) and made a loop of one-ray calls 100 times slower than a batch.
                if rays.len() <= cpu::query::CHUNK {
                    trace()
                } else {
                    self.install(trace)
                }
            },
        )?;
        for (o, s) in out.iter_mut().zip(scaled.iter().flat_map(|(s, _)| s)) {
            if let Some(s) = s {
                *o = o.scaled_back(*s);
            }
        }
        Ok(stats)
    }

    fn query_setup(
        &self,
        scene: &Committed,
        q: &QueryOptions,
        choices: &mut AutoChoices,
    ) -> (Traversal, TraverseOptions) {
        let (how, why) = dispatch::choose_traversal(scene, q.traversal);
        choices.traversal(q.traversal.is_none(), "CPU traversal", how.name(), why);
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

/// A GPU query answering a batch of rays (with their exclusions) on a context's GPU.
type GpuFn<T> = fn(
    &Gpu,
    &Committed,
    (&[Ray], Option<&[PrimIndex]>),
    &mut [T],
    Traversal,
    usize,
) -> GpuResult<TraversalStats>;

/// A [`RayAnswer`] the GPU kernels compute too, so that [`Context`] dispatches both kinds of
/// query with one path.
trait GpuAnswer: RayAnswer {
    const GPU: GpuFn<Self>;
}

impl GpuAnswer for Hit {
    const GPU: GpuFn<Self> = gpu::intersect;
}

impl GpuAnswer for bool {
    const GPU: GpuFn<Self> = gpu::occluded;
}

fn gpu_query_traversal(
    scene: &Committed,
    q: &QueryOptions,
    choices: &mut AutoChoices,
) -> Traversal {
    let (how, why) = dispatch::choose_gpu_traversal(scene, q.traversal);
    choices.traversal(q.traversal.is_none(), "GPU traversal", how.name(), why);
    how
}

/// Why the GPU kernels cannot run a job with this ray–triangle test (`None`: they can). They
/// implement Möller–Trumbore only (the watertight test's exact redo of edge cases needs f64).
fn gpu_lacks(intersector: Intersector) -> Option<&'static str> {
    (intersector != Intersector::MollerTrumbore)
        .then_some("the GPU kernels test triangles with Möller–Trumbore only (no watertight test)")
}

/// Refuses a batch whose exclusions or answers are not one per ray: the backends index all
/// three by ray, and a shorter slice would leave rays untraced on the CPU and panic on the GPU.
fn check_lengths<T>(rays: &[Ray], exclude: Option<&[PrimIndex]>, out: &[T]) -> Result<()> {
    let per_ray = |what: &str, n: usize| {
        Err(Error::invalid_argument(format!(
            "{n} {what} for {} rays: give one per ray",
            rays.len()
        )))
    };
    match exclude {
        Some(e) if e.len() != rays.len() => per_ray("excluded primitives", e.len()),
        _ if out.len() != rays.len() => per_ray("answers", out.len()),
        _ => Ok(()),
    }
}

/// Options of batch ray queries.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct QueryOptions {
    /// `None` lets the library choose (AUTO).
    pub traversal: Option<Traversal>,
    pub short_stack_size: usize,
    /// One ray at a time, packets or streams (same hits; see [`cpu::query::QueryMode`]);
    /// `None` lets the library choose (AUTO, `dispatch::choose_query_mode`).
    pub mode: Option<cpu::query::QueryMode>,
    /// The ray–triangle test (`crate::precision`).
    pub intersector: crate::precision::Intersector,
}

impl QueryOptions {
    /// The short stack's range (every mode takes every intersector). Checked by
    /// `Context::intersect` / `occluded`; the C API checks first, before it builds ropes or
    /// exact vertices.
    pub fn validate(&self) -> Result<()> {
        crate::error::check_range(
            "short_stack_size",
            self.short_stack_size,
            1..=crate::cpu::traverse::MAX_SHORT_STACK,
        )
    }
}

impl Default for QueryOptions {
    fn default() -> Self {
        QueryOptions {
            traversal: None,
            short_stack_size: 3,
            mode: None,
            intersector: crate::precision::Intersector::MollerTrumbore,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    /// An exclusion list of another length than the rays is refused, and nothing is written.
    #[test]
    fn one_exclusion_per_ray() {
        let ctx = Context::new(BackendRequest::Cpu, 1).unwrap();
        let s = crate::scene::unit_sphere();
        let rays = [Ray::new(Vec3::Z * 5.0, -Vec3::Z, 0.0, f32::INFINITY); 2];
        let q = QueryOptions::default();
        let mut hits = [Hit::MISS; 2];
        let c = s.committed().unwrap();
        let e = ctx
            .intersect_excluding(c, &rays, &[crate::geometry::INVALID], &mut hits, &q)
            .unwrap_err();
        assert_eq!(e.status, crate::error::Rt2Status::InvalidArgument);
        assert!(hits.iter().all(|h| !h.is_hit()));
        let mut occ = [false; 2];
        ctx.occluded_excluding(c, &rays, &[0, crate::geometry::INVALID], &mut occ, &q)
            .unwrap();
        assert_eq!(occ, [false, true], "ray 0 ignores the only sphere");
    }
}
