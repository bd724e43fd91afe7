//! What the packet and stream traversals share: the batch of rays in structure-of-arrays form
//! (the paper's global ray array), the per-ray answer (closest hit or any hit), the grouping of
//! rays by direction signs, and the one per-lane decision at an inner node.
//!
//! Both traversals make, for every ray, exactly the decisions of the standard single-ray
//! traversal (`traverse::standard`): the same split distance `(split - org) * inv_dir`, the same
//! tie rules, the same front-to-back order, the same stop rule at a leaf. Only the grouping of
//! rays differs, so their hits are bit-identical to [`Traversal::Standard`]'s.
//!
//! [`Traversal::Standard`]: super::traverse::Traversal::Standard

use super::packet::{Axes, Lanes};
use super::ray_order::{Blocks, RayOrder};
use super::simd::{
    self, lanes_less, lanes_less_eq, prefetch, Isa, Kernel, PreparedLeaf, RayLanes, Width,
};
use super::traverse::{
    any_among, any_in_subtree, clip_lanes, closest_among, closest_in_subtree, scene_box,
    tested_until, Entry,
};
use crate::geometry::{Aabb, Hit, PrimIndex, PrimitiveSet, Ray, RayTest, TraversalStats, INVALID};
use crate::kdtree::KdTree;
use crate::precision::Intersector;

/// The primitive test of a batch's rays: the ray–triangle test, and the primitive each ray
/// ignores (`OffsetMode::ExcludePrim`'s secondary rays). The SIMD leaf tests (N rays × 1
/// triangle in streams, 1 ray × N triangles in packets) compute every combination bit for bit
/// as the single-ray test does.
#[derive(Clone, Copy, Debug)]
pub struct RayTests<'a> {
    pub intersector: Intersector,
    pub exclude: Excluded<'a>,
}

/// The primitives the rays of a batch ignore.
#[derive(Clone, Copy, Debug)]
pub enum Excluded<'a> {
    /// The same one for every ray (`INVALID`: none).
    All(PrimIndex),
    /// Ray `i` ignores `Each(e)`'s `e[i]`; as long as the rays.
    Each(&'a [PrimIndex]),
}

impl Excluded<'_> {
    /// The primitive ray `i` ignores.
    #[inline(always)]
    pub fn of(&self, i: usize) -> PrimIndex {
        match self {
            Excluded::All(p) => *p,
            Excluded::Each(e) => e[i],
        }
    }

    /// The lanes of the rays `ids` that do not ignore primitive `p` (lanes past the rays:
    /// any).
    #[inline(always)]
    fn keeping<const N: usize>(&self, p: PrimIndex, ids: &[u32; N]) -> u32 {
        match self {
            Excluded::All(e) if *e == p => 0,
            Excluded::All(_) => first::<N>(N),
            Excluded::Each(e) => lanes_where::<N>(|l| e.get(ids[l] as usize) != Some(&p)),
        }
    }
}

impl<'a> RayTests<'a> {
    pub fn new(intersector: Intersector, exclude: Excluded<'a>) -> Self {
        RayTests {
            intersector,
            exclude,
        }
    }

    /// Möller–Trumbore, nothing excluded: the defaults.
    pub const PLAIN: RayTests<'static> = RayTests {
        intersector: Intersector::MollerTrumbore,
        exclude: Excluded::All(INVALID),
    };

    /// The test of ray `i`.
    #[inline(always)]
    fn of(&self, i: usize, ray: &Ray) -> RayTest {
        RayTest::new(ray, self.intersector, self.exclude.of(i))
    }
}

/// What a batch query computes per ray, written once for packets and streams.
pub(crate) trait Answer {
    /// Resets every ray's answer: a miss. Answers are written in full here, before the
    /// traversal: resetting only the rays that miss the tree here and each packet's rays while
    /// the packet before it was traced (so that the first writes, cache misses, overlap the
    /// traversal) did not change packets' speed (the bunny's 1024² primary rays, 16 lanes).
    fn reset(&mut self);
    /// Tests the planes (outside the tree) against ray `i`, not degenerate. False when that
    /// answers the ray (any-hit): it needs no traversal.
    fn planes(&mut self, prims: &PrimitiveSet, i: usize, ray: &Ray, test: &RayTest) -> bool;
    /// Tests ray `i` (its test `test`) against a leaf's prepared primitives; `t_exit` is where
    /// the ray leaves the leaf. True when the ray is finished (the standard traversal's stop
    /// rule). (The leaf, the ray and the width's proof: a struct bundling them would only
    /// rename the arguments.)
    #[allow(clippy::too_many_arguments)]
    fn leaf<const N: usize>(
        &mut self,
        isa: Isa<N>,
        prims: &PrimitiveSet,
        leaf: &PreparedLeaf<N>,
        i: usize,
        ray: &Ray,
        test: &RayTest,
        t_exit: f32,
        stats: &mut TraversalStats,
    ) -> bool;
    /// Tests the rays `ids` (lanes `live`, their tests `tests`, gathered in `lanes`) against a
    /// leaf's primitives `leaf`, N rays per triangle, primitives in leaf order as the single-ray
    /// test; `t_exit` is where each ray leaves the leaf. `kept`: the lanes' [`LaneBounds`] kept
    /// by a packet, read and updated here; `None` (a stream) reads them from the answers.
    /// Returns the lanes that are finished, and counts in `stats` the primitive tests each ray
    /// needed, as the single-ray test counts them.
    #[allow(clippy::too_many_arguments)]
    fn leaf_rays<const N: usize>(
        &mut self,
        isa: Isa<N>,
        prims: &PrimitiveSet,
        leaf: &[u32],
        rays: &[Ray],
        tests: &RayTests,
        lanes: &RayLanes<N>,
        kept: Option<&mut LaneBounds<N>>,
        ids: &[u32; N],
        live: u32,
        t_exit: &[f32; N],
        stats: &mut TraversalStats,
    ) -> u32;
    /// Reads into `bounds` the [`LaneBounds`] of the rays `ids` in lanes `live`; any-hit
    /// queries need none.
    fn read_bounds<const N: usize>(
        &self,
        rays: &[Ray],
        lanes: (&[u32; N], u32),
        bounds: &mut LaneBounds<N>,
    );
    /// Ray `i` through the subtree `start` alone, with the standard single-ray traversal.
    /// True when the ray is finished.
    #[allow(clippy::too_many_arguments)]
    fn single(
        &mut self,
        tree: &KdTree,
        prims: &PrimitiveSet,
        i: usize,
        ray: &Ray,
        test: &RayTest,
        start: Entry,
        stats: &mut TraversalStats,
    ) -> bool;
    /// Starts loading what [`Answer::leaf_rays`] will touch for ray `i`.
    fn prefetch(&self, i: usize);
    /// The lanes `live` of the rays `ids` that an empty leaf finishes (`t_exit`: where each
    /// leaves it): [`Answer::leaf_rays`] for a leaf without primitives, which reads nothing
    /// but the answers ([`Batch::visit_empty_leaf`]).
    fn empty_leaf<const N: usize>(&self, ids: &[u32; N], live: u32, t_exit: &[f32; N]) -> u32;
}

/// Closest hits, one per ray.
pub(crate) struct Closest<'a>(pub &'a mut [Hit]);

impl Answer for Closest<'_> {
    fn reset(&mut self) {
        self.0.fill(Hit::MISS);
    }

    fn planes(&mut self, prims: &PrimitiveSet, i: usize, ray: &Ray, test: &RayTest) -> bool {
        prims.intersect_planes(ray, test, &mut self.0[i]);
        true
    }

    #[inline(always)]
    fn leaf<const N: usize>(
        &mut self,
        isa: Isa<N>,
        prims: &PrimitiveSet,
        leaf: &PreparedLeaf<N>,
        i: usize,
        ray: &Ray,
        test: &RayTest,
        t_exit: f32,
        stats: &mut TraversalStats,
    ) -> bool {
        // The blocks' triangles here; the rest are counted by the single-ray leaf test.
        stats.prim_tests += (leaf.count - leaf.others.len()) as u64;
        let hit = &mut self.0[i];
        for b in leaf.blocks {
            b.intersect(isa, ray, test, hit);
        }
        closest_among(prims, ray, test, leaf.others, hit, stats);
        // Strictly before the exit, as `traverse::common::Closest`.
        hit.t < t_exit
    }

    #[inline(always)]
    fn leaf_rays<const N: usize>(
        &mut self,
        isa: Isa<N>,
        prims: &PrimitiveSet,
        leaf: &[u32],
        rays: &[Ray],
        tests: &RayTests,
        lanes: &RayLanes<N>,
        kept: Option<&mut LaneBounds<N>>,
        ids: &[u32; N],
        live: u32,
        t_exit: &[f32; N],
        stats: &mut TraversalStats,
    ) -> u32 {
        // A closest hit tests every primitive of the leaf.
        stats.prim_tests += live.count_ones() as u64 * leaf.len() as u64;
        let lane_tests = lanes.tests(tests.intersector);
        // Copied out (and back): captured by the closures below, the bounds would live in
        // memory.
        let LaneBounds {
            mut hit_t,
            mut bound,
        } = match &kept {
            Some(k) => **k,
            None => {
                let mut fresh = LaneBounds::of(lanes);
                self.read_bounds(rays, (ids, live), &mut fresh);
                fresh
            }
        };
        let update = |hit: &Hit, l: usize, hit_t: &mut [f32; N], bound: &mut [f32; N]| {
            hit_t[l] = hit.t;
            bound[l] = hit.bound(&rays[ids[l] as usize]);
        };
        for &p in leaf {
            if (p as usize) < prims.triangles.len() {
                let rows = prims.triangle_rows(p as usize, tests.intersector);
                let (t, u, v) = lanes.triangle(rows, &lane_tests, &bound);
                let hits = lanes_less(isa, &t, &[f32::INFINITY; N]);
                for_lanes(live & hits & tests.exclude.keeping(p, ids), |l| {
                    let hit = &mut self.0[ids[l] as usize];
                    hit.offer(t[l], u[l], v[l], p);
                    update(hit, l, &mut hit_t, &mut bound);
                });
            } else {
                for_lanes(live, |l| {
                    let (i, hit) = (ids[l] as usize, &mut self.0[ids[l] as usize]);
                    prims.intersect(p, &rays[i], &tests.of(i, &rays[i]), hit);
                    update(hit, l, &mut hit_t, &mut bound);
                });
            }
        }
        if let Some(k) = kept {
            *k = LaneBounds { hit_t, bound };
        }
        // Strictly before the exit, as `traverse::common::Closest`.
        live & lanes_less(isa, &hit_t, t_exit)
    }

    #[inline(always)]
    fn read_bounds<const N: usize>(
        &self,
        rays: &[Ray],
        (ids, live): (&[u32; N], u32),
        bounds: &mut LaneBounds<N>,
    ) {
        for_lanes(live, |l| {
            let i = ids[l] as usize;
            bounds.hit_t[l] = self.0[i].t;
            bounds.bound[l] = self.0[i].bound(&rays[i]);
        });
    }

    #[inline(always)]
    fn single(
        &mut self,
        tree: &KdTree,
        prims: &PrimitiveSet,
        i: usize,
        ray: &Ray,
        test: &RayTest,
        start: Entry,
        stats: &mut TraversalStats,
    ) -> bool {
        closest_in_subtree(tree, prims, ray, test, start, &mut self.0[i], stats)
    }

    #[inline(always)]
    fn prefetch(&self, i: usize) {
        if let Some(h) = self.0.get(i) {
            prefetch(h);
        }
    }

    #[inline(always)]
    fn empty_leaf<const N: usize>(&self, ids: &[u32; N], live: u32, t_exit: &[f32; N]) -> u32 {
        // Strictly before the exit, as `traverse::common::Closest`. A loop over the live lanes,
        // not `lanes_where`: LLVM kept that fold as a call, compiled without the kernel's SIMD
        // features (see `simd`).
        let (mut done, mut m) = (0u32, live);
        while m != 0 {
            let l = m.trailing_zeros() as usize;
            m &= m - 1;
            done |= u32::from(self.0[ids[l] as usize].t < t_exit[l]) << l;
        }
        done
    }
}

/// Any hit in the ray's window (shadow rays), one flag per ray.
pub(crate) struct AnyHit<'a>(pub &'a mut [bool]);

impl Answer for AnyHit<'_> {
    fn reset(&mut self) {
        self.0.fill(false);
    }

    fn planes(&mut self, prims: &PrimitiveSet, i: usize, ray: &Ray, test: &RayTest) -> bool {
        let mut planes = Hit::MISS;
        prims.intersect_planes(ray, test, &mut planes);
        self.0[i] = planes.is_hit();
        !self.0[i]
    }

    #[inline(always)]
    fn leaf<const N: usize>(
        &mut self,
        isa: Isa<N>,
        prims: &PrimitiveSet,
        leaf: &PreparedLeaf<N>,
        i: usize,
        ray: &Ray,
        test: &RayTest,
        _t_exit: f32,
        stats: &mut TraversalStats,
    ) -> bool {
        // The blocks' triangles here, up to the one that ends the search; the rest are counted
        // by the single-ray leaf test.
        let triangles = leaf.count - leaf.others.len();
        let found = leaf.blocks.iter().enumerate().any(|(k, b)| {
            let stop = b.occluders(isa, ray, test);
            stats.prim_tests += tested_until(stop, (triangles - k * N).min(N));
            stop != 0
        }) || any_among(prims, ray, test, leaf.others, stats);
        self.0[i] = found;
        found
    }

    #[inline(always)]
    fn leaf_rays<const N: usize>(
        &mut self,
        isa: Isa<N>,
        prims: &PrimitiveSet,
        leaf: &[u32],
        rays: &[Ray],
        tests: &RayTests,
        lanes: &RayLanes<N>,
        _: Option<&mut LaneBounds<N>>,
        ids: &[u32; N],
        live: u32,
        _t_exit: &[f32; N],
        stats: &mut TraversalStats,
    ) -> u32 {
        let lane_tests = lanes.tests(tests.intersector);
        let mut found = 0u32;
        for &p in leaf {
            // A ray stops at the first primitive in its way, as the single-ray test does;
            // counted so (every primitive for every ray was up to 44% more on spheres).
            let searching = live & !found;
            if searching == 0 {
                break;
            }
            stats.prim_tests += searching.count_ones() as u64;
            if (p as usize) < prims.triangles.len() {
                let rows = prims.triangle_rows(p as usize, tests.intersector);
                let (t, _, _) = lanes.triangle(rows, &lane_tests, &lanes.tmax);
                found |= lanes_less(isa, &t, &[f32::INFINITY; N]) & tests.exclude.keeping(p, ids);
            } else {
                for_lanes(live & !found, |l| {
                    let (i, mut hit) = (ids[l] as usize, Hit::MISS);
                    if prims.intersect(p, &rays[i], &tests.of(i, &rays[i]), &mut hit) {
                        found |= 1 << l;
                    }
                });
            }
        }
        let found = found & live;
        // Only the rays found: the others' flags are still false (as the finished flags in
        // `Batch::leaf_rays`).
        for_lanes(found, |l| self.0[ids[l] as usize] = true);
        found
    }

    #[inline(always)]
    fn single(
        &mut self,
        tree: &KdTree,
        prims: &PrimitiveSet,
        i: usize,
        ray: &Ray,
        test: &RayTest,
        start: Entry,
        stats: &mut TraversalStats,
    ) -> bool {
        self.0[i] = any_in_subtree(tree, prims, ray, test, start, stats);
        self.0[i]
    }

    #[inline(always)]
    fn prefetch(&self, _: usize) {}

    #[inline(always)]
    fn empty_leaf<const N: usize>(&self, _: &[u32; N], _: u32, _: &[f32; N]) -> u32 {
        0
    }

    #[inline(always)]
    fn read_bounds<const N: usize>(&self, _: &[Ray], _: (&[u32; N], u32), _: &mut LaneBounds<N>) {}
}

/// Each lane's closest `t` so far and its [`Hit::bound`], for the N-rays × 1-triangle leaf
/// test ([`Answer::leaf_rays`]), which updates them only when a lane's hit changes: recomputed
/// for every lane at every triangle, the bound (a `next_up` per lane) cost a twentieth of a
/// stream's instructions. A stream, which meets different rays at each leaf, reads them per leaf
/// visit; a packet keeps them across its leaves ([`PacketLanes`]).
#[derive(Clone, Copy)]
pub(crate) struct LaneBounds<const N: usize> {
    hit_t: [f32; N],
    bound: [f32; N],
}

impl<const N: usize> LaneBounds<N> {
    /// No hit yet: every candidate below the ray's `tmax`.
    #[inline(always)]
    fn of(rays: &RayLanes<N>) -> Self {
        LaneBounds {
            hit_t: [f32::INFINITY; N],
            bound: rays.tmax,
        }
    }
}

/// A packet's rays in structure-of-arrays form and their [`LaneBounds`], read once (or taken
/// from the packet's block) for all its leaves that take the N-rays × 1-triangle test
/// ([`Batch::visit_packet_leaf`]), and [`Batch::reread`] after tests made elsewhere.
pub(crate) struct PacketLanes<const N: usize> {
    rays: RayLanes<N>,
    bounds: LaneBounds<N>,
}

/// The batch: rays, their origins and reciprocal directions by axis (one array per axis, so a
/// node step gathers one pair per ray: origin and reciprocal direction share a cache line), the
/// finished flags and the answer.
///
/// `WATERTIGHT` is the rays' intersector as a constant (the watertight test or
/// Möller–Trumbore), so that each is compiled without the other's branches in its leaf tests:
/// read from the batch, it cost the default path 6–10% on the bunny's streams.
pub(crate) struct Batch<'a, A, const WATERTIGHT: bool> {
    pub tree: &'a KdTree,
    pub prims: &'a PrimitiveSet,
    pub rays: &'a [Ray],
    /// `split[a][i]` = (origin, reciprocal direction) of ray `i` on axis `a`, for the rays
    /// [`Batch::keep`] kept (a packet traversed as it is set up has them in vectors; empty
    /// until a ray is kept).
    pub split: [Vec<[f32; 2]>; 3],
    /// The single-ray traversal's box, padded for the watertight test: the rays are clipped
    /// to it.
    bounds: Aabb,
    /// Rays whose answer is final: dropped from every later list (the paper's "rayos
    /// terminados").
    pub done: Vec<bool>,
    /// How many rays are done so far: a list written when it was this value needs no filtering.
    pub finished: usize,
    pub answer: A,
    /// The primitives the rays ignore.
    pub exclude: Excluded<'a>,
    pub stats: TraversalStats,
}

/// A block of up to N rays set up for traversal ([`Batch::block`]).
pub(crate) struct Block<const N: usize> {
    /// The rays to traverse (`mask`: inside the root voxel, not degenerate, not finished by a
    /// plane; none when the tree is empty) and their segments there.
    pub lanes: Lanes<N>,
    pub axes: Axes<N>,
    pub rays: RayLanes<N>,
}

impl<const N: usize> Block<N> {
    /// The lanes to traverse whose direction is negative on each axis: their octants, as
    /// [`octant`] reads them from the rays. A reciprocal keeps its direction's sign, `-0.0`
    /// giving `-inf`, and is never zero or NaN for a sound ray (a finite direction).
    #[inline(always)]
    fn negative(&self, isa: Isa<N>) -> [u32; 3] {
        let mut negative = [0; 3];
        for (n, inv) in negative.iter_mut().zip(&self.axes.inv) {
            *n = self.lanes.mask & lanes_less(isa, inv, &[0.0; N]);
        }
        negative
    }

    /// The octant of all the lanes to traverse, when there are some and they share one.
    #[inline(always)]
    pub fn octant(&self, isa: Isa<N>) -> Option<usize> {
        let live = self.lanes.mask;
        let negative = self.negative(isa);
        let shared = (0..3).all(|a| negative[a] == 0 || negative[a] == live);
        (live != 0 && shared).then(|| octant_where(|a| negative[a] != 0))
    }
}

/// A ray entering the tree: its index and its segment `[t0, t1]` inside the root voxel.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Root {
    pub id: u32,
    pub t0: f32,
    pub t1: f32,
}

impl<'a, A: Answer, const WATERTIGHT: bool> Batch<'a, A, WATERTIGHT> {
    /// The rays' ray–triangle test.
    pub const INTERSECTOR: Intersector = if WATERTIGHT {
        Intersector::Watertight
    } else {
        Intersector::MollerTrumbore
    };

    /// The rays' primitive tests, built where they are used (not read from the batch), so that
    /// the intersector stays a constant.
    #[inline(always)]
    fn tests(&self) -> RayTests<'a> {
        RayTests::new(Self::INTERSECTOR, self.exclude)
    }

    /// A batch of `rays` with its answer reset; [`Batch::group`] or [`Batch::block`] then sets
    /// its rays up.
    pub fn new(
        tree: &'a KdTree,
        prims: &'a PrimitiveSet,
        rays: &'a [Ray],
        exclude: Excluded<'a>,
        mut answer: A,
    ) -> Self {
        let n = rays.len();
        assert!(
            u32::try_from(n).is_ok(),
            "a packet or stream batch holds at most u32::MAX rays, not {n}"
        );
        if let Excluded::Each(e) = exclude {
            assert_eq!(e.len(), n, "one excluded primitive per ray");
        }
        answer.reset();
        Batch {
            tree,
            prims,
            rays,
            split: Default::default(),
            bounds: scene_box(tree, Self::INTERSECTOR),
            done: vec![false; n],
            finished: 0,
            answer,
            exclude,
            stats: TraversalStats::default(),
        }
    }

    /// Sets every ray up ([`Batch::block`]) and returns them grouped by octant (the signs of
    /// the direction, `-0.0` negative as in `TRay::positive`): within a group every node has
    /// the same near child for every ray, so the group can be traversed front to back at once
    /// (paper: ≤ 8 traversals). The groups keep the order of the blocks (`RayOrder`): streams
    /// take their rays in it (packets set their blocks up and group only the mixed ones).
    #[inline(always)]
    pub fn group<const N: usize>(&mut self, isa: Isa<N>, order: RayOrder) -> [Vec<Root>; 8] {
        let mut groups: [Vec<Root>; 8] = Default::default();
        for (ids, live) in Blocks::<N>::new(self.rays.len(), order) {
            let block = self.block(isa, ids, live);
            self.keep(isa, &block, &mut groups);
        }
        groups
    }

    /// Sets up the rays `ids` (lanes `live`) as vectors: the reciprocal directions, the
    /// degenerate rays (`Ray::is_degenerate`) and the clipping to the root voxel
    /// (`traverse::clip_lanes`), with the same operations per lane, so the segments are
    /// bit-identical to the single-ray ones; the planes, which lie outside the tree, are
    /// tested here as the single-ray query does. Ray by ray, this setup cost a fifth of an
    /// 8-ray packet traversal's instructions.
    #[inline(always)]
    pub fn block<const N: usize>(&mut self, isa: Isa<N>, ids: [u32; N], live: u32) -> Block<N> {
        let rays = self.rays;
        // The rays of the tiles a few steps ahead, one prefetch per cache line (two rays):
        // the gathers below missed the caches on an image's rows (32 bytes per ray, read
        // once); loaded ahead, 16-lane packets ran 1.05x as fast on the bunny's 1024² set.
        for l in (0..N).step_by(2) {
            if let Some(r) = rays.get(ids[l] as usize + AHEAD) {
                prefetch(r);
            }
        }
        let r = RayLanes::<N>::gather(isa, rays, &ids);
        // Loops rather than `array::from_fn` and `array::map`, which LLVM left as calls here,
        // compiled without the kernel's SIMD features (see `simd`).
        let mut inv = [[0.0f32; N]; 3];
        for (inv, dir) in inv.iter_mut().zip(&r.dir) {
            for (i, d) in inv.iter_mut().zip(dir) {
                *i = 1.0 / d;
            }
        }
        let valid = live & sound(isa, &r);
        let mut todo = valid;
        if !self.prims.planes.is_empty() {
            let tests = self.tests();
            for_lanes(valid, |l| {
                let i = ids[l] as usize;
                let ray = &rays[i];
                if !self.answer.planes(self.prims, i, ray, &tests.of(i, ray)) {
                    todo &= !(1 << l);
                }
            });
        }
        if self.tree.nodes.is_empty() {
            todo = 0;
        }
        let (t0, t1, inside) = clip_lanes(isa, &self.bounds, &r.org, &inv, r.tmin, r.tmax);
        Block {
            lanes: Lanes {
                id: ids,
                t0,
                t1,
                mask: todo & inside,
            },
            axes: Axes { org: r.org, inv },
            rays: r,
        }
    }

    /// Keeps the rays of `block` for a later traversal: their origins and reciprocal
    /// directions in [`Batch::split`] (made on the first keep: packets may need none), their
    /// roots in the group of their octant.
    ///
    /// Measured and dropped: a block of consecutive rays of one octant (a stream's, always)
    /// written with whole-block stores (every lane's origin and reciprocal, its roots pushed
    /// without an octant per lane), 0.999–1.022× on the bunny's `incoherent_262144`, 0.994×
    /// on the dragon's `incoherent_131072`, 1.005× on the Snowden bust (16 lanes, one thread,
    /// 20–30 paired runs in one process).
    #[inline(always)]
    pub fn keep<const N: usize>(
        &mut self,
        isa: Isa<N>,
        block: &Block<N>,
        groups: &mut [Vec<Root>; 8],
    ) {
        let Block { lanes, axes, .. } = block;
        if lanes.mask != 0 && self.split[0].is_empty() {
            self.split = [(); 3].map(|_| vec![[0.0; 2]; self.rays.len()]);
        }
        let negative = block.negative(isa);
        for_lanes(lanes.mask, |l| {
            let i = lanes.id[l] as usize;
            for a in 0..3 {
                self.split[a][i] = [axes.org[a][l], axes.inv[a][l]];
            }
            groups[octant_where(|a| negative[a] >> l & 1 != 0)].push(Root {
                id: lanes.id[l],
                t0: lanes.t0[l],
                t1: lanes.t1[l],
            });
        });
    }

    /// Starts loading ray `i` and its answer, a few rays before a stream's leaf visit
    /// ([`Batch::visit_leaf_rays`]) needs them.
    #[inline(always)]
    pub fn prefetch_leaf(&self, i: u32) {
        let i = i as usize;
        if let Some(r) = self.rays.get(i) {
            prefetch(r);
        }
        self.answer.prefetch(i);
    }

    /// The packet's rays `ids` (lanes `live`) for [`Batch::visit_packet_leaf`]: `known` when
    /// the caller has them, else gathered (an index past the end reads the last ray, as
    /// [`RayLanes::gather`]).
    #[inline(always)]
    pub fn packet_lanes<const N: usize>(
        &self,
        isa: Isa<N>,
        ids: &[u32; N],
        live: u32,
        known: Option<RayLanes<N>>,
    ) -> PacketLanes<N> {
        let rays = known.unwrap_or_else(|| RayLanes::gather(isa, self.rays, ids));
        let mut bounds = LaneBounds::of(&rays);
        self.answer.read_bounds(self.rays, (ids, live), &mut bounds);
        PacketLanes { rays, bounds }
    }

    /// Brings the bounds of lanes `live` in `lanes` up to date, after tests that did not go
    /// through them.
    #[inline(always)]
    pub fn reread<const N: usize>(&self, lanes: &mut PacketLanes<N>, ids: &[u32; N], live: u32) {
        self.answer
            .read_bounds(self.rays, (ids, live), &mut lanes.bounds);
    }

    /// Tests the rays `ids` (lanes `live`, segments ending at `t_exit`) of a stream against
    /// leaf `leaf`, N rays per triangle, and marks the finished ones done.
    #[inline(always)]
    pub fn visit_leaf_rays<const N: usize>(
        &mut self,
        isa: Isa<N>,
        leaf: &[u32],
        ids: &[u32; N],
        live: u32,
        t_exit: &[f32; N],
    ) {
        let lanes = RayLanes::gather(isa, self.rays, ids);
        self.leaf_rays(isa, leaf, (&lanes, None), ids, live, t_exit);
    }

    /// [`Batch::visit_leaf_rays`] for a packet's rays, gathered in `lanes`; returns the lanes
    /// finished.
    #[inline(always)]
    pub fn visit_packet_leaf<const N: usize>(
        &mut self,
        isa: Isa<N>,
        leaf: &[u32],
        lanes: &mut PacketLanes<N>,
        ids: &[u32; N],
        live: u32,
        t_exit: &[f32; N],
    ) -> u32 {
        let kept = (&lanes.rays, Some(&mut lanes.bounds));
        self.leaf_rays(isa, leaf, kept, ids, live, t_exit)
    }

    /// Both of the above: the answer's [`Answer::leaf_rays`], the statistics and the finished
    /// flags.
    #[inline(always)]
    fn leaf_rays<const N: usize>(
        &mut self,
        isa: Isa<N>,
        leaf: &[u32],
        (lanes, kept): (&RayLanes<N>, Option<&mut LaneBounds<N>>),
        ids: &[u32; N],
        live: u32,
        t_exit: &[f32; N],
    ) -> u32 {
        self.stats.leaves_visited += live.count_ones() as u64;
        let done = self.answer.leaf_rays(
            isa,
            self.prims,
            leaf,
            self.rays,
            &self.tests(),
            lanes,
            kept,
            ids,
            live,
            t_exit,
            &mut self.stats,
        );
        // Only the lanes that finished: a ray's flag starts false and is never cleared, and
        // most leaf visits finish no ray. Writing every live lane's flag (a loop whose length
        // varies from visit to visit, its exit mispredicted) made 16-lane packets 7% slower on
        // the bunny's and dragon's primary sets.
        for_lanes(done, |l| self.done[ids[l] as usize] = true);
        self.finished += done.count_ones() as usize;
        done
    }

    /// [`Batch::visit_leaf_rays`] (and [`Batch::visit_packet_leaf`]) for a leaf without
    /// primitives: the rays whose hit lies before the leaf's exit `t_exit` are finished, and
    /// nothing but their hits is read. Returns the lanes finished.
    ///
    /// The SAH's empty bonus cuts empty space off into empty leaves, and incoherent rays cross
    /// many: on the bunny's `incoherent_262144` set, 4591 of a stream's 5011 leaf visits (411 K
    /// of its 528 K rays) and 53 K of its packets' 110 K leaf visits (186 K of 310 K lanes) were
    /// to empty leaves, where the full test gathered every ray's origin, direction and bounds
    /// (a packet's for its first N-rays × 1-triangle leaf) to test no triangle. Skipped so, with
    /// the same hits and statistics, 16-lane streams ran 1.07× as fast on that set, 1.05× on
    /// 262 K incoherent rays of the Snowden bust, 1.03× on the dragon's `incoherent_131072`,
    /// 1.10× on the bunny's `primary_262144` and 1.09× on its `diffuse_68202`; packets 1.04×
    /// on the bunny's incoherent set (one thread, AMD EPYC, the two paths alternated in one
    /// process, medians of 20–30 paired runs). A stream asking for the next chunk's answers
    /// only, or for nothing, ahead of an empty leaf's chunks ran alike (0.99–1.00×).
    #[inline(always)]
    pub fn visit_empty_leaf<const N: usize>(
        &mut self,
        ids: &[u32; N],
        live: u32,
        t_exit: &[f32; N],
    ) -> u32 {
        self.stats.leaves_visited += live.count_ones() as u64;
        let done = self.answer.empty_leaf(ids, live, t_exit);
        for_lanes(done, |l| self.done[ids[l] as usize] = true);
        self.finished += done.count_ones() as usize;
        done
    }

    /// Traces ray `i` through the subtree `start` alone and marks it done when finished.
    #[inline(always)]
    pub fn trace_single(&mut self, i: u32, start: Entry) {
        let i = i as usize;
        let ray = &self.rays[i];
        let done = self.answer.single(
            self.tree,
            self.prims,
            i,
            ray,
            &self.tests().of(i, ray),
            start,
            &mut self.stats,
        );
        self.done[i] = done;
        self.finished += done as usize;
    }

    /// Tests ray `i` against a prepared leaf and marks it done when finished.
    #[inline(always)]
    pub fn visit_leaf<const N: usize>(
        &mut self,
        isa: Isa<N>,
        leaf: &PreparedLeaf<N>,
        i: u32,
        t_exit: f32,
    ) -> bool {
        let (i, ray) = (i as usize, &self.rays[i as usize]);
        self.stats.leaves_visited += 1;
        let done = self.answer.leaf(
            isa,
            self.prims,
            leaf,
            i,
            ray,
            &self.tests().of(i, ray),
            t_exit,
            &mut self.stats,
        );
        self.done[i] = done;
        self.finished += done as usize;
        done
    }
}

/// How many rays ahead of a block [`Batch::block`] prefetches: a few tiles along an image's
/// rows, a few blocks of rays as given (16, 48 and 128 ran alike on the bunny's 1024² rays).
const AHEAD: usize = 32;

/// The lanes of rays that are not degenerate (`Ray::is_degenerate`, lane by lane): finite
/// origin and direction, a direction other than zero, a window `tmin <= tmax` without NaN.
#[inline(always)]
fn sound<const N: usize>(isa: Isa<N>, r: &RayLanes<N>) -> u32 {
    let inf = [f32::INFINITY; N];
    let mut ok = lanes_less_eq(isa, &r.tmin, &r.tmax);
    // Sum of the direction's magnitudes: above zero unless every component is ±0 (finite
    // components: a sum that overflows is infinite, still above zero).
    let mut length = [0.0f32; N];
    for a in 0..3 {
        ok &= lanes_less(isa, &r.org[a].map(f32::abs), &inf);
        ok &= lanes_less(isa, &r.dir[a].map(f32::abs), &inf);
        for (length, d) in length.iter_mut().zip(&r.dir[a]) {
            *length += d.abs();
        }
    }
    ok & lanes_less(isa, &[0.0; N], &length)
}

/// Lane mask of the first `count` lanes of N (N ≤ 16).
#[inline(always)]
pub(crate) fn first<const N: usize>(count: usize) -> u32 {
    (1u32 << count.min(N)) - 1
}

/// Calls `f` with each lane set in `mask`, lowest first.
#[inline(always)]
pub(crate) fn for_lanes(mut mask: u32, mut f: impl FnMut(usize)) {
    while mask != 0 {
        f(mask.trailing_zeros() as usize);
        mask &= mask - 1;
    }
}

/// The mask of the N lanes for which `f` holds.
#[inline(always)]
pub(crate) fn lanes_where<const N: usize>(f: impl Fn(usize) -> bool) -> u32 {
    (0..N).fold(0u32, |m, l| m | (f(l) as u32) << l)
}

/// Octant index of a ray: bit `a` set when the direction is negative on axis `a`.
#[inline]
pub(crate) fn octant(ray: &Ray) -> usize {
    octant_where(|a| ray.dir[a].is_sign_negative())
}

/// The octant index whose bit `a` is set where `negative(a)` holds.
#[inline(always)]
fn octant_where(negative: impl Fn(usize) -> bool) -> usize {
    (0..3).filter(|&a| negative(a)).fold(0, |o, a| o | 1 << a)
}

/// A way of tracing a whole batch N lanes at a time (packets, streams): how it sets the rays
/// of a new [`Batch`] up, in blocks taken in `order`, and traverses them.
pub(crate) trait Mode {
    type Out;
    fn trace<const N: usize, A: Answer, const WATERTIGHT: bool>(
        isa: Isa<N>,
        b: &mut Batch<A, WATERTIGHT>,
        order: RayOrder,
    ) -> Self::Out;
}

/// Traces `rays` with mode `M` at the lane width `width` asks for (compiled for its instruction
/// set by [`simd::dispatch`]).
pub(crate) fn run<M: Mode, A: Answer>(
    tree: &KdTree,
    prims: &PrimitiveSet,
    (rays, order): (&[Ray], RayOrder),
    tests: RayTests,
    answer: A,
    width: Width,
) -> M::Out {
    struct Job<'a, A, M, const WATERTIGHT: bool> {
        tree: &'a KdTree,
        prims: &'a PrimitiveSet,
        rays: &'a [Ray],
        order: RayOrder,
        exclude: Excluded<'a>,
        answer: A,
        mode: std::marker::PhantomData<M>,
    }
    impl<A: Answer, M: Mode, const WATERTIGHT: bool> Kernel for Job<'_, A, M, WATERTIGHT> {
        type Out = M::Out;
        #[inline(always)]
        fn run<const N: usize>(self, isa: Isa<N>) -> M::Out {
            let mut b = Batch::<A, WATERTIGHT>::new(
                self.tree,
                self.prims,
                self.rays,
                self.exclude,
                self.answer,
            );
            M::trace(isa, &mut b, self.order)
        }
    }
    fn job<'a, A, M, const WATERTIGHT: bool>(
        (tree, prims, rays, order): (&'a KdTree, &'a PrimitiveSet, &'a [Ray], RayOrder),
        exclude: Excluded<'a>,
        answer: A,
    ) -> Job<'a, A, M, WATERTIGHT> {
        Job {
            tree,
            prims,
            rays,
            order,
            exclude,
            answer,
            mode: std::marker::PhantomData,
        }
    }
    // One kernel per intersector (see `Batch`), each its own function: both in one made the
    // default path's code slower (a function too large for LLVM to keep its values in
    // registers).
    let scene = (tree, prims, rays, order);
    match tests.intersector {
        Intersector::MollerTrumbore => {
            simd::dispatch(width, job::<A, M, false>(scene, tests.exclude, answer))
        }
        Intersector::Watertight => {
            simd::dispatch(width, job::<A, M, true>(scene, tests.exclude, answer))
        }
    }
}

/// Whether the direction is positive on each axis, for the rays of octant `o`.
pub(crate) fn positive(o: usize) -> [bool; 3] {
    [o & 1 == 0, o & 2 == 0, o & 4 == 0]
}

/// Where N rays go at an inner node, from each ray's split distance `ts` and segment `[t0, t1]`:
/// the cases of `traverse::common::step`, lane by lane (`ts <= t0` or NaN: far only; `ts >= t1`:
/// near only; else both, cut at `ts`).
pub(crate) struct Split<const N: usize> {
    /// Lanes entering the near child, and the end of their segment there.
    pub near: u32,
    pub near_t1: [f32; N],
    /// Lanes entering the far child, and the start of their segment there.
    pub far: u32,
    pub far_t0: [f32; N],
}

impl<const N: usize> Split<N> {
    /// The split of the lanes `live` at plane `split`, for rays with origins `org` and
    /// reciprocal directions `inv` on the node's axis. Each result is one vector operation
    /// (masks by [`lanes_less`], segment ends by min/max selects): a lane-by-lane decision made
    /// LLVM build the masks one lane at a time, 60 instructions per 8-ray packet step.
    #[inline(always)]
    pub fn new(
        isa: Isa<N>,
        split: f32,
        org: &[f32; N],
        inv: &[f32; N],
        t0: &[f32; N],
        t1: &[f32; N],
        live: u32,
    ) -> Self {
        let mut ts = [0.0f32; N];
        for l in 0..N {
            ts[l] = (split - org[l]) * inv[l];
        }
        let (mut near_t1, mut far_t0) = ([0.0f32; N], [0.0f32; N]);
        for l in 0..N {
            near_t1[l] = if ts[l] < t1[l] { ts[l] } else { t1[l] };
            far_t0[l] = if ts[l] > t0[l] { ts[l] } else { t0[l] };
        }
        let near = lanes_less(isa, t0, &ts);
        Split {
            near: near & live,
            near_t1,
            far: (!near | lanes_less(isa, &ts, t1)) & live,
            far_t0,
        }
    }
}
