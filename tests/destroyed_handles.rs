//! A handle destroyed twice, or used after its destroy, is refused while its memory has not been
//! reused: `rt2_*_destroy` clears the handle's magic before freeing it (`api::ffi::destroy`).
//! The header calls both undefined, as `free` twice is; this is the best effort behind that.
//!
//! The test binary's allocator never hands freed memory out again and leaves its bytes as
//! they were, as valgrind does, so what a destroy left behind can be looked at. (Reading it
//! with the system allocator would see the allocator's own free-list links, not the clear.)

use rt2::api::*;
use rt2::error::Rt2Status;
use std::alloc::{GlobalAlloc, Layout, System};
use std::ptr::null_mut;

/// Allocates from the system and never frees: this binary makes few, small allocations.
struct NeverReused;

unsafe impl GlobalAlloc for NeverReused {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        System.alloc(layout)
    }

    unsafe fn dealloc(&self, _ptr: *mut u8, _layout: Layout) {}
}

#[global_allocator]
static ALLOCATOR: NeverReused = NeverReused;

#[test]
fn destroyed_handles_are_refused_and_a_second_destroy_is_ignored() {
    unsafe {
        let mut camera = null_mut();
        assert_eq!(rt2_camera_create(&mut camera), Rt2Status::Ok);
        rt2_camera_destroy(camera);
        rt2_camera_destroy(camera);
        assert_eq!(rt2_camera_set_fov(camera, 30.0), Rt2Status::InvalidArgument);

        let mut ctx = null_mut();
        assert_eq!(
            rt2_context_create(std::ptr::null(), &mut ctx),
            Rt2Status::Ok
        );
        let mut scene = null_mut();
        assert_eq!(rt2_scene_create(ctx, &mut scene), Rt2Status::Ok);
        let mut frame = null_mut();
        assert_eq!(rt2_frame_create(8, 8, &mut frame), Rt2Status::Ok);
        rt2_frame_destroy(frame);
        rt2_frame_destroy(frame);
        assert!(rt2_frame_pixels(frame).is_null());
        rt2_scene_destroy(scene);
        rt2_scene_destroy(scene);
        assert_eq!(rt2_scene_commit(scene), Rt2Status::InvalidArgument);
        rt2_context_destroy(ctx);
        rt2_context_destroy(ctx);
        let mut again = null_mut();
        assert_eq!(
            rt2_scene_create(ctx, &mut again),
            Rt2Status::InvalidArgument
        );
        assert!(again.is_null());
    }
}
