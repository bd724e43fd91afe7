//! The secondary-ray half of the chart: shadow-ray self-intersections (acne) of every offset
//! mode, depth-first one ray at a time and breadth-first in batches.

use super::queries::mesh_scene;
use super::{Backends, Engine, Point};
use crate::bench::{time_ms, Args};
use glam::Vec3;
use rayon::prelude::*;
use rt2::context::{Context, QueryOptions};
use rt2::cpu::query::QueryMode;
use rt2::cpu::whitted::Tracer;
use rt2::error::Result;
use rt2::geometry::{Hit, PrimIndex, Ray, INVALID};
use rt2::precision::OffsetMode;
use rt2::render::RenderOptions;
use rt2::scene::tessellate::{self, Mesh};
use rt2::scene::{Committed, PointLight, Scene};
use std::fmt::Write as _;

/// Object id of the torus in the secondary-ray scene: the one object that is not convex.
const TORUS: u32 = 1;

/// The secondary-ray scenes: the stress meshes on a floor (placed at the origin and 1e3 away),
/// each with its 192×192 primary rays and its light.
fn secondary_scenes() -> Result<Vec<(Scene, Vec<Ray>, Vec3)>> {
    let mut scenes = Vec::new();
    for offset in [0.0f32, 1e3] {
        let o = Vec3::splat(offset);
        let mut meshes = vec![
            tessellate::uv_sphere(24, 48).placed(1.0, o + Vec3::new(0.0, 1.0, 0.0)),
            tessellate::torus(48, 24, 0.35).placed(1.0, o + Vec3::new(2.6, 0.35, 0.0)),
            tessellate::cube().placed(1.2, o + Vec3::new(-3.2, 0.0, -0.6)),
        ];
        meshes.push(Mesh {
            positions: [(-6.0, -4.0), (6.0, -4.0), (6.0, 4.0), (-6.0, 4.0)]
                .map(|(x, z)| o + Vec3::new(x, 0.0, z))
                .to_vec(),
            triangles: vec![[0, 2, 1], [0, 3, 2]],
        });
        let mut s = mesh_scene(&meshes)?;
        s.add_light(PointLight {
            position: o + Vec3::new(1.0, 6.0, 3.0),
            color: Vec3::ONE,
            intensity: 1.0,
        })?;
        s.commit()?;
        s.ensure_ropes()?;
        s.ensure_exact_vertices()?;
        let (w, h) = (192u32, 192u32);
        let eye = o + Vec3::new(0.0, 4.0, 9.0);
        let rays: Vec<Ray> = (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w) as f32 / w as f32, (i / w) as f32 / h as f32);
                let target = o + Vec3::new(-5.0 + 10.0 * x, 3.0 - 3.5 * y, 0.0);
                Ray::new(eye, target - eye, 0.0, f32::INFINITY)
            })
            .collect();
        scenes.push((s, rays, o + Vec3::new(1.0, 6.0, 3.0)));
    }
    Ok(scenes)
}

/// Secondary rays: primary rays of a 192×192 view of the stress meshes on a floor, one shadow
/// ray each to a light above. On the lit side of a convex object (uv sphere, cube, floor)
/// nothing of that object can be in the way, so a shadow ray that hits its own object is a
/// self-intersection (shadow acne). Placed at the origin and 1e3 away (where the fixed
/// epsilon is below the coordinates' ULPs). One ray at a time, each pixel's shadow ray right
/// after its primary ray (the depth-first schedule); packets, streams and the GPU trace all
/// primary rays, then all shadow rays (the breadth-first schedule), the origins computed on
/// the host in between.
pub(super) fn secondary(a: &Args, b: &Backends) -> Result<(Vec<Point>, String)> {
    let scenes = secondary_scenes()?;
    let mut points = Vec::new();
    let mut table = String::from(
        "| mode | traversal | intersector | offset | Mrays/s (primary + shadow) | self-intersections /M shadow rays |\n\
         |---|---|---|---|---|---|\n",
    );
    for (engine, ctx) in b.engines() {
        for (how, intersector) in engine.methods() {
            for mode in OffsetMode::ALL {
                let opts = RenderOptions {
                    intersector,
                    offset_mode: mode,
                    ..RenderOptions::default()
                };
                let q = engine.query(how, intersector);
                let (mut ms, mut traced, mut acne) = (0.0, 0usize, Acne::default());
                for (s, rays, light) in &scenes {
                    let c = s.committed()?;
                    let tracer = Tracer::new(c, &opts, how);
                    let mut counts = Acne::default();
                    ms += time_ms(a.runs, || {
                        counts = if engine == Engine::Cpu(QueryMode::Single) {
                            depth_first(ctx, &tracer, rays, *light)
                        } else {
                            breadth_first(ctx, &tracer, &q, rays, *light)?
                        };
                        Ok(())
                    })?;
                    traced += rays.len() + counts.shadows;
                    acne.add(&counts);
                }
                let mrays = traced as f64 / ms / 1e3;
                let error = acne.per_million();
                writeln!(
                    table,
                    "| {} | {} | {} | {} | {mrays:.2} | {error:.0} |",
                    engine.name(),
                    how.name(),
                    intersector.name(),
                    mode.name()
                )
                .ok();
                points.push(Point {
                    set: match mode {
                        OffsetMode::Epsilon => "offset epsilon",
                        OffsetMode::Robust => "offset robust",
                        OffsetMode::ExcludePrim => "offset exclude-prim",
                    },
                    method: format!("{} {}", engine.label(how, intersector), mode.name()),
                    engine,
                    mrays,
                    error,
                });
            }
        }
    }
    Ok((points, table))
}

/// Shadow rays traced, of which judged (lit side of a convex object), of which self-intersections.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct Acne {
    shadows: usize,
    checked: usize,
    selfhits: usize,
}

impl Acne {
    fn add(&mut self, o: &Acne) {
        self.shadows += o.shadows;
        self.checked += o.checked;
        self.selfhits += o.selfhits;
    }

    /// Self-intersections per million judged shadow rays.
    fn per_million(&self) -> f64 {
        self.selfhits as f64 * 1e6 / self.checked.max(1) as f64
    }
}

/// The shadow ray of a primary hit toward `light`, and what judging its hit needs.
struct Shadow {
    ray: Ray,
    skip: PrimIndex,
    /// The object the primary ray hit.
    object: u32,
    /// Whether the point lies on the lit side of a convex object, where nothing of that object
    /// can be in the way.
    judged: bool,
}

impl Shadow {
    fn of(tracer: &Tracer, ray: &Ray, hit: &Hit, light: Vec3) -> Option<Shadow> {
        if !hit.is_hit() {
            return None;
        }
        let surface = tracer.surface(ray, hit);
        let (p, side) = (surface.p, surface.n);
        let (org, skip) = tracer.leave(&surface, side);
        let to_light = light - org;
        let object = tracer.scene.origins[hit.prim as usize].object;
        Some(Shadow {
            ray: Ray::new(org, to_light.normalize(), 0.0, to_light.length()),
            skip,
            object,
            judged: object != TORUS && side.dot(light - p) > 0.0,
        })
    }

    /// This shadow ray's count, given its closest hit.
    fn judge(&self, c: &Committed, hit: &Hit) -> Acne {
        let selfhit = hit.is_hit() && c.origins[hit.prim as usize].object == self.object;
        Acne {
            shadows: 1,
            checked: self.judged as usize,
            selfhits: (self.judged && selfhit) as usize,
        }
    }
}

fn sum(a: Acne, b: Acne) -> Acne {
    let mut s = a;
    s.add(&b);
    s
}

/// Each pixel's primary ray then its shadow ray, one ray at a time (the excluded primitive of
/// the exclude-prim offset included).
fn depth_first(ctx: &Context, tracer: &Tracer, rays: &[Ray], light: Vec3) -> Acne {
    ctx.install(|| {
        rays.par_iter()
            .filter_map(|ray| Shadow::of(tracer, ray, &tracer.intersect(ray, INVALID, None), light))
            .map(|s| {
                let start = tracer.start_leaf(|| s.ray.org);
                s.judge(tracer.scene, &tracer.intersect(&s.ray, s.skip, start))
            })
            .reduce(Acne::default, sum)
    })
}

/// All primary rays as one batch query, then all shadow rays as another (`q` says how).
fn breadth_first(
    ctx: &Context,
    tracer: &Tracer,
    q: &QueryOptions,
    rays: &[Ray],
    light: Vec3,
) -> Result<Acne> {
    let c = tracer.scene;
    let mut hits = vec![Hit::MISS; rays.len()];
    ctx.intersect(c, rays, &mut hits, q)?;
    let shadows: Vec<Shadow> = ctx.install(|| {
        rays.par_iter()
            .zip(&hits)
            .filter_map(|(ray, hit)| Shadow::of(tracer, ray, hit, light))
            .collect()
    });
    let shadow_rays: Vec<Ray> = shadows.iter().map(|s| s.ray).collect();
    let mut shadow_hits = vec![Hit::MISS; shadow_rays.len()];
    if tracer.opts.offset_mode == OffsetMode::ExcludePrim {
        let skip: Vec<PrimIndex> = shadows.iter().map(|s| s.skip).collect();
        ctx.intersect_excluding(c, &shadow_rays, &skip, &mut shadow_hits, q)?;
    } else {
        ctx.intersect(c, &shadow_rays, &mut shadow_hits, q)?;
    }
    Ok(shadows
        .iter()
        .zip(&shadow_hits)
        .map(|(s, h)| s.judge(c, h))
        .fold(Acne::default(), sum))
}

#[cfg(test)]
mod tests {
    use super::*;
    use rt2::cpu::traverse::Traversal;
    use rt2::dispatch::BackendRequest;
    use rt2::precision::Intersector;

    /// The breadth-first measurement (batch queries in every CPU mode) finds the same shadow
    /// rays and the same self-intersections as the depth-first one: the modes return the same
    /// hits with either intersector, so the chart's packet and stream points differ from the
    /// single-ray point of the same method in speed only. Every offset mode; the robust and
    /// exclude-prim ones have acne on this scene (BENCHMARKS.md), so the counts compared are
    /// not all zero.
    #[test]
    fn schedules_count_the_same_acne() -> Result<()> {
        let ctx = Context::new(BackendRequest::Cpu, 2)?;
        let scenes = secondary_scenes()?;
        let mut acne_seen = 0;
        for (mode, intersector) in OffsetMode::ALL
            .into_iter()
            .flat_map(|m| Intersector::ALL.map(|i| (m, i)))
        {
            let opts = RenderOptions {
                offset_mode: mode,
                intersector,
                ..RenderOptions::default()
            };
            for (s, rays, light) in &scenes {
                let tracer = Tracer::new(s.committed()?, &opts, Traversal::Standard);
                let depth = depth_first(&ctx, &tracer, rays, *light);
                assert!(depth.checked > 1000, "{depth:?}");
                acne_seen += depth.selfhits;
                for engine in [QueryMode::Single, QueryMode::Packet, QueryMode::Stream] {
                    let q = Engine::Cpu(engine).query(Traversal::Standard, intersector);
                    let breadth = breadth_first(&ctx, &tracer, &q, rays, *light)?;
                    assert_eq!(breadth, depth, "{engine:?} {mode:?} {intersector:?}");
                }
            }
        }
        assert!(acne_seen > 0);
        Ok(())
    }
}
