//! The context: the thread pool and the backend decision every operation goes through.

use crate::camera::Camera;
use crate::cpu;
use crate::dispatch::{self, Backend, BackendRequest, Decision};
use crate::error::{Error, Result};
use crate::frame::Frame;
use crate::render::RenderOptions;
use crate::scene::Committed;

pub struct Context {
    pool: rayon::ThreadPool,
    decision: Decision,
}

impl Context {
    /// `threads == 0` uses every core. The pool is the context's own: the host program's
    /// global rayon pool is never touched.
    pub fn new(request: BackendRequest, threads: u32) -> Result<Self> {
        let env = std::env::var("RT2_BACKEND").ok();
        let decision = dispatch::decide_backend(request, env.as_deref())?;
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads as usize)
            .thread_name(|i| format!("rt2-worker-{i}"))
            .build()
            .map_err(|e| Error::new(crate::error::Rt2Status::Internal, format!("cannot start threads: {e}")))?;
        Ok(Context { pool, decision })
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

    pub fn render(&self, scene: &Committed, camera: &Camera, opts: &RenderOptions, frame: &mut Frame) -> Result<()> {
        let (traversal, _why) = dispatch::choose_traversal(scene, opts.traversal);
        match self.decision.backend {
            Backend::Cpu => {
                self.install(|| cpu::whitted::render(scene, camera, opts, traversal, frame));
                Ok(())
            }
            Backend::Gpu => Err(Error::unsupported("the GPU backend is not built yet")),
        }
    }
}
