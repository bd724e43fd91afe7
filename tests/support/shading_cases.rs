//! Renders at the edges of the shading model (light, colours or sample counts out of the
//! ordinary range, glass near its critical angle, a surface seen from behind), each with its
//! expected image worked out by hand from the documented shading model (linear values,
//! `round(255 v)`, clamped): run on the CPU by `tests/shading_extremes.rs` and on the GPU by
//! `tests/gpu.rs`. Each case failed before the fix its comment names.

use glam::Vec3;
use rt2::camera::Camera;
use rt2::context::Context;
use rt2::frame::Frame;
use rt2::render::{RenderOptions, Transparency};
use rt2::scene::{Checker, Material, PointLight, Scene, Shape};

/// What a rendered frame must show: `Err` says what is wrong with it.
pub type Check = Box<dyn Fn(&Frame) -> Result<(), String>>;

/// A committed scene, how to look at it, and what the image must show.
pub struct Case {
    pub name: String,
    pub scene: Scene,
    pub camera: Camera,
    pub opts: RenderOptions,
    pub size: (u32, u32),
    pub check: Check,
}

/// Every case.
pub fn cases() -> Vec<Case> {
    let mut all: Vec<Case> = [10.0, 1e19, 2e19, 1e20, 1e30, 3e38]
        .into_iter()
        .map(far_light)
        .collect();
    all.push(faint_mirror());
    all.extend([2, 3, 4, 5, 9, 10].into_iter().map(half_covered_row));
    all.push(light_switched_off());
    all.extend([0.2, 0.52, 0.6, 0.64, 0.7].into_iter().map(leaving_glass));
    all.extend([3.0, -3.0].into_iter().map(checker_seen_from));
    all
}

/// Every case rendered by `ctx` with its options changed by `apply` for each of `variants`
/// (render schedules, GPU paths): what the checks found wrong, one line per render.
pub fn failures<V: std::fmt::Debug + Copy>(
    ctx: &Context,
    variants: &[V],
    apply: impl Fn(RenderOptions, V) -> RenderOptions,
) -> Vec<String> {
    let mut failures = Vec::new();
    for case in cases() {
        for &v in variants {
            let mut frame = Frame::new(case.size.0, case.size.1).unwrap();
            let committed = case.scene.committed().unwrap();
            let opts = apply(case.opts, v);
            ctx.render(committed, &case.camera, &opts, &mut frame)
                .unwrap();
            if let Err(e) = (case.check)(&frame) {
                failures.push(format!("{} ({v:?}): {e}", case.name));
            }
        }
    }
    failures
}

/// The red, green and blue of the centre pixel of a frame of odd size.
fn centre(f: &Frame) -> [u8; 3] {
    let (w, h) = (f.width(), f.height());
    let i = 4 * (h / 2 * w + w / 2) as usize;
    [f.pixels()[i], f.pixels()[i + 1], f.pixels()[i + 2]]
}

/// A check that the centre pixel is grey `v` (linear, in [0, 1]).
fn centre_is(v: f32) -> Check {
    let want = (255.0 * v).round() as u8;
    Box::new(move |f| match centre(f) {
        c if c == [want; 3] => Ok(()),
        c => Err(format!("centre pixel {c:?}, want {want} in every channel")),
    })
}

/// A unit sphere at the origin seen from (0, 0, 5), a committed scene of it in `material`.
fn sphere_in(material: Material, light: Option<PointLight>) -> Scene {
    let sphere = Shape::Sphere {
        center: Vec3::ZERO,
        radius: 1.0,
    };
    scene_of(sphere, material, light)
}

/// A committed scene of `shape` in `material`, lit by `light` if any.
fn scene_of(shape: Shape, material: Material, light: Option<PointLight>) -> Scene {
    let mut s = Scene::new();
    let m = s.add_material(material).unwrap();
    s.add_object(shape, m).unwrap();
    if let Some(l) = light {
        s.add_light(l).unwrap();
    }
    s.commit().unwrap();
    s
}

/// A light `dist` away on the view axis, behind the camera: light does not fall off, so the
/// centre pixel, where the normal faces the light, is ambient + diffuse at any distance:
/// 0.5 · (0.1 + 0.5) = 0.3. Past about 1.8e19 the squared distance overflowed and the light
/// lit nothing (0.05, ambient alone).
fn far_light(dist: f32) -> Case {
    let material = Material {
        color: Vec3::splat(0.5),
        ambient: 0.1,
        diffuse: 0.5,
        specular: 0.0,
        ..Material::default()
    };
    let light = PointLight {
        position: Vec3::new(0.0, 0.0, dist),
        color: Vec3::ONE,
        intensity: 1.0,
    };
    Case {
        name: format!("a light {dist:e} away"),
        scene: sphere_in(material, Some(light)),
        camera: Camera::default(),
        opts: RenderOptions::default(),
        size: (9, 9),
        check: centre_is(0.3),
    }
}

/// A black sphere reflecting 0.0015 of a background of 200: the centre ray comes straight
/// back into the background, 0.0015 · 200 = 0.3. The fixed cut-off of 1/512 of a ray's
/// weight, which assumed radiance at most 1, dropped it (0).
fn faint_mirror() -> Case {
    let material = Material {
        color: Vec3::ZERO,
        reflectivity: 0.0015,
        ..Material::default()
    };
    Case {
        name: "a faint mirror of a bright background".into(),
        scene: sphere_in(material, None),
        camera: Camera::default(),
        opts: RenderOptions {
            background: Vec3::splat(200.0),
            ..RenderOptions::default()
        },
        size: (9, 9),
        check: centre_is(0.3),
    }
}

/// A white wall (ambient 1) below y = 0 ahead of a camera at the origin, on a black
/// background, 16 × 31 pixels: the edge cuts the middle row in half, which `samples` samples
/// a pixel must see half covered (0.5 ± 0.15 over the row). Counts that are not squares put
/// their samples in the first rows of a square grid: 2 samples saw none of the wall (0.0), 3
/// a third, 5 a fifth.
fn half_covered_row(samples: u32) -> Case {
    let mut s = Scene::new();
    let white = Material {
        color: Vec3::ONE,
        ambient: 1.0,
        diffuse: 0.0,
        specular: 0.0,
        ..Material::default()
    };
    let white = s.add_material(white).unwrap();
    let wall = Shape::Mesh {
        positions: vec![
            Vec3::new(-50.0, -50.0, -10.0),
            Vec3::new(50.0, -50.0, -10.0),
            Vec3::new(50.0, 0.0, -10.0),
            Vec3::new(-50.0, 0.0, -10.0),
        ],
        triangles: vec![[0, 1, 2], [0, 2, 3]],
    };
    s.add_object(wall, white).unwrap();
    s.commit().unwrap();
    let mut camera = Camera::default();
    camera.look_at(Vec3::ZERO, -Vec3::Z, Vec3::Y).unwrap();
    Case {
        name: format!("{samples} samples on an edge"),
        scene: s,
        camera,
        opts: RenderOptions {
            samples,
            background: Vec3::ZERO,
            ..RenderOptions::default()
        },
        size: (16, 31),
        check: Box::new(|f| {
            let w = f.width() as usize;
            let row = &f.pixels()[4 * 15 * w..][..4 * w];
            let cover = row.chunks(4).map(|p| p[0] as f64).sum::<f64>() / (255.0 * w as f64);
            match (cover - 0.5).abs() < 0.15 {
                true => Ok(()),
                false => Err(format!("the middle row is {cover:.3} covered, want 0.5")),
            }
        }),
    }
}

/// A light of intensity 0 (and colour 1e10) over a material of colour 1e30: the light adds
/// nothing, and ambient 0.1 · 1e30 is white. The light's term overflowed to infinity before
/// its intensity multiplied it, and inf · 0 = NaN drew the pixel black.
fn light_switched_off() -> Case {
    let material = Material {
        color: Vec3::splat(1e30),
        ..Material::default()
    };
    let light = PointLight {
        position: Vec3::new(0.0, 0.0, 5.0),
        color: Vec3::splat(1e10),
        intensity: 0.0,
    };
    Case {
        name: "a light switched off over a colour of 1e30".into(),
        scene: sphere_in(material, Some(light)),
        camera: Camera::default(),
        opts: RenderOptions::default(),
        size: (9, 9),
        check: centre_is(1.0),
    }
}

/// The share of light a surface between indices `n1` (the ray's side) and `n2` reflects, for
/// incidence sine `sin_i`: Fresnel's equations for unpolarised light, 1 past the critical
/// angle.
fn fresnel(n1: f64, n2: f64, sin_i: f64) -> f64 {
    let sin_t = n1 / n2 * sin_i;
    if sin_t >= 1.0 {
        return 1.0;
    }
    let (ci, ct) = ((1.0 - sin_i * sin_i).sqrt(), (1.0 - sin_t * sin_t).sqrt());
    let rs = ((n1 * ci - n2 * ct) / (n1 * ci + n2 * ct)).powi(2);
    let rp = ((n1 * ct - n2 * ci) / (n1 * ct + n2 * ci)).powi(2);
    (rs + rp) / 2.0
}

/// The eye inside a black glass ball (index 1.5, all light transmitted or reflected), `sin_i`
/// off its centre, looking along -z with a field of view of 0.01°: every ray meets the wall
/// from inside at incidence sine `sin_i`, and with two rays in a chain the pixel is the white
/// background's transmitted share, 1 - F (the reflected ray meets black glass). F must be
/// within 0.025 of Fresnel's (Schlick's approximation stays that close taken with the cosine
/// on the air's side). Taken with the glass side's cosine it stayed at 0.04 up to the
/// critical angle (sine 2/3) and jumped to 1 there: 0.04 at sine 0.64, where Fresnel says 0.23.
fn leaving_glass(sin_i: f32) -> Case {
    let glass = Material {
        color: Vec3::ZERO,
        transparency: 1.0,
        ior: 1.5,
        ..Material::default()
    };
    let mut camera = Camera::default();
    let eye = Vec3::new(sin_i, 0.0, 0.0);
    camera.look_at(eye, eye - Vec3::Z, Vec3::Y).unwrap();
    camera.set_fov(0.01).unwrap();
    let want = 1.0 - fresnel(1.5, 1.0, sin_i as f64);
    Case {
        name: format!("leaving glass at incidence sine {sin_i}"),
        scene: sphere_in(glass, None),
        camera,
        opts: RenderOptions {
            max_depth: 2,
            transparency: Transparency::Refract,
            background: Vec3::ONE,
            ..RenderOptions::default()
        },
        size: (9, 9),
        check: Box::new(move |f| {
            let got = centre(f).map(|c| c as f64 / 255.0);
            match got.iter().all(|g| (g - want).abs() <= 0.025) {
                true => Ok(()),
                false => Err(format!("centre pixel {got:.3?}, want 1 - F = {want:.3}")),
            }
        }),
    }
}

/// The checkered plane y = 0 (normal +y, red and blue squares of side 1, ambient light only)
/// seen straight down or straight up (`eye_y` above or below) at (0.5, 0, 0.5): one square,
/// one colour from both sides, the square behind the normal, (0, -1, 0): blue. Sampled behind
/// the normal turned to the ray, it was blue from above and red from below.
fn checker_seen_from(eye_y: f32) -> Case {
    let (red, blue) = (Vec3::X, Vec3::Z);
    let material = Material {
        color: red,
        ambient: 1.0,
        diffuse: 0.0,
        specular: 0.0,
        checker: Some(Checker {
            color2: blue,
            scale: 1.0,
        }),
        ..Material::default()
    };
    let plane = Shape::Plane {
        normal: Vec3::Y,
        offset: 0.0,
    };
    let s = scene_of(plane, material, None);
    let target = Vec3::new(0.5, 0.0, 0.5);
    let mut camera = Camera::default();
    camera
        .look_at(target + eye_y * Vec3::Y, target, Vec3::Z)
        .unwrap();
    Case {
        name: format!("a checkered plane seen from y = {eye_y}"),
        scene: s,
        camera,
        opts: RenderOptions::default(),
        size: (9, 9),
        check: Box::new(|f| match centre(f) {
            [0, 0, 255] => Ok(()),
            c => Err(format!("centre pixel {c:?}, want blue [0, 0, 255]")),
        }),
    }
}
