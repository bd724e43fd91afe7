//! A fork while another thread is inside RT2: the child's calls must not wait for the copy of
//! that thread, which does not exist in the child. Four things did:
//! - the first call sets up what keeps the process id (`process::id`); a `OnceLock` held there
//!   across the fork hung every child that then made a context, and a loop of forks starves
//!   that call (each fork holds glibc's atfork lock, which `pthread_atfork` takes), so that
//!   hundreds of children were forked inside it;
//! - std's thread start and exit take a process-wide lock, which the workers of a context
//!   took while it started or stopped them (`workers.rs`);
//! - the first worker to run made crossbeam-epoch's default collector inside a `OnceLock`
//!   (`workers.rs` now makes it when the library is loaded);
//! - destroying a copy of the parent's context stopped its rayon pool, which locks each
//!   worker's sleep state: held for good if the parent's worker was falling asleep or being
//!   woken at the fork (`Context::drop` now leaves the copy's pool alone).
//!
//! Each test process makes no RT2 call itself: every round runs in a fresh child.

#![cfg(target_os = "linux")]

use rt2::api::*;
use rt2::error::Rt2Status;
use std::ptr::null;
use std::ptr::null_mut;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

mod support;

unsafe fn cpu_context() -> (Rt2Status, *mut rt2_context) {
    let mut desc = rt2_context_desc_default();
    desc.backend = 1;
    desc.threads = 1;
    let mut ctx = null_mut();
    (rt2_context_create(&desc, &mut ctx), ctx)
}

/// Forks children while `busy` runs on another thread, at most `max_children`, each of which
/// runs `child` and exits with its status (a hang is killed by an alarm); then the failures
/// `busy` returns and the children that hung or failed.
fn fork_while(
    busy: impl FnOnce() -> usize + Send + 'static,
    max_children: usize,
    child: impl Fn() -> i32,
) -> usize {
    let done = Arc::new(AtomicBool::new(false));
    let busy = std::thread::spawn({
        let done = done.clone();
        move || {
            let bad = busy();
            done.store(true, Ordering::SeqCst);
            bad
        }
    });
    let mut children = Vec::new();
    while !done.load(Ordering::SeqCst) && children.len() < max_children {
        let pid = unsafe { libc::fork() };
        assert!(pid >= 0, "fork failed");
        if pid == 0 {
            unsafe {
                libc::alarm(10);
                libc::_exit(child());
            }
        }
        children.push(pid);
    }
    let mut bad = busy.join().unwrap();
    for &pid in &children {
        bad += support::child_failure(pid, "").is_some() as usize;
    }
    bad
}

/// A thread makes and destroys `contexts` contexts (each starts and stops a worker thread);
/// each child makes its own.
fn making_contexts(contexts: usize, max_children: usize) -> usize {
    let make = |n: usize| unsafe {
        let mut bad = 0;
        for _ in 0..n {
            let (status, ctx) = cpu_context();
            bad += (status != Rt2Status::Ok) as usize;
            rt2_context_destroy(ctx);
        }
        bad
    };
    fork_while(move || make(contexts), max_children, || make(1) as i32)
}

/// A thread renders a scene `renders` times (each wakes the context's two workers, which fall
/// asleep again); each child destroys its copies of the scene and context.
fn rendering(renders: usize, max_children: usize) -> usize {
    unsafe {
        let (ctx, scene) = support::c_unit_sphere(2);
        let (mut camera, mut frame) = (null_mut(), null_mut());
        support::ok(rt2_camera_create(&mut camera));
        support::ok(rt2_frame_create(8, 8, &mut frame));
        let handles = [
            ctx as usize,
            scene as usize,
            camera as usize,
            frame as usize,
        ];
        let render = move || {
            let [ctx, scene, camera, frame] = handles;
            (0..renders)
                .filter(|_| {
                    let (ctx, scene) = (ctx as *mut rt2_context, scene as *mut rt2_scene);
                    let (camera, frame) = (camera as *mut rt2_camera, frame as *mut rt2_frame);
                    rt2_render(ctx, scene, camera, null(), frame) != Rt2Status::Ok
                })
                .count()
        };
        let destroy = || {
            rt2_scene_destroy(scene);
            rt2_context_destroy(ctx);
            0
        };
        let bad = fork_while(render, max_children, destroy);
        rt2_frame_destroy(frame);
        rt2_camera_destroy(camera);
        destroy();
        bad
    }
}

/// `rounds` rounds, each in a fresh child of the test (which itself never calls RT2): the
/// round's failures are its exit status.
fn rounds(rounds: usize, round: impl Fn() -> usize) {
    for r in 0..rounds {
        let pid = unsafe { libc::fork() };
        assert!(pid >= 0, "fork failed");
        if pid == 0 {
            // Forked beside the harness's other test threads: a lock one of them held would
            // hang the round, which its alarm then ends.
            unsafe { libc::alarm(120) };
            let bad = std::panic::catch_unwind(std::panic::AssertUnwindSafe(&round));
            unsafe { libc::_exit(bad.unwrap_or(255).min(255) as i32) };
        }
        if let Some(failure) = support::child_failure(pid, "children that hung or failed") {
            panic!("round {r}: the round {failure}");
        }
    }
}

/// Children forked while the first context is made: with the `OnceLock`, two rounds in five
/// had hung children, so eight rounds miss it about once in sixty.
#[test]
fn children_forked_during_the_first_context_make_their_own() {
    rounds(8, || making_contexts(1, 2000));
}

/// Children forked while contexts start and stop their workers: with std's threads as workers,
/// a quarter of the rounds had a hung child, so sixteen rounds miss it about once in 200.
#[test]
fn children_forked_while_workers_start_and_stop_make_their_own() {
    rounds(16, || making_contexts(3000, 300));
}

/// Children forked while the parent renders destroy their copies of its handles: with the
/// copy's pool stopped, four runs in ten of sixteen rounds had a hung child (one round in
/// thirty), so forty rounds catch it about seven times in ten.
#[test]
fn children_forked_while_the_parent_renders_destroy_its_handles() {
    rounds(40, || rendering(3000, 300));
}
