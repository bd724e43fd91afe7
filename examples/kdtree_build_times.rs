//! Build times of the two builders on a random triangle soup (release build):
//! `cargo run --release --example kdtree_build_times -- [triangles]`.

use glam::Vec3;
use rt2::geometry::{PrimitiveSet, Triangle};
use rt2::kdtree::{build, BuildOptions, Builder, Layout};

fn main() {
    let n: usize = std::env::args()
        .nth(1)
        .and_then(|a| a.parse().ok())
        .unwrap_or(100_000);
    // SplitMix64, so that every run builds the same soup.
    let mut state = 1u64;
    let mut f = move || {
        state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 40) as f32 / (1u64 << 24) as f32
    };
    let mut set = PrimitiveSet::default();
    for _ in 0..n {
        let c = Vec3::new(f(), f(), f());
        let mut v = || c + 0.01 * (Vec3::new(f(), f(), f()) - 0.5);
        set.triangles.push(Triangle::from_vertices(v(), v(), v()));
    }
    println!("{n} triangles, {} threads", rayon::current_num_threads());
    for builder in [Builder::Sah, Builder::Midpoint] {
        for layout in [Layout::DepthFirst, Layout::VanEmdeBoas] {
            let opts = BuildOptions {
                builder,
                layout,
                ropes: true,
                ..BuildOptions::default()
            };
            let t = build(&set, &opts);
            let s = t.stats;
            println!(
                "{builder:?}/{layout:?}: {:.1} ms, {} nodes, {} leaves ({} empty), depth {} (avg {:.1}), {:.2} prims/leaf, SAH cost {:.1}",
                s.build_ms, s.node_count, s.leaf_count, s.empty_leaf_count, s.max_depth,
                s.avg_leaf_depth, s.avg_prims_per_leaf, s.sah_cost
            );
        }
    }
}
