//! Batch ray queries on the CPU: rays split into chunks that the context's pool traces, with
//! the statistics of each chunk summed at the end (no shared counters in the hot loop). A chunk
//! is traced one ray at a time, in packets or as one stream ([`QueryMode`]); streams are cut
//! by octant ([`STREAM_MAX`]).

use super::batch::{octant, Excluded, RayTests};
use super::ray_order::{self, whole_bands, RayOrder};
use super::simd::Width;
use super::stream::StreamMemory;
use super::traverse::{self, Traversal, TraverseOptions};
use super::{packet, stream};
use crate::geometry::{Hit, PrimIndex, PrimitiveSet, Ray, TraversalStats};
use crate::kdtree::KdTree;
use crate::rng::Rng;
use crate::scene::Committed;
use rayon::prelude::*;

/// Rays per parallel task: the granularity Embree's peer harness uses too. A batch of at most
/// this many rays is traced in one piece on the calling thread, touching no pool: it would run
/// on one thread anyway (see `Context`, which then does not hand it to its pool either).
pub const CHUNK: usize = 4096;

/// Fewest rays per stream when a batch is cut to keep every thread busy.
pub const STREAM_CHUNK: usize = 16384;

/// Most rays per stream of rays that come in runs of one octant, as a camera's do (they are cut
/// in their own order), and fewest that incoherent rays get ([`incoherent_stream_max`]). A
/// stream walks the tree once per octant group (the paper), so incoherent batches are first
/// sorted by octant and cut into streams of one octant each: a stream then holds as many rays
/// of its octant as a batch eight times its size would. Past this size coherent rays outgrow
/// the caches: they cross both children of most upper nodes, so the far children's lists
/// pending on the ray stack hold about one copy of the stream per level, and the stream's ray
/// arrays are written out before the walk reads them back. On 1376×768 orbit frames (one
/// thread, `rt2 bench streams`) one 1 M-ray stream ran at 0.55–0.65× the speed of 32 K-ray
/// streams on the bunny and the Snowden bust, and 128 K-ray streams lost 40% on the bust.
pub const STREAM_MAX: usize = 32768;

/// Most rays per stream of incoherent rays (a batch in mixed octants, sorted by octant before
/// it is cut; see [`incoherent_stream_max`]).
pub const INCOHERENT_STREAM_MAX: usize = 262144;

/// Most rays per stream of incoherent rays on `tree`: about one ray per leaf, from
/// [`STREAM_MAX`] to [`INCOHERENT_STREAM_MAX`]. Incoherent rays spread over the tree as they
/// descend, and a list that has thinned to a packet's worth of rays is finished ray by ray (or
/// packet by packet); on the dragon's 2 M incoherent rays (one thread) those finishing walks
/// took 68% of a 32 K-ray stream's time. The more rays a stream holds, the deeper its lists
/// stay shared: one stream per octant (256 K rays) ran 1.3–1.5× as fast as 32 K-ray streams on
/// the dragon (367 K leaves), while on the bunny (26 K leaves) and the Snowden bust (15 K) it
/// was no faster at 128 K and slower at 256 K (2 M incoherent rays, one thread, 3–5 runs with
/// the stream sizes interleaved; `rt2 bench streams` traces 2 M-ray batches in its table 3).
/// Those trees predate the SAH's empty bonus; the three now have 514 K, 38 K and 22 K leaves.
/// A stream of one octant's incoherent rays takes 65–70 bytes per ray, ray stack and ray
/// arrays (16 MiB for the dragon's 256 K; `rt2 bench streams`, memory table).
/// Mirror reflections of the dragon's 2752×1536 camera rays (557 K rays in mixed octants) ran
/// alike with either stream size (2.93 and 3.05 Mrays/s, 5 interleaved runs). With the empty
/// bonus, on the bunny (one thread, 16 lanes, 5 runs each): 262 K incoherent rays in streams of
/// at most 4 K, 8 K and 16 K rays ran at 0.73×, 0.80× and 0.90× of one stream per octant (about
/// 32 K rays), and 2 M in streams of 64 K, 128 K and 256 K at 0.85–0.94×, 0.90–0.94× and
/// 0.71–0.74× of 32 K: on the bunny more rays per stream pay up to about 32 K, so streams of
/// mixed octants (larger ones from a small batch) were not tried.
pub fn incoherent_stream_max(tree: &KdTree) -> usize {
    // Every inner node has two children: a tree of n nodes has (n + 1) / 2 leaves.
    tree.nodes
        .len()
        .div_ceil(2)
        .clamp(STREAM_MAX, INCOHERENT_STREAM_MAX)
}

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
}

/// A single-ray traversal answering one ray (it ignores the primitive `opts.exclude`).
pub type SingleFn<T> =
    fn(&KdTree, &PrimitiveSet, &Ray, Traversal, &TraverseOptions, &mut TraversalStats) -> T;

/// A packet or stream traversal answering a slice of rays on the calling thread, at a lane
/// width; `S` is what it reports.
pub type BatchFn<T, S> =
    fn(&KdTree, &PrimitiveSet, (&[Ray], RayOrder), RayTests, &mut [T], Width) -> S;

/// What a query answers for each ray: its closest hit ([`Hit`]) or whether anything lies in
/// its window (`bool`, shadow rays), and the traversals of each mode that compute it, so that
/// each mode's path is written once for both.
pub trait RayAnswer: Copy + Send + Sync + 'static {
    /// The answer of a ray that finds nothing.
    const MISS: Self;
    const SINGLE: SingleFn<Self>;
    const PACKETS: BatchFn<Self, TraversalStats>;
    const STREAM: BatchFn<Self, (TraversalStats, StreamMemory)>;
    /// The answer of a ray traced with its direction scaled by `s` (`Ray::scaled`), for
    /// the unscaled ray.
    fn scaled_back(self, s: f32) -> Self;
}

impl RayAnswer for Hit {
    const MISS: Self = Hit::MISS;
    const SINGLE: SingleFn<Self> = traverse::intersect;
    const PACKETS: BatchFn<Self, TraversalStats> = packet::intersect;
    const STREAM: BatchFn<Self, (TraversalStats, StreamMemory)> = stream::intersect;
    fn scaled_back(self, s: f32) -> Self {
        Hit {
            t: self.t * s,
            ..self
        }
    }
}

impl RayAnswer for bool {
    const MISS: Self = false;
    const SINGLE: SingleFn<Self> = traverse::occluded;
    const PACKETS: BatchFn<Self, TraversalStats> = packet::occluded;
    const STREAM: BatchFn<Self, (TraversalStats, StreamMemory)> = stream::occluded;
    fn scaled_back(self, _: f32) -> Self {
        self
    }
}

/// Answers `rays` into `out` (same length): closest hits or occlusion ([`RayAnswer`]). Ray `i`
/// ignores primitive `exclude[i]` (`INVALID` for none) when `exclude` is given, else
/// `opts.exclude`. Packets and streams (of `width` lanes) use the standard traversal's order
/// whatever `how` says; every mode honours `opts.intersector` and the exclusions, with the
/// same answers. Larger batches run on the current rayon pool; one of at most [`CHUNK`] rays
/// on the calling thread alone.
///
/// Rays are traced as given: `Context` scales a direction far from unit length first
/// (`Ray::direction_scale`, [`RayAnswer::scaled_back`]).
///
/// # Panics
/// When `exclude` is not as long as `rays`.
pub fn trace<T: RayAnswer>(
    scene: &Committed,
    (rays, exclude): (&[Ray], Option<&[PrimIndex]>),
    out: &mut [T],
    how: Traversal,
    opts: &TraverseOptions,
    mode: QueryMode,
    width: Width,
) -> TraversalStats {
    let exclude = match exclude {
        None => Excluded::All(opts.exclude),
        Some(e) => {
            assert_eq!(e.len(), rays.len(), "one excluded primitive per ray");
            Excluded::Each(e)
        }
    };
    let rays = (rays, exclude);
    let (tree, prims, intersector) = (&scene.tree, &scene.prims, opts.intersector);
    match mode {
        QueryMode::Single => chunked(rays, out, CHUNK, |r, e, o| {
            serial((r, e), o, |ray, exclude, stats| {
                let opts = TraverseOptions { exclude, ..*opts };
                T::SINGLE(tree, prims, ray, how, &opts, stats)
            })
        }),
        QueryMode::Packet => {
            // Pieces of whole bands of an image's rows, so that each piece's packets are tiles.
            let order = ray_order::detect(rays.0);
            chunked(rays, out, whole_bands(order, CHUNK), |r, e, o| {
                T::PACKETS(
                    tree,
                    prims,
                    (r, order),
                    RayTests::new(intersector, e),
                    o,
                    width,
                )
            })
        }
        // Streams take the rays as given: in tiles, their lists touched more cache lines of
        // the ray arrays per node, and the 256² to 512² primary rays of the bunny and the
        // dragon ran at 0.97–0.985× (one thread, 16 lanes), 1.03× at 1024².
        QueryMode::Stream if rays.0.len() <= CHUNK => {
            let (r, e) = rays;
            let r = (r, RayOrder::AsGiven);
            T::STREAM(tree, prims, r, RayTests::new(intersector, e), out, width).0
        }
        QueryMode::Stream => streamed(rays, out, incoherent_stream_max(tree), |r, e, o| {
            let r = (r, RayOrder::AsGiven);
            T::STREAM(tree, prims, r, RayTests::new(intersector, e), o, width).0
        }),
    }
}

/// Rays and the primitives they ignore.
type Rays<'a> = (&'a [Ray], Excluded<'a>);

/// Traces `chunk`-ray pieces of a batch in parallel (`out[i]` belongs to `rays[i]`) and sums
/// their statistics: no shared counters in the hot loop.
fn chunked<T: Send>(
    (rays, exclude): Rays,
    out: &mut [T],
    chunk: usize,
    trace: impl Fn(&[Ray], Excluded, &mut [T]) -> TraversalStats + Sync,
) -> TraversalStats {
    if rays.len() <= chunk {
        return trace(rays, exclude, out);
    }
    rays.par_chunks(chunk)
        .zip(out.par_chunks_mut(chunk))
        .enumerate()
        .map(|(k, (r, o))| {
            let exclude = match exclude {
                Excluded::Each(e) => Excluded::Each(&e[k * chunk..][..r.len()]),
                all => all,
            };
            trace(r, exclude, o)
        })
        .reduce(TraversalStats::default, |mut a, b| {
            a.add(&b);
            a
        })
}

/// One ray at a time, for one chunk on the calling thread.
fn serial<T>(
    (rays, exclude): Rays,
    out: &mut [T],
    single: impl Fn(&Ray, PrimIndex, &mut TraversalStats) -> T,
) -> TraversalStats {
    let mut stats = TraversalStats::default();
    for (i, (ray, o)) in rays.iter().zip(out).enumerate() {
        *o = single(ray, exclude.of(i), &mut stats);
    }
    stats
}

/// Rays per octant run, on average, from which a batch is streamed in its own order: camera
/// rays in scanline order change octant once or twice per row, and sorting them would only
/// cost a copy of every ray (measured: 25% of the speed on 1376×768 frames).
const LONG_RUNS: usize = 64;

/// Neighbour pairs [`octant_runs_at_least`] looks at, at most.
const RUN_SAMPLES: usize = 1024;

/// Whether consecutive rays share an octant in runs of `run` rays or more on average, as a
/// camera's rays in scanline order do: whether the octant changes at one neighbour pair in
/// `run` or fewer. Judged from `RUN_SAMPLES` pairs in a larger batch, so that it costs the
/// same for a million rays as for a thousand, at positions drawn from a fixed SplitMix64
/// sequence: evenly spaced samples alias with an image's rows (all on the column where the
/// octant changes, or none), and so did a Weyl sequence for some image heights (1920×1104
/// counted 46 changes in 1024 samples where about one is expected).
pub fn octant_runs_at_least(rays: &[Ray], run: usize) -> bool {
    let pairs = rays.len().saturating_sub(1);
    let changed = |i: usize| octant(&rays[i]) != octant(&rays[i + 1]);
    let (samples, changes) = if pairs <= RUN_SAMPLES {
        (pairs, (0..pairs).filter(|&i| changed(i)).count())
    } else {
        let mut rng = Rng(0);
        let changes = (0..RUN_SAMPLES)
            .filter(|_| changed(rng.index(pairs)))
            .count();
        (RUN_SAMPLES, changes)
    };
    changes * run <= samples
}

/// Streams of no more than a thread's share (but at least [`STREAM_CHUNK`]), traced in
/// parallel. Rays that come in long octant runs are cut in their own order, in streams of at
/// most [`STREAM_MAX`] rays; others are sorted by octant (a stable counting sort) and each
/// octant cut into streams of at most `incoherent_max` rays, each traced on a copy of its rays
/// in the batch's order, with `out` filled from its answers: in one pass over the batch up to
/// [`ONE_PASS_MAX`] rays ([`one_pass`]), else through an index of the sorted order, a copy
/// gathered per stream.
///
/// Measured and dropped (2 M incoherent rays, one thread): an octant cut in the order of cells
/// of rays that start near each other and point alike (two levels of halves of the origin's
/// place in the tree's box, one of the direction, 512 cells; a counting sort into one copy of
/// the batch) rather than in the batch's order, so that a stream's rays share more nodes. The
/// streams traced in 193 ms on the bunny and 149 ms on the Snowden bust against 198 and 148 in
/// octant order, and the sort cost 45 ms more than the octant sort.
fn streamed<T: RayAnswer>(
    (rays, exclude): Rays,
    out: &mut [T],
    incoherent_max: usize,
    trace: impl Fn(&[Ray], Excluded, &mut [T]) -> TraversalStats + Sync,
) -> TraversalStats {
    let share = rays.len().div_ceil(rayon::current_num_threads());
    if octant_runs_at_least(rays, LONG_RUNS) {
        let size = share.clamp(STREAM_CHUNK, STREAM_MAX);
        return chunked((rays, exclude), out, size, trace);
    }
    let most = share.clamp(STREAM_CHUNK, incoherent_max.max(STREAM_CHUNK));
    if rays.len() <= ONE_PASS_MAX {
        return one_pass((rays, exclude), out, most, trace);
    }
    let (octants, start) = octant_starts(rays);
    // Ray indices as `usize`: a Rust caller may pass more than 2^32 rays.
    let mut order = vec![0usize; rays.len()];
    let mut next = start;
    for (i, &o) in octants.iter().enumerate() {
        order[next[o as usize]] = i;
        next[o as usize] += 1;
    }
    let parts: Vec<&[usize]> = (0..8)
        .flat_map(|o| order[start[o]..start[o + 1]].chunks(most))
        .collect();
    let answers: Vec<(TraversalStats, Vec<T>)> = parts
        .par_iter()
        .map(|part| {
            let part_rays: Vec<Ray> = part.iter().map(|&i| rays[i]).collect();
            let gathered: Vec<PrimIndex>;
            let part_exclude = match exclude {
                Excluded::Each(e) => {
                    gathered = part.iter().map(|&i| e[i]).collect();
                    Excluded::Each(&gathered)
                }
                all => all,
            };
            let mut answers = vec![T::MISS; part.len()];
            let stats = trace(&part_rays, part_exclude, &mut answers);
            (stats, answers)
        })
        .collect();
    let mut stats = TraversalStats::default();
    for (part, (s, answers)) in parts.iter().zip(answers) {
        stats.add(&s);
        for (&i, a) in part.iter().zip(answers) {
            out[i] = a;
        }
    }
    stats
}

/// Each ray's octant, and where each octant's rays start in the batch sorted by octant (a
/// stable counting sort: `start[o]..start[o + 1]` for octant `o`).
fn octant_starts(rays: &[Ray]) -> (Vec<u8>, [usize; 9]) {
    let octants: Vec<u8> = rays.iter().map(|r| octant(r) as u8).collect();
    let mut start = [0usize; 9];
    for &o in &octants {
        start[o as usize + 1] += 1;
    }
    for o in 0..8 {
        start[o + 1] += start[o];
    }
    (octants, start)
}

/// Most rays of an incoherent stream batch sorted by octant in one pass (`one_pass`): 512 K,
/// whose sorted copy and answers (48 bytes a ray, 24 MiB) fit in memory the allocator reuses
/// from batch to batch. On the bunny (one thread, 16 lanes, the two paths alternated in one
/// process, medians of 10–14 paired runs) 1 M and 2 M incoherent rays ran at 0.937× and 0.932×
/// of the per-stream gather, 512 K at 1.06×: presumably page faults, as glibc maps a block of
/// 32 MiB or more (the 1 M-ray copy) afresh for every batch; the eight-vector variant below
/// took 1000 more page faults per batch where it lost (`perf stat`).
pub const ONE_PASS_MAX: usize = 1 << 19;

/// [`streamed`]'s incoherent batches of at most [`ONE_PASS_MAX`] rays: one pass writes every
/// ray to its place in a copy of the batch sorted by octant (a stable counting sort, its
/// excluded primitive likewise), each octant's run of the copy is cut into streams of at most
/// `most` rays traced in place with their answers in one sorted array, and one pass in the
/// batch's order takes each ray's answer from its octant's next place. No index of the sorted
/// order is made: an index (8 bytes a ray) written by the sort, read to gather each stream's
/// copy and again to write its answers back cost about a tenth of the time of the bunny's
/// 262 K incoherent rays (sort 0.5 ms, gathers 1.25 ms, answers 0.5 ms of 23.5 ms). With the
/// same hits and statistics (one thread, 16 lanes, AMD EPYC, the two paths alternated in one
/// process, medians of 30 paired runs): the bunny's `incoherent_262144` 1.056–1.063×, 262 K
/// incoherent rays of the Snowden bust 1.056–1.059×, the dragon's `incoherent_131072`
/// 1.022–1.024×. An earlier one-pass copy that still wrote the answers back through an index
/// of the sorted order ran at 1.036×, 1.01× and 1.00× on these sets and 0.985× on 2 M of the
/// bunny's rays (10–30 paired runs). A copy per octant (eight vectors, each allocated for its
/// rays) lost on the Snowden bust (0.94×), with 1000 more page faults per batch.
fn one_pass<T: RayAnswer>(
    (rays, exclude): Rays,
    out: &mut [T],
    most: usize,
    trace: impl Fn(&[Ray], Excluded, &mut [T]) -> TraversalStats + Sync,
) -> TraversalStats {
    let (octants, start) = octant_starts(rays);
    // Writes each item to its octant's next place.
    fn sort<X: Copy>(items: &[X], octants: &[u8], start: &[usize; 9], sorted: &mut [X]) {
        let mut next = *start;
        for (x, &o) in items.iter().zip(octants) {
            sorted[next[o as usize]] = *x;
            next[o as usize] += 1;
        }
    }
    let mut sorted: Vec<Ray> = bytemuck::zeroed_vec(rays.len());
    sort(rays, &octants, &start, &mut sorted);
    let sorted_exclude: Vec<PrimIndex>;
    let exclude_of = match exclude {
        Excluded::Each(e) => {
            let mut x = vec![0; rays.len()];
            sort(e, &octants, &start, &mut x);
            sorted_exclude = x;
            Some(&sorted_exclude[..])
        }
        Excluded::All(_) => None,
    };
    let mut answers = vec![T::MISS; rays.len()];
    let mut parts = Vec::new();
    let mut rest = &mut answers[..];
    for o in 0..8 {
        let (octant_answers, after) = rest.split_at_mut(start[o + 1] - start[o]);
        rest = after;
        let octant_rays = &sorted[start[o]..start[o + 1]];
        let pieces = octant_rays
            .chunks(most)
            .zip(octant_answers.chunks_mut(most));
        for (k, (r, a)) in pieces.enumerate() {
            let e = match exclude_of {
                Some(x) => Excluded::Each(&x[start[o] + k * most..][..r.len()]),
                None => exclude,
            };
            parts.push((r, e, a));
        }
    }
    let stats = parts
        .into_par_iter()
        .map(|(r, e, a)| trace(r, e, a))
        .reduce(TraversalStats::default, |mut a, b| {
            a.add(&b);
            a
        });
    let mut next = start;
    for (o, &oct) in out.iter_mut().zip(&octants) {
        *o = answers[next[oct as usize]];
        next[oct as usize] += 1;
    }
    stats
}
