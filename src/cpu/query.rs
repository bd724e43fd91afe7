//! Batch ray queries on the CPU: rays split into chunks that the context's pool traces, with
//! the statistics of each chunk summed at the end (no shared counters in the hot loop). A chunk
//! is traced one ray at a time, in packets or as one stream ([`QueryMode`]).

use super::simd::Width;
use super::traverse::{self, Traversal, TraverseOptions};
use super::{packet, stream};
use crate::geometry::{Hit, Ray, TraversalStats};
use crate::scene::Committed;
use rayon::prelude::*;

/// Rays per parallel task: the granularity Embree's peer harness uses too.
const CHUNK: usize = 4096;

/// Fewest rays per stream. A stream gains from more rays per node (the paper traces all rays
/// at once): the batch is cut into one stream per thread, but not below this size.
pub const STREAM_CHUNK: usize = 16384;

/// Most rays per stream. Past this the lists of rays pending at the far children of the upper
/// nodes no longer fit the caches: coherent rays cross both children of most upper nodes, so
/// the ray stack holds about one copy of the stream per level. Measured with one thread on
/// 1376×768 orbit frames (the `rt2 bench streams` workload), one 1 M-ray stream ran at
/// 0.55–0.65× the speed of 32 K-ray streams on the bunny and the Snowden bust, and 64 K-ray
/// streams already lost 25% on the bust. Incoherent rays would take longer streams (on the
/// bunny's incoherent set 131 K-ray streams are about 12% faster than 32 K-ray ones), but their
/// loss is the smaller one.
pub const STREAM_MAX: usize = 32768;

/// How a batch is traced. Every mode returns the same closest hits, bit for bit (the packet and
/// stream traversals take the standard traversal's decisions for every ray).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum QueryMode {
    /// One ray at a time with the chosen [`Traversal`].
    #[default]
    Single,
    /// Packets of 4/8/16 rays of one octant (Wald), width by CPU features ([`Width::best`]).
    Packet,
    /// The n-ray traversal of the vectorised-traversal paper: all rays of a chunk at once.
    Stream,
}

impl QueryMode {
    /// The command-line spelling.
    pub fn name(self) -> &'static str {
        match self {
            QueryMode::Single => "single",
            QueryMode::Packet => "packet",
            QueryMode::Stream => "stream",
        }
    }

    /// Rays per parallel task in this mode for a batch of `n` rays.
    pub fn chunk(self, n: usize) -> usize {
        match self {
            QueryMode::Stream => n
                .div_ceil(rayon::current_num_threads())
                .clamp(STREAM_CHUNK, STREAM_MAX),
            _ => CHUNK,
        }
    }
}

/// Closest hits of `rays` into `hits` (same length). Packets and streams use the standard
/// traversal's order whatever `how` says.
pub fn intersect(
    scene: &Committed,
    rays: &[Ray],
    hits: &mut [Hit],
    how: Traversal,
    opts: &TraverseOptions,
    mode: QueryMode,
) -> TraversalStats {
    intersect_width(scene, rays, hits, how, opts, mode, Width::best())
}

/// [`intersect`] with packets and streams of a given lane width (for the benchmark's width rows).
pub fn intersect_width(
    scene: &Committed,
    rays: &[Ray],
    hits: &mut [Hit],
    how: Traversal,
    opts: &TraverseOptions,
    mode: QueryMode,
    width: Width,
) -> TraversalStats {
    let (tree, prims) = (&scene.tree, &scene.prims);
    chunked(rays, hits, mode.chunk(rays.len()), |r, h| {
        serial(
            r,
            h,
            mode,
            |ray, stats| traverse::intersect(tree, prims, ray, how, opts, stats),
            |r, h| packet::intersect(tree, prims, r, h, width),
            |r, h| stream::intersect(tree, prims, r, h, width).0,
        )
    })
}

/// Any-hit queries: `occluded[i]` is true when something lies in ray i's `[tmin, tmax)`.
pub fn occluded(
    scene: &Committed,
    rays: &[Ray],
    occluded: &mut [bool],
    how: Traversal,
    opts: &TraverseOptions,
    mode: QueryMode,
) -> TraversalStats {
    let (tree, prims, width) = (&scene.tree, &scene.prims, Width::best());
    chunked(rays, occluded, mode.chunk(rays.len()), |r, o| {
        serial(
            r,
            o,
            mode,
            |ray, stats| traverse::occluded(tree, prims, ray, how, opts, stats),
            |r, o| packet::occluded(tree, prims, r, o, width),
            |r, o| stream::occluded(tree, prims, r, o, width).0,
        )
    })
}

/// Traces `chunk`-ray pieces of a batch in parallel (`out[i]` belongs to `rays[i]`) and sums
/// their statistics: no shared counters in the hot loop.
fn chunked<T: Send>(
    rays: &[Ray],
    out: &mut [T],
    chunk: usize,
    serial: impl Fn(&[Ray], &mut [T]) -> TraversalStats + Sync,
) -> TraversalStats {
    rays.par_chunks(chunk)
        .zip(out.par_chunks_mut(chunk))
        .map(|(r, o)| serial(r, o))
        .reduce(TraversalStats::default, |mut a, b| {
            a.add(&b);
            a
        })
}

/// One chunk of a query on the calling thread: `single` answers one ray at a time, `packet`
/// and `stream` a whole chunk in their mode.
fn serial<T>(
    rays: &[Ray],
    out: &mut [T],
    mode: QueryMode,
    single: impl Fn(&Ray, &mut TraversalStats) -> T,
    packet: impl FnOnce(&[Ray], &mut [T]) -> TraversalStats,
    stream: impl FnOnce(&[Ray], &mut [T]) -> TraversalStats,
) -> TraversalStats {
    match mode {
        QueryMode::Single => {
            let mut stats = TraversalStats::default();
            for (ray, o) in rays.iter().zip(out) {
                *o = single(ray, &mut stats);
            }
            stats
        }
        QueryMode::Packet => packet(rays, out),
        QueryMode::Stream => stream(rays, out),
    }
}
