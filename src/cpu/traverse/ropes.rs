//! Rope traversals: ropes (Popov et al. 2007, thesis algorithm 7) and the thesis' ropes++
//! (algorithm 8). Each leaf knows its box and, per face, the node on the other side; after a leaf
//! the ray follows the rope of its exit face and descends from there to the leaf it enters — no
//! stack and no restart.
//!
//! The descent from a rope target is point location of the entry point written with ray
//! distances (`t_split <= t_entry` means "the ray is past the plane"), which is the coordinate
//! comparison of the pseudo-code with the direction sign deciding points on a split plane, and
//! rounds exactly like the other traversals' descent.

use super::common::{descend, visit_leaf, LeafQuery, TRay};
use crate::geometry::{Aabb, TraversalStats, INVALID};
use crate::kdtree::{KdTree, Ropes};

/// Exit distance and rope face of a leaf box, Popov's way: both planes of every slab are read
/// and the farther one is where the ray leaves the slab. A NaN distance (the ray lies in a face
/// plane) never exits: the ray stays inside the closed slab.
fn exit_six_faces(b: &Aabb, ray: &TRay) -> (f32, usize) {
    let mut best = (f32::INFINITY, 0);
    for axis in 0..3 {
        let (ta, tb) = (ray.dist(axis, b.min[axis]), ray.dist(axis, b.max[axis]));
        // A flat slab (`ta == tb`) is left through the face the direction points to: the other
        // rope leads back to the leaf the ray came from.
        let (t, face) = if ta > tb || (ta == tb && !ray.positive(axis)) {
            (ta, 2 * axis)
        } else if tb >= ta {
            (tb, 2 * axis + 1)
        } else {
            continue;
        };
        if t < best.0 {
            best = (t, face);
        }
    }
    best
}

/// Exit distance and rope face, ropes++'s way: the exit face of each slab follows from the
/// direction sign, so only three of the six box planes are read.
fn exit_three_faces(b: &Aabb, ray: &TRay) -> (f32, usize) {
    let mut best = (f32::INFINITY, 0);
    for axis in 0..3 {
        let positive = ray.positive(axis);
        let plane = if positive { b.max[axis] } else { b.min[axis] };
        let t = ray.dist(axis, plane);
        // NaN and +inf (parallel, or lying in the plane) never win.
        if t < best.0 {
            best = (t, 2 * axis + positive as usize);
        }
    }
    best
}

/// A rope other than `face` whose exit plane the ray meets at `t_exit` too, up to a few ULPs of
/// rounding (the ray leaves the leaf through an edge or a corner), and that leads somewhere.
fn tied_exit(b: &Aabb, links: &[u32; 6], ray: &TRay, face: usize, t_exit: f32) -> Option<u32> {
    let tol = 8.0 * f32::EPSILON * t_exit.abs().max(f32::MIN_POSITIVE);
    (0..3).find_map(|axis| {
        let positive = ray.positive(axis);
        let other = 2 * axis + positive as usize;
        let plane = if positive { b.max[axis] } else { b.min[axis] };
        let t = ray.dist(axis, plane);
        (other != face && (t - t_exit).abs() <= tol && links[other] != INVALID)
            .then_some(links[other])
    })
}

/// Where a rope walk starts and how it reads leaf boxes.
struct Walk<Exit> {
    node: u32,
    t_entry: f32,
    /// Stop once the ray has left the leaf at or beyond this distance: the end of the scene
    /// box's clip, where every other traversal's segment ends.
    t_end: f32,
    exit: Exit,
}

/// The loop of algorithms 7 and 8: locate the leaf, test its primitives, follow the exit rope.
fn walk(
    tree: &KdTree,
    ropes: &Ropes,
    ray: &TRay,
    w: Walk<impl Fn(&Aabb, &TRay) -> (f32, usize)>,
    query: &mut impl LeafQuery,
    stats: &mut TraversalStats,
) {
    let (mut node, mut t_entry) = (w.node, w.t_entry);
    // Leaves are crossed in a strict front-to-back order: more steps than leaves would be a bug.
    for _ in 0..tree.leaf_count() {
        let (at, leaf, _) = descend(tree, ray, node, t_entry, f32::INFINITY, stats, |_| {});
        let leaf_index = ropes.leaf_number(at);
        let bounds = &ropes.leaf_bounds[leaf_index];
        let (t_exit, face) = (w.exit)(bounds, ray);
        if visit_leaf(tree, leaf, t_exit, query, stats) || t_exit >= w.t_end {
            return;
        }
        node = ropes.links.get(leaf_index, face);
        if node == INVALID {
            // Leaving the scene through an edge or a corner of the leaf: the faces meeting there
            // tie up to rounding, and the neighbour across another of them may hold a hit at
            // that very point (the watertight test's scene box is padded). Go on through such
            // a face rather than stop.
            match tied_exit(bounds, &ropes.links.leaf(leaf_index), ray, face, t_exit) {
                Some(n) => node = n,
                None => return,
            }
        }
        t_entry = t_entry.max(t_exit);
    }
    debug_assert!(false, "rope walk visited more steps than there are leaves");
}

/// Ropes (Popov et al. 2007; algorithm 7): the scene box is clipped first (entry and exit), every
/// leaf exit reads all six planes of the leaf box.
pub(super) fn ropes(
    tree: &KdTree,
    ropes: &Ropes,
    ray: &TRay,
    (scene_min, scene_max): (f32, f32),
    query: &mut impl LeafQuery,
    stats: &mut TraversalStats,
) {
    let w = Walk {
        node: 0,
        t_entry: scene_min,
        t_end: scene_max,
        exit: exit_six_faces,
    };
    walk(tree, ropes, ray, w, query, stats);
}

/// Ropes++ (the thesis' algorithm 8): exits from the three planes the direction selects, and
/// secondary rays start at `start`, the leaf node holding their origin.
///
/// The thesis' entry-only scene test (the box's entry distance, its exit left to the first
/// leaf) is not kept: the scene box (`scene_box`, the tree's or its padded version) is clipped
/// as the other traversals clip it. A walk that does not know where their segments end went on,
/// at rounding ties with the box's exit, into leaves they never enter, and lost a hit at
/// `tmin` on a flat scene (both found by a helper's fuzz; `tests/traversals.rs`). The exit
/// costs three plane distances per ray.
///
/// The hint is checked against the leaf's box and used only when the origin is strictly inside:
/// on the boundary the neighbour holds the origin too (its primitives may touch it), and the
/// descent from the root searches both. A wrong hint costs the descent, never the answer.
pub(super) fn ropes_plus_plus(
    tree: &KdTree,
    ropes: &Ropes,
    (t0, t1): (f32, f32),
    ray: &TRay,
    start: Option<u32>,
    query: &mut impl LeafQuery,
    stats: &mut TraversalStats,
) {
    let origin = ray.ray.at(ray.ray.tmin);
    let holds_origin = |node: u32| {
        let n = tree.nodes.get(node as usize);
        n.is_some_and(|n| n.is_leaf()) && {
            let b = &ropes.leaf_bounds[ropes.leaf_number(node)];
            b.min.cmplt(origin).all() && origin.cmplt(b.max).all()
        }
    };
    let node = match start {
        Some(s) if holds_origin(s) => s,
        _ => 0,
    };
    let w = Walk {
        node,
        t_entry: t0,
        t_end: t1,
        exit: exit_three_faces,
    };
    walk(tree, ropes, ray, w, query, stats);
}
