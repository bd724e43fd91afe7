//! Shared by the integration tests: for those that compile C against `include/rt2.h` or load
//! the built shared library, where the library is and a `cc` compiler configured outside
//! build.rs; the shared folder's files; the memory tests' reading of `/proc/self/status`; the
//! fork tests' wait for a child; the C API tests' smallest scene and meshes; rays around a
//! target and the sequence behind them; whether a GPU context can be had; renders of shading
//! extremes (`shading_cases`); the tests' random numbers (`rng`); spheres and ellipsoids far
//! from the origin with their shading worked out in f64; a nearly singular transform that a
//! scene graph makes (`needle`).

#![allow(dead_code)]

pub mod any_hit_stats;
pub mod rng;
pub mod shading_cases;

use glam::{Affine3A, DVec3, Quat, Vec3};

use std::path::{Path, PathBuf};

/// `rt2_last_error_message()` of this thread, as a `String`.
pub fn last_error() -> String {
    // SAFETY: the library returns a NUL-terminated message valid until its next call here.
    unsafe { std::ffi::CStr::from_ptr(rt2::api::rt2_last_error_message()) }
        .to_string_lossy()
        .into_owned()
}

/// Asserts that a C API call succeeded, with its message if it did not.
pub fn ok(status: rt2::error::Rt2Status) {
    assert_eq!(status, rt2::error::Rt2Status::Ok, "{}", last_error());
}

/// Adds the triangle mesh of `positions` (x, y, z each) and `indices` (three per triangle) to
/// `scene` with material 0, and returns its object id.
///
/// # Safety
/// `scene` is a live scene.
pub unsafe fn add_mesh(scene: *mut rt2::api::rt2_scene, positions: &[f32], indices: &[u32]) -> u32 {
    let mut id = u32::MAX;
    ok(rt2::api::rt2_scene_add_mesh(
        scene,
        positions.as_ptr(),
        positions.len() / 3,
        indices.as_ptr(),
        indices.len() / 3,
        0,
        &mut id,
    ));
    id
}

/// `target/<profile>/deps`, where the test executable lives.
fn deps_dir() -> PathBuf {
    let exe = std::env::current_exe().expect("the test knows its own path");
    exe.parent()
        .expect("the test executable has a parent directory")
        .to_path_buf()
}

/// The shared library this `cargo test` run built, e.g. `target/debug/deps/librt2.so`.
///
/// `cargo test` compiles the library with all its crate types (cdylib included) into
/// `target/<profile>/deps`, next to the test executable, but only `cargo build` copies it up
/// to `target/<profile>/librt2.so`: that copy can be older than the sources under test, so it
/// is used only when `deps/` has none. Panics with both paths if neither exists.
pub fn shared_library() -> PathBuf {
    let name = format!(
        "{}rt2{}",
        std::env::consts::DLL_PREFIX,
        std::env::consts::DLL_SUFFIX
    );
    let deps = deps_dir();
    let fresh = deps.join(&name);
    if fresh.is_file() {
        return fresh;
    }
    let uplifted = deps
        .parent()
        .expect("target/<profile>/deps has a parent")
        .join(&name);
    assert!(
        uplifted.is_file(),
        "neither {} nor {} exists: the crate's cdylib is built by `cargo test` / `cargo build`",
        fresh.display(),
        uplifted.display()
    );
    uplifted
}

pub fn manifest_dir() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// Scratch space for this test binary (Cargo creates `target/tmp` for integration tests).
pub fn scratch(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join(name);
    std::fs::create_dir_all(&dir).expect("create a scratch directory under target/tmp");
    dir
}

/// The triple of the machine running the tests: the C code runs here, so target = host.
fn host_triple() -> String {
    let arch = std::env::consts::ARCH;
    match std::env::consts::OS {
        "linux" if cfg!(target_env = "musl") => format!("{arch}-unknown-linux-musl"),
        "linux" => format!("{arch}-unknown-linux-gnu"),
        "macos" => format!("{arch}-apple-darwin"),
        os => panic!("the C test harness supports Linux and macOS, not {os}"),
    }
}

/// A `cc` build for C (or C++ with `cpp`). Outside build.rs Cargo sets none of TARGET, HOST,
/// OPT_LEVEL or OUT_DIR, so they are given explicitly; no cargo: lines are printed.
pub fn compiler(cpp: bool, out_dir: &Path) -> cc::Tool {
    let triple = host_triple();
    cc::Build::new()
        .cpp(cpp)
        .target(&triple)
        .host(&triple)
        .opt_level(1)
        .debug(true)
        .warnings(false)
        .out_dir(out_dir)
        .cargo_metadata(false)
        .emit_rerun_if_env_changed(false)
        .get_compiler()
}

/// The shared folder beside the project (models, ray sets with Embree's hits): `$RT2_SHARED`,
/// by default `../shared` next to the crate.
pub fn shared_dir() -> PathBuf {
    std::env::var_os("RT2_SHARED")
        .map(PathBuf::from)
        .unwrap_or_else(|| manifest_dir().join("../shared"))
}

/// `rel` (a file or folder of the shared folder) when it exists. When it does not, the caller
/// skips its check after a SKIPPED line naming the path, or, with `RT2_REQUIRE_SHARED=1`, the
/// test fails: CI sets it, so that the checks against Embree's hits and the real models cannot
/// pass by skipping (libtest hides a passing test's SKIPPED line).
pub fn shared_path(rel: &str) -> Option<PathBuf> {
    let path = shared_dir().join(rel);
    if path.exists() {
        return Some(path);
    }
    assert!(
        std::env::var("RT2_REQUIRE_SHARED").as_deref() != Ok("1"),
        "{} is missing and RT2_REQUIRE_SHARED=1 (set RT2_SHARED to the shared folder)",
        path.display()
    );
    eprintln!(
        "SKIPPED: {} is missing (set RT2_SHARED to the shared folder)",
        path.display()
    );
    None
}

/// A field of this process's `/proc/self/status` in MiB (`VmRSS`, `VmHWM`, `VmSize`): the
/// memory tests, each alone in its test binary, read the process's own figures.
pub fn status_mib(field: &str) -> f64 {
    let status = std::fs::read_to_string("/proc/self/status").expect("Linux /proc");
    let kib: f64 = status
        .lines()
        .find_map(|l| l.strip_prefix(field))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
        .unwrap_or_else(|| panic!("{field} in /proc/self/status"));
    kib / 1024.0
}

/// Waits for the forked child `pid`: `None` if it exited with status 0, else how it failed:
/// its exit status, also in binary (`meaning` says what it counts or what each bit means), or
/// the signal that killed it (14, the child's alarm: a hang).
#[cfg(unix)]
pub fn child_failure(pid: i32, meaning: &str) -> Option<String> {
    let mut status = 0;
    assert_eq!(
        unsafe { libc::waitpid(pid, &mut status, 0) },
        pid,
        "waitpid"
    );
    if libc::WIFEXITED(status) {
        let code = libc::WEXITSTATUS(status);
        (code != 0).then(|| format!("exited with status {code} = {code:#b} ({meaning})"))
    } else {
        Some(format!(
            "was killed by signal {} (14, its alarm: a hang)",
            libc::WTERMSIG(status)
        ))
    }
}

/// A CPU context of `threads` workers (0: one per core) and an empty scene, through the C API.
///
/// # Safety
/// The caller destroys both handles.
pub unsafe fn c_cpu_scene(threads: u32) -> (*mut rt2::api::rt2_context, *mut rt2::api::rt2_scene) {
    use rt2::api::*;
    use rt2::error::Rt2Status;
    let mut desc = rt2_context_desc_default();
    desc.backend = 1;
    desc.threads = threads;
    let (mut ctx, mut scene) = (std::ptr::null_mut(), std::ptr::null_mut());
    assert_eq!(rt2_context_create(&desc, &mut ctx), Rt2Status::Ok);
    assert_eq!(rt2_scene_create(ctx, &mut scene), Rt2Status::Ok);
    (ctx, scene)
}

/// A CPU context of `threads` workers (0: one per core) and a committed scene of a unit sphere
/// at the origin, through the C API.
///
/// # Safety
/// The caller destroys both handles.
pub unsafe fn c_unit_sphere(
    threads: u32,
) -> (*mut rt2::api::rt2_context, *mut rt2::api::rt2_scene) {
    use rt2::api::*;
    use rt2::error::Rt2Status;
    let (ctx, scene) = c_cpu_scene(threads);
    let centre = [0.0f32; 3];
    let status = rt2_scene_add_sphere(scene, centre.as_ptr(), 1.0, 0, std::ptr::null_mut());
    assert_eq!(status, Rt2Status::Ok);
    assert_eq!(rt2_scene_commit(scene), Rt2Status::Ok);
    (ctx, scene)
}

/// `n` rays (origin, direction) from a sphere of radius `dist` around `target` towards points
/// within `spread` of it, from a xorshift sequence seeded by `seed`: most hit an object there,
/// many miss, some graze.
pub fn rays_around(
    target: glam::Vec3,
    dist: f32,
    spread: f32,
    n: usize,
    seed: u64,
) -> Vec<(glam::Vec3, glam::Vec3)> {
    use glam::Vec3;
    let mut uniform = uniform(seed);
    let mut next = move || uniform() as f32;
    (0..n)
        .map(|_| {
            let from = Vec3::new(next(), next(), next()).normalize_or(Vec3::X) * dist;
            let to = Vec3::new(next(), next(), next()) * spread;
            (target + from, to - from)
        })
        .collect()
}

/// A xorshift sequence seeded by `seed` (not 0), uniform in [-1, 1) on a grid of 2^-23: every
/// value is exact in f32 as well.
pub fn uniform(seed: u64) -> impl FnMut() -> f64 {
    let mut state = seed;
    move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 40) as f64 / (1u64 << 24) as f64 * 2.0 - 1.0
    }
}

/// Whether a GPU context can be made through the C API. Without one it prints SKIPPED and
/// returns false, or fails under `RT2_REQUIRE_GPU=1` (CI runs the GPU tests on lavapipe).
pub fn c_gpu_or_skip() -> bool {
    use rt2::api::*;
    let mut desc = rt2_context_desc_default();
    desc.backend = Rt2Backend::Gpu as u32;
    let mut probe = std::ptr::null_mut();
    // SAFETY: a default descriptor and an out pointer to a local; the context is destroyed.
    unsafe {
        if rt2_context_create(&desc, &mut probe) == rt2::error::Rt2Status::Ok {
            rt2_context_destroy(probe);
            return true;
        }
        let why = std::ffi::CStr::from_ptr(rt2_last_error_message()).to_string_lossy();
        assert!(
            std::env::var("RT2_REQUIRE_GPU").as_deref() != Ok("1"),
            "RT2_REQUIRE_GPU=1 but no GPU: {why}"
        );
        eprintln!("SKIPPED (no GPU adapter): {why}");
    }
    false
}

/// A sphere or rotated ellipsoid placed `distance` from the origin, alone, lit by one light and
/// seen from a few radii away, with its image worked out here in f64 (`expected`, RGBA8, `SIZE`)
/// for the shading tests far from the origin (`tests/render_reference.rs`, `tests/gpu.rs`).
pub struct FarShape {
    pub name: String,
    pub scene: rt2::scene::Scene,
    pub camera: rt2::camera::Camera,
    pub expected: Vec<u8>,
    /// The image `center + rot (radii * s)` of the unit sphere.
    center: glam::DVec3,
    rot: glam::DQuat,
    radii: glam::DVec3,
}

impl FarShape {
    /// The ray's first hit in front of `org` in f64: its `t` and the outward unit normal. In
    /// the shape's own axes, scaled to the unit sphere: exact to f64 rounding.
    pub fn hit(&self, org: glam::DVec3, dir: glam::DVec3) -> Option<(f64, glam::DVec3)> {
        let back = self.rot.inverse();
        let (o, du) = (
            back * (org - self.center) / self.radii,
            back * dir / self.radii,
        );
        let (a, b, c) = (du.dot(du), o.dot(du), o.dot(o) - 1.0);
        let disc = b * b - a * c;
        let t = (-b - disc.sqrt()) / a;
        (disc >= 0.0 && t > 0.0).then(|| (t, (self.rot * ((o + t * du) / self.radii)).normalize()))
    }
}

/// Width and height of a [`FarShape`]'s image.
pub const FAR_SIZE: (u32, u32) = (64, 48);

/// A unit sphere and an ellipsoid of radii (1.5, 0.4, 0.8) rotated 0.9 rad about (1, 2, 0.5),
/// 1e4 and 1e6 from the origin, the ellipsoid placed by a transform. Their material is plain
/// Phong (ambient, diffuse, a sharp highlight: normal errors show most there). The reference
/// traces each pixel's pinhole ray in f64 from the same f32 eye, hits the quadric relative to
/// its centre (the rotation undone, the radii divided out: exact to f64 rounding), and shades
/// by the documented model (a miss takes the default background): ambient plus Phong for the light, which nothing shadows (the
/// shape is convex and alone: where it faces the light, the shadow ray leaves it outward).
pub fn far_shapes() -> Vec<FarShape> {
    use glam::{Affine3A, DQuat, DVec3, Vec3};
    use rt2::scene::{Material, PointLight, Scene, Shape};
    let material = Material {
        color: Vec3::new(0.9, 0.6, 0.3),
        ambient: 0.1,
        diffuse: 0.7,
        specular: 0.5,
        shininess: 20.0,
        ..Material::default()
    };
    let mut out = Vec::new();
    for distance in [1e4f32, 1e6] {
        for ellipsoid in [false, true] {
            let c = Vec3::new(0.6, 0.48, 0.64) * distance;
            let rot = DQuat::from_axis_angle(DVec3::new(1.0, 2.0, 0.5).normalize(), 0.9);
            let radii = if ellipsoid {
                DVec3::new(1.5, 0.4, 0.8)
            } else {
                DVec3::ONE
            };
            let light = PointLight {
                position: c + Vec3::new(3.0, 4.0, 5.0),
                color: Vec3::ONE,
                intensity: 1.0,
            };
            let eye = c + Vec3::new(-1.5, 1.2, 3.5);
            let mut scene = Scene::new();
            let m = scene.add_material(material).unwrap();
            if ellipsoid {
                let shape = Shape::Ellipsoid {
                    center: Vec3::ZERO,
                    radii: radii.as_vec3(),
                };
                let id = scene.add_object(shape, m).unwrap();
                let place = Affine3A::from_rotation_translation(rot.as_quat(), c);
                scene.set_transform(id, place).unwrap();
            } else {
                let shape = Shape::Sphere {
                    center: c,
                    radius: 1.0,
                };
                scene.add_object(shape, m).unwrap();
            }
            scene.add_light(light).unwrap();
            scene.commit().unwrap();
            let mut camera = rt2::camera::Camera::default();
            camera.look_at(eye, c, Vec3::Y).unwrap();
            camera.set_fov(40.0).unwrap();

            let shape = if ellipsoid {
                "ellipsoid"
            } else {
                "unit sphere"
            };
            let mut far = FarShape {
                name: format!("{shape} at {distance:e}"),
                scene,
                camera,
                expected: Vec::new(),
                center: c.as_dvec3(),
                rot,
                radii,
            };
            let (w, h) = FAR_SIZE;
            let eye = eye.as_dvec3();
            let fwd = (far.center - eye).normalize();
            let right = fwd.cross(DVec3::Y).normalize();
            let up = right.cross(fwd);
            let hh = (40f64.to_radians() / 2.0).tan();
            let hw = hh * w as f64 / h as f64;
            let d = |v: Vec3| v.as_dvec3();
            for y in 0..h {
                for x in 0..w {
                    let nx = 2.0 * (x as f64 + 0.5) / w as f64 - 1.0;
                    let ny = 1.0 - 2.0 * (y as f64 + 0.5) / h as f64;
                    let dir = (fwd + nx * hw * right + ny * hh * up).normalize();
                    let color = match far.hit(eye, dir) {
                        None => d(rt2::render::RenderOptions::default().background),
                        Some((t, n)) => {
                            let p = eye + t * dir;
                            let base = d(material.color);
                            let mut color = material.ambient as f64 * base;
                            let l = (d(light.position) - p).normalize();
                            let ndotl = n.dot(l);
                            if ndotl > 0.0 {
                                let r = -l - 2.0 * (-l).dot(n) * n;
                                let spec = r.dot(-dir).max(0.0).powf(material.shininess as f64);
                                color += material.diffuse as f64 * ndotl * base
                                    + DVec3::splat(material.specular as f64 * spec);
                            }
                            color
                        }
                    };
                    let c = color.clamp(DVec3::ZERO, DVec3::ONE) * 255.0 + 0.5;
                    far.expected
                        .extend_from_slice(&[c.x as u8, c.y as u8, c.z as u8, 255]);
                }
            }
            out.push(far);
        }
    }
    out
}

/// The mean and largest difference of `pixels` from `expected`, in 8-bit steps over every
/// channel of every pixel, and how many pixels (RGBA) have a channel more than `steps` off.
pub fn pixel_difference(pixels: &[u8], expected: &[u8], steps: u8) -> (f64, u8, usize) {
    let d: Vec<u8> = pixels
        .iter()
        .zip(expected)
        .map(|(a, b)| a.abs_diff(*b))
        .collect();
    let mean = d.iter().map(|&x| x as f64).sum::<f64>() / d.len() as f64;
    let off = d.chunks(4).filter(|p| p.iter().any(|&x| x > steps)).count();
    (mean, d.into_iter().max().unwrap_or(0), off)
}

/// A thin scale between two rotations, as a scene graph makes it (a parent's rotation, a
/// child's scale of `e` on two axes, the child's rotation): nearly singular in f32, whose
/// determinant there comes out -1.4e-10 at `e` = 1e-5 where the matrix's is +1.0e-10 (the
/// rotations' determinants are 1). Returns the transform and the world image of its long
/// axis (unit length, in f64).
pub fn needle(e: f32) -> (Affine3A, DVec3) {
    let r1 = Quat::from_axis_angle(Vec3::new(1.0, 1.0, 0.3).normalize(), 0.7);
    let r2 = Quat::from_axis_angle(Vec3::new(-0.2, 1.0, 0.5).normalize(), 1.9);
    let t = Affine3A::from_quat(r1)
        * Affine3A::from_scale(Vec3::new(e, e, 1.0))
        * Affine3A::from_quat(r2);
    (t, r1.as_dquat() * DVec3::Z)
}
