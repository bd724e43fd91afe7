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

/// The order in which the CPU renderer traces rays.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Schedule {
    /// Every pixel's rays to the end before the next pixel, one ray at a time.
    #[default]
    DepthFirst,
    /// Wavefronts (the vectorised-traversal paper): all primary rays, then all shadow rays,
    /// then all reflected and refracted rays, each wave traced as ray streams.
    BreadthFirst,
}

/// Which GPU render path runs a frame (thesis §3.3); ignored on the CPU.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum GpuPathRequest {
    /// The dispatch layer picks by the share of reflective and transparent primitives.
    #[default]
    Auto,
    /// One kernel traces every ray of a pixel.
    Megakernel,
    /// One kernel per bounce; rays still alive are compacted by a prefix sum.
    Wavefront,
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
    pub schedule: Schedule,
    pub gpu_path: GpuPathRequest,
    /// The ray–triangle test (`crate::precision`).
    pub intersector: Intersector,
    /// Where secondary rays start (`crate::precision`).
    pub offset_mode: OffsetMode,
}

impl RenderOptions {
    /// The ranges every backend relies on; checked by `Context::render`, so the C API, the CLI
    /// and Rust callers all get the same errors (the C API checks first, before it builds ropes or exact vertices).
    /// Outside the ranges a render would allocate per depth (`max_depth` 2^32 asked for 400 GB
    /// and aborted), run forever (2^32 samples) or silently draw black (0 samples).
    pub fn validate(&self) -> crate::error::Result<()> {
        use crate::error::check_range;
        check_range("max_depth", self.max_depth, 1..=64)?;
        check_range("samples", self.samples, 1..=1024)?;
        check_range(
            "short_stack_size",
            self.short_stack_size,
            1..=crate::cpu::traverse::MAX_SHORT_STACK,
        )?;
        if !self.background.is_finite() || self.background.min_element() < 0.0 {
            return Err(crate::error::Error::invalid_argument(format!(
                "background is {:?} (must be finite and >= 0)",
                self.background.to_array()
            )));
        }
        Ok(())
    }
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
            schedule: Schedule::DepthFirst,
            gpu_path: GpuPathRequest::Auto,
            intersector: Intersector::MollerTrumbore,
            offset_mode: OffsetMode::Epsilon,
        }
    }
}
