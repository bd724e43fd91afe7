//! The C API's query modes and render schedules: `rt2_query_options.mode` selects single rays,
//! packets or streams (same hits), `rt2_render_options.schedule` depth- or breadth-first, and
//! out-of-range values are errors, not undefined behaviour.

use rt2::api::*;
use rt2::error::Rt2Status;
use std::ptr::{null, null_mut};

/// A context and a committed scene of the spheres `(centre, radius)`, with their object ids.
unsafe fn sphere_scene(
    spheres: impl Iterator<Item = ([f32; 3], f32)>,
) -> (*mut rt2_context, *mut rt2_scene, Vec<u32>) {
    let mut ctx = null_mut();
    assert_eq!(rt2_context_create(null(), &mut ctx), Rt2Status::Ok);
    let mut scene = null_mut();
    assert_eq!(rt2_scene_create(ctx, &mut scene), Rt2Status::Ok);
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
        for mode in [
            Rt2QueryMode::Single,
            Rt2QueryMode::Packet,
            Rt2QueryMode::Stream,
        ] {
            let mut opt = rt2_query_options_default();
            assert_eq!(opt.mode, Rt2QueryMode::Single as u32);
            opt.mode = mode as u32;
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
            let st = rt2_intersect(
                ctx,
                scene,
                rays.as_ptr(),
                rays.len(),
                hits.as_mut_ptr(),
                &opt,
                null_mut(),
            );
            assert_eq!(st, Rt2Status::Ok);
            let mut occ = vec![2u8; rays.len()];
            let st = rt2_occluded(
                ctx,
                scene,
                rays.as_ptr(),
                rays.len(),
                occ.as_mut_ptr(),
                &opt,
                null_mut(),
            );
            assert_eq!(st, Rt2Status::Ok);
            for (h, o) in hits.iter().zip(&occ) {
                assert_eq!(*o, (h.object != RT2_INVALID_ID) as u8);
            }
            results.push(hits);
        }
        assert!(results
            .iter()
            .any(|r| r.iter().any(|h| h.object != RT2_INVALID_ID)));
        assert_eq!(results[0], results[1]);
        assert_eq!(results[0], results[2]);

        let mut opt = rt2_query_options_default();
        opt.mode = 3;
        let mut hits = vec![
            rt2_hit {
                t: 0.0,
                u: 0.0,
                v: 0.0,
                object: 0,
                prim: 0
            };
            1
        ];
        let st = rt2_intersect(
            ctx,
            scene,
            rays.as_ptr(),
            1,
            hits.as_mut_ptr(),
            &opt,
            null_mut(),
        );
        assert_eq!(st, Rt2Status::InvalidArgument);

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
        ropt.schedule = Rt2Schedule::BreadthFirst as u32;
        assert_eq!(rt2_render(ctx, scene, camera, &ropt, frame), Rt2Status::Ok);
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
        for mode in [Rt2QueryMode::Single, Rt2QueryMode::Stream] {
            let mut opt = rt2_query_options_default();
            opt.mode = mode as u32;
            let mut hits = vec![
                rt2_hit {
                    t: -1.0,
                    u: 0.0,
                    v: 0.0,
                    object: 7,
                    prim: 7
                };
                n
            ];
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
