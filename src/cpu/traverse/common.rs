//! Pieces every traversal shares: the prepared ray, the one inner-node decision, the descent to
//! a leaf, the leaf visit (closest hit or any hit) and the two stacks.
//!
//! Every distance to a split or face plane is computed by [`TRay::dist`], `(plane - org) *
//! inv_dir`. The thesis divides by the direction; one formula with one rounding everywhere is what
//! makes the seven traversals return bit-identical hits, because they then agree on every leaf's
//! exit distance and on every side decision.

use crate::cpu::batch::octant;
use crate::cpu::simd::{lanes_less, lanes_less_eq, Isa, TriBlock};
use crate::geometry::{Aabb, Hit, PrimitiveSet, Ray, RayTest, TraversalStats, TriangleTest};
use crate::kdtree::{KdNode, KdTree};

/// The ray as the traversals read it, with the reciprocal direction (`±inf` for `±0` components).
///
/// Origin and reciprocal are arrays, not `Vec3`s: indexing a `Vec3` by a run-time axis is a
/// `match`, which LLVM compiles to an indirect jump through a table, one per node visited and
/// mispredicted whenever the split axis changes. An array index is a plain load.
#[derive(Clone, Copy, Debug)]
pub(crate) struct TRay {
    pub ray: Ray,
    org: [f32; 3],
    pub inv_dir: [f32; 3],
    /// Bit `axis` set where the direction is negative ([`Self::positive`] false): the ray's
    /// octant, as packets and streams group rays.
    negative: u32,
}

impl TRay {
    pub fn new(ray: &Ray) -> Self {
        TRay {
            ray: *ray,
            org: ray.org.to_array(),
            inv_dir: ray.dir.recip().to_array(),
            negative: octant(ray) as u32,
        }
    }

    /// 1 where the direction on `axis` is negative, else 0. A step picks the near child by it,
    /// from a mask in a register rather than from the sign of `inv_dir[axis]`: on that load
    /// LLVM chose the child with a conditional move in the standard traversal, so every step's
    /// next node waited on one more load (the restart family's loop got a branch). With the
    /// mask the standard traversal ran the bunny's primary rays 1.14× as fast (one thread; it
    /// had run at 0.84× the short-stack traversal), the dragon's 1.1×, and CPU renders of the
    /// bunny 1.12×, the others as fast as before. Written as an `if`: the near child as
    /// `index + bit` cost the restart family 4–10%.
    #[inline]
    pub fn negative_bit(&self, axis: usize) -> u32 {
        self.negative >> axis & 1
    }

    /// Ray parameter where the ray meets the plane `x[axis] = plane`. NaN when the ray lies in
    /// the plane (zero direction component, origin on the plane); `±inf` when it runs parallel.
    #[inline]
    pub fn dist(&self, axis: usize, plane: f32) -> f32 {
        (plane - self.org[axis]) * self.inv_dir[axis]
    }

    /// Direction sign on `axis`, with `-0.0` negative: the sign of a zero component still picks
    /// a side, so a ray lying in a split plane is sent to exactly one child, consistently (and
    /// the reciprocal keeps the direction's sign: `1 / -0 = -inf`).
    #[inline]
    pub fn positive(&self, axis: usize) -> bool {
        self.negative_bit(axis) == 0
    }
}

/// The parametric segment `[t0, t1]` of the ray inside the closed box, clamped to the ray's window,
/// or `None` when the ray misses it: [`clip_lanes`] with one lane.
pub(crate) fn clip(bounds: &Aabb, ray: &TRay) -> Option<(f32, f32)> {
    let (t0, t1, inside) = clip_lanes::<1>(
        Isa::baseline(),
        bounds,
        &ray.org.map(|x| [x]),
        &ray.inv_dir.map(|x| [x]),
        [ray.ray.tmin],
        [ray.ray.tmax],
    );
    (inside == 1).then_some((t0[0], t1[0]))
}

/// The segments `[t0, t1]` of N rays (origins `org`, reciprocal directions `inv`, windows
/// `[tmin, tmax]`) inside the closed box, and the mask of the lanes whose segment is not empty.
/// `Aabb::clip_ray`'s slab test (near and far planes chosen by the direction sign, so a ray
/// lying in a face plane is inside the closed slab for either sign of zero), written over lanes
/// so that the batch setup of packets and streams clips N rays as vectors, with the single-ray
/// clip's operations.
#[inline(always)]
pub(crate) fn clip_lanes<const N: usize>(
    isa: Isa<N>,
    bounds: &Aabb,
    org: &[[f32; N]; 3],
    inv: &[[f32; N]; 3],
    tmin: [f32; N],
    tmax: [f32; N],
) -> ([f32; N], [f32; N], u32) {
    let (mut t0, mut t1) = (tmin, tmax);
    for a in 0..3 {
        let (min, max) = (bounds.min[a], bounds.max[a]);
        for l in 0..N {
            // The reciprocal keeps the direction's sign (`TRay::positive`).
            let (near, far) = if inv[a][l].is_sign_positive() {
                (min, max)
            } else {
                (max, min)
            };
            let near = (near - org[a][l]) * inv[a][l];
            let far = (far - org[a][l]) * inv[a][l];
            // NaN compares false: no clipping by a plane the ray lies in.
            t0[l] = if near > t0[l] { near } else { t0[l] };
            t1[l] = if far < t1[l] { far } else { t1[l] };
        }
    }
    // `t0 = inf` is a ray outside a slab it runs parallel to.
    let inside = lanes_less_eq(isa, &t0, &t1) & lanes_less(isa, &t0, &[f32::INFINITY; N]);
    (t0, t1, inside)
}

/// What the segment `[t0, t1]` does at an inner node (the three cases of the thesis' pseudo-code).
/// `near` is the child the ray enters first (by the direction sign), `far` the other.
#[derive(Clone, Copy, Debug)]
pub(super) enum Crossing {
    /// Only one child is crossed; the descent continues there with the same segment.
    One { child: u32 },
    /// Both: the descent goes on in `near` with `[t0, t_split]`; `far` is left for `[t_split, t1]`.
    Both {
        near: u32,
        far: u32,
        t_split: f32,
        t1: f32,
    },
}

/// One inner-node step for the segment `[t0, t1]`. Ties go to the far child when the split is at
/// `t0` (the segment starts on the plane and moves into `far`) and to the near child when it is at
/// `t1`. A NaN `t_split` (the ray lies in the split plane) also goes to `far`: for `+0.0` that is
/// the child above, for `-0.0` the child below — the side the direction sign points to, the same rule
/// point location uses for a point on the plane. The child left out holds nothing the ray needs:
/// the builders list every primitive touching or lying in a split plane on both sides of it.
#[inline]
fn step(node: KdNode, ray: &TRay, t0: f32, t1: f32) -> Crossing {
    let axis = node.axis();
    let t_split = ray.dist(axis, node.split);
    let (below, above) = (node.index(), node.index() + 1);
    let (near, far) = if ray.negative_bit(axis) == 0 {
        (below, above)
    } else {
        (above, below)
    };
    if t_split.is_nan() || t_split <= t0 {
        Crossing::One { child: far }
    } else if t_split >= t1 {
        Crossing::One { child: near }
    } else {
        Crossing::Both {
            near,
            far,
            t_split,
            t1,
        }
    }
}

/// The child a descent continues in after crossing `c`.
#[inline]
fn next(c: Crossing) -> u32 {
    match c {
        Crossing::One { child } => child,
        Crossing::Both { near, .. } => near,
    }
}

/// Descends from `node` to the leaf holding the start of the segment `[t0, t1]`, telling `seen`
/// about every crossing (the stack-based traversals push there, push-down moves its root there).
/// Counts every node fetched, the leaf included. Returns the leaf's node index, the node and
/// its exit distance (`t1` shrunk to the near part at every two-child crossing).
#[inline]
pub(super) fn descend(
    tree: &KdTree,
    ray: &TRay,
    mut node: u32,
    t0: f32,
    mut t1: f32,
    stats: &mut TraversalStats,
    mut seen: impl FnMut(Crossing),
) -> (u32, KdNode, f32) {
    loop {
        let n = tree.nodes[node as usize];
        stats.nodes_visited += 1;
        if n.is_leaf() {
            return (node, n, t1);
        }
        let c = step(n, ray, t0, t1);
        if let Crossing::Both { t_split, .. } = c {
            t1 = t_split;
        }
        node = next(c);
        seen(c);
    }
}

/// What a traversal does with the primitives of a leaf: the closest hit or any hit. Written once,
/// so every traversal serves both `intersect` and `occluded`.
pub(super) trait LeafQuery {
    /// Tests the leaf's primitives; `t_exit` is where the ray leaves the leaf. True when the
    /// traversal can stop.
    fn visit(&mut self, prims: &[u32], t_exit: f32, stats: &mut TraversalStats) -> bool;
}

/// Closest hit. Primitives are tested against the whole ray window (`Hit::bound`), so a hit may lie
/// beyond the current leaf; the traversal stops only when the hit is *before* the leaf's exit:
/// every later leaf starts at or after `t_exit`. Strictly before — a primitive in a later leaf may
/// be hit at exactly `t_exit` with a lower index, and the tie rule wants it.
pub(super) struct Closest<'a> {
    pub prims: &'a PrimitiveSet,
    pub ray: &'a Ray,
    pub test: RayTest,
    pub hit: Hit,
}

impl LeafQuery for Closest<'_> {
    #[inline(always)]
    fn visit(&mut self, prims: &[u32], t_exit: f32, stats: &mut TraversalStats) -> bool {
        closest_among(
            self.prims,
            self.ray,
            &self.test,
            prims,
            &mut self.hit,
            stats,
        );
        self.hit.t < t_exit
    }
}

/// Offers every primitive of `prims` (a leaf's list) to `hit`: the leaf test of one ray.
#[inline(always)]
pub(crate) fn closest_among(
    set: &PrimitiveSet,
    ray: &Ray,
    test: &RayTest,
    prims: &[u32],
    hit: &mut Hit,
    stats: &mut TraversalStats,
) {
    /// Every primitive is tested: a closest-hit query never stops inside a leaf.
    struct Offer<'a> {
        set: &'a PrimitiveSet,
        ray: &'a Ray,
        test: &'a RayTest,
        hit: &'a mut Hit,
    }
    impl GroupTest for Offer<'_> {
        #[inline(always)]
        fn block(&mut self, b: &TriBlock<BLOCK>, test: &RayTest) -> u32 {
            b.intersect(Isa::baseline(), self.ray, test, self.hit);
            0
        }
        #[inline(always)]
        fn one(&mut self, p: u32) -> bool {
            self.set.intersect(p, self.ray, self.test, self.hit);
            false
        }
    }
    let mut offer = Offer {
        set,
        ray,
        test,
        hit,
    };
    test_groups(set, test, prims, stats, &mut offer);
}

/// Whether some primitive of `prims` is hit in the ray's window; stops at the first.
#[inline(always)]
pub(crate) fn any_among(
    set: &PrimitiveSet,
    ray: &Ray,
    test: &RayTest,
    prims: &[u32],
    stats: &mut TraversalStats,
) -> bool {
    struct Any<'a> {
        set: &'a PrimitiveSet,
        ray: &'a Ray,
        test: &'a RayTest,
    }
    impl GroupTest for Any<'_> {
        #[inline(always)]
        fn block(&mut self, b: &TriBlock<BLOCK>, test: &RayTest) -> u32 {
            b.occluders(Isa::baseline(), self.ray, test)
        }
        #[inline(always)]
        fn one(&mut self, p: u32) -> bool {
            let mut hit = Hit::MISS;
            self.set.intersect(p, self.ray, self.test, &mut hit)
        }
    }
    test_groups(set, test, prims, stats, &mut Any { set, ray, test })
}

/// Triangles per SIMD block of a leaf test: 4 lanes are SSE, which every x86-64 has, and SAH
/// leaves hold about 3 triangles. Testing a group of one triangle alone instead (no block to
/// build) ran at 0.99–1.01× on the bunny's incoherent set (single rays, 3 runs), groups of up
/// to two at 0.95–0.99× (`perf` puts most of that time in the descent's node loads and
/// branches, not in building blocks).
const BLOCK: usize = 4;

/// What a leaf test does with its groups of primitives; each returns true to stop. A trait
/// rather than a closure, so that both are inlined into every traversal.
trait GroupTest {
    /// Up to [`BLOCK`] triangles at once, with the ray's test `test`: the mask of the lanes
    /// that end the search (0: it goes on).
    fn block(&mut self, b: &TriBlock<BLOCK>, test: &RayTest) -> u32;
    /// One primitive alone.
    fn one(&mut self, p: u32) -> bool;
}

/// Runs `t` on the leaf's primitives in order, triangles gathered into SIMD blocks (1 ray ×
/// 4 triangles, the vectorised-traversal paper's test), which compute the scalar test bit for
/// bit; other primitives one at a time. Stops when `t` says so and returns whether it did.
/// Counts the primitives tested.
#[inline(always)]
fn test_groups(
    set: &PrimitiveSet,
    test: &RayTest,
    prims: &[u32],
    stats: &mut TraversalStats,
    t: &mut impl GroupTest,
) -> bool {
    // One loop per intersector, each with a copy of the test whose kind is a constant, so that
    // neither carries the other's branches (as `cpu::batch::Batch`'s `WATERTIGHT`).
    let exclude = test.exclude;
    match test.triangle {
        TriangleTest::MollerTrumbore => {
            let triangle = TriangleTest::MollerTrumbore;
            test_groups_with(set, &RayTest { triangle, exclude }, prims, stats, t)
        }
        TriangleTest::Watertight { k, s } => {
            let triangle = TriangleTest::Watertight { k, s };
            test_groups_with(set, &RayTest { triangle, exclude }, prims, stats, t)
        }
    }
}

/// Primitive tests a search in leaf order makes in a block of `len` triangles whose lanes
/// `stop` end it: up to the first of them, else all (as one at a time, and as the GPU counts).
#[inline(always)]
pub(crate) fn tested_until(stop: u32, len: usize) -> u64 {
    match stop {
        0 => len as u64,
        _ => stop.trailing_zeros() as u64 + 1,
    }
}

/// [`test_groups`] for one intersector.
#[inline(always)]
fn test_groups_with(
    set: &PrimitiveSet,
    test: &RayTest,
    prims: &[u32],
    stats: &mut TraversalStats,
    t: &mut impl GroupTest,
) -> bool {
    let triangles = set.triangles.len();
    let intersector = test.triangle.intersector();
    for group in prims.chunks(BLOCK) {
        if group.iter().all(|&p| (p as usize) < triangles) {
            let stop = t.block(&TriBlock::from_prims(set, group, intersector), test);
            stats.prim_tests += tested_until(stop, group.len());
            if stop != 0 {
                return true;
            }
        } else {
            for &p in group {
                stats.prim_tests += 1;
                if t.one(p) {
                    return true;
                }
            }
        }
    }
    false
}

/// Any hit in the ray window (shadow rays): stops at the first primitive hit.
pub(super) struct AnyHit<'a> {
    pub prims: &'a PrimitiveSet,
    pub ray: &'a Ray,
    pub test: RayTest,
    pub found: bool,
}

impl LeafQuery for AnyHit<'_> {
    #[inline(always)]
    fn visit(&mut self, prims: &[u32], _t_exit: f32, stats: &mut TraversalStats) -> bool {
        self.found = any_among(self.prims, self.ray, &self.test, prims, stats);
        self.found
    }
}

/// Visits leaf node `leaf` (counting it) and says whether the traversal can stop.
#[inline]
pub(super) fn visit_leaf(
    tree: &KdTree,
    leaf: KdNode,
    t_exit: f32,
    query: &mut impl LeafQuery,
    stats: &mut TraversalStats,
) -> bool {
    stats.leaves_visited += 1;
    query.visit(tree.leaf_prims(leaf), t_exit, stats)
}

/// A subtree still to traverse for the segment `[t0, t1]`.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct Entry {
    pub node: u32,
    pub t0: f32,
    pub t1: f32,
}

/// Slots of the standard traversal's stack. Its entries are far children pending on the path
/// from the start to the current node, at most one per level below the start, and the
/// builders make every node at depth `MAX_DEPTH_LIMIT` a leaf: that many slots and the start's
/// always suffice (`tests/traversals.rs` walks a tree at the limit). A fixed array: the
/// earlier inline part of 32 entries with a heap vector past it ran 1.02–1.03× slower on the
/// bunny's primary rays (one thread) and could never spill.
const STACK_SLOTS: usize = crate::kdtree::MAX_DEPTH_LIMIT as usize + 1;

/// The standard traversal's stack ([`STACK_SLOTS`]).
pub(super) struct Stack {
    entries: [Entry; STACK_SLOTS],
    len: usize,
}

impl Stack {
    pub fn new() -> Self {
        Stack {
            entries: [Entry::default(); STACK_SLOTS],
            len: 0,
        }
    }

    #[inline]
    pub fn push(&mut self, e: Entry) {
        self.entries[self.len] = e;
        self.len += 1;
    }

    #[inline]
    pub fn pop(&mut self) -> Option<Entry> {
        self.len = self.len.checked_sub(1)?;
        Some(self.entries[self.len])
    }
}

/// Largest short stack (the thesis uses 3): the query and render options refuse larger sizes,
/// and the traversal clamps them. The GPU kernels hold the same bound (`SHORT_STACK_MAX`).
pub const MAX_SHORT_STACK: usize = 32;

/// The short stack of Horn et al.: circular, so a push onto a full stack overwrites the oldest
/// (farthest) entry. Losing it is safe: when the stack runs dry the traversal restarts and finds
/// that part of the ray again.
pub(super) struct ShortStack {
    buf: [Entry; MAX_SHORT_STACK],
    cap: usize,
    top: usize,
    len: usize,
}

impl ShortStack {
    pub fn new(size: usize) -> Self {
        ShortStack {
            buf: [Entry::default(); MAX_SHORT_STACK],
            cap: size.min(MAX_SHORT_STACK),
            top: 0,
            len: 0,
        }
    }

    #[inline]
    pub fn push(&mut self, e: Entry) {
        if self.cap == 0 {
            return;
        }
        self.top = (self.top + 1) % self.cap;
        self.buf[self.top] = e;
        self.len = (self.len + 1).min(self.cap);
    }

    #[inline]
    pub fn pop(&mut self) -> Option<Entry> {
        self.len = self.len.checked_sub(1)?;
        let e = self.buf[self.top];
        self.top = (self.top + self.cap - 1) % self.cap;
        Some(e)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn entry(node: u32) -> Entry {
        Entry {
            node,
            t0: node as f32,
            t1: node as f32 + 1.0,
        }
    }

    #[test]
    fn stack_holds_a_far_child_per_level_and_the_start() {
        let mut s = Stack::new();
        for i in 0..STACK_SLOTS as u32 {
            s.push(entry(i));
        }
        for i in (0..STACK_SLOTS as u32).rev() {
            assert_eq!(s.pop().map(|e| e.node), Some(i));
        }
        assert!(s.pop().is_none());
    }

    #[test]
    fn short_stack_keeps_the_newest_entries() {
        let mut s = ShortStack::new(3);
        for i in 0..5 {
            s.push(entry(i));
        }
        let popped: Vec<u32> = std::iter::from_fn(|| s.pop()).map(|e| e.node).collect();
        assert_eq!(popped, [4, 3, 2]);
        s.push(entry(9));
        assert_eq!(s.pop().map(|e| e.node), Some(9));
        assert!(s.pop().is_none());
    }

    #[test]
    fn empty_short_stack_is_kd_restart() {
        let mut s = ShortStack::new(0);
        s.push(entry(1));
        assert!(s.pop().is_none());
    }
}
