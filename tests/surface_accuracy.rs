//! `rt2_hit_surfaces` where precision is at stake, against f64 references (a review's cases,
//! beyond `tests/surfaces.rs`): ellipsoids and triangles far from unit size, slivers, spheres
//! and ellipsoids far from the origin, thin ellipsoids and boxes (the sheet or face the ray
//! meets), box edges and corners, directions far from unit length, every traversal and mode,
//! GPU hits, planes met beyond the f32 range, and commits racing the call.

use glam::{DVec3, Vec3};
use rt2::api::*;
use rt2::error::Rt2Status;
use std::ptr::{null, null_mut};

mod support;
use support::{last_error, ok};

/// What no call writes: an output left untouched keeps it.
const SENTINEL: rt2_surface = rt2_surface {
    position: [-7.0; 3],
    normal: [-7.0; 3],
    material: 0xdead,
};

struct S {
    ctx: *mut rt2_context,
    scene: *mut rt2_scene,
}
impl Drop for S {
    fn drop(&mut self) {
        unsafe {
            rt2_scene_destroy(self.scene);
            rt2_context_destroy(self.ctx);
        }
    }
}
fn new(backend: Rt2Backend) -> S {
    let (mut ctx, mut scene) = (null_mut(), null_mut());
    let mut d = rt2_context_desc_default();
    d.backend = backend as u32;
    unsafe {
        ok(rt2_context_create(&d, &mut ctx));
        ok(rt2_scene_create(ctx, &mut scene));
    }
    S { ctx, scene }
}
fn ray(o: [f32; 3], d: [f32; 3]) -> rt2_ray {
    rt2_ray {
        org: o,
        tmin: 0.0,
        dir: d,
        tmax: f32::INFINITY,
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
impl S {
    fn commit(&self) {
        unsafe { ok(rt2_scene_commit(self.scene)) }
    }
    fn hits(&self, rays: &[rt2_ray], opt: Option<&rt2_query_options>) -> Vec<rt2_hit> {
        let mut h = vec![miss(); rays.len()];
        unsafe {
            ok(rt2_intersect(
                self.ctx,
                self.scene,
                rays.as_ptr(),
                rays.len(),
                h.as_mut_ptr(),
                opt.map_or(null(), |o| o as *const _),
                null_mut(),
            ))
        };
        h
    }
    fn surf(&self, rays: &[rt2_ray], hits: &[rt2_hit]) -> Vec<rt2_surface> {
        let mut out = vec![SENTINEL; rays.len()];
        unsafe {
            ok(rt2_hit_surfaces(
                self.scene,
                rays.as_ptr(),
                hits.as_ptr(),
                rays.len(),
                out.as_mut_ptr(),
            ))
        };
        out
    }
}
fn mat(s: &S) -> u32 {
    let mut m = 0;
    unsafe {
        ok(rt2_scene_add_material(
            s.scene,
            &rt2_material_default(),
            &mut m,
        ))
    };
    m
}

/// Ellipsoids far from unit size: the normal inv^T inv (p - c) is ~1/size long; squared it
/// overflows below ~5e-20 and underflows above ~3e22 (the same as the triangle fix). Those
/// within the header's limits (semi-axes from about 2.7e-23 to 1.8e19) are accepted and get
/// the right normal; those outside are refused.
#[test]
fn ellipsoid_normals_far_from_unit_size() {
    let mut bad = vec![];
    for (radii, name, accepted) in [
        ([1e-20f32, 1e-20, 1e-20], "tiny", true),
        ([1.0, 1.0, 1e-20], "thin", true),
        ([1e-19, 1e-19, 1e-19], "tiny19", true),
        ([1e-10, 1e-10, 1e-10], "small", true),
        ([1e19, 1e19, 1e19], "large", true),
        ([1e20, 1e20, 1e20], "past the upper limit", false),
        ([1e22, 1e22, 1e22], "huge22", false),
        ([1e25, 1e25, 1e25], "huge", false),
        ([1e-30, 1e-30, 1e-30], "tiny30", false),
        ([1.0, 1e-25, 1.0], "thin25", false),
    ] {
        let s = new(Rt2Backend::Cpu);
        let m = mat(&s);
        let mut id = 0;
        let st = unsafe {
            rt2_scene_add_ellipsoid(s.scene, [0.0; 3].as_ptr(), radii.as_ptr(), m, &mut id)
        };
        if !accepted {
            assert_eq!(st, Rt2Status::InvalidArgument, "{name}");
            continue;
        }
        assert_eq!(st, Rt2Status::Ok, "{name}: {}", last_error());
        s.commit();
        let r = [ray([0.0, 0.0, 5.0 * radii[2]], [0.0, 0.0, -1.0])];
        let h = s.hits(&r, None);
        assert_eq!(h[0].object, id, "{name}: no hit");
        let o = s.surf(&r, &h);
        let n = Vec3::from(o[0].normal);
        if (n - Vec3::Z).length() > 1e-5 {
            bad.push((name, o[0]));
        }
    }
    assert!(bad.is_empty(), "{bad:?}");
}

/// Directions far from unit length: the query scales them by a power of two and scales t
/// back; the surface from the caller's ray and returned t must be the unit-direction one.
#[test]
fn surfaces_of_rays_with_long_and_short_directions() {
    let s = new(Rt2Backend::Cpu);
    let m = mat(&s);
    let mut ids = [0u32; 5];
    unsafe {
        let p: [f32; 9] = [-1.0, -1.0, 0.0, 1.0, -1.0, 0.0, 0.0, 1.0, 0.0];
        ok(rt2_scene_add_mesh(
            s.scene,
            p.as_ptr(),
            3,
            [0u32, 1, 2].as_ptr(),
            1,
            m,
            &mut ids[0],
        ));
        ok(rt2_scene_add_sphere(
            s.scene,
            [5.0, 0.0, 0.0].as_ptr(),
            1.0,
            m,
            &mut ids[1],
        ));
        ok(rt2_scene_add_ellipsoid(
            s.scene,
            [10.0, 0.0, 0.0].as_ptr(),
            [1.0, 0.5, 0.25].as_ptr(),
            m,
            &mut ids[2],
        ));
        ok(rt2_scene_add_box(
            s.scene,
            [14.0, -1.0, -1.0].as_ptr(),
            [16.0, 1.0, 1.0].as_ptr(),
            m,
            &mut ids[3],
        ));
        ok(rt2_scene_add_plane(
            s.scene,
            [0.0, 0.0, 1.0].as_ptr(),
            -5.0,
            m,
            &mut ids[4],
        ));
    }
    s.commit();
    let targets = [
        [0.1f32, 0.2, 0.0],
        [5.3, 0.2, 0.0],
        [10.2, 0.1, 0.0],
        [15.2, 0.3, 0.0],
        [30.0, 0.0, -5.0],
    ];
    let mut bad = vec![];
    let mut n = 0;
    for (k, tg) in targets.iter().enumerate() {
        let org = [tg[0] + 0.37, tg[1] - 0.21, 20.0];
        let d0 = Vec3::from(*tg) - Vec3::from(org);
        let base = [ray(org, d0.to_array())];
        let hb = s.hits(&base, None);
        assert_eq!(hb[0].object, ids[k], "target {k}");
        let sb = s.surf(&base, &hb)[0];
        for sc in [1e-38f32, 1e-30, 1e-20, 1e-5, 1e5, 1e20, 1e30, 1e36] {
            for tmin in [0.0f32, -1.0] {
                let mut r = base[0];
                r.dir = (d0 * sc).to_array();
                r.tmin = tmin / sc;
                let h = s.hits(&[r], None);
                n += 1;
                if h[0].object != ids[k] {
                    bad.push(format!("target {k} scale {sc:e}: hit {:?}", h[0]));
                    continue;
                }
                let o = s.surf(&[r], &h)[0];
                let dp = (Vec3::from(o.position) - Vec3::from(sb.position)).length();
                let dn = (Vec3::from(o.normal) - Vec3::from(sb.normal)).length();
                if dp > 1e-5 * 20.0 || dn > 1e-5 {
                    bad.push(format!(
                        "target {k} scale {sc:e} tmin {tmin}: {o:?} vs {sb:?} (t {} vs {})",
                        h[0].t, hb[0].t
                    ));
                }
            }
        }
    }
    assert!(bad.is_empty(), "{n} rays:\n{}", bad.join("\n"));
}

/// Adds a wavy grid of `n` × `n` quads (two triangles each) of material `m`, placed by a
/// mirroring, rotating, non-uniformly scaling transform.
fn wavy_grid(s: &S, m: u32, n: u32) {
    let (mut pos, mut idx) = (vec![], vec![]);
    for i in 0..=n {
        for j in 0..=n {
            let (x, y) = (
                i as f32 / n as f32 * 2.0 - 1.0,
                j as f32 / n as f32 * 2.0 - 1.0,
            );
            pos.extend([x, y, 0.3 * (3.0 * x).sin() * (2.0 * y).cos()]);
        }
    }
    for i in 0..n {
        for j in 0..n {
            let a = i * (n + 1) + j;
            idx.extend([a, a + 1, a + n + 2, a, a + n + 2, a + n + 1]);
        }
    }
    let mut id = 0;
    let t: [f32; 12] = [
        -0.8, 0.3, 0.0, 0.2, 0.1, 1.5, 0.2, -0.1, 0.0, 0.2, 0.6, 0.05,
    ];
    unsafe {
        ok(rt2_scene_add_mesh(
            s.scene,
            pos.as_ptr(),
            pos.len() / 3,
            idx.as_ptr(),
            idx.len() / 3,
            m,
            &mut id,
        ));
        ok(rt2_scene_set_transform(s.scene, id, t.as_ptr()));
    }
}

/// 4096 rays down from the square `[-2, 2]²` at height 5, their directions leaning up to
/// `lean` in x and y (a xorshift sequence seeded by `seed`).
fn downward_rays(seed: u64, lean: f32) -> Vec<rt2_ray> {
    let mut uniform = support::uniform(seed);
    let mut next = move || uniform() as f32;
    (0..4096)
        .map(|_| {
            ray(
                [next() * 2.0, next() * 2.0, 5.0],
                [next() * lean, next() * lean, -1.0],
            )
        })
        .collect()
}

/// Every traversal and mode: the same surfaces.
#[test]
fn every_traversal_and_mode_same_surfaces() {
    let s = new(Rt2Backend::Cpu);
    let m = mat(&s);
    wavy_grid(&s, m, 24);
    s.commit();
    let rays = downward_rays(0x1234_5678_9abc_def1u64, 0.3);
    let base = s.hits(&rays, None);
    let sb = s.surf(&rays, &base);
    let hits = base.iter().filter(|h| h.object != RT2_INVALID_ID).count();
    assert!(hits > 1000, "{hits}");
    let mut bad = vec![];
    for mode in [
        Rt2QueryMode::Single as u32,
        Rt2QueryMode::Packet as u32,
        Rt2QueryMode::Stream as u32,
    ] {
        for trav in 0..8u32 {
            let mut o = rt2_query_options_default();
            o.mode = mode;
            o.traversal = trav;
            for isect in 0..2u32 {
                o.intersector = isect;
                let mut h = vec![miss(); rays.len()];
                let st = unsafe {
                    rt2_intersect(
                        s.ctx,
                        s.scene,
                        rays.as_ptr(),
                        rays.len(),
                        h.as_mut_ptr(),
                        &o,
                        null_mut(),
                    )
                };
                assert_eq!(
                    st,
                    Rt2Status::Ok,
                    "mode {mode} traversal {trav} intersector {isect}: {}",
                    last_error()
                );
                let sf = s.surf(&rays, &h);
                let diff = sf
                    .iter()
                    .zip(&sb)
                    .filter(|(a, b)| {
                        (Vec3::from(a.position) - Vec3::from(b.position)).length() > 1e-5
                            || (Vec3::from(a.normal) - Vec3::from(b.normal)).length() > 1e-5
                            || a.material != b.material
                    })
                    .count();
                if diff > 0 {
                    bad.push((mode, trav, isect, diff));
                }
            }
        }
    }
    assert!(bad.is_empty(), "{bad:?}");
}

/// GPU hits (lavapipe): the same surfaces as the CPU's hits, for every traversal (AUTO and the
/// seven), on a mirrored mesh and analytic shapes; the GPU's hits name the CPU's primitive on
/// all but a few rays (ties on shared edges).
#[test]
fn gpu_hits_give_the_cpu_surfaces() {
    if !support::c_gpu_or_skip() {
        return;
    }
    let build = |b: Rt2Backend| {
        let s = new(b);
        let m = mat(&s);
        wavy_grid(&s, m, 16);
        unsafe {
            let mut id = 0;
            ok(rt2_scene_add_sphere(
                s.scene,
                [1.5, 1.0, 0.5].as_ptr(),
                0.4,
                m,
                &mut id,
            ));
            ok(rt2_scene_add_ellipsoid(
                s.scene,
                [-1.5, 1.0, 0.5].as_ptr(),
                [0.6, 0.3, 0.1].as_ptr(),
                m,
                &mut id,
            ));
            ok(rt2_scene_add_box(
                s.scene,
                [-1.5, -1.5, 0.0].as_ptr(),
                [-1.0, -1.0, 0.5].as_ptr(),
                m,
                &mut id,
            ));
            ok(rt2_scene_add_plane(
                s.scene,
                [0.0, 0.0, 1.0].as_ptr(),
                -1.0,
                m,
                &mut id,
            ));
        }
        s.commit();
        s
    };
    let (c, g) = (build(Rt2Backend::Cpu), build(Rt2Backend::Gpu));
    let rays = downward_rays(0x9876_5432_1abc_def1u64, 0.5);
    let hc = c.hits(&rays, None);
    let sc = c.surf(&rays, &hc);
    let mut bad = vec![];
    for trav in 0..8u32 {
        let mut o = rt2_query_options_default();
        o.traversal = trav;
        let hg = g.hits(&rays, Some(&o));
        // GPU hits looked up in the GPU context's scene and in the CPU one (same scene).
        let sg = g.surf(&rays, &hg);
        let sx = c.surf(&rays, &hg);
        for i in 0..rays.len() {
            let (a, b) = (sg[i], sc[i]);
            if hg[i].object != hc[i].object || hg[i].prim != hc[i].prim {
                continue;
            }
            let dp = (Vec3::from(a.position) - Vec3::from(b.position)).length();
            let dn = (Vec3::from(a.normal) - Vec3::from(b.normal)).length();
            if dp > 1e-4 || dn > 1e-4 || a.material != b.material || sx[i] != sg[i] {
                bad.push(format!(
                    "trav {trav} ray {i}: {:?} {:?} gpu {a:?} cpu {b:?}",
                    hg[i], hc[i]
                ));
            }
        }
        let same = hg
            .iter()
            .zip(&hc)
            .filter(|(a, b)| a.object == b.object && a.prim == b.prim)
            .count();
        eprintln!(
            "trav {trav}: {same}/{} same ids, {} hits",
            rays.len(),
            hc.iter().filter(|h| h.object != RT2_INVALID_ID).count()
        );
        assert!(
            same * 1000 >= rays.len() * 999,
            "traversal {trav}: the GPU named the CPU's primitive on {same} of {} rays",
            rays.len()
        );
    }
    assert!(bad.is_empty(), "{}", bad[..bad.len().min(10)].join("\n"));
}

/// Slivers (largest angle 1e-4..1e-6 rad from straight, above the 2^-21 the tree drops): the
/// f32 cross product `e1 × e2` cancels; its direction against the f64 one of the same f32
/// corners.
#[test]
fn sliver_normals_against_f64() {
    let mut next = support::uniform(0x5151_2323_abab_0101u64);
    let mut worst = (0.0f64, 0.0f64);
    let mut hist = [0usize; 4];
    let mut count = 0;
    for k in 0..2000 {
        let delta = 10f64.powf(-4.0 - 2.0 * (k as f64 / 2000.0));
        let dir = DVec3::new(next(), next(), next()).normalize();
        let perp = dir.any_orthonormal_vector();
        let perp = (perp * next() + dir.cross(perp) * next()).normalize();
        // a = 0, c = 2 * dir, b = dir + perp * delta: angle at b is pi - ~2 delta.
        let a = DVec3::ZERO;
        let c = (dir * 2.0).as_vec3().as_dvec3();
        let b = (dir + perp * delta).as_vec3().as_dvec3();
        let s = new(Rt2Backend::Cpu);
        let m = mat(&s);
        let mut id = 0;
        let p: Vec<f32> = [a, b, c]
            .iter()
            .flat_map(|v| v.as_vec3().to_array())
            .collect();
        unsafe {
            ok(rt2_scene_add_mesh(
                s.scene,
                p.as_ptr(),
                3,
                [0u32, 1, 2].as_ptr(),
                1,
                m,
                &mut id,
            ))
        };
        s.commit();
        let want = (b - a).cross(c - a);
        let sin = want.length() / ((b - a).length() * (c - b).length());
        let want = want.normalize();
        let centroid = (a + b + c) / 3.0;
        let r = [ray(
            (centroid + want * 3.0).as_vec3().to_array(),
            (-want).as_vec3().to_array(),
        )];
        let h = s.hits(&r, None);
        if h[0].object != id {
            continue;
        }
        count += 1;
        let o = s.surf(&r, &h)[0];
        let err = Vec3::from(o.normal).as_dvec3().angle_between(want);
        if err > worst.0 {
            worst = (err, sin);
        }
        hist[if err < 1e-6 {
            0
        } else if err < 1e-4 {
            1
        } else if err < 1e-2 {
            2
        } else {
            3
        }] += 1;
    }
    eprintln!("{count} hit; angle error <1e-6 / <1e-4 / <1e-2 / more: {hist:?}; worst {worst:?} (rad, sin of largest angle)");
    assert!(worst.0 < 1e-4, "{worst:?}");
    // Each ray aims at its sliver's centroid along the f64 normal: all but a few (rounding at
    // the thinnest) must hit.
    assert!(count >= 1990, "only {count} of 2000 slivers hit");
}

/// A unit sphere and ellipsoid 1e6 from the origin, seen from 5 away: the normal against the
/// f64 one at the f64 hit point of the same f32 ray.
#[test]
fn far_from_origin_normals_against_f64() {
    for off in [1e2, 1e3, 1e4, 1e5, 1e6] {
        far_from_origin(off);
    }
}
fn far_from_origin(off: f64) {
    let s = new(Rt2Backend::Cpu);
    let m = mat(&s);
    let (mut sid, mut eid) = (0, 0);
    let cs = DVec3::new(off, 0.0, 0.0);
    let ce = DVec3::new(off, 10.0, 0.0);
    let radii = DVec3::new(1.0, 0.7, 0.5);
    unsafe {
        ok(rt2_scene_add_sphere(
            s.scene,
            cs.as_vec3().to_array().as_ptr(),
            1.0,
            m,
            &mut sid,
        ));
        ok(rt2_scene_add_ellipsoid(
            s.scene,
            ce.as_vec3().to_array().as_ptr(),
            radii.as_vec3().to_array().as_ptr(),
            m,
            &mut eid,
        ));
    }
    s.commit();
    let mut next = support::uniform(0x1111_2222_3333_4445u64);
    for (id, c) in [(sid, cs), (eid, ce)] {
        let rays: Vec<rt2_ray> = (0..2000)
            .map(|_| {
                let o = c + DVec3::new(next() * 0.5, next() * 0.5, 5.0);
                let t = c + DVec3::new(next() * 0.8, next() * 0.5, 0.0);
                ray(o.as_vec3().to_array(), (t - o).as_vec3().to_array())
            })
            .collect();
        let h = s.hits(&rays, None);
        let out = s.surf(&rays, &h);
        let mut worst = 0.0f64;
        let mut worst_local = 0.0f64;
        let mut n = 0;
        for ((r, h), o) in rays.iter().zip(&h).zip(&out) {
            if h.object != id {
                continue;
            }
            n += 1;
            // f64 root of the f32 ray with the shape (unit-sphere space).
            let org = Vec3::from(r.org).as_dvec3() - c;
            let dir = Vec3::from(r.dir).as_dvec3();
            let sc = if id == sid { DVec3::ONE } else { radii };
            let (ou, du) = (org / sc, dir / sc);
            let (a, b, cc) = (du.dot(du), ou.dot(du), ou.dot(ou) - 1.0);
            let t = (-b - (b * b - a * cc).sqrt()) / a;
            let p = org + t * dir;
            let want = (p / (sc * sc)).normalize();
            let err = Vec3::from(o.normal).as_dvec3().angle_between(want);
            worst = worst.max(err);
            // What the f32 local point org - c + t dir (all f32) would give.
            let lp = (Vec3::from(r.org) - c.as_vec3()) + h.t * Vec3::from(r.dir);
            let ln = (lp.as_dvec3() / (sc * sc)).normalize();
            worst_local = worst_local.max(ln.angle_between(want));
        }
        eprintln!("offset {off:e} object {id}: {n} hits, worst normal error {worst:e} rad (local f32 point: {worst_local:e})");
        assert!(
            n > 1000 && worst < 1e-4,
            "offset {off:e} object {id}: {n} hits, worst normal error {worst:e} rad"
        );
    }
}

/// One thread asks for surfaces (the lookup dropped by every commit, so rebuilt under the write
/// lock again and again) while another moves an object and commits: only OK or
/// INVALID_OPERATION, and every OK surface lies on one of the two placements.
#[test]
fn surfaces_race_commits() {
    let s = new(Rt2Backend::Cpu);
    let m = mat(&s);
    let mut id = 0;
    unsafe {
        let p: [f32; 12] = [
            -1.0, -1.0, 0.0, 1.0, -1.0, 0.0, 1.0, 1.0, 0.0, -1.0, 1.0, 0.0,
        ];
        ok(rt2_scene_add_mesh(
            s.scene,
            p.as_ptr(),
            4,
            [0u32, 1, 2, 0, 2, 3].as_ptr(),
            2,
            m,
            &mut id,
        ));
    }
    s.commit();
    let rays: Vec<rt2_ray> = (0..64)
        .map(|i| ray([-0.9 + i as f32 * 0.028, 0.1, 5.0], [0.0, 0.0, -1.0]))
        .collect();
    let hits = s.hits(&rays, None);
    assert!(hits.iter().all(|h| h.object == id));
    let scene = s.scene as usize;
    let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let st2 = stop.clone();
    let mover = std::thread::spawn(move || {
        let mut k = 0;
        while !st2.load(std::sync::atomic::Ordering::Relaxed) {
            let z = if k % 2 == 0 { 0.0f32 } else { 1.0 };
            let t: [f32; 12] = [1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, z];
            unsafe {
                assert_eq!(
                    rt2_scene_set_transform(scene as *mut rt2_scene, 0, t.as_ptr()),
                    Rt2Status::Ok
                );
                assert_eq!(rt2_scene_commit(scene as *mut rt2_scene), Rt2Status::Ok);
            }
            k += 1;
        }
        k
    });
    let (mut oks, mut stale, mut other) = (0, 0, vec![]);
    let t0 = std::time::Instant::now();
    while t0.elapsed().as_secs_f32() < 3.0 {
        let mut out = vec![SENTINEL; rays.len()];
        let st = unsafe {
            rt2_hit_surfaces(
                s.scene,
                rays.as_ptr(),
                hits.as_ptr(),
                rays.len(),
                out.as_mut_ptr(),
            )
        };
        match st {
            Rt2Status::Ok => {
                oks += 1;
                let zs: Vec<f32> = out.iter().map(|o| o.position[2]).collect();
                if !(zs.iter().all(|&z| z == 0.0) || zs.iter().all(|&z| z == 1.0)) {
                    other.push(format!("mixed placements {zs:?}"));
                }
            }
            Rt2Status::InvalidOperation => {
                stale += 1;
                assert_eq!(out[0], SENTINEL);
            }
            e => other.push(format!("{e:?}: {}", last_error())),
        }
    }
    stop.store(true, std::sync::atomic::Ordering::Relaxed);
    let commits = mover.join().unwrap();
    eprintln!("{commits} commits, {oks} OK, {stale} stale");
    assert!(other.is_empty(), "{:?}", &other[..other.len().min(5)]);
}

/// A grazing ray on a plane whose hit point lies past f32::MAX: `rt2_intersect` reports the
/// hit (t = 1e36 and 1e38), and `rt2_hit_surfaces` gives the plane's normal and the point as
/// far as f32 goes: infinite where it overflows, on the plane elsewhere, never NaN (the
/// projection onto the plane made every coordinate NaN). A hit whose `t` itself is past
/// f32::MAX (1e39, 1e40) cannot be reported: a miss.
#[test]
fn plane_hit_past_f32_max() {
    let s = new(Rt2Backend::Cpu);
    let m = mat(&s);
    let mut id = 0;
    unsafe {
        ok(rt2_scene_add_plane(
            s.scene,
            [0.0, 0.0, 1.0].as_ptr(),
            0.0,
            m,
            &mut id,
        ))
    };
    s.commit();
    let mut bad = vec![];
    for (o, d, t) in [
        ([0.0f32, 0.0, 10.0], [1000.0f32, 0.0, -1e-35], Some(1e36)),
        ([0.0, 0.0, 10.0], [1.0, 0.0, -1e-37], Some(1e38)),
        ([0.0, 0.0, 1e30], [1.0, 0.0, -1e-10], None),
        ([0.0, 0.0, 10.0], [1.0, 1.0, -1e-38], None),
    ] {
        let r = [ray(o, d)];
        let h = s.hits(&r, None);
        let Some(t) = t else {
            assert_eq!(h[0].object, RT2_INVALID_ID, "{o:?} {d:?}: t past f32::MAX");
            continue;
        };
        assert_eq!(h[0].object, id, "{o:?} {d:?}: a miss");
        assert!((h[0].t / t - 1.0).abs() < 1e-6, "{o:?} {d:?}: t {}", h[0].t);
        let out = s.surf(&r, &h)[0];
        eprintln!("{o:?} {d:?}: t {:e} -> {out:?}", h[0].t);
        let on_plane = out.position[2] == 0.0 || out.position[2].is_infinite();
        if out.position.iter().any(|x| x.is_nan()) || !on_plane || out.normal != [0.0, 0.0, 1.0] {
            bad.push((o, d, h[0].t, out));
        }
    }
    assert!(bad.is_empty(), "{bad:?}");
}

/// Box edges, corners, a flat box, far from the origin: the position on the box's surface,
/// the normal one of the faces meeting there. A ray aimed at the centre of a face it crosses
/// (not parallel to it) hits wherever the face is wider than rounding; at edges and corners it
/// may pass either side.
#[test]
fn box_edges_and_corners() {
    let mut bad = vec![];
    let mut n = 0;
    for off in [0.0f32, 1e3, 1e5] {
        for (lo, hi) in [
            ([-1.0f32, -1.0, -1.0], [1.0f32, 1.0, 1.0]),
            ([-1.0, -1.0, 0.0], [1.0, 1.0, 0.0]),
            ([0.0, 0.0, 0.0], [1e-3, 2e-3, 5e-4]),
        ] {
            let lo = Vec3::from(lo) + off;
            let hi = Vec3::from(hi) + off;
            let s = new(Rt2Backend::Cpu);
            let m = mat(&s);
            let mut id = 0;
            unsafe {
                ok(rt2_scene_add_box(
                    s.scene,
                    lo.to_array().as_ptr(),
                    hi.to_array().as_ptr(),
                    m,
                    &mut id,
                ))
            };
            s.commit();
            let size = (hi - lo).max_element();
            // Targets: the corners, edge midpoints, face centres (with the face's axis).
            let mut targets = vec![];
            for i in 0..27 {
                let f = Vec3::new((i % 3) as f32, (i / 3 % 3) as f32, (i / 9) as f32) * 0.5;
                let off_centre: Vec<usize> = (0..3).filter(|&a| f[a] != 0.5).collect();
                let face = (off_centre.len() == 1).then(|| off_centre[0]);
                targets.push((lo + (hi - lo) * f, face));
            }
            // A face is wider than rounding when both of its sides span many ULPs.
            let wide = |axis: usize| {
                let ulp = hi.abs().max_element().max(lo.abs().max_element()) * f32::EPSILON;
                (0..3).all(|a| a == axis || hi[a] - lo[a] > 64.0 * ulp)
            };
            for (tg, face) in targets {
                for dir in [
                    Vec3::new(-1.0, -0.7, -0.3),
                    Vec3::new(0.3, 0.5, -1.0),
                    Vec3::new(1.0, -1.0, 1.0),
                    Vec3::new(0.0, 0.0, -1.0),
                ] {
                    let org = tg - dir * 3.0 * size.max(1e-3);
                    let r = [ray(org.to_array(), dir.to_array())];
                    let h = s.hits(&r, None);
                    if h[0].object != id {
                        if face.is_some_and(|a| dir[a] != 0.0 && wide(a)) {
                            bad.push(format!(
                                "off {off} box {lo}..{hi} face centre {tg} dir {dir}: a miss"
                            ));
                        }
                        continue;
                    }
                    n += 1;
                    let o = s.surf(&r, &h)[0];
                    let p = Vec3::from(o.position);
                    let nn = Vec3::from(o.normal);
                    // On a face: one coordinate at lo or hi, the others inside.
                    let inside = p.cmpge(lo).all() && p.cmple(hi).all();
                    let axis = (0..3).find(|&a| nn[a] != 0.0);
                    let on_face =
                        axis.is_some_and(|a| p[a] == if nn[a] > 0.0 { hi[a] } else { lo[a] });
                    let unit = (nn.length() - 1.0).abs() < 1e-6;
                    let near = (p.as_dvec3()
                        - (Vec3::from(r[0].org).as_dvec3() + h[0].t as f64 * dir.as_dvec3()))
                    .length()
                        < 1e-5 * (1.0 + org.length() as f64);
                    if !(inside && on_face && unit && near) {
                        bad.push(format!(
                            "off {off} box {lo}..{hi} target {tg} dir {dir}: {o:?} t {}",
                            h[0].t
                        ));
                    }
                }
            }
        }
    }
    eprintln!("{n} box hits");
    assert!(bad.is_empty(), "{}", bad[..bad.len().min(8)].join("\n"));
}

/// Thin ellipsoids at the origin: the normal against the f64 one at the f64 hit of the f32 ray.
#[test]
fn thin_ellipsoid_normals_against_f64() {
    for thin in [1e-3f64, 1e-4, 1e-5, 3e-6, 1e-6, 1e-10, 1e-15, 1e-19, 3e-20] {
        let s = new(Rt2Backend::Cpu);
        let m = mat(&s);
        let mut id = 0;
        let radii = DVec3::new(1.0, 0.5, thin);
        unsafe {
            ok(rt2_scene_add_ellipsoid(
                s.scene,
                [0.0f32; 3].as_ptr(),
                radii.as_vec3().to_array().as_ptr(),
                m,
                &mut id,
            ))
        };
        s.commit();
        let mut next = support::uniform(0x7777_2222_3333_4445u64);
        let rays: Vec<rt2_ray> = (0..2000)
            .map(|_| {
                let o = DVec3::new(next() * 2.0, next() * 2.0, 3.0 * next().signum());
                let t = DVec3::new(next() * 0.9, next() * 0.45, 0.0);
                ray(o.as_vec3().to_array(), (t - o).as_vec3().to_array())
            })
            .collect();
        let h = s.hits(&rays, None);
        let out = s.surf(&rays, &h);
        let (mut worst, mut n) = (0.0f64, 0);
        let mut hist = [0usize; 3];
        for ((r, h), o) in rays.iter().zip(&h).zip(&out) {
            if h.object != id {
                continue;
            }
            n += 1;
            let org = Vec3::from(r.org).as_dvec3();
            let dir = Vec3::from(r.dir).as_dvec3();
            let (ou, du) = (org / radii, dir / radii);
            // Closest approach in unit space (well conditioned), then back by the half chord.
            let dd = du.dot(du);
            let tc = -ou.dot(du) / dd;
            let q = ou + tc * du;
            let h2 = 1.0 - q.length_squared();
            if h2 < 1e-6 {
                continue; // grazing: the rim
            }
            let pu = q - (h2 / dd).sqrt() * du;
            let t = tc - (h2 / dd).sqrt();
            let p = pu * radii;
            let want = (pu / radii).normalize();
            let err = Vec3::from(o.normal).as_dvec3().angle_between(want);
            if err > 1e-3 && hist[2] < 2 {
                eprintln!(
                    "  ray {r:?} t {} (f64 {t}) -> {o:?}; f64 point {p}, normal {want}",
                    h.t
                );
            }
            worst = worst.max(err);
            hist[if err < 1e-5 {
                0
            } else if err < 1e-3 {
                1
            } else {
                2
            }] += 1;
        }
        eprintln!(
            "thin {thin:e}: {n} hits, normal error <1e-5/<1e-3/more {hist:?}, worst {worst:e}"
        );
        assert!(
            n > 1000 && worst < 1e-4,
            "thin {thin:e}: {n} hits, {hist:?}, worst {worst:e}"
        );
    }
}

/// Thin boxes seen from 3 units away, above and below: the face the ray meets.
#[test]
fn thin_box_faces() {
    let mut report = vec![];
    for thin in [1e-3f32, 1e-5, 1e-6, 1e-7, 1e-9] {
        let s = new(Rt2Backend::Cpu);
        let m = mat(&s);
        let mut id = 0;
        unsafe {
            ok(rt2_scene_add_box(
                s.scene,
                [-1.0f32, -1.0, 0.0].as_ptr(),
                [1.0f32, 1.0, thin].as_ptr(),
                m,
                &mut id,
            ))
        };
        s.commit();
        let mut uniform = support::uniform(0x4242_2222_3333_4445u64);
        let mut next = move || uniform() as f32;
        let rays: Vec<rt2_ray> = (0..2000)
            .map(|_| {
                let o = Vec3::new(next() * 2.0, next() * 2.0, 3.0 * next().signum());
                let t = Vec3::new(next() * 0.9, next() * 0.9, 0.0);
                ray(o.to_array(), (t - o).to_array())
            })
            .collect();
        let h = s.hits(&rays, None);
        let out = s.surf(&rays, &h);
        let (mut n, mut wrong) = (0, 0);
        for ((r, h), o) in rays.iter().zip(&h).zip(&out) {
            if h.object != id {
                continue;
            }
            n += 1;
            let want = if r.org[2] > 0.0 { 1.0 } else { -1.0 };
            if o.normal[2] != want {
                wrong += 1;
            }
        }
        report.push(format!(
            "thin {thin:e}: {wrong} of {n} hits on the far face"
        ));
        assert!(n > 1000 && wrong == 0, "{}", report.last().unwrap());
    }
    eprintln!("{}", report.join("\n"));
}

/// Spheres down to 1e-10 across and ellipsoids down to 1e-7, seen from 3 units, at the origin
/// and 2e3 from it: the normal is that of the f64 entry point of the ray as given (in unit
/// space), facing the ray. From the final review: in f32 the point `(org - c) + t dir` is off
/// across the ray by about an ULP of 3, so a sphere of radius 1e-5 had normals 0.05 rad off
/// and one of 1e-7 a fifth of them facing away; ellipsoids 1e-5 across 0.04 rad, 1e-6 0.3.
#[test]
fn tiny_spheres_and_ellipsoids_have_the_normals_of_f64() {
    let far = Vec3::new(1e3, -2e3, 5e2);
    let spheres = [1e-3f32, 1e-5, 1e-6, 1e-7, 1e-8, 1e-10]
        .map(|r| (Vec3::ZERO, Vec3::splat(r), true))
        .into_iter()
        .chain([
            (far, Vec3::splat(1e-2), true),
            (far, Vec3::splat(1e-3), true),
        ]);
    let ellipsoids =
        [1e-3f32, 1e-5, 1e-6, 1e-7].map(|r| (Vec3::ZERO, Vec3::new(1.0, 0.7, 0.5) * r, false));
    let mut report = vec![];
    let mut worst_all = 0f64;
    for (c, radii, sphere) in spheres.chain(ellipsoids) {
        let sc = new(Rt2Backend::Cpu);
        unsafe {
            let (centre, r) = (c.to_array(), radii.to_array());
            ok(match sphere {
                true => rt2_scene_add_sphere(sc.scene, centre.as_ptr(), r[0], 0, null_mut()),
                false => {
                    rt2_scene_add_ellipsoid(sc.scene, centre.as_ptr(), r.as_ptr(), 0, null_mut())
                }
            });
        }
        sc.commit();
        let aim = 0.3 * radii.min_element();
        let rays: Vec<rt2_ray> = support::rays_around(c, 3.0, aim, 4000, 0x1234_5678_9abc_def1)
            .into_iter()
            .map(|(o, d)| ray(o.to_array(), d.to_array()))
            .collect();
        let hits = sc.hits(&rays, None);
        let out = sc.surf(&rays, &hits);
        let rd = radii.as_dvec3();
        let (mut n, mut back, mut worst) = (0, 0, 0f64);
        for ((ray, h), s) in rays.iter().zip(&hits).zip(&out) {
            if h.prim == RT2_INVALID_ID {
                continue;
            }
            // The entry point in unit space, where the ellipsoid is the unit sphere.
            let o = (Vec3::from(ray.org).as_dvec3() - c.as_dvec3()) / rd;
            let dir = Vec3::from(ray.dir).as_dvec3() / rd;
            let dd = dir.dot(dir);
            let qp = o - (o.dot(dir) / dd) * dir;
            let h2 = 1.0 - qp.length_squared();
            if h2 < 1e-2 {
                continue; // grazing
            }
            n += 1;
            let pu = qp - (h2 / dd).sqrt() * dir;
            let want: DVec3 = (pu / rd).normalize();
            worst = worst.max(Vec3::from(s.normal).as_dvec3().angle_between(want));
            if Vec3::from(s.normal).dot(Vec3::from(ray.dir)) > 0.0 {
                back += 1;
            }
        }
        worst_all = worst_all.max(worst);
        report.push(format!(
            "centre {c}, radii {radii}: {n} hits, {back} facing away, worst {worst:e}"
        ));
        assert!(n > 1000, "{}", report.join("\n"));
    }
    eprintln!("{}", report.join("\n"));
    assert!(
        worst_all < 1e-5 && report.iter().all(|l| l.contains(" 0 facing")),
        "{report:#?}"
    );
}
