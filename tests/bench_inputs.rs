//! `rt2 bench` and its inputs: the shared models and ray sets, and Embree's harness. A section
//! measured without some of them says so and never replaces a complete one in the benchmark
//! file; what the harness reports lands in the right cells, and output it should not have
//! written is an error rather than a zero or a NaN in a table. The shared folder here is a
//! stand-in (a two-triangle "bunny" and four shadow rays) and the harness a shell script, so
//! that these run in seconds and need no `../shared`.
#![cfg(unix)]

mod support;

use std::os::unix::fs::PermissionsExt;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// A shared folder holding `models/bunny.ply` (a unit square of two triangles at z = 0) and
/// `raysets/bunny/shadow_4.rays` (four rays down onto it), fresh for test `name`.
fn stand_in_shared(name: &str) -> PathBuf {
    let dir = support::scratch(name).join("shared");
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(dir.join("models")).unwrap();
    std::fs::create_dir_all(dir.join("raysets/bunny")).unwrap();
    std::fs::write(
        dir.join("models/bunny.ply"),
        "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n\
         property float z\nelement face 2\nproperty list uchar int vertex_indices\nend_header\n\
         0 0 0\n1 0 0\n1 1 0\n0 1 0\n3 0 1 2\n3 0 2 3\n",
    )
    .unwrap();
    // The shared ray format: magic, version 1, count, then (org, tmin, dir, tmax) in f32.
    let mut rays = b"RT2RAYS\0".to_vec();
    rays.extend(1u32.to_le_bytes());
    rays.extend(4u32.to_le_bytes());
    for (x, y) in [(0.25f32, 0.25f32), (0.75, 0.25), (0.5, 0.75), (2.0, 2.0)] {
        for v in [x, y, 1.0, 0.0, 0.0, 0.0, -1.0, f32::INFINITY] {
            rays.extend(v.to_le_bytes());
        }
    }
    std::fs::write(dir.join("raysets/bunny/shadow_4.rays"), rays).unwrap();
    dir
}

/// A stand-in for Embree's harness: a script that appends `rows` to the file after `--tsv`
/// and exits with `status`. In `rows`, `$N` is how many times it has been called (1 first).
fn harness(name: &str, rows: &str, status: i32) -> PathBuf {
    let path = support::scratch(name).join("bench_embree");
    let count = path.with_extension("count");
    let _ = std::fs::remove_file(&count);
    let script = format!(
        "#!/bin/sh\n\
         N=$(( $(cat '{count}' 2>/dev/null || echo 0) + 1 ))\n\
         echo $N > '{count}'\n\
         while [ $# -gt 0 ]; do if [ \"$1\" = --tsv ]; then tsv=$2; fi; shift; done\n\
         printf \"{rows}\" >> \"$tsv\"\n\
         exit {status}\n",
        count = count.display()
    );
    std::fs::write(&path, script).unwrap();
    std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o755)).unwrap();
    path
}

/// `rt2 bench ARGS` with the shared folder `shared` and Embree's harness `embree`.
fn bench(args: &[&str], shared: &Path, embree: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_rt2"))
        .arg("bench")
        .args(args)
        .env("RT2_SHARED", shared)
        .env("RT2_EMBREE_BENCH", embree)
        .output()
        .expect("run the rt2 binary")
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

/// Without its models a benchmark's section says it is incomplete, and `--write` leaves the
/// file's section as it was, with an error naming the file (it was overwritten with an empty
/// table, exit 0).
#[test]
fn an_incomplete_section_is_not_written() {
    let dir = support::scratch("bench-incomplete");
    let empty = dir.join("no-shared");
    std::fs::create_dir_all(&empty).unwrap();
    let file = dir.join("BENCH.md");
    let before = "# Benchmarks\n<!-- bench:memory -->\nmeasured before\n<!-- /bench:memory -->\n";
    std::fs::write(&file, before).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_rt2"))
        .args(["bench", "memory", "--write"])
        .arg(&file)
        .env("RT2_SHARED", &empty)
        .output()
        .expect("run the rt2 binary");
    let err = text(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("BENCH.md keeps its section"), "{err}");
    assert!(err.contains("bunny.ply (missing"), "{err}");
    assert_eq!(std::fs::read_to_string(&file).unwrap(), before);
    let stdout = text(&out.stdout);
    assert!(
        stdout.contains("**Incomplete**, measured without: "),
        "{stdout}"
    );
    assert!(stdout.contains("bunny.ply (missing"), "{stdout}");
}

/// The build ratio against Embree pairs each run of RT2's build with a run of the harness, and
/// Embree's row is the median of its runs: two calls reporting 10 and 30 ms give 20, the mean
/// of the two middle values (the upper one, 30, before).
#[test]
fn embree_builds_are_read_run_by_run() {
    let shared = stand_in_shared("bench-embree-builds");
    let embree = harness(
        "bench-embree-builds",
        "embree\\tbunny\\tBUILD\\thigh(non-robust)\\t2\\t1048576\\t$((N * 20 - 10))\\t-\\t0.0\\t1\\n\
         embree\\tbunny\\tBUILD\\trobust+high\\t1\\t2097152\\t5.5\\t-\\t0.0\\t5.5\\n",
        0,
    );
    let out = bench(&["build", "--runs", "2"], &shared, &embree);
    let stdout = text(&out.stdout);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let calls = std::fs::read_to_string(embree.with_extension("count")).unwrap();
    assert_eq!(calls.trim(), "2", "one call of the harness per run");
    assert!(
        stdout.contains("| bunny.ply | high(non-robust) | 2 | 20.00 | 1.00 |"),
        "{stdout}"
    );
    assert!(
        stdout.contains("| bunny.ply | robust+high | 1 | 5.50 | 2.00 |"),
        "{stdout}"
    );
    // The ratio is against the multi-threaded build only: none for robust+high here.
    let ratio = stdout
        .lines()
        .find(|l| l.starts_with("| bunny.ply |") && l.contains("x (2 threads)"))
        .unwrap_or_else(|| panic!("no ratio row: {stdout}"));
    assert!(ratio.ends_with("x (2 threads) | — |"), "{ratio}");
    // The snowden and the dragon are missing from the stand-in folder.
    assert!(stdout.contains("**Incomplete**"), "{stdout}");
}

/// The rays table puts each of Embree's speeds in the column of its thread count (the
/// two-thread figure sat in the one-thread column) and marks only the traced scene's
/// one-thread `intersect1` as the hits' reference.
#[test]
fn embree_speeds_land_in_their_thread_columns() {
    let shared = stand_in_shared("bench-embree-rays");
    let embree = harness(
        "bench-embree-rays",
        "embree\\tbunny\\tBUILD\\trobust+high\\t1\\t1024\\t1.0\\t-\\t0.0\\t1.0\\n\
         embree\\tbunny\\tshadow_4\\tintersect1\\t1\\t4\\t0.1\\t1.5\\t0.0\\t0.1\\n\
         embree\\tbunny\\tshadow_4\\tintersect1\\t2\\t4\\t0.1\\t2.5\\t0.0\\t0.1\\n\
         embree\\tbunny\\tshadow_4\\toccluded1\\t2\\t4\\t0.1\\t7.25\\t0.0\\t0.1\\n",
        0,
    );
    let out = bench(&["rays", "--runs", "1"], &shared, &embree);
    let stdout = text(&out.stdout);
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert!(
        stdout.contains("| bunny shadow_4 | Embree intersect1 | 1.50 | 2.50 | | | | reference |"),
        "{stdout}"
    );
    assert!(
        stdout.contains("| bunny shadow_4 | Embree occluded1 |  | 7.25 | | | |  |"),
        "{stdout}"
    );
}

/// A harness that fails, or writes a row short of fields or with a figure that is not a
/// number, stops the benchmark with an error saying so (it panicked on a short row, and
/// printed `nan?`, `NaNx` or a zero for the others).
#[test]
fn bad_harness_output_is_an_error() {
    let shared = stand_in_shared("bench-embree-bad");
    for (rows, status, said) in [
        ("", 3, "failed"),
        ("", 0, "wrote no results"),
        (
            "embree\\tbunny\\tBUILD\\thigh(non-robust)\\n",
            0,
            "all of its 9 fields",
        ),
        (
            "embree\\tbunny\\tBUILD\\thigh(non-robust)\\t2\\t1024\\tfast\\t-\\t0.0\\t1\\n",
            0,
            "a time in ms",
        ),
        (
            "embree\\tbunny\\tBUILD\\thigh(non-robust)\\tmany\\t1024\\t1.0\\t-\\t0.0\\t1\\n",
            0,
            "a thread count",
        ),
        (
            "embree\\tbunny\\tshadow_4\\tintersect1\\t1\\t4\\t0.1\\tnan\\t0.0\\t0.1\\n",
            0,
            "a speed in Mrays/s",
        ),
    ] {
        let embree = harness("bench-embree-bad", rows, status);
        let out = bench(&["build", "--runs", "1"], &shared, &embree);
        let err = text(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{rows}: {err}");
        assert!(err.contains(said), "{rows}: should say '{said}': {err}");
        assert!(!err.contains("panicked"), "{err}");
    }
}
