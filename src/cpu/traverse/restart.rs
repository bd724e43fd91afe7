//! The stackless and short-stack traversals of Foley & Sugerman (2005) and Horn et al. (2007):
//! thesis algorithms 3 (kd-restart), 4 (push-down), 5 (short-stack) and 6 (push-down +
//! short-stack). Algorithm 6 contains the other three — a short stack of size 0 never pops, and
//! without push-down the restart root stays the tree root — so they are one loop here,
//! parameterised, instead of four copies of it.
//!
//! After each leaf the traversal continues from the top of the short stack; when that is empty it
//! *restarts*: it descends again, from the root (or the push-down node), for the rest of the
//! scene segment `[t_exit, scene_max]` of the original ray. Each leaf's exit is strictly beyond its
//! entry, so every restart makes progress and no leaf is visited twice.

use super::common::{descend, visit_leaf, Crossing, Entry, LeafQuery, ShortStack, TRay};
use crate::geometry::TraversalStats;
use crate::kdtree::KdTree;

/// Which member of the restart family to run.
#[derive(Clone, Copy, Debug)]
pub(super) struct Restart {
    /// Entries of the circular short stack; 0 for kd-restart and push-down.
    pub short_stack: usize,
    /// Restart from the deepest node whose subtree holds the whole remaining segment (the
    /// nodes on the first descent where only one child was crossed), not from the root.
    pub push_down: bool,
}

pub(super) fn traverse(
    tree: &KdTree,
    ray: &TRay,
    (scene_min, scene_max): (f32, f32),
    how: Restart,
    query: &mut impl LeafQuery,
    stats: &mut TraversalStats,
) {
    let mut stack = ShortStack::new(how.short_stack);
    let mut root = 0;
    let mut t_max = scene_min;
    // One leaf per pass and no leaf twice: more passes than leaves would be a bug.
    for _ in 0..tree.leaf_count() {
        let (node, t0, t1, mut push_down) = match stack.pop() {
            Some(e) => (e.node, e.t0, e.t1, false),
            // The restart event.
            None => (root, t_max, scene_max, how.push_down),
        };
        let (_, leaf, t_exit) = descend(tree, ray, node, t0, t1, stats, |c| match c {
            Crossing::One { child } if push_down => root = child,
            Crossing::One { .. } => {}
            Crossing::Both {
                far, t_split, t1, ..
            } => {
                push_down = false;
                stack.push(Entry {
                    node: far,
                    t0: t_split,
                    t1,
                });
            }
        });
        if visit_leaf(tree, leaf, t_exit, query, stats) || t_exit >= scene_max {
            return;
        }
        t_max = t_exit;
    }
    debug_assert!(false, "restart traversal made no progress");
}
