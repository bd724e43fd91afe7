//! Random sequences of `rt2_scene_*` calls through the C API against a small model of what
//! the scene holds, every query checked against a brute force in f64 over the model's objects
//! (none of the library's placement, tree or intersection code): adds of every kind of object,
//! removals, transforms, enabled states, materials, lights, build options and commits, mixed
//! with refused calls (ids removed or never given, NaN and infinite values, singular or
//! tilting transforms, NULL pointers, wrong `struct_size`s), each of which must say why and
//! leave the scene as it was, committed or not, with no id used up. After each commit the
//! closest hits (object, primitive, `t`, `u`, `v`), occlusion, the hits excluded in turn, the
//! hits' surfaces (material, point and normal) and the statistics' counts are those of the
//! model, under each query mode, traversal and intersector in turn; between an edit and the
//! next commit every query is INVALID_OPERATION and writes nothing. 150 sequences of 100 calls
//! take about half a second in release.
//!
//! The reference takes each ray into an object's own space with the inverse of its transform
//! (the ray parameter `t` and a triangle's barycentrics do not change) and meets the shape as
//! it was added. Rays that pass within a small margin of an edge, a silhouette, or the end of
//! their window are left out of the comparison: rounding may put them on either side.

use glam::{DMat3, DQuat, DVec3};
use rt2::api::*;
use rt2::error::Rt2Status;
use std::ptr::{null, null_mut};

mod support;
use support::last_error;
use support::rng::{Draws, Rng};

/// An object's shape as added through the C API.
#[derive(Clone, Debug)]
enum Shape {
    Mesh(Vec<[f32; 3]>, Vec<[u32; 3]>),
    Sphere([f32; 3], f32),
    Ellipsoid([f32; 3], [f32; 3]),
    Box([f32; 3], [f32; 3]),
    Plane([f32; 3], f32),
}

/// An object the scene should hold.
#[derive(Clone, Debug)]
struct Obj {
    shape: Shape,
    material: u32,
    enabled: bool,
    /// Row-major `[R | t]`, as `rt2_scene_set_transform` takes it.
    transform: [f32; 12],
}

const IDENTITY: [f32; 12] = [1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0];

/// What the scene should be: its objects by id (`None`: removed), how many materials and
/// lights it has, and whether its last commit is current (no edit since).
struct Model {
    objects: Vec<Option<Obj>>,
    materials: u32,
    lights: u32,
    fresh: bool,
}

impl Model {
    fn live(&self) -> impl Iterator<Item = (u32, &Obj)> {
        (0..)
            .zip(&self.objects)
            .filter_map(|(id, o)| Some((id, o.as_ref()?)))
    }

    fn live_ids(&self) -> Vec<u32> {
        self.live().map(|(id, _)| id).collect()
    }

    fn removed_ids(&self) -> Vec<u32> {
        (0..)
            .zip(&self.objects)
            .filter(|(_, o)| o.is_none())
            .map(|(id, _)| id)
            .collect()
    }
}

/// One primitive's answer for one ray in the reference.
#[derive(Clone, Copy, Debug)]
struct Cand {
    t: f64,
    object: u32,
    prim: u32,
    u: f64,
    v: f64,
    /// The geometric normal at the hit, unit length, in world space.
    normal: DVec3,
}

/// Barycentric, angular and relative margins under which rounding decides.
const MARGIN: f64 = 1e-4;

/// The reference hits of the ray `o + t d`, `t` in `[0, tmax)`, on every enabled object of
/// `model`, or `None` when the ray passes within [`MARGIN`] of a decision.
fn reference(model: &Model, o: DVec3, d: DVec3, tmax: f64) -> Option<Vec<Cand>> {
    let mut out = Vec::new();
    // Whether `t` is in the window, or `None` when it is too near an end of it.
    let window = |t: f64| -> Option<bool> {
        let near = |end: f64| (t - end).abs() <= MARGIN * t.abs().max(1.0);
        if near(0.0) || (tmax.is_finite() && near(tmax)) {
            return None;
        }
        Some(t > 0.0 && t < tmax)
    };
    for (id, obj) in model.live().filter(|(_, o)| o.enabled) {
        let m = obj.transform.map(f64::from);
        let lin = DMat3::from_cols(
            DVec3::new(m[0], m[4], m[8]),
            DVec3::new(m[1], m[5], m[9]),
            DVec3::new(m[2], m[6], m[10]),
        );
        let inv = lin.inverse();
        let (oo, dd) = (inv * (o - DVec3::new(m[3], m[7], m[11])), inv * d);
        let v3 = |a: &[f32; 3]| DVec3::from_array(a.map(f64::from));
        // An object-space normal goes to world space by the inverse transpose.
        let mut push = |t: f64, prim: u32, (u, v): (f64, f64), n: DVec3| -> Option<()> {
            if window(t)? {
                out.push(Cand {
                    t,
                    object: id,
                    prim,
                    u,
                    v,
                    normal: (inv.transpose() * n).normalize(),
                });
            }
            Some(())
        };
        match &obj.shape {
            Shape::Mesh(positions, triangles) => {
                for (k, tri) in (0..).zip(triangles) {
                    let [a, b, c] = tri.map(|i| v3(&positions[i as usize]));
                    let (e1, e2) = (b - a, c - a);
                    let p = dd.cross(e2);
                    let det = e1.dot(p);
                    if det.abs() <= MARGIN * e1.length() * e2.length() * dd.length() {
                        return None;
                    }
                    let s = oo - a;
                    let u = s.dot(p) / det;
                    let q = s.cross(e1);
                    let v = dd.dot(q) / det;
                    let t = e2.dot(q) / det;
                    let inside = u.min(v).min(1.0 - u - v);
                    if inside.abs() <= MARGIN {
                        return None;
                    }
                    if inside > 0.0 {
                        push(t, k, (u, v), e1.cross(e2))?;
                    }
                }
            }
            Shape::Sphere(..) | Shape::Ellipsoid(..) => {
                let (c, r) = match &obj.shape {
                    Shape::Sphere(c, r) => (v3(c), DVec3::splat(*r as f64)),
                    Shape::Ellipsoid(c, r) => (v3(c), v3(r)),
                    _ => unreachable!(),
                };
                let (oc, dr) = ((oo - c) / r, dd / r);
                let (a, b, cc) = (dr.dot(dr), 2.0 * oc.dot(dr), oc.dot(oc) - 1.0);
                let disc = b * b - 4.0 * a * cc;
                if disc.abs() <= MARGIN * b * b {
                    return None;
                }
                if disc > 0.0 {
                    let s = disc.sqrt();
                    let (t0, t1) = ((-b - s) / (2.0 * a), (-b + s) / (2.0 * a));
                    // The nearer root in the window (the origins lie outside every solid).
                    // The gradient of |(x - c) / r|² - 1 at the hit.
                    let at = |t: f64| (oc + t * dr) / r;
                    if window(t0)? {
                        push(t0, 0, (0.0, 0.0), at(t0))?;
                    } else if window(t1)? {
                        push(t1, 0, (0.0, 0.0), at(t1))?;
                    }
                }
            }
            Shape::Box(lo, hi) => {
                let (lo, hi) = (v3(lo), v3(hi));
                let (mut t0, mut t1) = (f64::NEG_INFINITY, f64::INFINITY);
                // The faces the ray enters and leaves by, as outward normals.
                let (mut n0, mut n1) = (DVec3::ZERO, DVec3::ZERO);
                for a in 0..3 {
                    let (ta, tb) = ((lo[a] - oo[a]) / dd[a], (hi[a] - oo[a]) / dd[a]);
                    let axis = DVec3::AXES[a] * dd[a].signum();
                    if ta.min(tb) > t0 {
                        (t0, n0) = (ta.min(tb), -axis);
                    }
                    if ta.max(tb) < t1 {
                        (t1, n1) = (ta.max(tb), axis);
                    }
                }
                if (t1 - t0).abs() <= MARGIN * t0.abs().max(1.0) {
                    return None;
                }
                if t0 < t1 {
                    if window(t0)? {
                        push(t0, 0, (0.0, 0.0), n0)?;
                    } else if window(t1)? {
                        push(t1, 0, (0.0, 0.0), n1)?;
                    }
                }
            }
            Shape::Plane(n, offset) => {
                let n = v3(n);
                let nd = n.dot(dd);
                // Grazing planes are met far off, where f32's rounding of the placed plane
                // moves `t` by more than the margin.
                if nd.abs() <= 0.02 * n.length() * dd.length() {
                    return None;
                }
                push((*offset as f64 - n.dot(oo)) / nd, 0, (0.0, 0.0), n)?;
            }
        }
    }
    Some(out)
}

/// Random objects of about unit size within `[-4, 4]³`.
fn random_shape(rng: &mut Rng) -> Shape {
    let c = rng.vec(-3.0, 3.0);
    match rng.below(9) {
        0..=2 => {
            // A few triangles over a small vertex pool: shared corners, unused vertices, and
            // now and then a mesh of no triangles at all.
            let nv = 3 + rng.below(6);
            let positions: Vec<[f32; 3]> = (0..nv)
                .map(|_| (c + rng.vec(-1.0, 1.0)).to_array())
                .collect();
            let nt = if rng.below(8) == 0 {
                0
            } else {
                1 + rng.below(8)
            };
            let triangles = (0..nt)
                .map(|_| loop {
                    let t = [0; 3].map(|_| rng.below(nv) as u32);
                    if t[0] != t[1] && t[1] != t[2] && t[0] != t[2] {
                        break t;
                    }
                })
                .collect();
            Shape::Mesh(positions, triangles)
        }
        3 | 4 => Shape::Sphere(c.to_array(), rng.range(0.2, 1.0)),
        5 => Shape::Ellipsoid(c.to_array(), rng.vec(0.2, 1.0).to_array()),
        6 | 7 => {
            let lo = c - rng.vec(0.1, 0.8);
            Shape::Box(lo.to_array(), (c + rng.vec(0.1, 0.8)).to_array())
        }
        _ => {
            // Any length of normal; the plane passes near the objects.
            let n = rng.dir() * rng.range(0.3, 3.0);
            Shape::Plane(n.to_array(), n.dot(rng.vec(-4.0, 4.0)))
        }
    }
}

/// A random valid transform for `shape`: for a box, axes swapped, mirrored and scaled; for the
/// others also rotated and sheared by a non-uniform scale; sometimes mirrored.
fn random_transform(rng: &mut Rng, shape: &Shape) -> [f32; 12] {
    let t = rng.vec(-1.5, 1.5).as_dvec3();
    let sign = |rng: &mut Rng| if rng.below(4) == 0 { -1.0 } else { 1.0 };
    let lin = if matches!(shape, Shape::Box(..)) {
        let mut axes = [0, 1, 2];
        for i in (1..3).rev() {
            axes.swap(i, rng.below(i + 1));
        }
        let cols = axes.map(|a| DVec3::AXES[a] * sign(rng) * rng.range(0.5, 1.5) as f64);
        DMat3::from_cols(cols[0], cols[1], cols[2])
    } else {
        let rot = DQuat::from_axis_angle(rng.dir().as_dvec3(), rng.range(0.0, 6.3) as f64);
        let scale = match rng.below(3) {
            0 => DVec3::splat(rng.range(0.5, 1.5) as f64),
            1 => rng.vec(0.5, 1.5).as_dvec3(),
            _ => DVec3::ONE,
        };
        DMat3::from_quat(rot) * DMat3::from_diagonal(scale * DVec3::new(sign(rng), 1.0, 1.0))
    };
    let mut m = [0.0f32; 12];
    for r in 0..3 {
        for c in 0..3 {
            m[4 * r + c] = lin.col(c)[r] as f32;
        }
        m[4 * r + 3] = t[r] as f32;
    }
    m
}

/// A material with random valid terms.
fn random_material(rng: &mut Rng) -> rt2_material {
    let mut m = rt2_material_default();
    m.color = rng.vec(0.0, 1.0).to_array();
    m.diffuse = rng.unit();
    m.reflectivity = rng.range(0.0, 0.5);
    m
}

/// Adds `shape` with `material`, returning the status and the id written (`sentinel` if
/// none).
unsafe fn add(
    scene: *mut rt2_scene,
    shape: &Shape,
    material: u32,
    sentinel: u32,
) -> (Rt2Status, u32) {
    let mut id = sentinel;
    let st = match shape {
        Shape::Mesh(p, t) => rt2_scene_add_mesh(
            scene,
            p.as_ptr().cast(),
            p.len(),
            t.as_ptr().cast(),
            t.len(),
            material,
            &mut id,
        ),
        Shape::Sphere(c, r) => rt2_scene_add_sphere(scene, c.as_ptr(), *r, material, &mut id),
        Shape::Ellipsoid(c, r) => {
            rt2_scene_add_ellipsoid(scene, c.as_ptr(), r.as_ptr(), material, &mut id)
        }
        Shape::Box(lo, hi) => rt2_scene_add_box(scene, lo.as_ptr(), hi.as_ptr(), material, &mut id),
        Shape::Plane(n, d) => rt2_scene_add_plane(scene, n.as_ptr(), *d, material, &mut id),
    };
    (st, id)
}

/// Removes object `id` from the scene and from the model, whose commit is then stale.
unsafe fn remove(scene: *mut rt2_scene, model: &mut Model, id: u32) {
    assert_eq!(
        rt2_scene_remove(scene, id),
        Rt2Status::Ok,
        "{}",
        last_error()
    );
    model.objects[id as usize] = None;
    model.fresh = false;
}

/// `shape` made invalid in one way its add refuses (a NaN or infinite value, a non-positive
/// size, min past max, a zero normal, an index past the vertices).
fn spoiled(rng: &mut Rng, shape: &Shape) -> Shape {
    let bad = [f32::NAN, f32::INFINITY, f32::NEG_INFINITY][rng.below(3)];
    let mut s = shape.clone();
    match &mut s {
        Shape::Mesh(p, t) => {
            if t.is_empty() || rng.below(2) == 0 {
                let nv = p.len();
                p[rng.below(nv)][rng.below(3)] = bad;
            } else {
                let nt = t.len();
                t[rng.below(nt)][rng.below(3)] = (p.len() + rng.below(3)) as u32;
            }
        }
        Shape::Sphere(c, r) => match rng.below(3) {
            0 => c[rng.below(3)] = bad,
            1 => *r = [0.0, -1.0, bad][rng.below(3)],
            _ => *r = -0.0,
        },
        Shape::Ellipsoid(c, r) => match rng.below(2) {
            0 => c[rng.below(3)] = bad,
            _ => r[rng.below(3)] = [0.0, -0.5, bad][rng.below(3)],
        },
        Shape::Box(lo, hi) => match rng.below(2) {
            0 => lo[rng.below(3)] = bad,
            _ => {
                let a = rng.below(3);
                hi[a] = lo[a] - 0.1;
            }
        },
        Shape::Plane(n, d) => match rng.below(3) {
            0 => *n = [0.0; 3],
            1 => n[rng.below(3)] = bad,
            _ => *d = bad,
        },
    }
    s
}

/// Asserts that a refused call said why: `status` is `want`, with a message.
#[track_caller]
fn refused(status: Rt2Status, want: Rt2Status, what: &str) {
    let msg = last_error();
    assert_eq!(status, want, "{what}: {msg}");
    assert!(!msg.is_empty(), "{what}: no message");
}

/// The rays of a check: from about 30 away towards points among the objects, of lengths 0.5
/// to 2, half of them cut short by a finite `tmax`.
fn random_rays(rng: &mut Rng, n: usize) -> Vec<rt2_ray> {
    (0..n)
        .map(|_| {
            let org = rng.dir() * 30.0;
            let target = rng.vec(-4.5, 4.5);
            let dir = (target - org).normalize() * rng.range(0.5, 2.0);
            let tmax = if rng.below(2) == 0 {
                f32::INFINITY
            } else {
                rng.range(20.0, 40.0) / dir.length()
            };
            rt2_ray {
                org: org.to_array(),
                tmin: 0.0,
                dir: dir.to_array(),
                tmax,
            }
        })
        .collect()
}

/// The query options of the `k`th check: default, each mode and traversal, watertight.
fn options(k: usize) -> rt2_query_options {
    let mut o = rt2_query_options_default();
    match k % 10 {
        0 => {}
        1..=3 => o.mode = (k % 10 - 1) as u32,
        4..=8 => o.traversal = (k % 10 - 2) as u32,
        _ => o.intersector = 1,
    }
    o
}

const SENTINEL: rt2_hit = rt2_hit {
    t: -7.0,
    u: -7.0,
    v: -7.0,
    object: 7777,
    prim: 7777,
};

/// Runs the queries of one check; `Err` with the status when refused (then nothing may have
/// been written).
unsafe fn query(
    ctx: *mut rt2_context,
    scene: *mut rt2_scene,
    rays: &[rt2_ray],
    opt: &rt2_query_options,
) -> Result<(Vec<rt2_hit>, Vec<u8>), Rt2Status> {
    let mut hits = vec![SENTINEL; rays.len()];
    let mut occ = vec![7u8; rays.len()];
    let (r, n) = (rays.as_ptr(), rays.len());
    let st = rt2_intersect(ctx, scene, r, n, hits.as_mut_ptr(), opt, null_mut());
    let st2 = rt2_occluded(ctx, scene, r, n, occ.as_mut_ptr(), opt, null_mut());
    if st != Rt2Status::Ok || st2 != Rt2Status::Ok {
        assert_eq!(st, st2, "intersect and occluded disagree: {}", last_error());
        assert!(
            hits.iter().all(|h| h.object == SENTINEL.object),
            "refused query wrote hits"
        );
        assert!(occ.iter().all(|&o| o == 7), "refused query wrote occlusion");
        return Err(st);
    }
    Ok((hits, occ))
}

/// Compares the library's closest hit `h` of ray `i` with the reference candidates `cands`
/// (leaving out the primitive `excluded` names); `Err` says how they differ.
fn compare(
    h: &rt2_hit,
    cands: &[Cand],
    excluded: Option<&rt2_hit>,
) -> Result<Option<Cand>, String> {
    let kept: Vec<&Cand> = cands
        .iter()
        .filter(|c| excluded.is_none_or(|e| (e.object, e.prim) != (c.object, c.prim)))
        .collect();
    let nearest = kept.iter().map(|c| c.t).fold(f64::INFINITY, f64::min);
    if nearest.is_infinite() {
        return if h.object == RT2_INVALID_ID && h.prim == RT2_INVALID_ID && h.t == f32::INFINITY {
            Ok(None)
        } else {
            Err(format!("the reference misses, the library hit {h:?}"))
        };
    }
    let tol = |t: f64| MARGIN * t.abs().max(1.0);
    // Candidates as near as rounding can make the nearest one.
    let near: Vec<&&Cand> = kept
        .iter()
        .filter(|c| c.t - nearest <= 2.0 * tol(nearest))
        .collect();
    let Some(c) = near
        .iter()
        .find(|c| (c.object, c.prim) == (h.object, h.prim))
    else {
        return Err(format!("the library hit {h:?}, the reference {near:?}"));
    };
    let ok = (h.t as f64 - c.t).abs() <= tol(c.t)
        && (h.u as f64 - c.u).abs() <= 1e-3
        && (h.v as f64 - c.v).abs() <= 1e-3;
    if ok {
        Ok(Some(***c))
    } else {
        Err(format!("the library hit {h:?}, the reference {c:?}"))
    }
}

/// Checks a committed scene against `model`: hits, occlusion, hits excluded, surfaces'
/// materials and the statistics. Returns how many rays were compared.
unsafe fn check(
    ctx: *mut rt2_context,
    scene: *mut rt2_scene,
    model: &Model,
    rays: &[rt2_ray],
    opt: &rt2_query_options,
    step: &str,
) -> usize {
    let (hits, occ) = query(ctx, scene, rays, opt).unwrap_or_else(|st| {
        panic!(
            "{step}: a committed scene refused a query: {st:?} {}",
            last_error()
        )
    });
    let mut ex = *opt;
    ex.exclude = hits.as_ptr();
    let (second, _) = query(ctx, scene, rays, &ex).unwrap_or_else(|st| {
        panic!(
            "{step}: excluding the hits was refused: {st:?} {}",
            last_error()
        )
    });
    // The reference hit each compared ray's closest hit matched.
    let mut matched = vec![None; rays.len()];
    let mut compared = 0;
    for (i, r) in rays.iter().enumerate() {
        let (o, d) = (
            DVec3::from_array(r.org.map(f64::from)),
            DVec3::from_array(r.dir.map(f64::from)),
        );
        let Some(cands) = reference(model, o, d, r.tmax as f64) else {
            continue;
        };
        compared += 1;
        let what = format!(
            "{step}, ray {i} {r:?} (live objects {:?})",
            model.live_ids()
        );
        matched[i] = compare(&hits[i], &cands, None).unwrap_or_else(|e| panic!("{what}: {e}"));
        assert_eq!(
            occ[i],
            u8::from(!cands.is_empty()),
            "{what}: occlusion, hit {:?}",
            hits[i]
        );
        if let Err(e) = compare(&second[i], &cands, Some(&hits[i])) {
            panic!("{what}, excluding {:?}: {e}", hits[i]);
        }
    }
    // The hits' surfaces: their objects' materials, and where a ray was compared, the point
    // on the ray and the reference's normal.
    let mut surfaces = vec![
        rt2_surface {
            position: [0.0; 3],
            normal: [0.0; 3],
            material: 7777,
        };
        rays.len()
    ];
    let st = rt2_hit_surfaces(
        scene,
        rays.as_ptr(),
        hits.as_ptr(),
        rays.len(),
        surfaces.as_mut_ptr(),
    );
    assert_eq!(st, Rt2Status::Ok, "{step}: surfaces: {}", last_error());
    for (i, (h, s)) in hits.iter().zip(&surfaces).enumerate() {
        let want = match model.objects.get(h.object as usize) {
            Some(Some(o)) => o.material,
            _ => RT2_INVALID_ID,
        };
        assert_eq!(s.material, want, "{step}: the material of {h:?}");
        if let Some(c) = matched[i] {
            let r = &rays[i];
            let p = DVec3::from_array(r.org.map(f64::from))
                + c.t * DVec3::from_array(r.dir.map(f64::from));
            let (got_p, got_n) = (
                DVec3::from_array(s.position.map(f64::from)),
                DVec3::from_array(s.normal.map(f64::from)),
            );
            assert!(
                (got_p - p).length() <= 1e-3 * p.length().max(1.0)
                    && (got_n - c.normal).length() <= 1e-3,
                "{step}, ray {i}: the surface of {h:?} is {s:?}, the reference's point \
                 {p} and normal {}",
                c.normal
            );
        }
    }
    // The statistics count what the model holds.
    let mut st = std::mem::zeroed::<rt2_scene_statistics>();
    st.struct_size = std::mem::size_of::<rt2_scene_statistics>() as u32;
    assert_eq!(
        rt2_scene_stats(scene, &mut st),
        Rt2Status::Ok,
        "{step}: {}",
        last_error()
    );
    let mut want = [0u32; 5];
    for (_, o) in model.live().filter(|(_, o)| o.enabled) {
        match &o.shape {
            Shape::Mesh(_, t) => want[0] += t.len() as u32,
            Shape::Sphere(..) | Shape::Ellipsoid(..) => want[1] += 1,
            Shape::Box(..) => want[2] += 1,
            Shape::Plane(..) => want[3] += 1,
        }
    }
    want[4] = model.live().count() as u32;
    let got = [
        st.triangle_count,
        st.sphere_count + st.ellipsoid_count,
        st.box_count,
        st.plane_count,
        st.object_count,
    ];
    assert_eq!(
        got, want,
        "{step}: statistics (triangles, quadrics, boxes, planes, objects)"
    );
    compared
}

/// One random sequence of `steps` calls on a new scene; returns (checks, checks with no object
/// left after removals, checks with 8 or more objects, rays compared).
fn sequence(seed: u64, steps: usize) -> [usize; 4] {
    let mut rng = Rng(seed);
    let (mut ctx, mut scene) = (null_mut(), null_mut());
    let mut tally = [0; 4];
    unsafe {
        let mut desc = rt2_context_desc_default();
        desc.backend = Rt2Backend::Cpu as u32;
        desc.threads = 1;
        assert_eq!(rt2_context_create(&desc, &mut ctx), Rt2Status::Ok);
        assert_eq!(rt2_scene_create(ctx, &mut scene), Rt2Status::Ok);
        let mut model = Model {
            objects: Vec::new(),
            materials: 1,
            lights: 0,
            fresh: false,
        };
        let mut log: Vec<String> = Vec::new();
        for step in 0..steps {
            let live = model.live_ids();
            let removed = model.removed_ids();
            let pick = |rng: &mut Rng| live[rng.below(live.len())];
            let op = rng.below(20);
            let what;
            match op {
                // Adds.
                0..=4 => {
                    let shape = random_shape(&mut rng);
                    let material = rng.below(model.materials as usize) as u32;
                    let (st, id) = add(scene, &shape, material, 7777);
                    assert_eq!(
                        st,
                        Rt2Status::Ok,
                        "seed {seed} step {step}: {}",
                        last_error()
                    );
                    assert_eq!(
                        id,
                        model.objects.len() as u32,
                        "seed {seed} step {step}: not the next id"
                    );
                    what = format!("add {id} {shape:?} material {material}");
                    model.objects.push(Some(Obj {
                        shape,
                        material,
                        enabled: true,
                        transform: IDENTITY,
                    }));
                    model.fresh = false;
                }
                5 | 6 if !live.is_empty() => {
                    let id = pick(&mut rng);
                    remove(scene, &mut model, id);
                    what = format!("remove {id}");
                }
                7 if !live.is_empty() && rng.below(4) == 0 => {
                    for &id in &live {
                        remove(scene, &mut model, id);
                    }
                    what = "remove every object".into();
                }
                8 | 9 if !live.is_empty() => {
                    let id = pick(&mut rng);
                    let obj = model.objects[id as usize].as_mut().unwrap();
                    let m = random_transform(&mut rng, &obj.shape);
                    let st = rt2_scene_set_transform(scene, id, m.as_ptr());
                    assert_eq!(
                        st,
                        Rt2Status::Ok,
                        "seed {seed} step {step}: {}",
                        last_error()
                    );
                    obj.transform = m;
                    model.fresh = false;
                    what = format!("transform {id} {m:?}");
                }
                10 if !live.is_empty() => {
                    let id = pick(&mut rng);
                    let obj = model.objects[id as usize].as_mut().unwrap();
                    let enabled = rng.below(2) == 1;
                    let st = rt2_scene_set_enabled(
                        scene,
                        id,
                        if enabled { 1 + rng.below(5) as u32 } else { 0 },
                    );
                    assert_eq!(st, Rt2Status::Ok, "{}", last_error());
                    // Setting the state it has is no edit.
                    model.fresh &= obj.enabled == enabled;
                    obj.enabled = enabled;
                    what = format!("enable {id} {enabled}");
                }
                11 => {
                    let m = random_material(&mut rng);
                    let mut id = 7777;
                    assert_eq!(
                        rt2_scene_add_material(scene, &m, &mut id),
                        Rt2Status::Ok,
                        "{}",
                        last_error()
                    );
                    assert_eq!(id, model.materials, "seed {seed} step {step}: material id");
                    model.materials += 1;
                    model.fresh = false;
                    what = format!("material {id}");
                }
                12 => {
                    let (p, c) = (rng.vec(-5.0, 5.0).to_array(), rng.vec(0.0, 1.0).to_array());
                    let mut id = 7777;
                    let st = rt2_scene_add_point_light(
                        scene,
                        p.as_ptr(),
                        c.as_ptr(),
                        rng.unit(),
                        &mut id,
                    );
                    assert_eq!(st, Rt2Status::Ok, "{}", last_error());
                    assert_eq!(id, model.lights, "seed {seed} step {step}: light id");
                    model.lights += 1;
                    model.fresh = false;
                    what = format!("light {id}");
                }
                13 => {
                    let mut o = rt2_build_options_default();
                    o.builder = rng.below(2) as u32;
                    o.layout = rng.below(2) as u32;
                    o.max_depth = [0, 1, 3, 8][rng.below(4)];
                    o.leaf_size = 1 + rng.below(4) as u32;
                    o.ropes = rng.below(2) as u32;
                    assert_eq!(
                        rt2_scene_set_build_options(scene, &o),
                        Rt2Status::Ok,
                        "{}",
                        last_error()
                    );
                    model.fresh = false;
                    what = format!("build options {o:?}");
                }
                14 | 15 => {
                    assert_eq!(rt2_scene_commit(scene), Rt2Status::Ok, "{}", last_error());
                    model.fresh = true;
                    what = "commit".into();
                }
                // Refused calls: each must change nothing (ids, committed state, contents).
                _ => {
                    what = refuse(&mut rng, scene, &model, &live, &removed);
                }
            }
            log.push(what);
            let steps_so_far = || {
                let from = log.len().saturating_sub(12);
                format!(
                    "seed {seed} step {step}, last calls:\n  {}",
                    log[from..].join("\n  ")
                )
            };
            if rng.below(3) == 0 || step + 1 == steps {
                let rays = random_rays(&mut rng, 128);
                let opt = options(tally[0] + seed as usize);
                if model.fresh {
                    tally[3] += check(ctx, scene, &model, &rays, &opt, &steps_so_far());
                    tally[0] += 1;
                    tally[1] += usize::from(model.live().count() == 0 && !model.objects.is_empty());
                    tally[2] += usize::from(model.live().count() >= 8);
                } else {
                    let st = query(ctx, scene, &rays, &opt).map(|_| ()).unwrap_err();
                    assert_eq!(
                        st,
                        Rt2Status::InvalidOperation,
                        "{}: {}",
                        steps_so_far(),
                        last_error()
                    );
                }
            }
        }
        rt2_scene_destroy(scene);
        rt2_context_destroy(ctx);
    }
    tally
}

/// One refused call, chosen at random, and a description of it. Every one is checked for its
/// status and message here; that it changed nothing, by the checks that follow.
unsafe fn refuse(
    rng: &mut Rng,
    scene: *mut rt2_scene,
    model: &Model,
    live: &[u32],
    removed: &[u32],
) -> String {
    let issued = model.objects.len() as u32;
    let bad = [f32::NAN, f32::INFINITY, f32::NEG_INFINITY][rng.below(3)];
    let inv = Rt2Status::InvalidArgument;
    match rng.below(12) {
        0 => {
            // An invalid shape of any kind.
            let good = random_shape(rng);
            let shape = spoiled(rng, &good);
            let (st, id) = add(scene, &shape, 0, 7777);
            refused(st, inv, &format!("add {shape:?}"));
            assert_eq!(id, 7777, "a refused add wrote an id");
            format!("refused add {shape:?}")
        }
        1 => {
            // A material the scene does not have.
            let shape = random_shape(rng);
            let material = model.materials + rng.below(3) as u32;
            let (st, id) = add(scene, &shape, material, 7777);
            refused(st, inv, "add with a missing material");
            assert_eq!(id, 7777, "a refused add wrote an id");
            format!("refused add of material {material}")
        }
        2 => {
            // An id removed, never given, or the miss id.
            let mut ids = vec![issued, issued + 1, RT2_INVALID_ID];
            ids.extend_from_slice(removed);
            let id = ids[rng.below(ids.len())];
            let m = IDENTITY;
            let st = match rng.below(4) {
                0 => rt2_scene_remove(scene, id),
                1 => rt2_scene_set_enabled(scene, id, rng.below(2) as u32),
                2 => rt2_scene_set_transform(scene, id, m.as_ptr()),
                _ => rt2_scene_set_transform(scene, id, null()),
            };
            refused(st, inv, &format!("call naming object {id}"));
            format!("refused call naming {id}")
        }
        3 | 4 if !live.is_empty() => {
            // A transform that is not finite, singular, or (for a box) off its axes.
            let id = live[rng.below(live.len())];
            let obj = model.objects[id as usize].as_ref().unwrap();
            let mut m = random_transform(rng, &obj.shape);
            let want = match rng.below(3) {
                0 => {
                    m[rng.below(12)] = bad;
                    inv
                }
                1 => {
                    let r = rng.below(3);
                    m[4 * r..4 * r + 3].fill(0.0);
                    inv
                }
                _ => {
                    // A turn of 30 degrees about z.
                    let (s, c) = 0.5f32.atan2(0.866).sin_cos();
                    m[..3].copy_from_slice(&[c, -s, 0.0]);
                    m[4..7].copy_from_slice(&[s, c, 0.0]);
                    m[8..11].copy_from_slice(&[0.0, 0.0, 1.0]);
                    if matches!(obj.shape, Shape::Box(..)) {
                        Rt2Status::Unsupported
                    } else {
                        // Valid for the others: spoil it.
                        m[11] = bad;
                        inv
                    }
                }
            };
            let st = rt2_scene_set_transform(scene, id, m.as_ptr());
            refused(st, want, &format!("transform {id} {m:?}"));
            format!("refused transform {id} {m:?}")
        }
        5 => {
            let mut m = random_material(rng);
            match rng.below(4) {
                0 => m.struct_size += 4,
                1 => m.ambient = bad,
                2 => (m.reflectivity, m.transparency) = (0.6, 0.6),
                _ => m.color[rng.below(3)] = -0.5,
            }
            let mut id = 7777;
            refused(rt2_scene_add_material(scene, &m, &mut id), inv, "material");
            assert_eq!(id, 7777, "a refused material wrote an id");
            let mut id = 7777;
            refused(
                rt2_scene_add_material(scene, null(), &mut id),
                inv,
                "NULL material",
            );
            assert_eq!(id, 7777, "a refused material wrote an id");
            "refused material".into()
        }
        6 => {
            let (mut p, mut c, mut i) = ([0.0f32; 3], [1.0f32; 3], 1.0f32);
            match rng.below(4) {
                0 => p[rng.below(3)] = bad,
                1 => c[rng.below(3)] = [-1.0, bad][rng.below(2)],
                2 => i = [-1.0, bad][rng.below(2)],
                _ => {
                    let mut id = 7777;
                    refused(
                        rt2_scene_add_point_light(scene, null(), c.as_ptr(), i, &mut id),
                        inv,
                        "NULL light",
                    );
                    assert_eq!(id, 7777);
                    return "refused NULL light".into();
                }
            }
            let mut id = 7777;
            refused(
                rt2_scene_add_point_light(scene, p.as_ptr(), c.as_ptr(), i, &mut id),
                inv,
                "light",
            );
            "refused light".into()
        }
        7 => {
            let mut o = rt2_build_options_default();
            match rng.below(4) {
                0 => o.struct_size -= 4,
                1 => o.leaf_size = 0,
                2 => o.traversal_cost = bad,
                _ => o.builder = 9,
            }
            refused(rt2_scene_set_build_options(scene, &o), inv, "build options");
            refused(
                rt2_scene_set_build_options(scene, null()),
                inv,
                "NULL build options",
            );
            "refused build options".into()
        }
        8 => {
            // NULL arrays with counts, and counts that overflow.
            let p = [0.0f32; 9];
            let t = [0u32, 1, 2];
            let mut id = 7777;
            let st = match rng.below(3) {
                0 => rt2_scene_add_mesh(scene, null(), 3, t.as_ptr(), 1, 0, &mut id),
                1 => rt2_scene_add_mesh(scene, p.as_ptr(), 3, null(), 1, 0, &mut id),
                _ => rt2_scene_add_mesh(scene, p.as_ptr(), usize::MAX, t.as_ptr(), 1, 0, &mut id),
            };
            refused(st, inv, "mesh arrays");
            assert_eq!(id, 7777);
            let c = [0.0f32; 3];
            refused(
                rt2_scene_add_sphere(scene, null(), 1.0, 0, &mut id),
                inv,
                "NULL centre",
            );
            refused(
                rt2_scene_add_box(scene, c.as_ptr(), null(), 0, &mut id),
                inv,
                "NULL max",
            );
            refused(
                rt2_scene_add_sphere(null_mut(), c.as_ptr(), 1.0, 0, &mut id),
                inv,
                "NULL scene",
            );
            assert_eq!(id, 7777);
            "refused NULL arrays".into()
        }
        9 => {
            // Statistics with a wrong struct_size, on a committed scene or not.
            let mut st = std::mem::zeroed::<rt2_scene_statistics>();
            st.struct_size = std::mem::size_of::<rt2_scene_statistics>() as u32 - 8;
            refused(rt2_scene_stats(scene, &mut st), inv, "stats struct_size");
            "refused stats".into()
        }
        _ => "nothing".into(),
    }
}

/// 150 sequences of 100 calls; both ends of the scene's size were met.
#[test]
fn random_edit_sequences_match_a_brute_force_model() {
    let mut total = [0; 4];
    for seed in 1..=150 {
        let t = sequence(seed, 100);
        for (a, b) in total.iter_mut().zip(t) {
            *a += b;
        }
    }
    let [checks, emptied, full, rays] = total;
    println!("{checks} checks, {emptied} with every object removed, {full} with 8 or more; {rays} rays compared");
    assert!(checks >= 500 && emptied > 0 && full > 0, "{total:?}");
}
