//! The n-ray traversal of Noguera & Ureña (seeds/000, "recorrido vectorial"): the tree is walked
//! once per octant group with all the group's rays at once. Every node receives a list of the
//! rays that enter it; an inner node splits its list into the near and far children's lists
//! (SIMD over N lanes), a leaf tests its triangles against every ray of its list (1 ray × N
//! triangles, triangles gathered once per leaf visit).
//!
//! Memory follows the paper's hybrid layout: a list is a run of [`Lanes`] packets (structure of
//! arrays inside, array of packets outside) on one ray stack, a `Vec` reused for the whole batch
//! and never shrunk, so no node allocates. Finished rays are left out when a node builds its
//! children's lists; rays past their `tmax` never get a segment there. When few rays reach a node
//! (≤ [`SWITCH`]) the lists stop paying and the subtree is finished by the packet traversal (the
//! paper's future work). The parametric traversal uses the general split distance
//! `(split - org) * inv_dir` rather than the paper's halving: it serves SAH trees too and is what
//! makes the hits bit-identical to the single-ray traversals.

use super::batch::{positive, split_lane, Answer, AnyHit, Batch, Closest};
use super::packet::{self, Lanes};
use super::simd::{self, Kernel, Width};
use crate::geometry::{Hit, PrimitiveSet, Ray, TraversalStats};
use crate::kdtree::KdTree;

/// Lists of at most this many rays go on as one packet (the paper's future work suggests 4): a
/// list that small no longer amortises its compaction, and one packet walks the rest of the
/// subtree with one node fetch per node. Capped at the lane width.
pub const SWITCH: usize = 4;

/// A node still to visit and its list: `count` rays in packets from `start`. A popped frame's
/// list is always the highest live one on the ray stack (children's lists are written above their
/// parent's, and the near child is walked first), so its children go right above it.
#[derive(Clone, Copy, Debug)]
struct Frame {
    node: u32,
    start: usize,
    count: usize,
}

/// What a stream query used, for the memory report of `rt2 bench streams`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct StreamMemory {
    /// Peak bytes of the ray stack (the lists).
    pub ray_stack_bytes: usize,
    /// Bytes of the batch's ray arrays (origins, reciprocal directions, flags).
    pub ray_array_bytes: usize,
}

/// Walks the tree once with all the rays of one octant group.
#[inline(always)]
fn traverse<const N: usize, A: Answer>(
    b: &mut Batch<A>,
    list: &mut Vec<Lanes<N>>,
    frames: &mut Vec<Frame>,
    scratch: &mut packet::Scratch<N>,
    roots: &[super::batch::Root],
    positive: [bool; 3],
) {
    let packets = |count: usize| count.div_ceil(N);
    let need = packets(roots.len());
    if list.len() < need {
        list.resize(need, Lanes::new());
    }
    for (k, chunk) in roots.chunks(N).enumerate() {
        list[k] = packet::lanes_of(chunk);
    }
    frames.push(Frame {
        node: 0,
        start: 0,
        count: roots.len(),
    });
    while let Some(f) = frames.pop() {
        let n = b.tree.nodes[f.node as usize];
        if f.count <= SWITCH.min(N) {
            let mut p = list[f.start];
            p.mask &= !(0..N).fold(0u32, |m, l| m | (b.done[p.id[l] as usize] as u32) << l);
            if p.mask != 0 {
                packet::traverse(b, scratch, f.node, p, positive);
            }
            continue;
        }
        let lists = &list[f.start..f.start + packets(f.count)];
        if n.is_leaf() {
            scratch
                .leaf
                .gather(&b.prims.triangles, b.tree.leaf_prims(n.index()), f.count);
            for (k, p) in lists.iter().enumerate() {
                for l in 0..N.min(f.count - k * N) {
                    if !b.done[p.id[l] as usize] {
                        b.stats.nodes_visited += 1;
                        b.visit_leaf(&scratch.leaf, p.id[l], p.t1[l]);
                    }
                }
            }
            continue;
        }
        // Children's lists: far at `top`, near one parent-size further (both fit).
        let cap = packets(f.count);
        let top = f.start + cap;
        let (far_start, near_start) = (top, top + cap);
        if list.len() < near_start + cap {
            list.resize(near_start + cap, Lanes::new());
        }
        let axis = n.axis();
        let (below, above) = (n.index(), n.index() + 1);
        let (near, far) = if positive[axis] {
            (below, above)
        } else {
            (above, below)
        };
        let (mut nc, mut fc) = (0usize, 0usize);
        for k in 0..cap {
            let p = list[f.start + k];
            let (mut near_t1, mut far_t0, mut en, mut ef) =
                ([0.0; N], [0.0; N], [false; N], [false; N]);
            for l in 0..N {
                let i = p.id[l] as usize;
                let ts = (n.split - b.org[axis][i]) * b.inv[axis][i];
                (en[l], near_t1[l], ef[l], far_t0[l]) = split_lane(ts, p.t0[l], p.t1[l]);
            }
            // Compaction, branch-free: every live ray is written, the counts step by its flags.
            for l in 0..N.min(f.count - k * N) {
                let id = p.id[l];
                if b.done[id as usize] {
                    continue;
                }
                b.stats.nodes_visited += 1;
                let d = &mut list[far_start + fc / N];
                d.id[fc % N] = id;
                d.t0[fc % N] = far_t0[l];
                d.t1[fc % N] = p.t1[l];
                fc += ef[l] as usize;
                let d = &mut list[near_start + nc / N];
                d.id[nc % N] = id;
                d.t0[nc % N] = p.t0[l];
                d.t1[nc % N] = near_t1[l];
                nc += en[l] as usize;
            }
        }
        // Far first on the frame stack, so that near is walked first (front to back).
        for (node, start, count) in [(far, far_start, fc), (near, near_start, nc)] {
            if count == 0 {
                continue;
            }
            if count <= SWITCH.min(N) {
                // The live lanes of a list that goes on as one packet.
                list[start].mask = (1u32 << count) - 1;
            }
            frames.push(Frame { node, start, count });
        }
    }
}

/// The stream mode of a batch (one thread): every octant group traversed once with all its rays.
pub(crate) fn run<A: Answer>(
    tree: &KdTree,
    prims: &PrimitiveSet,
    rays: &[Ray],
    answer: A,
    width: Width,
) -> (TraversalStats, StreamMemory) {
    struct Job<'a, A> {
        tree: &'a KdTree,
        prims: &'a PrimitiveSet,
        rays: &'a [Ray],
        answer: A,
    }
    impl<A: Answer> Kernel for Job<'_, A> {
        type Out = (TraversalStats, StreamMemory);
        #[inline(always)]
        fn run<const N: usize>(self) -> Self::Out {
            let (mut b, groups) = Batch::new(self.tree, self.prims, self.rays, self.answer);
            let mut list: Vec<Lanes<N>> = Vec::new();
            let mut frames = Vec::with_capacity(128);
            let mut scratch = packet::Scratch::<N>::new();
            for (o, group) in groups.iter().enumerate() {
                if !group.is_empty() {
                    traverse(
                        &mut b,
                        &mut list,
                        &mut frames,
                        &mut scratch,
                        group,
                        positive(o),
                    );
                }
            }
            let n = self.rays.len();
            let mem = StreamMemory {
                ray_stack_bytes: list.capacity() * std::mem::size_of::<Lanes<N>>(),
                ray_array_bytes: n * (6 * 4 + 1),
            };
            (b.stats, mem)
        }
    }
    simd::dispatch(
        width,
        Job {
            tree,
            prims,
            rays,
            answer,
        },
    )
}

/// Closest hits of `rays` with the n-ray traversal (one thread).
pub fn intersect(
    tree: &KdTree,
    prims: &PrimitiveSet,
    rays: &[Ray],
    hits: &mut [Hit],
    width: Width,
) -> (TraversalStats, StreamMemory) {
    run(tree, prims, rays, Closest(hits), width)
}

/// Any-hit queries of `rays` with the n-ray traversal (one thread).
pub fn occluded(
    tree: &KdTree,
    prims: &PrimitiveSet,
    rays: &[Ray],
    found: &mut [bool],
    width: Width,
) -> (TraversalStats, StreamMemory) {
    run(tree, prims, rays, AnyHit(found), width)
}
