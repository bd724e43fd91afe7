//! Scenes and rays on which every query mode, traversal and backend must report the same
//! any-hit statistics (`rt2_query_stats` of `rt2_occluded`: per ray, the primitives of each
//! leaf up to the first in its way), as documented for leaves that do not mix triangles with
//! other kinds: 300 spheres, ellipsoids and boxes, and a soup of 2000 triangles (tested in
//! SIMD blocks), each traced by shadow rays (ending at a point inside the scene) and rays
//! without end, with and without an exclusion on every other ray. Run on the CPU by
//! `tests/traversals.rs` and against the GPU by `tests/gpu.rs`.

use glam::Vec3;
use rt2::context::{Context, QueryOptions};
use rt2::geometry::{PrimIndex, Ray, TraversalStats, INVALID};
use rt2::scene::{Committed, Scene, Shape};

/// A scene, rays through it and, for every other ray, a primitive to exclude.
pub struct Case {
    pub name: String,
    pub scene: Scene,
    pub rays: Vec<Ray>,
    pub exclude: Vec<PrimIndex>,
}

/// What an any-hit query reports: its statistics and how many rays are blocked. All but
/// `nodes_visited` must not depend on the mode, traversal or backend.
pub type Counts = (TraversalStats, usize);

/// `counts` without the nodes visited, which depend on the traversal.
pub fn but_nodes((st, blocked): Counts) -> (u64, u64, usize) {
    (st.leaves_visited, st.prim_tests, blocked)
}

/// Every case: both scenes, both kinds of rays.
pub fn cases() -> Vec<Case> {
    let mut all = Vec::new();
    for (name, build) in [
        ("analytic", analytic as fn() -> Scene),
        ("triangles", triangles),
    ] {
        for shadow in [true, false] {
            let scene = build();
            let rays = rays(2048, 11, shadow);
            let prims = scene.committed().unwrap().prims.len() as u32;
            let exclude = (0..rays.len() as u32)
                .map(|i| if i % 2 == 0 { i * 7 % prims } else { INVALID })
                .collect();
            let kind = if shadow { "shadow rays" } else { "open rays" };
            all.push(Case {
                name: format!("{name}, {kind}"),
                scene,
                rays,
                exclude,
            });
        }
    }
    all
}

/// [`Counts`] of `rays` under `q`, excluding `exclude` where given.
pub fn counts(
    ctx: &Context,
    scene: &Committed,
    rays: &[Ray],
    exclude: Option<&[PrimIndex]>,
    q: &QueryOptions,
) -> Counts {
    let mut out = vec![false; rays.len()];
    let st = match exclude {
        Some(e) => ctx.occluded_excluding(scene, rays, e, &mut out, q),
        None => ctx.occluded(scene, rays, &mut out, q),
    }
    .unwrap();
    (st, out.iter().filter(|&&b| b).count())
}

/// Uniform in [0, a) (`super::uniform` is in [-1, 1)).
fn positive(seed: u64) -> impl FnMut(f32) -> f32 {
    let mut r = super::uniform(seed);
    move |a| ((r() + 1.0) * 0.5) as f32 * a
}

fn committed(mut s: Scene) -> Scene {
    s.commit().unwrap();
    s.ensure_ropes().unwrap();
    s
}

/// 300 spheres, ellipsoids and boxes in a 10-unit cube.
fn analytic() -> Scene {
    let mut v = positive(7);
    let mut s = Scene::new();
    for k in 0..300 {
        let c = Vec3::new(v(10.0), v(10.0), v(10.0));
        let mut extent = || Vec3::new(0.2 + v(0.5), 0.2 + v(0.5), 0.2 + v(0.5));
        let shape = match k % 3 {
            0 => Shape::Sphere {
                center: c,
                radius: extent().x,
            },
            1 => Shape::Ellipsoid {
                center: c,
                radii: extent(),
            },
            _ => Shape::Box {
                min: c,
                max: c + extent(),
            },
        };
        s.add_object(shape, 0).unwrap();
    }
    committed(s)
}

/// 2000 triangles of about a unit across in a 10-unit cube.
fn triangles() -> Scene {
    let mut v = positive(9);
    let mut positions = Vec::new();
    for _ in 0..2000 {
        let c = Vec3::new(v(10.0), v(10.0), v(10.0));
        for _ in 0..3 {
            positions.push(c + Vec3::new(v(1.0), v(1.0), v(1.0)));
        }
    }
    let triangles = (0..2000u32)
        .map(|k| [3 * k, 3 * k + 1, 3 * k + 2])
        .collect();
    let mut s = Scene::new();
    s.add_object(
        Shape::Mesh {
            positions,
            triangles,
        },
        0,
    )
    .unwrap();
    committed(s)
}

/// `n` rays from around the cube towards points in it: shadow rays end there.
fn rays(n: usize, seed: u64, shadow: bool) -> Vec<Ray> {
    let mut v = positive(seed);
    (0..n)
        .map(|_| {
            let o = Vec3::new(v(14.0), v(14.0), v(14.0)) - 2.0;
            let to = Vec3::new(v(10.0), v(10.0), v(10.0));
            let tmax = if shadow {
                (to - o).length()
            } else {
                f32::INFINITY
            };
            Ray::new(o, (to - o).normalize(), 0.0, tmax)
        })
        .collect()
}
