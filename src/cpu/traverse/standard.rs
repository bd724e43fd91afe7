//! Standard traversal (thesis algorithm 2; Jansen, Havran's TA-B): descend to the nearest leaf,
//! pushing the far child of every node whose both children the segment crosses; after a leaf, pop
//! the nearest pending subtree. Visits every node at most once; needs a stack as deep as the tree.

use super::common::{descend, visit_leaf, Crossing, Entry, LeafQuery, Stack, TRay};
use crate::geometry::TraversalStats;
use crate::kdtree::KdTree;

/// Traverses the subtree `start` (a node and the ray's segment in it). Returns true when the
/// query stopped (the ray is finished), false when the subtree ran out first.
pub(super) fn traverse(
    tree: &KdTree,
    ray: &TRay,
    start: Entry,
    query: &mut impl LeafQuery,
    stats: &mut TraversalStats,
) -> bool {
    let mut stack = Stack::new();
    stack.push(start);
    while let Some(Entry { node, t0, t1 }) = stack.pop() {
        let (_, leaf, t_exit) = descend(tree, ray, node, t0, t1, stats, |c| {
            if let Crossing::Both {
                far, t_split, t1, ..
            } = c
            {
                stack.push(Entry {
                    node: far,
                    t0: t_split,
                    t1,
                });
            }
        });
        if visit_leaf(tree, leaf, t_exit, query, stats) {
            return true;
        }
    }
    false
}
