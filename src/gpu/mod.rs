//! Layer 3b: the GPU backend on wgpu compute shaders (WGSL in `shaders/`). It owns the
//! devices of a context, their pipelines and their copy of the committed scene; the kd-tree
//! is always built on the CPU and uploaded (RT² render cycle, thesis fig. 13).
//!
//! - [`open`] picks adapters and creates devices; the dispatch layer decides whether to use
//!   them (a software adapter is slower than the CPU path).
//! - `query`: batch ray queries, one thread per ray.
//! - [`render()`]: Whitted frames, megakernel or wavefront, rows split across devices.

mod device;
mod faults;
pub mod kernels;
pub mod layout;
mod query;
mod render;
mod scene;

pub use device::{open, Device, Gpu, GpuOptions};
pub use faults::InjectedFault;
pub use render::GpuPath;

use crate::camera::Camera;
use crate::cpu::traverse::Traversal;
use crate::frame::Frame;
use crate::geometry::{Hit, PrimIndex, Ray, TraversalStats};
use crate::render::RenderOptions;
use crate::scene::Committed;

/// Renders a frame on every device of `gpu`, each a band of rows.
pub fn render(
    gpu: &Gpu,
    scene: &Committed,
    camera: &Camera,
    opts: &RenderOptions,
    traversal: Traversal,
    path: GpuPath,
    frame: &mut Frame,
) -> GpuResult<()> {
    render::render(gpu, scene, camera, opts, traversal, path, frame)
}

/// Closest hits of a batch of rays, on the first device; ray `i` ignores primitive
/// `exclude[i]` (`INVALID`: none) when `exclude` is given (as long as `rays`).
pub fn intersect(
    gpu: &Gpu,
    scene: &Committed,
    (rays, exclude): (&[Ray], Option<&[PrimIndex]>),
    hits: &mut [Hit],
    traversal: Traversal,
    short_stack: usize,
) -> GpuResult<TraversalStats> {
    query::run(
        &gpu.devices[0],
        scene,
        (rays, exclude),
        traversal,
        short_stack,
        Some(hits),
        None,
    )
}

/// Any-hit flags of a batch of rays, on the first device; exclusions as [`intersect`].
pub fn occluded(
    gpu: &Gpu,
    scene: &Committed,
    (rays, exclude): (&[Ray], Option<&[PrimIndex]>),
    out: &mut [bool],
    traversal: Traversal,
    short_stack: usize,
) -> GpuResult<TraversalStats> {
    query::run(
        &gpu.devices[0],
        scene,
        (rays, exclude),
        traversal,
        short_stack,
        None,
        Some(out),
    )
}

/// Errors of the GPU backend that the dispatch layer may answer by running on the CPU.
#[derive(Clone, Debug)]
pub enum GpuError {
    /// The scene or job does not fit the device's limits; AUTO falls back to the CPU.
    Limits(String),
    /// wgpu reported an out-of-memory error during the job; AUTO falls back to the CPU, an
    /// explicit GPU context fails with `OUT_OF_MEMORY`.
    OutOfMemory(String),
    /// The device was lost (driver reset, unplugged, destroyed); AUTO falls back to the CPU,
    /// an explicit GPU context fails with `BACKEND_UNAVAILABLE`.
    Lost(String),
    /// Anything else (a kernel or validation error: a bug): an error status.
    Other(crate::error::Error),
}

impl GpuError {
    /// The driver cut `count` of a job's rays or pixels (`what`) short: its loop budget
    /// ([`crate::dispatch::SOFTWARE_LOOP_BUDGET`]) ran out, as the kernels' last loop found
    /// (`loops_ran_to_the_end` in `shaders/common.wgsl`). Their answers may be wrong, so the
    /// job gives none: a limit of the device, which AUTO meets by running the job on the CPU.
    pub(crate) fn cut_short(count: usize, what: &str) -> Self {
        GpuError::Limits(format!(
            "the GPU driver cut {count} {what} short: a software driver (llvmpipe) ends every \
             loop of a shader invocation after {} iterations in all (a group of invocations \
             in lockstep), and this job needed more",
            crate::dispatch::SOFTWARE_LOOP_BUDGET
        ))
    }
}

/// Host memory for a job's buffers (rays, mask, read-back) that could not be allocated: as
/// when the device runs out, AUTO runs the job on the CPU.
impl From<crate::fallible::OutOfMemory> for GpuError {
    fn from(_: crate::fallible::OutOfMemory) -> Self {
        GpuError::OutOfMemory("no host memory for the GPU job's buffers".into())
    }
}

impl From<crate::error::Error> for GpuError {
    fn from(e: crate::error::Error) -> Self {
        GpuError::Other(e)
    }
}

impl GpuError {
    /// The error a caller sees when no fallback applies.
    pub fn into_error(self) -> crate::error::Error {
        use crate::error::{Error, Rt2Status};
        match self {
            GpuError::Limits(m) | GpuError::Lost(m) => Error::new(Rt2Status::BackendUnavailable, m),
            GpuError::OutOfMemory(m) => Error::out_of_memory(m),
            GpuError::Other(e) => e,
        }
    }

    /// Why AUTO may run the job on the CPU instead (`None`: it is an error either way).
    pub fn fallback_reason(&self) -> Option<&str> {
        match self {
            GpuError::Limits(m) | GpuError::OutOfMemory(m) | GpuError::Lost(m) => Some(m),
            GpuError::Other(_) => None,
        }
    }
}

pub type GpuResult<T> = std::result::Result<T, GpuError>;
