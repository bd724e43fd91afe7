//! The C API's query modes and render schedules: `rt2_query_options.mode` selects single rays,
//! packets, streams or AUTO's choice among them (same hits), `rt2_render_options.schedule`
//! depth- or breadth-first, and out-of-range values are errors, not undefined behaviour.

use rt2::api::*;
use rt2::error::Rt2Status;
use std::ptr::{null, null_mut};

/// The query modes of the C API.
const MODES: [Rt2QueryMode; 4] = [
    Rt2QueryMode::Single,
    Rt2QueryMode::Packet,
    Rt2QueryMode::Stream,
    Rt2QueryMode::Auto,
];

/// A miss as the C API writes it; as an excluded primitive, none.
const MISS: rt2_hit = rt2_hit {
    t: f32::INFINITY,
    u: 0.0,
    v: 0.0,
    object: RT2_INVALID_ID,
    prim: RT2_INVALID_ID,
};

/// A hit record no query writes: outputs start as it, so that an answer left unwritten shows.
const UNWRITTEN: rt2_hit = rt2_hit {
    t: -1.0,
    u: 0.0,
    v: 0.0,
    object: 7,
    prim: 7,
};

/// Query options of the standard traversal in `mode`.
fn standard_in(mode: Rt2QueryMode) -> rt2_query_options {
    let mut opt = rt2_query_options_default();
    opt.traversal = Rt2Traversal::Standard as u32;
    opt.mode = mode as u32;
    opt
}

mod support;
use support::add_mesh;

/// A context of the default backend and a committed scene of the spheres `(centre, radius)`,
/// with their object ids.
unsafe fn sphere_scene(
    spheres: impl Iterator<Item = ([f32; 3], f32)>,
) -> (*mut rt2_context, *mut rt2_scene, Vec<u32>) {
    sphere_scene_on(null(), spheres)
}

/// A context made from `desc` (NULL: the defaults) and an empty scene of it.
unsafe fn empty_scene_on(desc: *const rt2_context_desc) -> (*mut rt2_context, *mut rt2_scene) {
    let mut ctx = null_mut();
    assert_eq!(rt2_context_create(desc, &mut ctx), Rt2Status::Ok);
    let mut scene = null_mut();
    assert_eq!(rt2_scene_create(ctx, &mut scene), Rt2Status::Ok);
    (ctx, scene)
}

/// [`sphere_scene`] on a context made from `desc` (NULL: the defaults).
unsafe fn sphere_scene_on(
    desc: *const rt2_context_desc,
    spheres: impl Iterator<Item = ([f32; 3], f32)>,
) -> (*mut rt2_context, *mut rt2_scene, Vec<u32>) {
    let (ctx, scene) = empty_scene_on(desc);
    let ids = spheres
        .map(|(c, r)| {
            let mut id = 0;
            assert_eq!(
                rt2_scene_add_sphere(scene, c.as_ptr(), r, 0, &mut id),
                Rt2Status::Ok
            );
            id
        })
        .collect();
    assert_eq!(rt2_scene_commit(scene), Rt2Status::Ok);
    (ctx, scene, ids)
}

/// The unit squares (two triangles each) of an `n` × `n` grid at height `z` for which
/// `keep(x, y)` holds: positions and triangle indices.
fn grid(n: u32, z: f32, keep: impl Fn(u32, u32) -> bool) -> (Vec<f32>, Vec<u32>) {
    let positions = (0..=n)
        .flat_map(|y| (0..=n).flat_map(move |x| [x as f32, y as f32, z]))
        .collect();
    let corner = |x: u32, y: u32| y * (n + 1) + x;
    let indices = (0..n)
        .flat_map(|y| (0..n).map(move |x| (x, y)))
        .filter(|&(x, y)| keep(x, y))
        .flat_map(|(x, y)| {
            let (a, b) = (corner(x, y), corner(x + 1, y));
            let (c, d) = (corner(x, y + 1), corner(x + 1, y + 1));
            [a, b, d, a, d, c]
        })
        .collect();
    (positions, indices)
}

/// `rt2_intersect` of every ray of `rays` into `hits` (as long), no statistics.
unsafe fn intersect_all(
    ctx: *const rt2_context,
    scene: *const rt2_scene,
    rays: &[rt2_ray],
    hits: &mut [rt2_hit],
    opt: *const rt2_query_options,
) -> Rt2Status {
    assert_eq!(rays.len(), hits.len());
    rt2_intersect(
        ctx,
        scene,
        rays.as_ptr(),
        rays.len(),
        hits.as_mut_ptr(),
        opt,
        null_mut(),
    )
}

/// `rt2_occluded` of every ray of `rays` into `occ` (as long), no statistics.
unsafe fn occluded_all(
    ctx: *const rt2_context,
    scene: *const rt2_scene,
    rays: &[rt2_ray],
    occ: &mut [u8],
    opt: *const rt2_query_options,
) -> Rt2Status {
    assert_eq!(rays.len(), occ.len());
    rt2_occluded(
        ctx,
        scene,
        rays.as_ptr(),
        rays.len(),
        occ.as_mut_ptr(),
        opt,
        null_mut(),
    )
}

#[test]
fn every_query_mode_gives_the_same_hits_and_bad_values_are_rejected() {
    unsafe {
        let (ctx, scene, _) = sphere_scene((0..50).map(|k| {
            let c = [
                (k % 7) as f32 - 3.0,
                (k / 7) as f32 - 3.0,
                0.2 * (k % 3) as f32,
            ];
            (c, 0.4)
        }));
        let rays: Vec<rt2_ray> = (0..4000)
            .map(|i| {
                let a = i as f32 * 0.37;
                rt2_ray {
                    org: [0.3 * a.sin(), 0.2 * a.cos(), 10.0],
                    tmin: 0.0,
                    dir: [0.3 * (a * 1.7).sin(), 0.3 * (a * 0.9).cos(), -1.0],
                    tmax: f32::INFINITY,
                }
            })
            .collect();
        let mut results = Vec::new();
        let intersectors = [Rt2Intersector::MollerTrumbore, Rt2Intersector::Watertight];
        for (intersector, mode) in intersectors.iter().flat_map(|&i| MODES.map(|m| (i, m))) {
            let mut opt = rt2_query_options_default();
            assert_eq!(opt.mode, Rt2QueryMode::Auto as u32);
            opt.mode = mode as u32;
            opt.intersector = intersector as u32;
            let mut hits = vec![
                rt2_hit {
                    t: 0.0,
                    u: 0.0,
                    v: 0.0,
                    object: 0,
                    prim: 0
                };
                rays.len()
            ];
            let st = intersect_all(ctx, scene, &rays, &mut hits, &opt);
            assert_eq!(st, Rt2Status::Ok);
            let mut occ = vec![2u8; rays.len()];
            let st = occluded_all(ctx, scene, &rays, &mut occ, &opt);
            assert_eq!(st, Rt2Status::Ok);
            for (h, o) in hits.iter().zip(&occ) {
                assert_eq!(*o, (h.object != RT2_INVALID_ID) as u8);
            }
            results.push(hits);
        }
        assert!(results
            .iter()
            .any(|r| r.iter().any(|h| h.object != RT2_INVALID_ID)));
        // Every mode with either intersector (spheres: both tests give the same hits).
        for r in &results[1..] {
            assert_eq!(&results[0], r);
        }

        // One ray with the options `opt`: its status.
        let one_ray = |opt: &rt2_query_options| {
            let mut hit = results[0][0];
            rt2_intersect(ctx, scene, rays.as_ptr(), 1, &mut hit, opt, null_mut())
        };
        let mut opt = rt2_query_options_default();
        opt.mode = 4;
        assert_eq!(one_ray(&opt), Rt2Status::InvalidArgument);
        // The short stack holds at most 32 entries: 33 is refused, 32 runs.
        for (size, want) in [(33, Rt2Status::InvalidArgument), (32, Rt2Status::Ok)] {
            let mut opt = rt2_query_options_default();
            opt.traversal = Rt2Traversal::ShortStack as u32;
            opt.short_stack_size = size;
            assert_eq!(one_ray(&opt), want, "short_stack_size {size}");
        }

        let mut ropt = rt2_render_options_default();
        assert_eq!(ropt.schedule, Rt2Schedule::DepthFirst as u32);
        ropt.schedule = 2;
        let mut frame = null_mut();
        assert_eq!(rt2_frame_create(8, 8, &mut frame), Rt2Status::Ok);
        let mut camera = null_mut();
        assert_eq!(rt2_camera_create(&mut camera), Rt2Status::Ok);
        assert_eq!(
            rt2_render(ctx, scene, camera, &ropt, frame),
            Rt2Status::InvalidArgument
        );
        // The schedule the C caller names is the one that runs: breadth-first draws what
        // depth-first draws (up to 1/255, the order of a pixel's sums), with every intersector
        // and offset mode (exclude-prim: the streams carry each ray's excluded primitive).
        let (w, h) = (64u32, 48u32);
        let offsets = [
            Rt2OffsetMode::Epsilon,
            Rt2OffsetMode::Robust,
            Rt2OffsetMode::ExcludePrim,
        ];
        for (intersector, offset) in intersectors.iter().flat_map(|&i| offsets.map(|o| (i, o))) {
            ropt.intersector = intersector as u32;
            ropt.offset_mode = offset as u32;
            let mut pixels = Vec::new();
            for schedule in [Rt2Schedule::DepthFirst, Rt2Schedule::BreadthFirst] {
                ropt.schedule = schedule as u32;
                let mut f = null_mut();
                assert_eq!(rt2_frame_create(w, h, &mut f), Rt2Status::Ok);
                assert_eq!(rt2_render(ctx, scene, camera, &ropt, f), Rt2Status::Ok);
                let n = (4 * w * h) as usize;
                pixels.push(std::slice::from_raw_parts(rt2_frame_pixels(f), n).to_vec());
                rt2_frame_destroy(f);
            }
            let worst = pixels[0]
                .iter()
                .zip(&pixels[1])
                .map(|(a, b)| a.abs_diff(*b))
                .max();
            let what = format!("{intersector:?}, {offset:?}");
            assert!(
                worst <= Some(1),
                "{what}: breadth-first differs by {worst:?}/255"
            );
            assert!(
                pixels[0].chunks(4).any(|p| p != &pixels[0][..4]),
                "{what}: the image is uniform: nothing was compared"
            );
        }
        rt2_camera_destroy(camera);
        rt2_frame_destroy(frame);
        rt2_scene_destroy(scene);
        rt2_context_destroy(ctx);
    }
}

/// A query of more rays than the API traces in one step (2^20, `QUERY_CHUNK`): every ray's
/// answer still lands at its own index, across the steps, in every mode.
#[test]
fn a_query_longer_than_one_step_answers_every_ray_in_place() {
    unsafe {
        let (ctx, scene, ids) = sphere_scene(std::iter::once(([0.0; 3], 1.0)));
        let id = ids[0];
        // Every third ray goes through the unit sphere's centre (hit at t = 9), the others pass
        // 5 units beside it (miss).
        let n = (1 << 20) + 3;
        let hits_sphere = |i: usize| i.is_multiple_of(3);
        let rays: Vec<rt2_ray> = (0..n)
            .map(|i| rt2_ray {
                org: [if hits_sphere(i) { 0.0 } else { 5.0 }, 0.0, 10.0],
                tmin: 0.0,
                dir: [0.0, 0.0, -1.0],
                tmax: f32::INFINITY,
            })
            .collect();
        for mode in MODES {
            let mut opt = rt2_query_options_default();
            opt.mode = mode as u32;
            let mut hits = vec![UNWRITTEN; n];
            let status = rt2_intersect(
                ctx,
                scene,
                rays.as_ptr(),
                n,
                hits.as_mut_ptr(),
                &opt,
                null_mut(),
            );
            assert_eq!(status, Rt2Status::Ok);
            for (i, h) in hits.iter().enumerate() {
                if hits_sphere(i) {
                    assert!(
                        h.object == id && (h.t - 9.0).abs() < 1e-5,
                        "{mode:?}: ray {i} should hit at t = 9, got t = {} object {}",
                        h.t,
                        h.object
                    );
                } else {
                    assert!(
                        h.object == RT2_INVALID_ID && h.t == f32::INFINITY,
                        "{mode:?}: ray {i} should miss, got t = {} object {}",
                        h.t,
                        h.object
                    );
                }
            }
            let mut occluded = vec![7u8; n];
            let status = rt2_occluded(
                ctx,
                scene,
                rays.as_ptr(),
                n,
                occluded.as_mut_ptr(),
                &opt,
                null_mut(),
            );
            assert_eq!(status, Rt2Status::Ok);
            for (i, &o) in occluded.iter().enumerate() {
                assert_eq!(o, hits_sphere(i) as u8, "{mode:?}: ray {i} occluded flag");
            }
        }
        rt2_scene_destroy(scene);
        rt2_context_destroy(ctx);
    }
}

/// Calls of 1 to 20 rays (staged on the stack up to a limit, on the heap beyond it) answer
/// every ray as the unit sphere says, in every mode: ray i passes at height `x_i` beside its
/// centre, a hit at `t = 10 - sqrt(1 - x_i^2)` where `|x_i| < 1`.
#[test]
fn small_calls_answer_every_ray() {
    unsafe {
        let (ctx, scene, ids) = sphere_scene(std::iter::once(([0.0; 3], 1.0)));
        let heights: Vec<f32> = (0..60).map(|i| (i as f32 - 29.5) / 20.0).collect();
        let rays: Vec<rt2_ray> = heights
            .iter()
            .map(|&x| rt2_ray {
                org: [x, 0.0, 10.0],
                tmin: 0.0,
                dir: [0.0, 0.0, -1.0],
                tmax: f32::INFINITY,
            })
            .collect();
        for mode in MODES {
            let mut opt = rt2_query_options_default();
            opt.mode = mode as u32;
            for size in 1..=20 {
                for (k, (rays, heights)) in rays.chunks(size).zip(heights.chunks(size)).enumerate()
                {
                    let mut hits = vec![UNWRITTEN; rays.len()];
                    let mut occ = vec![9u8; rays.len()];
                    assert_eq!(
                        intersect_all(ctx, scene, rays, &mut hits, &opt),
                        Rt2Status::Ok
                    );
                    assert_eq!(
                        occluded_all(ctx, scene, rays, &mut occ, &opt),
                        Rt2Status::Ok
                    );
                    for ((h, o), &x) in hits.iter().zip(&occ).zip(heights) {
                        let what = format!("{mode:?}, call {k} of {size} rays, height {x}");
                        let inside = x.abs() < 1.0;
                        assert_eq!(*o, inside as u8, "{what}");
                        match inside {
                            true => {
                                let t = 10.0 - (1.0 - (x as f64).powi(2)).sqrt();
                                assert!((h.t as f64 - t).abs() < 1e-5, "{what}: t {}", h.t);
                                assert_eq!(h.object, ids[0], "{what}");
                            }
                            false => assert_eq!(h.object, RT2_INVALID_ID, "{what}"),
                        }
                    }
                }
            }
        }
        rt2_scene_destroy(scene);
        rt2_context_destroy(ctx);
    }
}

/// The counters of `rt2_query_stats`, through the C API in every mode, on a tree whose every
/// node a ray meets is known from the geometry: two stacks of triangles facing x, `A` (5, at
/// x in [0, 1]) and `B` (7, at x in [9, 10]), each covering `y + z <= 1` of the unit square.
/// The midpoint builder at depth 1 splits the root at x = 5 into a leaf per stack. A ray along
/// +x through `y + z > 1` misses everything: root and both leaves (3 nodes, 2 leaves, 12
/// tests). One through `y + z < 1` hits A's first triangle, before leaving A's leaf: 2 nodes,
/// 1 leaf, 5 tests. Along -x, the same with B first (7 tests).
#[test]
fn query_statistics_count_the_nodes_leaves_and_tests_of_each_ray() {
    let (na, nb) = (5usize, 7usize);
    let xs: Vec<f32> = (0..na)
        .map(|k| k as f32 / (na - 1) as f32)
        .chain((0..nb).map(|k| 9.0 + k as f32 / (nb - 1) as f32))
        .collect();
    let positions: Vec<f32> = xs
        .iter()
        .flat_map(|&x| [x, 0.0, 0.0, x, 1.0, 0.0, x, 0.0, 1.0])
        .collect();
    let indices: Vec<u32> = (0..3 * xs.len() as u32).collect();
    // (y, z, direction sign) and the expected (nodes, leaves, tests) per ray.
    let mut rays = Vec::new();
    let mut want = [0u64; 3];
    for k in 0..40 {
        // Even k through the triangles (y + z <= 0.69), odd k past them (y + z >= 1.2), all
        // inside the scene's box.
        let through = k % 2 == 0;
        let (y, z) = if through {
            (0.1 + 0.01 * k as f32, 0.2)
        } else {
            (0.5 + 0.01 * k as f32, 0.7)
        };
        for sign in [1.0f32, -1.0] {
            rays.push(rt2_ray {
                org: [5.0 - 6.0 * sign, y, z],
                tmin: 0.0,
                dir: [sign, 0.0, 0.0],
                tmax: f32::INFINITY,
            });
            let first = if sign > 0.0 { na } else { nb };
            let [n, l, t] = if through {
                [2, 1, first]
            } else {
                [3, 2, na + nb]
            };
            want[0] += n as u64;
            want[1] += l as u64;
            want[2] += t as u64;
        }
    }
    unsafe {
        let mut ctx = null_mut();
        assert_eq!(rt2_context_create(null(), &mut ctx), Rt2Status::Ok);
        let mut scene = null_mut();
        assert_eq!(rt2_scene_create(ctx, &mut scene), Rt2Status::Ok);
        let mut id = 0;
        assert_eq!(
            rt2_scene_add_mesh(
                scene,
                positions.as_ptr(),
                positions.len() / 3,
                indices.as_ptr(),
                xs.len(),
                0,
                &mut id
            ),
            Rt2Status::Ok
        );
        let mut b = rt2_build_options_default();
        b.builder = Rt2Builder::Midpoint as u32;
        b.max_depth = 1;
        b.leaf_size = 1;
        assert_eq!(rt2_scene_set_build_options(scene, &b), Rt2Status::Ok);
        assert_eq!(rt2_scene_commit(scene), Rt2Status::Ok);
        for mode in MODES {
            let opt = standard_in(mode);
            let miss = rt2_hit {
                t: 0.0,
                u: 0.0,
                v: 0.0,
                object: 0,
                prim: 0,
            };
            let mut hits = vec![miss; rays.len()];
            let mut stats = rt2_query_stats {
                nodes_visited: 99,
                leaves_visited: 99,
                prim_tests: 99,
            };
            let st = rt2_intersect(
                ctx,
                scene,
                rays.as_ptr(),
                rays.len(),
                hits.as_mut_ptr(),
                &opt,
                &mut stats,
            );
            assert_eq!(st, Rt2Status::Ok);
            let got = [stats.nodes_visited, stats.leaves_visited, stats.prim_tests];
            assert_eq!(got, want, "{mode:?}: (nodes, leaves, tests)");
            let hit_count = hits.iter().filter(|h| h.t.is_finite()).count();
            assert_eq!(hit_count, rays.len() / 2, "{mode:?}");
        }
        rt2_scene_destroy(scene);
        rt2_context_destroy(ctx);
    }
}

/// An any-hit query counts, for each ray, the primitives tested until the first in its way,
/// in every mode: six overlapping spheres, and twelve stacked triangles (tested in SIMD
/// blocks), each scene in one leaf; rays through all of its primitives (one test: the first
/// of the leaf ends the search) and rays past them all (every primitive). Streams counted
/// every primitive of the leaf for every ray before, and blocks counted whole.
#[test]
fn any_hit_statistics_stop_at_the_first_primitive_in_the_way() {
    unsafe {
        let spheres = (0..6).map(|k| ([0.2 * k as f32, 0.0, 0.0], 1.0));
        let (ctx, scene, _) = sphere_scene(spheres);
        // Within 0.5 of every centre.
        any_hit_counts(ctx, scene, [0.5, 0.0], 6);
        rt2_scene_destroy(scene);
        let mut scene = null_mut();
        assert_eq!(rt2_scene_create(ctx, &mut scene), Rt2Status::Ok);
        let positions: Vec<f32> = (0..12)
            .flat_map(|k| {
                let z = 0.1 * k as f32;
                [-1.0, -1.0, z, 2.0, -1.0, z, -1.0, 1.0, z]
            })
            .collect();
        let indices: Vec<u32> = (0..36).collect();
        let status = rt2_scene_add_mesh(
            scene,
            positions.as_ptr(),
            36,
            indices.as_ptr(),
            12,
            0,
            null_mut(),
        );
        assert_eq!(status, Rt2Status::Ok);
        // Inside every triangle (the long edge crosses y = 0 at x = 0.5).
        any_hit_counts(ctx, scene, [0.0, 0.0], 12);
        rt2_scene_destroy(scene);
        rt2_context_destroy(ctx);
    }
}

/// The any-hit statistics of rays along -z through `through` (in all `prims` primitives) and
/// through (1.9, 0.9), inside the scene's box but past every primitive, with `scene` built
/// as one leaf: one test for each ray of the first kind, `prims` for the others.
unsafe fn any_hit_counts(
    ctx: *const rt2_context,
    scene: *mut rt2_scene,
    through: [f32; 2],
    prims: u64,
) {
    let mut b = rt2_build_options_default();
    b.max_depth = 0;
    assert_eq!(rt2_scene_set_build_options(scene, &b), Rt2Status::Ok);
    assert_eq!(rt2_scene_commit(scene), Rt2Status::Ok);
    let past = [1.9, 0.9];
    let rays: Vec<rt2_ray> = (0..64)
        .map(|i| {
            let [x, y] = if i % 3 == 0 { past } else { through };
            rt2_ray {
                org: [x, y, 5.0],
                tmin: 0.0,
                dir: [0.0, 0.0, -1.0],
                tmax: f32::INFINITY,
            }
        })
        .collect();
    let missing = rays.iter().filter(|r| r.org[0] == past[0]).count() as u64;
    let want = rays.len() as u64 - missing + prims * missing;
    for mode in MODES {
        let opt = standard_in(mode);
        let mut occ = vec![9u8; rays.len()];
        let mut stats = rt2_query_stats {
            nodes_visited: 99,
            leaves_visited: 99,
            prim_tests: 99,
        };
        let st = rt2_occluded(
            ctx,
            scene,
            rays.as_ptr(),
            rays.len(),
            occ.as_mut_ptr(),
            &opt,
            &mut stats,
        );
        assert_eq!(st, Rt2Status::Ok);
        let blocked = occ.iter().filter(|&&o| o == 1).count() as u64;
        assert_eq!(
            blocked,
            rays.len() as u64 - missing,
            "{mode:?}, {prims} primitives"
        );
        assert_eq!(
            stats.leaves_visited,
            rays.len() as u64,
            "{mode:?}, {prims} primitives"
        );
        assert_eq!(
            stats.prim_tests, want,
            "{mode:?}: tests among {prims} primitives"
        );
    }
}

/// As `rt2_query_stats` documents: an any-hit query reports the same leaves, primitive tests
/// and answers in every mode, with every traversal and either intersector, with and without
/// exclusions, on scenes whose leaves hold triangles alone or no triangles
/// (`support::any_hit_stats`); packets and streams also visit the nodes single rays visit with
/// the standard traversal. Streams counted every primitive of a leaf for every ray, and SIMD
/// blocks counted whole (9% more tests here on the spheres, ellipsoids and boxes).
#[test]
fn any_hit_statistics_agree_in_every_mode_and_traversal() {
    use rt2::context::{Context, QueryOptions};
    use rt2::cpu::query::QueryMode;
    use rt2::cpu::traverse::Traversal;
    use rt2::dispatch::BackendRequest;
    use rt2::precision::Intersector;
    use support::any_hit_stats::{but_nodes, cases, counts};
    let ctx = Context::new(BackendRequest::Cpu, 2).unwrap();
    let mut wrong = Vec::new();
    for case in cases() {
        let c = case.scene.committed().unwrap();
        for exclude in [None, Some(&case.exclude[..])] {
            for intersector in Intersector::ALL {
                let q = |mode, traversal| QueryOptions {
                    mode: Some(mode),
                    traversal: Some(traversal),
                    intersector,
                    ..QueryOptions::default()
                };
                let single = q(QueryMode::Single, Traversal::Standard);
                let want = counts(&ctx, c, &case.rays, exclude, &single);
                for mode in [QueryMode::Single, QueryMode::Packet, QueryMode::Stream] {
                    for traversal in Traversal::ALL {
                        let q = q(mode, traversal);
                        let what = format!(
                            "{}, excluding: {}, {intersector:?}, {mode:?}, {traversal:?}",
                            case.name,
                            exclude.is_some()
                        );
                        let got = counts(&ctx, c, &case.rays, exclude, &q);
                        if but_nodes(got) != but_nodes(want) {
                            wrong.push(format!("{what}: {got:?}, single rays {want:?}"));
                        }
                        if mode != QueryMode::Single && got.0.nodes_visited != want.0.nodes_visited
                        {
                            wrong.push(format!("{what}: {got:?} nodes, single rays {want:?}"));
                        }
                    }
                }
            }
        }
    }
    assert!(wrong.is_empty(), "{}", wrong.join("\n"));
}

/// `rt2_query_options.exclude`: two grids of triangles, at z = 0 (object 0) and z = -1 (object
/// 1), and rays straight down from z = 10. A ray that ignores the triangle it hits first hits
/// the lower grid at t = 11; one that ignores a triangle it does not hit is unchanged. The same
/// in every query mode with either intersector, for closest and any hits. Names the scene
/// lacks are refused before any output is written.
#[test]
fn excluded_primitives_are_ignored_in_every_mode() {
    unsafe {
        let (ctx, scene) = empty_scene_on(null());
        // Two 8 × 8 grids of unit squares, at heights 0 and -1.
        let n = 8u32;
        for (z, want_id) in [(0.0, 0), (-1.0, 1)] {
            let (p, i) = grid(n, z, |_, _| true);
            assert_eq!(add_mesh(scene, &p, &i), want_id);
        }
        assert_eq!(rt2_scene_commit(scene), Rt2Status::Ok);
        // Rays inside the grid, off its edges (0.1 + 0.37 k mod 8).
        let rays: Vec<rt2_ray> = (0..3000)
            .map(|k| {
                let f = |s: f32| 0.1 + (s * 0.37) % (n as f32 - 0.2);
                rt2_ray {
                    org: [f(k as f32), f(k as f32 * 1.9 + 0.5), 10.0],
                    tmin: 0.0,
                    dir: [0.0, 0.0, -1.0],
                    tmax: f32::INFINITY,
                }
            })
            .collect();
        let run = |opt: &rt2_query_options| {
            let mut hits = vec![MISS; rays.len()];
            let st = intersect_all(ctx, scene, &rays, &mut hits, opt);
            (st, hits)
        };
        let (st, first) = run(&rt2_query_options_default());
        assert_eq!(st, Rt2Status::Ok);
        assert!(first.iter().all(|h| h.object == 0 && h.t == 10.0));
        // The lookup the exclusions need is built on their first use: 4 bytes per triangle
        // and a word per object (and one more).
        // (lookup, primitives) bytes.
        let bytes = || {
            let mut stats: rt2_scene_statistics = std::mem::zeroed();
            stats.struct_size = std::mem::size_of::<rt2_scene_statistics>() as u32;
            assert_eq!(rt2_scene_stats(scene, &mut stats), Rt2Status::Ok);
            (stats.bytes_prim_lookup, stats.bytes_primitives)
        };
        let (lookup, primitives) = bytes();
        assert_eq!(lookup, 0);
        // A refused query (an object the scene lacks) builds neither it nor what its other
        // options would need (the watertight test's exact corners).
        let mut opt = rt2_query_options_default();
        opt.intersector = Rt2Intersector::Watertight as u32;
        let bad = vec![
            rt2_hit {
                object: 2,
                prim: 0,
                ..MISS
            };
            rays.len()
        ];
        opt.exclude = bad.as_ptr();
        assert_eq!(run(&opt).0, Rt2Status::InvalidArgument);
        assert_eq!(bytes(), (0, primitives));
        // Every other ray ignores its own first hit, the others the neighbouring triangle
        // (one they do not hit), or nothing.
        let exclude: Vec<rt2_hit> = first
            .iter()
            .enumerate()
            .map(|(k, h)| match k % 3 {
                0 => *h,
                1 => rt2_hit {
                    prim: h.prim ^ 1,
                    ..*h
                },
                _ => MISS,
            })
            .collect();
        for intersector in [Rt2Intersector::MollerTrumbore, Rt2Intersector::Watertight] {
            for mode in MODES {
                let mut opt = rt2_query_options_default();
                (opt.mode, opt.intersector, opt.exclude) =
                    (mode as u32, intersector as u32, exclude.as_ptr());
                let (st, hits) = run(&opt);
                assert_eq!(st, Rt2Status::Ok);
                for (k, (h, f)) in hits.iter().zip(&first).enumerate() {
                    let through = k % 3 == 0;
                    let (object, t) = if through { (1, 11.0) } else { (0, 10.0) };
                    // Within rounding: the watertight test's `t` is not exact.
                    assert!(
                        h.object == object && (h.t - t).abs() <= 2e-6 * t,
                        "{mode:?} {intersector:?} ray {k}: {h:?}"
                    );
                    if !through {
                        // The same triangle (`u`, `v` round differently per intersector).
                        assert_eq!(h.prim, f.prim, "{mode:?} {intersector:?} ray {k}");
                    }
                }
                // Shadow rays ending between the grids: only those that see through are clear.
                let short: Vec<rt2_ray> =
                    rays.iter().map(|r| rt2_ray { tmax: 10.5, ..*r }).collect();
                let mut occ = vec![2u8; rays.len()];
                let st = occluded_all(ctx, scene, &short, &mut occ, &opt);
                assert_eq!(st, Rt2Status::Ok);
                for (k, o) in occ.iter().enumerate() {
                    assert_eq!(*o, (k % 3 != 0) as u8, "{mode:?} {intersector:?} ray {k}");
                }
            }
        }

        let word = std::mem::size_of::<usize>() as u32;
        assert_eq!(bytes().0, (4 * 4 * n * n + word * 3) as u64);

        // In place: the hits a query writes may be the array it excludes (ray i leaving hit i).
        let mut hits = first.clone();
        let mut opt = rt2_query_options_default();
        (opt.mode, opt.exclude) = (Rt2QueryMode::Stream as u32, hits.as_ptr());
        let st = intersect_all(ctx, scene, &rays, &mut hits, &opt);
        assert_eq!(st, Rt2Status::Ok);
        assert!(hits.iter().all(|h| h.object == 1 && h.t == 11.0));

        // Names the scene lacks: the call fails and writes nothing.
        let bad_ids = [
            (2, 0),
            (0, 2 * n * n),
            (RT2_INVALID_ID, 0),
            (0, RT2_INVALID_ID),
        ];
        for (object, prim) in bad_ids {
            let mut bad = exclude.clone();
            bad[rays.len() - 1] = rt2_hit {
                object,
                prim,
                ..MISS
            };
            let mut opt = rt2_query_options_default();
            (opt.mode, opt.exclude) = (Rt2QueryMode::Stream as u32, bad.as_ptr());
            let (st, hits) = run(&opt);
            assert_eq!(st, Rt2Status::InvalidArgument, "({object}, {prim})");
            assert!(hits.iter().all(|h| *h == MISS), "({object}, {prim})");
        }
        // A query of more than one step (2^20 rays) is checked whole first: a bad name in
        // its last step leaves the first step's hits unwritten too.
        let long = (1 << 20) + 1;
        let (many, mut bad): (Vec<rt2_ray>, Vec<rt2_hit>) =
            (0..long).map(|k| (rays[k % rays.len()], MISS)).unzip();
        bad[long - 1] = rt2_hit {
            object: 7,
            prim: 0,
            ..MISS
        };
        let mut hits = vec![MISS; long];
        let mut opt = rt2_query_options_default();
        opt.exclude = bad.as_ptr();
        let st = rt2_intersect(
            ctx,
            scene,
            many.as_ptr(),
            long,
            hits.as_mut_ptr(),
            &opt,
            null_mut(),
        );
        assert_eq!(st, Rt2Status::InvalidArgument);
        assert!(hits.iter().all(|h| *h == MISS));
        rt2_scene_destroy(scene);
        rt2_context_destroy(ctx);
    }
}

/// Exclusions travel with their rays through the octant sort of incoherent stream batches: rays
/// in every octant, in batches that `query` sorts in one pass (at most `ONE_PASS_MAX` rays) and
/// through a gathered copy per stream (more). Every mode, both intersectors, closest and any
/// hits, gives the single-ray answers bit for bit (which the test above checks analytically),
/// and a ray that ignores its first hit meets the other grid (or, where it crosses the first on
/// an edge, the neighbouring triangle).
#[test]
fn excluded_primitives_follow_their_rays_through_the_octant_sort() {
    unsafe {
        let (ctx, scene) = empty_scene_on(null());
        for z in [0.0, -1.0] {
            let (p, i) = grid(8, z, |_, _| true);
            add_mesh(scene, &p, &i);
        }
        assert_eq!(rt2_scene_commit(scene), Rt2Status::Ok);
        // Down from above or up from below, tilted so that consecutive rays change octant.
        let ray = |k: usize| {
            let sign = |bit: usize| if k >> bit & 1 == 0 { 1.0 } else { -1.0 };
            let f = |s: f32| 1.0 + (s * 0.37) % 6.0;
            let z = sign(0);
            rt2_ray {
                org: [f(k as f32), f(k as f32 * 1.9 + 0.5), 10.0 * z],
                tmin: 0.0,
                dir: [0.01 * sign(1), 0.01 * sign(2), -z],
                tmax: f32::INFINITY,
            }
        };
        let one_pass_max = rt2::cpu::query::ONE_PASS_MAX;
        for (count, modes) in [(20_000, &MODES[..]), (one_pass_max + 1000, &MODES[2..3])] {
            let rays: Vec<rt2_ray> = (0..count).map(ray).collect();
            let answers = |mode: Rt2QueryMode, intersector: Rt2Intersector, exclude: &[rt2_hit]| {
                let mut opt = rt2_query_options_default();
                (opt.mode, opt.intersector) = (mode as u32, intersector as u32);
                if !exclude.is_empty() {
                    opt.exclude = exclude.as_ptr();
                }
                let mut hits = vec![UNWRITTEN; rays.len()];
                assert_eq!(
                    intersect_all(ctx, scene, &rays, &mut hits, &opt),
                    Rt2Status::Ok
                );
                let short: Vec<rt2_ray> =
                    rays.iter().map(|r| rt2_ray { tmax: 10.5, ..*r }).collect();
                let mut occ = vec![2u8; rays.len()];
                assert_eq!(
                    occluded_all(ctx, scene, &short, &mut occ, &opt),
                    Rt2Status::Ok
                );
                (hits, occ)
            };
            let (first, _) = answers(Rt2QueryMode::Single, Rt2Intersector::MollerTrumbore, &[]);
            assert!(first.iter().all(|h| h.object != RT2_INVALID_ID));
            // Every third ray ignores its first hit, the others nothing.
            let exclude: Vec<rt2_hit> = first
                .iter()
                .enumerate()
                .map(|(k, h)| if k % 3 == 0 { *h } else { MISS })
                .collect();
            for intersector in [Rt2Intersector::MollerTrumbore, Rt2Intersector::Watertight] {
                let (want, want_occ) = answers(Rt2QueryMode::Single, intersector, &exclude);
                // The other grid, or (through an edge) the neighbouring triangle at the same t (but for
                // rounding).
                for (k, (w, f)) in want.iter().zip(&first).enumerate().step_by(3) {
                    let near = (w.t - f.t).abs() <= 1e-5 * f.t;
                    let neighbour = w.object == f.object && near && w.prim != f.prim;
                    assert!(
                        w.object == 1 - f.object || neighbour,
                        "ray {k}: {w:?} after {f:?}"
                    );
                }
                for &mode in modes {
                    let (hits, occ) = answers(mode, intersector, &exclude);
                    let same = |a: &rt2_hit, b: &rt2_hit| {
                        (a.t, a.u, a.v, a.object, a.prim) == (b.t, b.u, b.v, b.object, b.prim)
                    };
                    let wrong = hits.iter().zip(&want).position(|(h, w)| !same(h, w));
                    assert_eq!(wrong, None, "{count} rays {mode:?} {intersector:?}");
                    assert!(occ == want_occ, "{count} rays {mode:?} {intersector:?}");
                }
            }
        }
        rt2_scene_destroy(scene);
        rt2_context_destroy(ctx);
    }
}

/// A rope traversal asked of PACKET or STREAM queries on the CPU, which follow the standard
/// order whatever the traversal, builds no ropes (about 3x the tree); asked of SINGLE queries,
/// it does. Before, every such query built them. A GPU context builds them for any mode: its
/// kernels take the traversal.
#[test]
fn packets_and_streams_build_no_ropes_on_the_cpu() {
    unsafe {
        let spheres = (0..64).map(|k| ([k as f32 * 3.0, 0.0, 0.0], 1.0));
        let (ctx, scene, _) = sphere_scene(spheres);
        let mut info: rt2_context_properties = std::mem::zeroed();
        info.struct_size = std::mem::size_of::<rt2_context_properties>() as u32;
        assert_eq!(rt2_context_info(ctx, &mut info), Rt2Status::Ok);
        let on_gpu = info.backend == Rt2Backend::Gpu as u32;
        let rope_bytes = || {
            let mut stats: rt2_scene_statistics = std::mem::zeroed();
            stats.struct_size = std::mem::size_of::<rt2_scene_statistics>() as u32;
            assert_eq!(rt2_scene_stats(scene, &mut stats), Rt2Status::Ok);
            stats.bytes_ropes
        };
        let rays: Vec<rt2_ray> = (0..64)
            .map(|k| rt2_ray {
                org: [k as f32 * 3.0, 0.0, 5.0],
                tmin: 0.0,
                dir: [0.0, 0.0, -1.0],
                tmax: f32::INFINITY,
            })
            .collect();
        let mut hits: Vec<rt2_hit> = vec![std::mem::zeroed(); rays.len()];
        // AUTO runs a rope traversal one ray at a time, so it needs the ropes: it comes
        // before SINGLE, which would build them anyway.
        for (mode, ropes) in [
            (Rt2QueryMode::Packet, on_gpu),
            (Rt2QueryMode::Stream, on_gpu),
            (Rt2QueryMode::Auto, true),
            (Rt2QueryMode::Single, true),
        ] {
            let mut opt = rt2_query_options_default();
            opt.traversal = Rt2Traversal::RopesPlusPlus as u32;
            opt.mode = mode as u32;
            let st = intersect_all(ctx, scene, &rays, &mut hits, &opt);
            assert_eq!(st, Rt2Status::Ok);
            assert!(hits.iter().all(|h| h.t == 4.0), "{mode:?}");
            assert_eq!(rope_bytes() > 0, ropes, "{mode:?}: ropes built?");
        }
        rt2_scene_destroy(scene);
        rt2_context_destroy(ctx);
    }
}

/// `rt2_context_properties.auto_choice` of `ctx` (`None`: NULL).
unsafe fn auto_choice(ctx: *const rt2_context) -> Option<String> {
    let mut info: rt2_context_properties = std::mem::zeroed();
    info.struct_size = std::mem::size_of::<rt2_context_properties>() as u32;
    assert_eq!(rt2_context_info(ctx, &mut info), Rt2Status::Ok);
    (!info.auto_choice.is_null()).then(|| {
        std::ffi::CStr::from_ptr(info.auto_choice)
            .to_string_lossy()
            .into_owned()
    })
}

/// AUTO (the default mode) traces a camera's rays in scanline order as packets, the same rays
/// shuffled as streams, a handful of rays and any batch of a non-standard traversal one ray at
/// a time; it says so in `auto_choice`, and every choice gives SINGLE's hits bit for bit, for
/// closest and any hits.
#[test]
fn auto_mode_chooses_by_coherence_and_size_and_says_why() {
    unsafe {
        let spheres = (0..100).map(|k| {
            let c = [
                (k % 10) as f32 - 4.5,
                (k / 10) as f32 - 4.5,
                0.3 * (k % 4) as f32,
            ];
            (c, 0.35)
        });
        // On the CPU, where the mode is chosen (a GPU runs its kernels whatever the mode).
        let mut desc = rt2_context_desc_default();
        desc.backend = Rt2Backend::Cpu as u32;
        let (ctx, scene, _) = sphere_scene_on(&desc, spheres);
        // A 64×64 pinhole camera 12 units in front of the spheres, in scanline order.
        let camera: Vec<rt2_ray> = (0..64 * 64)
            .map(|i| rt2_ray {
                org: [0.0, 0.0, 12.0],
                tmin: 0.0,
                dir: [
                    ((i % 64) as f32 + 0.5 - 32.0) / 64.0,
                    (32.0 - (i / 64) as f32 - 0.5) / 64.0,
                    -1.0,
                ],
                tmax: f32::INFINITY,
            })
            .collect();
        let shuffled: Vec<rt2_ray> = (0..camera.len())
            .map(|k| camera[k * 2741 % camera.len()])
            .collect();
        let cases: [(&[rt2_ray], Rt2Traversal, &str); 5] = [
            (&camera, Rt2Traversal::Auto, "CPU query mode packet: "),
            (&camera, Rt2Traversal::Standard, "CPU query mode packet: "),
            (&shuffled, Rt2Traversal::Auto, "CPU query mode stream: "),
            (&camera[..5], Rt2Traversal::Auto, "CPU query mode single: "),
            (&shuffled, Rt2Traversal::Ropes, "CPU query mode single: "),
        ];
        let mut hit_some = false;
        for (rays, traversal, said) in cases {
            let mut single = standard_in(Rt2QueryMode::Single);
            single.traversal = traversal as u32;
            let mut want = vec![std::mem::zeroed::<rt2_hit>(); rays.len()];
            assert_eq!(
                intersect_all(ctx, scene, rays, &mut want, &single),
                Rt2Status::Ok
            );
            let mut want_occ = vec![2u8; rays.len()];
            assert_eq!(
                occluded_all(ctx, scene, rays, &mut want_occ, &single),
                Rt2Status::Ok
            );

            let mut auto = rt2_query_options_default();
            auto.traversal = traversal as u32;
            let mut got = vec![std::mem::zeroed::<rt2_hit>(); rays.len()];
            assert_eq!(
                intersect_all(ctx, scene, rays, &mut got, &auto),
                Rt2Status::Ok
            );
            let choice = auto_choice(ctx).expect("the mode was left to AUTO");
            assert!(choice.contains(said), "{said}: {choice}");
            assert_eq!(got, want, "{said}");
            let mut occ = vec![2u8; rays.len()];
            assert_eq!(
                occluded_all(ctx, scene, rays, &mut occ, &auto),
                Rt2Status::Ok
            );
            assert_eq!(occ, want_occ, "{said}");
            hit_some |= got.iter().any(|h| h.object != RT2_INVALID_ID);
        }
        assert!(hit_some, "the camera sees spheres");
        // A mode the caller chose is not reported as AUTO's.
        let packets = standard_in(Rt2QueryMode::Packet);
        let mut hits = vec![std::mem::zeroed::<rt2_hit>(); camera.len()];
        assert_eq!(
            intersect_all(ctx, scene, &camera, &mut hits, &packets),
            Rt2Status::Ok
        );
        assert_eq!(auto_choice(ctx), None);
        rt2_scene_destroy(scene);
        rt2_context_destroy(ctx);
    }
}

/// A camera image longer than one step of the API (2^20 rays) whose width does not divide
/// 2^20: the API steps through it in whole bands of rows, where packets take tiles, and every
/// mode returns the single rays' hits bit for bit, excluding each ray's primitive from the
/// right place of `opt.exclude` in every step.
#[test]
fn an_image_of_several_steps_gives_every_mode_the_same_hits() {
    unsafe {
        let (ctx, scene) = empty_scene_on(null());
        // A checkerboard of unit squares at z = 0 over a full grid of them at z = -1.
        for (z, checkerboard) in [(0.0, true), (-1.0, false)] {
            let (p, i) = grid(16, z, |x, y| !checkerboard || (x + y) % 2 == 0);
            add_mesh(scene, &p, &i);
        }
        assert_eq!(rt2_scene_commit(scene), Rt2Status::Ok);
        // A pinhole camera above the grid, 1376 × 770 pixels in scanline order (1,059,520
        // rays; 2^20 is 762.05 of its rows).
        let (w, h) = (1376usize, 770usize);
        let eye = [8.3f32, 8.1, 12.0];
        let rays: Vec<rt2_ray> = (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w) as f32 + 0.5, (i / w) as f32 + 0.5);
                let at = [-1.0 + 18.0 * x / w as f32, 17.0 - 18.0 * y / h as f32, 0.0];
                let d = [at[0] - eye[0], at[1] - eye[1], at[2] - eye[2]];
                let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
                rt2_ray {
                    org: eye,
                    tmin: 0.0,
                    dir: d.map(|c| c / len),
                    tmax: f32::INFINITY,
                }
            })
            .collect();
        let run = |opt: &rt2_query_options| {
            let mut hits = vec![UNWRITTEN; rays.len()];
            assert_eq!(
                intersect_all(ctx, scene, &rays, &mut hits, opt),
                Rt2Status::Ok
            );
            hits
        };
        let first = run(&standard_in(Rt2QueryMode::Single));
        let on = |object: u32| first.iter().filter(|h| h.object == object).count();
        assert!(
            on(0) > rays.len() / 4 && on(1) > rays.len() / 4,
            "both layers seen"
        );
        // Every third ray ignores its first hit and finds the lower layer, or nothing.
        let exclude: Vec<rt2_hit> = first
            .iter()
            .enumerate()
            .map(|(i, h)| if i % 3 == 0 { *h } else { miss_of(h) })
            .collect();
        for excluding in [false, true] {
            let with = |mode| {
                let mut opt = standard_in(mode);
                if excluding {
                    opt.exclude = exclude.as_ptr();
                }
                opt
            };
            let want = run(&with(Rt2QueryMode::Single));
            if excluding {
                let moved = (0..rays.len()).filter(|&i| want[i].t != first[i].t);
                assert!(moved.count() > rays.len() / 8, "exclusions changed hits");
            }
            for mode in [
                Rt2QueryMode::Packet,
                Rt2QueryMode::Stream,
                Rt2QueryMode::Auto,
            ] {
                let got = run(&with(mode));
                for (i, (g, s)) in got.iter().zip(&want).enumerate() {
                    let bits = |h: &rt2_hit| (h.t.to_bits(), h.u.to_bits(), h.v.to_bits());
                    assert!(
                        bits(g) == bits(s) && (g.object, g.prim) == (s.object, s.prim),
                        "{mode:?}, excluding {excluding}: ray {i} (pixel {}, {}) got {:?}, \
                         single rays {:?}",
                        i % w,
                        i / w,
                        (g.t, g.object, g.prim),
                        (s.t, s.object, s.prim)
                    );
                }
            }
        }
        rt2_scene_destroy(scene);
        rt2_context_destroy(ctx);
    }
}

/// The exclusion of nothing: a hit record whose ids are both `RT2_INVALID_ID`.
fn miss_of(h: &rt2_hit) -> rt2_hit {
    rt2_hit {
        object: RT2_INVALID_ID,
        prim: RT2_INVALID_ID,
        ..*h
    }
}
