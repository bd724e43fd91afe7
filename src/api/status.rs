//! Status codes, the thread-local error message and the version.

use super::ffi::guard_ptr;
use std::cell::RefCell;
use std::ffi::{c_char, CString};

thread_local! {
    static LAST_ERROR: RefCell<CString> = RefCell::new(CString::default());
}

pub(crate) fn set_last_error(message: &str) {
    // Interior NULs would cut the C string short; they cannot occur in our messages but a
    // file name could carry one, so replace them.
    let c = CString::new(message.replace('\0', "\\0")).unwrap_or_default();
    // During thread exit (a C `atexit` handler, a C++ static destructor) the thread-local is
    // gone: the message is lost but the status still says what failed. `with` would panic
    // there, outside the panic barrier.
    let _ = LAST_ERROR.try_with(|e| *e.borrow_mut() = c);
}

/// The library version as "MAJOR.MINOR.PATCH" (static storage).
#[no_mangle]
pub extern "C" fn rt2_version() -> *const c_char {
    concat!(env!("CARGO_PKG_VERSION"), "\0").as_ptr().cast()
}

/// The name of a status code, e.g. "RT2_STATUS_OK" (static storage; "RT2_STATUS_UNKNOWN" for
/// values that are not codes).
#[no_mangle]
pub extern "C" fn rt2_status_string(status: u32) -> *const c_char {
    let s: &'static str = match status {
        0 => "RT2_STATUS_OK\0",
        1 => "RT2_STATUS_INVALID_ARGUMENT\0",
        2 => "RT2_STATUS_INVALID_OPERATION\0",
        3 => "RT2_STATUS_OUT_OF_MEMORY\0",
        4 => "RT2_STATUS_IO\0",
        5 => "RT2_STATUS_PARSE\0",
        6 => "RT2_STATUS_UNSUPPORTED\0",
        7 => "RT2_STATUS_BACKEND_UNAVAILABLE\0",
        8 => "RT2_STATUS_INTERNAL\0",
        _ => "RT2_STATUS_UNKNOWN\0",
    };
    s.as_ptr().cast()
}

/// The message of the last failed call on this thread ("" if none failed yet). Valid until
/// the next failing call on this thread. During thread exit, when the message is gone, a
/// static message says so.
#[no_mangle]
pub extern "C" fn rt2_last_error_message() -> *const c_char {
    guard_ptr(|| {
        Ok(LAST_ERROR
            .try_with(|e| e.borrow().as_ptr())
            .unwrap_or(c"(no error message: the thread is exiting)".as_ptr()))
    })
}
