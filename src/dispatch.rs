//! Layer 2: decides where each operation runs and records why (RT² fig. 11's control layer).
//! Tree builds always run on the CPU (as in the thesis); tracing goes to the GPU when one is
//! usable, otherwise to the CPU. `RT2_BACKEND=cpu|gpu|auto` overrides the caller's choice.

use crate::cpu::traverse::Traversal;
use crate::error::{Error, Result, Rt2Status};
use crate::gpu::{self, Gpu, GpuOptions, GpuPath};
use crate::render::{GpuPathRequest, RenderOptions};
use crate::scene::Committed;

/// Backend requested by a caller.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BackendRequest {
    Auto,
    Cpu,
    Gpu,
}

/// Where tracing runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Backend {
    Cpu,
    Gpu,
}

/// A decision and the reason for it, reported by `rt2_context_info`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Decision {
    pub backend: Backend,
    pub reason: String,
    /// Chosen by AUTO: a job the GPU cannot hold (device limits) then runs on the CPU.
    pub auto: bool,
}

impl BackendRequest {
    pub fn parse(s: &str) -> Option<Self> {
        match s.trim().to_ascii_lowercase().as_str() {
            "auto" => Some(BackendRequest::Auto),
            "cpu" => Some(BackendRequest::Cpu),
            "gpu" => Some(BackendRequest::Gpu),
            _ => None,
        }
    }
}

/// Resolves the backend for a new context. `env` is the value of `RT2_BACKEND`, if set.
/// Returns the GPU devices when tracing goes there.
pub fn decide_backend(
    requested: BackendRequest,
    env: Option<&str>,
    gpu_opts: &GpuOptions,
) -> Result<(Decision, Option<Gpu>)> {
    let (request, source) = match env {
        Some(v) => match BackendRequest::parse(v) {
            Some(r) => (r, format!("RT2_BACKEND={v}")),
            None => {
                return Err(Error::invalid_argument(format!(
                    "RT2_BACKEND is '{v}' (expected cpu, gpu or auto)"
                )))
            }
        },
        None => (requested, "the context descriptor".to_string()),
    };
    let cpu = |reason: String, auto: bool| {
        Ok((
            Decision {
                backend: Backend::Cpu,
                reason,
                auto,
            },
            None,
        ))
    };
    match request {
        BackendRequest::Cpu => cpu(format!("CPU requested by {source}"), false),
        BackendRequest::Gpu => match gpu::open(gpu_opts, true) {
            // Explicitly requested, a software adapter is accepted (that is how CI tests).
            Ok(g) => Ok((
                Decision {
                    backend: Backend::Gpu,
                    reason: format!("GPU requested by {source}: {}", g.description),
                    auto: false,
                },
                Some(g),
            )),
            Err(why) => Err(Error::new(
                Rt2Status::BackendUnavailable,
                format!("GPU requested by {source}, but {why}"),
            )),
        },
        BackendRequest::Auto => match gpu::open(gpu_opts, gpu_opts.auto_accepts_software) {
            Ok(g) => Ok((
                Decision {
                    backend: Backend::Gpu,
                    reason: format!("AUTO from {source}: tracing on {}", g.description),
                    auto: true,
                },
                Some(g),
            )),
            Err(why) => cpu(
                format!("AUTO from {source}: {why}, so tracing runs on the CPU"),
                true,
            ),
        },
    }
}

/// The traversal AUTO picks on the GPU, and why.
pub fn choose_gpu_traversal(
    scene: &Committed,
    requested: Option<Traversal>,
) -> (Traversal, &'static str) {
    match requested {
        Some(t) => (t, "requested by the caller"),
        // Thesis table 2: ropes++ is the fastest GPU traversal in every scene.
        None if scene.tree.ropes.is_some() => (
            Traversal::RopesPlusPlus,
            "ropes++ is the fastest GPU traversal (thesis table 2) and the tree has ropes",
        ),
        // Without ropes (3x the tree memory, built only on request), the standard stack
        // visits the fewest nodes (thesis table 1); a 64-entry private stack fits a thread.
        None => (
            Traversal::Standard,
            "the tree has no ropes: standard visits the fewest nodes of the stack methods",
        ),
    }
}

/// The render path AUTO picks on the GPU (thesis §3.3), and why.
pub fn choose_gpu_path(scene: &Committed, opts: &RenderOptions) -> (GpuPath, &'static str) {
    match opts.gpu_path {
        GpuPathRequest::Megakernel => (GpuPath::Megakernel, "requested by the caller"),
        GpuPathRequest::Wavefront => (GpuPath::Wavefront, "requested by the caller"),
        GpuPathRequest::Auto => {
            // Thesis: the megakernel for primary rays with few reflections; one kernel per
            // bounce, with compaction, pays off when most objects spawn secondary rays.
            let secondary = scene
                .origins
                .iter()
                .filter(|o| {
                    let m = &scene.materials[scene.object_material[o.object as usize] as usize];
                    m.reflectivity > 0.0 || m.transparency > 0.0
                })
                .count();
            if opts.max_depth > 1 && 2 * secondary >= scene.origins.len().max(1) {
                (
                    GpuPath::Wavefront,
                    "most primitives reflect or transmit: wavefront",
                )
            } else {
                (GpuPath::Megakernel, "few secondary rays: megakernel")
            }
        }
    }
}

/// The traversal AUTO picks for a scene on the CPU, and why.
pub fn choose_traversal(
    _scene: &Committed,
    requested: Option<Traversal>,
) -> (Traversal, &'static str) {
    match requested {
        Some(t) => (t, "requested by the caller"),
        // On a CPU the stack costs nothing: the standard traversal visits the fewest nodes of
        // the stack-based and restart methods (thesis table 1) and needs no ropes, which cost
        // about 3x the tree memory.
        None => (
            Traversal::Standard,
            "the CPU has a cheap stack: standard visits the fewest nodes and needs no ropes",
        ),
    }
}
