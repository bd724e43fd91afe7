//! `rt2_hit_surfaces` through the C API, as a user shading the hits of `rt2_intersect` calls
//! it, against references computed here in f64 from the shapes as given: each hit point is
//! taken into its object's own space with the inverse transform, where the analytic normal
//! (or the triangle's `(v1 - v0) × (v2 - v0)`) is known, and that normal is carried back by the
//! inverse transpose. Positions must lie on the surface and near `org + t * dir`.

mod support;
use support::{last_error, ok};

use glam::{Affine3A, DAffine3, DVec3, Quat, Vec3};
use rt2::api::*;
use rt2::error::Rt2Status;
use std::ptr::{null, null_mut};

/// An object as this test gave it: the shape in object space, its transform and material.
#[derive(Clone)]
enum Shape {
    Mesh(Vec<DVec3>, Vec<[u32; 3]>),
    Sphere(DVec3, f64),
    Ellipsoid(DVec3, DVec3),
    Box(DVec3, DVec3),
    Plane(DVec3, f64),
}

struct Object {
    shape: Shape,
    transform: DAffine3,
    material: u32,
}

/// A context and a scene, destroyed on drop, with the objects as added.
struct Scene {
    ctx: *mut rt2_context,
    scene: *mut rt2_scene,
    objects: Vec<Object>,
}

impl Drop for Scene {
    fn drop(&mut self) {
        unsafe {
            rt2_scene_destroy(self.scene);
            rt2_context_destroy(self.ctx);
        }
    }
}

fn f3(v: DVec3) -> [f32; 3] {
    v.as_vec3().to_array()
}

impl Scene {
    fn new() -> Self {
        let (mut ctx, mut scene) = (null_mut(), null_mut());
        let mut desc = rt2_context_desc_default();
        desc.backend = Rt2Backend::Cpu as u32;
        unsafe {
            ok(rt2_context_create(&desc, &mut ctx));
            ok(rt2_scene_create(ctx, &mut scene));
        }
        Scene {
            ctx,
            scene,
            objects: Vec::new(),
        }
    }

    /// Adds `shape` with a material of its own, placed by `t`; the reference takes both as
    /// given (the shape's numbers rounded to f32 move it by about 1e-8, far inside the
    /// tolerances). Returns the object id.
    fn add(&mut self, shape: Shape, t: Affine3A) -> u32 {
        let (s, mut material, mut id) = (self.scene, 0, 0);
        unsafe {
            let m = rt2_material_default();
            ok(rt2_scene_add_material(s, &m, &mut material));
            ok(match &shape {
                Shape::Mesh(p, tris) => {
                    let p: Vec<f32> = p.iter().flat_map(|v| f3(*v)).collect();
                    let i: Vec<u32> = tris.iter().flatten().copied().collect();
                    let (np, nt) = (p.len() / 3, tris.len());
                    rt2_scene_add_mesh(s, p.as_ptr(), np, i.as_ptr(), nt, material, &mut id)
                }
                Shape::Sphere(c, r) => {
                    rt2_scene_add_sphere(s, f3(*c).as_ptr(), *r as f32, material, &mut id)
                }
                Shape::Ellipsoid(c, r) => {
                    rt2_scene_add_ellipsoid(s, f3(*c).as_ptr(), f3(*r).as_ptr(), material, &mut id)
                }
                Shape::Box(lo, hi) => {
                    rt2_scene_add_box(s, f3(*lo).as_ptr(), f3(*hi).as_ptr(), material, &mut id)
                }
                Shape::Plane(n, d) => {
                    rt2_scene_add_plane(s, f3(*n).as_ptr(), *d as f32, material, &mut id)
                }
            });
            let m = t.matrix3;
            let row = |r: usize| [m.x_axis[r], m.y_axis[r], m.z_axis[r], t.translation[r]];
            let rows: Vec<f32> = (0..3).flat_map(row).collect();
            ok(rt2_scene_set_transform(s, id, rows.as_ptr()));
        }
        self.register(id, shape, t, material);
        id
    }

    /// Records object `id`, added by the caller (a loaded file), for the reference.
    fn register(&mut self, id: u32, shape: Shape, t: Affine3A, material: u32) {
        assert_eq!(id as usize, self.objects.len());
        self.objects.push(Object {
            shape,
            transform: DAffine3::from_cols_array(&t.to_cols_array().map(f64::from)),
            material,
        });
    }

    fn commit(&self) {
        unsafe { ok(rt2_scene_commit(self.scene)) };
    }

    fn intersect(&self, rays: &[rt2_ray]) -> Vec<rt2_hit> {
        let mut hits = vec![miss(); rays.len()];
        let n = rays.len();
        unsafe {
            let st = rt2_intersect(
                self.ctx,
                self.scene,
                rays.as_ptr(),
                n,
                hits.as_mut_ptr(),
                null(),
                null_mut(),
            );
            ok(st);
        }
        hits
    }

    /// `rt2_hit_surfaces` into an array prefilled with [`SENTINEL`].
    fn surfaces(&self, rays: &[rt2_ray], hits: &[rt2_hit]) -> (Rt2Status, Vec<rt2_surface>) {
        let mut out = vec![SENTINEL; rays.len()];
        let n = rays.len();
        let st = unsafe {
            rt2_hit_surfaces(
                self.scene,
                rays.as_ptr(),
                hits.as_ptr(),
                n,
                out.as_mut_ptr(),
            )
        };
        (st, out)
    }

    fn lookup_bytes(&self) -> u64 {
        let mut st = rt2_scene_statistics {
            struct_size: std::mem::size_of::<rt2_scene_statistics>() as u32,
            ..Default::default()
        };
        unsafe { ok(rt2_scene_stats(self.scene, &mut st)) };
        st.bytes_prim_lookup
    }
}

fn miss() -> rt2_hit {
    rt2_hit {
        t: f32::INFINITY,
        u: 0.0,
        v: 0.0,
        object: RT2_INVALID_ID,
        prim: RT2_INVALID_ID,
    }
}

/// What no call writes: an untouched output keeps it.
const SENTINEL: rt2_surface = rt2_surface {
    position: [-7.0; 3],
    normal: [-7.0; 3],
    material: 0xdead,
};

/// `n` rays from a sphere of radius `dist` around `target` towards points within `spread` of
/// it (xorshift, fixed seed).
fn rays(target: Vec3, dist: f32, spread: f32, n: usize) -> Vec<rt2_ray> {
    let seed = 0x2545_f491_4f6c_dd1du64 ^ target.x.to_bits() as u64;
    support::rays_around(target, dist, spread, n, seed)
        .into_iter()
        .map(|(org, dir)| rt2_ray {
            org: org.to_array(),
            tmin: 0.0,
            dir: dir.to_array(),
            tmax: f32::INFINITY,
        })
        .collect()
}

/// Object-space normal of `shape` at `q` (near its surface), not normalised, and how far `q`
/// is from an edge where the normal jumps (infinite where it does not).
fn object_normal(shape: &Shape, prim: u32, q: DVec3) -> (DVec3, f64) {
    match shape {
        Shape::Mesh(p, tris) => {
            let [a, b, c] = tris[prim as usize].map(|i| p[i as usize]);
            ((b - a).cross(c - a), f64::INFINITY)
        }
        Shape::Sphere(c, _) => (q - *c, f64::INFINITY),
        Shape::Ellipsoid(c, r) => ((q - *c) / (*r * *r), f64::INFINITY),
        Shape::Box(lo, hi) => {
            // The face nearest to q; the second nearest says how close an edge is.
            let mut faces: Vec<(f64, DVec3)> = (0..3)
                .flat_map(|a| {
                    let e = DVec3::AXES[a];
                    [((q[a] - lo[a]).abs(), -e), ((q[a] - hi[a]).abs(), e)]
                })
                .collect();
            faces.sort_by(|x, y| x.0.total_cmp(&y.0));
            (faces[0].1, faces[1].0)
        }
        Shape::Plane(n, _) => (*n, f64::INFINITY),
    }
}

/// How far the object-space point `q` lies from `shape`'s surface (the triangle's plane for a
/// mesh), relative to the shape's size (to `q`'s distance from the origin for a plane, whose
/// hits can lie far out).
fn off_surface(shape: &Shape, prim: u32, q: DVec3) -> f64 {
    match shape {
        Shape::Mesh(p, tris) => {
            let [a, b, c] = tris[prim as usize].map(|i| p[i as usize]);
            let n = (b - a).cross(c - a).normalize();
            n.dot(q - a).abs() / (b - a).length()
        }
        Shape::Sphere(c, r) => ((q - *c).length() - r).abs() / r,
        Shape::Ellipsoid(c, r) => ((q - *c) / *r).length() - 1.0,
        Shape::Box(lo, hi) => {
            let d = (0..3)
                .flat_map(|a| [(q[a] - lo[a]).abs(), (q[a] - hi[a]).abs()])
                .fold(f64::INFINITY, f64::min);
            d / (*hi - *lo).max_element()
        }
        Shape::Plane(n, d) => (n.dot(q) - d).abs() / n.length() / (1.0 + q.length()),
    }
    .abs()
}

/// Tolerances: positions are f32 (a few ULPs of coordinates about 10 here, 1e-6; relative to
/// the origin's and the hit's distance, which a plane's hits can take far), normals
/// are f32 products of a few terms (1e-6 measured); both kept well above that and well below
/// what a wrong normal (another face, a transform by the matrix instead of its inverse
/// transpose: 0.1 and more) or a wrong point (swapped barycentrics: the triangle's size)
/// would give.
const POSITION_TOL: f64 = 1e-4;
const NORMAL_TOL: f64 = 1e-4;
/// Relative distance from the surface: f32 rounding of a point recomputed on it.
const SURFACE_TOL: f64 = 1e-5;

/// Checks every surface against the reference of the object its hit names; returns how many
/// hits were compared (rays near a box edge are left out: either face is right there).
fn check(scene: &Scene, rays: &[rt2_ray], hits: &[rt2_hit], out: &[rt2_surface]) -> usize {
    let mut compared = 0;
    for ((r, h), s) in rays.iter().zip(hits).zip(out) {
        if h.object == RT2_INVALID_ID {
            assert_eq!(*s, no_surface(), "a miss");
            continue;
        }
        let obj = &scene.objects[h.object as usize];
        let on_ray = Vec3::from(r.org).as_dvec3() + h.t as f64 * Vec3::from(r.dir).as_dvec3();
        let p = Vec3::from(s.position).as_dvec3();
        let inv = obj.transform.inverse();
        let (q, q_ray) = (inv.transform_point3(p), inv.transform_point3(on_ray));
        let (n_obj, edge) = object_normal(&obj.shape, h.prim, q_ray);
        if edge < 1e-3 {
            continue;
        }
        compared += 1;
        let what = format!("object {} prim {} ray {r:?}", h.object, h.prim);
        assert_eq!(s.material, obj.material, "{what}");
        let org = Vec3::from(r.org).as_dvec3();
        let tol = POSITION_TOL * (org.length() + (on_ray - org).length());
        assert!(
            (p - on_ray).length() < tol,
            "{what}: {p} against org + t dir {on_ray}"
        );
        let off = off_surface(&obj.shape, h.prim, q);
        assert!(off < SURFACE_TOL, "{what}: {p} is {off:e} off the surface");
        let inverse_transpose = inv.matrix3.transpose();
        let want = (inverse_transpose * n_obj).normalize();
        let n = Vec3::from(s.normal).as_dvec3();
        assert!(
            (n - want).length() < NORMAL_TOL,
            "{what}: normal {n} against {want}"
        );
        if let Shape::Mesh(pos, tris) = &obj.shape {
            // The hit's own barycentrics on the corners as given, placed.
            let [a, b, c] =
                tris[h.prim as usize].map(|i| obj.transform.transform_point3(pos[i as usize]));
            let bary = a + h.u as f64 * (b - a) + h.v as f64 * (c - a);
            assert!(
                (p - bary).length() < tol,
                "{what}: {p} against u, v: {bary}"
            );
        }
    }
    compared
}

fn no_surface() -> rt2_surface {
    rt2_surface {
        position: [0.0; 3],
        normal: [0.0; 3],
        material: RT2_INVALID_ID,
    }
}

/// A tetrahedron's corners and its four faces, wound outward.
fn tetrahedron() -> Shape {
    let p = [
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.0, 0.0, 1.0],
    ];
    let faces = vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]];
    Shape::Mesh(p.iter().map(|v| DVec3::from_array(*v)).collect(), faces)
}

/// A rotation about a tilted axis, a non-uniform scale and a translation.
fn general(scale: Vec3, at: Vec3) -> Affine3A {
    Affine3A::from_scale_rotation_translation(
        scale,
        Quat::from_axis_angle(Vec3::new(1.0, 1.0, 0.3).normalize(), 0.7),
        at,
    )
}

/// Traces rays from `dist` away at each object's `target` and checks the surfaces of their
/// hits; each object must be hit at least `min` times, and some rays must miss.
fn trace_and_check(scene: &Scene, targets: &[(u32, Vec3, f32)], dist: f32, min: usize) {
    for &(id, target, spread) in targets {
        let rays = rays(target, dist, spread, 2000);
        let hits = scene.intersect(&rays);
        let (st, out) = scene.surfaces(&rays, &hits);
        assert_eq!(st, Rt2Status::Ok, "{}", last_error());
        check(scene, &rays, &hits, &out);
        let on_it = hits.iter().filter(|h| h.object == id).count();
        let misses = hits.iter().filter(|h| h.object == RT2_INVALID_ID).count();
        assert!(on_it >= min, "object {id}: only {on_it} hits");
        assert!(misses > 0, "object {id}: no miss among the rays");
    }
}

#[test]
fn a_mesh_hit_has_its_triangles_normal_also_when_placed_mirrored() {
    let mut scene = Scene::new();
    let plain = scene.add(
        tetrahedron(),
        Affine3A::from_translation(Vec3::new(-4.0, 0.0, 0.0)),
    );
    // A negative determinant: the library stores these triangles with two corners swapped.
    let mirrored = general(Vec3::new(-1.3, 0.8, 1.1), Vec3::new(4.0, 1.0, -1.0));
    assert!(mirrored.matrix3.determinant() < 0.0);
    let mirror = scene.add(tetrahedron(), mirrored);
    scene.commit();
    let c = Vec3::splat(0.25);
    trace_and_check(
        &scene,
        &[
            (plain, Vec3::new(-4.0, 0.0, 0.0) + c, 0.8),
            (mirror, mirrored.transform_point3(c), 0.8),
        ],
        6.0,
        500,
    );
}

/// Triangles far from unit size: `e1 × e2` squared (its length) underflows for edges below
/// about 1e-10 and overflows above about 1e10, though such triangles are hit.
#[test]
fn tiny_and_huge_triangles_have_unit_normals() {
    for s in [1e-12f32, 1e11] {
        let mut scene = Scene::new();
        let id = scene.add(tetrahedron(), Affine3A::from_scale(Vec3::splat(s)));
        scene.commit();
        trace_and_check(
            &scene,
            &[(id, Vec3::splat(0.25 * s), 0.8 * s)],
            6.0 * s,
            500,
        );
    }
}

#[test]
fn analytic_shapes_have_their_normals_under_rotations_and_non_uniform_scales() {
    let mut scene = Scene::new();
    let sphere = scene.add(
        Shape::Sphere(DVec3::new(0.2, 0.1, -0.1), 0.9),
        Affine3A::IDENTITY,
    );
    let stretched_at = Vec3::new(5.0, 0.0, 0.0);
    let stretched = general(Vec3::new(1.5, 0.6, 1.1), stretched_at);
    let sphere_stretched = scene.add(Shape::Sphere(DVec3::ZERO, 0.8), stretched);
    let ellipsoid_at = Vec3::new(-5.0, 0.0, 0.0);
    let ellipsoid = scene.add(
        Shape::Ellipsoid(DVec3::new(0.1, 0.0, 0.2), DVec3::new(1.2, 0.4, 0.7)),
        general(Vec3::new(0.7, 1.6, 1.2), ellipsoid_at),
    );
    // A quarter turn about z (exact), a non-uniform scale and a translation: a box stays
    // axis-aligned, its faces swap axes.
    let box_at = Vec3::new(0.0, 5.0, 0.0);
    let turn = glam::Mat3::from_cols(
        Vec3::new(0.0, 2.0, 0.0),
        Vec3::new(-0.5, 0.0, 0.0),
        Vec3::new(0.0, 0.0, 1.5),
    );
    let boxed = scene.add(
        Shape::Box(DVec3::new(-1.0, -0.5, -0.4), DVec3::new(0.6, 1.0, 0.5)),
        Affine3A::from_mat3_translation(turn, box_at),
    );
    scene.commit();
    trace_and_check(
        &scene,
        &[
            (sphere, Vec3::ZERO, 1.5),
            (sphere_stretched, stretched_at, 1.5),
            (ellipsoid, ellipsoid_at, 1.5),
            (boxed, box_at, 1.5),
        ],
        6.0,
        300,
    );
    // A plane alone: it would catch the other objects' misses.
    let mut scene = Scene::new();
    let plane = scene.add(
        Shape::Plane(DVec3::new(0.3, 2.0, -0.4), 1.0),
        general(Vec3::new(1.0, 2.5, 0.5), Vec3::new(0.0, -4.0, 1.0)),
    );
    scene.commit();
    trace_and_check(&scene, &[(plane, Vec3::new(0.0, -4.0, 1.0), 1.5)], 6.0, 300);
}

#[test]
fn a_loaded_file_has_the_normals_of_its_faces() {
    // A quad (fan-triangulated by the loader into triangles 0 and 1) and a triangle, not
    // coplanar, with a negative index.
    let obj = "v 0 0 0\nv 2 0 0\nv 2 1.5 0.5\nv 0 1 0\nv 1 0.5 2\n\
               f 1 2 3 4\nf 2 -1 3\n";
    let path = support::scratch("surfaces").join("quad_and_triangle.obj");
    std::fs::write(&path, obj).unwrap();
    let c_path = std::ffi::CString::new(path.to_str().unwrap()).unwrap();
    let mut scene = Scene::new();
    let (mut material, mut id) = (0, 0);
    unsafe {
        let m = rt2_material_default();
        ok(rt2_scene_add_material(scene.scene, &m, &mut material));
        ok(rt2_scene_load_file(
            scene.scene,
            c_path.as_ptr(),
            material,
            &mut id,
        ));
    }
    let v = [
        [0.0, 0.0, 0.0],
        [2.0, 0.0, 0.0],
        [2.0, 1.5, 0.5],
        [0.0, 1.0, 0.0],
        [1.0, 0.5, 2.0],
    ];
    let positions = v.iter().map(|p| DVec3::from_array(*p)).collect();
    // The file's faces, fan-triangulated as the loader documents: (v0, v1, v2), (v0, v2, v3).
    let file = Shape::Mesh(positions, vec![[0, 1, 2], [0, 2, 3], [1, 4, 2]]);
    scene.register(id, file, Affine3A::IDENTITY, material);
    scene.commit();
    let rays = rays(Vec3::new(1.0, 0.6, 0.5), 6.0, 1.2, 3000);
    let hits = scene.intersect(&rays);
    let (st, out) = scene.surfaces(&rays, &hits);
    assert_eq!(st, Rt2Status::Ok, "{}", last_error());
    assert!(check(&scene, &rays, &hits, &out) > 500);
    for prim in 0..3 {
        assert!(
            hits.iter().any(|h| h.prim == prim),
            "no hit on triangle {prim}"
        );
    }
}

/// Shapes placed at the edge of f32 (translation z = f32::MAX) and rays from the origin with
/// directions 1e36 long: the last bit of the query's `t` moves `org + t·dir` by 1e31, so the
/// line's offset from the shape is lost to rounding. A helper's stateful fuzz found
/// `rt2_hit_surfaces` refusing such a hit that `rt2_intersect` had just returned (the first
/// case is its repro). Each must be answered: a unit normal facing the ray, a point within
/// the shape's bounds.
#[test]
fn hits_at_the_edge_of_f32_have_surfaces() {
    let fuzz = Affine3A::from_cols_array(&[
        0.7966295,
        -0.1133584,
        0.5304893,
        0.4595938,
        -0.041391082,
        -0.6990112,
        0.21147762,
        1.673205,
        0.039967988,
        -2.5591354,
        18.555008,
        3.4028235e38,
    ]);
    let far = Vec3::new(0.0, 0.0, f32::MAX);
    let cases = [
        (
            Shape::Sphere(DVec3::new(-11.951399, 12.0179405, 5.9753933), 1.9253507),
            fuzz,
            rt2_ray {
                org: [-3.0267277, 14.098213, -14.826452],
                tmin: 0.5,
                dir: [-0.018959675, 0.1595673, 3.4028233e36],
                tmax: 1e30,
            },
        ),
        (
            Shape::Sphere(DVec3::ZERO, 1.5),
            general(Vec3::new(1.0, 0.5, 2.0), far),
            rt2_ray {
                org: [0.0; 3],
                tmin: 0.0,
                dir: [0.0, 0.0, 3.4028233e36],
                tmax: f32::INFINITY,
            },
        ),
        (
            Shape::Ellipsoid(DVec3::ZERO, DVec3::new(2.0, 1.0, 1.5)),
            general(Vec3::ONE, far),
            rt2_ray {
                org: [0.0; 3],
                tmin: 0.0,
                dir: [1e-38, 0.0, 3.4e36],
                tmax: f32::INFINITY,
            },
        ),
    ];
    for (k, (shape, t, ray)) in cases.into_iter().enumerate() {
        let hits = far_surfaces(shape, t, &[ray]);
        assert_eq!(hits, 1, "case {k}: the ray misses");
    }
    // Direction lengths and offsets across one shape: a review found a quarter of such hits
    // facing away when only the exact cancellation of the first case was handled.
    let mut sweep = vec![];
    for len in [1e30f32, 1e33, 1e35, 2.7583652e36, 3.4028233e36] {
        for k in 0..49 {
            let (x, y) = ((k % 7) as f32 / 4.0 - 0.75, (k / 7) as f32 / 4.0 - 0.75);
            sweep.push(rt2_ray {
                org: [x, y, 0.0],
                tmin: 0.0,
                dir: [0.0, 0.0, len],
                tmax: f32::INFINITY,
            });
        }
    }
    let swept = Shape::Sphere(DVec3::ZERO, 1.5);
    let hits = far_surfaces(swept, general(Vec3::new(1.0, 0.5, 2.0), far), &sweep);
    assert!(
        hits >= sweep.len() / 4,
        "only {hits} of {} hit",
        sweep.len()
    );
}

/// Adds `shape` placed by `t` to a scene of its own and traces `rays`: every hit must get a
/// surface with a unit normal facing the ray (all start outside) and a point within the
/// placed shape's bounds. Returns the number of hits.
fn far_surfaces(shape: Shape, t: Affine3A, rays: &[rt2_ray]) -> usize {
    let (centre, radius) = match shape {
        Shape::Sphere(c, r) => (c, r),
        Shape::Ellipsoid(c, r) => (c, r.max_element()),
        _ => unreachable!("spheres and ellipsoids only"),
    };
    let mut scene = Scene::new();
    scene.add(shape, t);
    scene.commit();
    let hits = scene.intersect(rays);
    let (st, out) = scene.surfaces(rays, &hits);
    assert_eq!(st, Rt2Status::Ok, "{}", last_error());
    // The bounds: the centre, plus the transform's largest stretch of the radius, plus the
    // rounding of coordinates near f32::MAX.
    let c = t.transform_point3(centre.as_vec3());
    let stretch: f32 = t.matrix3.to_cols_array().iter().map(|x| x.abs()).sum();
    let slack = Vec3::splat(radius as f32 * stretch) + c.abs() * f32::EPSILON;
    let mut count = 0;
    for ((ray, hit), surface) in rays.iter().zip(&hits).zip(&out) {
        if hit.object == RT2_INVALID_ID {
            continue;
        }
        count += 1;
        let (p, n) = (Vec3::from(surface.position), Vec3::from(surface.normal));
        assert!((n.length() - 1.0).abs() < 1e-6, "{ray:?}: normal {n}");
        assert!(
            n.dot(Vec3::from(ray.dir)) < 0.0,
            "{ray:?}: normal {n} faces away"
        );
        assert!(
            p.is_finite() && (p - c).abs().cmple(slack).all(),
            "{ray:?}: position {p} outside {c} ± {slack}"
        );
    }
    count
}

/// From far away, `org + t * dir` in f32 is off the surface by about an ULP of the distance
/// times the direction: the positions are recomputed on the primitive, far closer. (Checked to
/// be discriminating: the ray's own point is asserted to be further off.)
#[test]
fn positions_lie_on_the_surface_not_on_the_ray() {
    let mut scene = Scene::new();
    let tri = Shape::Mesh(
        vec![
            DVec3::new(-1.0, -1.0, 0.3),
            DVec3::new(1.5, -1.0, -0.2),
            DVec3::new(0.0, 1.2, 0.1),
        ],
        vec![[0, 1, 2]],
    );
    let mesh = scene.add(tri, Affine3A::IDENTITY);
    let sphere = scene.add(
        Shape::Sphere(DVec3::ZERO, 1.0),
        Affine3A::from_translation(Vec3::new(4.0, 0.0, 0.0)),
    );
    scene.commit();
    for (id, target) in [(mesh, Vec3::ZERO), (sphere, Vec3::new(4.0, 0.0, 0.0))] {
        let rays = rays(target, 3e4, 0.6, 500);
        let hits = scene.intersect(&rays);
        let (st, out) = scene.surfaces(&rays, &hits);
        assert_eq!(st, Rt2Status::Ok, "{}", last_error());
        let obj = &scene.objects[id as usize];
        let inv = obj.transform.inverse();
        let (mut worst_surface, mut worst_ray, mut n) = (0.0f64, 0.0f64, 0);
        for ((r, h), s) in rays.iter().zip(&hits).zip(&out) {
            if h.object != id {
                continue;
            }
            n += 1;
            let on_ray = Vec3::from(r.org) + h.t * Vec3::from(r.dir);
            let off = |p: Vec3| off_surface(&obj.shape, h.prim, inv.transform_point3(p.as_dvec3()));
            worst_surface = worst_surface.max(off(Vec3::from(s.position)));
            worst_ray = worst_ray.max(off(on_ray));
        }
        assert!(n > 100, "object {id}: {n} hits");
        assert!(
            worst_surface < SURFACE_TOL,
            "object {id}: {worst_surface:e} off the surface"
        );
        assert!(
            worst_ray > 10.0 * worst_surface,
            "object {id}: org + t dir is {worst_ray:e} off, no worse"
        );
    }
}

#[test]
fn misses_get_the_no_surface_record_and_count_zero_is_fine() {
    let mut scene = Scene::new();
    scene.add(Shape::Sphere(DVec3::ZERO, 1.0), Affine3A::IDENTITY);
    scene.commit();
    let away = rt2_ray {
        org: [0.0, 0.0, 5.0],
        tmin: 0.0,
        dir: [0.0, 0.0, 1.0],
        tmax: f32::INFINITY,
    };
    let hits = scene.intersect(&[away, away]);
    assert_eq!(hits[0].object, RT2_INVALID_ID);
    let (st, out) = scene.surfaces(&[away, away], &hits);
    assert_eq!(st, Rt2Status::Ok, "{}", last_error());
    assert_eq!(out, vec![no_surface(); 2]);
    // Misses alone need no lookup: none is built.
    assert_eq!(scene.lookup_bytes(), 0);
    unsafe {
        let st = rt2_hit_surfaces(scene.scene, null(), null(), 0, null_mut());
        assert_eq!(st, Rt2Status::Ok, "{}", last_error());
    }
}

/// Every bad input is refused with a message naming it, and nothing is written: `out` keeps
/// the sentinel, and a refused first call keeps no lookup.
#[test]
fn bad_input_is_refused_and_writes_nothing() {
    let mut scene = Scene::new();
    let mesh = scene.add(tetrahedron(), Affine3A::IDENTITY);
    let sphere = scene.add(
        Shape::Sphere(DVec3::new(3.0, 0.0, 0.0), 1.0),
        Affine3A::IDENTITY,
    );
    scene.commit();
    let toward = |at: Vec3| rt2_ray {
        org: (at + Vec3::new(0.1, 0.2, 6.0)).to_array(),
        tmin: 0.0,
        dir: [0.0, 0.0, -1.0],
        tmax: f32::INFINITY,
    };
    let rays = [
        toward(Vec3::splat(0.1)),
        toward(Vec3::new(3.0, 0.0, 0.0)),
        toward(Vec3::new(0.0, 9.0, 0.0)),
    ];
    let hits = scene.intersect(&rays);
    assert_eq!(
        [hits[0].object, hits[1].object, hits[2].object],
        [mesh, sphere, RT2_INVALID_ID]
    );
    let refused = |rays: &[rt2_ray], hits: &[rt2_hit], status: Rt2Status, says: &str| {
        let (st, out) = scene.surfaces(rays, hits);
        let message = last_error();
        assert_eq!(st, status, "{says}: {message}");
        assert!(message.contains(says), "{message} (expected {says})");
        assert!(out.iter().all(|s| *s == SENTINEL), "{says}: written");
    };
    let with = |i: usize, h: rt2_hit| {
        let mut hs = hits.clone();
        hs[i] = h;
        hs
    };
    let bad = Rt2Status::InvalidArgument;
    // Ids the scene lacks, the bad one last so that the good ones come first.
    for (object, prim) in [
        (2, 0),
        (mesh, 4),
        (sphere, 1),
        (RT2_INVALID_ID, 0),
        (mesh, RT2_INVALID_ID),
    ] {
        let hs = with(
            2,
            rt2_hit {
                object,
                prim,
                ..hits[0]
            },
        );
        refused(
            &rays,
            &hs,
            bad,
            &format!("hits[2] names object {object} primitive {prim}"),
        );
    }
    assert_eq!(scene.lookup_bytes(), 0, "a refused call keeps no lookup");
    for h in [
        rt2_hit {
            t: f32::NAN,
            ..hits[1]
        },
        rt2_hit {
            t: f32::INFINITY,
            ..hits[1]
        },
        rt2_hit {
            u: f32::NAN,
            ..hits[0]
        },
    ] {
        refused(&rays, &with(2, h), bad, "hits[2] has t");
    }
    // Barycentrics off the triangle name a point off it (u = 2, v = 3 got one, extrapolated);
    // a sphere's u and v are not read.
    for (u, v) in [(2.0, 3.0), (-0.01, 0.5), (0.5, -0.01), (0.6, 0.41)] {
        let h = rt2_hit { u, v, ..hits[0] };
        refused(&rays, &with(2, h), bad, "on a triangle");
    }
    let corner_edge_sphere = [
        rt2_hit {
            u: 1.0,
            v: 0.0,
            ..hits[0]
        },
        rt2_hit {
            u: 0.5,
            v: 0.5,
            ..hits[0]
        },
        rt2_hit {
            u: 7.0,
            v: 7.0,
            ..hits[1]
        },
    ];
    let (st, _) = scene.surfaces(&[rays[0], rays[0], rays[1]], &corner_edge_sphere);
    assert_eq!(st, Rt2Status::Ok, "{}", last_error());
    // Rays that always miss cannot have given a hit (a zero direction gave a zero normal).
    let mut far = rays;
    far[1].org[0] = f32::INFINITY;
    let mut zero = rays;
    zero[1].dir = [0.0; 3];
    let mut empty = rays;
    (empty[1].tmin, empty[1].tmax) = (1.0, 0.5);
    for rays in [far, zero, empty] {
        refused(&rays, &hits, bad, "rays[1] has org");
    }
    // A point 3e38 along a ray through the sphere's centre: the root nearest it is lost to
    // rounding, so it has no point on the surface and no normal (it got a zero one).
    let mut through = rays;
    through[1].org = [3.0, 0.0, 6.0];
    let lost = rt2_hit { t: 3e38, ..hits[1] };
    refused(&through, &with(1, lost), bad, "hits[1] at t = 3e38");
    let ok_now = scene.surfaces(&rays, &hits);
    assert_eq!(ok_now.0, Rt2Status::Ok, "{}", last_error());
    // Kept once a call succeeds, of the size the header gives: 4 bytes for each of the 5
    // primitives (the tetrahedron's 4 triangles and the sphere) and a `size_t` for each of the
    // 2 object ids and one more.
    let size_t = std::mem::size_of::<usize>() as u64;
    assert_eq!(scene.lookup_bytes(), 4 * 5 + size_t * (2 + 1));

    let mut out = [SENTINEL; 3];
    let o = out.as_mut_ptr();
    let untouched = |out: &[rt2_surface]| assert!(out.iter().all(|s| *s == SENTINEL));
    unsafe {
        let (r, h, s) = (
            rays.as_ptr(),
            hits.as_ptr(),
            scene.scene as *const rt2_scene,
        );
        let calls: [(&dyn Fn() -> Rt2Status, &str); 5] = [
            (&|| rt2_hit_surfaces(s, null(), h, 3, o), "rays is NULL"),
            (&|| rt2_hit_surfaces(s, r, null(), 3, o), "hits is NULL"),
            (
                &|| rt2_hit_surfaces(s, r, h, 3, null_mut()),
                "surfaces is NULL",
            ),
            (&|| rt2_hit_surfaces(null(), r, h, 3, o), "scene is NULL"),
            (
                &|| rt2_hit_surfaces(scene.ctx.cast(), r, h, 3, o),
                "not a live rt2_scene",
            ),
        ];
        for (call, says) in calls {
            assert_eq!(call(), bad, "{says}: {}", last_error());
            let message = last_error();
            assert!(message.contains(says), "{message} (expected {says})");
            untouched(&out);
        }
        // The output over the inputs: refused, the inputs intact.
        let mut buffer = vec![0u64; 64];
        let b = buffer.as_mut_ptr().cast::<u8>();
        b.cast::<rt2_ray>()
            .copy_from_nonoverlapping(rays.as_ptr(), 3);
        let (aliased_rays, aliased_out) = (b.cast::<rt2_ray>(), b.add(32).cast::<rt2_surface>());
        let st = rt2_hit_surfaces(scene.scene, aliased_rays, hits.as_ptr(), 3, aliased_out);
        assert_eq!(st, bad);
        assert!(
            last_error().contains("surfaces overlaps rays"),
            "{}",
            last_error()
        );
        assert_eq!(std::slice::from_raw_parts(aliased_rays, 3), &rays);
        let mut hits_copy = hits.clone();
        let h = hits_copy.as_mut_ptr();
        let st = rt2_hit_surfaces(scene.scene, rays.as_ptr(), h, 3, h.cast::<rt2_surface>());
        assert_eq!(st, bad);
        assert!(
            last_error().contains("surfaces overlaps hits"),
            "{}",
            last_error()
        );
        assert_eq!(hits_copy, hits);

        // An edit since the commit: the scene's state is refused, as by queries.
        let c = [0.0f32, 9.0, 0.0];
        ok(rt2_scene_add_sphere(
            scene.scene,
            c.as_ptr(),
            1.0,
            0,
            null_mut(),
        ));
        let st = rt2_hit_surfaces(scene.scene, rays.as_ptr(), hits.as_ptr(), 3, o);
        assert_eq!(st, Rt2Status::InvalidOperation, "{}", last_error());
        untouched(&out);
        let st = rt2_hit_surfaces(scene.scene, null(), null(), 0, null_mut());
        assert_eq!(
            st,
            Rt2Status::InvalidOperation,
            "count 0 still checks the scene"
        );
    }
}

#[test]
fn a_scene_never_committed_is_refused() {
    let scene = Scene::new();
    unsafe {
        let st = rt2_hit_surfaces(scene.scene, null(), null(), 0, null_mut());
        assert_eq!(st, Rt2Status::InvalidOperation, "{}", last_error());
        assert!(last_error().contains("never committed"), "{}", last_error());
    }
}

/// A hit on an object disabled since (`rt2_scene_set_enabled` + commit) is no hit of the
/// current commit: refused, naming the object, and nothing written. Enabled again, the same
/// hits give the same surfaces as before.
#[test]
fn hits_on_a_disabled_object_are_refused_until_it_is_enabled_again() {
    let mut scene = Scene::new();
    scene.add(tetrahedron(), Affine3A::IDENTITY);
    let sphere = scene.add(
        Shape::Sphere(DVec3::new(3.0, 0.0, 0.0), 1.0),
        Affine3A::IDENTITY,
    );
    scene.commit();
    let all = rays(Vec3::new(3.0, 0.0, 0.0), 6.0, 0.5, 32);
    let (rays, hits): (Vec<rt2_ray>, Vec<rt2_hit>) = all
        .iter()
        .zip(scene.intersect(&all))
        .filter(|(_, h)| h.object == sphere)
        .unzip();
    assert!(rays.len() >= 16, "{} of 32 rays hit the sphere", rays.len());
    let (st, before) = scene.surfaces(&rays, &hits);
    assert_eq!(st, Rt2Status::Ok, "{}", last_error());
    assert_eq!(check(&scene, &rays, &hits, &before), rays.len());
    let enable = |on: u32| unsafe {
        ok(rt2_scene_set_enabled(scene.scene, sphere, on));
        scene.commit();
    };
    enable(0);
    let (st, out) = scene.surfaces(&rays, &hits);
    let message = last_error();
    assert_eq!(st, Rt2Status::InvalidArgument, "{message}");
    assert!(
        message.contains(&format!(
            "hits[0] names object {sphere} primitive 0, whose object is disabled"
        )),
        "{message}"
    );
    assert!(out.iter().all(|s| *s == SENTINEL), "written: {out:?}");
    enable(1);
    let (st, after) = scene.surfaces(&rays, &hits);
    assert_eq!(st, Rt2Status::Ok, "{}", last_error());
    assert_eq!(after, before);
}
