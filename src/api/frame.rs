//! `rt2_frame`: an RGBA8 image that renders write into, with an optional HUD mask. A frame is
//! used by one call at a time.

use super::ffi::{
    check_out, destroy, guard, guard_ptr, handle, handle_mut, handle_type, path_arg, slice,
    write_out, Handle,
};
use crate::error::Rt2Status;
use crate::frame::Frame;

/// Opaque frame handle: `width × height` RGBA8 pixels, row-major from the top-left, initially
/// transparent black.
#[repr(C)]
pub struct rt2_frame {
    /// First field of every handle, so checking it never reads past a handle of another type.
    magic: u64,
    pub(crate) frame: Frame,
}

handle_type!(rt2_frame, 0x7274_325f_6672_6d00);

/// Creates a frame; each side must be in 1..=32768.
///
/// # Safety
/// `out` points to writable storage.
#[no_mangle]
pub unsafe extern "C" fn rt2_frame_create(
    width: u32,
    height: u32,
    out: *mut *mut rt2_frame,
) -> Rt2Status {
    guard(|| {
        check_out(out, "out")?;
        let h = Box::new(rt2_frame {
            magic: rt2_frame::MAGIC,
            frame: Frame::new(width, height)?,
        });
        write_out(out, "out", Box::into_raw(h))
    })
}

/// Frees a frame. NULL is a no-op.
///
/// # Safety
/// `frame` is NULL or a frame not yet destroyed.
#[no_mangle]
pub unsafe extern "C" fn rt2_frame_destroy(frame: *mut rt2_frame) {
    guard(|| {
        destroy(frame);
        Ok(())
    });
}

/// Writes the frame's size.
///
/// # Safety
/// `frame` is a live frame; `width` and `height` are writable.
#[no_mangle]
pub unsafe extern "C" fn rt2_frame_size(
    frame: *const rt2_frame,
    width: *mut u32,
    height: *mut u32,
) -> Rt2Status {
    guard(|| {
        let f = handle(frame, "frame")?;
        check_out(width, "width")?;
        check_out(height, "height")?;
        write_out(width, "width", f.frame.width())?;
        write_out(height, "height", f.frame.height())
    })
}

/// Sets the mask: one byte per pixel, 0 = not traced (left as it was, e.g. under a HUD).
/// NULL clears the mask. The bytes are copied.
///
/// # Safety
/// `frame` is a live frame; `mask` is NULL or holds width × height bytes.
#[no_mangle]
pub unsafe extern "C" fn rt2_frame_set_mask(frame: *mut rt2_frame, mask: *const u8) -> Rt2Status {
    guard(|| {
        let f = handle_mut(frame, "frame")?;
        if mask.is_null() {
            return f.frame.set_mask(None);
        }
        let m = slice(mask, f.frame.pixel_count(), "mask")?;
        f.frame.set_mask(Some(m))
    })
}

/// The pixels, `4 × width × height` bytes (RGBA8); valid until the frame is destroyed.
/// Row-major, row 0 at the top. A rendered pixel is the linear colour clamped to [0, 1],
/// times 255, rounded: no sRGB encoding is applied. Its alpha is 255. Pixels no render has
/// written (masked ones, all of a new frame) keep their bytes: 0 in a new frame.
/// NULL (with the error message set) if `frame` is not a live frame.
///
/// # Safety
/// `frame` is a live frame.
#[no_mangle]
pub unsafe extern "C" fn rt2_frame_pixels(frame: *const rt2_frame) -> *const u8 {
    guard_ptr(|| Ok(handle(frame, "frame")?.frame.pixels().as_ptr()))
}

/// Saves the frame as an 8-bit RGBA PNG file, replacing any file at `path`. The bytes are
/// written as they are, with no gamma or colour-space chunk (`rt2_frame_pixels`). The file name
/// must have the extension `.png` (any case; a bare `.png` has none), else INVALID_ARGUMENT;
/// a directory at `path`, a missing folder or a failed write is an IO error. A FIFO at `path`
/// is written when a process reads it; one that no process reads is an IO error at once
/// (rather than a call that waits for a reader). As with any write to a pipe, a reader that
/// closes it early raises SIGPIPE in the calling process unless that signal is ignored.
///
/// # Safety
/// `frame` is a live frame; `path` is a NUL-terminated string.
#[no_mangle]
pub unsafe extern "C" fn rt2_frame_save_png(
    frame: *const rt2_frame,
    path: *const std::ffi::c_char,
) -> Rt2Status {
    guard(|| {
        let f = handle(frame, "frame")?;
        f.frame.save_png(&path_arg(path, "path")?)
    })
}
