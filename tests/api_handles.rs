//! The C boundary through the exported functions themselves: handles of the wrong type,
//! destroyed handles and NULLs are errors with a message, never a crash, and a failed call
//! changes nothing.

use rt2::api::*;
use rt2::error::Rt2Status;
use std::ffi::CStr;
use std::ptr::{null, null_mut};

fn last_error() -> String {
    unsafe { CStr::from_ptr(rt2_last_error_message()) }
        .to_string_lossy()
        .into_owned()
}

#[test]
fn a_handle_of_another_type_is_rejected() {
    unsafe {
        let mut cam = null_mut();
        assert_eq!(rt2_camera_create(&mut cam), Rt2Status::Ok);
        let (mut w, mut h) = (7u32, 9u32);
        let status = rt2_frame_size(cam as *const rt2_frame, &mut w, &mut h);
        assert_eq!(status, Rt2Status::InvalidArgument);
        assert!(last_error().contains("rt2_frame"), "{}", last_error());
        assert_eq!((w, h), (7, 9), "outputs untouched on failure");
        rt2_camera_destroy(cam);
    }
}

#[test]
fn null_handles_and_outputs_are_errors_and_destroy_null_is_a_no_op() {
    unsafe {
        assert_eq!(rt2_scene_commit(null_mut()), Rt2Status::InvalidArgument);
        assert!(last_error().contains("scene is NULL"), "{}", last_error());
        assert_eq!(
            rt2_context_create(null(), null_mut()),
            Rt2Status::InvalidArgument
        );
        assert!(rt2_frame_pixels(null()).is_null());
        rt2_context_destroy(null_mut());
        rt2_scene_destroy(null_mut());
        rt2_camera_destroy(null_mut());
        rt2_frame_destroy(null_mut());
    }
}

#[test]
fn failed_edits_leave_the_scene_as_it_was() {
    unsafe {
        let (mut ctx, mut scene) = (null_mut(), null_mut());
        assert_eq!(rt2_context_create(null(), &mut ctx), Rt2Status::Ok);
        assert_eq!(rt2_scene_create(ctx, &mut scene), Rt2Status::Ok);
        let c = [0.0f32, 0.0, 0.0];
        let mut id = 77u32;
        assert_eq!(
            rt2_scene_add_sphere(scene, c.as_ptr(), -1.0, 0, &mut id),
            Rt2Status::InvalidArgument
        );
        assert!(last_error().contains("radius"), "{}", last_error());
        assert_eq!(id, 77, "no id written on failure");
        let nan = [f32::NAN, 0.0, 0.0];
        assert_eq!(
            rt2_scene_add_sphere(scene, nan.as_ptr(), 1.0, 0, &mut id),
            Rt2Status::InvalidArgument
        );
        let positions = [0.0f32, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0];
        let bad = [0u32, 1, 3];
        let status = rt2_scene_add_mesh(scene, positions.as_ptr(), 3, bad.as_ptr(), 1, 0, &mut id);
        assert_eq!(status, Rt2Status::InvalidArgument);
        assert!(last_error().contains("indices[2]"), "{}", last_error());
        assert_eq!(
            rt2_scene_add_sphere(scene, c.as_ptr(), 1.0, 5, &mut id),
            Rt2Status::InvalidArgument
        );
        // The first successful add gets object 0: nothing was added by the failures.
        assert_eq!(
            rt2_scene_add_sphere(scene, c.as_ptr(), 1.0, 0, &mut id),
            Rt2Status::Ok
        );
        assert_eq!(id, 0);
        // A render before commit is an invalid operation, and so is one after a new edit.
        let (mut cam, mut frame) = (null_mut(), null_mut());
        assert_eq!(rt2_camera_create(&mut cam), Rt2Status::Ok);
        assert_eq!(rt2_frame_create(8, 8, &mut frame), Rt2Status::Ok);
        assert_eq!(
            rt2_render(ctx, scene, cam, null(), frame),
            Rt2Status::InvalidOperation
        );
        assert_eq!(rt2_scene_commit(scene), Rt2Status::Ok);
        assert_eq!(rt2_render(ctx, scene, cam, null(), frame), Rt2Status::Ok);
        assert_eq!(
            rt2_scene_add_sphere(scene, c.as_ptr(), 0.5, 0, &mut id),
            Rt2Status::Ok
        );
        assert_eq!(
            rt2_render(ctx, scene, cam, null(), frame),
            Rt2Status::InvalidOperation
        );
        assert!(
            last_error().contains("modified after its last commit"),
            "{}",
            last_error()
        );
        // Unknown enum values in options are rejected, not transmuted.
        let mut opts = rt2_render_options_default();
        opts.traversal = 99;
        assert_eq!(rt2_scene_commit(scene), Rt2Status::Ok);
        assert_eq!(
            rt2_render(ctx, scene, cam, &opts, frame),
            Rt2Status::InvalidArgument
        );
        assert!(last_error().contains("rt2_traversal"), "{}", last_error());
        // Destroying the context first is safe: the scene keeps what it needs alive.
        rt2_context_destroy(ctx);
        assert_eq!(rt2_scene_commit(scene), Rt2Status::Ok);
        rt2_frame_destroy(frame);
        rt2_camera_destroy(cam);
        rt2_scene_destroy(scene);
    }
}
