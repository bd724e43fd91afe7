//! The Whitted ray tracer on the CPU: iterative (an explicit stack of pending rays instead of
//! recursion, as the thesis' GPU loop), Phong shading with hard shadows, mirror reflection and
//! transparency, image rows split into bands that the context's rayon pool renders.

use super::query::{self, QueryMode};
use super::simd::Width;
use super::traverse::{self, Traversal, TraverseOptions};
use crate::camera::{Camera, CameraRays};
use crate::frame::Frame;
use crate::geometry::{Hit, PrimIndex, Ray, TraversalStats, INVALID};
use crate::precision::{offset_ray_origin, OffsetMode};
use crate::render::{RenderOptions, Schedule, Transparency};
use crate::scene::{Committed, Material};
use crate::shading::{phong, reflect, refract};
use glam::{Vec2, Vec3};
use rayon::prelude::*;
use std::cell::OnceCell;

/// Rows per parallel band: small enough to balance two cores, large enough to amortise.
const BAND_ROWS: usize = 4;

/// Rays whose weight drops below this add less than a 1/255 step and are not traced.
const MIN_WEIGHT: f32 = 1.0 / 512.0;

/// The largest radiance bound [`min_weight`] honours: at most 16 times the rays of the fixed
/// cut-off. In scenes brighter than that, rays under 1/8192 of a pixel's weight are still
/// dropped, each worth less than `bound / 8192` of the pixel (a documented limit).
const MAX_RADIANCE_BOUND: f32 = 16.0;

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
    /// Rays of smaller weight are not traced ([`min_weight`]).
    pub min_weight: f32,
}

/// The weight below which a secondary ray cannot change its pixel by a 1/255 step:
/// `MIN_WEIGHT` divided by a bound on the radiance any ray can bring back, the background or
/// a surface's ambient plus every light's diffuse and specular term at full strength (weights
/// along a ray tree sum to at most 1). Colours, lights and the background are not capped at 1,
/// and a fixed 1/512 dropped a mirror of 0.0015 under a background of 200 (0.3 of the pixel).
/// The bound is capped at `MAX_RADIANCE_BOUND`: the rays of a tree grow about as the inverse
/// of the cut-off, and uncapped, a light of intensity 1e4 over 41 half-mirror glass planes
/// took a second per pixel at depth 64 (a light of 1e30, the cut-off 1e-33, never finished).
pub fn min_weight(scene: &Committed, opts: &RenderOptions) -> f32 {
    let lights: f32 = scene
        .lights
        .iter()
        .map(|l| (l.color * l.intensity).max_element())
        .sum();
    let surfaces = scene.materials.iter().map(|m| {
        let c = m
            .checker
            .map_or(m.color, |k| m.color.max(k.color2))
            .max_element();
        c * (m.ambient + m.diffuse * lights) + m.specular * lights
    });
    let bound = surfaces.fold(opts.background.max_element(), f32::max);
    // Never above MIN_WEIGHT: scenes whose bound is at most 1 render as before. Colours and
    // lights within [0, 1] can still exceed it (the built-in `default` scene's glass: 2.14,
    // with ~7% more render time and a step's difference on 0.5% of its pixels). A NaN bound
    // (none seen) keeps the fixed cut-off.
    MIN_WEIGHT / bound.clamp(1.0, MAX_RADIANCE_BOUND).max(1.0)
}

impl<'a> Tracer<'a> {
    pub fn new(scene: &'a Committed, opts: &'a RenderOptions, traversal: Traversal) -> Self {
        Tracer {
            scene,
            opts,
            traversal,
            eps: 1e-5 * scene.scale(),
            scale: scene.scale(),
            min_weight: min_weight(scene, opts),
        }
    }

    /// The traversal's options for a ray that ignores primitive `exclude` and starts at leaf
    /// `start` ([`Self::start_leaf`]).
    fn traverse_options(&self, exclude: PrimIndex, start: Option<u32>) -> TraverseOptions {
        TraverseOptions {
            short_stack_size: self.opts.short_stack_size,
            intersector: self.opts.intersector,
            exclude,
            start_node: start,
        }
    }

    /// Ropes++ only (the thesis' algorithm 8, [`Traversal::starts_in_origin_leaf`]; the GPU
    /// render's `start_leaf` in shaders/common.wgsl is the same): the leaf node holding the
    /// point `p()` (asked for only then: the other traversals pay nothing), where the secondary
    /// rays leaving from it start their rope walk instead of at the root
    /// (`TraverseOptions::start_node`, which the walk checks against the leaf's box). The
    /// thesis keeps the leaf in which the hit was found; here it is located from the root, a
    /// descent that costs about what the walk's own first descent does, once for all the
    /// shadow rays of a point and its mirror ray. Same images; CPU ropes++ renders (`rt2 render
    /// S --traversal ropes++ --backend cpu --threads 1`, 1376×768) ran 1.06× as fast on the
    /// bunny, 1.04–1.08× on spheres3 and 1.10× on spheres2.
    pub fn start_leaf(&self, p: impl FnOnce() -> Vec3) -> Option<u32> {
        (self.traversal.starts_in_origin_leaf() && self.scene.tree.ropes.is_some())
            .then(|| self.scene.tree.locate_leaf(p()))
    }

    /// Closest hit of `ray`, ignoring primitive `exclude` (`INVALID` for none), its walk started
    /// at leaf `start` if the traversal takes one ([`Self::start_leaf`]).
    pub fn intersect(&self, ray: &Ray, exclude: PrimIndex, start: Option<u32>) -> Hit {
        let mut stats = TraversalStats::default();
        let s = self.scene;
        let opts = self.traverse_options(exclude, start);
        traverse::intersect(&s.tree, &s.prims, ray, self.traversal, &opts, &mut stats)
    }

    /// Whether anything blocks `ray`, as [`Self::intersect`] walks.
    pub fn occluded(&self, ray: &Ray, exclude: PrimIndex, start: Option<u32>) -> bool {
        let mut stats = TraversalStats::default();
        let s = self.scene;
        let opts = self.traverse_options(exclude, start);
        traverse::occluded(&s.tree, &s.prims, ray, self.traversal, &opts, &mut stats)
    }

    /// Radiance along a primary ray: pops pending rays until none is left.
    pub fn radiance(&self, primary: Ray) -> Vec3 {
        // Each pending ray with the leaf its walk starts in: none for the primary; a secondary
        // ray's is located when it is pushed ([`Self::start_leaf`]).
        let mut pending: Vec<(Ray, PrimIndex, Vec3, u32, Option<u32>)> =
            Vec::with_capacity(2 * self.opts.max_depth as usize + 2);
        pending.push((primary, INVALID, Vec3::ONE, 1, None));
        let mut color = Vec3::ZERO;
        while let Some((ray, exclude, weight, depth, start)) = pending.pop() {
            let hit = self.intersect(&ray, exclude, start);
            if !hit.is_hit() {
                color += weight * self.opts.background;
                continue;
            }
            let s = self.surface(&ray, &hit);
            // The shadow rays and the mirror ray all leave from one point (`leave(s, s.n)`):
            // its leaf is located once, by the first of them that is traced.
            let above = OnceCell::new();
            let above_leaf = || *above.get_or_init(|| self.start_leaf(|| self.leave(&s, s.n).0));
            if s.local_weight > 0.0 {
                let start = above_leaf();
                let local =
                    self.local(&s, &ray, |shadow, skip| !self.occluded(shadow, skip, start));
                color += weight * s.local_weight * local;
            }
            self.secondary(&s, &ray, weight, depth, |r, skip, w, d, leaves_above| {
                let start = if leaves_above {
                    above_leaf()
                } else {
                    self.start_leaf(|| r.org)
                };
                pending.push((r, skip, w, d, start))
            });
        }
        color
    }

    /// The shading point of a hit: position, normal facing the ray, material, texture colour.
    /// The fixed epsilon keeps the historical point `org + t·dir`; the other offset modes
    /// start from the point recomputed on the surface. A sphere's or ellipsoid's normal is
    /// re-solved relative to its centre in every mode (`PrimitiveSet::shading_surface`).
    pub fn surface(&self, ray: &Ray, hit: &Hit) -> Surface<'a> {
        let s = self.scene;
        let m = s.material_of(hit.prim);
        let on_surface = self.opts.offset_mode != OffsetMode::Epsilon;
        let (p, n_geo) = s.prims.shading_surface(hit, ray, on_surface);
        let entering = n_geo.dot(ray.dir) < 0.0;
        let n = if entering { n_geo } else { -n_geo };
        Surface {
            m,
            prim: hit.prim,
            p,
            n,
            n_geo,
            entering,
            // The pattern is sampled just inside the surface: a checker boundary lying in the
            // surface itself (a checkered plane at y = 0) would otherwise flicker with rounding.
            // Inside is behind the primitive's own normal, not the one facing the ray: a plane
            // seen from below showed the other colour of each square.
            base: m.color_at(p - self.eps * n_geo),
            local_weight: 1.0 - m.reflectivity - m.transparency,
        }
    }

    /// Where a secondary ray leaving surface `s` into the side of the unit normal `side`
    /// starts, and which primitive it ignores (the offset modes of `crate::precision`).
    pub fn leave(&self, s: &Surface, side: Vec3) -> (Vec3, PrimIndex) {
        match self.opts.offset_mode {
            OffsetMode::Epsilon => (s.p + self.eps * side, INVALID),
            OffsetMode::Robust => (offset_ray_origin(s.p, side, self.scale), INVALID),
            // Leaving a flat primitive, or a convex one to its outside, never meets it again.
            OffsetMode::ExcludePrim
                if self.scene.prims.is_flat(s.prim) || side.dot(s.n_geo) > 0.0 =>
            {
                (s.p, s.prim)
            }
            OffsetMode::ExcludePrim => (offset_ray_origin(s.p, side, self.scale), INVALID),
        }
    }

    /// The shadow rays of a surface, light by light, with the primitive each ignores (`None`
    /// for a light at the point itself).
    fn shadow_rays<'s>(
        &'s self,
        s: &'s Surface,
    ) -> impl Iterator<Item = Option<(Ray, PrimIndex)>> + 's {
        let (above, skip) = self.leave(s, s.n);
        self.scene.lights.iter().map(move |light| {
            let to_light = light.position - above;
            let dist = crate::shading::distance(to_light);
            // As before where |to_light|² is a normal float (the GPU's division, bit for bit).
            let dir = match to_light.length_squared().is_normal() {
                true => to_light / dist,
                false => crate::shading::direction_to(to_light),
            };
            (dist > 0.0).then(|| (Ray::new(above, dir, 0.0, dist), skip))
        })
    }

    /// Ambient plus the Phong term of every light whose shadow ray `lit` says is unblocked.
    fn local(&self, s: &Surface, ray: &Ray, mut lit: impl FnMut(&Ray, PrimIndex) -> bool) -> Vec3 {
        let mut local = s.m.ambient * s.base;
        for (light, shadow) in self.scene.lights.iter().zip(self.shadow_rays(s)) {
            if shadow.is_some_and(|(r, skip)| lit(&r, skip)) {
                local += phong(s.m, s.base, s.p, s.n, -ray.dir, light);
            }
        }
        local
    }

    /// The reflected and transmitted rays of a surface with their weights, below the depth limit,
    /// each with whether it leaves from the side of the facing normal, where the shadow rays
    /// leave from (`leave(s, s.n)`: the same origin).
    fn secondary(
        &self,
        s: &Surface,
        ray: &Ray,
        weight: Vec3,
        depth: u32,
        mut out: impl FnMut(Ray, PrimIndex, Vec3, u32, bool),
    ) {
        if depth >= self.opts.max_depth {
            return;
        }
        let (m, n) = (s.m, s.n);
        let mut push = |dir: Vec3, side: f32, w: f32| {
            let w = weight * w;
            if w.max_element() >= self.min_weight {
                let (org, skip) = self.leave(s, side * n);
                let ray = Ray::new(org, dir, 0.0, f32::INFINITY);
                out(ray, skip, w, depth + 1, side > 0.0);
            }
        };
        let mut mirror = m.reflectivity;
        if m.transparency > 0.0 {
            match self.opts.transparency {
                Transparency::Straight => push(ray.dir, -1.0, m.transparency),
                Transparency::Refract => {
                    let eta = if s.entering { 1.0 / m.ior } else { m.ior };
                    match refract(ray.dir, n, eta) {
                        Some((t, f)) => {
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
}

/// A hit being shaded, shared by the depth-first and breadth-first schedules.
pub struct Surface<'a> {
    pub m: &'a Material,
    pub prim: PrimIndex,
    pub p: Vec3,
    /// Normal turned to face the incoming ray.
    pub n: Vec3,
    /// The primitive's outward normal.
    pub n_geo: Vec3,
    pub entering: bool,
    pub base: Vec3,
    pub local_weight: f32,
}

/// Deterministic per-pixel sample positions: a stratified grid jittered by a hash, so that a
/// render does not depend on thread scheduling. Sample `s` takes cell `cell` (row by row) of
/// a grid of `side` cells a side.
fn stratified(x: u32, y: u32, s: u32, cell: u32, side: u32, salt: u32) -> Vec2 {
    let h = |k: u32| (mix(x, y, s, k ^ salt) >> 8) as f32 / (1u32 << 24) as f32;
    Vec2::new(
        ((cell % side) as f32 + h(1)) / side as f32,
        ((cell / side) as f32 + h(2)) / side as f32,
    )
}

/// A hash of pixel `(x, y)`, sample `s` and key `k`.
fn mix(x: u32, y: u32, s: u32, k: u32) -> u32 {
    let mut v =
        x.wrapping_mul(0x9E37_79B1) ^ y.wrapping_mul(0x85EB_CA77) ^ s.wrapping_mul(0xC2B2_AE3D) ^ k;
    v ^= v >> 16;
    v = v.wrapping_mul(0x7FEB_352D);
    v ^= v >> 15;
    v = v.wrapping_mul(0x846C_A68B);
    v ^ (v >> 16)
}

/// The offset of sample `s` of `n` inside its pixel (the pixel's centre for one sample).
fn pixel_offset(x: u32, y: u32, s: u32, n: u32) -> Vec2 {
    if n == 1 {
        return Vec2::new(0.5, 0.5);
    }
    let k = side(n);
    if k * k == n {
        return stratified(x, y, s, s, k, 0);
    }
    // Not a square: n-rooks (one sample per row and per column of an n × n grid, the columns
    // dealt by a per-pixel permutation), so that every part of the pixel is sampled alike.
    // The first rows of the `side(n)` grid alone left 2 samples both in the top half.
    let col = permute(s, n, mix(x, y, 0, 0x68e3_1da4));
    stratified(x, y, s, s * n + col, n, 0x68e3_1da4)
}

/// The lens point (in the unit square) of sample `s` of `n`: stratified on the `side(n)` grid
/// (the pixel offsets' grid where `n` is a square; theirs is n-rooks otherwise), but each
/// pixel deals the cells to its samples in its own shuffled order (Kensler's hashed
/// permutation), and every cell can be dealt. Sample `s` used to take cell `s` for both,
/// which tied a sample's lens radius to its place in the pixel and left the
/// outer ring and lower half of the lens unused at one sample per pixel: an edge out of focus
/// blurred 3% off the thin lens' circle of confusion.
fn lens_offset(x: u32, y: u32, s: u32, n: u32) -> Vec2 {
    let side = side(n);
    let cell = permute(s, side * side, mix(x, y, 0, 0x5bd1_e995));
    stratified(x, y, s, cell, side, 0x5bd1_e995)
}

/// The grid side for `n` samples: the smallest `k` with `k² >= n`. The float square root is
/// corrected in integers, as in WGSL, where `sqrt` may be a few ULPs off (64 → 8.0000005).
fn side(n: u32) -> u32 {
    let mut k = (n as f32).sqrt().ceil() as u32;
    if k > 1 && (k - 1) * (k - 1) >= n {
        k -= 1;
    }
    if k * k < n {
        k += 1;
    }
    k
}

/// Element `i` of a permutation of `0..l` chosen by `p` (Kensler 2013, "Correlated
/// Multi-Jittered Sampling", Pixar technical memo 13-01): a hash that is a bijection on the
/// next power of two, walked until it lands below `l`.
fn permute(i: u32, l: u32, p: u32) -> u32 {
    let w = l.next_power_of_two() - 1;
    let mut i = i;
    loop {
        i ^= p;
        i = i.wrapping_mul(0xe170_893d);
        i ^= p >> 16;
        i ^= (i & w) >> 4;
        i ^= p >> 8;
        i = i.wrapping_mul(0x0929_eb3f);
        i ^= p >> 23;
        i ^= (i & w) >> 1;
        i = i.wrapping_mul(1 | p >> 27);
        i = i.wrapping_mul(0x6935_fa69);
        i ^= (i & w) >> 11;
        i = i.wrapping_mul(0x74dc_b303);
        i ^= (i & w) >> 2;
        i = i.wrapping_mul(0x9e50_1cc3);
        i ^= (i & w) >> 2;
        i = i.wrapping_mul(0xc860_a3df);
        i &= w;
        i ^= i >> 5;
        if i < l {
            // `(i + p) % l` in Kensler's paper wraps past 2^32 for `p` near it, and then two
            // indices meet.
            return (i + p % l) % l;
        }
    }
}

/// Renders `frame` in the current rayon pool (the caller installs the context's pool).
pub fn render(
    scene: &Committed,
    camera: &Camera,
    opts: &RenderOptions,
    traversal: Traversal,
    frame: &mut Frame,
) {
    if opts.schedule == Schedule::BreadthFirst {
        return render_breadth_first(scene, camera, opts, traversal, frame);
    }
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
                let c = (0..opts.samples).fold(Vec3::ZERO, |c, s| {
                    c + tracer.radiance(primary_ray(&rays, size, x, y, s, opts.samples))
                });
                px.copy_from_slice(&rgba(c, opts.samples));
            }
        });
}

/// Primary ray of sample `s` of pixel (x, y).
fn primary_ray(rays: &CameraRays, size: Vec2, x: u32, y: u32, s: u32, samples: u32) -> Ray {
    let pixel = Vec2::new(x as f32, y as f32) + pixel_offset(x, y, s, samples);
    let lens = lens_offset(x, y, s, samples);
    rays.ray(pixel, size, lens)
}

/// The pixel of the sum `c` of `samples` radiances.
fn rgba(c: Vec3, samples: u32) -> [u8; 4] {
    let c = (c / samples as f32).clamp(Vec3::ZERO, Vec3::ONE) * 255.0 + 0.5;
    [c.x as u8, c.y as u8, c.z as u8, 255]
}

/// A ray of a wavefront: its weight in the pixel, its depth and the sample (path) it adds to.
#[derive(Clone, Copy)]
struct WaveRay {
    ray: Ray,
    /// The primitive the ray ignores (`OffsetMode::ExcludePrim`; `INVALID` for none).
    exclude: PrimIndex,
    weight: Vec3,
    depth: u32,
    path: u32,
}

/// Most samples traced as one wavefront: the pixels are rendered in runs of at most this many
/// primary rays, so that a frame's memory does not grow with its size × samples (a 4096² frame
/// at 64 samples is a billion paths; as one wavefront its rays alone took 3.5 GB and the
/// allocation aborted). A million rays keeps the stream queries long.
const WAVE_PATHS: usize = 1 << 20;

/// Breadth-first (wavefront) rendering, the schedule the vectorised-traversal paper needs: the
/// closest hits of a depth's rays as stream queries, then their shadow rays as one occlusion query,
/// then the next depth's rays (a depth larger than a slice of [`WAVE_RAYS`] is traced slice by
/// slice, each slice's next depth before the next slice). Each sample's radiance is the depth-first
/// one's terms (same rays, same hits, same shading) summed in another order; float addition is not
/// associative, so a pixel may round to the next 1/255 step. Each ray carries the primitive it
/// ignores (`OffsetMode::ExcludePrim`) into the stream queries. The traced pixels go in runs of at
/// most [`WAVE_PATHS`] samples.
fn render_breadth_first(
    scene: &Committed,
    camera: &Camera,
    opts: &RenderOptions,
    traversal: Traversal,
    frame: &mut Frame,
) {
    let (w, h) = (frame.width(), frame.height());
    let rays = camera.rays(w, h);
    let size = Vec2::new(w as f32, h as f32);
    let tracer = Tracer::new(scene, opts, traversal);
    let (pixels, mask) = frame.pixels_and_mask_mut();
    // The traced pixels, taken a run at a time (a list of all of them would be 4 bytes per
    // pixel: 4 GiB at the largest frame).
    let mut traced = (0..w * h).filter(|&i| mask.is_none_or(|m| m[i as usize] != 0));
    let samples = opts.samples;
    let run = (WAVE_PATHS / samples as usize).max(1);
    loop {
        let pixels_run: Vec<u32> = traced.by_ref().take(run).collect();
        if pixels_run.is_empty() {
            break;
        }
        let wave: Vec<WaveRay> = pixels_run
            .par_iter()
            .enumerate()
            .flat_map_iter(|(k, &i)| {
                let rays = &rays;
                (0..samples).map(move |s| WaveRay {
                    ray: primary_ray(rays, size, i % w, i / w, s, samples),
                    exclude: INVALID,
                    weight: Vec3::ONE,
                    depth: 1,
                    path: (k as u32) * samples + s,
                })
            })
            .collect();
        let color = trace_wavefronts(scene, &tracer, opts, traversal, wave, pixels_run.len());
        for (k, &i) in pixels_run.iter().enumerate() {
            let s = samples as usize;
            let c = color[k * s..(k + 1) * s]
                .iter()
                .fold(Vec3::ZERO, |a, &c| a + c);
            let i = i as usize * 4;
            pixels[i..i + 4].copy_from_slice(&rgba(c, samples));
        }
    }
}

/// Most rays and shadow rays traced in one step of a wavefront. A hit on a material both
/// reflective and transparent spawns two rays, so a wave can double at every depth (up to 512
/// rays per path before the weight cut-off): traced whole, a 1024² frame at depth 12 asked for
/// tens of GB and aborted. A wave larger than this is traced in slices, the newest first, and
/// each slice's next wave before the slice after it, so at most one slice waits per depth.
const WAVE_RAYS: usize = 1 << 18;

/// Traces the wavefront `wave` of `pixels` pixels' samples and every wavefront it spawns, depth
/// by depth in slices of at most [`WAVE_RAYS`] rays and shadow rays; returns the radiance of
/// each path (`WaveRay::path`).
fn trace_wavefronts(
    scene: &Committed,
    tracer: &Tracer,
    opts: &RenderOptions,
    traversal: Traversal,
    wave: Vec<WaveRay>,
    pixels: usize,
) -> Vec<Vec3> {
    let topts = tracer.traverse_options(INVALID, None);
    let samples = opts.samples;
    let mut color = vec![Vec3::ZERO; pixels * samples as usize];
    let mut hits = Vec::new();
    let mut shadows = Vec::new();
    let mut skips = Vec::new();
    let mut blocked = Vec::new();
    // Each ray of a slice may add a shadow ray per light.
    let slice = (WAVE_RAYS / (1 + scene.lights.len())).max(1);
    let mut waiting = vec![wave];
    while let Some(mut rest) = waiting.pop() {
        let wave = rest.split_off(rest.len().saturating_sub(slice));
        if !rest.is_empty() {
            waiting.push(rest);
        }
        let rays: Vec<Ray> = wave.iter().map(|r| r.ray).collect();
        let exclude: Vec<PrimIndex> = wave.iter().map(|r| r.exclude).collect();
        hits.resize(rays.len(), Hit::MISS);
        query::trace(
            scene,
            (&rays, Some(&exclude)),
            &mut hits,
            traversal,
            &topts,
            QueryMode::Stream,
            Width::best(),
        );
        let surfaces: Vec<Option<Surface>> = wave
            .par_iter()
            .zip(&hits)
            .map(|(r, hit)| hit.is_hit().then(|| tracer.surface(&r.ray, hit)))
            .collect();
        shadows.clear();
        skips.clear();
        for s in surfaces.iter().flatten().filter(|s| s.local_weight > 0.0) {
            for (r, skip) in tracer.shadow_rays(s).flatten() {
                shadows.push(r);
                skips.push(skip);
            }
        }
        blocked.resize(shadows.len(), false);
        query::trace(
            scene,
            (&shadows, Some(&skips)),
            &mut blocked,
            traversal,
            &topts,
            QueryMode::Stream,
            Width::best(),
        );
        let mut blocked = blocked.iter();
        let mut next = Vec::new();
        for (r, s) in wave.iter().zip(&surfaces) {
            let c = &mut color[r.path as usize];
            let Some(s) = s else {
                *c += r.weight * opts.background;
                continue;
            };
            if s.local_weight > 0.0 {
                let local = tracer.local(s, &r.ray, |_, _| !blocked.next().is_some_and(|&b| b));
                *c += r.weight * s.local_weight * local;
            }
            tracer.secondary(
                s,
                &r.ray,
                r.weight,
                r.depth,
                |ray, exclude, weight, depth, _| {
                    next.push(WaveRay {
                        ray,
                        exclude,
                        weight,
                        depth,
                        path: r.path,
                    })
                },
            );
        }
        if !next.is_empty() {
            waiting.push(next);
        }
    }
    color
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{PointLight, Scene, Shape};

    /// The cut-off follows the scene's brightness (a faint mirror of a bright background is
    /// traced) up to its cap: a light of 1e30 made it 1e-33, and renders never finished.
    #[test]
    fn the_weight_cut_off_is_bounded_by_the_scene_and_by_its_cap() {
        let cut_off = |intensity: f32, background: f32| {
            let mut s = Scene::new();
            let sphere = Shape::Sphere {
                center: Vec3::ZERO,
                radius: 1.0,
            };
            s.add_object(sphere, 0).unwrap();
            s.add_light(PointLight {
                position: Vec3::Z * 5.0,
                color: Vec3::ONE,
                intensity,
            })
            .unwrap();
            s.commit().unwrap();
            let opts = RenderOptions {
                background: Vec3::splat(background),
                ..RenderOptions::default()
            };
            min_weight(s.committed().unwrap(), &opts)
        };
        // The default material (colour 0.8, ambient 0.1, diffuse 0.9, specular 0.3) under a
        // light of 0.5: 0.8 * (0.1 + 0.45) + 0.15 = 0.59, under 1.
        assert_eq!(cut_off(0.5, 0.0), MIN_WEIGHT);
        // A background of 4 is the brightest thing.
        assert_eq!(cut_off(0.5, 4.0), MIN_WEIGHT / 4.0);
        for intensity in [1e4, 1e30, f32::MAX] {
            assert_eq!(cut_off(intensity, 0.0), MIN_WEIGHT / MAX_RADIANCE_BOUND);
        }
    }

    /// Ropes++ starts secondary rays in the leaf of their origin (the thesis): `start_leaf`
    /// names, for ropes++ on a tree with ropes only, a leaf whose box holds the point; the walk
    /// from it finds what the walk from the root finds, visiting fewer nodes; and a render with
    /// ropes++ is the standard traversal's, pixel for pixel, on scenes of shadows, mirrors and
    /// glass.
    #[test]
    fn ropes_plus_plus_starts_secondary_rays_in_the_leaf_of_their_origin() {
        for name in ["spheres2", "default"] {
            let mut b = crate::scene::builtin::by_name(name).unwrap();
            let opts = RenderOptions {
                max_depth: b.max_depth,
                ..RenderOptions::default()
            };
            b.scene.commit().unwrap();
            let plain = b.scene.committed().unwrap();
            let centre = plain.bounds.center();
            let rope_less = Tracer::new(plain, &opts, Traversal::RopesPlusPlus);
            assert_eq!(rope_less.start_leaf(|| centre), None, "{name}: no ropes");
            b.scene.ensure_ropes().unwrap();
            let c = b.scene.committed().unwrap();
            let ropes = c.tree.ropes.as_ref().unwrap();
            let standard = Tracer::new(c, &opts, Traversal::Standard);
            assert_eq!(standard.start_leaf(|| centre), None, "{name}: standard");
            let tracer = Tracer::new(c, &opts, Traversal::RopesPlusPlus);

            let (w, h) = (48u32, 32u32);
            let size = Vec2::new(w as f32, h as f32);
            let camera = b.camera.rays(w, h);
            let (mut hinted, mut nodes_hint, mut nodes_root) = (0, 0, 0);
            for (x, y) in (0..h).flat_map(|y| (0..w).map(move |x| (x, y))) {
                let primary =
                    camera.ray(Vec2::new(x as f32 + 0.5, y as f32 + 0.5), size, Vec2::ZERO);
                let hit = tracer.intersect(&primary, INVALID, None);
                if !hit.is_hit() {
                    continue;
                }
                let s = tracer.surface(&primary, &hit);
                let (org, skip) = tracer.leave(&s, s.n);
                let start = tracer.start_leaf(|| org).unwrap();
                assert!(c.tree.nodes[start as usize].is_leaf(), "{name}: a leaf");
                let leaf_box = ropes.leaf_bounds[ropes.leaf_number(start)];
                if !(leaf_box.min.cmplt(org).all() && org.cmplt(leaf_box.max).all()) {
                    continue; // On a face: the walk takes the root instead.
                }
                hinted += 1;
                let mirror = Ray::new(org, reflect(primary.dir, s.n), 0.0, f32::INFINITY);
                let want = tracer.intersect(&mirror, skip, None);
                for (hint, nodes) in [(Some(start), &mut nodes_hint), (None, &mut nodes_root)] {
                    let mut stats = TraversalStats::default();
                    let topts = tracer.traverse_options(skip, hint);
                    let how = Traversal::RopesPlusPlus;
                    let got =
                        traverse::intersect(&c.tree, &c.prims, &mirror, how, &topts, &mut stats);
                    assert_eq!(got, want, "{name} ({x}, {y})");
                    *nodes += stats.nodes_visited;
                }
            }
            println!(
                "{name}: {hinted} origins inside a leaf; {nodes_hint} nodes from their leaves, \
                 {nodes_root} from the root"
            );
            assert!(
                hinted > 100,
                "{name}: {hinted} origins strictly inside a leaf"
            );
            assert!(
                nodes_hint < nodes_root,
                "{name}: {nodes_hint} nodes from the origins' leaves, {nodes_root} from the root"
            );

            let image = |how| {
                let mut frame = Frame::new(w, h).unwrap();
                render(c, &b.camera, &opts, how, &mut frame);
                frame.pixels().to_vec()
            };
            assert!(
                image(Traversal::RopesPlusPlus) == image(Traversal::Standard),
                "{name}: images"
            );
        }
    }

    /// The lens deals every cell once per pixel: `permute` is a bijection of `0..l` for every
    /// grid the samples use, with seeds near 2^32 too (where `(i + p) % l` wrapped and two
    /// indices met), and `side` is the smallest grid that holds `n` samples.
    #[test]
    fn lens_cells_are_a_permutation_and_grids_hold_their_samples() {
        for n in 1..=1024u32 {
            let k = side(n);
            assert!(k * k >= n && (k - 1) * (k - 1) < n, "side({n}) = {k}");
        }
        let seeds = [0, 1, 0x5bd1_e995, u32::MAX - 2, u32::MAX - 1, u32::MAX];
        for l in (1..=32u32).map(|k| k * k).chain([2, 3, 5, 7, 1000, 1023]) {
            for (j, p) in seeds
                .into_iter()
                .chain((0..20).map(|k| mix(k, l, 0, 7)))
                .enumerate()
            {
                let mut seen = vec![false; l as usize];
                for i in 0..l {
                    let c = permute(i, l, p) as usize;
                    assert!(
                        c < l as usize && !seen[c],
                        "l {l}, seed {j} ({p:#x}): {i} -> {c}"
                    );
                    seen[c] = true;
                }
            }
        }
    }
}
