//! Packet traversal (Wald et al. 2001, the "4 rayos" column of the vectorised-traversal paper,
//! seeds/000): N rays of one octant walk the tree together, one node fetch for all, with an active
//! mask; a lane leaves the mask where the standard traversal would not take that ray. Generic over
//! the lane width N (4 with SSE, 8 with AVX2, 16 with AVX-512; see [`super::simd`]). A leaf
//! reached by many of the packet's rays tests them all against one triangle at a time, as Wald's
//! packets do; one reached by few tests each ray against blocks of its triangles
//! (`rays_per_triangle`).
//!
//! The same function finishes a stream traversal when few rays reach a node (the paper's future
//! work: stop paying for lists when the rays no longer share nodes).

use super::batch::{positive, run, Answer, Batch, Mode, RayTests, Root, Split};
use super::ray_order::{Blocks, RayOrder};
use super::simd::{self, Isa, LeafPrims, PreparedLeaf, RayLanes, Width, GATHER_MIN_RAYS};
use crate::geometry::{Hit, PrimitiveSet, Ray, TraversalStats};
use crate::kdtree::KdTree;

/// Up to N rays with their segments `[t0, t1]` at some node; `mask` bit `l` marks lane `l` live.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Lanes<const N: usize> {
    pub id: [u32; N],
    pub t0: [f32; N],
    pub t1: [f32; N],
    pub mask: u32,
}

impl<const N: usize> Lanes<N> {
    pub fn new() -> Self {
        Lanes {
            id: [0; N],
            t0: [0.0; N],
            t1: [0.0; N],
            mask: 0,
        }
    }
}

/// Up to N rays' origins and reciprocal directions, by axis (structure of arrays): what an
/// inner step reads of them.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Axes<const N: usize> {
    pub org: [[f32; N]; 3],
    pub inv: [[f32; N]; 3],
}

/// A packet's rays: their [`Axes`], and the rays themselves when they are at hand (gathered
/// at the first leaf that tests them N rays per triangle otherwise).
pub(crate) struct PacketRays<const N: usize> {
    pub axes: Axes<N>,
    pub rays: Option<RayLanes<N>>,
}

impl<const N: usize> PacketRays<N> {
    /// The rays `ids` that [`Batch::keep`](super::batch::Batch::keep) kept in the batch.
    #[inline(always)]
    pub fn kept<A, const WATERTIGHT: bool>(
        isa: Isa<N>,
        b: &Batch<A, WATERTIGHT>,
        ids: &[u32; N],
    ) -> Self {
        let (mut org, mut inv) = ([[0.0f32; N]; 3], [[0.0f32; N]; 3]);
        for a in 0..3 {
            [org[a], inv[a]] = simd::gather_columns(isa, &b.split[a], [0, 1], ids);
        }
        PacketRays {
            axes: Axes { org, inv },
            rays: None,
        }
    }
}

/// A pending far subtree: the node, the lanes' segments there and the live lanes. The ray
/// indices are the packet's throughout, so they are not copied with every entry.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Entry<const N: usize> {
    node: u32,
    t0: [f32; N],
    t1: [f32; N],
    mask: u32,
}

/// Slots of the packet stack. A step at an inner node of depth `d` has at most `d` far children
/// pending (one per level above it) and writes slot `d` before it knows whether its own far
/// child is pending; the builders make every node at depth `MAX_DEPTH_LIMIT` a leaf, so inner
/// nodes lie at depth `MAX_DEPTH_LIMIT - 1` at most.
const STACK_SLOTS: usize = crate::kdtree::MAX_DEPTH_LIMIT as usize;

/// Reused buffers of one thread: the packet stack and the leaf's gathered triangles (`lone`:
/// in blocks of [`LONE_BLOCK`] for a ray or two).
pub(crate) struct Scratch<const N: usize> {
    stack: Vec<Entry<N>>,
    pub leaf: LeafPrims<N>,
    lone: LeafPrims<LONE_BLOCK>,
}

impl<const N: usize> Scratch<N> {
    pub fn new() -> Self {
        let empty = Entry {
            node: 0,
            t0: [0.0; N],
            t1: [0.0; N],
            mask: 0,
        };
        Scratch {
            stack: vec![empty; STACK_SLOTS],
            leaf: LeafPrims::default(),
            lone: LeafPrims::default(),
        }
    }
}

/// Traverses the subtree of `node` with the packet `p` (all lanes of octant `positive`; their
/// rays `rays`), front to back, as the standard traversal does for each lane: descend to the
/// nearest leaf, keep far children on a stack, stop a lane when its closest hit lies before the
/// leaf's exit.
///
/// An inner step branches only on whether the near child has lanes, which it has at most steps
/// (a well-predicted branch): the far child is always written to the top stack slot, and kept
/// (the stack pointer moved) when the near child has lanes too. A branch on which of the three
/// cases a step meets (near, far, both) mispredicted often: a packet's crossings are close to
/// random.
#[inline(always)]
pub(crate) fn traverse<const N: usize, A: Answer, const WATERTIGHT: bool>(
    isa: Isa<N>,
    b: &mut Batch<A, WATERTIGHT>,
    s: &mut Scratch<N>,
    node: u32,
    p: Lanes<N>,
    rays: PacketRays<N>,
    positive: [bool; 3],
) {
    let Axes { org, inv } = rays.axes;
    let mut known = rays.rays;
    let tree = b.tree;
    let stack = &mut s.stack[..];
    let mut sp = 0;
    let mut dead = 0u32;
    let id = p.id;
    // The rays for the N-rays × 1-triangle leaf test, made at the first leaf that takes it from
    // `known` or a gather (a stream hands over many short packets, some of which never take it).
    let mut lanes = None;
    let mut cur = Entry {
        node,
        t0: p.t0,
        t1: p.t1,
        mask: p.mask,
    };
    loop {
        let n = tree.nodes[cur.node as usize];
        let live = cur.mask;
        b.stats.nodes_visited += live.count_ones() as u64;
        if !n.is_leaf() {
            let axis = n.axis();
            let (below, above) = (n.index(), n.index() + 1);
            let (near, far) = if positive[axis] {
                (below, above)
            } else {
                (above, below)
            };
            let Split {
                near: nm,
                near_t1,
                far: fm,
                far_t0,
            } = Split::new(isa, n.split, &org[axis], &inv[axis], &cur.t0, &cur.t1, live);
            // Every live lane enters near or far (`Split`), so the next node has lanes.
            let far_entry = Entry {
                node: far,
                t0: far_t0,
                mask: fm,
                ..cur
            };
            stack[sp] = far_entry;
            sp += usize::from(nm != 0 && fm != 0);
            cur = if nm != 0 {
                Entry {
                    node: near,
                    t1: near_t1,
                    mask: nm,
                    ..cur
                }
            } else {
                far_entry
            };
            continue;
        }
        let list = tree.leaf_prims(n);
        if list.is_empty() {
            dead |= b.visit_empty_leaf(&id, live, &cur.t1);
        } else if rays_per_triangle(live, list) {
            let lanes = match lanes {
                Some(ref mut lanes) => lanes,
                None => lanes.insert(b.packet_lanes(isa, &id, p.mask, known.take())),
            };
            dead |= b.visit_packet_leaf(isa, list, lanes, &id, live, &cur.t1);
        } else {
            dead |= visit_few(isa, b, (&mut s.leaf, &mut s.lone), list, &id, &cur.t1, live);
            if let Some(lanes) = &mut lanes {
                b.reread(lanes, &id, live);
            }
        }
        cur = loop {
            if sp == 0 {
                return;
            }
            sp -= 1;
            let mut e = stack[sp];
            e.mask &= !dead;
            if e.mask != 0 {
                break e;
            }
        };
    }
}

/// Triangles per block of a leaf that one or two of a packet's rays reach (fewer than
/// [`GATHER_MIN_RAYS`]), when it holds more than one block of the single-ray leaf test (4
/// triangles) and the CPU runs 8 lanes: each ray then tests blocks of 8 triangles (AVX), made
/// once for both rays, rather than gathering blocks of 4 itself. Such leaves are the large
/// ones (on the bunny's `incoherent_262144` set most leaf visits of a lone ray met 8
/// triangles or more), and blocks of 4 took them in two steps or more, each with its block
/// to gather. With the same hits and statistics, 16-lane streams ran 1.05× as fast on that
/// set, 1.045× on the dragon's `incoherent_131072` and 1.02× on 262 K incoherent rays of the
/// Snowden bust, alike on the bunny's `primary_262144`; 8-lane streams 1.025× and 16-lane
/// packets 1.05× on the bunny's incoherent set (one thread, AMD EPYC, the two paths
/// alternated in one process, medians of 20–30 paired runs). Blocks of 16 (AVX-512, which
/// Zen 4 runs as two halves, and twice the lanes to gather) ran alike with blocks of 4 on the
/// bunny; blocks of 8 for every such leaf, however many rays reach it (instead of
/// [`LeafPrims::gather`]'s N-lane blocks from three rays on), 1.03× on the bunny and 1.01× on
/// the Snowden bust.
const LONE_BLOCK: usize = 8;

/// Tests the leaf `list` against the few lanes `live` (the N-rays × 1-triangle test would
/// waste most of its lanes: [`rays_per_triangle`]) one ray at a time: in blocks of
/// [`LONE_BLOCK`] made once for one or two rays, else as [`LeafPrims::gather`] prepares it
/// (the [`Scratch`] buffers for each). Returns the lanes finished.
#[inline(always)]
fn visit_few<const N: usize, A: Answer, const WATERTIGHT: bool>(
    isa: Isa<N>,
    b: &mut Batch<A, WATERTIGHT>,
    (gathered, lone_blocks): (&mut LeafPrims<N>, &mut LeafPrims<LONE_BLOCK>),
    list: &[u32],
    id: &[u32; N],
    t_exit: &[f32; N],
    live: u32,
) -> u32 {
    let rays = live.count_ones() as usize;
    let intersector = Batch::<A, WATERTIGHT>::INTERSECTOR;
    if let Some(lone) = isa.narrow::<LONE_BLOCK>() {
        if rays < GATHER_MIN_RAYS && list.len() > LONE_BLOCK / 2 {
            if let Some(leaf) = lone_blocks.whole_blocks(b.prims, list, intersector) {
                return visit_each(lone, b, &leaf, id, t_exit, live);
            }
        }
    }
    let leaf = gathered.gather(b.prims, list, rays, intersector);
    visit_each(isa, b, &leaf, id, t_exit, live)
}

/// Tests the prepared leaf `leaf` against the rays of lanes `live`, one at a time; returns the
/// lanes finished. A loop, not `for_lanes`: LLVM kept that closure as a call, compiled without
/// the kernel's SIMD features (see `simd`).
#[inline(always)]
fn visit_each<const M: usize, const N: usize, A: Answer, const WATERTIGHT: bool>(
    isa: Isa<M>,
    b: &mut Batch<A, WATERTIGHT>,
    leaf: &PreparedLeaf<M>,
    id: &[u32; N],
    t_exit: &[f32; N],
    live: u32,
) -> u32 {
    let (mut finished, mut m) = (0u32, live);
    while m != 0 {
        let l = m.trailing_zeros() as usize;
        m &= m - 1;
        if b.visit_leaf(isa, leaf, id[l], t_exit[l]) {
            finished |= 1 << l;
        }
    }
    finished
}

/// Whether the live lanes `live` test the leaf `prims` as Wald's packets do, all rays against
/// one triangle at a time, rather than one ray against a block of the leaf's triangles: when at
/// least one ray reaches it per two primitives. Fewer rays pay less for their few block tests
/// (or single-ray tests) than for a test of every triangle. Against block tests at every leaf,
/// this took 8-lane packets from 767 to 659 instructions per ray on the bunny's primary set and
/// from 1081 to 944 on the dragon's, 3% fewer on the bunny's diffuse set and the same on its
/// incoherent set (callgrind, which lacks AVX-512); testing every leaf so cost 30% more on
/// incoherent rays. With 16 lanes (AVX-512, the bunny's 1024² primary rays) one, two or four
/// rays per triangle, or every leaf so, were within the machine's noise of each other. On the
/// bunny's `incoherent_262144` set (16-lane streams, one thread, 20–30 paired runs in one
/// process) one ray per triangle ran at 1.00×, and leaving one or two rays to the single-ray
/// test however few triangles the leaf holds at 1.006–1.008× (1.00× on the dragon's
/// `incoherent_131072`).
///
/// The single-ray tests of such leaves take about a third of a 16-lane stream's time on the
/// bunny's incoherent set, but not for want of the triangles in the caches: with the mesh's
/// triangles sorted by a Morton code of their centres, or shuffled, before the tree is built,
/// streams ran at 10.3 and 10.0 Mrays/s against 10.2 as loaded, so copies of the leaves'
/// triangles in tree order were not tried.
#[inline(always)]
fn rays_per_triangle(live: u32, prims: &[u32]) -> bool {
    2 * live.count_ones() as usize >= prims.len()
}

/// The packet mode of a batch: the rays taken in blocks of N in the batch's [`RayOrder`] (N
/// consecutive rays, or a tile of an image's rows: neighbours of an image are coherent). A
/// block whose rays share an octant is traversed as one packet as soon as it is set up, its
/// rays still in vectors; the rays of the other blocks are grouped by octant, and each group
/// cut into packets of N rays in the same order. Against grouping every ray first (packets
/// of N consecutive rays inside the box, so a tile shifted whenever a ray of it missed the
/// box, and the rays written to the batch and gathered back), this ran 1.25× as fast on the
/// bunny's 1024² primary rays at 16 lanes, 1.1–1.25× on its 512² set at 4 and 16 lanes and
/// the dragon's at 8 and 16 (AMD EPYC, one thread).
///
/// Measured and dropped (the bunny's 1024² primary rays, one thread, 16 lanes, where inner
/// steps take about half the time): sorting each 4096-ray piece by a Morton code of its
/// directions (1.16× on the traversal, as 4×4 tiles) cost more than it saved (a comparison
/// sort: 36 ns per ray against 6 ns per ray gained); tiles of rows found in the rays
/// (`ray_order::detect`) cost nothing of the kind. Packets of 32 lanes (two AVX-512 vectors
/// per value) ran at 0.92× of 16.
struct PacketMode;

impl Mode for PacketMode {
    type Out = TraversalStats;
    #[inline(always)]
    fn trace<const N: usize, A: Answer, const WATERTIGHT: bool>(
        isa: Isa<N>,
        b: &mut Batch<A, WATERTIGHT>,
        order: RayOrder,
    ) -> Self::Out {
        let mut s = Scratch::<N>::new();
        let mut groups: [Vec<Root>; 8] = Default::default();
        for (ids, live) in Blocks::<N>::new(b.rays.len(), order) {
            let block = b.block(isa, ids, live);
            match block.octant(isa) {
                Some(o) => {
                    let rays = PacketRays {
                        axes: block.axes,
                        rays: Some(block.rays),
                    };
                    traverse(isa, b, &mut s, 0, block.lanes, rays, positive(o));
                }
                None => b.keep(isa, &block, &mut groups),
            }
        }
        for (o, group) in groups.iter().enumerate() {
            for chunk in group.chunks(N) {
                let p = lanes_of(chunk);
                let rays = PacketRays::kept(isa, b, &p.id);
                traverse(isa, b, &mut s, 0, p, rays, positive(o));
            }
        }
        b.stats
    }
}

/// Packs up to N rays into lanes.
#[inline(always)]
pub(crate) fn lanes_of<const N: usize>(roots: &[Root]) -> Lanes<N> {
    let mut p = Lanes::new();
    for (l, r) in roots.iter().take(N).enumerate() {
        p.id[l] = r.id;
        p.t0[l] = r.t0;
        p.t1[l] = r.t1;
        p.mask |= 1 << l;
    }
    p
}

/// Closest hits of `rays` (primitive tests `tests`) with N-ray packets (one thread).
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
) -> TraversalStats {
    run::<PacketMode, _>(tree, prims, rays, tests, super::batch::Closest(hits), width)
}

/// Any-hit queries of `rays` (primitive tests `tests`) with N-ray packets (one thread).
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
) -> TraversalStats {
    run::<PacketMode, _>(tree, prims, rays, tests, super::batch::AnyHit(found), width)
}
