//! Render options shared by every backend.

use crate::cpu::traverse::Traversal;
use crate::precision::{Intersector, OffsetMode};
use glam::Vec3;

/// How transparent materials pass light.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Transparency {
    /// The RT² mode: the ray continues unbent through the surface.
    Straight,
    /// Snell's law with Fresnel-weighted reflection (Schlick); total internal reflection
    /// sends all the light back.
    Refract,
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RenderOptions {
    /// Longest chain of rays from the eye (1 = primary rays only, plus shadows).
    pub max_depth: u32,
    /// Samples per pixel (stratified; also sample the lens).
    pub samples: u32,
    /// `None` lets the renderer choose (AUTO).
    pub traversal: Option<Traversal>,
    pub short_stack_size: usize,
    pub transparency: Transparency,
    pub background: Vec3,
    /// The ray–triangle test (`crate::precision`).
    pub intersector: Intersector,
    /// Where secondary rays start (`crate::precision`).
    pub offset_mode: OffsetMode,
}

impl Default for RenderOptions {
    fn default() -> Self {
        RenderOptions {
            max_depth: 6,
            samples: 1,
            traversal: None,
            short_stack_size: 3,
            transparency: Transparency::Refract,
            background: Vec3::new(0.05, 0.05, 0.08),
            intersector: Intersector::MollerTrumbore,
            offset_mode: OffsetMode::Epsilon,
        }
    }
}
