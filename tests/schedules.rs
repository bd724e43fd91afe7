//! The breadth-first (wavefront, stream-traced) Whitted renderer against the depth-first one.
//! Both trace the same rays, find the same hits (streams are bit-identical to single rays) and
//! shade them with the same code; only the order in which a pixel's terms are summed differs, and
//! float addition is not associative. So a channel may round to the neighbouring 1/255 step: the
//! pass mark is |Δ| ≤ 1 on every channel and Δ ≠ 0 on at most 0.1% of the pixels. A frame with
//! more samples than one wavefront run holds is rendered in runs of pixels, checked the same way.

use rt2::context::Context;
use rt2::dispatch::BackendRequest;
use rt2::frame::Frame;
use rt2::render::{RenderOptions, Schedule, Transparency};
use rt2::scene::builtin;

fn render(name: &str, opts: &RenderOptions, w: u32, h: u32) -> Frame {
    let mut b = builtin::by_name(name).unwrap();
    b.scene.commit().unwrap();
    let mut frame = Frame::new(w, h).unwrap();
    let ctx = Context::new(BackendRequest::Cpu, 2).unwrap();
    ctx.render(b.scene.committed().unwrap(), &b.camera, opts, &mut frame)
        .unwrap();
    frame
}

#[test]
fn breadth_first_matches_depth_first() {
    for (name, samples, transparency) in [
        ("default", 1, Transparency::Refract),
        ("default", 2, Transparency::Straight),
        ("spheres2", 1, Transparency::Refract),
        ("spheres3", 1, Transparency::Refract),
        // 30000 pixels × 40 samples: more than one wavefront run (`WAVE_PATHS`, 2^20 samples),
        // so the runs' pixels must land where depth-first puts them.
        ("spheres2", 40, Transparency::Refract),
    ] {
        let max_depth = builtin::by_name(name).unwrap().max_depth;
        let opts = RenderOptions {
            max_depth,
            samples,
            transparency,
            ..RenderOptions::default()
        };
        let (w, h) = (200, 150);
        let df = render(name, &opts, w, h);
        let bf = render(
            name,
            &RenderOptions {
                schedule: Schedule::BreadthFirst,
                ..opts
            },
            w,
            h,
        );
        let mut differing = 0;
        for (i, (a, b)) in df.pixels().chunks(4).zip(bf.pixels().chunks(4)).enumerate() {
            let worst = a.iter().zip(b).map(|(x, y)| x.abs_diff(*y)).max().unwrap();
            assert!(worst <= 1, "{name}: pixel {i} is {b:?}, depth-first {a:?}");
            differing += (worst > 0) as usize;
        }
        let allowed = (w * h) as usize / 1000;
        println!("{name}, {samples} spp: {differing} pixels differ by 1/255 (allowed {allowed})");
        assert!(differing <= allowed, "{name}: {differing} pixels differ");
    }
}

/// Out-of-range render options are refused by the context itself, so the CLI and Rust callers
/// get the C API's errors; the frame is left untouched. (`max_depth` 2^32 - 1 used to abort on
/// a 400 GB allocation, 2^32 - 1 samples to run for ever, 0 samples to draw black.)
#[test]
fn render_options_out_of_range_are_refused_by_the_context() {
    let mut b = builtin::by_name("spheres2").unwrap();
    b.scene.commit().unwrap();
    let ctx = Context::new(BackendRequest::Cpu, 2).unwrap();
    let d = RenderOptions::default();
    for (what, opts) in [
        ("max_depth", RenderOptions { max_depth: 0, ..d }),
        ("max_depth", RenderOptions { max_depth: 65, ..d }),
        (
            "max_depth",
            RenderOptions {
                max_depth: u32::MAX,
                ..d
            },
        ),
        ("samples", RenderOptions { samples: 0, ..d }),
        (
            "samples",
            RenderOptions {
                samples: u32::MAX,
                ..d
            },
        ),
        (
            "short_stack_size",
            RenderOptions {
                short_stack_size: 0,
                ..d
            },
        ),
        // The traversal holds 32 entries (`MAX_SHORT_STACK`); 33 to 64 were accepted and
        // silently run as 32.
        (
            "short_stack_size",
            RenderOptions {
                short_stack_size: 33,
                ..d
            },
        ),
        (
            "background",
            RenderOptions {
                background: glam::Vec3::NAN,
                ..d
            },
        ),
    ] {
        for schedule in [Schedule::DepthFirst, Schedule::BreadthFirst] {
            let opts = RenderOptions { schedule, ..opts };
            let mut frame = Frame::new(8, 8).unwrap();
            let e = ctx
                .render(b.scene.committed().unwrap(), &b.camera, &opts, &mut frame)
                .expect_err(what);
            assert_eq!(e.status, rt2::error::Rt2Status::InvalidArgument, "{what}");
            assert!(e.message.contains(what), "{what}: {}", e.message);
            assert!(
                frame.pixels().iter().all(|&p| p == 0),
                "{what}: frame written"
            );
        }
    }
}

/// A HUD mask on the CPU, in both schedules and with one and several samples: masked pixels
/// keep what the frame held, and every other pixel is exactly what an unmasked render of the
/// same schedule draws (a pixel's samples do not depend on its neighbours being traced).
#[test]
fn masked_pixels_are_left_alone_and_the_rest_are_rendered_as_without_a_mask() {
    let (w, h) = (64u32, 48u32);
    // Every 7th pixel is masked, and a whole band of rows, so both lone pixels and runs
    // longer than a breadth-first run's row are skipped.
    let mask: Vec<u8> = (0..w * h)
        .map(|i| (i % 7 != 0 && !(20..26).contains(&(i / w))) as u8)
        .collect();
    let masked = mask.iter().filter(|&&m| m == 0).count();
    assert!(masked > 400, "{masked}");
    for schedule in [Schedule::DepthFirst, Schedule::BreadthFirst] {
        for samples in [1, 2] {
            let opts = RenderOptions {
                samples,
                schedule,
                ..RenderOptions::default()
            };
            let full = render("default", &opts, w, h);
            let mut b = builtin::by_name("default").unwrap();
            b.scene.commit().unwrap();
            let mut f = Frame::new(w, h).unwrap();
            f.pixels_mut().fill(7);
            f.set_mask(Some(&mask)).unwrap();
            let ctx = Context::new(BackendRequest::Cpu, 2).unwrap();
            ctx.render(b.scene.committed().unwrap(), &b.camera, &opts, &mut f)
                .unwrap();
            let pairs = f.pixels().chunks(4).zip(full.pixels().chunks(4));
            for (i, (px, want)) in pairs.enumerate() {
                let expected = if mask[i] == 0 { &[7u8; 4][..] } else { want };
                assert_eq!(px, expected, "{schedule:?}, {samples} spp, pixel {i}");
            }
        }
    }
}
