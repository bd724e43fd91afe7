//! Node layouts: depth-first and van Emde Boas.
//!
//! The unit of layout is the sibling pair: the format keeps the two children of a node side by
//! side, so a layout is an order of pairs (the root sits alone at index 0). The builders write
//! the pairs and the leaves' primitive lists in depth-first order; a layout only reorders the
//! pairs, so two trees that differ only in layout have identical `prim_indices` and the same
//! leaf nodes in depth-first order.

use super::split::Subtree;
use super::{KdNode, KdTree, Layout, TreeStats};
use crate::fallible::{self, Fallible, TryGrow};
use crate::geometry::Aabb;

/// The tree of the builder's depth-first arrays in the chosen layout.
pub(super) fn lay_out(built: Subtree, bounds: Aabb, layout: Layout) -> Fallible<KdTree> {
    let nodes = match layout {
        Layout::DepthFirst => built.nodes,
        Layout::VanEmdeBoas => van_emde_boas(&built.nodes)?,
    };
    Ok(KdTree {
        nodes,
        prim_indices: built.prims,
        bounds,
        ropes: None,
        stats: TreeStats::default(),
    })
}

/// Reorders the sibling pairs of a depth-first tree in van Emde Boas order (Prokop's
/// cache-oblivious layout, as used for kd-trees in the RT² thesis): the pair tree of height
/// `h` is cut at half its height, the top part is laid out recursively, then each bottom
/// subtree, left to right, recursively. Any run of `B` pairs then holds a subtree of height
/// about `log B`, whatever the cache line or page size, so a root-to-leaf path touches
/// `O(log_B N)` blocks.
fn van_emde_boas(nodes: &[KdNode]) -> Fallible<Vec<KdNode>> {
    if nodes.len() == 1 {
        return fallible::collect(nodes.iter().copied());
    }
    let pairs = PairTree::new(nodes)?;
    let mut order = fallible::with_capacity(nodes.len() / 2)?;
    let root_pair = nodes[0].index();
    pairs.lay_out(root_pair, pairs.height(root_pair), &mut order)?;
    // New position of each old pair.
    let mut moved = fallible::filled(0u32, nodes.len())?;
    for (rank, &old) in order.iter().enumerate() {
        moved[old as usize] = 1 + 2 * rank as u32;
    }
    let relink = |n: KdNode| {
        if n.is_leaf() {
            n
        } else {
            KdNode::inner(n.axis(), n.split, moved[n.index() as usize])
        }
    };
    let mut out = fallible::with_capacity(nodes.len())?;
    out.push(relink(nodes[0]));
    for &old in &order {
        out.push(relink(nodes[old as usize]));
        out.push(relink(nodes[old as usize + 1]));
    }
    Ok(out)
}

/// The tree of sibling pairs of a depth-first node array: a pair is named by the index of its
/// first node, its children are the child pairs of its (up to two) inner nodes.
struct PairTree<'a> {
    nodes: &'a [KdNode],
    /// Height (in pairs) of the subtree under each pair, indexed by the pair's first node.
    heights: Vec<u32>,
}

impl<'a> PairTree<'a> {
    fn new(nodes: &'a [KdNode]) -> Fallible<Self> {
        let mut tree = PairTree {
            nodes,
            heights: fallible::filled(0, nodes.len())?,
        };
        // Depth-first order puts every child pair after its parent: fill heights backwards.
        for pair in (1..nodes.len()).step_by(2).rev() {
            let below = tree.children(pair as u32).map(|c| tree.height(c)).max();
            tree.heights[pair] = 1 + below.unwrap_or(0);
        }
        Ok(tree)
    }

    fn height(&self, pair: u32) -> u32 {
        self.heights[pair as usize]
    }

    fn children(&self, pair: u32) -> impl Iterator<Item = u32> + '_ {
        let p = pair as usize;
        self.nodes[p..p + 2]
            .iter()
            .filter(|n| !n.is_leaf())
            .map(|n| n.index())
    }

    /// Appends the pairs of the subtree of `pair`, cut `height` levels down, in vEB order.
    fn lay_out(&self, pair: u32, height: u32, order: &mut Vec<u32>) -> Fallible<()> {
        if height <= 1 {
            return order.try_push(pair);
        }
        let top = height / 2;
        self.lay_out(pair, top, order)?;
        let mut frontier = Vec::new();
        self.pairs_at_depth(pair, top, &mut frontier)?;
        for bottom in frontier {
            self.lay_out(bottom, height - top, order)?;
        }
        Ok(())
    }

    /// The pairs exactly `depth` levels below `pair`, left to right.
    fn pairs_at_depth(&self, pair: u32, depth: u32, out: &mut Vec<u32>) -> Fallible<()> {
        if depth == 0 {
            return out.try_push(pair);
        }
        for child in self.children(pair) {
            self.pairs_at_depth(child, depth - 1, out)?;
        }
        Ok(())
    }
}
