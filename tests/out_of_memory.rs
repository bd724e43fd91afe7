//! A commit (or a frame's mask) that cannot have the memory it needs returns
//! `RT2_STATUS_OUT_OF_MEMORY` instead of aborting the host program (Rust's default on a failed
//! allocation), and the call works once memory is there.
//!
//! The memory is limited as a cluster or `ulimit -v` limits it: an address-space limit
//! (`RLIMIT_AS`) on this process. That is why this is one test alone in its test binary: the
//! limit holds for every thread of the process while it is set.

#![cfg(target_os = "linux")]

use rt2::api::*;
use rt2::error::Rt2Status;
use std::io::Write;
use std::ptr::{null, null_mut};

mod support;
use support::last_error;

/// The process's address space now (`VmSize`), in bytes.
fn address_space() -> u64 {
    (support::status_mib("VmSize:") * 1024.0 * 1024.0) as u64
}

/// Sets the soft address-space limit (`None`: back to the hard limit).
fn limit_address_space(bytes: Option<u64>) {
    let mut lim = libc::rlimit {
        rlim_cur: 0,
        rlim_max: 0,
    };
    // SAFETY: plain system calls on a valid struct.
    unsafe {
        assert_eq!(libc::getrlimit(libc::RLIMIT_AS, &mut lim), 0);
        lim.rlim_cur = bytes.map_or(lim.rlim_max, |b| b.min(lim.rlim_max));
        assert_eq!(libc::setrlimit(libc::RLIMIT_AS, &lim), 0);
    }
}

/// A square grid of `k` × `k` cells, two triangles each, in the plane z = 1 over [0, 1]².
fn grid(k: u32) -> (Vec<f32>, Vec<u32>) {
    let mut positions = Vec::new();
    for j in 0..=k {
        for i in 0..=k {
            positions.extend([i as f32 / k as f32, j as f32 / k as f32, 1.0]);
        }
    }
    let mut indices = Vec::new();
    for j in 0..k {
        for i in 0..k {
            let v = j * (k + 1) + i;
            indices.extend([v, v + 1, v + k + 1, v + 1, v + k + 2, v + k + 1]);
        }
    }
    (positions, indices)
}

/// Where a ray straight down the z axis at (x, y) meets the scene, as `rt2_intersect` says.
unsafe fn hit_at(ctx: *const rt2_context, scene: *const rt2_scene, x: f32, y: f32) -> rt2_hit {
    let ray = rt2_ray {
        org: [x, y, 3.0],
        tmin: 0.0,
        dir: [0.0, 0.0, -1.0],
        tmax: f32::INFINITY,
    };
    let mut hit = rt2_hit {
        t: 0.0,
        u: 0.0,
        v: 0.0,
        object: 0,
        prim: 0,
    };
    let status = rt2_intersect(ctx, scene, &ray, 1, &mut hit, null(), null_mut());
    assert_eq!(status, Rt2Status::Ok, "{}", last_error());
    hit
}

#[test]
fn calls_without_memory_fail_with_out_of_memory_and_can_be_retried() {
    // 2 million triangles: the commit places them (36 bytes each), builds the tree (its event
    // lists alone take 48 bytes per triangle) and renumbers them, a few hundred MB in all,
    // more than the slack in what the allocator has reserved already (address space counts
    // reservations, and an allocation inside one adds nothing to it).
    let (positions, indices) = grid(1000);
    let triangles = indices.len() / 3;
    unsafe {
        let mut desc = rt2_context_desc_default();
        desc.backend = 1; // CPU: the GPU's driver is not what is measured here
        desc.threads = 2;
        let mut ctx = null_mut();
        assert_eq!(rt2_context_create(&desc, &mut ctx), Rt2Status::Ok);
        // Limits above the address space the process has before the commit: at the smallest
        // the placed triangles alone do not fit; at the largest the whole commit does; in
        // between it runs out at different steps (placing, the build's events, its node
        // arrays, renumbering). At each one the commit either succeeds or says OUT_OF_MEMORY;
        // an abort ends the test.
        let mut failed = 0;
        for extra_mib in [4u64, 24, 48, 72, 96, 120, 144, 168, 192, 256, 384, 4096] {
            let mut scene = null_mut();
            assert_eq!(rt2_scene_create(ctx, &mut scene), Rt2Status::Ok);
            let mut object = 0;
            let status = rt2_scene_add_mesh(
                scene,
                positions.as_ptr(),
                positions.len() / 3,
                indices.as_ptr(),
                triangles,
                0,
                &mut object,
            );
            assert_eq!(status, Rt2Status::Ok, "{}", last_error());

            // Said before the commit, straight to stderr: an abort loses captured output.
            writeln!(std::io::stderr(), "address space + {extra_mib} MiB").unwrap();
            // Free memory the allocator kept goes back first, so that each limit counts from
            // about the same start.
            libc::malloc_trim(0);
            limit_address_space(Some(address_space() + (extra_mib << 20)));
            let status = rt2_scene_commit(scene);
            limit_address_space(None);
            let message = last_error();
            writeln!(std::io::stderr(), "  {status:?}").unwrap();

            match status {
                Rt2Status::Ok => {}
                Rt2Status::OutOfMemory => {
                    failed += 1;
                    assert!(message.contains("out of memory"), "{message}");
                    // Nothing was committed: the scene refuses queries until a commit works.
                    let ray = rt2_ray {
                        org: [0.5, 0.5, 3.0],
                        tmin: 0.0,
                        dir: [0.0, 0.0, -1.0],
                        tmax: f32::INFINITY,
                    };
                    let mut hit = std::mem::zeroed();
                    let refused = rt2_intersect(ctx, scene, &ray, 1, &mut hit, null(), null_mut());
                    assert_eq!(refused, Rt2Status::InvalidOperation, "{}", last_error());
                    // With the memory back, the same scene commits (once: each commit of this
                    // scene takes a second or two).
                    if failed == 1 {
                        assert_eq!(rt2_scene_commit(scene), Rt2Status::Ok, "{}", last_error());
                    }
                }
                other => panic!("+{extra_mib} MiB: {other:?}: {message}"),
            }
            if status == Rt2Status::Ok || failed == 1 {
                // The committed grid answers: a ray down at (0.3, 0.7) meets the plane z = 1.
                let hit = hit_at(ctx, scene, 0.3, 0.7);
                assert_eq!(hit.object, object, "+{extra_mib} MiB");
                assert!(
                    (hit.t - 2.0).abs() < 1e-6,
                    "+{extra_mib} MiB: t = {}",
                    hit.t
                );
            }
            if extra_mib == 4 {
                assert_eq!(
                    status,
                    Rt2Status::OutOfMemory,
                    "4 MiB cannot hold the commit"
                );
            }
            if extra_mib == 4096 {
                assert_eq!(status, Rt2Status::Ok, "4 GiB holds the commit: {message}");
            }
            rt2_scene_destroy(scene);
        }
        assert!(failed >= 3, "only {failed} limits were too small");
        rt2_context_destroy(ctx);

        // A frame's mask is copied: a byte per pixel, 64 MiB for an 8192² frame.
        let mut frame = null_mut();
        assert_eq!(rt2_frame_create(8192, 8192, &mut frame), Rt2Status::Ok);
        let mask = vec![1u8; 8192 * 8192];
        libc::malloc_trim(0);
        limit_address_space(Some(address_space() + (16 << 20)));
        let status = rt2_frame_set_mask(frame, mask.as_ptr());
        limit_address_space(None);
        assert_eq!(status, Rt2Status::OutOfMemory, "{}", last_error());
        assert!(last_error().contains("mask"), "{}", last_error());
        assert_eq!(rt2_frame_set_mask(frame, mask.as_ptr()), Rt2Status::Ok);
        rt2_frame_destroy(frame);
    }
    models_without_memory_fail_with_out_of_memory();
    streamed_object_ids_without_memory_fail_with_out_of_memory();
    contexts_without_memory_for_their_threads_fail_with_out_of_memory();
}

/// Spheres added and removed one after another (`rt2_scene_remove`, ids never reused) under a
/// limit of 16 MiB more: the scene's slot per id given (8 bytes) outgrows it within about two
/// million ids, and the add that cannot have its slot says OUT_OF_MEMORY, gives no id and
/// leaves the scene as it was (its doubling aborted the process before). Each Vec doubling
/// is a fresh mapping once past the allocator's mmap threshold, so the limit is met.
#[allow(clippy::explicit_write)]
fn streamed_object_ids_without_memory_fail_with_out_of_memory() {
    unsafe {
        let (ctx, scene) = support::c_cpu_scene(0);
        let at = [0.5f32, 0.5, 1.0];
        writeln!(std::io::stderr(), "streaming spheres").unwrap();
        libc::malloc_trim(0);
        limit_address_space(Some(address_space() + (16 << 20)));
        let (mut status, mut given, mut id) = (Rt2Status::Ok, 0u32, RT2_INVALID_ID);
        while given < 8 << 20 {
            status = rt2_scene_add_sphere(scene, at.as_ptr(), 0.25, 0, &mut id);
            if status != Rt2Status::Ok {
                break;
            }
            assert_eq!(id, given, "ids are given in order");
            assert_eq!(rt2_scene_remove(scene, id), Rt2Status::Ok);
            given += 1;
        }
        limit_address_space(None);
        assert_eq!(
            status,
            Rt2Status::OutOfMemory,
            "after {given} ids: {}",
            last_error()
        );
        assert!(last_error().contains("object ids"), "{}", last_error());
        assert_eq!(id, given - 1, "no id written on failure");
        // The scene is as it was: the next add gets the next id, and the sphere is hit.
        let status = rt2_scene_add_sphere(scene, at.as_ptr(), 0.25, 0, &mut id);
        assert_eq!(status, Rt2Status::Ok, "{}", last_error());
        assert_eq!(id, given);
        assert_eq!(rt2_scene_commit(scene), Rt2Status::Ok, "{}", last_error());
        let hit = hit_at(ctx, scene, 0.5, 0.5);
        assert_eq!(hit.object, given);
        assert!((hit.t - 1.75).abs() < 1e-6, "t = {}", hit.t);
        rt2_scene_destroy(scene);
        rt2_context_destroy(ctx);
    }
}

/// The threads of this process now (`Threads` in `/proc/self/status`).
fn threads() -> usize {
    let status = std::fs::read_to_string("/proc/self/status").expect("Linux /proc");
    let field = status.lines().find_map(|l| l.strip_prefix("Threads:"));
    field
        .and_then(|n| n.trim().parse().ok())
        .expect("Threads in /proc/self/status")
}

/// The threads of this process once they number `want`, or after a second what they number:
/// a joined thread may be counted a moment longer.
fn threads_settled_at(want: usize) -> usize {
    let start = std::time::Instant::now();
    let mut n = threads();
    while n != want && start.elapsed().as_secs() < 1 {
        std::thread::sleep(std::time::Duration::from_millis(1));
        n = threads();
    }
    n
}

/// A context of 64 workers under a limit of 16 MiB more: their stacks (2 MiB each) do not
/// fit, so a worker's start fails part way through the pool. The context says OUT_OF_MEMORY,
/// writes no handle and leaves no thread behind (those already started are stopped and
/// joined); with the memory back, the same request works.
#[allow(clippy::explicit_write)]
fn contexts_without_memory_for_their_threads_fail_with_out_of_memory() {
    writeln!(std::io::stderr(), "a context of 64 workers").unwrap();
    let before = threads();
    let mut desc = rt2_context_desc_default();
    desc.backend = 1;
    desc.threads = 64;
    let mut ctx = null_mut();
    unsafe {
        libc::malloc_trim(0);
        limit_address_space(Some(address_space() + (16 << 20)));
        let status = rt2_context_create(&desc, &mut ctx);
        limit_address_space(None);
        assert_eq!(status, Rt2Status::OutOfMemory, "{}", last_error());
        assert!(
            last_error().contains("64 worker threads"),
            "{}",
            last_error()
        );
        assert!(ctx.is_null(), "no handle on failure");
        assert_eq!(threads_settled_at(before), before, "threads left behind");
        assert_eq!(rt2_context_create(&desc, &mut ctx), Rt2Status::Ok);
        assert_eq!(threads_settled_at(before + 64), before + 64);
        rt2_context_destroy(ctx);
    }
    assert_eq!(
        threads_settled_at(before),
        before,
        "threads left behind by a destroyed context"
    );
}

/// A model file of one polygon with ten million corners: 20 MB of file, 120 MB of fan
/// triangles. Each format says OUT_OF_MEMORY under a limit that holds the file but not the
/// triangles, and leaves the scene without the object.
// Straight to stderr, as above: `eprintln!` is captured by the harness, and an abort loses it.
#[allow(clippy::explicit_write)]
fn models_without_memory_fail_with_out_of_memory() {
    const CORNERS: usize = 10_000_000;
    let header = |format: &str, count: &str| {
        format!(
            "ply\nformat {format} 1.0\nelement vertex 3\nproperty float x\nproperty float y\n\
             property float z\nelement face 1\nproperty list {count} uchar vertex_indices\n\
             end_header\n"
        )
        .into_bytes()
    };
    let mut binary = header("binary_little_endian", "uint");
    for c in [0f32, 0., 0., 1., 0., 0., 0., 1., 0.] {
        binary.extend(c.to_le_bytes());
    }
    binary.extend((CORNERS as u32).to_le_bytes());
    binary.extend([0u8, 1]);
    binary.resize(binary.len() + CORNERS - 2, 2);
    let mut ascii = header("ascii", "uint");
    ascii.extend(format!("0 0 0\n1 0 0\n0 1 0\n{CORNERS} 0 1").bytes());
    ascii.extend(" 2".repeat(CORNERS - 2).bytes());
    ascii.push(b'\n');
    let mut obj = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2".to_vec();
    obj.extend(" 3".repeat(CORNERS - 2).bytes());
    obj.push(b'\n');

    let dir = std::env::temp_dir().join(format!("rt2-oom-models-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    unsafe {
        let (ctx, scene) = support::c_cpu_scene(0);
        for (file, bytes) in [
            ("binary.ply", binary),
            ("ascii.ply", ascii),
            ("big.obj", obj),
        ] {
            let path = dir.join(file);
            std::fs::write(&path, &bytes).unwrap();
            let c_path = std::ffi::CString::new(path.to_str().unwrap()).unwrap();
            writeln!(std::io::stderr(), "loading {file}").unwrap();
            libc::malloc_trim(0);
            limit_address_space(Some(address_space() + bytes.len() as u64 + (32 << 20)));
            let mut object = 7;
            let status = rt2_scene_load_file(scene, c_path.as_ptr(), 0, &mut object);
            limit_address_space(None);
            std::fs::remove_file(&path).unwrap();
            assert_eq!(status, Rt2Status::OutOfMemory, "{file}: {}", last_error());
            assert!(last_error().contains(file), "{file}: {}", last_error());
            assert_eq!(object, 7, "{file}: no object id on failure");
        }
        // None of the three was added: the scene commits empty, and a ray misses.
        assert_eq!(rt2_scene_commit(scene), Rt2Status::Ok, "{}", last_error());
        assert_eq!(hit_at(ctx, scene, 0.1, 0.1).object, RT2_INVALID_ID);
        rt2_scene_destroy(scene);
        rt2_context_destroy(ctx);
    }
    std::fs::remove_dir(&dir).unwrap();
}
