//! Builder entry point and options: picks the root voxel and the primitives, runs one of the two
//! builders (which write the node arrays in depth-first order), lays the nodes out as asked,
//! fills the statistics and adds ropes when asked.

use std::time::Instant;

use super::split::Subtree;
use super::{layout, midpoint, sah, stats, KdTree};
use crate::fallible::{self, Fallible};
use crate::geometry::{Aabb, Clipped};

/// What a builder needs to know of the primitives.
pub trait BuildInput: Sync {
    fn prim_count(&self) -> usize;
    fn bounds(&self, prim: usize) -> Aabb;
    /// Bounds of the part of `prim` inside `voxel` (`Aabb::EMPTY` when they do not overlap),
    /// and which of their faces are padded.
    fn clipped_bounds(&self, prim: usize, voxel: &Aabb) -> Clipped;
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Builder {
    /// Surface Area Heuristic with perfect splits, O(N log N) (Wald & Havran 2006).
    Sah,
    /// Split at the voxel centre (the vectorised-traversal paper).
    Midpoint,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Layout {
    /// Sibling pairs in depth-first (pre-)order: a subtree is one contiguous run of pairs.
    DepthFirst,
    /// Cache-oblivious van Emde Boas order of the sibling pairs (see `layout.rs`).
    VanEmdeBoas,
}

/// Depth limit applied to every tree whatever `max_depth` asks for, so that a traversal stack
/// of this many entries is always enough (GPU kernels size theirs statically).
pub const MAX_DEPTH_LIMIT: u32 = 64;

/// Midpoint trees default to depth 20, the best value of the vectorised-traversal paper. The
/// paper's n-ray gain over single rays is not theirs alone: on the bunny's `incoherent_262144`
/// (16 lanes, one thread, the two modes alternating) streams ran 2.1× as fast as single rays on
/// this tree and 2.25× on the default SAH tree, which is faster for both.
const MIDPOINT_DEFAULT_DEPTH: u32 = 20;

#[derive(Clone, Copy, Debug)]
pub struct BuildOptions {
    pub builder: Builder,
    pub layout: Layout,
    /// Maximum depth; `None` picks `8 + 1.3 log2 N` (Havran's rule) for SAH, 20 for midpoint.
    /// Clamped to [`MAX_DEPTH_LIMIT`].
    pub max_depth: Option<u32>,
    /// Midpoint trees stop splitting at this many primitives (or before, where a split would
    /// leave every primitive in both children).
    pub leaf_size: u32,
    /// SAH cost of one traversal step, relative to one primitive test (1.0). Larger values make
    /// fewer, fuller leaves: a smaller tree built faster, slower coherent single rays. The
    /// default 3 keeps the dragon's tree (15 MiB) under the RT² thesis' 17.2 MB and builds about
    /// 20% faster than 2. It costs up to 6% of the single rays per second (bunny, primary rays)
    /// and up to 9% of incoherent packets (dragon); streams are unchanged within noise (`rt2
    /// bench build`, "Effect of the SAH traversal cost").
    pub traversal_cost: f32,
    /// Factor λ applied to the SAH cost of a split that leaves one side empty (Wald & Havran
    /// 2006, §4.3 use 0.8): below 1 it favours cutting off empty space. "Empty" means nothing
    /// reaches into that side: primitives touching the plane are in both children (`sah`).
    /// Against no bonus, 0.8 gave the bunny's tree 48% more nodes (three times the empty
    /// leaves) and a 3% lower SAH cost, and ran 16-lane packets and single rays 4–7% faster on
    /// its 1024² primary rays, streams 4% slower on its incoherent set; on the dragon every
    /// mode ran 2–17% faster (one thread, alternating processes). (Until the `sah` sweep
    /// judged emptiness by what reaches inside a side, no split counted as empty and this
    /// factor did nothing.)
    pub empty_bonus: f32,
    /// Most leaf references (entries of the leaves' primitive lists) the tree may hold per
    /// primitive; a node whose children would exceed its share stays a leaf. A split copies the
    /// primitives that straddle its plane into both children, and neither builder's own rule
    /// bounds how often that compounds: with coincident large triangles among tiny ones, every
    /// split separates a few tiny ones and copies all the large ones. 6,000 such triangles
    /// asked a midpoint build for gigabytes (and Rust aborts on a failed allocation), 2,000 made
    /// a SAH tree of 135 references per triangle. Real scenes need far fewer (2.5–3.4 with
    /// SAH, 2.5–7 with midpoint splits); the default 32 leaves their SAH trees unchanged and
    /// keeps a few dozen nodes deep in dense spots of three midpoint trees (the Snowden bust,
    /// spheres2, spheres3) as leaves, at an equal or lower SAH cost.
    pub references_per_prim: u32,
    pub ropes: bool,
}

impl Default for BuildOptions {
    fn default() -> Self {
        BuildOptions {
            builder: Builder::Sah,
            layout: Layout::DepthFirst,
            max_depth: None,
            leaf_size: 4,
            traversal_cost: 3.0,
            empty_bonus: 0.8,
            references_per_prim: 32,
            ropes: false,
        }
    }
}

impl BuildOptions {
    /// The depth limit for `prim_count` primitives: the explicit one, else the builder's default.
    pub fn depth_limit(&self, prim_count: usize) -> u32 {
        let depth = self.max_depth.unwrap_or(match self.builder {
            Builder::Sah => (8.0 + 1.3 * (prim_count.max(1) as f64).log2()).round() as u32,
            Builder::Midpoint => MIDPOINT_DEFAULT_DEPTH,
        });
        depth.min(MAX_DEPTH_LIMIT)
    }
}

/// Builds the tree of `input`.
///
/// The root voxel is the union of the primitive bounds. Primitives whose bounds are empty or not
/// finite cannot be hit and are left out of the tree. With no primitive left, the tree is a
/// single empty leaf and `bounds` is `Aabb::EMPTY` (infinite, never NaN), which overlaps nothing.
///
/// The result depends only on `input` and `opts`, not on the number of threads of the rayon
/// pool the call runs in: the builders write the node arrays in depth-first order whichever
/// parts ran in parallel (see `split::Subtree`).
///
/// Fails, rather than aborting the process, when the memory for the tree or its build cannot
/// be allocated: every allocation that grows with the input goes through [`crate::fallible`].
pub fn build(input: &dyn BuildInput, opts: &BuildOptions) -> Fallible<KdTree> {
    let start = Instant::now();
    let prims: Vec<(u32, Aabb)> = fallible::collect(
        (0..input.prim_count())
            .map(|p| (p as u32, input.bounds(p)))
            .filter(|(_, b)| !b.is_empty() && b.is_finite()),
    )?;
    let bounds = prims.iter().fold(Aabb::EMPTY, |acc, (_, b)| acc.union(*b));
    let max_depth = opts.depth_limit(prims.len());
    let built = if prims.is_empty() {
        Subtree::built(|slot| slot.leaf(Vec::new()))?
    } else {
        match opts.builder {
            // Beyond 2^29 primitives (more memory than a machine of this kind has) the SAH
            // builder's packed events run out of bits; the midpoint builder still works.
            Builder::Sah if prims.len() <= sah::MAX_PRIMS => {
                sah::build(input, prims, bounds, max_depth, opts)?
            }
            Builder::Sah => midpoint::build(input, prims, bounds, max_depth, opts)?,
            Builder::Midpoint => midpoint::build(input, prims, bounds, max_depth, opts)?,
        }
    };
    let mut tree = layout::lay_out(built, bounds, opts.layout)?;
    tree.stats = stats::tree_stats(&tree, opts.traversal_cost);
    if opts.ropes {
        tree.ensure_ropes()?;
    }
    tree.stats.build_ms = start.elapsed().as_secs_f32() * 1e3;
    Ok(tree)
}
