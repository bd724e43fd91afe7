//! Batch ray queries on the CPU: rays split into chunks that the context's pool traces, with
//! the statistics of each chunk summed at the end (no shared counters in the hot loop).

use super::traverse::{self, Traversal, TraverseOptions};
use crate::geometry::{Hit, Ray, TraversalStats};
use crate::scene::Committed;
use rayon::prelude::*;

/// Rays per parallel task: the granularity Embree's peer harness uses too.
const CHUNK: usize = 4096;

/// Runs `query` on every ray, writing `out[i]` for `rays[i]`, and sums the statistics.
fn batch<T: Send>(
    rays: &[Ray],
    out: &mut [T],
    query: impl Fn(&Ray, &mut TraversalStats) -> T + Sync,
) -> TraversalStats {
    rays.par_chunks(CHUNK)
        .zip(out.par_chunks_mut(CHUNK))
        .map(|(r, o)| {
            let mut stats = TraversalStats::default();
            for (ray, slot) in r.iter().zip(o) {
                *slot = query(ray, &mut stats);
            }
            stats
        })
        .reduce(TraversalStats::default, |mut a, b| {
            a.add(&b);
            a
        })
}

/// Closest hits of `rays` into `hits` (same length).
pub fn intersect(
    scene: &Committed,
    rays: &[Ray],
    hits: &mut [Hit],
    how: Traversal,
    opts: &TraverseOptions,
) -> TraversalStats {
    batch(rays, hits, |ray, stats| {
        traverse::intersect(&scene.tree, &scene.prims, ray, how, opts, stats)
    })
}

/// Any-hit queries: `occluded[i]` is true when something lies in ray i's `[tmin, tmax)`.
pub fn occluded(
    scene: &Committed,
    rays: &[Ray],
    occluded: &mut [bool],
    how: Traversal,
    opts: &TraverseOptions,
) -> TraversalStats {
    batch(rays, occluded, |ray, stats| {
        traverse::occluded(&scene.tree, &scene.prims, ray, how, opts, stats)
    })
}
