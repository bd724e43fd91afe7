//! `rt2_context`: the thread pool and backend choice. Thread-safe: any number of threads may
//! use one context at once. Scenes keep their context alive, so destroy order is free.

use super::ffi::{check_out, check_struct_size, destroy, guard, handle, write_out, Handle};
use super::options::{backend_from, rt2_context_desc, Rt2Backend};
use crate::context::Context;
use crate::dispatch::Backend;
use crate::error::Rt2Status;
use std::ffi::{c_char, CString};
use std::sync::Arc;

/// Opaque context handle. Create with `rt2_context_create`, free with `rt2_context_destroy`.
#[repr(C)]
pub struct rt2_context {
    /// First field of every handle, so checking it never reads past a handle of another type.
    magic: u64,
    pub(crate) inner: Arc<Context>,
    reason: CString,
}

impl Handle for rt2_context {
    const MAGIC: u64 = 0x7274_325f_6374_7800;
    const NAME: &'static str = "rt2_context";
    fn magic(&self) -> u64 {
        self.magic
    }
}

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
    /// Why that backend was chosen; valid while the context lives.
    pub reason: *const c_char,
}

/// Creates a context. `desc` may be NULL for the defaults. On failure `*out` is untouched.
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
            *desc
        };
        check_struct_size::<rt2_context_desc>(d.struct_size, "rt2_context_desc")?;
        let ctx = Context::new(backend_from(d.backend)?, d.threads)?;
        let reason = CString::new(ctx.decision().reason.replace('\0', "")).unwrap_or_default();
        let h = Box::new(rt2_context {
            magic: rt2_context::MAGIC,
            inner: Arc::new(ctx),
            reason,
        });
        write_out(out, "out", Box::into_raw(h))
    })
}

/// Releases the caller's reference; scenes created from it keep working. NULL is a no-op.
///
/// # Safety
/// `ctx` is NULL or a context not yet destroyed.
#[no_mangle]
pub unsafe extern "C" fn rt2_context_destroy(ctx: *mut rt2_context) {
    guard(|| {
        destroy(ctx, |c| c.magic = 0);
        Ok(())
    });
}

/// Reports the backend tracing runs on and why.
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
        write_out(
            out,
            "out",
            rt2_context_properties {
                struct_size: std::mem::size_of::<rt2_context_properties>() as u32,
                backend: backend as u32,
                threads: c.inner.threads() as u32,
                reason: c.reason.as_ptr(),
            },
        )
    })
}
