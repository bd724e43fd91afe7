//! Midpoint builder of the vectorised-traversal paper (Noguera & Ureña): every voxel is split
//! at its centre along its longest axis until it holds at most `leaf_size` primitives, the
//! depth limit is reached, no split separates its primitives (see `Midpoint::split`) or the
//! children would exceed the node's share of the reference budget
//! (`BuildOptions::references_per_prim`). Cheap to build and the natural tree for
//! breadth-first ray streams.

use super::split::{centre_plane, child_voxels, classify, clip, fork, Budget, Side, Slot, Subtree};
use super::{BuildInput, BuildOptions};
use crate::fallible::{Fallible, TryGrow};
use crate::geometry::Aabb;

/// `prims` are (index, bounds inside `voxel`) pairs.
pub(super) fn build(
    input: &dyn BuildInput,
    prims: Vec<(u32, Aabb)>,
    voxel: Aabb,
    max_depth: u32,
    opts: &BuildOptions,
) -> Fallible<Subtree> {
    let budget = Budget::root(prims.len(), opts.references_per_prim);
    let m = Midpoint {
        input,
        max_depth,
        leaf_size: opts.leaf_size as usize,
    };
    Subtree::built(|slot| m.node(prims, voxel, 0, budget, slot))
}

/// (index, bounds inside the child voxel) pairs below and above a split plane.
type Sides = [Vec<(u32, Aabb)>; 2];

/// A split plane (axis, position), the primitives of each side and their budgets.
type Split = (usize, f32, Sides, [Budget; 2]);

struct Midpoint<'a> {
    input: &'a dyn BuildInput,
    max_depth: u32,
    leaf_size: usize,
}

impl Midpoint<'_> {
    /// Writes the subtree of `voxel` into `slot`.
    fn node(
        &self,
        prims: Vec<(u32, Aabb)>,
        voxel: Aabb,
        depth: u32,
        budget: Budget,
        slot: Slot,
    ) -> Fallible<()> {
        let Some((axis, split, [below, above], [bb, ba])) =
            self.split(&prims, &voxel, depth, budget)?
        else {
            // Collected in place, into the pairs' own buffer (std reuses it): a leaf allocates
            // no list of its own before `leaf` copies it into the tree.
            return slot.leaf(prims.into_iter().map(|(p, _)| p).collect());
        };
        drop(prims);
        let [vb, va] = child_voxels(&voxel, axis, split);
        let n = below.len() + above.len();
        fork(
            depth,
            n,
            slot.inner(axis, split)?,
            |slot| self.node(below, vb, depth + 1, bb, slot),
            |slot| self.node(above, va, depth + 1, ba, slot),
        )
    }

    /// The split plane, the primitives of each side and their budgets, or `None` for a leaf:
    /// few primitives, depth limit, a voxel too small to be halved in `f32` (point-like or
    /// rounding-limited), a split that separates nothing, or children past `budget`.
    ///
    /// A split that leaves every primitive in both children only doubles the references:
    /// overlapping primitives (two coincident spheres, coplanar triangles) would stay together
    /// down to the depth limit, 2^depth nodes (at the allowed depth 64, an allocation failure
    /// and an abort). Such a voxel becomes a leaf, the usual kd-tree termination rule (SAH gets
    /// it from its cost). Only the longest axis is tried, as in the paper: primitives that all
    /// span the voxel's longest axis but could be told apart on another one (long thin
    /// parallel ones), or that all touch its centre plane (a fan of triangles around a vertex
    /// at the centre, needles crossing there), stay in one leaf: a slower leaf (100k fan
    /// triangles: about 90 times slower rays than a random soup) but never a wrong one. The SAH
    /// builder splits such scenes.
    fn split(
        &self,
        prims: &[(u32, Aabb)],
        voxel: &Aabb,
        depth: u32,
        budget: Budget,
    ) -> Fallible<Option<Split>> {
        if prims.len() <= self.leaf_size || depth >= self.max_depth {
            return Ok(None);
        }
        let Some((axis, split)) = centre_plane(voxel) else {
            return Ok(None);
        };
        let sides = self.partition(prims, voxel, axis, split)?;
        // Each primitive is at most once on each side: a side shorter than `prims` misses one.
        if sides.iter().all(|s| s.len() == prims.len()) {
            return Ok(None);
        }
        Ok(budget
            .split(sides[0].len(), sides[1].len())
            .map(|budgets| (axis, split, sides, budgets)))
    }

    /// The primitives of each child voxel of the split at `axis = split`, with their bounds
    /// inside it.
    fn partition(
        &self,
        prims: &[(u32, Aabb)],
        voxel: &Aabb,
        axis: usize,
        split: f32,
    ) -> Fallible<Sides> {
        let voxels = child_voxels(voxel, axis, split);
        let mut sides: Sides = Default::default();
        for &(p, b) in prims {
            // A primitive in the plane touches both closed child voxels: it is clipped like a
            // straddling one, which keeps it in both.
            match classify(b.min[axis], b.max[axis], split) {
                Side::Below => sides[0].try_push((p, b))?,
                Side::Above => sides[1].try_push((p, b))?,
                Side::Both => {
                    for (side, v) in sides.iter_mut().zip(&voxels) {
                        if let Some(c) = clip(self.input, p, v) {
                            side.try_push((p, c.bounds))?;
                        }
                    }
                }
            }
        }
        Ok(sides)
    }
}
