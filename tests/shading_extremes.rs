//! Renders at the edges of the shading model's range on the CPU, in both schedules, against
//! the images worked out by hand in `support::shading_cases` (the GPU's in `tests/gpu.rs`),
//! and a frame written to a full disk.

mod support;

use rt2::context::Context;
use rt2::dispatch::BackendRequest;
use rt2::render::{RenderOptions, Schedule};
use support::shading_cases::failures;

#[test]
fn extreme_lights_colours_and_sample_counts_render_as_the_shading_model_says() {
    let cpu = Context::new(BackendRequest::Cpu, 0).unwrap();
    let schedules = [Schedule::DepthFirst, Schedule::BreadthFirst];
    let failures = failures(&cpu, &schedules, |o, schedule| RenderOptions {
        schedule,
        ..o
    });
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// `rt2_frame_save_png` to a full disk (a link to `/dev/full`) is an IO error. A PNG smaller
/// than the encoder's 8 KiB buffer reached the file only when the buffer was dropped, and the
/// drop's error was lost: the call returned OK and nothing was written.
#[test]
fn a_frame_saved_to_a_full_disk_is_an_io_error() {
    use rt2::api::*;
    use rt2::error::Rt2Status;
    let link = support::scratch("shading_extremes").join("full.png");
    let _ = std::fs::remove_file(&link);
    std::os::unix::fs::symlink("/dev/full", &link).unwrap();
    let path = std::ffi::CString::new(link.to_str().unwrap()).unwrap();
    for size in [1, 16, 200] {
        // SAFETY: a frame made and destroyed here; `path` is a C string.
        let status = unsafe {
            let mut f = std::ptr::null_mut();
            assert_eq!(rt2_frame_create(size, size, &mut f), Rt2Status::Ok);
            let status = rt2_frame_save_png(f, path.as_ptr());
            rt2_frame_destroy(f);
            status
        };
        assert_eq!(status, Rt2Status::Io, "a {size}x{size} frame");
    }
    std::fs::remove_file(&link).unwrap();
}
