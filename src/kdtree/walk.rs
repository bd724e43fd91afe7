//! Walking the flat tree: voxels of the leaves and point location.

use glam::Vec3;

use super::split::child_voxels;
use super::KdTree;
use crate::geometry::Aabb;

impl KdTree {
    /// Calls `visit(node, voxel, depth)` for every node, parents before children. Voxels are
    /// recomputed from the root box and the split planes, exactly as a traversal sees them.
    pub fn visit_nodes(&self, mut visit: impl FnMut(u32, &Aabb, u32)) {
        let mut stack = vec![(0u32, self.bounds, 0u32)];
        while let Some((node, voxel, depth)) = stack.pop() {
            visit(node, &voxel, depth);
            let n = self.nodes[node as usize];
            if !n.is_leaf() {
                let [below, above] = child_voxels(&voxel, n.axis(), n.split);
                stack.push((n.index() + 1, above, depth + 1));
                stack.push((n.index(), below, depth + 1));
            }
        }
    }

    /// `(leaf node, voxel, depth)` of every leaf, in depth-first order.
    pub fn leaf_voxels(&self) -> Vec<(u32, Aabb, u32)> {
        let mut out = Vec::with_capacity(self.leaf_count());
        self.visit_nodes(|node, voxel, depth| {
            if self.nodes[node as usize].is_leaf() {
                out.push((node, *voxel, depth));
            }
        });
        out
    }

    /// The leaf node (a node index, not a rope leaf number) whose voxel holds `p`, descending below
    /// the plane when `p[axis] <= split`. For points outside the root box it is the leaf the
    /// point would fall in if the outer voxels were extended to infinity; ropes++ starts
    /// secondary rays here instead of at the root (the CPU's depth-first render,
    /// `Tracer::start_leaf`; the GPU's render, `start_leaf` in shaders/common.wgsl).
    pub fn locate_leaf(&self, p: Vec3) -> u32 {
        let mut node = 0u32;
        loop {
            let n = self.nodes[node as usize];
            if n.is_leaf() {
                return node;
            }
            node = n.index() + u32::from(p[n.axis()] > n.split);
        }
    }
}
