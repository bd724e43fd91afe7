//! Layer 2: decides where each operation runs and records why (RT² fig. 11's control layer).
//! Tree builds always run on the CPU (as in the thesis); tracing goes to the GPU when one is
//! usable, otherwise to the CPU. `RT2_BACKEND=cpu|gpu|auto` overrides the caller's choice.

use crate::cpu::traverse::Traversal;
use crate::error::{Error, Result, Rt2Status};
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
}

/// Why no GPU is available in this build; the GPU backend replaces this with adapter probing.
const NO_GPU: &str = "this build of RT2 has no GPU backend yet";

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
pub fn decide_backend(requested: BackendRequest, env: Option<&str>) -> Result<Decision> {
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
    match request {
        BackendRequest::Cpu => Ok(Decision {
            backend: Backend::Cpu,
            reason: format!("CPU requested by {source}"),
        }),
        BackendRequest::Gpu => Err(Error::new(
            Rt2Status::BackendUnavailable,
            format!("GPU requested by {source}, but {NO_GPU}"),
        )),
        BackendRequest::Auto => Ok(Decision {
            backend: Backend::Cpu,
            reason: format!("AUTO from {source}: {NO_GPU}, so tracing runs on the CPU"),
        }),
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
