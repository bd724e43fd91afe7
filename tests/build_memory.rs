//! A build's memory against the tree it makes. The builders write the node arrays as they
//! recurse; they used to return a tree of boxed nodes, flattened afterwards, which took about
//! 110 bytes per node where the flat arrays take 8 (a midpoint tree of 19M nodes peaked at
//! 2.36 GB for a 226 MB tree, and glibc kept most of it resident after the build). Alone in its
//! test binary: the peak is the process's (Linux `VmHWM`).

use glam::Vec3;
use rt2::geometry::{PrimitiveSet, Triangle};
use rt2::kdtree::{build, BuildOptions, Builder};

mod support;

#[test]
#[cfg(target_os = "linux")]
fn a_deep_midpoint_build_peaks_near_the_size_of_its_tree() {
    // A flat grid of small triangles, one per cell: at depth 64 with one primitive per leaf the
    // midpoint builder makes over 5 nodes per triangle (empty leaves around each one), so the
    // node arrays weigh more than the input. Measured: the boxed node tree peaked at 95.8 MiB
    // for this 8.1 MiB tree (5.5 MiB of triangles), the flat arrays at 31.4 MiB.
    let side = 400;
    let mut set = PrimitiveSet::default();
    for i in 0..side {
        for j in 0..side {
            let corner = Vec3::new(i as f32, j as f32, 0.0);
            set.triangles.push(Triangle::from_vertices(
                corner,
                corner + Vec3::new(0.5, 0.0, 0.0),
                corner + Vec3::new(0.0, 0.5, 0.0),
            ));
        }
    }
    let opts = BuildOptions {
        builder: Builder::Midpoint,
        max_depth: Some(64),
        leaf_size: 1,
        ..BuildOptions::default()
    };
    // Two threads whatever the machine: glibc gives every thread its own arena, which adds to
    // the peak on many cores (45-51 MiB here with 16 threads, against 24-32 MiB with 2). Two
    // still build the top of the tree in parallel parts, grafted together.
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(2)
        .build()
        .expect("a thread pool");
    let before = support::status_mib("VmRSS:");
    let tree = pool
        .install(|| build(&set, &opts))
        .expect("memory for the tree");
    let peak = support::status_mib("VmHWM:") - before;
    let tree_mib = (tree.nodes.len() * std::mem::size_of_val(&tree.nodes[0])
        + tree.prim_indices.len() * 4) as f64
        / (1024.0 * 1024.0);
    let input_mib =
        (set.triangles.len() * std::mem::size_of::<Triangle>()) as f64 / (1024.0 * 1024.0);
    println!(
        "{} nodes, {} references: tree {tree_mib:.1} MiB, input {input_mib:.1} MiB, build peak {peak:.1} MiB",
        tree.nodes.len(),
        tree.prim_indices.len()
    );
    assert!(tree.nodes.len() > 5 * set.triangles.len(), "a deep tree");
    assert!(
        peak < 3.0 * tree_mib + 4.0 * input_mib,
        "build peak {peak:.1} MiB for a tree of {tree_mib:.1} MiB (input {input_mib:.1} MiB)"
    );
}
