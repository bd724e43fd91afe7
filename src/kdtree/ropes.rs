//! Ropes and leaf boxes (Popov, Günther, Seidel & Slusallek 2007, "Stackless kd-tree traversal
//! for high performance GPU ray tracing", §3.1).
//!
//! Every node passes its six ropes down: the child below the plane gets the child above as its
//! `+axis` rope and vice versa, the other ropes are inherited. Each rope is then pushed down
//! ("rope optimisation") to the deepest node whose voxel still covers the whole face, so that
//! a traversal following it descends as little as possible. Ropes on the root box are
//! `INVALID`.

use super::split::child_voxels;
use super::{KdNode, KdTree, RankWord, RopeLinks, Ropes, ROPE_FACES};
use crate::fallible::{self, Fallible};
use crate::geometry::{Aabb, INVALID};

pub(super) fn build_ropes(tree: &KdTree) -> Fallible<Ropes> {
    let mut out = Unpacked {
        rank: rank(&tree.nodes)?,
        links: fallible::filled([INVALID; ROPE_FACES], tree.leaf_count())?,
        leaf_bounds: fallible::filled(Aabb::EMPTY, tree.leaf_count())?,
    };
    descend(tree, 0, tree.bounds, [INVALID; ROPE_FACES], &mut out);
    Ok(Ropes {
        links: RopeLinks::pack(&out.links, tree.nodes.len())?,
        leaf_bounds: out.leaf_bounds,
        rank: out.rank,
    })
}

/// The ropes while they are built, one `u32` per rope.
struct Unpacked {
    rank: Vec<RankWord>,
    links: Vec<[u32; ROPE_FACES]>,
    leaf_bounds: Vec<Aabb>,
}

/// The rank words of `nodes`: leaf bits per 32 nodes, with the count of leaves before them.
fn rank(nodes: &[KdNode]) -> Fallible<Vec<RankWord>> {
    let mut before = 0;
    fallible::collect(nodes.chunks(32).map(|chunk| {
        let leaf_bits = chunk
            .iter()
            .enumerate()
            .filter(|(_, n)| n.is_leaf())
            .fold(0u32, |bits, (i, _)| bits | 1 << i);
        let word = RankWord { leaf_bits, before };
        before += leaf_bits.count_ones();
        word
    }))
}

fn descend(
    tree: &KdTree,
    node: u32,
    voxel: Aabb,
    mut links: [u32; ROPE_FACES],
    out: &mut Unpacked,
) {
    for (face, link) in links.iter_mut().enumerate() {
        *link = push_down(tree, *link, face, &voxel);
    }
    let n = tree.nodes[node as usize];
    if n.is_leaf() {
        let leaf = RankWord::leaf_number(&out.rank, node);
        out.links[leaf] = links;
        out.leaf_bounds[leaf] = voxel;
        return;
    }
    let axis = n.axis();
    let (below, above) = (n.index(), n.index() + 1);
    let [vb, va] = child_voxels(&voxel, axis, n.split);
    let mut links_below = links;
    links_below[2 * axis + 1] = above;
    descend(tree, below, vb, links_below, out);
    let mut links_above = links;
    links_above[2 * axis] = below;
    descend(tree, above, va, links_above, out);
}

/// Moves the rope of `face` of `voxel` from `node` down to the deepest descendant that still
/// covers the whole face. `node` is adjacent to the face: its voxel starts at the face plane.
fn push_down(tree: &KdTree, mut node: u32, face: usize, voxel: &Aabb) -> u32 {
    let (face_axis, positive) = (face / 2, face % 2 == 1);
    while node != INVALID {
        let n = tree.nodes[node as usize];
        if n.is_leaf() {
            break;
        }
        let axis = n.axis();
        node = if axis == face_axis {
            // Across a +x face the child below the plane is the one touching the face.
            n.index() + u32::from(!positive)
        } else if n.split <= voxel.min[axis] {
            n.index() + 1
        } else if n.split >= voxel.max[axis] {
            n.index()
        } else {
            break; // the plane cuts the face: this node is the deepest that covers it
        };
    }
    node
}
