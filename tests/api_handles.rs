//! The C boundary through the exported functions themselves: handles of the wrong type,
//! destroyed handles and NULLs are errors with a message, never a crash, and a failed call
//! changes nothing.

use rt2::api::*;
use rt2::error::Rt2Status;
use std::ptr::{null, null_mut};

mod support;
use support::last_error;

#[test]
fn a_handle_of_another_type_is_rejected() {
    unsafe {
        let mut cam = null_mut();
        assert_eq!(rt2_camera_create(&mut cam), Rt2Status::Ok);
        let (mut w, mut h) = (7u32, 9u32);
        let status = rt2_frame_size(cam as *const rt2_frame, &mut w, &mut h);
        assert_eq!(status, Rt2Status::InvalidArgument);
        assert!(last_error().contains("rt2_frame"), "{}", last_error());
        assert_eq!((w, h), (7, 9), "outputs untouched on failure");
        rt2_camera_destroy(cam);
    }
}

#[test]
fn null_handles_and_outputs_are_errors_and_destroy_null_is_a_no_op() {
    unsafe {
        assert_eq!(rt2_scene_commit(null_mut()), Rt2Status::InvalidArgument);
        assert!(last_error().contains("scene is NULL"), "{}", last_error());
        assert_eq!(
            rt2_context_create(null(), null_mut()),
            Rt2Status::InvalidArgument
        );
        assert!(rt2_frame_pixels(null()).is_null());
        rt2_context_destroy(null_mut());
        rt2_scene_destroy(null_mut());
        rt2_camera_destroy(null_mut());
        rt2_frame_destroy(null_mut());
    }
}

/// A C caller may pass any address, e.g. a pointer into a packed byte buffer. Rust may not
/// read a float, a ray or a handle from a misaligned one (undefined behaviour; an abort in a
/// build with debug assertions): every such argument is an error naming it, and nothing is
/// written or changed.
#[test]
fn misaligned_pointers_are_errors() {
    unsafe {
        let (ctx, scene) = support::c_unit_sphere(0);
        let c = [0.0f32; 3];
        // 64-byte aligned storage, used one byte in.
        let mut buffer = vec![0u64; 64];
        let odd = buffer.as_mut_ptr().cast::<u8>().add(1);
        let expect_misaligned = |status: Rt2Status, arg: &str| {
            assert_eq!(status, Rt2Status::InvalidArgument, "{arg}");
            let e = last_error();
            assert!(e.contains(arg) && e.contains("not aligned"), "{arg}: {e}");
        };
        expect_misaligned(
            rt2_scene_add_sphere(scene, odd.cast(), 1.0, 0, null_mut()),
            "center",
        );
        expect_misaligned(
            rt2_scene_add_sphere(scene, c.as_ptr(), 1.0, 0, odd.cast()),
            "out_object",
        );
        let mut material_id = 7u32;
        let material = rt2_material_default();
        expect_misaligned(
            rt2_scene_add_material(scene, &material, odd.cast()),
            "out_id",
        );
        let ray = rt2_ray {
            org: [0.0, 0.0, 5.0],
            tmin: 0.0,
            dir: [0.0, 0.0, -1.0],
            tmax: f32::INFINITY,
        };
        // A sentinel hit: no failed query may write it.
        let sentinel = rt2_hit {
            t: -1.0,
            u: 0.0,
            v: 0.0,
            object: 99,
            prim: 99,
        };
        let mut hit = sentinel;
        expect_misaligned(
            rt2_intersect(ctx, scene, odd.cast(), 1, &mut hit, null(), null_mut()),
            "rays",
        );
        expect_misaligned(
            rt2_intersect(ctx, scene, &ray, 1, odd.cast(), null(), null_mut()),
            "hits",
        );
        expect_misaligned(
            rt2_intersect(ctx, odd.cast(), &ray, 1, &mut hit, null(), null_mut()),
            "scene",
        );
        // The statistics are checked before any hit is written.
        expect_misaligned(
            rt2_intersect(ctx, scene, &ray, 1, &mut hit, null(), odd.cast()),
            "stats",
        );
        let mut opt = rt2_query_options_default();
        opt.exclude = odd.cast();
        expect_misaligned(
            rt2_intersect(ctx, scene, &ray, 1, &mut hit, &opt, null_mut()),
            "opt.exclude",
        );
        assert_eq!(hit.t, sentinel.t, "a refused query wrote its hit");
        let mut misaligned_ctx = null_mut();
        expect_misaligned(
            rt2_context_create(odd.cast(), &mut misaligned_ctx),
            "rt2_context_desc",
        );
        assert!(misaligned_ctx.is_null());
        // Ignored, like any pointer that is not a live handle.
        rt2_scene_destroy(odd.cast());
        // The scene is unchanged: one sphere (object 0, no material added), hit at t = 4.
        assert_eq!(
            rt2_scene_add_material(scene, &material, &mut material_id),
            Rt2Status::Ok
        );
        assert_eq!(material_id, 1, "the refused material was not added");
        assert_eq!(rt2_scene_commit(scene), Rt2Status::Ok);
        assert_eq!(
            rt2_intersect(ctx, scene, &ray, 1, &mut hit, null(), null_mut()),
            Rt2Status::Ok
        );
        assert_eq!((hit.object, hit.t), (0, 4.0));
        rt2_scene_destroy(scene);
        rt2_context_destroy(ctx);
    }
}

#[test]
fn failed_edits_leave_the_scene_as_it_was() {
    unsafe {
        let (mut ctx, mut scene) = (null_mut(), null_mut());
        assert_eq!(rt2_context_create(null(), &mut ctx), Rt2Status::Ok);
        assert_eq!(rt2_scene_create(ctx, &mut scene), Rt2Status::Ok);
        let c = [0.0f32, 0.0, 0.0];
        let mut id = 77u32;
        assert_eq!(
            rt2_scene_add_sphere(scene, c.as_ptr(), -1.0, 0, &mut id),
            Rt2Status::InvalidArgument
        );
        assert!(last_error().contains("radius"), "{}", last_error());
        assert_eq!(id, 77, "no id written on failure");
        let nan = [f32::NAN, 0.0, 0.0];
        assert_eq!(
            rt2_scene_add_sphere(scene, nan.as_ptr(), 1.0, 0, &mut id),
            Rt2Status::InvalidArgument
        );
        let positions = [0.0f32, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0];
        let bad = [0u32, 1, 3];
        let status = rt2_scene_add_mesh(scene, positions.as_ptr(), 3, bad.as_ptr(), 1, 0, &mut id);
        assert_eq!(status, Rt2Status::InvalidArgument);
        assert!(last_error().contains("indices[2]"), "{}", last_error());
        assert_eq!(
            rt2_scene_add_sphere(scene, c.as_ptr(), 1.0, 5, &mut id),
            Rt2Status::InvalidArgument
        );
        // Material 0 alone exists yet.
        assert!(
            last_error().contains("material is 5, but the scene's materials are 0 to 0"),
            "{}",
            last_error()
        );
        // The first successful add gets object 0: nothing was added by the failures.
        assert_eq!(
            rt2_scene_add_sphere(scene, c.as_ptr(), 1.0, 0, &mut id),
            Rt2Status::Ok
        );
        assert_eq!(id, 0);
        // A render before commit is an invalid operation, and so is one after a new edit.
        let (mut cam, mut frame) = (null_mut(), null_mut());
        assert_eq!(rt2_camera_create(&mut cam), Rt2Status::Ok);
        assert_eq!(rt2_frame_create(8, 8, &mut frame), Rt2Status::Ok);
        assert_eq!(
            rt2_render(ctx, scene, cam, null(), frame),
            Rt2Status::InvalidOperation
        );
        assert_eq!(rt2_scene_commit(scene), Rt2Status::Ok);
        assert_eq!(rt2_render(ctx, scene, cam, null(), frame), Rt2Status::Ok);
        assert_eq!(
            rt2_scene_add_sphere(scene, c.as_ptr(), 0.5, 0, &mut id),
            Rt2Status::Ok
        );
        assert_eq!(
            rt2_render(ctx, scene, cam, null(), frame),
            Rt2Status::InvalidOperation
        );
        assert!(
            last_error().contains("modified after its last commit"),
            "{}",
            last_error()
        );
        // Unknown enum values in options are rejected, not transmuted.
        let mut opts = rt2_render_options_default();
        opts.traversal = 99;
        assert_eq!(rt2_scene_commit(scene), Rt2Status::Ok);
        assert_eq!(
            rt2_render(ctx, scene, cam, &opts, frame),
            Rt2Status::InvalidArgument
        );
        assert!(last_error().contains("rt2_traversal"), "{}", last_error());
        // Destroying the context first is safe: the scene keeps what it needs alive.
        rt2_context_destroy(ctx);
        assert_eq!(rt2_scene_commit(scene), Rt2Status::Ok);
        rt2_frame_destroy(frame);
        rt2_camera_destroy(cam);
        rt2_scene_destroy(scene);
    }
}

/// Closest hit of one ray through the C API.
unsafe fn hit_of(
    ctx: *mut rt2_context,
    scene: *mut rt2_scene,
    org: [f32; 3],
    dir: [f32; 3],
) -> rt2_hit {
    let ray = rt2_ray {
        org,
        tmin: 0.0,
        dir,
        tmax: f32::INFINITY,
    };
    let mut hit = std::mem::zeroed::<rt2_hit>();
    assert_eq!(
        rt2_intersect(ctx, scene, &ray, 1, &mut hit, null(), null_mut()),
        Rt2Status::Ok
    );
    hit
}

/// Objects that do not fit in f32 once placed in world space are rejected when added or moved
/// (they were counted but never hit: their bounds overflowed and the tree left them out), and
/// shapes whose size is extreme but representable are hit.
#[test]
fn objects_beyond_the_f32_range_are_errors_and_extreme_valid_ones_are_hit() {
    unsafe {
        let (mut ctx, mut scene) = (null_mut(), null_mut());
        assert_eq!(rt2_context_create(null(), &mut ctx), Rt2Status::Ok);
        assert_eq!(rt2_scene_create(ctx, &mut scene), Rt2Status::Ok);
        let mut id = 77u32;
        let far = [3e38f32, 0.0, 0.0];
        assert_eq!(
            rt2_scene_add_sphere(scene, far.as_ptr(), 1e38, 0, &mut id),
            Rt2Status::InvalidArgument
        );
        assert!(
            last_error().contains("does not fit in f32"),
            "{}",
            last_error()
        );
        assert_eq!(id, 77, "no id written on failure");
        let huge = [1e30f32; 3];
        assert_eq!(
            rt2_scene_add_ellipsoid(scene, far.as_ptr(), huge.as_ptr(), 0, &mut id),
            Rt2Status::InvalidArgument
        );
        // A triangle whose edge overflows although its corners are finite.
        let wide = [-3e38f32, 0.0, 0.0, 3e38, 0.0, 0.0, 0.0, 1.0, 0.0];
        let tri = [0u32, 1, 2];
        assert_eq!(
            rt2_scene_add_mesh(scene, wide.as_ptr(), 3, tri.as_ptr(), 1, 0, &mut id),
            Rt2Status::InvalidArgument
        );
        assert!(last_error().contains("triangle 0"), "{}", last_error());
        // Finite corners, edges and edge cross product (every component 2.25e38), but the
        // product of the edge lengths, which bounds Möller–Trumbore's determinant, overflows:
        // missed by almost every ray, so refused.
        let vast = [0.0f32, 0.0, 0.0, 1.5e19, -1.5e19, 0.0, 0.0, 1.5e19, -1.5e19];
        assert_eq!(
            rt2_scene_add_mesh(scene, vast.as_ptr(), 3, tri.as_ptr(), 1, 0, &mut id),
            Rt2Status::InvalidArgument
        );
        assert!(last_error().contains("triangle 0"), "{}", last_error());

        // Valid: a triangle in z = 0, then a move past the f32 range, which is refused.
        let small = [-1.0f32, -1.0, 0.0, 1.0, -1.0, 0.0, 0.0, 1.0, 0.0];
        assert_eq!(
            rt2_scene_add_mesh(scene, small.as_ptr(), 3, tri.as_ptr(), 1, 0, &mut id),
            Rt2Status::Ok
        );
        assert_eq!(id, 0, "nothing was added by the failures");
        // x scaled by 1e38 and moved by 3e38: the corner at x = 1 lands at 4e38.
        let beyond = [
            1e38f32, 0.0, 0.0, 3e38, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0,
        ];
        assert_eq!(
            rt2_scene_set_transform(scene, 0, beyond.as_ptr()),
            Rt2Status::InvalidArgument
        );
        assert!(
            last_error().contains("does not fit in f32"),
            "{}",
            last_error()
        );
        // Extreme but representable: ellipsoid radii 1e13 and 1e-16 (determinants 1e39 and
        // 1e-48), plane normals of length 1e20 and 1e-23 ("any length").
        let (c1, r1) = ([0.0f32, 0.0, 1e14], [1e13f32; 3]);
        let (c2, r2) = ([0.0f32, 0.0, -10.0], [1e-16f32; 3]);
        for (c, r) in [(c1, r1), (c2, r2)] {
            assert_eq!(
                rt2_scene_add_ellipsoid(scene, c.as_ptr(), r.as_ptr(), 0, null_mut()),
                Rt2Status::Ok
            );
        }
        let (n1, n2) = ([1e20f32, 0.0, 0.0], [0.0f32, 1e-23, 0.0]);
        assert_eq!(
            rt2_scene_add_plane(scene, n1.as_ptr(), 1e21, 0, &mut id),
            Rt2Status::Ok
        );
        assert_eq!(id, 3);
        assert_eq!(
            rt2_scene_add_plane(scene, n2.as_ptr(), 4e-23, 0, &mut id),
            Rt2Status::Ok
        );
        assert_eq!(rt2_scene_commit(scene), Rt2Status::Ok);
        let mut st = std::mem::zeroed::<rt2_scene_statistics>();
        st.struct_size = std::mem::size_of::<rt2_scene_statistics>() as u32;
        assert_eq!(rt2_scene_stats(scene, &mut st), Rt2Status::Ok);
        assert_eq!(
            (st.object_count, st.triangle_count, st.ellipsoid_count),
            (5, 1, 2)
        );

        // The triangle kept its place: hit at z = 0 from z = 5.
        let h = hit_of(ctx, scene, [0.0, 0.0, 5.0], [0.0, 0.0, -1.0]);
        assert_eq!((h.object, h.t), (0, 5.0));
        // The big ellipsoid's near side is at z = 9e13.
        let h = hit_of(ctx, scene, [0.0, 0.0, 1.0], [0.0, 0.0, 1.0]);
        assert_eq!(h.object, 1);
        assert!((h.t / 9e13 - 1.0).abs() < 1e-5, "{}", h.t);
        // The tiny one at z = -10, seen from 1e-15 away.
        let h = hit_of(ctx, scene, [0.0, 0.0, -10.0 + 1e-6], [0.0, 0.0, -1.0]);
        assert_eq!(h.object, 2, "t {}", h.t);
        // Plane x = 10 (normal 1e20, offset 1e21) and y = 4 (normal 1e-23, offset 4e-23).
        let h = hit_of(ctx, scene, [5.0, 0.0, 0.0], [1.0, 0.0, 0.0]);
        assert_eq!((h.object, h.t), (3, 5.0));
        let h = hit_of(ctx, scene, [0.0, 1.0, 0.0], [0.0, 1.0, 0.0]);
        assert_eq!((h.object, h.t), (4, 3.0));
        rt2_scene_destroy(scene);
        rt2_context_destroy(ctx);
    }
}

/// The documented limits of the analytic shapes: a sphere's squared radius must be a normal
/// f32 (radii from about 1.1e-19 to 1.8e19), an ellipsoid's squared semi-axes must neither
/// overflow nor vanish (about 2.7e-23 to 1.8e19), a plane's offset over its normal's largest
/// component must be finite. Past them: INVALID_ARGUMENT, nothing added.
#[test]
fn analytic_shapes_are_refused_past_their_documented_limits() {
    unsafe {
        let (mut ctx, mut scene) = (null_mut(), null_mut());
        let mut desc = rt2_context_desc_default();
        desc.backend = Rt2Backend::Cpu as u32;
        assert_eq!(rt2_context_create(&desc, &mut ctx), Rt2Status::Ok);
        assert_eq!(rt2_scene_create(ctx, &mut scene), Rt2Status::Ok);
        let origin = [0.0f32; 3];
        let (o, none) = (origin.as_ptr(), null_mut());
        let fits = |status: Rt2Status| match status {
            Rt2Status::Ok => true,
            Rt2Status::InvalidArgument => {
                assert!(
                    last_error().contains("does not fit in f32"),
                    "{}",
                    last_error()
                );
                false
            }
            other => panic!("{other:?}: {}", last_error()),
        };
        for (radius, expected) in [
            (1.8e19f32, true),
            (1.1e-19, true),
            (1.9e19, false),
            (1e-19, false),
            (1e30, false),
            (1e-45, false),
        ] {
            let added = fits(rt2_scene_add_sphere(scene, o, radius, 0, none));
            assert_eq!(added, expected, "sphere of radius {radius:e}");
        }
        for (axis, expected) in [
            (1.8e19f32, true),
            (2.7e-23, true),
            (1.9e19, false),
            (2.6e-23, false),
        ] {
            let radii = [axis, 1.0, 1.0];
            let added = fits(rt2_scene_add_ellipsoid(scene, o, radii.as_ptr(), 0, none));
            assert_eq!(added, expected, "ellipsoid {radii:?}");
        }
        let short = [1e-45f32, 0.0, 0.0];
        for (offset, expected) in [(1.0f32, false), (0.0, true)] {
            let added = fits(rt2_scene_add_plane(scene, short.as_ptr(), offset, 0, none));
            assert_eq!(added, expected, "plane (1e-45, 0, 0) . x = {offset}");
        }
        assert_eq!(rt2_scene_commit(scene), Rt2Status::Ok);
        let mut st = std::mem::zeroed::<rt2_scene_statistics>();
        st.struct_size = std::mem::size_of::<rt2_scene_statistics>() as u32;
        assert_eq!(rt2_scene_stats(scene, &mut st), Rt2Status::Ok);
        assert_eq!(
            (
                st.object_count,
                st.sphere_count,
                st.ellipsoid_count,
                st.plane_count
            ),
            (5, 2, 2, 1)
        );
        rt2_scene_destroy(scene);
        rt2_context_destroy(ctx);
    }
}

/// Outputs of the queries may not overlap their rays: the hits are written while the rays are
/// read, one step at a time (and Rust may not read what it writes through another borrow).
/// Such a call is an error naming both arrays, and neither is written.
#[test]
fn query_outputs_overlapping_their_rays_are_errors() {
    unsafe {
        let (ctx, scene) = support::c_unit_sphere(0);
        let ray = rt2_ray {
            org: [0.0, 0.0, 5.0],
            tmin: 0.0,
            dir: [0.0, 0.0, -1.0],
            tmax: f32::INFINITY,
        };
        let mut rays = [ray; 4];
        let base = rays.as_mut_ptr();
        let expect_overlap = |status: Rt2Status, out: &str| {
            assert_eq!(status, Rt2Status::InvalidArgument, "{out}");
            let e = last_error();
            assert!(e.contains(&format!("{out} overlaps rays")), "{out}: {e}");
        };
        // The hits over the rays themselves, and from the last ray on (the arrays share 12 bytes).
        for hits in [base.cast::<rt2_hit>(), base.add(3).cast::<rt2_hit>()] {
            let st = rt2_intersect(ctx, scene, base, 4, hits, null(), null_mut());
            expect_overlap(st, "hits");
        }
        let st = rt2_occluded(ctx, scene, base, 4, base.add(1).cast(), null(), null_mut());
        expect_overlap(st, "occluded");
        assert!(rays
            .iter()
            .all(|r| r.org == ray.org && r.dir == ray.dir && r.tmax == ray.tmax));
        // Right after the rays (no byte shared) is fine.
        let mut both = vec![0u64; (4 * std::mem::size_of::<rt2_ray>() + 4 * 20) / 8];
        let rays_at = both.as_mut_ptr().cast::<rt2_ray>();
        for k in 0..4 {
            rays_at.add(k).write(ray);
        }
        let hits_at = rays_at.add(4).cast::<rt2_hit>();
        assert_eq!(
            rt2_intersect(ctx, scene, rays_at, 4, hits_at, null(), null_mut()),
            Rt2Status::Ok,
            "{}",
            last_error()
        );
        assert!((0..4).all(|k| (*hits_at.add(k)).t == 4.0));
        // The statistics, written last, over the rays or the hits: refused before anything is
        // written (rays and hits as they were).
        let hits_before: Vec<rt2_hit> = (0..4).map(|k| *hits_at.add(k)).collect();
        for (stats, over) in [(rays_at.cast(), "rays"), (hits_at.cast(), "hits")] {
            let st = rt2_intersect(ctx, scene, rays_at, 4, hits_at, null(), stats);
            assert_eq!(st, Rt2Status::InvalidArgument, "stats over {over}");
            let e = last_error();
            assert!(e.contains(&format!("stats overlaps {over}")), "{e}");
            assert!((0..4).all(|k| *rays_at.add(k) == ray && *hits_at.add(k) == hits_before[k]));
        }
        rt2_scene_destroy(scene);
        rt2_context_destroy(ctx);
    }
}
