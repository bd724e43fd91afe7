//! Rays at the ends of f32's range through the C API: windows open to `-inf`, directions of
//! 1e-45 or 3e38, origins near `f32::MAX`. A query may miss such a ray but never returns a
//! hit that is not a point of the ray: every hit has a finite `t`, `u` and `v`, and
//! `rt2_hit_surfaces` (which refuses anything else) accepts it. On the CPU every mode,
//! traversal and intersector returns the same hits, bit for bit; the GPU's are checked for
//! finiteness only (its arithmetic may round differently).

mod support;
use support::{last_error, ok};

use rt2::api::*;
use rt2::error::Rt2Status;
use std::ptr::{null, null_mut};
use support::rng::{Draws, Rng};

const INF: f32 = f32::INFINITY;
const MAX: f32 = f32::MAX;

/// What the outputs hold before a call writes them.
const NO_HIT: rt2_hit = rt2_hit {
    t: f32::NAN,
    u: f32::NAN,
    v: f32::NAN,
    object: 7,
    prim: 7,
};
const NO_SURFACE: rt2_surface = rt2_surface {
    position: [f32::NAN; 3],
    normal: [f32::NAN; 3],
    material: 7,
};

fn ray(org: [f32; 3], tmin: f32, dir: [f32; 3], tmax: f32) -> rt2_ray {
    rt2_ray {
        org,
        tmin,
        dir,
        tmax,
    }
}

/// A context and a scene on it.
struct Scene {
    ctx: *mut rt2_context,
    scene: *mut rt2_scene,
}

impl Scene {
    /// An empty scene on a context of `backend`, or `None` when that backend is unavailable.
    fn empty(backend: Rt2Backend) -> Option<Scene> {
        let mut desc = rt2_context_desc_default();
        desc.backend = backend as u32;
        let mut ctx = null_mut();
        unsafe {
            if rt2_context_create(&desc, &mut ctx) != Rt2Status::Ok {
                return None;
            }
            let mut scene = null_mut();
            ok(rt2_scene_create(ctx, &mut scene));
            Some(Scene { ctx, scene })
        }
    }

    /// Adds a mesh of `positions` (x, y, z each) and `indices` (three per triangle).
    fn add_mesh(&self, positions: &[f32], indices: &[u32]) {
        let mut id = 0;
        unsafe {
            ok(rt2_scene_add_mesh(
                self.scene,
                positions.as_ptr(),
                positions.len() / 3,
                indices.as_ptr(),
                indices.len() / 3,
                0,
                &mut id,
            ));
        }
    }

    fn commit(self) -> Scene {
        unsafe { ok(rt2_scene_commit(self.scene)) };
        self
    }

    /// A committed scene of the review's triangle and the plane `y = -2`, and with
    /// `every_kind` a sphere, an ellipsoid and a box.
    fn new(backend: Rt2Backend, every_kind: bool) -> Option<Scene> {
        let s = Scene::empty(backend)?;
        s.add_mesh(
            &[
                -1.0, -1.0, 0.0, 1.0, -1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 1.0, 0.5,
            ],
            &[0, 1, 2, 1, 3, 2],
        );
        let mut id = 0;
        unsafe {
            ok(rt2_scene_add_plane(
                s.scene,
                [0.0, 1.0, 0.0].as_ptr(),
                -2.0,
                0,
                &mut id,
            ));
            if !every_kind {
                return Some(s.commit());
            }
            ok(rt2_scene_add_sphere(
                s.scene,
                [3.0, 0.0, 0.0].as_ptr(),
                1.0,
                0,
                &mut id,
            ));
            let (c, r) = ([-3.0f32, 0.0, 0.0], [0.5f32, 1.0, 2.0]);
            ok(rt2_scene_add_ellipsoid(
                s.scene,
                c.as_ptr(),
                r.as_ptr(),
                0,
                &mut id,
            ));
            let (lo, hi) = ([-1.0f32, 2.0, -1.0], [1.0f32, 3.0, 1.0]);
            ok(rt2_scene_add_box(
                s.scene,
                lo.as_ptr(),
                hi.as_ptr(),
                0,
                &mut id,
            ));
        }
        Some(s.commit())
    }

    /// The hits of `rays` with `opt`, or the status of a refused query.
    fn intersect(
        &self,
        rays: &[rt2_ray],
        opt: &rt2_query_options,
    ) -> Result<Vec<rt2_hit>, Rt2Status> {
        let mut hits = vec![NO_HIT; rays.len()];
        let st = unsafe {
            rt2_intersect(
                self.ctx,
                self.scene,
                rays.as_ptr(),
                rays.len(),
                hits.as_mut_ptr(),
                opt,
                null_mut(),
            )
        };
        (st == Rt2Status::Ok).then_some(hits).ok_or(st)
    }

    /// Whether each of `rays` is occluded with `opt` (`rt2_occluded`).
    fn occluded(&self, rays: &[rt2_ray], opt: &rt2_query_options) -> Vec<u8> {
        let mut found = vec![7u8; rays.len()];
        unsafe {
            ok(rt2_occluded(
                self.ctx,
                self.scene,
                rays.as_ptr(),
                rays.len(),
                found.as_mut_ptr(),
                opt,
                null_mut(),
            ))
        };
        found
    }

    /// Checks that every hit is a miss or a point of its ray: finite `t`, `u`, `v`, and a
    /// surface `rt2_hit_surfaces` accepts.
    fn check_hits(&self, what: &str, rays: &[rt2_ray], hits: &[rt2_hit]) -> usize {
        let mut found = 0;
        for (r, h) in rays.iter().zip(hits) {
            if h.object == RT2_INVALID_ID {
                assert_eq!(h.t, INF, "{what}: a miss with t = {} for {r:?}", h.t);
                continue;
            }
            found += 1;
            assert!(
                h.t.is_finite() && h.u.is_finite() && h.v.is_finite(),
                "{what}: hit {h:?} for {r:?} is not a point of the ray"
            );
        }
        let mut surfaces = vec![NO_SURFACE; rays.len()];
        let st = unsafe {
            rt2_hit_surfaces(
                self.scene,
                rays.as_ptr(),
                hits.as_ptr(),
                rays.len(),
                surfaces.as_mut_ptr(),
            )
        };
        assert_eq!(
            st,
            Rt2Status::Ok,
            "{what}: surfaces refused: {}",
            last_error()
        );
        found
    }
}

impl Drop for Scene {
    fn drop(&mut self) {
        unsafe {
            rt2_scene_destroy(self.scene);
            rt2_context_destroy(self.ctx);
        }
    }
}

/// Two rays a review found returning `t = -inf` (and a NaN `v`) on the triangle and plane
/// alone, then their mirror images: they cross only beyond `-f32::MAX` (`+f32::MAX`) along
/// the ray, so each is a miss, as the mirror images already were (`t < tmax = inf`).
fn found_by_review() -> Vec<rt2_ray> {
    vec![
        ray([0.0, 0.0, -1.0], -INF, [0.0, 0.0, -1e-45], INF),
        ray([0.0, 0.0, 0.0], -INF, [1.0, 1e-45, 0.0], INF),
        ray([0.0, 0.0, -1.0], 0.0, [0.0, 0.0, 1e-45], INF),
        ray([0.0, 0.0, 0.0], 0.0, [-1.0, -1e-45, 0.0], INF),
    ]
}

/// Rays whose components are drawn from the ends of f32's range and a few ordinary values.
fn extreme_rays(n: usize) -> Vec<rt2_ray> {
    const PARTS: [f32; 12] = [
        0.0, 1e-45, 1e-38, 1e-20, 0.5, 1.0, 3.0, 1e19, 1e30, 3.4e38, MAX, 2.0,
    ];
    const TMIN: [f32; 5] = [-INF, -MAX, -1.0, 0.0, 1e-45];
    const TMAX: [f32; 4] = [INF, MAX, 1.0, 10.0];
    let mut rng = Rng(0x005e_ede7);
    let part = |rng: &mut Rng| {
        let v = PARTS[rng.below(PARTS.len())];
        if rng.below(2) == 0 {
            -v
        } else {
            v
        }
    };
    let v3 = |rng: &mut Rng| [part(rng), part(rng), part(rng)];
    (0..n)
        .map(|_| {
            let org = v3(&mut rng);
            let dir = v3(&mut rng);
            ray(org, TMIN[rng.below(5)], dir, TMAX[rng.below(4)])
        })
        .collect()
}

/// Every (mode, traversal, intersector) of the query options.
fn every_option() -> Vec<(String, rt2_query_options)> {
    let modes = [
        Rt2QueryMode::Single,
        Rt2QueryMode::Packet,
        Rt2QueryMode::Stream,
        Rt2QueryMode::Auto,
    ];
    let traversals = [
        Rt2Traversal::Standard,
        Rt2Traversal::KdRestart,
        Rt2Traversal::PushDown,
        Rt2Traversal::ShortStack,
        Rt2Traversal::PushDownShortStack,
        Rt2Traversal::Ropes,
        Rt2Traversal::RopesPlusPlus,
    ];
    let intersectors = [Rt2Intersector::MollerTrumbore, Rt2Intersector::Watertight];
    let mut out = Vec::new();
    for i in intersectors {
        for m in modes {
            for t in traversals {
                let mut o = rt2_query_options_default();
                (o.mode, o.traversal, o.intersector) = (m as u32, t as u32, i as u32);
                out.push((format!("{m:?} {t:?} {i:?}"), o));
            }
        }
    }
    out
}

fn same_bits(a: &rt2_hit, b: &rt2_hit) -> bool {
    (
        a.t.to_bits(),
        a.u.to_bits(),
        a.v.to_bits(),
        a.object,
        a.prim,
    ) == (
        b.t.to_bits(),
        b.u.to_bits(),
        b.v.to_bits(),
        b.object,
        b.prim,
    )
}

#[test]
fn rays_whose_crossings_lie_beyond_f32_miss() {
    let s = Scene::new(Rt2Backend::Cpu, false).expect("a CPU context");
    let rays = found_by_review();
    for (what, opt) in every_option() {
        let hits = s.intersect(&rays, &opt).unwrap();
        for (r, h) in rays.iter().zip(&hits) {
            assert_eq!(h.object, RT2_INVALID_ID, "{what}: {r:?} hit {h:?}");
        }
    }
}

/// A ray 1e-20 long starting on a quad: its hit is at `t = 0`, inside the window `[0, 1e-26)`
/// and `[-1e-26, inf)` but not `[1e-26, inf)`. The queries scale such a direction by 2^66, and
/// the window's ends divided by it are subnormal: rounded to nearest, `tmin` 1e-26 became 0
/// (the hit was reported) and `tmax` 1e-26 became 0 (the hit was lost).
#[test]
fn a_tiny_direction_keeps_its_window_exactly() {
    let s = Scene::empty(Rt2Backend::Cpu).expect("a CPU context");
    let quad = [
        -1.0, -1.0, 0.0, 1.0, -1.0, 0.0, 1.0, 1.0, 0.0, -1.0, 1.0, 0.0,
    ];
    s.add_mesh(&quad, &[0, 1, 2, 0, 2, 3]);
    let s = s.commit();
    let down = |tmin, tmax| ray([0.3, -0.2, 0.0], tmin, [0.0, 0.0, -1e-20], tmax);
    let rays = [down(1e-26, INF), down(0.0, 1e-26), down(-1e-26, INF)];
    for (what, opt) in every_option() {
        let hits = s.intersect(&rays, &opt).unwrap();
        let found = s.occluded(&rays, &opt);
        assert_eq!(hits[0].object, RT2_INVALID_ID, "{what}: {:?}", hits[0]);
        assert_eq!(found[0], 0, "{what}: occluded past its tmin");
        for (h, f) in hits[1..].iter().zip(&found[1..]) {
            assert!(h.object == 0 && h.t == 0.0, "{what}: {h:?}");
            assert_eq!(*f, 1, "{what}");
        }
    }
}

#[test]
fn extreme_rays_hit_only_points_of_the_ray_and_agree_across_cpu_modes() {
    let s = Scene::new(Rt2Backend::Cpu, true).expect("a CPU context");
    let rays = extreme_rays(6000);
    let mut first: [Option<Vec<rt2_hit>>; 2] = [None, None];
    for (what, opt) in every_option() {
        let hits = s.intersect(&rays, &opt).unwrap();
        let found = s.check_hits(&what, &rays, &hits);
        // Enough of the rays are ordinary for the check to see hits of every kind.
        assert!(found > 300, "{what}: only {found} hits");
        match &first[opt.intersector as usize] {
            None => first[opt.intersector as usize] = Some(hits),
            Some(reference) => {
                for ((r, a), b) in rays.iter().zip(reference).zip(&hits) {
                    assert!(
                        same_bits(a, b),
                        "{what}: {b:?}, first mode {a:?}, for {r:?}"
                    );
                }
            }
        }
    }
}

#[test]
fn extreme_rays_on_the_gpu_hit_only_points_of_the_ray() {
    if !support::c_gpu_or_skip() {
        return;
    }
    let rays = extreme_rays(6000);
    let review = found_by_review();
    for (every_kind, rays) in [(true, &rays), (false, &review)] {
        let s = Scene::new(Rt2Backend::Gpu, every_kind).expect("a GPU context (probed)");
        for (what, opt) in every_option() {
            if opt.mode != Rt2QueryMode::Auto as u32 {
                continue;
            }
            match s.intersect(rays, &opt) {
                Ok(hits) => {
                    let found = s.check_hits(&what, rays, &hits);
                    if every_kind {
                        assert!(found > 300, "{what}: only {found} hits");
                    } else {
                        assert_eq!(found, 0, "{what}: {hits:?}");
                    }
                }
                Err(st) => assert_eq!(st, Rt2Status::Unsupported, "{what}: {}", last_error()),
            }
        }
    }
}

/// Three small triangles and a ray from near `f32::MAX` found by a probe of the C API: the
/// ray's `dir · q` in Möller–Trumbore overflowed to `inf - inf`, and the `v = NaN` it gave
/// passed the test's `v < 0 || u + v > 1` rejection (false for NaN) as a hit, which
/// `rt2_hit_surfaces` then refused. Every CPU option and the GPU must return finite hits
/// or misses for it.
fn overflowing_barycentric() -> (Vec<f32>, Vec<rt2_ray>) {
    // The probe's corners (the shortest decimals of its f32 values).
    let positions = [
        [-0.81355965, -0.30981278, -0.20845008],
        [-1.0678718, -0.908358, 0.15750265],
        [-0.9784814, -0.95990026, 1.8586066],
        [1.6103475, -0.9007782, -1.4971786],
        [-1.8435988, 1.7184398, 0.5351081],
        [1.3317447, -1.2947357, 1.464411],
        [0.9241147, 0.030079365, -0.27529728],
        [0.19805574, -0.98177326, 0.7719383],
        [0.78650093, -1.3763561, 1.047344],
    ];
    // The probe's ray: components of 0x1.c363ccp+127 (3.0e38) and -0x1.1b1c6p+0.
    let big = f32::from_bits(0x7f61_b1e6);
    let rays = vec![ray(
        [-0.0, -big, big],
        0.0,
        [-f32::from_bits(0x3f8d_8e30), big, -big],
        INF,
    )];
    (positions.concat(), rays)
}

#[test]
fn an_overflowing_barycentric_gives_a_finite_hit_or_a_miss() {
    let (positions, rays) = overflowing_barycentric();
    let indices: Vec<u32> = (0..9).collect();
    let mut backends = vec![Rt2Backend::Cpu];
    if support::c_gpu_or_skip() {
        backends.push(Rt2Backend::Gpu);
    }
    for backend in backends {
        let s = Scene::empty(backend).expect("a context (probed)");
        s.add_mesh(&positions, &indices);
        let s = s.commit();
        for (what, opt) in every_option() {
            if backend == Rt2Backend::Gpu && opt.mode != Rt2QueryMode::Auto as u32 {
                continue;
            }
            match s.intersect(&rays, &opt) {
                Ok(hits) => {
                    s.check_hits(&format!("{backend:?} {what}"), &rays, &hits);
                }
                Err(st) => assert_eq!(st, Rt2Status::Unsupported, "{what}: {}", last_error()),
            }
        }
    }
}

/// An ellipsoid whose thinnest semi-axis is far below 1 (1e-19: its inverse square is near
/// `f32::MAX`) is hit on the CPU where the GPU hits it, or refused when added.
#[test]
fn very_flat_ellipsoids_are_hit_or_refused() {
    let mut backends = vec![Rt2Backend::Cpu];
    if support::c_gpu_or_skip() {
        backends.push(Rt2Backend::Gpu);
    }
    for backend in backends {
        for thin in [
            1e-30f32, 1e-25, 1e-21, 1e-20, 7e-20, 1e-19, 3e-19, 1e-18, 1e-15, 1e-10,
        ] {
            let mut desc = rt2_context_desc_default();
            desc.backend = backend as u32;
            let (mut ctx, mut scene) = (null_mut(), null_mut());
            unsafe {
                ok(rt2_context_create(&desc, &mut ctx));
                ok(rt2_scene_create(ctx, &mut scene));
                let mut id = RT2_INVALID_ID;
                let st = rt2_scene_add_ellipsoid(
                    scene,
                    [0.0f32; 3].as_ptr(),
                    [thin, 1.0, 1.0].as_ptr(),
                    0,
                    &mut id,
                );
                if st == Rt2Status::Ok {
                    ok(rt2_scene_commit(scene));
                    let rays = [
                        ray([5.0, 0.0, 0.0], 0.0, [-1.0, 0.0, 0.0], INF),
                        ray([5.0, 0.25, -0.5], 0.0, [-1.0, 0.0, 0.0], INF),
                    ];
                    let mut hits = [NO_HIT; 2];
                    ok(rt2_intersect(
                        ctx,
                        scene,
                        rays.as_ptr(),
                        2,
                        hits.as_mut_ptr(),
                        null(),
                        null_mut(),
                    ));
                    for h in hits {
                        assert_eq!(h.object, id, "{backend:?} radii ({thin}, 1, 1): {h:?}");
                        assert!(
                            (h.t - 5.0).abs() < 1e-5,
                            "{backend:?} ({thin}, 1, 1): {h:?}"
                        );
                    }
                } else {
                    assert_eq!(st, Rt2Status::InvalidArgument);
                    assert_eq!(id, RT2_INVALID_ID);
                    assert!(thin < 1e-18, "radius {thin} refused: {}", last_error());
                }
                rt2_scene_destroy(scene);
                rt2_context_destroy(ctx);
            }
        }
    }
}
