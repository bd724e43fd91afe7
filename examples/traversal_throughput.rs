//! Single-thread throughput of the seven traversals on a random triangle soup, with the work
//! counters of the thesis' table 1. A quick look, not the benchmark tool:
//! `cargo run --release --example traversal_throughput [triangles] [rays]`.

use glam::Vec3;
use rt2::cpu::traverse::{intersect, Traversal, TraverseOptions};
use rt2::geometry::{PrimitiveSet, Ray, TraversalStats, Triangle};
use rt2::kdtree::{build, BuildOptions, Builder};
use std::time::Instant;

/// SplitMix64, so runs are repeatable.
struct Rng(u64);

impl Rng {
    fn unit(&mut self) -> f32 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        ((z ^ (z >> 31)) >> 40) as f32 / (1u64 << 24) as f32
    }

    fn vec(&mut self, lo: f32, hi: f32) -> Vec3 {
        Vec3::new(self.unit(), self.unit(), self.unit()) * (hi - lo) + Vec3::splat(lo)
    }
}

fn main() {
    let arg = |i: usize, default: usize| {
        std::env::args()
            .nth(i)
            .and_then(|a| a.parse().ok())
            .unwrap_or(default)
    };
    let (n_tris, n_rays) = (arg(1, 100_000), arg(2, 100_000));
    let mut rng = Rng(42);
    let mut prims = PrimitiveSet::default();
    // Triangles of about 1/100 of the cube: a few hundred along a ray through it.
    for _ in 0..n_tris {
        let a = rng.vec(0.0, 1.0);
        prims.triangles.push(Triangle::from_vertices(
            a,
            a + rng.vec(-0.01, 0.01),
            a + rng.vec(-0.01, 0.01),
        ));
    }
    // Origins around the cube, aimed at random points inside it.
    let rays: Vec<Ray> = (0..n_rays)
        .map(|_| {
            let org = rng.vec(-0.5, 1.5);
            Ray::new(
                org,
                (rng.vec(0.0, 1.0) - org).normalize(),
                0.0,
                f32::INFINITY,
            )
        })
        .collect();
    for builder in [Builder::Sah, Builder::Midpoint] {
        let start = Instant::now();
        let opts = BuildOptions {
            builder,
            ..BuildOptions::default()
        };
        let mut tree = build(&prims, &opts);
        tree.ensure_ropes();
        println!(
            "{builder:?}: {n_tris} triangles, {} nodes, depth {}, built in {:.2} s; {n_rays} rays",
            tree.nodes.len(),
            tree.stats.max_depth,
            start.elapsed().as_secs_f64()
        );
        for how in Traversal::ALL {
            let mut stats = TraversalStats::default();
            let mut hits = 0;
            let start = Instant::now();
            for ray in &rays {
                hits += intersect(
                    &tree,
                    &prims,
                    ray,
                    how,
                    &TraverseOptions::default(),
                    &mut stats,
                )
                .is_hit() as usize;
            }
            let secs = start.elapsed().as_secs_f64();
            let per_ray = |x: u64| x as f64 / n_rays as f64;
            println!(
                "  {:<22} {:7.3} Mrays/s  hits {hits}  per ray: nodes {:6.1} leaves {:5.1} prim tests {:6.1}",
                how.name(),
                n_rays as f64 / secs / 1e6,
                per_ray(stats.nodes_visited),
                per_ray(stats.leaves_visited),
                per_ray(stats.prim_tests)
            );
        }
    }
}
