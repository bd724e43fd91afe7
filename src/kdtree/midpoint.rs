//! Midpoint builder of the vectorised-traversal paper (Noguera & Ureña): every voxel is split
//! at its centre along its longest axis until it holds at most `leaf_size` primitives or the
//! depth limit is reached. Cheap to build and the natural tree for breadth-first ray streams.

use super::split::{child_voxels, classify, clip, fork, BuildNode, Side};
use super::BuildInput;
use crate::geometry::Aabb;

/// `prims` are (index, bounds inside `voxel`) pairs.
pub(super) fn build(
    input: &dyn BuildInput,
    prims: Vec<(u32, Aabb)>,
    voxel: Aabb,
    max_depth: u32,
    leaf_size: u32,
) -> BuildNode {
    Midpoint {
        input,
        max_depth,
        leaf_size: leaf_size as usize,
    }
    .node(prims, voxel, 0)
}

struct Midpoint<'a> {
    input: &'a dyn BuildInput,
    max_depth: u32,
    leaf_size: usize,
}

impl Midpoint<'_> {
    fn node(&self, prims: Vec<(u32, Aabb)>, voxel: Aabb, depth: u32) -> BuildNode {
        let Some((axis, split)) = self.plane(&prims, &voxel, depth) else {
            return BuildNode::leaf(prims.into_iter().map(|(p, _)| p).collect());
        };
        let voxels = child_voxels(&voxel, axis, split);
        let mut sides: [Vec<(u32, Aabb)>; 2] = Default::default();
        for (p, b) in prims {
            // A primitive in the plane touches both closed child voxels: it is clipped like a
            // straddling one, which keeps it in both.
            match classify(b.min[axis], b.max[axis], split) {
                Side::Below => sides[0].push((p, b)),
                Side::Above => sides[1].push((p, b)),
                Side::Both => {
                    for (side, v) in sides.iter_mut().zip(&voxels) {
                        if let Some(c) = clip(self.input, p, v) {
                            side.push((p, c));
                        }
                    }
                }
            }
        }
        let [below, above] = sides;
        let [vb, va] = voxels;
        let n = below.len() + above.len();
        let children = fork(
            depth,
            n,
            || self.node(below, vb, depth + 1),
            || self.node(above, va, depth + 1),
        );
        BuildNode::Inner {
            axis,
            split,
            children: Box::new(children),
        }
    }

    /// The split plane, or `None` for a leaf: few primitives, depth limit, or a voxel too
    /// small to be halved in `f32` (a point-like or rounding-limited voxel).
    fn plane(&self, prims: &[(u32, Aabb)], voxel: &Aabb, depth: u32) -> Option<(usize, f32)> {
        if prims.len() <= self.leaf_size || depth >= self.max_depth {
            return None;
        }
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
}
