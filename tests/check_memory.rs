//! Memory the scene's world-space check allocates: adding or moving a mesh validates every
//! triangle, and must do so without a copy of the mesh (a 10M-triangle mesh once needed
//! ~935 MB extra just to be checked).
//!
//! Its own test binary, with this one test, because it installs a counting global allocator:
//! the count is of every thread (a copy made on worker threads counts too), so nothing else
//! may run beside it.

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicIsize, Ordering::SeqCst};

use glam::{Affine3A, Vec3};
use rt2::scene::{Scene, Shape};

struct Counting;

/// Bytes the process holds through the global allocator (allocated minus freed).
static LIVE: AtomicIsize = AtomicIsize::new(0);
/// The most `LIVE` has been since the last [`peak_during`] began.
static PEAK: AtomicIsize = AtomicIsize::new(0);

fn count(delta: isize) {
    let live = LIVE.fetch_add(delta, SeqCst) + delta;
    PEAK.fetch_max(live, SeqCst);
}

// SAFETY: forwards every call to the system allocator unchanged; only counts sizes.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        count(layout.size() as isize);
        System.alloc(layout)
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        count(layout.size() as isize);
        System.alloc_zeroed(layout)
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        count(new_size as isize - layout.size() as isize);
        System.realloc(ptr, layout, new_size)
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        count(-(layout.size() as isize));
        System.dealloc(ptr, layout)
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

/// The most memory `f` holds at once (on any thread), beyond what was held before.
fn peak_during(f: impl FnOnce()) -> isize {
    let before = LIVE.load(SeqCst);
    PEAK.store(before, SeqCst);
    f();
    PEAK.load(SeqCst) - before
}

/// A strip of `n` triangles over `n + 2` vertices.
fn strip(n: u32) -> Shape {
    Shape::Mesh {
        positions: (0..n + 2)
            .map(|i| Vec3::new(i as f32, (i % 2) as f32, 0.0))
            .collect(),
        triangles: (0..n).map(|i| [i, i + 1, i + 2]).collect(),
    }
}

#[test]
fn checking_a_mesh_in_world_space_allocates_no_copy_of_it() {
    const TRIANGLES: u32 = 200_000;
    // A copy would be at least the placed triangles: 36 bytes each, 7.2 MB here.
    const LIMIT: isize = 64 * 1024;
    let mut scene = Scene::new();
    let shape = strip(TRIANGLES);
    let mut id = 0;
    let added = peak_during(|| id = scene.add_object(shape, 0).unwrap());
    assert!(
        added < LIMIT,
        "add_object held {added} bytes at its peak for {TRIANGLES} triangles"
    );
    let t = Affine3A::from_translation(Vec3::new(1.0, 2.0, 3.0));
    let moved = peak_during(|| scene.set_transform(id, t).unwrap());
    assert!(
        moved < LIMIT,
        "set_transform held {moved} bytes at its peak for {TRIANGLES} triangles"
    );
    // The check still refuses a mesh that overflows f32 once moved (x beyond 340 times 1e36;
    // the determinant stays finite, so the world-space check is what refuses it), and the
    // object keeps its transform.
    let far = Affine3A::from_scale(Vec3::new(1e36, 1e-10, 1e-10));
    let err = scene.set_transform(id, far).unwrap_err();
    assert!(
        err.message.contains("does not fit in f32"),
        "{}",
        err.message
    );
    assert_eq!(
        scene.objects()[id as usize].as_ref().map(|o| o.transform),
        Some(t)
    );
}
