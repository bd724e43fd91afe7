//! The seven single-ray kd-tree traversals of the RT² thesis (§2.4, §3.4, tables 1–2), all
//! returning the same closest hit as a brute-force search (ties to the lowest primitive index).
//!
//! - [`Traversal::Standard`]: stack of far children (algorithm 2), in `standard`.
//! - [`Traversal::KdRestart`], [`Traversal::PushDown`], [`Traversal::ShortStack`],
//!   [`Traversal::PushDownShortStack`]: algorithms 3–6, one parameterised loop in `restart`.
//! - [`Traversal::Ropes`], [`Traversal::RopesPlusPlus`]: algorithms 7–8, in `ropes`.
//!
//! The leaf work (closest hit or any hit) is a `LeafQuery` (in `common`), so each traversal is
//! written once for both [`intersect`] and [`occluded`].

mod common;
mod restart;
mod ropes;
mod standard;

pub use common::MAX_SHORT_STACK;
pub(crate) use common::{any_among, clip, clip_lanes, closest_among, tested_until, Entry, TRay};

use crate::geometry::{Aabb, Hit, PrimIndex, PrimitiveSet, Ray, RayTest, TraversalStats, INVALID};
use crate::kdtree::KdTree;
use crate::precision::Intersector;
use common::{AnyHit, Closest, LeafQuery};
use restart::Restart;

/// A kd-tree traversal algorithm.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Traversal {
    Standard,
    KdRestart,
    PushDown,
    ShortStack,
    PushDownShortStack,
    Ropes,
    RopesPlusPlus,
}

impl Traversal {
    pub const ALL: [Traversal; 7] = [
        Traversal::Standard,
        Traversal::KdRestart,
        Traversal::PushDown,
        Traversal::ShortStack,
        Traversal::PushDownShortStack,
        Traversal::Ropes,
        Traversal::RopesPlusPlus,
    ];

    /// The command-line spelling.
    pub fn name(self) -> &'static str {
        match self {
            Traversal::Standard => "standard",
            Traversal::KdRestart => "kd-restart",
            Traversal::PushDown => "push-down",
            Traversal::ShortStack => "short-stack",
            Traversal::PushDownShortStack => "push-down-short-stack",
            Traversal::Ropes => "ropes",
            Traversal::RopesPlusPlus => "ropes++",
        }
    }

    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|t| t.name() == name)
    }

    /// Whether a renderer starts its secondary rays in the leaf holding their origin
    /// ([`TraverseOptions::start_node`]): ropes++, as the thesis defines it (algorithm 8). The
    /// others descend from the root, or restart there, whatever leaf they are given.
    pub fn starts_in_origin_leaf(self) -> bool {
        self == Traversal::RopesPlusPlus
    }

    /// Whether the tree must carry ropes and leaf boxes (`KdTree::ensure_ropes`). Without them a
    /// rope traversal falls back to [`Traversal::Standard`] (same answer, other statistics).
    pub fn needs_ropes(self) -> bool {
        matches!(self, Traversal::Ropes | Traversal::RopesPlusPlus)
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TraverseOptions {
    /// Entries of the short stack (thesis: 3), clamped to [`MAX_SHORT_STACK`].
    pub short_stack_size: usize,
    /// Ropes++ only: the leaf node holding the ray's start point `at(tmin)` (a secondary ray's
    /// origin, from `KdTree::locate_leaf`), so the walk starts there instead of at the root.
    /// Checked against the leaf's box; the other traversals ignore it.
    pub start_node: Option<u32>,
    /// The ray–triangle test (see [`Intersector`] for what each guarantees).
    pub intersector: Intersector,
    /// A primitive the ray ignores (the one a secondary ray leaves, `OffsetMode::ExcludePrim`);
    /// `INVALID` for none.
    pub exclude: PrimIndex,
}

impl Default for TraverseOptions {
    fn default() -> Self {
        TraverseOptions {
            short_stack_size: 3,
            start_node: None,
            intersector: Intersector::MollerTrumbore,
            exclude: INVALID,
        }
    }
}

/// The scene box the traversal clips rays to. The watertight test must not lose a hit on a
/// triangle lying in a face of the box to the rounding of the clip (a grazing ray whose entry
/// rounds past its exit), so for it the box is padded by a few ULPs of its largest coordinate:
/// the conservative traversal bounds of Woop et al. §4. Inside the tree the rounded split
/// distances are shared by consecutive leaves, so the leaves cover the clipped segment without
/// gaps; a ray through a leaf corner may still be placed in a neighbouring leaf, which is why
/// the builders list a primitive in every leaf it touches, with padded clipped boxes
/// (`kdtree::split::classify`, `Triangle::clipped_bounds`).
pub(crate) fn scene_box(tree: &KdTree, intersector: Intersector) -> Aabb {
    match intersector {
        Intersector::MollerTrumbore => tree.bounds,
        Intersector::Watertight => {
            let b = tree.bounds;
            let pad = 4.0 * f32::EPSILON * b.min.abs().max(b.max.abs()).max_element();
            Aabb::new(b.min - pad, b.max + pad)
        }
    }
}

/// Closest hit of `ray` in `[tmin, tmax)` among the tree's primitives and the planes.
/// Degenerate rays are misses that touch nothing. The ray is traced as given: `Context`'s
/// queries first scale a direction far from unit length (`Ray::direction_scale`); the
/// renderers' rays are unit length.
pub fn intersect(
    tree: &KdTree,
    prims: &PrimitiveSet,
    ray: &Ray,
    how: Traversal,
    opts: &TraverseOptions,
    stats: &mut TraversalStats,
) -> Hit {
    if ray.is_degenerate() {
        return Hit::MISS;
    }
    let mut query = Closest {
        prims,
        ray,
        test: RayTest::new(ray, opts.intersector, opts.exclude),
        hit: Hit::MISS,
    };
    // Planes first: their hit bounds the tree search and ends it early.
    prims.intersect_planes(ray, &query.test, &mut query.hit);
    traverse(tree, ray, how, opts, &mut query, stats);
    query.hit
}

/// Whether anything is hit in `[tmin, tmax)` (shadow rays); stops at the first hit found.
/// Traced as given, as [`intersect`].
pub fn occluded(
    tree: &KdTree,
    prims: &PrimitiveSet,
    ray: &Ray,
    how: Traversal,
    opts: &TraverseOptions,
    stats: &mut TraversalStats,
) -> bool {
    if ray.is_degenerate() {
        return false;
    }
    let test = RayTest::new(ray, opts.intersector, opts.exclude);
    let mut planes = Hit::MISS;
    prims.intersect_planes(ray, &test, &mut planes);
    if planes.is_hit() {
        return true;
    }
    let mut query = AnyHit {
        prims,
        ray,
        test,
        found: false,
    };
    traverse(tree, ray, how, opts, &mut query, stats);
    query.found
}

/// The standard traversal of one subtree, `start`, for ray `ray` (primitive test `test`) of a
/// batch whose list of rays became too short to share nodes (the n-ray traversal's finish): the
/// closest hit goes into `hit` (the planes were tested already). Returns whether the ray is
/// finished there.
pub(crate) fn closest_in_subtree(
    tree: &KdTree,
    prims: &PrimitiveSet,
    ray: &Ray,
    test: &RayTest,
    start: Entry,
    hit: &mut Hit,
    stats: &mut TraversalStats,
) -> bool {
    let mut query = Closest {
        prims,
        ray,
        test: *test,
        hit: *hit,
    };
    let done = standard::traverse(tree, &TRay::new(ray), start, &mut query, stats);
    *hit = query.hit;
    done
}

/// [`closest_in_subtree`] for any-hit queries: whether something is hit in the subtree.
pub(crate) fn any_in_subtree(
    tree: &KdTree,
    prims: &PrimitiveSet,
    ray: &Ray,
    test: &RayTest,
    start: Entry,
    stats: &mut TraversalStats,
) -> bool {
    let mut query = AnyHit {
        prims,
        ray,
        test: *test,
        found: false,
    };
    standard::traverse(tree, &TRay::new(ray), start, &mut query, stats)
}

fn traverse(
    tree: &KdTree,
    ray: &Ray,
    how: Traversal,
    opts: &TraverseOptions,
    query: &mut impl LeafQuery,
    stats: &mut TraversalStats,
) {
    if tree.nodes.is_empty() {
        return;
    }
    let ray = TRay::new(ray);
    let bounds = scene_box(tree, opts.intersector);
    let restart = |short_stack, push_down| Restart {
        short_stack,
        push_down,
    };
    let Some(scene) = clip(&bounds, &ray) else {
        return;
    };
    let short = opts.short_stack_size;
    match (how, &tree.ropes) {
        (Traversal::KdRestart, _) => {
            restart::traverse(tree, &ray, scene, restart(0, false), query, stats)
        }
        (Traversal::PushDown, _) => {
            restart::traverse(tree, &ray, scene, restart(0, true), query, stats)
        }
        (Traversal::ShortStack, _) => {
            restart::traverse(tree, &ray, scene, restart(short, false), query, stats)
        }
        (Traversal::PushDownShortStack, _) => {
            restart::traverse(tree, &ray, scene, restart(short, true), query, stats)
        }
        (Traversal::Ropes, Some(ropes)) => ropes::ropes(tree, ropes, &ray, scene, query, stats),
        (Traversal::RopesPlusPlus, Some(ropes)) => {
            let start = opts.start_node;
            ropes::ropes_plus_plus(tree, ropes, scene, &ray, start, query, stats)
        }
        // Standard, and rope traversals on a tree without ropes.
        _ => {
            let (t0, t1) = scene;
            standard::traverse(tree, &ray, Entry { node: 0, t0, t1 }, query, stats);
        }
    }
}
