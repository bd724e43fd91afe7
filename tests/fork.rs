//! After `fork()`, the child holds copies of the parent's contexts and scenes but none of
//! their worker threads (nor the GPU driver's): a job there would wait forever for workers
//! that do not exist. Python's `multiprocessing` forks by default on Linux before 3.14, so a
//! ctypes user meets this easily. The child's calls on the parent's handles are refused
//! (INVALID_OPERATION, saying why), destroying them does not wait for those threads, and a
//! context the child makes itself works. One test alone in its binary: forking a process
//! with other test threads running would copy whatever locks they hold.

#![cfg(target_os = "linux")]

use rt2::api::*;
use rt2::error::Rt2Status;
use std::ptr::{null, null_mut};

mod support;
use support::last_error;

#[test]
fn a_forked_child_is_refused_the_parents_context_and_makes_its_own() {
    unsafe {
        let (ctx, scene) = support::c_unit_sphere(2);
        let (mut camera, mut frame) = (null_mut(), null_mut());
        assert_eq!(rt2_camera_create(&mut camera), Rt2Status::Ok);
        assert_eq!(rt2_frame_create(16, 16, &mut frame), Rt2Status::Ok);
        assert_eq!(rt2_render(ctx, scene, camera, null(), frame), Rt2Status::Ok);

        let pid = libc::fork();
        assert!(pid >= 0, "fork failed");
        if pid == 0 {
            // The child: a hang is killed by the alarm, which the parent sees.
            libc::alarm(20);
            let mut failed = 0;
            let commit = rt2_scene_commit(scene);
            if commit != Rt2Status::InvalidOperation || !last_error().contains("fork") {
                failed |= 1;
            }
            if rt2_render(ctx, scene, camera, null(), frame) != Rt2Status::InvalidOperation {
                failed |= 2;
            }
            let (own_ctx, own_scene) = support::c_unit_sphere(2);
            if rt2_render(own_ctx, own_scene, camera, null(), frame) != Rt2Status::Ok {
                failed |= 4;
            }
            rt2_scene_destroy(own_scene);
            rt2_context_destroy(own_ctx);
            rt2_scene_destroy(scene);
            rt2_context_destroy(ctx);
            libc::_exit(failed);
        }
        if let Some(failure) =
            support::child_failure(pid, "1: commit, 2: render refused; 4: own context")
        {
            panic!("the child {failure}");
        }
        // The parent's handles are untouched by the child.
        assert_eq!(rt2_scene_commit(scene), Rt2Status::Ok, "{}", last_error());
        assert_eq!(rt2_render(ctx, scene, camera, null(), frame), Rt2Status::Ok);
        rt2_frame_destroy(frame);
        rt2_camera_destroy(camera);
        rt2_scene_destroy(scene);
        rt2_context_destroy(ctx);
    }
}
