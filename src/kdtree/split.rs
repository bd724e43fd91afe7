//! What both builders share: the depth-first node arrays they write, the rule that sends a
//! primitive to one or both sides of a split plane, and the parallel recursion.

use super::{BuildInput, KdNode};
use crate::fallible::{self, Fallible, TryGrow};
use crate::geometry::{Aabb, Clipped};

/// A tree (or a subtree built on its own thread) in the final node format, written by a builder
/// as it recurses: the root at index 0, and every inner node's child pair appended when the
/// node is written, so the pairs come in depth-first pre-order and the leaves' lists in
/// depth-first order. Parallel parts are built into their own `Subtree` and grafted in the
/// same order, so the arrays do not depend on the thread count.
///
/// Writing the flat arrays directly, rather than a tree of boxed nodes flattened afterwards,
/// keeps a build's memory near the tree's own: a boxed node with its leaf list cost about 110
/// bytes per node (two small allocations) against 8 here, and glibc kept most of it resident
/// after the build (a 19M-node midpoint tree left 2.3 GB behind).
pub(super) struct Subtree {
    pub nodes: Vec<KdNode>,
    pub prims: Vec<u32>,
}

impl Subtree {
    /// The subtree that `build` writes from its root.
    pub(super) fn built(build: impl FnOnce(Slot) -> Fallible<()>) -> Fallible<Self> {
        let mut sub = Subtree {
            nodes: fallible::filled(KdNode::leaf(0, 0), 1)?,
            prims: Vec::new(),
        };
        build(Slot {
            tree: &mut sub,
            at: 0,
        })?;
        Ok(sub)
    }

    /// Appends `sub` (built on its own) and writes its root at `at`: its nodes' child indices
    /// and leaf list starts move by where its arrays land in these.
    fn graft(&mut self, at: usize, sub: Subtree) -> Fallible<()> {
        let (node_shift, prim_shift) = (self.nodes.len() as u32 - 1, self.prims_end());
        // The moved leaf starts fit in u32 when the joined lists do: `prims_end` checks that,
        // as it does for every leaf written here.
        self.prims.try_extend_from_slice(&sub.prims)?;
        self.prims_end();
        let moved = |n: KdNode| {
            if n.is_leaf() {
                let r = n.prim_range();
                KdNode::leaf(r.start as u32 + prim_shift, r.len() as u32)
            } else {
                KdNode::inner(n.axis(), n.split, n.index() + node_shift)
            }
        };
        self.nodes[at] = moved(sub.nodes[0]);
        self.nodes
            .try_extend(sub.nodes[1..].iter().map(|&n| moved(n)))
    }

    /// Where the next leaf list starts.
    fn prims_end(&self) -> u32 {
        u32::try_from(self.prims.len())
            .expect("over 2^32 leaf references: more than the node format can address")
    }
}

/// The place of a node still to be written: a leaf, or an inner node whose children follow.
pub(super) struct Slot<'a> {
    tree: &'a mut Subtree,
    at: usize,
}

impl<'a> Slot<'a> {
    /// Writes a leaf listing `prims` in ascending order, so that equal inputs give equal
    /// leaves and a traversal meets the lowest index first.
    pub(super) fn leaf(self, mut prims: Vec<u32>) -> Fallible<()> {
        prims.sort_unstable();
        let first = self.tree.prims_end();
        self.tree.nodes[self.at] = KdNode::leaf(first, prims.len() as u32);
        self.tree.prims.try_extend_from_slice(&prims)
    }

    /// Writes an inner node and appends its child pair, to be written by [`fork`].
    pub(super) fn inner(self, axis: usize, split: f32) -> Fallible<Children<'a>> {
        let first = self.tree.nodes.len();
        self.tree.nodes.try_extend([KdNode::leaf(0, 0); 2])?;
        self.tree.nodes[self.at] = KdNode::inner(axis, split, first as u32);
        Ok(Children {
            tree: self.tree,
            first,
        })
    }
}

/// The child pair an inner node just appended: nothing else is written until [`fork`] fills
/// it, so grafted subtrees land right after it, in pre-order.
pub(super) struct Children<'a> {
    tree: &'a mut Subtree,
    first: usize,
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

/// The plane through the centre of `voxel` across its longest axis (the midpoint builder's
/// split), or `None` when the voxel is too thin there to be halved in `f32`.
pub(super) fn centre_plane(voxel: &Aabb) -> Option<(usize, f32)> {
    let e = voxel.extent();
    let axis = if e.x >= e.y && e.x >= e.z {
        0
    } else if e.y >= e.z {
        1
    } else {
        2
    };
    let split = voxel.center()[axis];
    (split > voxel.min[axis] && split < voxel.max[axis]).then_some((axis, split))
}

/// The two child voxels of `voxel` split at `axis = split`.
pub(super) fn child_voxels(voxel: &Aabb, axis: usize, split: f32) -> [Aabb; 2] {
    let (mut below, mut above) = (*voxel, *voxel);
    below.max[axis] = split;
    above.min[axis] = split;
    [below, above]
}

/// Clipped bounds of `prim` in `voxel`, `None` when the prim does not reach into it.
pub(super) fn clip(input: &dyn BuildInput, prim: u32, voxel: &Aabb) -> Option<Clipped> {
    let c = input.clipped_bounds(prim as usize, voxel);
    (!c.bounds.is_empty()).then_some(c)
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

/// Builds the two `children` of an inner node, in parallel near the root (each into its own
/// [`Subtree`], grafted below then above). The arrays do not depend on whether the closures ran
/// in parallel.
pub(super) fn fork<A, B>(
    depth: u32,
    prims: usize,
    children: Children,
    below: A,
    above: B,
) -> Fallible<()>
where
    A: FnOnce(Slot) -> Fallible<()> + Send,
    B: FnOnce(Slot) -> Fallible<()> + Send,
{
    let Children { tree, first } = children;
    if parallel(depth, prims) {
        let (b, a) = rayon::join(|| Subtree::built(below), || Subtree::built(above));
        let (b, a) = (b?, a?);
        tree.graft(first, b)?;
        tree.graft(first + 1, a)
    } else {
        below(Slot {
            tree: &mut *tree,
            at: first,
        })?;
        above(Slot {
            tree,
            at: first + 1,
        })
    }
}
