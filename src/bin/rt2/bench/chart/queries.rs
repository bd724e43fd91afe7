//! The ray-query half of the chart: every method on the bunny's sets and the stress scene,
//! scored against an f64 brute-force reference.

use super::{Backends, Point};
use crate::bench::{find_set, model_scene, time_ms, Args};
use glam::{DVec3, Vec3};
use rayon::prelude::*;
use rt2::error::Result;
use rt2::geometry::{Hit, Ray};
use rt2::rayset;
use rt2::scene::tessellate::{self, Mesh};
use rt2::scene::{Committed, Scene, Shape};
use std::fmt::Write as _;

/// Errors of one method against the reference, summed over rays.
#[derive(Clone, Copy, Debug, Default)]
struct Tally {
    rays: usize,
    /// Rays from inside a closed mesh whose first hit is not that mesh (a miss, or an object
    /// beyond it): they slipped through. Exact, no reference needed.
    leaks: usize,
    false_misses: usize,
    false_hits: usize,
    wrong_prims: usize,
    /// |Δt| · |dir| / scene diagonal, over rays both hit.
    max_dt: f64,
    sum_dt: f64,
    both: usize,
    ms: f64,
    timed_rays: usize,
}

impl Tally {
    fn add(&mut self, o: &Tally) {
        self.rays += o.rays;
        self.leaks += o.leaks;
        self.false_misses += o.false_misses;
        self.false_hits += o.false_hits;
        self.wrong_prims += o.wrong_prims;
        self.max_dt = self.max_dt.max(o.max_dt);
        self.sum_dt += o.sum_dt;
        self.both += o.both;
        self.ms += o.ms;
        self.timed_rays += o.timed_rays;
    }

    fn per_million(&self, n: usize) -> f64 {
        n as f64 * 1e6 / self.rays.max(1) as f64
    }

    fn failures(&self) -> f64 {
        self.per_million(self.leaks + self.false_misses + self.false_hits + self.wrong_prims)
    }
}

/// The reference triangle test: Woop et al.'s watertight test in f64 on the exact corners,
/// edges closed (a ray through an edge or vertex hits). f64 Möller–Trumbore is not enough: it
/// leaks too where a ray passes exactly through a vertex, which the stress rays do.
fn tri_t(c: &[[f32; 3]; 3], o: DVec3, d: DVec3) -> Option<f64> {
    let kz = d.abs().max_position();
    let (mut kx, mut ky) = ((kz + 1) % 3, (kz + 2) % 3);
    if d[kz] < 0.0 {
        std::mem::swap(&mut kx, &mut ky);
    }
    let (sx, sy, sz) = (d[kx] / d[kz], d[ky] / d[kz], 1.0 / d[kz]);
    let [a, b, cc] = c.map(|v| Vec3::from(v).as_dvec3() - o);
    let shear = |p: DVec3| (p[kx] - sx * p[kz], p[ky] - sy * p[kz]);
    let ((ax, ay), (bx, by), (cx, cy)) = (shear(a), shear(b), shear(cc));
    let (u, v, w) = (cx * by - cy * bx, ax * cy - ay * cx, bx * ay - by * ax);
    if (u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0) {
        return None;
    }
    let det = u + v + w;
    (det != 0.0).then(|| sz * (u * a[kz] + v * b[kz] + w * cc[kz]) / det)
}

/// The f64 reference: closest `(t, triangle)` in `[tmin, tmax)`.
fn reference(c: &Committed, ray: &Ray) -> Option<(f64, u32)> {
    let (o, d) = (ray.org.as_dvec3(), ray.dir.as_dvec3());
    c.prims
        .vertices
        .iter()
        .enumerate()
        .filter_map(|(i, v)| tri_t(v, o, d).map(|t| (t, i as u32)))
        .filter(|&(t, _)| t >= ray.tmin as f64 && t < ray.tmax as f64)
        .min_by(|a, b| a.0.total_cmp(&b.0))
}

/// Scores `hits`: the must-hit rays by the object they hit, the sampled rays against the
/// reference.
fn score(c: &Committed, set: &RaySet, hits: &[Hit]) -> Tally {
    let (rays, refs) = (&set.rays, &set.refs);
    let diag = c.bounds.diagonal().max(f32::MIN_POSITIVE) as f64;
    let mut t = Tally {
        rays: refs.len() + set.must_hit.len(),
        ..Tally::default()
    };
    for &(i, object) in &set.must_hit {
        let h = &hits[i];
        t.leaks += (!h.is_hit() || c.origins[h.prim as usize].object != object) as usize;
    }
    for &(i, r) in refs {
        let (ray, h) = (&rays[i], &hits[i]);
        let len = ray.dir.as_dvec3().length();
        match (r, h.is_hit()) {
            (Some(_), false) => t.false_misses += 1,
            (None, true) => t.false_hits += 1,
            (Some((tr, pr)), true) => {
                let dt = (h.t as f64 - tr).abs() * len / diag;
                t.max_dt = t.max_dt.max(dt);
                t.sum_dt += dt;
                t.both += 1;
                // A different triangle is wrong unless it is a tie: the hit lies at the reference
                // distance (a neighbour across the shared edge or vertex the ray passes within
                // rounding of), or the reference puts that triangle at the same distance.
                if h.prim != pr && dt * diag > 1e-6 * diag {
                    let (o, d) = (ray.org.as_dvec3(), ray.dir.as_dvec3());
                    let other = c
                        .prims
                        .vertices
                        .get(h.prim as usize)
                        .and_then(|v| tri_t(v, o, d));
                    if other.is_none_or(|to| (to - tr).abs() * len > 1e-6 * diag) {
                        t.wrong_prims += 1;
                    }
                }
            }
            (None, false) => {}
        }
    }
    t
}

/// A ray set: a committed scene (with exact corners and ropes), its rays, the rays that start
/// inside a closed mesh (with its object id) and the reference on sampled other rays.
struct RaySet {
    scene: Scene,
    rays: Vec<Ray>,
    must_hit: Vec<(usize, u32)>,
    refs: Vec<(usize, Option<(f64, u32)>)>,
}

impl RaySet {
    /// `must_hit[k]` is the object ray k starts inside, for the first `must_hit.len()` rays;
    /// every `sample_every`-th of the others is checked against the reference.
    fn new(
        mut scene: Scene,
        rays: Vec<Ray>,
        must_hit: Vec<u32>,
        sample_every: usize,
    ) -> Result<Self> {
        scene.commit()?;
        scene.ensure_ropes()?;
        scene.ensure_exact_vertices()?;
        let c = scene.committed()?;
        let first = must_hit.len();
        let refs = (first..rays.len())
            .into_par_iter()
            .filter(|i| (i - first).is_multiple_of(sample_every))
            .map(|i| (i, reference(c, &rays[i])))
            .collect();
        Ok(RaySet {
            scene,
            rays,
            must_hit: must_hit.into_iter().enumerate().collect(),
            refs,
        })
    }
}

pub(super) fn mesh_scene(meshes: &[Mesh]) -> Result<Scene> {
    let mut s = Scene::new();
    for m in meshes {
        s.add_object(
            Shape::Mesh {
                positions: m.positions.clone(),
                triangles: m.triangles.clone(),
            },
            0,
        )?;
    }
    Ok(s)
}

/// SplitMix64 in [0, 1).
fn unit(state: &mut u64) -> f32 {
    *state = state.wrapping_add(0x9e37_79b9_7f4a_7c15);
    let mut z = *state;
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    ((z ^ (z >> 31)) >> 40) as f32 / (1u64 << 24) as f32
}

/// The placements of the stress scene: tiny, unit, huge, and far from the origin.
const PLACEMENTS: [(f32, f32); 4] = [(1e-7, 0.0), (1.0, 0.0), (1e7, 0.0), (1.0, 1e4)];

/// The stress scene at one placement: a uv sphere (poles where 24 thin triangles meet), a
/// torus and a cube of triangles (faces in the scene box), all closed. Rays: from inside each
/// mesh to every vertex and edge midpoint; axis-parallel from inside with every sign of zero;
/// grazing the sphere's silhouette from outside (±1e-4 of its radius).
fn stress_set(scale: f32, offset: f32) -> Result<RaySet> {
    let at = [
        Vec3::ZERO,
        Vec3::new(3.0, 0.0, 0.0),
        Vec3::new(-3.0, -0.5, -0.5),
    ];
    let meshes = [
        tessellate::uv_sphere(12, 24),
        tessellate::torus(24, 12, 0.35),
        tessellate::cube(),
    ];
    let inside = [
        Vec3::new(0.1, 0.2, -0.1),
        Vec3::new(1.0, 0.0, 0.05),
        Vec3::splat(0.4),
    ];
    let place = |p: Vec3| p * scale + Vec3::splat(offset);
    let placed: Vec<Mesh> = meshes
        .iter()
        .zip(at)
        .map(|(m, a)| m.placed(1.0, a).placed(scale, Vec3::splat(offset)))
        .collect();
    let (mut rays, mut inside_of) = (Vec::new(), Vec::new());
    for (k, m) in placed.iter().enumerate() {
        let o = place(inside[k] + at[k]);
        for t in m.positions.iter().chain(&m.edge_midpoints()) {
            rays.push(Ray::new(o, *t - o, 0.0, f32::INFINITY));
            inside_of.push(k as u32);
        }
        for axis in 0..3 {
            for sign in [1.0f32, -1.0] {
                for zeros in 0..4 {
                    let mut d = Vec3::splat(0.0);
                    d[(axis + 1) % 3] = if zeros & 1 == 0 { 0.0 } else { -0.0 };
                    d[(axis + 2) % 3] = if zeros & 2 == 0 { 0.0 } else { -0.0 };
                    d[axis] = sign;
                    rays.push(Ray::new(o, d, 0.0, f32::INFINITY));
                    inside_of.push(k as u32);
                }
            }
        }
    }
    let mut rng = 7u64;
    for _ in 0..4096 {
        let a = std::f32::consts::TAU * unit(&mut rng);
        let r = 1.0 + 2e-4 * (unit(&mut rng) - 0.5);
        let edge = Vec3::new(a.cos() * r, a.sin() * r, 0.0);
        let org = place(edge - 5.0 * Vec3::Z);
        rays.push(Ray::new(org, place(edge) - org, 0.0, f32::INFINITY));
    }
    RaySet::new(mesh_scene(&placed)?, rays, inside_of, 1)
}

fn bunny_sets(a: &Args) -> Result<Vec<(&'static str, RaySet)>> {
    let mut out = Vec::new();
    for (label, kind) in [
        ("bunny incoherent", "incoherent"),
        ("bunny primary", "primary"),
    ] {
        let (Some(scene), Some(path)) = (model_scene(a, "bunny.ply")?, find_set(a, "bunny", kind))
        else {
            continue;
        };
        let rays = rayset::read_rays(&path)?;
        // 4096 of the 262144 rays against the f64 brute force over 69k triangles.
        out.push((label, RaySet::new(scene, rays, Vec::new(), 64)?));
    }
    Ok(out)
}

/// Ray queries: every method of every engine (`Engine::methods`) on every set.
pub(super) fn queries(a: &Args, b: &Backends) -> Result<(Vec<Point>, String)> {
    let mut sets: Vec<(&'static str, Vec<RaySet>)> = bunny_sets(a)?
        .into_iter()
        .map(|(l, s)| (l, vec![s]))
        .collect();
    let stress = PLACEMENTS
        .iter()
        .map(|&(s, o)| stress_set(s, o))
        .collect::<Result<Vec<_>>>()?;
    sets.push(("stress", stress));
    let mut points = Vec::new();
    let mut table = String::from(
        "| set | mode | traversal | intersector | Mrays/s | leaks /M | false misses /M | false hits /M | wrong prim /M | max \\|Δt\\|/diag | mean \\|Δt\\|/diag |\n\
         |---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    for (label, group) in &sets {
        for (engine, ctx) in b.engines() {
            for (how, intersector) in engine.methods() {
                let q = engine.query(how, intersector);
                let mut total = Tally::default();
                for set in group {
                    let c = set.scene.committed()?;
                    let mut hits = vec![Hit::MISS; set.rays.len()];
                    let ms = time_ms(a.runs, || {
                        ctx.intersect(c, &set.rays, &mut hits, &q).map(drop)
                    })?;
                    let mut t = score(c, set, &hits);
                    t.ms = ms;
                    t.timed_rays = set.rays.len();
                    total.add(&t);
                }
                let mrays = total.timed_rays as f64 / total.ms / 1e3;
                writeln!(
                    table,
                    "| {label} | {} | {} | {} | {mrays:.2} | {:.0} | {:.0} | {:.0} | {:.0} | {:.1e} | {:.1e} |",
                    engine.name(),
                    how.name(),
                    intersector.name(),
                    total.per_million(total.leaks),
                    total.per_million(total.false_misses),
                    total.per_million(total.false_hits),
                    total.per_million(total.wrong_prims),
                    total.max_dt,
                    total.sum_dt / total.both.max(1) as f64
                )
                .ok();
                points.push(Point {
                    set: label,
                    method: engine.label(how, intersector),
                    engine,
                    mrays,
                    error: total.failures(),
                });
            }
        }
    }
    let checked: Vec<String> = sets
        .iter()
        .map(|(l, g)| {
            let (r, m, c) = g.iter().fold((0, 0, 0), |(r, m, c), s| {
                (r + s.rays.len(), m + s.must_hit.len(), c + s.refs.len())
            });
            format!("{l}: {r} rays, {m} from inside closed meshes, {c} checked against the f64 reference")
        })
        .collect();
    Ok((points, format!("{}.\n\n{table}", checked.join("; "))))
}
