//! A child made by glibc's `_Fork` (2.34, POSIX.1-2024: a fork that runs no `pthread_atfork`
//! handler, async-signal-safe) is a forked child like any other: its calls on the parent's
//! handles are refused, not run on worker threads that do not exist (a hang). One test alone
//! in its binary, as in `fork.rs`.

#![cfg(all(target_os = "linux", target_env = "gnu"))]

use rt2::api::*;
use rt2::error::Rt2Status;
use std::ptr::null_mut;

mod support;

#[test]
fn a_child_of_fork_without_handlers_is_refused_the_parents_scene() {
    // Looked up, not linked: a glibc before 2.34 lacks it, and the test is then moot.
    let f = unsafe { libc::dlsym(libc::RTLD_DEFAULT, c"_Fork".as_ptr()) };
    if f.is_null() {
        eprintln!("no _Fork in this libc: skipped");
        return;
    }
    let fork_without_handlers: unsafe extern "C" fn() -> libc::pid_t =
        unsafe { std::mem::transmute(f) };
    unsafe {
        let (ctx, scene) = support::c_unit_sphere(2);
        let add = |c: &[f32; 3]| rt2_scene_add_sphere(scene, c.as_ptr(), 1.0, 0, null_mut());

        let pid = fork_without_handlers();
        assert!(pid >= 0, "_Fork failed");
        if pid == 0 {
            libc::alarm(20);
            // An edit and a commit would run on the parent's workers.
            let added = add(&[3.0, 0.0, 0.0]);
            let commit = rt2_scene_commit(scene);
            rt2_scene_destroy(scene);
            rt2_context_destroy(ctx);
            let refused = Rt2Status::InvalidOperation;
            libc::_exit((added != refused) as i32 | ((commit != refused) as i32) << 1);
        }
        if let Some(failure) = support::child_failure(pid, "1: add, 2: commit not refused") {
            panic!("the child {failure}");
        }
        rt2_scene_destroy(scene);
        rt2_context_destroy(ctx);
    }
}
