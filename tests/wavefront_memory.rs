//! The breadth-first renderer's memory on a scene whose waves double at every depth: nested
//! spheres of a material that both reflects and transmits (each hit spawns two rays) inside a
//! mirror sphere, seen from inside (every ray hits). Traced whole, a 256² frame at depth 8 held
//! its last wave of 65536 × 128 rays at once (1.5 GB); in slices of `WAVE_RAYS` it stays near
//! 200 MB. Alone in its test binary: the peak is the process's (Linux `VmHWM`).

use glam::Vec3;
use rt2::camera::Camera;
use rt2::context::Context;
use rt2::dispatch::BackendRequest;
use rt2::frame::Frame;
use rt2::render::{RenderOptions, Schedule, Transparency};
use rt2::scene::{Material, Scene, Shape};

mod support;

#[test]
#[cfg(target_os = "linux")]
fn doubling_waves_are_traced_in_bounded_slices() {
    let mut scene = Scene::new();
    let half = scene
        .add_material(Material {
            reflectivity: 0.5,
            transparency: 0.5,
            ..Material::default()
        })
        .unwrap();
    let mirror = scene
        .add_material(Material {
            reflectivity: 1.0,
            ..Material::default()
        })
        .unwrap();
    for radius in 1..=5 {
        let sphere = Shape::Sphere {
            center: Vec3::ZERO,
            radius: radius as f32,
        };
        scene.add_object(sphere, half).unwrap();
    }
    let outer = Shape::Sphere {
        center: Vec3::ZERO,
        radius: 10.0,
    };
    scene.add_object(outer, mirror).unwrap();
    scene.commit().unwrap();
    let mut camera = Camera::default();
    camera
        .look_at(Vec3::new(0.0, 0.0, 0.5), Vec3::new(0.0, 0.0, -1.0), Vec3::Y)
        .unwrap();
    let ctx = Context::new(BackendRequest::Cpu, 2).unwrap();
    let opts = RenderOptions {
        max_depth: 8,
        transparency: Transparency::Straight,
        ..RenderOptions::default()
    };
    let render = |schedule| {
        let mut frame = Frame::new(256, 256).unwrap();
        let opts = RenderOptions { schedule, ..opts };
        ctx.render(scene.committed().unwrap(), &camera, &opts, &mut frame)
            .unwrap();
        frame
    };
    let before = support::status_mib("VmHWM:");
    let bf = render(Schedule::BreadthFirst);
    let peak = support::status_mib("VmHWM:");
    println!("peak {peak:.0} MiB (before the render {before:.0} MiB)");
    assert!(
        peak < 600.0,
        "the breadth-first render peaked at {peak:.0} MiB"
    );
    // The slices trace the same rays as depth-first: the same image up to the rounding of a
    // differently ordered sum (tests/schedules.rs).
    let df = render(Schedule::DepthFirst);
    let worst = df
        .pixels()
        .iter()
        .zip(bf.pixels())
        .map(|(a, b)| a.abs_diff(*b))
        .max()
        .unwrap();
    assert!(
        worst <= 1,
        "a channel differs by {worst}/255 from depth-first"
    );
}
