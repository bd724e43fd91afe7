//! `rt2 bench chart`: speed against accuracy for every traversal × intersector (ray queries)
//! and traversal × intersector × offset mode (secondary rays) on the CPU backend one ray at a
//! time, plus packets, streams and the GPU backend where they apply, measured against an
//! independent f64 reference (brute force over the exact triangle corners), and the chart of
//! it (docs/chart.svg, docs/chart.png; needs `--features chart`).
//! `rt2 bench memory`: bytes per primitive of each part of each scene, beside a tessellation.

use super::{mib, shared, time_ms, Args};
use glam::{DVec3, Vec3};
use rayon::prelude::*;
use rt2::context::{Context, QueryOptions};
use rt2::cpu::query::QueryMode;
use rt2::cpu::traverse::Traversal;
use rt2::cpu::whitted::Tracer;
use rt2::dispatch::BackendRequest;
use rt2::error::Result;
use rt2::geometry::{Hit, PrimIndex, Ray, INVALID};
use rt2::precision::{Intersector, OffsetMode};
use rt2::rayset;
use rt2::render::RenderOptions;
use rt2::scene::tessellate::{self, Mesh};
use rt2::scene::{builtin, Committed, PointLight, Scene, Shape};
use std::fmt::Write as _;
use std::time::Instant;

/// Who traces a method's rays.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Engine {
    /// The CPU backend in one of its query modes. Packets and streams follow the standard
    /// traversal's order and test triangles with Möller–Trumbore only (the library refuses the
    /// watertight test there).
    Cpu(QueryMode),
    /// The GPU backend: Möller–Trumbore and the fixed epsilon offset only.
    Gpu,
}

impl Engine {
    /// The engines of the chart, in the order of its tables and legend.
    const ALL: [Engine; 4] = [
        Engine::Cpu(QueryMode::Single),
        Engine::Cpu(QueryMode::Packet),
        Engine::Cpu(QueryMode::Stream),
        Engine::Gpu,
    ];

    fn name(self) -> &'static str {
        match self {
            Engine::Cpu(m) => m.name(),
            Engine::Gpu => "gpu",
        }
    }

    /// The traversals × intersectors measured with this engine. One ray at a time: all of
    /// them. Packets and streams: their one combination. The GPU: every traversal kernel,
    /// Möller–Trumbore.
    fn methods(self) -> Vec<(Traversal, Intersector)> {
        let mt = Intersector::MollerTrumbore;
        match self {
            Engine::Cpu(QueryMode::Single) => Traversal::ALL
                .into_iter()
                .flat_map(|t| Intersector::ALL.map(|i| (t, i)))
                .collect(),
            Engine::Cpu(_) => vec![(Traversal::Standard, mt)],
            Engine::Gpu => Traversal::ALL.map(|t| (t, mt)).to_vec(),
        }
    }

    /// The offset modes measured with this engine: the breadth-first waves carry no excluded
    /// primitive, and the GPU kernels offset by the fixed epsilon only.
    fn offsets(self) -> &'static [OffsetMode] {
        match self {
            Engine::Cpu(QueryMode::Single) => &OffsetMode::ALL,
            Engine::Cpu(_) => &[OffsetMode::Epsilon, OffsetMode::Robust],
            Engine::Gpu => &[OffsetMode::Epsilon],
        }
    }

    /// A method's name in the tables and on the chart: one ray at a time keeps the bare
    /// "traversal intersector".
    fn label(self, how: Traversal, intersector: Intersector) -> String {
        match self {
            Engine::Cpu(QueryMode::Single) => format!("{} {}", how.name(), intersector.name()),
            Engine::Cpu(m) => format!("{} {}", m.name(), intersector.name()),
            Engine::Gpu => format!("gpu {} {}", how.name(), intersector.name()),
        }
    }

    fn query(self, how: Traversal, intersector: Intersector) -> QueryOptions {
        QueryOptions {
            traversal: Some(how),
            intersector,
            mode: match self {
                Engine::Cpu(m) => m,
                Engine::Gpu => QueryMode::Single,
            },
            ..QueryOptions::default()
        }
    }
}

/// The contexts the chart measures with: the CPU's, and the GPU's when an adapter opens.
struct Backends {
    cpu: Context,
    gpu: Option<Context>,
    /// The adapter and whether it is software, or why there is no GPU point.
    gpu_note: String,
}

impl Backends {
    fn open() -> Result<Self> {
        let cpu = Context::new(BackendRequest::Cpu, 0)?;
        let (gpu, gpu_note) = match Context::new(BackendRequest::Gpu, 0) {
            Ok(ctx) => match ctx.gpu().map(|g| (g.software, g.description.clone())) {
                Some((true, name)) => {
                    let lavapipe = if name.contains("llvmpipe") {
                        ", Mesa lavapipe"
                    } else {
                        ""
                    };
                    let note = format!(
                        "{name} (SOFTWARE adapter{lavapipe}: a CPU-emulated GPU on the same \
                         cores, not representative of GPU speed)"
                    );
                    (Some(ctx), note)
                }
                Some((false, name)) => (Some(ctx), format!("{name} (hardware adapter)")),
                // RT2_BACKEND=cpu overrides the request.
                None => (
                    None,
                    "none: RT2_BACKEND keeps the context on the CPU".into(),
                ),
            },
            Err(e) => (
                None,
                format!("no adapter ({}); the GPU points are skipped", e.message),
            ),
        };
        Ok(Backends { cpu, gpu, gpu_note })
    }

    /// The GPU's name in the chart's legend: the adapter's name and its kind.
    fn gpu_legend(&self) -> Option<String> {
        let g = self.gpu.as_ref()?.gpu()?;
        let name = g.description.split(" (").next().unwrap_or("adapter");
        let kind = match (g.software, name.contains("llvmpipe")) {
            (true, true) => "software: lavapipe",
            (true, false) => "software",
            (false, _) => "hardware",
        };
        Some(format!("{name}, {kind}"))
    }

    /// The engines that can run here, with their context.
    fn engines(&self) -> Vec<(Engine, &Context)> {
        Engine::ALL
            .into_iter()
            .filter_map(|e| match e {
                Engine::Gpu => self.gpu.as_ref().map(|g| (e, g)),
                Engine::Cpu(_) => Some((e, &self.cpu)),
            })
            .collect()
    }
}

/// One method measured on one ray set (or summed over the placements of the stress scene).
#[derive(Clone, Debug)]
pub(super) struct Point {
    pub set: &'static str,
    pub method: String,
    /// Its marker on the chart (read only when the chart is drawn: `--features chart`).
    #[cfg_attr(not(feature = "chart"), allow(dead_code))]
    pub engine: Engine,
    pub mrays: f64,
    /// Failures per million rays: false misses + false hits + wrong primitives (ray queries),
    /// self-intersections (secondary rays).
    pub error: f64,
}

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

fn mesh_scene(meshes: &[Mesh]) -> Result<Scene> {
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

fn bunny_sets() -> Result<Vec<(&'static str, RaySet)>> {
    let mut out = Vec::new();
    for (label, file) in [
        ("bunny incoherent", "incoherent_262144"),
        ("bunny primary", "primary_262144"),
    ] {
        let path = shared().join("raysets/bunny").join(format!("{file}.rays"));
        let (Some(scene), Ok(rays)) = (super::model_scene("bunny.ply")?, rayset::read_rays(&path))
        else {
            eprintln!(
                "bench chart: the bunny or {} is missing; skipped",
                path.display()
            );
            continue;
        };
        // 4096 of the 262144 rays against the f64 brute force over 69k triangles.
        out.push((label, RaySet::new(scene, rays, Vec::new(), 64)?));
    }
    Ok(out)
}

/// Ray queries: every method of every engine (`Engine::methods`) on every set.
fn queries(a: &Args, b: &Backends) -> Result<(Vec<Point>, String)> {
    let mut sets: Vec<(&'static str, Vec<RaySet>)> = bunny_sets()?
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
                    let mut done = Ok(Default::default());
                    let ms = time_ms(a.runs, || {
                        done = ctx.intersect(c, &set.rays, &mut hits, &q);
                    });
                    done?;
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
fn secondary(a: &Args, b: &Backends) -> Result<(Vec<Point>, String)> {
    let scenes = secondary_scenes()?;
    let mut points = Vec::new();
    let mut table = String::from(
        "| mode | traversal | intersector | offset | Mrays/s (primary + shadow) | self-intersections /M shadow rays |\n\
         |---|---|---|---|---|---|\n",
    );
    for (engine, ctx) in b.engines() {
        for (how, intersector) in engine.methods() {
            for &mode in engine.offsets() {
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
                    let mut done = Ok(Acne::default());
                    ms += time_ms(a.runs, || {
                        done = if engine == Engine::Cpu(QueryMode::Single) {
                            Ok(depth_first(ctx, &tracer, rays, *light))
                        } else {
                            breadth_first(ctx, &tracer, &q, rays, *light)
                        };
                    });
                    let counts = done?;
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
            .filter_map(|ray| Shadow::of(tracer, ray, &tracer.intersect(ray, INVALID), light))
            .map(|s| s.judge(tracer.scene, &tracer.intersect(&s.ray, s.skip)))
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
    ctx.intersect(c, &shadow_rays, &mut shadow_hits, q)?;
    Ok(shadows
        .iter()
        .zip(&shadow_hits)
        .map(|(s, h)| s.judge(c, h))
        .fold(Acne::default(), sum))
}

/// Size of the PSNR renders: half the README's 1376x768 in each direction.
const PSNR_SIZE: (u32, u32) = (688, 384);

/// PSNR of renders of every built-in scene with each offset mode (and each intersector where
/// the scene has triangles; on the GPU: the epsilon and Möller–Trumbore it has), standard
/// traversal, against the CPU render with the watertight test and the robust offset.
fn psnr_table(b: &Backends) -> Result<String> {
    let (w, h) = PSNR_SIZE;
    let mut out = format!(
        "\n#### Renders against a reference render\n\n\
         Every built-in scene at {w}x{h} and its own depth, standard traversal; PSNR in dB of \
         the RGB channels against the CPU render with the watertight test and the robust offset \
         (inf: identical), and in brackets the pixels that differ. Only triangles have two \
         intersectors: scenes without any show one row. The GPU kernels have the epsilon \
         offset only. This table measures how far the modes move an image from each other; \
         against an independent f64 brute-force tracer (spheres, plane, two lights, \
         reflection; `cargo test --release --test render_reference -- --nocapture`) every \
         offset mode scores above 62 dB in both schedules.\n\n| scene | mode | intersector |"
    );
    for mode in OffsetMode::ALL {
        write!(out, " {} |", mode.name()).ok();
    }
    out.push_str("\n|---|---|---|");
    out.push_str(&"---|".repeat(OffsetMode::ALL.len()));
    out.push('\n');
    for name in builtin::NAMES {
        let mut scene = builtin::by_name(name)?;
        b.cpu.install(|| scene.scene.commit())?;
        scene.scene.ensure_exact_vertices()?;
        let c = scene.scene.committed()?;
        let render = |ctx: &Context, intersector, offset_mode| -> Result<Vec<u8>> {
            let opts = RenderOptions {
                max_depth: scene.max_depth,
                traversal: Some(Traversal::Standard),
                intersector,
                offset_mode,
                ..RenderOptions::default()
            };
            let mut frame = rt2::frame::Frame::new(w, h)?;
            ctx.render(c, &scene.camera, &opts, &mut frame)?;
            Ok(frame.pixels().to_vec())
        };
        let reference = render(&b.cpu, Intersector::Watertight, OffsetMode::Robust)?;
        let intersectors: &[Intersector] = if c.prims.triangles.is_empty() {
            &[Intersector::MollerTrumbore]
        } else {
            &Intersector::ALL
        };
        let mut rows: Vec<(Engine, &Context, Intersector)> = intersectors
            .iter()
            .map(|&i| (Engine::Cpu(QueryMode::Single), &b.cpu, i))
            .collect();
        if let Some(g) = &b.gpu {
            rows.push((Engine::Gpu, g, Intersector::MollerTrumbore));
        }
        for (engine, ctx, intersector) in rows {
            let shown = if c.prims.triangles.is_empty() {
                "any (no triangles)"
            } else {
                intersector.name()
            };
            write!(out, "| {name} | {} | {shown} |", engine.name()).ok();
            for mode in OffsetMode::ALL {
                if engine.offsets().contains(&mode) {
                    let (db, differ) = psnr(&render(ctx, intersector, mode)?, &reference);
                    write!(out, " {db:.1} ({differ}) |").ok();
                } else {
                    out.push_str(" — |");
                }
            }
            out.push('\n');
        }
    }
    Ok(out)
}

/// PSNR in dB of the RGB channels of RGBA image `img` against `reference` (inf when they are
/// equal), and how many pixels differ in RGB. Alpha is left out: it is 255 in every render.
fn psnr(img: &[u8], reference: &[u8]) -> (f64, usize) {
    let (mut se, mut n, mut differ) = (0.0f64, 0usize, 0usize);
    for (p, q) in img.chunks_exact(4).zip(reference.chunks_exact(4)) {
        differ += (p[..3] != q[..3]) as usize;
        for k in 0..3 {
            se += (p[k] as f64 - q[k] as f64).powi(2);
            n += 1;
        }
    }
    let db = 10.0 * (255.0f64 * 255.0 / (se / n.max(1) as f64)).log10();
    (db, differ)
}

/// The points no other point beats in both speed and error (lower error, higher Mrays/s),
/// by increasing error.
pub(super) fn pareto(points: &[Point]) -> Vec<Point> {
    let mut sorted: Vec<&Point> = points.iter().collect();
    sorted.sort_by(|a, b| {
        a.error
            .total_cmp(&b.error)
            .then(b.mrays.total_cmp(&a.mrays))
    });
    let mut front: Vec<Point> = Vec::new();
    for p in sorted {
        if front.last().is_none_or(|f| p.mrays > f.mrays) {
            front.push(p.clone());
        }
    }
    front
}

/// The sets of `points`, in order of first appearance.
fn sets_of(points: &[Point]) -> Vec<&'static str> {
    let mut sets: Vec<&'static str> = Vec::new();
    for p in points {
        if !sets.contains(&p.set) {
            sets.push(p.set);
        }
    }
    sets
}

/// The Pareto front of each set (methods are compared on the same rays only).
fn fronts(points: &[Point]) -> Vec<Vec<Point>> {
    sets_of(points)
        .into_iter()
        .map(|set| {
            let of_set: Vec<Point> = points.iter().filter(|p| p.set == set).cloned().collect();
            pareto(&of_set)
        })
        .collect()
}

fn front_table(title: &str, points: &[Point]) -> String {
    let mut s = format!(
        "\nPareto fronts, {title} (per set):\n\n| set | method | Mrays/s | failures /M |\n|---|---|---|---|\n"
    );
    for p in fronts(points).iter().flatten() {
        writeln!(
            s,
            "| {} | {} | {:.2} | {:.0} |",
            p.set, p.method, p.mrays, p.error
        )
        .ok();
    }
    s
}

pub(super) fn chart(a: &Args) -> Result<String> {
    let b = Backends::open()?;
    let t0 = Instant::now();
    let (qp, qt) = queries(a, &b)?;
    let (sp, st) = secondary(a, &b)?;
    let psnr = psnr_table(&b)?;
    let secs = t0.elapsed().as_secs_f64();
    eprintln!("bench chart: measured in {secs:.0} s");
    let images = draw(
        &[("Ray queries", &qp), ("Secondary rays (shadow)", &sp)],
        b.gpu_legend().as_deref(),
    );
    Ok(format!(
        "### Speed against accuracy (CPU and GPU backends)\n\n\
         ![speed against accuracy](docs/chart.png)\n\n{images}\n\n\
         Modes (the `mode` column; marker on the chart): **single** = `QueryMode::Single`, one ray \
         at a time, every traversal × intersector (circles); **packet** = `QueryMode::Packet` \
         (triangles) and **stream** = `QueryMode::Stream` (squares), which follow the standard \
         traversal's order and test triangles with Möller–Trumbore only (the library refuses \
         the watertight test there); **gpu** = the GPU backend (diamonds), every traversal \
         kernel, Möller–Trumbore and the epsilon offset only (all its kernels have); its \
         Möller–Trumbore rounds differently from the CPU's near edges (Vulkan lets a division \
         be off by 2.5 ULP and a shader compiler fuse multiply-adds), so its leak count on the \
         stress set differs a little from the CPU's. GPU: {}. Colour: the ray set; filled: \
         watertight test. \
         Mrays/s with all cores (median of the runs) on a shared 2-core machine: speeds are \
         noisy (compare points measured in the same run), the error counts are exact. Measured in {secs:.0} s.\n\n\
         Errors against an f64 brute force over the exact triangle corners (a watertight test in f64, \
         closed edges; a neighbour hit at the same distance is a tie, not an error). Failures = false misses (leaks) + false hits + wrong \
         primitive, per million rays; leaks are rays from inside a closed mesh whose first hit is \
         not that mesh (exact: no reference needed). The stress scene (closed uv sphere, torus, cube of \
         triangles; all closed) at scale 1e-7, 1, 1e7 and 1e4 from the origin: rays from inside \
         to every vertex and edge midpoint and axis-parallel with every sign of zero (all must \
         hit, and must hit the mesh they start in), and rays grazing the sphere's silhouette \
         (checked against the reference).\n\n{qt}{}\n\
         #### Secondary-ray origins\n\n\
         192×192 primary rays onto the stress meshes on a floor, at the origin and 1e3 away, one \
         shadow ray each; on the lit side of a convex object (sphere, cube, floor) a shadow ray \
         that hits its own object is a self-intersection (acne), per million such shadow rays. \
         They include silhouette edges where the primary ray's closest hit is the back face \
         sharing the edge (the tie goes to the lower index): the shading side then points into \
         the object and every offset mode starts inside it. Single: each pixel's shadow ray \
         right after its primary ray (the depth-first schedule). Packet, stream and gpu: all \
         primary rays as one batch query, the shadow origins computed on the host, then all \
         shadow rays as another (the breadth-first schedule); batches carry no excluded \
         primitive, so these have no exclude-prim point.\n\n{st}{}{psnr}",
        b.gpu_note,
        front_table("ray queries", &qp),
        front_table("secondary rays", &sp)
    ))
}

#[cfg(feature = "chart")]
fn draw(panels: &[(&str, &Vec<Point>)], gpu: Option<&str>) -> String {
    match plot::draw(panels, gpu) {
        Ok(()) => {
            "Chart: [docs/chart.svg](docs/chart.svg), [docs/chart.png](docs/chart.png).".into()
        }
        Err(e) => {
            eprintln!("bench chart: no chart drawn: {e}");
            format!("(chart not drawn: {e})")
        }
    }
}

#[cfg(not(feature = "chart"))]
fn draw(_: &[(&str, &Vec<Point>)], _: Option<&str>) -> String {
    eprintln!("bench chart: built without the `chart` feature; no images drawn");
    "(chart not drawn: build with `--features chart`)".into()
}

#[cfg(feature = "chart")]
mod plot {
    use super::{fronts, sets_of, Engine, Point};
    use plotters::coord::Shift;
    use plotters::element::ComposedElement;
    use plotters::prelude::*;
    use plotters::style::text_anchor::{HPos, Pos, VPos};
    use rt2::cpu::query::QueryMode;
    use std::error::Error;
    use std::path::Path;

    /// Zero failures are drawn here on the log axis (and labelled "0" in the axis text).
    const FLOOR: f64 = 0.1;

    const COLORS: [RGBColor; 6] = [
        RGBColor(31, 119, 180),
        RGBColor(255, 127, 14),
        RGBColor(44, 160, 44),
        RGBColor(214, 39, 40),
        RGBColor(148, 103, 189),
        RGBColor(140, 86, 75),
    ];

    /// A filled polygon and its outline, in pixels around a point.
    type Marker<C, DB> = ComposedElement<C, DB, Polygon<(i32, i32)>, PathElement<(i32, i32)>>;

    /// The marker of a point of `engine`: circle (one ray at a time), triangle (packets),
    /// square (streams), diamond (GPU); filled for the watertight test. One element type for
    /// every engine (a polygon and its outline, in pixels around the point), so one series and
    /// one legend entry draw any of them.
    fn marker<DB: DrawingBackend, C>(
        engine: Engine,
        at: C,
        color: RGBColor,
        filled: bool,
    ) -> Marker<C, DB> {
        let corners: Vec<(i32, i32)> = match engine {
            Engine::Cpu(QueryMode::Single) => (0..16)
                .map(|k| {
                    let a = k as f64 * std::f64::consts::TAU / 16.0;
                    (
                        (5.0 * a.cos()).round() as i32,
                        (5.0 * a.sin()).round() as i32,
                    )
                })
                .collect(),
            Engine::Cpu(QueryMode::Packet) => vec![(0, -6), (5, 4), (-5, 4)],
            Engine::Cpu(QueryMode::Stream) => vec![(-4, -4), (4, -4), (4, 4), (-4, 4)],
            Engine::Gpu => vec![(0, -6), (6, 0), (0, 6), (-6, 0)],
        };
        let fill = if filled {
            color.filled()
        } else {
            TRANSPARENT.filled()
        };
        let mut outline = corners.clone();
        outline.push(corners[0]);
        EmptyElement::at(at)
            + Polygon::new(corners, fill)
            + PathElement::new(outline, color.stroke_width(2))
    }

    fn panel<DB: DrawingBackend>(
        area: &DrawingArea<DB, Shift>,
        title: &str,
        points: &[Point],
        gpu: Option<&str>,
    ) -> Result<(), Box<dyn Error>>
    where
        DB::ErrorType: 'static,
    {
        let x = |p: &Point| p.error.max(FLOOR);
        // The points take the left 58% of the log axis; the legend, the right 40%.
        let xmin = FLOOR * 0.7;
        let xmax = xmin * (points.iter().map(x).fold(10.0, f64::max) / xmin).powf(1.0 / 0.58);
        let ymax = points.iter().map(|p| p.mrays).fold(0.1, f64::max) * 1.15;
        let mut chart = ChartBuilder::on(area)
            .caption(title, ("sans-serif", 20))
            .margin(12)
            .x_label_area_size(44)
            .y_label_area_size(56)
            .build_cartesian_2d((xmin..xmax).log_scale(), 0.0..ymax)?;
        chart
            .configure_mesh()
            .x_desc("failures per million rays (log; 0 drawn at 0.1); lines: Pareto front per set")
            .x_label_formatter(&|v| {
                if *v >= 1e3 {
                    format!("{v:.0e}")
                } else {
                    format!("{v}")
                }
            })
            .y_desc("Mrays/s")
            .label_style(("sans-serif", 13))
            .draw()?;
        let all_fronts = fronts(points);
        for (k, (set, front)) in sets_of(points).iter().zip(&all_fronts).enumerate() {
            let color = COLORS[k % COLORS.len()];
            let watertight = |p: &Point| p.method.contains("watertight");
            chart
                .draw_series(
                    points
                        .iter()
                        .filter(|p| p.set == *set)
                        .map(|p| marker(p.engine, (x(p), p.mrays), color, watertight(p))),
                )?
                .label(format!("{set} (filled: watertight)"))
                .legend(move |(lx, ly)| Circle::new((lx, ly), 5, color.filled()));
            // The set's Pareto front: a line through it.
            chart.draw_series(LineSeries::new(
                front.iter().map(|p| (x(p), p.mrays)),
                color.stroke_width(2),
            ))?;
        }
        // Each front point named: right of points near the left edge, left of the others
        // (names never reach the legend's side); moved up or down, nearest first, off the
        // names already placed.
        let mut placed: Vec<(i32, i32, i32, i32)> = Vec::new();
        for p in all_fronts.iter().flatten() {
            let (px, py) = chart.backend_coord(&(x(p), p.mrays));
            let left_edge = (x(p) / xmin).ln() / (xmax / xmin).ln() < 0.3;
            let (dx, h) = if left_edge {
                (9, HPos::Left)
            } else {
                (-9, HPos::Right)
            };
            let font =
                TextStyle::from(("sans-serif", 12).into_font()).pos(Pos::new(h, VPos::Center));
            let (w, th) = area.estimate_text_size(&p.method, &font)?;
            let (w, th) = (w as i32, th as i32 + 2);
            let x0 = if left_edge { px + dx } else { px + dx - w };
            let rect = |dy: i32| (x0, py + dy - th / 2, x0 + w, py + dy + th / 2);
            let free = |r: (i32, i32, i32, i32)| {
                placed
                    .iter()
                    .all(|q| r.2 <= q.0 || q.2 <= r.0 || r.3 <= q.1 || q.3 <= r.1)
            };
            // 0, -th, th, -2th, 2th, ...
            let dy = (0..9)
                .map(|i| th * ((i + 1) / 2) * if i % 2 == 0 { 1 } else { -1 })
                .find(|&d| free(rect(d)))
                .unwrap_or(0);
            placed.push(rect(dy));
            chart.draw_series(std::iter::once(
                EmptyElement::at((x(p), p.mrays)) + Text::new(p.method.clone(), (dx, dy), font),
            ))?;
        }
        // One legend entry per engine present: its marker in black.
        for engine in Engine::ALL {
            if !points.iter().any(|p| p.engine == engine) {
                continue;
            }
            let name = match engine {
                Engine::Cpu(QueryMode::Single) => "one ray at a time".to_string(),
                Engine::Cpu(QueryMode::Packet) => "packets (standard order)".to_string(),
                Engine::Cpu(QueryMode::Stream) => "streams (standard order)".to_string(),
                Engine::Gpu => format!("gpu: {}", gpu.unwrap_or("adapter")),
            };
            chart
                .draw_series(std::iter::empty::<Circle<(f64, f64), i32>>())?
                .label(name)
                .legend(move |at| marker(engine, at, BLACK, false));
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .label_font(("sans-serif", 13))
            .border_style(BLACK)
            .background_style(WHITE.mix(0.85))
            .draw()?;
        Ok(())
    }

    fn all<DB: DrawingBackend>(
        root: DrawingArea<DB, Shift>,
        panels: &[(&str, &Vec<Point>)],
        gpu: Option<&str>,
    ) -> Result<(), Box<dyn Error>>
    where
        DB::ErrorType: 'static,
    {
        root.fill(&WHITE)?;
        for (area, (title, points)) in root.split_evenly((1, panels.len())).iter().zip(panels) {
            panel(area, title, points, gpu)?;
        }
        root.present()?;
        Ok(())
    }

    /// Writes docs/chart.svg and docs/chart.png. Text needs a TTF font: `$RT2_FONT` or
    /// DejaVu Sans where Debian and Ubuntu put it.
    pub(super) fn draw(
        panels: &[(&str, &Vec<Point>)],
        gpu: Option<&str>,
    ) -> Result<(), Box<dyn Error>> {
        let font = std::env::var("RT2_FONT")
            .unwrap_or_else(|_| "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf".into());
        let bytes = std::fs::read(&font).map_err(|e| format!("font {font}: {e} (set RT2_FONT)"))?;
        plotters::style::register_font("sans-serif", FontStyle::Normal, Box::leak(bytes.into()))
            .map_err(|_| format!("{font} is not a usable TTF font"))?;
        std::fs::create_dir_all("docs")?;
        let size = (1500u32, 650u32);
        all(
            SVGBackend::new(Path::new("docs/chart.svg"), size).into_drawing_area(),
            panels,
            gpu,
        )?;
        let mut buf = vec![0u8; (size.0 * size.1 * 3) as usize];
        all(
            BitMapBackend::with_buffer(&mut buf, size).into_drawing_area(),
            panels,
            gpu,
        )?;
        image::RgbImage::from_raw(size.0, size.1, buf)
            .ok_or("PNG buffer size")?
            .save("docs/chart.png")?;
        Ok(())
    }
}

/// Bytes per primitive of each part of each built-in scene and the bunny, and what the same
/// analytic primitives would cost tessellated (a 16×32 uv sphere per sphere: 960 triangles).
pub(super) fn memory(_: &Args) -> Result<String> {
    let tess = tessellate::uv_sphere(16, 32);
    let tri_bytes = std::mem::size_of::<rt2::geometry::Triangle>();
    let per_sphere = tess.triangles.len() * tri_bytes;
    let mut out = format!(
        "### Memory: bytes per primitive of each part\n\n\
         Total = what a committed scene holds (primitives, nodes, leaf lists). Built only on \
         demand, and shown at what they cost then: ropes + leaf boxes (rope traversals), exact \
         triangle corners (watertight test). Tessellated: every sphere or ellipsoid as a \
         closed {}-triangle uv sphere ({per_sphere} B of triangles, before any tree).\n\n\
         | scene | primitives | kinds | primitive arrays B/prim | tree nodes B/prim | leaf lists B/prim | on demand: ropes + leaf boxes B/prim | on demand: exact corners B/prim | total MiB | tessellated triangles MiB |\n\
         |---|---|---|---|---|---|---|---|---|---|\n",
        tess.triangles.len()
    );
    let mut scenes: Vec<(String, Scene)> = Vec::new();
    for name in builtin::NAMES {
        scenes.push((name.to_string(), builtin::by_name(name)?.scene));
    }
    if let Some(s) = super::model_scene("bunny.ply")? {
        scenes.push(("bunny".into(), s));
    }
    for (name, mut s) in scenes {
        s.commit()?;
        let plain = s.committed()?.prims.bytes();
        // The on-demand parts, built here to report what they cost when asked for.
        s.ensure_ropes()?;
        s.ensure_exact_vertices()?;
        let c = s.committed()?;
        let p = &c.prims;
        let n = (p.len() + p.planes.len()).max(1) as f64;
        let kinds = format!(
            "{} tri, {} sph, {} ell, {} box, {} plane",
            p.triangles.len(),
            p.spheres.len(),
            p.ellipsoids.len(),
            p.boxes.len(),
            p.planes.len()
        );
        let parts = [
            plain,
            c.tree.node_bytes(),
            c.tree.leaf_list_bytes(),
            c.tree.rope_bytes() + c.tree.leaf_box_bytes(),
            p.vertices.len() * 36,
        ];
        let analytic = p.spheres.len() + p.ellipsoids.len();
        writeln!(
            out,
            "| {name} | {} | {kinds} | {:.1} | {:.1} | {:.1} | {:.1} | {:.1} | {:.2} | {} |",
            n,
            parts[0] as f64 / n,
            parts[1] as f64 / n,
            parts[2] as f64 / n,
            parts[3] as f64 / n,
            parts[4] as f64 / n,
            mib(parts[..3].iter().sum()),
            if analytic > 0 {
                format!(
                    "{:.1}",
                    mib(analytic * per_sphere + p.triangles.len() * tri_bytes)
                )
            } else {
                "-".into()
            }
        )
        .ok();
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn psnr_is_over_rgb_and_counts_differing_pixels() {
        let a = [10u8, 20, 30, 255, 0, 0, 0, 255];
        assert_eq!(psnr(&a, &a), (f64::INFINITY, 0));
        // Alpha is not an image channel here.
        let mut b = a;
        b[3] = 0;
        assert_eq!(psnr(&b, &a), (f64::INFINITY, 0));
        // One of 6 channels off by 255: MSE = 255² / 6, PSNR = 10 log10(6) dB.
        b[4] = 255;
        let (db, differ) = psnr(&b, &a);
        assert!((db - 10.0 * 6f64.log10()).abs() < 1e-12, "{db}");
        assert_eq!(differ, 1);
    }

    /// The breadth-first measurement (batch queries in every CPU mode) finds the same shadow
    /// rays and the same self-intersections as the depth-first one: the modes return the same
    /// hits, so the chart's packet and stream points differ from the single-ray point of the
    /// same method in speed only. Both offsets the batches support; the robust one has acne
    /// on this scene (BENCHMARKS.md), so the counts compared are not all zero.
    #[test]
    fn schedules_count_the_same_acne() -> Result<()> {
        let ctx = Context::new(BackendRequest::Cpu, 2)?;
        let scenes = secondary_scenes()?;
        let mut acne_seen = 0;
        for mode in [OffsetMode::Epsilon, OffsetMode::Robust] {
            let opts = RenderOptions {
                offset_mode: mode,
                ..RenderOptions::default()
            };
            for (s, rays, light) in &scenes {
                let tracer = Tracer::new(s.committed()?, &opts, Traversal::Standard);
                let depth = depth_first(&ctx, &tracer, rays, *light);
                assert!(depth.checked > 1000, "{depth:?}");
                acne_seen += depth.selfhits;
                for engine in [QueryMode::Single, QueryMode::Packet, QueryMode::Stream] {
                    let (how, intersector) = Engine::Cpu(engine).methods()[0];
                    let q = Engine::Cpu(engine).query(how, intersector);
                    let breadth = breadth_first(&ctx, &tracer, &q, rays, *light)?;
                    assert_eq!(breadth, depth, "{engine:?} {mode:?}");
                }
            }
        }
        assert!(acne_seen > 0);
        Ok(())
    }
}
