//! What both builders share: the temporary node tree they return, the rule that sends a
//! primitive to one or both sides of a split plane, and the parallel recursion.

use super::BuildInput;
use crate::geometry::Aabb;

/// Node tree produced by a builder before it is flattened by `layout::flatten`. Building this
/// value first (instead of writing the flat arrays during the parallel recursion) is what makes
/// the flat arrays independent of the thread count.
pub(super) enum BuildNode {
    /// Global primitive indices, ascending.
    Leaf(Vec<u32>),
    Inner {
        axis: usize,
        split: f32,
        /// Below (`[min, split]`) and above (`[split, max]`) the plane.
        children: Box<[BuildNode; 2]>,
    },
}

impl BuildNode {
    /// A leaf listing `prims` in ascending order, so that equal inputs give equal leaves and a
    /// traversal meets the lowest index first.
    pub(super) fn leaf(mut prims: Vec<u32>) -> Self {
        prims.sort_unstable();
        BuildNode::Leaf(prims)
    }
}

/// Where a primitive goes when its voxel is split.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Side {
    Below,
    Above,
    /// Straddles the plane: it is clipped to each child voxel (perfect splits) and kept in the
    /// children whose clipped part is not empty.
    Both,
}

/// Side of a primitive that spans `[lo, hi]` along the split axis inside the voxel, for the
/// plane at `split`.
///
/// The interval is closed, and a primitive that touches the plane from one side (a vertex on
/// it) goes to both sides. Wald & Havran (2006, §4.2) send it to its side alone, since the
/// other child sees it only in its boundary face; but a ray through that vertex may be placed
/// in the other child by the rounding of the split distances, and when the triangle that
/// holds the hit there is missing, the ray slips through a closed mesh (found by
/// `tests/precision.rs`: 1% of the rays aimed at vertices of a tessellated sphere leaked with
/// the watertight test). Listing it on both sides makes leaf membership conservative for every
/// traversal at the cost of a few more references. A primitive lying in the plane
/// (`lo == hi == split`) goes to both sides too: a ray lying in the plane, or starting on it,
/// then finds it in whichever child the traversal enters (and the GPU kernels, which do not
/// search the child left out, give the CPU's answer).
pub(super) fn classify(lo: f32, hi: f32, split: f32) -> Side {
    if hi < split {
        Side::Below
    } else if lo > split {
        Side::Above
    } else {
        Side::Both
    }
}

/// The two child voxels of `voxel` split at `axis = split`.
pub(super) fn child_voxels(voxel: &Aabb, axis: usize, split: f32) -> [Aabb; 2] {
    let (mut below, mut above) = (*voxel, *voxel);
    below.max[axis] = split;
    above.min[axis] = split;
    [below, above]
}

/// Clipped bounds of `prim` in `voxel`, `None` when the prim does not reach into it.
pub(super) fn clip(input: &dyn BuildInput, prim: u32, voxel: &Aabb) -> Option<Aabb> {
    let b = input.clipped_bounds(prim as usize, voxel);
    (!b.is_empty()).then_some(b)
}

/// The most leaf references (entries of the leaves' primitive lists) a subtree may hold
/// (`BuildOptions::references_per_prim`). A split goes ahead only when its children's
/// references fit, and they then share the budget in proportion to their counts, so each
/// keeps at least its own count and the whole tree holds at most the root's budget.
#[derive(Clone, Copy, Debug)]
pub(super) struct Budget(usize);

impl Budget {
    /// The root's budget, for `prims` primitives.
    pub(super) fn root(prims: usize, per_prim: u32) -> Self {
        Budget(prims.saturating_mul(per_prim as usize))
    }

    /// The children's budgets for a split into `below` and `above` references, or `None` when
    /// they exceed this budget (the node stays a leaf).
    pub(super) fn split(self, below: usize, above: usize) -> Option<[Budget; 2]> {
        let n = below + above;
        if n > self.0 {
            return None;
        }
        let b = (self.0 as u128 * below as u128 / n.max(1) as u128) as usize;
        Some([Budget(b), Budget(self.0 - b)])
    }
}

/// Nodes above this depth with at least [`PARALLEL_MIN_PRIMS`] primitives are worked on in
/// parallel; below that a rayon fork costs more than it saves.
const PARALLEL_MAX_DEPTH: u32 = 10;
const PARALLEL_MIN_PRIMS: usize = 2048;

/// Whether a node at `depth` with `prims` primitives is worth parallel work.
pub(super) fn parallel(depth: u32, prims: usize) -> bool {
    depth < PARALLEL_MAX_DEPTH && prims >= PARALLEL_MIN_PRIMS
}

/// Builds the two children, in parallel near the root. The result does not depend on whether
/// the closures ran in parallel.
pub(super) fn fork<A, B>(depth: u32, prims: usize, below: A, above: B) -> [BuildNode; 2]
where
    A: FnOnce() -> BuildNode + Send,
    B: FnOnce() -> BuildNode + Send,
{
    if parallel(depth, prims) {
        let (b, a) = rayon::join(below, above);
        [b, a]
    } else {
        [below(), above()]
    }
}
