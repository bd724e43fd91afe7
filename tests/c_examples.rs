//! Compiles the C examples in `c_examples/` against `include/rt2.h` with the `cc` crate, links
//! them to the cdylib that `cargo test` built (`target/<profile>/deps/librt2.so`, through an
//! rpath), runs them and checks their exit codes, their output and the PNGs they write.
//!
//! `load_model` renders `$RT2_SHARED/models/bunny.ply` (`RT2_SHARED` defaults to `../shared`
//! next to the crate); if that file is absent the case says so and is skipped.
//!
//! Set `RT2_SANITIZE=valgrind` to run every example under
//! `valgrind --error-exitcode=99 --leak-check=full --errors-for-leak-kinds=definite,indirect,possible`
//! with `scripts/valgrind.supp` (reports that are not RT2's, each with its reason, among them
//! crossbeam-epoch's records of exited rayon workers, "possibly lost"): a memory error or a
//! leak then makes the example exit with 99 and the test fail with valgrind's report, as
//! `scripts/sanitize.sh` counts them.
//! (`load_model` renders 69k triangles; under valgrind that takes minutes.)

mod support;

use image::RgbaImage;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// Compiles `c_examples/<name>.c` into an executable in the scratch directory.
fn build_example(name: &str) -> PathBuf {
    build_example_as(name, name)
}

/// [`build_example`] into the executable `exe_name`: tests that run at the same time must not
/// rewrite each other's executable.
fn build_example_as(name: &str, exe_name: &str) -> PathBuf {
    let source = support::manifest_dir()
        .join("c_examples")
        .join(format!("{name}.c"));
    build_c(&source, exe_name)
}

/// Compiles the C file `source` with the examples' flags (C99, warnings as errors) into the
/// executable `exe_name` in the scratch directory.
fn build_c(source: &Path, exe_name: &str) -> PathBuf {
    let dir = support::scratch("c_examples");
    let lib_dir = support::shared_library()
        .parent()
        .expect("library directory")
        .to_path_buf();
    let exe = dir.join(exe_name);
    let tool = support::compiler(false, &dir);
    let mut cmd = tool.to_command();
    cmd.args(["-std=c99", "-Wall", "-Wextra", "-Wpedantic", "-Werror"])
        .arg("-I")
        .arg(support::manifest_dir().join("include"))
        .arg(source)
        .arg("-o")
        .arg(&exe)
        .arg(format!("-L{}", lib_dir.display()))
        .arg("-lrt2")
        .arg(format!("-Wl,-rpath,{}", lib_dir.display()))
        .arg("-lm");
    let out = cmd
        .output()
        .unwrap_or_else(|e| panic!("cannot run the C compiler {:?}: {e}", tool.path()));
    assert!(
        out.status.success(),
        "compiling {} failed:\n{}{}",
        source.display(),
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    exe
}

/// Runs an example (under valgrind if `RT2_SANITIZE=valgrind`) and returns its output.
fn run(exe: &Path, args: &[&std::ffi::OsStr]) -> Output {
    run_with(exe, args, &[])
}

/// [`run`] with extra environment variables (e.g. `RT2_BACKEND`).
fn run_with(exe: &Path, args: &[&std::ffi::OsStr], env: &[(&str, &str)]) -> Output {
    let mut cmd = match std::env::var("RT2_SANITIZE").as_deref() {
        Ok("valgrind") => {
            let mut c = Command::new("valgrind");
            c.args([
                "--error-exitcode=99",
                "--leak-check=full",
                "--errors-for-leak-kinds=definite,indirect,possible",
                "--quiet",
            ])
            .arg(format!(
                "--suppressions={}",
                support::manifest_dir()
                    .join("scripts/valgrind.supp")
                    .display()
            ))
            .arg(exe);
            c
        }
        Ok("") | Err(_) => Command::new(exe),
        Ok(other) => panic!("RT2_SANITIZE={other} is not supported (only \"valgrind\")"),
    };
    // Two workers keep runs of several test binaries at once from oversubscribing the machine.
    cmd.args(args)
        .env("RAYON_NUM_THREADS", "2")
        .envs(env.iter().copied());
    // Cargo's LD_LIBRARY_PATH for tests also lists target/<profile>, whose librt2.so is only
    // refreshed by `cargo build` and would win over the rpath: name the library's own directory.
    let lib_dir = support::shared_library()
        .parent()
        .expect("library directory")
        .to_path_buf();
    let var = if cfg!(target_os = "macos") {
        "DYLD_LIBRARY_PATH"
    } else {
        "LD_LIBRARY_PATH"
    };
    cmd.env(var, lib_dir);
    let out = cmd
        .output()
        .unwrap_or_else(|e| panic!("cannot run {}: {e}", exe.display()));
    println!(
        "--- {} stdout:\n{}",
        exe.display(),
        String::from_utf8_lossy(&out.stdout)
    );
    println!(
        "--- {} stderr:\n{}",
        exe.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

fn assert_exit(out: &Output, want: i32, what: &str) {
    assert_eq!(
        out.status.code(),
        Some(want),
        "{what} exited with {:?}, expected {want} (99 = valgrind found errors)\nstdout:\n{}\nstderr:\n{}",
        out.status,
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}

fn stdout(out: &Output) -> String {
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// Mean RGB of the `r`-pixel square around (x, y).
fn patch_mean(img: &RgbaImage, x: u32, y: u32, r: u32) -> [f32; 3] {
    let mut sum = [0f32; 3];
    let mut n = 0f32;
    for py in y.saturating_sub(r)..=(y + r).min(img.height() - 1) {
        for px in x.saturating_sub(r)..=(x + r).min(img.width() - 1) {
            let p = img.get_pixel(px, py).0;
            for k in 0..3 {
                sum[k] += p[k] as f32;
            }
            n += 1.0;
        }
    }
    sum.map(|s| s / n)
}

#[test]
fn minimal_renders_the_triangle() {
    let exe = build_example("minimal");
    let out = run(&exe, &[]);
    assert_exit(&out, 0, "minimal");
    let text = stdout(&out);
    // "centre pixel (32, 24): r=R g=G b=B a=A"
    let line = text
        .lines()
        .find(|l| l.starts_with("centre pixel"))
        .expect("minimal prints the centre pixel");
    let value = |key: &str| -> u32 {
        let rest = &line[line
            .find(key)
            .unwrap_or_else(|| panic!("no {key} in {line:?}"))
            + key.len()..];
        rest.split_whitespace()
            .next()
            .and_then(|v| v.parse().ok())
            .unwrap_or_else(|| panic!("bad {key} in {line:?}"))
    };
    let (r, g, b) = (value("r="), value("g="), value("b="));
    // The background is pure blue (0, 0, 255) and the default material grey: a grey pixel with
    // some red is the triangle.
    assert!(
        r > 0 && r == g && r == b,
        "centre pixel {r},{g},{b} is not the grey triangle"
    );
}

/// The README's C example as a user copies it (its image written into scratch space): it
/// compiles without a warning, runs, and draws its red sphere in the middle of the image over
/// a grey floor.
#[test]
fn readme_c_example_renders_the_red_sphere() {
    let readme =
        std::fs::read_to_string(support::manifest_dir().join("README.md")).expect("read README.md");
    let code = readme
        .split("```c\n")
        .nth(1)
        .and_then(|rest| rest.split("```").next())
        .expect("README.md has a C example");
    let dir = support::scratch("c_examples");
    let png = dir.join("readme_demo.png");
    assert!(code.contains("\"demo.png\""), "the example writes demo.png");
    let code = code.replace("\"demo.png\"", &format!("{:?}", png.display().to_string()));
    let source = dir.join("readme_demo.c");
    std::fs::write(&source, code).expect("write the example");
    let _ = std::fs::remove_file(&png);
    let exe = build_c(&source, "readme_demo");
    assert_exit(&run(&exe, &[]), 0, "the README's example");
    let img = image::open(&png)
        .expect("the example wrote its PNG")
        .to_rgba8();
    assert_eq!(img.dimensions(), (640, 360));
    let [r, g, b] = patch_mean(&img, 320, 180, 3);
    assert!(
        r > 2.0 * g && r > 2.0 * b,
        "centre {r},{g},{b} is not the red sphere"
    );
    let [r, g, b] = patch_mean(&img, 320, 350, 3);
    assert!(
        (r - g).abs() < 8.0 && (g - b).abs() < 8.0 && r > 20.0,
        "floor {r},{g},{b}"
    );
}

/// The scene of spheres.c: eye, target, vertical field of view and image size.
const EYE: [f32; 3] = [0.0, 2.0, 7.0];
const TARGET: [f32; 3] = [0.0, 0.75, 0.0];
const FOV_Y: f32 = 45.0;
const SIZE: (u32, u32) = (640, 360);
const SKY: [f32; 3] = [0.2 * 255.0, 0.3 * 255.0, 0.5 * 255.0];

/// Pixel where a world point projects through spheres.c's pinhole camera (up = +y).
fn project(p: [f32; 3]) -> (u32, u32) {
    let sub = |a: [f32; 3], b: [f32; 3]| [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
    let dot = |a: [f32; 3], b: [f32; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    let cross = |a: [f32; 3], b: [f32; 3]| {
        [
            a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0],
        ]
    };
    let norm = |a: [f32; 3]| {
        let l = dot(a, a).sqrt();
        [a[0] / l, a[1] / l, a[2] / l]
    };
    let f = norm(sub(TARGET, EYE));
    let r = norm(cross(f, [0.0, 1.0, 0.0]));
    let u = cross(r, f);
    let d = sub(p, EYE);
    let half_h = (FOV_Y.to_radians() / 2.0).tan();
    let half_w = half_h * SIZE.0 as f32 / SIZE.1 as f32;
    let z = dot(d, f);
    let x = (dot(d, r) / (z * half_w) + 1.0) / 2.0 * SIZE.0 as f32;
    let y = (1.0 - dot(d, u) / (z * half_h)) / 2.0 * SIZE.1 as f32;
    (x as u32, y as u32)
}

#[test]
fn spheres_png_shows_the_spheres_and_the_sky() {
    let exe = build_example("spheres");
    let png = support::scratch("c_examples").join("spheres.png");
    let _ = std::fs::remove_file(&png);
    let out = run(&exe, &[png.as_os_str()]);
    assert_exit(&out, 0, "spheres");
    assert!(
        stdout(&out).contains("spheres: OK"),
        "spheres did not report OK"
    );
    // Every one of its pixel checks ran: the four sphere centres, the sky and the floor. The
    // program skips a centre hidden by another sphere ("not checked"), which would pass.
    let checked = stdout(&out).lines().filter(|l| l.ends_with(": ok")).count();
    assert_eq!(checked, 6, "spheres ran {checked} of its 6 pixel checks");

    let img = image::open(&png)
        .unwrap_or_else(|e| panic!("cannot decode {}: {e}", png.display()))
        .to_rgba8();
    assert_eq!(img.dimensions(), SIZE, "PNG size");
    // Sphere centres and material colours from spheres.c. Around each centre's projection
    // (a 5x5 patch, well inside a sphere of radius >= 0.4 at distance <= 9, i.e. >= 20 px),
    // the material's dominant channel must lead and the patch must not be sky.
    for (name, center, channel) in [
        ("red", [-1.8, 0.75, 0.0], 0),
        ("green", [1.8, 0.75, 0.0], 1),
        ("blue", [0.4, 0.4, 1.6], 2),
    ] {
        let (x, y) = project(center);
        let m = patch_mean(&img, x, y, 2);
        let others = (0..3)
            .filter(|&k| k != channel)
            .map(|k| m[k])
            .fold(0.0, f32::max);
        // 1.5x: the material colours are 0.8..0.9 in the dominant channel against 0.1..0.25
        // elsewhere, so lit or only ambient, the ratio is > 3; 1.5 leaves room for highlights.
        assert!(
            m[channel] > 1.5 * others,
            "{name} sphere at ({x},{y}): mean {m:?} is not {name}"
        );
        let dist_to_sky: f32 = (0..3).map(|k| (m[k] - SKY[k]).abs()).sum();
        assert!(
            dist_to_sky > 30.0,
            "{name} sphere at ({x},{y}) looks like the sky: {m:?}"
        );
    }
    // Above the horizon: the top rows look up (10.1 deg pitch down, 22.5 deg half field of
    // view) and no sphere reaches that high, so the top 20 rows are all sky. Tolerance 2/255:
    // rounding of the background colour to 8 bits.
    let mut worst = 0f32;
    for y in 0..20 {
        for x in 0..SIZE.0 {
            let p = img.get_pixel(x, y).0;
            for k in 0..3 {
                worst = worst.max((p[k] as f32 - SKY[k]).abs());
            }
        }
    }
    assert!(
        worst <= 2.0,
        "the sky above the horizon differs from the background by {worst}/255"
    );
}

#[test]
fn load_model_renders_the_bunny() {
    let Some(model) = support::shared_path("models/bunny.ply") else {
        return;
    };
    let exe = build_example("load_model");
    let png = support::scratch("c_examples").join("bunny.png");
    let _ = std::fs::remove_file(&png);
    let out = run(&exe, &[model.as_os_str(), png.as_os_str()]);
    assert_exit(&out, 0, "load_model");
    let text = stdout(&out);
    // 69,451 triangles: shared/models/README.md.
    assert!(
        text.lines().any(|l| l == "triangles: 69451"),
        "wrong triangle count in:\n{text}"
    );
    assert!(text.contains("kd-tree: "), "no tree statistics in:\n{text}");

    let img = image::open(&png)
        .unwrap_or_else(|e| panic!("cannot decode {}: {e}", png.display()))
        .to_rgba8();
    let (w, h) = img.dimensions();
    assert_eq!(
        (w, h),
        (200, 150),
        "PNG size (load_model.c renders 200x150)"
    );
    // Camera of load_model.c: 2.4 x 0.156 from the bounding-box centre, 45 deg vertical field
    // of view. The box's front face (0.06 nearer) projects to at most 59% of the height and
    // 45% of the width; the silhouette lies inside it. Lit = not the black background (the
    // ambient term alone gives >= 0.1 x 0.8 x 255 = 20).
    let (half_w, half_h) = (0.45 * w as f32 / 2.0 + 2.0, 0.59 * h as f32 / 2.0 + 2.0);
    let mut lit = 0u32;
    for (x, y, p) in img.enumerate_pixels() {
        if p.0[..3].iter().any(|&c| c > 0) {
            lit += 1;
            let (dx, dy) = (
                (x as f32 + 0.5 - w as f32 / 2.0).abs(),
                (y as f32 + 0.5 - h as f32 / 2.0).abs(),
            );
            assert!(
                dx <= half_w && dy <= half_h,
                "lit pixel ({x},{y}) outside the model's projected bounding box"
            );
        }
    }
    let fraction = lit as f32 / (w * h) as f32;
    // At most the projected box (0.45 x 0.59 = 27%); at least 5%: the box's back face covers
    // 14% and the bunny fills well over a third of its box (a loose lower bound).
    assert!(
        (0.05..=0.27).contains(&fraction),
        "{:.1}% of the pixels show the model",
        100.0 * fraction
    );
    for (x, y) in [(0, 0), (w - 1, 0), (0, h - 1), (w - 1, h - 1)] {
        assert_eq!(
            &img.get_pixel(x, y).0[..3],
            &[0, 0, 0],
            "corner ({x},{y}) is not background"
        );
    }
}

#[test]
fn load_model_reports_a_missing_file() {
    // Its own executable: `load_model_renders_the_bunny` may be running `load_model` while this
    // test's compiler writes it (Linux refuses to run a file open for writing: ETXTBSY).
    let exe = build_example_as("load_model", "load_model-missing");
    let missing = support::scratch("c_examples").join("no-such-model.ply");
    let out = run(&exe, &[missing.as_os_str()]);
    assert_exit(&out, 2, "load_model with a missing file");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("no-such-model.ply") && err.contains("missing"),
        "unclear message: {err}"
    );
}

/// load_model.c's camera numbers are read whole: one with trailing text, not finite, or a size
/// that is not positive is a usage error (exit 2) before any work, not a partial read
/// (`strtof` took "1x" as 1) that loads and renders with a wrong camera.
#[test]
fn load_model_refuses_bad_numbers_before_any_work() {
    let load = build_example_as("load_model", "load_model-bad-numbers");
    let missing = support::scratch("c_examples").join("no-such-model.ply");
    let out_png = support::scratch("c_examples").join("bad-numbers.png");
    for (numbers, said) in [
        (["0", "0", "1x", "1"], "'1x' is not a finite number"),
        (["0", "inf", "0", "1"], "'inf' is not a finite number"),
        (["0", "0", "0", "0"], "size must be positive"),
    ] {
        let mut args = vec![missing.as_os_str(), out_png.as_os_str()];
        args.extend(numbers.iter().map(std::ffi::OsStr::new));
        let out = run(&load, &args);
        assert_exit(&out, 2, "load_model with a bad number");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains(said), "should say {said:?}: {err}");
    }
    assert!(!out_png.exists(), "an image was written for bad arguments");
}

/// ambient_occlusion.c: camera rays and occlusion rays through `rt2_intersect` and
/// `rt2_occluded` in every query mode, the occlusion rays excluding the primitive they leave.
#[test]
fn ambient_occlusion_passes_its_checks_and_writes_the_image() {
    ambient_occlusion("ambient_occlusion", &[]);
}

/// ambient_occlusion.c on the GPU backend (`RT2_BACKEND=gpu`, lavapipe in CI): the kernels
/// take the exclusions too, and every check holds (the modes agree trivially there: the GPU
/// traces one ray per thread whatever the mode).
#[test]
fn ambient_occlusion_on_the_gpu_backend_passes_its_checks() {
    if !gpu_available("ambient_occlusion_on_the_gpu_backend_passes_its_checks") {
        return;
    }
    ambient_occlusion("ambient_occlusion-gpu", &[("RT2_BACKEND", "gpu")]);
}

/// Runs ambient_occlusion.c as `name` with `env` and checks its report and its image.
fn ambient_occlusion(name: &str, env: &[(&str, &str)]) {
    let exe = build_example_as("ambient_occlusion", name);
    let pgm = support::scratch("c_examples").join(format!("{name}.pgm"));
    let _ = std::fs::remove_file(&pgm);
    let out = run_with(&exe, &[pgm.as_os_str()], env);
    assert_exit(&out, 0, name);
    let text = stdout(&out);
    assert!(text.contains("ambient_occlusion: OK"), "no OK in:\n{text}");
    // Four probes (modes agree, view factor), the probe without exclusion (modes agree, every
    // ray hits the ground), camera rays and occlusion rays (modes agree), the open ground: 13.
    // A check that did not run would pass silently.
    let checked = text.lines().filter(|l| l.ends_with(": ok")).count();
    assert_eq!(
        checked, 13,
        "ambient_occlusion ran {checked} of its 13 checks"
    );

    // Binary PGM: "P5\n256 144\n255\n" and one byte per pixel.
    let bytes = std::fs::read(&pgm).unwrap_or_else(|e| panic!("no {}: {e}", pgm.display()));
    let header = b"P5\n256 144\n255\n";
    assert!(bytes.starts_with(header), "not a 256x144 binary PGM");
    let pixels = &bytes[header.len()..];
    assert_eq!(pixels.len(), 256 * 144, "PGM pixel count");
    // Open ground (nothing within the occlusion rays' reach: 255) and the wall's foot, where
    // at least half of a point's rays are blocked, must both be in the picture.
    let open = pixels.iter().filter(|&&p| p == 255).count();
    let dark = pixels.iter().filter(|&&p| (1..=128).contains(&p)).count();
    assert!(open > pixels.len() / 10, "only {open} open pixels");
    assert!(dark > 100, "only {dark} pixels at least half occluded");
}

/// A sample count out of range or with trailing text (`atoi` took "8abc" as 8) is a usage
/// error before any work.
#[test]
fn ambient_occlusion_refuses_a_bad_sample_count() {
    let exe = build_example_as("ambient_occlusion", "ambient_occlusion-args");
    let pgm = support::scratch("c_examples").join("ambient_occlusion-args.pgm");
    let _ = std::fs::remove_file(&pgm);
    for samples in ["0", "4097", "8abc", ""] {
        let out = run(&exe, &[pgm.as_os_str(), samples.as_ref()]);
        assert_exit(
            &out,
            2,
            &format!("ambient_occlusion with samples {samples:?}"),
        );
        assert!(
            String::from_utf8_lossy(&out.stderr).contains("SAMPLES"),
            "the message does not name SAMPLES"
        );
    }
    assert!(!pgm.exists(), "an image was written for bad arguments");
}

#[test]
fn errors_example_passes_every_check() {
    errors_example(build_example("errors"), &[]);
}

/// errors.c with its contexts on the GPU: the same statuses, messages and untouched outputs.
#[test]
fn errors_example_passes_every_check_on_the_gpu_backend() {
    if !gpu_available("errors_example_passes_every_check_on_the_gpu_backend") {
        return;
    }
    errors_example(
        build_example_as("errors", "errors-gpu"),
        &[("RT2_BACKEND", "gpu")],
    );
}

fn errors_example(exe: PathBuf, env: &[(&str, &str)]) {
    let tmp = support::scratch("c_examples");
    let out = run_with(&exe, &[tmp.as_os_str()], env);
    let text = stdout(&out);
    let failed: Vec<&str> = text.lines().filter(|l| l.starts_with("FAIL")).collect();
    assert!(
        failed.is_empty(),
        "errors.c checks failed:\n{}",
        failed.join("\n")
    );
    assert_exit(&out, 0, "errors");
    let summary = text.lines().last().unwrap_or("");
    let (passed, failed_n) = summary
        .strip_suffix(" failed")
        .and_then(|s| s.split_once(" passed, "))
        .and_then(|(p, f)| Some((p.parse::<usize>().ok()?, f.parse::<usize>().ok()?)))
        .unwrap_or_else(|| panic!("no \"N passed, M failed\" summary, last line {summary:?}"));
    assert_eq!(failed_n, 0, "summary line: {summary}");
    let pass_lines = text.lines().filter(|l| l.starts_with("pass")).count();
    assert_eq!(
        passed, pass_lines,
        "the summary disagrees with the pass lines"
    );
    // errors.c makes more than 80 checks; 80 catches a run that stopped early but exited 0.
    assert!(passed >= 80, "only {passed} checks ran");
}

/// Whether a GPU adapter is usable; without one the caller prints SKIPPED and returns,
/// unless `RT2_REQUIRE_GPU=1`.
fn gpu_available(test: &str) -> bool {
    match rt2::context::Context::new(rt2::dispatch::BackendRequest::Gpu, 1) {
        Ok(_) => true,
        Err(e) => {
            assert!(
                std::env::var("RT2_REQUIRE_GPU").as_deref() != Ok("1"),
                "RT2_REQUIRE_GPU=1 but no GPU: {}",
                e.message
            );
            eprintln!("SKIPPED {test} (no GPU adapter): {}", e.message);
            false
        }
    }
}

/// Runs `exe` with `args` plus an output PNG on the CPU and on the GPU backend
/// (`RT2_BACKEND`), and checks that the GPU drew the CPU's image within the tolerance of
/// tests/gpu.rs: mean absolute difference <= 1.0 and 99th percentile <= 12 per channel
/// (headroom for hardware GPUs, which fuse multiply-adds; lavapipe draws the same bytes).
/// Returns the two runs' outputs.
fn cpu_and_gpu_images_agree(exe: &Path, args: &[&std::ffi::OsStr], name: &str) -> [Output; 2] {
    let dir = support::scratch("c_examples");
    let mut images = Vec::new();
    let mut outputs = Vec::new();
    for backend in ["cpu", "gpu"] {
        let png = dir.join(format!("{name}-{backend}.png"));
        let _ = std::fs::remove_file(&png);
        let mut all = args.to_vec();
        all.push(png.as_os_str());
        let out = run_with(exe, &all, &[("RT2_BACKEND", backend)]);
        assert_exit(&out, 0, &format!("{name} on the {backend} backend"));
        let img = image::open(&png)
            .unwrap_or_else(|e| panic!("cannot decode {}: {e}", png.display()))
            .to_rgba8();
        images.push(img);
        outputs.push(out);
    }
    let mut diffs: Vec<u8> = images[0]
        .as_raw()
        .iter()
        .zip(images[1].as_raw())
        .map(|(a, b)| a.abs_diff(*b))
        .collect();
    let mean = diffs.iter().map(|&d| d as f64).sum::<f64>() / diffs.len() as f64;
    diffs.sort_unstable();
    let p99 = diffs[diffs.len() * 99 / 100];
    println!("{name} GPU against CPU: mean {mean:.3}, 99th percentile {p99}");
    assert!(
        mean <= 1.0 && p99 <= 12,
        "{name}: GPU image differs: mean {mean:.3}, p99 {p99}"
    );
    [outputs.remove(0), outputs.remove(0)]
}

/// spheres.c on the GPU backend (`RT2_BACKEND=gpu`, lavapipe in CI) draws the CPU's image.
#[test]
fn spheres_on_the_gpu_backend_draws_the_cpu_image() {
    if !gpu_available("spheres_on_the_gpu_backend_draws_the_cpu_image") {
        return;
    }
    let exe = build_example_as("spheres", "spheres-backends");
    cpu_and_gpu_images_agree(&exe, &[], "spheres");
}

/// load_model.c renders the bunny (69k triangles) on the GPU backend as on the CPU, and
/// reports through `rt2_context_info` that the render ran where the context said.
#[test]
fn load_model_on_the_gpu_backend_draws_the_cpu_image() {
    let Some(model) = support::shared_path("models/bunny.ply") else {
        return;
    };
    if !gpu_available("load_model_on_the_gpu_backend_draws_the_cpu_image") {
        return;
    }
    let exe = build_example_as("load_model", "load_model-backends");
    let [cpu, gpu] = cpu_and_gpu_images_agree(&exe, &[model.as_os_str()], "bunny");
    for (out, want) in [
        (cpu, "backend: CPU (CPU requested by RT2_BACKEND=cpu)"),
        (gpu, "backend: GPU (GPU requested by RT2_BACKEND=gpu"),
    ] {
        let text = stdout(&out);
        assert!(text.contains(want), "no {want:?} in:\n{text}");
        assert!(
            !text.contains("ran on the CPU"),
            "a fallback on an explicit backend:\n{text}"
        );
    }
}

/// minimal.c passes its own check on the GPU backend.
#[test]
fn minimal_on_the_gpu_backend_renders_the_triangle() {
    if !gpu_available("minimal_on_the_gpu_backend_renders_the_triangle") {
        return;
    }
    let exe = build_example_as("minimal", "minimal-gpu");
    let out = run_with(&exe, &[], &[("RT2_BACKEND", "gpu")]);
    assert_exit(&out, 0, "minimal on the GPU backend");
    assert!(stdout(&out).contains("minimal: OK"));
}

/// `RT2_BACKEND`, `RT2_ADAPTER` and `RT2_GPU_DEVICES` set but empty (a shell's `VAR= program`)
/// count as unset, all three alike: an empty `RT2_BACKEND` made every context creation fail
/// ("expected cpu, gpu or auto") where the other two were already taken as unset.
#[test]
fn empty_environment_variables_count_as_unset() {
    let exe = build_example_as("minimal", "minimal-empty-env");
    let empty = [
        ("RT2_BACKEND", ""),
        ("RT2_ADAPTER", ""),
        ("RT2_GPU_DEVICES", ""),
    ];
    let out = run_with(&exe, &[], &empty);
    assert_exit(&out, 0, "minimal with the RT2_* variables empty");
    assert!(stdout(&out).contains("minimal: OK"), "{}", stdout(&out));
}

/// No usable adapter (`RT2_ADAPTER` names none, or `WGPU_BACKEND` a backend RT2 lacks): the
/// GPU requested is
/// `RT2_STATUS_BACKEND_UNAVAILABLE` with the reason; AUTO traces on the CPU and
/// `rt2_context_info` says why. Needs no GPU.
#[test]
fn no_adapter_is_an_error_for_gpu_and_the_cpu_for_auto() {
    let env = |backend| {
        [
            ("RT2_BACKEND", backend),
            ("RT2_ADAPTER", "no-such-adapter-rt2"),
        ]
    };
    let exe = build_example_as("minimal", "minimal-no-adapter");
    let out = run_with(&exe, &[], &env("gpu"));
    assert_exit(&out, 1, "minimal asking for a GPU that is not there");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("rt2_context_create failed: RT2_STATUS_BACKEND_UNAVAILABLE: GPU requested by RT2_BACKEND=gpu, but "),
        "unclear message: {err}"
    );
    // WGPU_BACKEND is honoured: a backend RT2 is not built with leaves no adapter.
    let out = run_with(&exe, &[], &[("RT2_BACKEND", "gpu"), ("WGPU_BACKEND", "gl")]);
    assert_exit(&out, 1, "minimal asking for a GPU on WGPU_BACKEND=gl");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("RT2_STATUS_BACKEND_UNAVAILABLE") && err.contains("WGPU_BACKEND=gl"),
        "unclear message: {err}"
    );
    let Some(model) = support::shared_path("models/bunny.ply") else {
        return;
    };
    let exe = build_example_as("load_model", "load_model-no-adapter");
    let png = support::scratch("c_examples").join("bunny-no-adapter.png");
    let out = run_with(&exe, &[model.as_os_str(), png.as_os_str()], &env("auto"));
    assert_exit(&out, 0, "load_model on AUTO without an adapter");
    let text = stdout(&out);
    assert!(
        text.contains("backend: CPU (AUTO from RT2_BACKEND=auto: ")
            && text.contains("so tracing runs on the CPU)"),
        "no reason for the CPU in:\n{text}"
    );
}
