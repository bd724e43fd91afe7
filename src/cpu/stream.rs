//! The n-ray traversal of Noguera & Ureña (seeds/000, "recorrido vectorial"): the tree is walked
//! once per octant group with all the group's rays at once. Every node receives a list of the
//! rays that enter it; an inner node splits its list into the near and far children's lists
//! (SIMD over N lanes), a leaf tests its triangles against every ray of its list (N rays × 1
//! triangle: SAH leaves hold ~2 triangles per visit, too few to fill a block of N triangles;
//! either intersector, each lane with its own excluded primitive: [`RayTests`]).
//!
//! Memory: the lists live on one ray stack, reused for the whole batch and never shrunk, so no node
//! allocates. Each list is a run of slots in columns (ray index, segment start, segment end),
//! structure of arrays over the whole list rather than the paper's array of 4-ray packets, so that
//! a compacted group of live lanes is one vector store per column wherever the list ends
//! ([`simd::compress`]); a list whose rays all enter one child with their segments unchanged is
//! handed to that child in place, uncopied. Rays that finished in a nearer subtree leave a list
//! when it is popped; rays past their `tmax` never get a segment there. A list of one or two rays
//! is finished one ray at a time by the standard traversal, one that fits a packet (≤ N rays) by
//! the packet traversal (the paper's future work: stop paying for lists once rays no longer share
//! nodes). The parametric traversal uses the general split distance `(split - org) * inv_dir`
//! rather than the paper's halving: it serves SAH trees too and is what makes the hits
//! bit-identical to the single-ray traversals.

use super::batch::{
    first, lanes_where, positive, run, Answer, AnyHit, Batch, Closest, Mode, RayTests, Root, Split,
};
use super::packet::{self, Lanes};
use super::ray_order::RayOrder;
use super::simd::{self, Isa, Width};
use super::traverse::Entry;
use crate::geometry::{Hit, PrimitiveSet, Ray, TraversalStats};
use crate::kdtree::KdTree;

/// A node still to visit and its list: `count` rays from `start` on the ray stack, written when
/// `finished` rays were done. A popped frame's list is always the highest live one on the ray
/// stack (children's lists are written above their parent's, and the near child is walked
/// first), so its children go right above it.
#[derive(Clone, Copy, Debug)]
struct Frame {
    node: u32,
    start: usize,
    count: usize,
    finished: usize,
}

/// The ray stack: every list is a run of slots in three columns (ray index, segment start and
/// end), so a compacted run of N lanes is stored at any slot with one vector store per column.
/// Reused for the whole batch and never shrunk: no node allocates.
#[derive(Default)]
struct Lists {
    id: Vec<u32>,
    t0: Vec<u32>,
    t1: Vec<u32>,
}

impl Lists {
    /// Makes room for slots up to `end` (exclusive).
    #[inline(always)]
    fn reserve(&mut self, end: usize) {
        if self.id.len() < end {
            for c in [&mut self.id, &mut self.t0, &mut self.t1] {
                c.resize(end, 0);
            }
        }
    }

    /// The N slots from `at`: ray indices and segments.
    #[inline(always)]
    fn load<const N: usize>(&self, at: usize) -> ([u32; N], [f32; N], [f32; N]) {
        let col = |c: &Vec<u32>| -> [u32; N] { c[at..at + N].try_into().expect("N slots") };
        (
            col(&self.id),
            col(&self.t0).map(f32::from_bits),
            col(&self.t1).map(f32::from_bits),
        )
    }

    /// Appends the `count` slots from `from` to the list whose end is `*at` (below `from` or at
    /// least `count` slots above it), and moves the end past them.
    #[inline(always)]
    fn copy(&mut self, from: usize, count: usize, at: &mut usize) {
        for c in [&mut self.id, &mut self.t0, &mut self.t1] {
            c.copy_within(from..from + count, *at);
        }
        *at += count;
    }

    /// Appends the lanes of `keep` to the list whose end is `*at`, and moves the end past them.
    #[inline(always)]
    fn push<const N: usize>(
        &mut self,
        isa: Isa<N>,
        at: &mut usize,
        keep: u32,
        id: &[u32; N],
        t0: &[f32; N],
        t1: &[f32; N],
    ) {
        let (t0, t1) = (t0.map(f32::to_bits), t1.map(f32::to_bits));
        let a = *at;
        simd::compress(
            isa,
            keep,
            [id, &t0, &t1],
            [&mut self.id[a..], &mut self.t0[a..], &mut self.t1[a..]],
        );
        *at += keep.count_ones() as usize;
    }
}

/// What a stream query used, for the memory report of `rt2 bench streams`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct StreamMemory {
    /// Peak bytes of the ray stack (the lists).
    pub ray_stack_bytes: usize,
    /// Bytes of the batch's ray arrays (origins, reciprocal directions, flags).
    pub ray_array_bytes: usize,
}

/// Longest list finished one ray at a time by the standard traversal (the paper's future work:
/// single rays once few rays share a node); longer lists of at most N rays are finished as one
/// packet. A packet of one or two live lanes pays for N. Tuned on the bunny's and dragon's
/// sets (`rt2 bench streams`, 1 thread, 5 interleaved runs each): thresholds 0, 2, 3 and 4 were
/// within the machine's noise of each other on primary, incoherent and diffuse rays.
///
/// Measured and dropped for the lists of at most N rays (16 lanes, one thread, the bunny's
/// `incoherent_262144` and the dragon's `incoherent_131072`, where these finishing walks take 58%
/// and 85% of the time): single rays taken in turns, 16 at once, each ray's next node and its
/// leaf's triangles prefetched while the others step (same hits and statistics), ran at 0.68× on
/// the bunny and 0.95–1.10× on the dragon: a lone ray's steps cost more than its cache misses. Two
/// lists' packets walked in turns, a step of each (their node fetches in flight together; same
/// hits): 0.95–0.97× on the bunny, 0.99–1.05× on the dragon. Independent lanes (each lane its own
/// ray, node, segment and stack, as on a GPU: an inner step moves every live ray one node, their
/// fetches in flight together; a leaf visit one lane at a time with the single-ray leaf test): same
/// hits, 10.5 steps per list against the packet's 19, but 0.55× on the bunny and 0.65× on the
/// dragon: the packet's rays share their leaves' gathered triangles, which lone rays each gather
/// again. Lists of up to 2N and 4N rays as two or four packets: 0.92× and 0.86× on the bunny, no
/// change on the dragon. Packets that finish their last one to four live lanes as single rays
/// (Embree's switch to single rays): 0.90–0.94× on the dragon. Lists of three or four rays as
/// 4-lane packets (in 16-lane streams): 0.99× on the bunny, 1.01× on the dragon. On the dragon's
/// 256² primary rays, lists of up to 2N, 4N and 8N rays as packets: 0.98–0.99×. The other way,
/// fewer lists as packets: split further as lists down to three rays (no packets), 0.53× on the
/// bunny's incoherent set; packets for lists of at most 8 or 12 rays (16 lanes), 0.96–1.00× on the
/// dragon's primary set.
const SINGLE_MAX: usize = 2;

/// Cache lines of a subtree's nodes asked for before its list of at most N rays walks it as
/// one packet or as single rays (8 KiB, 1024 nodes). Those walks go down the subtree one
/// dependent node load at a time, and below the top of a large tree each load missed the
/// caches; the depth-first layout keeps a subtree in one run of nodes, so its first lines,
/// fetched together, hold most of the nodes the walk reaches. 16 lanes, one thread, the two
/// builds alternated (`incoherent_*` and `primary_*` sets): the dragon's incoherent rays ran
/// 1.2–1.28× as fast (8 lanes too), its primary rays 1.14×; the bunny's, whose tree the caches
/// mostly hold, 1.0–1.06×. 64 and 256 lines did as well as 128 within the machine's noise on
/// the bunny; on the dragon 64 ran at 0.98× of 128, and 256 at 1.04× on incoherent rays but
/// 0.98× on primary ones. Asking for the next frame's subtree too (the walk after this one)
/// added nothing measurable. Measured and dropped: a packet asking for the primitive lists of
/// its leaf children at each inner step, 1.03–1.05× on the dragon's incoherent rays and no
/// change on its primary rays or the bunny's; single rays asking for the far child's subtree as
/// they push it, about 1.1× on the dragon's incoherent set but no change on its 1376×768 CPU
/// frame; the list's rays and answers asked for as it starts as a packet (what its leaf tests
/// read of them), 1.00× on the bunny's incoherent set (30 paired runs in one process); a
/// packet asking, at each leaf, for the triangles of the leaf on top of its stack (the next
/// leaf it visits, while this one is tested), 0.975–0.981× on the bunny's incoherent set,
/// 1.016× on the dragon's `incoherent_131072`, 0.994× on the Snowden bust (20 paired runs).
const SUBTREE_PREFETCH_LINES: usize = 128;

/// Asks the cache for the first [`SUBTREE_PREFETCH_LINES`] lines of the nodes below `node`.
#[inline(always)]
fn prefetch_subtree(tree: &KdTree, node: u32) {
    let n = tree.nodes[node as usize];
    if !n.is_leaf() {
        let per_line = 64 / std::mem::size_of_val(&n);
        let below = &tree.nodes[n.index() as usize..];
        for x in below.iter().step_by(per_line).take(SUBTREE_PREFETCH_LINES) {
            simd::prefetch(x);
        }
    }
}

/// Walks the tree once with all the rays of one octant group.
#[inline(always)]
fn traverse<const N: usize, A: Answer, const WATERTIGHT: bool>(
    isa: Isa<N>,
    b: &mut Batch<A, WATERTIGHT>,
    lists: &mut Lists,
    frames: &mut Vec<Frame>,
    scratch: &mut packet::Scratch<N>,
    roots: &[Root],
    positive: [bool; 3],
) {
    lists.reserve(roots.len() + N);
    for (k, r) in roots.iter().enumerate() {
        (lists.id[k], lists.t0[k], lists.t1[k]) = (r.id, r.t0.to_bits(), r.t1.to_bits());
    }
    frames.push(Frame {
        node: 0,
        start: 0,
        count: roots.len(),
        finished: b.finished,
    });
    while let Some(f) = frames.pop() {
        let mut count = f.count;
        if f.finished != b.finished {
            // Rays finished since the list was written (in a nearer subtree) leave it, in place.
            let mut end = f.start;
            for k in (0..count).step_by(N) {
                let (id, t0, t1) = lists.load::<N>(f.start + k);
                let live = lanes_where::<N>(|l| !b.done[id[l] as usize]);
                lists.push(isa, &mut end, live & first::<N>(count - k), &id, &t0, &t1);
            }
            count = end - f.start;
        }
        if count == 0 {
            continue;
        }
        if count <= N {
            prefetch_subtree(b.tree, f.node);
        }
        if count <= SINGLE_MAX {
            for k in f.start..f.start + count {
                let (t0, t1) = (f32::from_bits(lists.t0[k]), f32::from_bits(lists.t1[k]));
                b.trace_single(
                    lists.id[k],
                    Entry {
                        node: f.node,
                        t0,
                        t1,
                    },
                );
            }
            continue;
        }
        if count <= N {
            let (id, t0, t1) = lists.load::<N>(f.start);
            let p = Lanes {
                id,
                t0,
                t1,
                mask: first::<N>(count),
            };
            let rays = packet::PacketRays::kept(isa, b, &id);
            packet::traverse(isa, b, scratch, f.node, p, rays, positive);
            continue;
        }
        let n = b.tree.nodes[f.node as usize];
        b.stats.nodes_visited += count as u64;
        if n.is_leaf() {
            let leaf = b.tree.leaf_prims(n);
            for k in (0..count).step_by(N) {
                let at = f.start + k;
                for &i in
                    &lists.id[(at + N).min(f.start + count)..(at + 2 * N).min(f.start + count)]
                {
                    b.prefetch_leaf(i);
                }
                let (id, _, t1) = lists.load::<N>(at);
                let live = first::<N>(count - k);
                if leaf.is_empty() {
                    b.visit_empty_leaf(&id, live, &t1);
                } else {
                    b.visit_leaf_rays(isa, leaf, &id, live, &t1);
                }
            }
            continue;
        }
        // Children's lists: far right above the parent's, near above the far one's room (a
        // compacted store may run N slots past a list's end).
        let far_start = f.start + count;
        let near_start = far_start + count + N;
        lists.reserve(near_start + count + N);
        let axis = n.axis();
        let (below, above) = (n.index(), n.index() + 1);
        let (near, far) = if positive[axis] {
            (below, above)
        } else {
            (above, below)
        };
        let split = &b.split[axis];
        let (mut nc, mut fc) = (near_start, far_start);
        // While every ray so far enters one and the same child with its segment unchanged, the
        // child's list would be a copy of the parent's: nothing is written, and if the whole
        // list does so the child takes over the parent's slots. Coherent rays skip most copies
        // this way below the top of the tree.
        let mut whole = Side::Unknown;
        for k in (0..count).step_by(N) {
            let (id, t0, t1) = lists.load::<N>(f.start + k);
            // Lanes past the list's end hold stale ray indices: the gather clamps them. The next
            // chunk's rays are not prefetched here (the leaves do it): with the gathers, 16-lane
            // streams ran 1.01–1.05× as fast without it on the bunny's and dragon's sets.
            let [org, inv] = simd::gather_columns(isa, split, [0, 1], &id);
            let live = first::<N>(count - k);
            let Split {
                near: en,
                near_t1,
                far: ef,
                far_t0,
            } = Split::new(isa, n.split, &org, &inv, &t0, &t1, live);
            if whole != Side::Both {
                // A lane entering one child only keeps its segment: near only means
                // `ts >= t1` (so `near_t1 = t1`), far only `ts <= t0` (so `far_t0 = t0`).
                let side = match (en, ef) {
                    (near, 0) if near == live => Side::Near,
                    (0, far) if far == live => Side::Far,
                    _ => Side::Both,
                };
                if side != Side::Both && (whole == Side::Unknown || whole == side) {
                    whole = side;
                    continue;
                }
                // The rays before this chunk all went to one child: written there now.
                match whole {
                    Side::Near => lists.copy(f.start, k, &mut nc),
                    Side::Far => lists.copy(f.start, k, &mut fc),
                    Side::Unknown | Side::Both => {}
                }
                whole = Side::Both;
            }
            lists.push(isa, &mut fc, ef, &id, &far_t0, &t1);
            lists.push(isa, &mut nc, en, &id, &t0, &near_t1);
        }
        let (far_list, near_list) = match whole {
            Side::Near => ((far_start, far_start), (f.start, f.start + count)),
            Side::Far => ((f.start, f.start + count), (near_start, near_start)),
            Side::Unknown | Side::Both => ((far_start, fc), (near_start, nc)),
        };
        // Far first on the frame stack, so that near is walked first (front to back).
        for (node, (start, end)) in [(far, far_list), (near, near_list)] {
            if end > start {
                frames.push(Frame {
                    node,
                    start,
                    count: end - start,
                    finished: b.finished,
                });
            }
        }
    }
}

/// Which children the rays of a list seen so far enter: the chunk's rays at a node, or the
/// whole list's while it is one child for all of them.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Side {
    /// No ray seen yet.
    Unknown,
    /// All of them enter the near child only, segments unchanged.
    Near,
    /// All of them enter the far child only, segments unchanged.
    Far,
    /// Some enter both, or not all the same one: the children's lists are written out.
    Both,
}

/// The stream mode of a batch (one thread): every octant group traversed once with all its rays.
struct StreamMode;

impl Mode for StreamMode {
    type Out = (TraversalStats, StreamMemory);
    #[inline(always)]
    fn trace<const N: usize, A: Answer, const WATERTIGHT: bool>(
        isa: Isa<N>,
        b: &mut Batch<A, WATERTIGHT>,
        order: RayOrder,
    ) -> Self::Out {
        let groups = b.group(isa, order);
        let mut lists = Lists::default();
        let mut frames = Vec::with_capacity(128);
        let mut scratch = packet::Scratch::<N>::new();
        for (o, group) in groups.iter().enumerate() {
            if !group.is_empty() {
                traverse(
                    isa,
                    b,
                    &mut lists,
                    &mut frames,
                    &mut scratch,
                    group,
                    positive(o),
                );
            }
        }
        let mem = StreamMemory {
            ray_stack_bytes: 3 * 4 * lists.id.capacity(),
            ray_array_bytes: b.rays.len() * (6 * 4 + 1),
        };
        (b.stats, mem)
    }
}

/// Closest hits of `rays` (primitive tests `tests`) with the n-ray traversal (one thread).
/// Traced as given, as `traverse::intersect`, N rays at a time in the order `rays.1` says
/// (the answers are the same in any order).
///
/// # Panics
/// With more than `u32::MAX` rays (ray indices are 32-bit: `query` cuts batches smaller), or
/// a tree deeper than `MAX_DEPTH_LIMIT` (the packet stack's size; `kdtree::build` never makes
/// one).
pub fn intersect(
    tree: &KdTree,
    prims: &PrimitiveSet,
    rays: (&[Ray], RayOrder),
    tests: RayTests,
    hits: &mut [Hit],
    width: Width,
) -> (TraversalStats, StreamMemory) {
    run::<StreamMode, _>(tree, prims, rays, tests, Closest(hits), width)
}

/// Any-hit queries of `rays` (primitive tests `tests`) with the n-ray traversal (one thread).
/// Traced as given, as `traverse::intersect`, N rays at a time in the order `rays.1` says
/// (the answers are the same in any order).
///
/// # Panics
/// With more than `u32::MAX` rays (ray indices are 32-bit: `query` cuts batches smaller), or
/// a tree deeper than `MAX_DEPTH_LIMIT` (the packet stack's size; `kdtree::build` never makes
/// one).
pub fn occluded(
    tree: &KdTree,
    prims: &PrimitiveSet,
    rays: (&[Ray], RayOrder),
    tests: RayTests,
    found: &mut [bool],
    width: Width,
) -> (TraversalStats, StreamMemory) {
    run::<StreamMode, _>(tree, prims, rays, tests, AnyHit(found), width)
}
