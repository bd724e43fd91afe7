//! Builder entry point and options. (Stub interface; the SAH and midpoint builders land here.)

use super::KdTree;
use crate::geometry::Aabb;

/// What a builder needs to know of the primitives.
pub trait BuildInput: Sync {
    fn prim_count(&self) -> usize;
    fn bounds(&self, prim: usize) -> Aabb;
    /// Bounds of the part of `prim` inside `voxel`; `Aabb::EMPTY` when they do not overlap.
    fn clipped_bounds(&self, prim: usize, voxel: &Aabb) -> Aabb;
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
    DepthFirst,
    VanEmdeBoas,
}

#[derive(Clone, Copy, Debug)]
pub struct BuildOptions {
    pub builder: Builder,
    pub layout: Layout,
    /// Maximum depth; `None` picks `8 + 1.3 log2 N` (Havran's rule) for SAH, 20 for midpoint.
    pub max_depth: Option<u32>,
    /// Midpoint trees stop splitting at this many primitives.
    pub leaf_size: u32,
    /// SAH cost of one traversal step, relative to one primitive test (1.0).
    pub traversal_cost: f32,
    /// Fraction of the cost saved when one side of a split is empty (the empty-space bonus).
    pub empty_bonus: f32,
    pub ropes: bool,
}

impl Default for BuildOptions {
    fn default() -> Self {
        BuildOptions {
            builder: Builder::Sah,
            layout: Layout::DepthFirst,
            max_depth: None,
            leaf_size: 4,
            traversal_cost: 1.5,
            empty_bonus: 0.8,
            ropes: false,
        }
    }
}

pub fn build(_input: &dyn BuildInput, _opts: &BuildOptions) -> KdTree {
    unimplemented!("the builders are written in the kd-tree issue")
}
