//! `rt2_context`: the thread pool and backend choice. Thread-safe: any number of threads may
//! use one context at once. Scenes keep their context alive, so destroy order is free.
//! `rt2_context_info` reports the backend, why it was chosen, why the last job ran on the CPU
//! after all when an AUTO context's GPU could not take it, and what AUTO chose for that job.

use super::ffi::{
    check_out, check_struct_size, destroy, guard, handle, handle_type, read_versioned, write_out,
    Handle,
};
use super::options::{backend_from, rt2_context_desc, Rt2Backend};
use crate::context::Context;
use crate::dispatch::Backend;
use crate::error::Rt2Status;
use std::cell::RefCell;
use std::ffi::{c_char, CString};
use std::sync::Arc;

thread_local! {
    /// This thread's copies of the fallback reason and AUTO's choices that `rt2_context_info`
    /// last returned. Copies, because the context's own record changes with every job of any
    /// thread.
    static LAST_JOB: RefCell<[Option<CString>; 2]> = const { RefCell::new([None, None]) };
}

/// Opaque context handle. Create with `rt2_context_create`, free with `rt2_context_destroy`.
#[repr(C)]
pub struct rt2_context {
    /// First field of every handle, so checking it never reads past a handle of another type.
    magic: u64,
    pub(crate) inner: Arc<Context>,
    reason: CString,
}

handle_type!(rt2_context, 0x7274_325f_6374_7800, |c: &rt2_context| c
    .inner
    .same_process());

/// What a context decided (`rt2_context_info`).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct rt2_context_properties {
    /// Set to `sizeof(rt2_context_properties)` before the call.
    pub struct_size: u32,
    /// The `rt2_backend` tracing runs on (CPU or GPU, never AUTO).
    pub backend: u32,
    /// Worker threads of the context's pool.
    pub threads: u32,
    /// Why that backend was chosen; valid until `rt2_context_destroy` (scenes may keep the
    /// context's work alive longer, not this string).
    pub reason: *const c_char,
    /// Why the context's last render or ray query ran on the CPU although `backend` is GPU:
    /// an AUTO context whose device could not take that job (the scene or the job exceeds a
    /// device limit such as the largest storage buffer binding, the device ran out of memory
    /// during the job or was lost, or an option the GPU kernels lack, e.g. the watertight
    /// intersector). NULL when that job ran on `backend`, when no job
    /// ran yet, and always on a CPU context. With several threads using the context, it is
    /// the job that chose its backend last. A copy, valid until the next `rt2_context_info`
    /// on this thread; during thread exit (an `atexit` handler, a thread-local destructor),
    /// where this thread's copies are gone, a static "(not available: the thread is
    /// exiting)" instead.
    pub fallback: *const c_char,
    /// What the library chose for the context's last render or ray query where the caller
    /// left the choice to it (`RT2_TRAVERSAL_AUTO`, `RT2_QUERY_MODE_AUTO`, `RT2_GPU_PATH_AUTO`),
    /// and why, on the backend that ran the job, as `"<what> <choice>: <why>"` items joined by
    /// `"; "`, e.g. `"GPU traversal ropes++: ...; GPU render path megakernel: ..."` or
    /// `"CPU traversal standard: ...; CPU query mode packet: ..."`. NULL when the caller chose
    /// everything or no job ran yet. Same job and same lifetime as `fallback`: a copy, valid
    /// until the next `rt2_context_info` on this thread.
    pub auto_choice: *const c_char,
}

/// Creates a context. `desc` may be NULL for the defaults. On failure `*out` is untouched.
///
/// A context and its scenes belong to the process that made them: after `fork()`, the child
/// has no copy of their worker threads, so its calls on them return INVALID_OPERATION
/// (destroying them is allowed, and does not wait for those threads). A child makes its own
/// context.
///
/// # Safety
/// `desc` is NULL or points to an `rt2_context_desc`; `out` points to writable storage.
#[no_mangle]
pub unsafe extern "C" fn rt2_context_create(
    desc: *const rt2_context_desc,
    out: *mut *mut rt2_context,
) -> Rt2Status {
    guard(|| {
        check_out(out, "out")?;
        let d = if desc.is_null() {
            super::options::rt2_context_desc_default()
        } else {
            read_versioned(desc)?
        };
        let ctx = Context::new(backend_from(d.backend)?, d.threads)?;
        write_out(out, "out", rt2_context::from_context(ctx))
    })
}

impl rt2_context {
    /// Hands a Rust [`Context`] to C code as an `rt2_context` (for Rust programs that made the
    /// context with [`Context::with_gpu_options`]); free it with `rt2_context_destroy`.
    pub fn from_context(ctx: Context) -> *mut rt2_context {
        let reason = CString::new(ctx.decision().reason.replace('\0', "")).unwrap_or_default();
        Box::into_raw(Box::new(rt2_context {
            magic: rt2_context::MAGIC,
            inner: Arc::new(ctx),
            reason,
        }))
    }
}

/// Releases the caller's reference; scenes created from it keep working (they hold the
/// context's worker threads for their commits). NULL is a no-op.
///
/// # Safety
/// `ctx` is NULL or a context not yet destroyed.
#[no_mangle]
pub unsafe extern "C" fn rt2_context_destroy(ctx: *mut rt2_context) {
    guard(|| {
        destroy(ctx);
        Ok(())
    });
}

/// Reports the backend tracing runs on and why, why the last job ran on the CPU instead
/// (`fallback`, NULL when it did not), and what AUTO chose for that job (`auto_choice`). A query
/// of more than 2^20 rays runs as several jobs, steps of up to 2^20 rays (see `rt2_intersect`):
/// this reports its last.
/// On failure `*out` is untouched.
///
/// # Safety
/// `ctx` is a live context; `out` points to an `rt2_context_properties` whose `struct_size` is set.
#[no_mangle]
pub unsafe extern "C" fn rt2_context_info(
    ctx: *const rt2_context,
    out: *mut rt2_context_properties,
) -> Rt2Status {
    guard(|| {
        let c = handle(ctx, "ctx")?;
        check_out(out, "out")?;
        check_struct_size::<rt2_context_properties>((*out).struct_size, "rt2_context_properties")?;
        let backend = match c.inner.decision().backend {
            Backend::Cpu => Rt2Backend::Cpu,
            Backend::Gpu => Rt2Backend::Gpu,
        };
        let c_string =
            |s: Option<String>| s.map(|s| CString::new(s.replace('\0', "")).unwrap_or_default());
        let (fallback, auto_choice) = c.inner.last_job();
        let copies = [c_string(fallback), c_string(auto_choice)];
        let present = copies.each_ref().map(Option::is_some);
        // Every check passed: only now are the pointers of the previous call replaced.
        // During thread exit (an `atexit` handler, a thread-local destructor) this thread's
        // copies are gone, and `with` would panic: each text present is then a static note.
        let [fallback, auto_choice] = LAST_JOB
            .try_with(|cell| {
                let mut slots = cell.borrow_mut();
                *slots = copies;
                slots
                    .each_ref()
                    .map(|s| s.as_ref().map_or(std::ptr::null(), |s| s.as_ptr()))
            })
            .unwrap_or(present.map(|p| {
                if p {
                    c"(not available: the thread is exiting)".as_ptr()
                } else {
                    std::ptr::null()
                }
            }));
        write_out(
            out,
            "out",
            rt2_context_properties {
                struct_size: std::mem::size_of::<rt2_context_properties>() as u32,
                backend: backend as u32,
                threads: c.inner.threads() as u32,
                reason: c.reason.as_ptr(),
                fallback,
                auto_choice,
            },
        )
    })
}
