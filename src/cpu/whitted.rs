//! The Whitted ray tracer on the CPU: iterative (an explicit stack of pending rays instead of
//! recursion, as the thesis' GPU loop), Phong shading with hard shadows, mirror reflection and
//! transparency, image rows split into bands that the context's rayon pool renders.

use super::traverse::{self, Traversal, TraverseOptions};
use crate::camera::Camera;
use crate::frame::Frame;
use crate::geometry::{Hit, PrimIndex, Ray, TraversalStats, INVALID};
use crate::precision::{offset_ray_origin, OffsetMode};
use crate::render::{RenderOptions, Transparency};
use crate::scene::Committed;
use crate::shading::{phong, reflect, refract, schlick};
use glam::{Vec2, Vec3};
use rayon::prelude::*;

/// Rows per parallel band: small enough to balance two cores, large enough to amortise.
const BAND_ROWS: usize = 4;

/// Rays whose weight drops below this add less than a 1/255 step and are not traced.
const MIN_WEIGHT: f32 = 1.0 / 512.0;

/// One scene + options, shared by all bands of a frame.
pub struct Tracer<'a> {
    pub scene: &'a Committed,
    pub opts: &'a RenderOptions,
    pub traversal: Traversal,
    /// Offset of secondary-ray origins along the normal, scaled to the scene
    /// (`OffsetMode::Epsilon`; also where the checker pattern is sampled).
    pub eps: f32,
    /// The scene diagonal, for the robust offset near the origin.
    pub scale: f32,
}

impl<'a> Tracer<'a> {
    pub fn new(scene: &'a Committed, opts: &'a RenderOptions, traversal: Traversal) -> Self {
        Tracer {
            scene,
            opts,
            traversal,
            eps: 1e-5 * scene.scale(),
            scale: scene.scale(),
        }
    }

    fn traverse_options(&self, exclude: PrimIndex) -> TraverseOptions {
        TraverseOptions {
            short_stack_size: self.opts.short_stack_size,
            intersector: self.opts.intersector,
            exclude,
            ..TraverseOptions::default()
        }
    }

    /// Closest hit of `ray`, ignoring primitive `exclude` (`INVALID` for none).
    pub fn intersect(&self, ray: &Ray, exclude: PrimIndex) -> Hit {
        let mut stats = TraversalStats::default();
        let s = self.scene;
        traverse::intersect(
            &s.tree,
            &s.prims,
            ray,
            self.traversal,
            &self.traverse_options(exclude),
            &mut stats,
        )
    }

    pub fn occluded(&self, ray: &Ray, exclude: PrimIndex) -> bool {
        let mut stats = TraversalStats::default();
        let s = self.scene;
        traverse::occluded(
            &s.tree,
            &s.prims,
            ray,
            self.traversal,
            &self.traverse_options(exclude),
            &mut stats,
        )
    }

    /// The hit point of `hit` as the offset mode wants it, and the geometric normal there. The
    /// fixed epsilon keeps the historical `org + t·dir` (its default renders are unchanged); the
    /// other modes start from the point recomputed on the surface.
    pub fn surface(&self, ray: &Ray, hit: &Hit) -> (Vec3, Vec3) {
        let prims = &self.scene.prims;
        let p = match self.opts.offset_mode {
            OffsetMode::Epsilon => ray.at(hit.t),
            _ => prims.hit_point(hit, ray),
        };
        (p, prims.normal(hit.prim, p))
    }

    /// Where a secondary ray leaving `hit` at `p` into the side of the unit normal `side`
    /// starts, and which primitive it ignores (the offset modes of `crate::precision`).
    /// `n_geo` is the primitive's outward normal.
    pub fn leave(&self, hit: &Hit, p: Vec3, side: Vec3, n_geo: Vec3) -> (Vec3, PrimIndex) {
        match self.opts.offset_mode {
            OffsetMode::Epsilon => (p + self.eps * side, INVALID),
            OffsetMode::Robust => (offset_ray_origin(p, side, self.scale), INVALID),
            // Leaving a flat primitive, or a convex one to its outside, never meets it again.
            OffsetMode::ExcludePrim
                if self.scene.prims.is_flat(hit.prim) || side.dot(n_geo) > 0.0 =>
            {
                (p, hit.prim)
            }
            OffsetMode::ExcludePrim => (offset_ray_origin(p, side, self.scale), INVALID),
        }
    }

    /// Radiance along a primary ray: pops pending rays until none is left.
    pub fn radiance(&self, primary: Ray) -> Vec3 {
        let mut pending: Vec<(Ray, PrimIndex, Vec3, u32)> =
            Vec::with_capacity(2 * self.opts.max_depth as usize + 2);
        pending.push((primary, INVALID, Vec3::ONE, 1));
        let mut color = Vec3::ZERO;
        while let Some((ray, exclude, weight, depth)) = pending.pop() {
            let hit = self.intersect(&ray, exclude);
            if !hit.is_hit() {
                color += weight * self.opts.background;
                continue;
            }
            let s = self.scene;
            let m = s.material_of(hit.prim);
            let (p, n_geo) = self.surface(&ray, &hit);
            let entering = n_geo.dot(ray.dir) < 0.0;
            let n = if entering { n_geo } else { -n_geo };
            // The pattern is sampled just inside the surface: a checker boundary lying in the
            // surface itself (a checkered plane at y = 0) would otherwise flicker with rounding.
            let base = m.color_at(p - self.eps * n);
            let local_weight = 1.0 - m.reflectivity - m.transparency;
            if local_weight > 0.0 {
                let mut local = m.ambient * base;
                let (above, skip) = self.leave(&hit, p, n, n_geo);
                for light in &s.lights {
                    let to_light = light.position - above;
                    let dist = to_light.length();
                    let shadow = Ray::new(above, to_light / dist, 0.0, dist);
                    if dist > 0.0 && !self.occluded(&shadow, skip) {
                        local += phong(m, base, p, n, -ray.dir, light);
                    }
                }
                color += weight * local_weight * local;
            }
            if depth >= self.opts.max_depth {
                continue;
            }
            let mut push = |dir: Vec3, side: f32, w: f32| {
                let w = weight * w;
                if w.max_element() >= MIN_WEIGHT {
                    let (org, skip) = self.leave(&hit, p, side * n, n_geo);
                    pending.push((Ray::new(org, dir, 0.0, f32::INFINITY), skip, w, depth + 1));
                }
            };
            let mut mirror = m.reflectivity;
            if m.transparency > 0.0 {
                match self.opts.transparency {
                    Transparency::Straight => push(ray.dir, -1.0, m.transparency),
                    Transparency::Refract => {
                        let eta = if entering { 1.0 / m.ior } else { m.ior };
                        match refract(ray.dir, n, eta) {
                            Some(t) => {
                                let f = schlick(-ray.dir.dot(n), eta);
                                mirror += m.transparency * f;
                                push(t, -1.0, m.transparency * (1.0 - f));
                            }
                            None => mirror += m.transparency,
                        }
                    }
                }
            }
            if mirror > 0.0 {
                push(reflect(ray.dir, n), 1.0, mirror);
            }
        }
        color
    }
}

/// Deterministic per-pixel sample positions: a stratified grid jittered by a hash, so that a
/// render does not depend on thread scheduling.
fn sample_offset(x: u32, y: u32, s: u32, n: u32, salt: u32) -> Vec2 {
    let h = |k: u32| {
        let mut v = x.wrapping_mul(0x9E37_79B1)
            ^ y.wrapping_mul(0x85EB_CA77)
            ^ s.wrapping_mul(0xC2B2_AE3D)
            ^ k
            ^ salt;
        v ^= v >> 16;
        v = v.wrapping_mul(0x7FEB_352D);
        v ^= v >> 15;
        v = v.wrapping_mul(0x846C_A68B);
        v ^= v >> 16;
        (v >> 8) as f32 / (1u32 << 24) as f32
    };
    if n == 1 {
        return Vec2::new(0.5, 0.5);
    }
    let side = (n as f32).sqrt().ceil() as u32;
    Vec2::new(
        ((s % side) as f32 + h(1)) / side as f32,
        ((s / side) as f32 + h(2)) / side as f32,
    )
}

/// Renders `frame` in the current rayon pool (the caller installs the context's pool).
pub fn render(
    scene: &Committed,
    camera: &Camera,
    opts: &RenderOptions,
    traversal: Traversal,
    frame: &mut Frame,
) {
    let (w, h) = (frame.width(), frame.height());
    let rays = camera.rays(w, h);
    let tracer = Tracer::new(scene, opts, traversal);
    let size = Vec2::new(w as f32, h as f32);
    let row_bytes = w as usize * 4;
    let (pixels, mask) = frame.pixels_and_mask_mut();
    pixels
        .par_chunks_mut(row_bytes * BAND_ROWS)
        .enumerate()
        .for_each(|(band, chunk)| {
            for (i, px) in chunk.chunks_exact_mut(4).enumerate() {
                let idx = band * BAND_ROWS * w as usize + i;
                if mask.is_some_and(|m| m[idx] == 0) {
                    continue;
                }
                let (x, y) = ((idx % w as usize) as u32, (idx / w as usize) as u32);
                let mut c = Vec3::ZERO;
                for s in 0..opts.samples {
                    let pixel =
                        Vec2::new(x as f32, y as f32) + sample_offset(x, y, s, opts.samples, 0);
                    let lens = sample_offset(x, y, s, opts.samples.max(2), 0x5bd1_e995);
                    c += tracer.radiance(rays.ray(pixel, size, lens));
                }
                let c = (c / opts.samples as f32).clamp(Vec3::ZERO, Vec3::ONE) * 255.0 + 0.5;
                px.copy_from_slice(&[c.x as u8, c.y as u8, c.z as u8, 255]);
            }
        });
}
