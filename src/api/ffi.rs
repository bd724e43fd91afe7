//! Helpers for the C boundary: the panic barrier, handle checks and checked views of
//! caller memory. Nothing here trusts a pointer it has not checked.

use super::status::set_last_error;
use crate::error::{Error, Result, Rt2Status};
use std::ffi::{c_char, CStr};
use std::panic::{catch_unwind, AssertUnwindSafe};

/// Runs `f`, turning its error or panic into a status and this thread's error message.
pub(crate) fn guard(f: impl FnOnce() -> Result<()>) -> Rt2Status {
    match catch_unwind(AssertUnwindSafe(f)) {
        Ok(Ok(())) => Rt2Status::Ok,
        Ok(Err(e)) => {
            set_last_error(&e.message);
            e.status
        }
        Err(panic) => {
            let what = panic
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| panic.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "unknown panic".into());
            set_last_error(&format!(
                "internal error (a bug in RT2, please report it): {what}"
            ));
            Rt2Status::Internal
        }
    }
}

/// Like [`guard`] for calls that return a pointer: NULL on failure.
pub(crate) fn guard_ptr<T>(f: impl FnOnce() -> Result<*const T>) -> *const T {
    let mut out = std::ptr::null();
    guard(|| {
        out = f()?;
        Ok(())
    });
    out
}

/// A boxed object handed to C. `MAGIC` tells handles of this type from anything else. Every
/// handle is `#[repr(C)]` with its magic as the first field (a `u64` at offset 0, asserted by
/// [`handle_type!`]), so the magic is read through the raw pointer before any reference to the
/// handle exists.
pub(crate) trait Handle: Sized {
    const MAGIC: u64;
    const NAME: &'static str;
    /// Whether this live handle can serve a call in this process (a context's worker threads
    /// do not survive a `fork`).
    fn usable(&self) -> Result<()>;
}

/// The magic at the start of the handle `p` points to, read without making a `&T`: a handle
/// of another kind may be smaller than `T`, and a reference to it would claim `T`'s size.
///
/// # Safety
/// `p` must be non-NULL and point to a live RT2 handle (of any kind).
unsafe fn magic_of<T: Handle>(p: *const T) -> u64 {
    p.cast::<u64>().read()
}

/// Borrows a handle after checking it is non-NULL and carries the right magic.
///
/// # Safety
/// `p` must be NULL or point to a live RT2 handle. Only its magic (first) is read before the
/// check, so a handle of another type is read within its own allocation and rejected; a
/// destroyed handle is rejected as long as its memory was not reused.
pub(crate) unsafe fn handle<'a, T: Handle>(p: *const T, arg: &str) -> Result<&'a T> {
    if p.is_null() {
        return Err(Error::invalid_argument(format!("{arg} is NULL")));
    }
    check_aligned(p, arg)?;
    if magic_of(p) != T::MAGIC {
        return Err(Error::invalid_argument(format!(
            "{arg} is not a live {} (destroyed, or a different kind of handle)",
            T::NAME
        )));
    }
    let h = &*p;
    h.usable()
        .map_err(|e| Error::new(e.status, format!("{arg}: {}", e.message)))?;
    Ok(h)
}

/// Mutable variant of [`handle`].
///
/// # Safety
/// As for [`handle`], and no other reference to `*p` may be alive.
pub(crate) unsafe fn handle_mut<'a, T: Handle>(p: *mut T, arg: &str) -> Result<&'a mut T> {
    handle(p as *const T, arg)?;
    Ok(&mut *p)
}

/// Frees a handle made by `Box::into_raw`, ignoring NULL and handles that fail the check. The
/// magic is cleared first, so a second destroy of the same pointer is ignored while the
/// memory is not reused (the header still calls it undefined, as `free` twice is). The
/// clear is a volatile write: a plain store into memory freed right after is dead to the
/// optimiser, which removed it for the camera (valgrind showed its second destroy freeing
/// the block again).
///
/// # Safety
/// `p` must be NULL or point to a live RT2 handle (of any kind).
pub(crate) unsafe fn destroy<T: Handle>(p: *mut T) {
    if p.is_null() || !p.is_aligned() || magic_of(p) != T::MAGIC {
        return;
    }
    p.cast::<u64>().write_volatile(0);
    drop(Box::from_raw(p));
}

/// An error unless the non-NULL `p` is aligned for `T`: C can hand over any address (a
/// pointer into a packed buffer), and Rust may not read a `T` from a misaligned one.
fn check_aligned<T>(p: *const T, arg: &str) -> Result<()> {
    if p.is_aligned() {
        Ok(())
    } else {
        Err(Error::invalid_argument(format!(
            "{arg} ({p:p}) is not aligned to {} bytes",
            std::mem::align_of::<T>()
        )))
    }
}

/// A slice of `count` elements at `p`; NULL is allowed only for `count == 0`.
///
/// # Safety
/// A non-NULL `p` must point to `count` readable, initialised elements.
pub(crate) unsafe fn slice<'a, T>(p: *const T, count: usize, arg: &str) -> Result<&'a [T]> {
    if count == 0 {
        return Ok(&[]);
    }
    if p.is_null() {
        return Err(Error::invalid_argument(format!(
            "{arg} is NULL but its count is {count}"
        )));
    }
    check_aligned(p, arg)?;
    if count
        .checked_mul(std::mem::size_of::<T>())
        .is_none_or(|b| b > isize::MAX as usize)
    {
        return Err(Error::invalid_argument(format!(
            "{arg}: count {count} overflows the address space"
        )));
    }
    Ok(std::slice::from_raw_parts(p, count))
}

/// Mutable variant of [`slice()`].
///
/// # Safety
/// A non-NULL `p` must point to `count` writable elements not aliased elsewhere.
pub(crate) unsafe fn slice_mut<'a, T>(p: *mut T, count: usize, arg: &str) -> Result<&'a mut [T]> {
    slice(p as *const T, count, arg)?;
    if count == 0 {
        return Ok(&mut []);
    }
    Ok(std::slice::from_raw_parts_mut(p, count))
}

/// An error unless the `count` elements at `out` and the `input_count` at `input` (both
/// already checked by [`slice()`]) share no byte: Rust may not read an input while writing
/// an output over it, and a C caller may hand over one buffer as both.
pub(crate) fn check_disjoint<T, U>(
    (out, count, out_name): (*const T, usize, &str),
    (input, input_count, input_name): (*const U, usize, &str),
) -> Result<()> {
    if count == 0 || input_count == 0 {
        return Ok(());
    }
    let range = |p: *const u8, bytes: usize| (p as usize, p as usize + bytes);
    let (a0, a1) = range(out.cast(), count * std::mem::size_of::<T>());
    let (b0, b1) = range(input.cast(), input_count * std::mem::size_of::<U>());
    if a0 < b1 && b0 < a1 {
        return Err(Error::invalid_argument(format!(
            "{out_name} overlaps {input_name}: the output must be a separate array"
        )));
    }
    Ok(())
}

/// Reads a fixed-size array argument such as `const float pos[3]`.
///
/// # Safety
/// A non-NULL `p` must point to `N` readable elements.
pub(crate) unsafe fn array<T: Copy, const N: usize>(p: *const T, arg: &str) -> Result<[T; N]> {
    let s = slice(p, N, arg)?;
    let mut out = [s[0]; N];
    out.copy_from_slice(s);
    Ok(out)
}

/// Writes an output argument, checking it first.
///
/// # Safety
/// A non-NULL `p` must be writable.
pub(crate) unsafe fn write_out<T>(p: *mut T, arg: &str, value: T) -> Result<()> {
    check_out(p, arg)?;
    p.write(value);
    Ok(())
}

/// Checks an output pointer before any work is done, so that failures leave no side effects.
pub(crate) fn check_out<T>(p: *mut T, arg: &str) -> Result<()> {
    if p.is_null() {
        return Err(Error::invalid_argument(format!("{arg} is NULL")));
    }
    check_aligned(p, arg)
}

/// A NUL-terminated path argument.
///
/// # Safety
/// A non-NULL `p` must point to a NUL-terminated string.
pub(crate) unsafe fn path_arg(p: *const c_char, arg: &str) -> Result<std::path::PathBuf> {
    if p.is_null() {
        return Err(Error::invalid_argument(format!("{arg} is NULL")));
    }
    let bytes = CStr::from_ptr(p).to_bytes();
    if bytes.is_empty() {
        return Err(Error::invalid_argument(format!("{arg} is an empty string")));
    }
    #[cfg(unix)]
    {
        use std::os::unix::ffi::OsStrExt;
        Ok(std::ffi::OsStr::from_bytes(bytes).into())
    }
    #[cfg(not(unix))]
    {
        std::str::from_utf8(bytes)
            .map(Into::into)
            .map_err(|_| Error::invalid_argument(format!("{arg} is not valid UTF-8")))
    }
}

/// A versioned C input struct: `#[repr(C)]`, starting with its `struct_size` (a `u32` at
/// offset 0). Implemented through [`versioned!`], which asserts that layout at compile time.
pub(crate) trait Versioned: Copy {
    const NAME: &'static str;
}

/// Implements [`Versioned`] for a struct and asserts that its `struct_size` is at offset 0,
/// which [`read_versioned`] relies on.
macro_rules! versioned {
    ($t:ident) => {
        impl $crate::api::ffi::Versioned for $t {
            const NAME: &'static str = stringify!($t);
        }
        const _: () = assert!(std::mem::offset_of!($t, struct_size) == 0);
    };
}
pub(crate) use versioned;

/// Implements [`Handle`] for a handle type and asserts that its `magic` is at offset 0, which
/// [`handle`] and [`destroy`] rely on. `usable` (a closure of the handle) defaults to always.
macro_rules! handle_type {
    ($t:ident, $magic:expr) => {
        $crate::api::ffi::handle_type!($t, $magic, |_: &$t| Ok(()));
    };
    ($t:ident, $magic:expr, $usable:expr) => {
        impl $crate::api::ffi::Handle for $t {
            const MAGIC: u64 = $magic;
            const NAME: &'static str = stringify!($t);
            fn usable(&self) -> $crate::error::Result<()> {
                ($usable)(self)
            }
        }
        const _: () = assert!(std::mem::offset_of!($t, magic) == 0);
    };
}
pub(crate) use handle_type;

/// Copies the versioned input at `p` (non-NULL) once its `struct_size` is checked. The size is
/// read alone first: a caller built against an older, smaller struct gets the error instead of
/// a read past its struct's end.
///
/// # Safety
/// `p` must point to at least a readable `u32`, and to a whole `T` when that `u32` is
/// `size_of::<T>()`.
pub(crate) unsafe fn read_versioned<T: Versioned>(p: *const T) -> Result<T> {
    check_aligned(p, T::NAME)?;
    check_struct_size::<T>(p.cast::<u32>().read(), T::NAME)?;
    Ok(p.read())
}

/// Checks the `struct_size` field of a versioned descriptor.
pub(crate) fn check_struct_size<T>(struct_size: u32, name: &str) -> Result<()> {
    let want = std::mem::size_of::<T>();
    if struct_size as usize != want {
        return Err(Error::invalid_argument(format!(
            "{name}.struct_size is {struct_size}, expected {want}: set it to sizeof({name})"
        )));
    }
    Ok(())
}

/// Unknown enum values from C are errors, never transmuted.
pub(crate) fn enum_error(name: &str, value: u32) -> Error {
    Error::new(
        Rt2Status::InvalidArgument,
        format!("{value} is not a valid {name} value"),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::api::status::rt2_last_error_message;

    fn last_message() -> String {
        // SAFETY: rt2_last_error_message returns a NUL-terminated string valid until the next
        // failing call on this thread.
        unsafe { CStr::from_ptr(rt2_last_error_message()) }
            .to_string_lossy()
            .into_owned()
    }

    /// The panic barrier every `rt2_*` function runs in: a panic (a `&str` or a formatted
    /// `String` payload) becomes `RT2_STATUS_INTERNAL` with the panic's text in the thread's
    /// message, an error its own status and message, and the call after either still works.
    #[test]
    fn guard_turns_panics_and_errors_into_statuses() {
        let st = guard(|| panic!("plain payload"));
        assert_eq!(st, Rt2Status::Internal);
        let m = last_message();
        assert!(
            m.contains("internal error") && m.contains("plain payload"),
            "{m}"
        );

        let n = 7;
        let st = guard(|| panic!("formatted payload {n}"));
        assert_eq!(st, Rt2Status::Internal);
        assert!(last_message().contains("formatted payload 7"));

        let st = guard(|| Err(Error::invalid_argument("bad input")));
        assert_eq!(st, Rt2Status::InvalidArgument);
        assert_eq!(last_message(), "bad input");

        assert_eq!(guard(|| Ok(())), Rt2Status::Ok);
        let p: *const u8 = guard_ptr(|| panic!("in a pointer call"));
        assert!(p.is_null());
        assert!(last_message().contains("in a pointer call"));
    }
}
