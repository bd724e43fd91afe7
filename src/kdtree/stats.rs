//! Tree statistics, including the SAH cost of the finished tree.

use super::{KdTree, TreeStats};

/// Statistics of a flat tree (all but `build_ms`).
///
/// The SAH cost is `Σ_inner K_T·A(v)/A(root) + Σ_leaf K_I·n·A(v)/A(root)` with `K_I = 1`
/// (MacDonald & Booth 1990; without the empty-space factor, which only steers the builder). A
/// root with zero area (all primitives on a line or at a point) counts every node with
/// probability 1.
pub(super) fn tree_stats(tree: &KdTree, traversal_cost: f32) -> TreeStats {
    // Areas at the root's unit scale, which a voxel past 1e19 needs to have one in f32.
    let unit = tree.bounds.unit_scale();
    let root_area = tree.bounds.scaled_surface_area(unit);
    let probability = |a: f32| if root_area > 0.0 { a / root_area } else { 1.0 };
    let mut s = TreeStats {
        node_count: tree.nodes.len() as u32,
        leaf_count: tree.leaf_count() as u32,
        ..TreeStats::default()
    };
    let (mut depth_sum, mut refs, mut cost) = (0u64, 0u64, 0f64);
    tree.visit_nodes(|node, voxel, depth| {
        let n = tree.nodes[node as usize];
        let p = f64::from(probability(voxel.scaled_surface_area(unit)));
        if n.is_leaf() {
            let count = n.prim_range().len() as u32;
            s.max_depth = s.max_depth.max(depth);
            s.empty_leaf_count += u32::from(count == 0);
            depth_sum += u64::from(depth);
            refs += u64::from(count);
            cost += p * f64::from(count);
        } else {
            cost += p * f64::from(traversal_cost);
        }
    });
    s.avg_leaf_depth = (depth_sum as f64 / f64::from(s.leaf_count.max(1))) as f32;
    let full = s.leaf_count - s.empty_leaf_count;
    s.avg_prims_per_leaf = (refs as f64 / f64::from(full.max(1))) as f32;
    s.sah_cost = cost as f32;
    s
}
