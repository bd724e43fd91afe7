//! The `rt2` command line: the README's render command draws the built-in scene, and a bad
//! option or output path fails before any work (no load, no commit, no file), with a message
//! naming what is wrong and exit status 1.

mod support;

use std::collections::HashSet;
use std::ffi::OsStr;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};

/// The binary with `args`, its output captured.
fn run<S: AsRef<OsStr>>(args: &[S]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_rt2"))
        .args(args)
        .output()
        .expect("run the rt2 binary")
}

/// The binary with `args`, writing its stdout to `stdout`; stderr is captured.
fn run_into<S: AsRef<OsStr>>(args: &[S], stdout: impl Into<Stdio>) -> Output {
    Command::new(env!("CARGO_BIN_EXE_rt2"))
        .args(args)
        .stdout(stdout)
        .output()
        .expect("run the rt2 binary")
}

fn rt2(args: &[&str], output: &Path) -> Output {
    let mut args: Vec<&OsStr> = args.iter().map(OsStr::new).collect();
    args.extend([OsStr::new("-o"), output.as_os_str()]);
    run(&args)
}

/// Exit status 1 with a message on stderr that names `named`, and no panic.
fn assert_refused(out: &Output, named: &str) {
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains(named), "should name '{named}': {err}");
}

/// The README's first command (`rt2 render default -o default.png`), into scratch space.
#[test]
fn readme_render_command_draws_the_default_scene() {
    let png = support::scratch("cli").join("default.png");
    let _ = std::fs::remove_file(&png);
    let out = rt2(&["render", "default"], &png);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let img = image::open(&png)
        .expect("the command wrote a PNG")
        .to_rgb8();
    assert_eq!(img.dimensions(), (1376, 768), "the documented default size");
    // Shaded objects, not one flat colour: a frame of background alone has one.
    let colours: HashSet<[u8; 3]> = img.pixels().map(|p| p.0).collect();
    assert!(colours.len() > 1000, "{} colours", colours.len());
    // The image is the library's render of the built-in scene with the documented defaults
    // (the scene's own depth, 1 sample) on the CPU. The command's AUTO context may take a
    // hardware GPU, whose rounding differs a little: PSNR 40 dB there, identical on the CPU.
    let mut b = rt2::scene::builtin::by_name("default").unwrap();
    b.scene.commit().unwrap();
    let opts = rt2::render::RenderOptions {
        max_depth: b.max_depth,
        ..Default::default()
    };
    let mut frame = rt2::frame::Frame::new(1376, 768).unwrap();
    let ctx = rt2::context::Context::new(rt2::dispatch::BackendRequest::Cpu, 0).unwrap();
    ctx.render(b.scene.committed().unwrap(), &b.camera, &opts, &mut frame)
        .unwrap();
    let want: Vec<u8> = frame
        .pixels()
        .chunks(4)
        .flat_map(|p| [p[0], p[1], p[2]])
        .collect();
    let mse = img
        .as_raw()
        .iter()
        .zip(&want)
        .map(|(a, b)| (*a as f64 - *b as f64).powi(2))
        .sum::<f64>()
        / want.len() as f64;
    let psnr = 10.0 * (255.0f64.powi(2) / mse.max(1e-12)).log10();
    assert!(
        psnr >= 40.0,
        "the PNG is {psnr:.1} dB from the library's render"
    );
    // The command reports where it rendered; on the CPU the image is the same, byte for byte.
    let report = String::from_utf8_lossy(&out.stdout);
    if report.contains("on the CPU") || report.contains("CPU requested") {
        assert!(
            mse == 0.0,
            "rendered on the CPU but {psnr:.1} dB off: {report}"
        );
    }
}

/// Each bad input fails with status 1, a message naming it, and no PNG written.
#[test]
fn bad_options_fail_before_any_work() {
    let dir = support::scratch("cli");
    let png = dir.join("never.png");
    let cases: [(&[&str], &str); 10] = [
        (&["render", "default", "--samples", "0"], "samples"),
        // Checked before the model is loaded: the missing file is never reached.
        (&["render", "missing.ply", "--samples", "0"], "samples"),
        (&["render", "missing.ply", "--size", "0x10"], "size"),
        (&["render", "default", "--depth", "65"], "max_depth"),
        (&["render", "default", "--size", "0x10"], "size"),
        (
            &["render", "--size", "10x10x10"],
            "WIDTHxHEIGHT (e.g. 1376x768), got '10x10x10'",
        ),
        (
            &["render", "--size", "10"],
            "WIDTHxHEIGHT (e.g. 1376x768), got '10'",
        ),
        (&["render", "default", "--frobnicate"], "--frobnicate"),
        (
            &["render", "no-such-scene"],
            "unknown scene 'no-such-scene': the built-in scenes are default, spheres1",
        ),
        (&["draw"], "draw"),
    ];
    for (args, named) in cases {
        let _ = std::fs::remove_file(&png);
        let out = rt2(args, &png);
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{args:?}: {err}");
        assert!(err.contains(named), "{args:?} should name '{named}': {err}");
        assert!(!png.exists(), "{args:?} wrote {}", png.display());
    }
    // An output path that cannot be written is refused before the render.
    let out = rt2(&["render", "default"], &dir.join("missing-dir/x.png"));
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains("missing-dir"));
}

/// File names are bytes on Unix: a model and an output path that are not UTF-8 are used as
/// given; any other argument that is not UTF-8 is refused with a message, not a panic.
#[cfg(unix)]
#[test]
fn paths_need_not_be_utf8() {
    use std::os::unix::ffi::OsStrExt;
    let dir = support::scratch("cli");
    let model = dir.join(OsStr::from_bytes(b"caf\xe9.obj"));
    std::fs::write(&model, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
    let png = dir.join(OsStr::from_bytes(b"caf\xe9.png"));
    let _ = std::fs::remove_file(&png);
    let out = run(&[
        OsStr::new("render"),
        model.as_os_str(),
        OsStr::new("--size"),
        OsStr::new("8x8"),
        OsStr::new("--backend"),
        OsStr::new("cpu"),
        OsStr::new("-o"),
        png.as_os_str(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(png.exists(), "no PNG at {}", png.display());

    let bad = OsStr::from_bytes(b"cp\xffu");
    for args in [
        vec![OsStr::new("render"), OsStr::new("--backend"), bad],
        vec![OsStr::new("render"), OsStr::from_bytes(b"--\xff")],
        vec![bad],
        vec![OsStr::new("bench"), bad],
    ] {
        assert_refused(&run(&args), "not valid UTF-8");
    }
}

/// Stdout that cannot be written never panics: a full disk is an error (status 1, a message
/// on stderr), a reader that has gone (`| head -1`) ends the command quietly with status 0.
#[cfg(target_os = "linux")]
#[test]
fn unwritable_stdout_is_not_a_panic() {
    let png = support::scratch("cli").join("stdout.png");
    let png = png.to_str().expect("a UTF-8 scratch path");
    let commands: [&[&str]; 3] = [
        &["--help"],
        &["bench", "-h"],
        &["render", "--size", "8x8", "--backend", "cpu", "-o", png],
    ];
    for args in commands {
        let full = std::fs::File::options()
            .write(true)
            .open("/dev/full")
            .unwrap();
        let out = run_into(args, full);
        assert!(!String::from_utf8_lossy(&out.stderr).contains("panicked"));
        assert_refused(&out, "stdout");

        let (reader, writer) = std::io::pipe().unwrap();
        drop(reader);
        let out = run_into(args, writer);
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(0), "{args:?}: {err}");
        assert!(err.is_empty(), "{args:?}: {err}");
    }
}

/// Stderr that cannot be written (a full disk) is not a panic (status 101): an error still
/// ends with status 1, and a benchmark's notes (here: the models are missing) are dropped.
#[cfg(target_os = "linux")]
#[test]
fn unwritable_stderr_is_not_a_panic() {
    let empty = support::scratch("cli-no-models");
    for (args, status) in [
        (&["render", "--frobnicate"][..], 1),
        (&["bench", "memory"], 0),
    ] {
        let full = std::fs::File::options()
            .write(true)
            .open("/dev/full")
            .unwrap();
        let out = Command::new(env!("CARGO_BIN_EXE_rt2"))
            .args(args)
            .env("RT2_SHARED", &empty)
            .stderr(full)
            .output()
            .expect("run the rt2 binary");
        assert_eq!(out.status.code(), Some(status), "{args:?}");
    }
}

/// One scene or benchmark per command: a second positional argument is refused, not silently
/// taken in place of the first.
#[test]
fn a_second_positional_argument_is_refused() {
    let empty = support::scratch("cli-no-models");
    let png = support::scratch("cli").join("two-scenes.png");
    let _ = std::fs::remove_file(&png);
    let out = rt2(&["render", "spheres1", "spheres2", "--size", "8x8"], &png);
    assert_refused(&out, "spheres2");
    assert!(!png.exists());
    let out = Command::new(env!("CARGO_BIN_EXE_rt2"))
        .args(["bench", "extra", "memory"])
        .env("RT2_SHARED", &empty)
        .output()
        .expect("run the rt2 binary");
    assert_refused(&out, "memory");
    assert!(out.stdout.is_empty(), "no benchmark runs");
}

/// A `--write` target that cannot take the section is refused before any benchmark runs.
#[cfg(unix)]
#[test]
fn bench_checks_its_write_target_first() {
    use std::os::unix::ffi::OsStrExt;
    let empty = support::scratch("cli-no-models");
    let dir = support::scratch("cli");
    let not_text = dir.join("not-text.md");
    std::fs::write(&not_text, b"\xff\xfe").unwrap();
    for target in [
        dir.join("missing-dir/x.md"),
        dir.join(OsStr::from_bytes(b"missing-dir/caf\xe9.md")),
        not_text,
        dir.clone(),
        // A folder that exists but takes no new file, even for root.
        PathBuf::from("/proc/rt2-bench.md"),
    ] {
        let out = Command::new(env!("CARGO_BIN_EXE_rt2"))
            .args(["bench", "memory", "--write"])
            .arg(&target)
            .env("RT2_SHARED", &empty)
            .output()
            .expect("run the rt2 binary");
        let named = target.file_name().unwrap().to_string_lossy();
        assert_refused(&out, &named);
        // Without the models, a benchmark that runs notes each one it skips.
        let ran =
            !out.stdout.is_empty() || String::from_utf8_lossy(&out.stderr).contains("skipped");
        assert!(!ran, "{}: a benchmark ran", target.display());
    }
}

/// An unknown benchmark or option, or an option without its value or with one that is not a
/// number, is refused with a message naming it before any benchmark runs.
#[test]
fn bench_refuses_unknown_names_and_bad_options() {
    let cases: [(&[&str], &str); 5] = [
        (&["bench", "frobnicate"], "unknown benchmark 'frobnicate'"),
        (
            &["bench", "memory", "--frobnicate"],
            "unknown option '--frobnicate'",
        ),
        (
            &["bench", "memory", "--runs", "abc"],
            "--runs: cannot parse 'abc'",
        ),
        (&["bench", "memory", "--runs"], "--runs needs a value"),
        (&["bench", "memory", "--write"], "--write needs a value"),
    ];
    for (args, named) in cases {
        let out = Command::new(env!("CARGO_BIN_EXE_rt2"))
            .args(args)
            .env("RT2_SHARED", support::scratch("cli-no-models"))
            .output()
            .expect("run the rt2 binary");
        assert_refused(&out, named);
        assert!(out.stdout.is_empty(), "{args:?}: a benchmark ran");
    }
}

/// `bench --runs 0` is refused, not silently taken as 1, and so is a count no bench could
/// finish, with a range a user can act on (it read 1..=18446744073709551615).
#[test]
fn bench_refuses_zero_and_endless_runs() {
    for runs in ["0", "1001"] {
        let out = Command::new(env!("CARGO_BIN_EXE_rt2"))
            .args(["bench", "memory", "--runs", runs])
            .env("RT2_SHARED", support::scratch("cli-no-models"))
            .output()
            .expect("run the rt2 binary");
        assert_refused(&out, "--runs");
        assert!(
            String::from_utf8_lossy(&out.stderr).contains("1..=1000"),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        assert!(out.stdout.is_empty(), "a benchmark ran");
    }
}

/// No command is an error (exit 1, the usage on stderr); `help` and `--version` answer on
/// stdout with success.
#[test]
fn help_version_and_no_command() {
    let out = run::<&str>(&[]);
    assert_refused(&out, "no command given");
    assert!(String::from_utf8_lossy(&out.stderr).contains("rt2 render [SCENE|MODEL]"));
    for help in ["help", "-h", "--help"] {
        let out = run(&[help]);
        assert!(out.status.success(), "{help}");
        assert!(String::from_utf8_lossy(&out.stdout).contains("rt2 render [SCENE|MODEL]"));
    }
    for version in ["--version", "-V"] {
        let out = run(&[version]);
        assert!(out.status.success(), "{version}");
        let expected = format!("rt2 {}\n", env!("CARGO_PKG_VERSION"));
        assert_eq!(String::from_utf8_lossy(&out.stdout), expected);
    }
}

/// `render -h` and `--help` print the usage, as `bench -h` does.
#[test]
fn render_help_prints_the_usage() {
    for flag in ["-h", "--help"] {
        let out = run(&["render", flag]);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        assert!(String::from_utf8_lossy(&out.stdout).contains("rt2 render [SCENE|MODEL]"));
    }
}
