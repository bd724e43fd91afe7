//! Memory `rt2_scene_remove` gives back: a program that streams a mesh in and out of a scene
//! (add, commit, remove, commit) must not grow by the mesh each time, as it did when objects
//! could only be disabled.
//!
//! Its own test binary, holding this one test, because it installs a counting global
//! allocator that counts the whole process (not per thread, as `check_memory.rs` does: commits
//! run on the context's worker threads, which allocate what the calling thread frees).
use std::alloc::{GlobalAlloc, Layout, System};
use std::ffi::CStr;
use std::ptr::null_mut;
use std::sync::atomic::{AtomicIsize, Ordering};

use rt2::api::*;
use rt2::error::Rt2Status;

mod support;

struct Counting;

/// Bytes the process holds (allocated minus freed, through the Rust allocator).
static LIVE: AtomicIsize = AtomicIsize::new(0);

// SAFETY: forwards every call to the system allocator unchanged; only counts sizes.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        LIVE.fetch_add(layout.size() as isize, Ordering::Relaxed);
        System.alloc(layout)
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        LIVE.fetch_add(layout.size() as isize, Ordering::Relaxed);
        System.alloc_zeroed(layout)
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        LIVE.fetch_add(
            new_size as isize - layout.size() as isize,
            Ordering::Relaxed,
        );
        System.realloc(ptr, layout, new_size)
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        LIVE.fetch_sub(layout.size() as isize, Ordering::Relaxed);
        System.dealloc(ptr, layout)
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

fn live() -> isize {
    LIVE.load(Ordering::Relaxed)
}

fn ok(status: Rt2Status, what: &str) {
    let msg = unsafe { CStr::from_ptr(rt2_last_error_message()) };
    assert_eq!(status, Rt2Status::Ok, "{what}: {msg:?}");
}

/// The bytes of the committed scene's arrays that hold primitives (`rt2_scene_stats`).
fn placed_bytes(scene: *const rt2_scene) -> isize {
    let mut st = rt2_scene_statistics {
        struct_size: std::mem::size_of::<rt2_scene_statistics>() as u32,
        ..Default::default()
    };
    ok(unsafe { rt2_scene_stats(scene, &mut st) }, "stats");
    (st.bytes_nodes + st.bytes_leaf_lists + st.bytes_leaf_boxes + st.bytes_primitives) as isize
}

/// The hit of `ray` ignoring primitive 0 of `object`: the exclusion builds the scene's
/// primitive lookup, which holds an entry per object id.
unsafe fn trace_excluding(
    ctx: *const rt2_context,
    scene: *const rt2_scene,
    ray: &rt2_ray,
    object: u32,
) -> rt2_hit {
    let mut opt = rt2_query_options_default();
    let exclude = rt2_hit {
        t: 0.0,
        u: 0.0,
        v: 0.0,
        object,
        prim: 0,
    };
    opt.exclude = &exclude;
    let mut hit = exclude;
    ok(
        rt2_intersect(ctx, scene, ray, 1, &mut hit, &opt, null_mut()),
        "intersect",
    );
    hit
}

/// Eight times a 45,000-triangle mesh added, committed, named by an exclusion (which builds
/// the primitive lookup), removed and committed again beside a sphere: the removal gives back
/// the mesh's own arrays at the call and the placed arrays (as `rt2_scene_stats` counts them)
/// at the commit, and after the eight rounds the process holds what it held after the first,
/// up to the slots the removed ids keep (about 25 bytes each) and the growth of the arrays
/// that hold them. Kept, each mesh would add its 0.8 MB of vertices and indices and its
/// placed triangles. Then 10,000 spheres streamed in and out the same way keep at most 64
/// bytes per removed id, doubling arrays included (an unboxed object's slot alone was 128).
#[test]
fn streaming_a_mesh_in_and_out_gives_its_memory_back() {
    const N: u32 = 150;
    let mut positions = Vec::new();
    for j in 0..=N {
        for i in 0..=N {
            positions.extend([
                i as f32 / N as f32,
                j as f32 / N as f32,
                (i * j % 7) as f32 * 1e-3,
            ]);
        }
    }
    let mut indices = Vec::new();
    for j in 0..N {
        for i in 0..N {
            let v = j * (N + 1) + i;
            indices.extend([v, v + 1, v + N + 1, v + 1, v + N + 2, v + N + 1]);
        }
    }
    // The mesh as the scene keeps it: 12 bytes per vertex and per triangle.
    let shape_bytes = 4 * (positions.len() + indices.len()) as isize;
    let mut desc = rt2_context_desc_default();
    desc.backend = Rt2Backend::Cpu as u32;
    let (mut ctx, mut scene) = (null_mut(), null_mut());
    let ray = [rt2_ray {
        org: [0.3, 0.3, 2.0],
        tmin: 0.0,
        dir: [0.0, 0.0, -1.0],
        tmax: f32::INFINITY,
    }];
    unsafe {
        ok(rt2_context_create(&desc, &mut ctx), "context");
        ok(rt2_scene_create(ctx, &mut scene), "scene");
        let center = [0.5f32, 0.5, -1.0];
        ok(
            rt2_scene_add_sphere(scene, center.as_ptr(), 0.5, 0, null_mut()),
            "sphere",
        );
        ok(rt2_scene_commit(scene), "commit");
        let sphere_only = placed_bytes(scene);
        let mut after_first = 0;
        for round in 0..8 {
            let id = support::add_mesh(scene, &positions, &indices);
            assert_eq!(id, round + 1, "ids are not reused");
            ok(rt2_scene_commit(scene), "commit");
            let hit = trace_excluding(ctx, scene, &ray[0], id);
            assert_eq!(hit.object, id, "the ray misses the mesh");
            let placed = placed_bytes(scene) - sphere_only;
            let before = live();
            ok(rt2_scene_remove(scene, id), "remove");
            let at_call = before - live();
            assert!(
                at_call >= shape_bytes,
                "round {round}: the removal freed {at_call} bytes, the mesh holds {shape_bytes}"
            );
            let before = live();
            ok(rt2_scene_commit(scene), "commit");
            let at_commit = before - live();
            assert!(
                at_commit >= placed,
                "round {round}: the commit freed {at_commit} bytes, the mesh was placed in {placed}"
            );
            assert_eq!(placed_bytes(scene), sphere_only, "round {round}");
            if round == 0 {
                after_first = live();
            }
        }
        let growth = live() - after_first;
        eprintln!("seven rounds grew the process by {growth} bytes");
        assert!(
            growth < 8 * 1024,
            "seven rounds grew the process by {growth} bytes (one mesh holds {shape_bytes})"
        );
        let before = live();
        const SPHERES: isize = 10_000;
        for _ in 0..SPHERES {
            let (mut id, at) = (0, [0.5f32, 0.5, 1.0]);
            ok(
                rt2_scene_add_sphere(scene, at.as_ptr(), 0.1, 0, &mut id),
                "sphere",
            );
            ok(rt2_scene_commit(scene), "commit");
            ok(rt2_scene_remove(scene, id), "remove");
        }
        ok(rt2_scene_commit(scene), "commit");
        trace_excluding(ctx, scene, &ray[0], 0);
        let per_id = (live() - before) / SPHERES;
        eprintln!("{SPHERES} spheres streamed through: {per_id} bytes per removed id");
        assert!(per_id <= 64, "{per_id} bytes kept per removed id");
        rt2_scene_destroy(scene);
        rt2_context_destroy(ctx);
    }
}
