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

/// `rt2_frame_save_png` to a FIFO: one that no process reads is an IO error at once (the
/// call blocked forever in `open`), one that a process reads receives the PNG.
#[test]
fn a_frame_saved_to_a_fifo_is_written_only_when_something_reads_it() {
    use rt2::api::*;
    use rt2::error::Rt2Status;
    use std::io::Read;
    let fifo = support::scratch("shading_extremes").join("fifo.png");
    let _ = std::fs::remove_file(&fifo);
    let made = std::process::Command::new("mkfifo").arg(&fifo).status();
    assert!(made.is_ok_and(|s| s.success()), "mkfifo {}", fifo.display());
    let path = std::ffi::CString::new(fifo.to_str().unwrap()).unwrap();
    let mut frame = std::ptr::null_mut();
    // SAFETY: a frame made here, destroyed at the end; `path` is a C string.
    assert_eq!(
        unsafe { rt2_frame_create(64, 32, &mut frame) },
        Rt2Status::Ok
    );
    let save = || unsafe { rt2_frame_save_png(frame, path.as_ptr()) };
    // On a thread, so that a save that blocks fails the test rather than hanging it.
    let (tx, rx) = std::sync::mpsc::channel();
    let (f, p) = (frame as usize, path.clone());
    std::thread::spawn(move || {
        let status = unsafe { rt2_frame_save_png(f as *const rt2_frame, p.as_ptr()) };
        let _ = tx.send((status, support::last_error()));
    });
    let (status, message) = rx
        .recv_timeout(std::time::Duration::from_secs(10))
        .expect("the save returned (it blocked, waiting for a reader)");
    assert_eq!(status, Rt2Status::Io, "no reader: {message}");
    assert!(message.contains("no process reads"), "{message}");

    // A reader blocks in its open until a writer comes; the save is retried until the reader
    // is in its open (before that there is none, and the save is refused as above).
    let reader = {
        let fifo = fifo.clone();
        std::thread::spawn(move || {
            let mut bytes = Vec::new();
            std::fs::File::open(fifo)
                .and_then(|mut f| f.read_to_end(&mut bytes))
                .map(|_| bytes)
        })
    };
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(60);
    let mut status = save();
    while status == Rt2Status::Io && std::time::Instant::now() < deadline {
        std::thread::sleep(std::time::Duration::from_millis(10));
        status = save();
    }
    assert_eq!(status, Rt2Status::Ok, "{}", support::last_error());
    let bytes = reader.join().unwrap().unwrap();
    let png = image::load_from_memory(&bytes).expect("a PNG came through the FIFO");
    assert_eq!((png.width(), png.height()), (64, 32));
    unsafe { rt2_frame_destroy(frame) };
    std::fs::remove_file(&fifo).unwrap();
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
