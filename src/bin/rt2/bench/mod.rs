//! `rt2 bench`: the measurements quoted in BENCHMARKS.md. Every figure is a median of several
//! runs; Embree (the peer of `../shared/peers`) is measured in the same invocation when its
//! harness is built, so ratios compare like with like on a noisy shared machine.

mod build;
mod chart;
mod frames;
mod gpu;
mod memory;
mod rays;
mod streams;
mod tables;

use crate::args::{Arg, Reader};
use crate::output::{say, warn};
use rt2::error::{Error, Result};
use rt2::scene::{loaders, Scene, Shape};
use std::ffi::OsString;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

const USAGE: &str = "usage: rt2 bench [frames|build|rays|tables|streams|gpu|chart|memory|all] [--runs N] [--write FILE]
  frames   ms per 1376x768 frame on the CPU: spheres3 and the bunny, with build time and memory
  build    kd-tree build time (SAH+perfect splits, midpoint) at 1 and 2 threads, Embree beside
  rays     Mrays/s per traversal on ../shared/raysets, agreement with Embree's hits, Embree beside
  tables   the RT² thesis' tables 1 and 2 on the CPU: nodes visited per ray, tree memory and
           ms per 1376x768 frame for every traversal, beside the thesis' figures
  streams  n-ray streams vs packets vs single rays: the vectorised-traversal paper's tables, Embree beside
  gpu      thesis table 2 on the GPU backend: ms per frame per traversal, both render paths, vs CPU
  chart    speed against accuracy: every traversal x intersector x offset mode, packets,
           streams and the GPU backend (when an adapter opens) against an f64 reference on
           the bunny sets and a stress scene; PSNR per offset mode on every built-in scene;
           docs/chart.svg and .png with --features chart
  memory   bytes per primitive of each part of each built-in scene and the bunny, beside a
           tessellation of their analytic primitives
  --runs N       timed runs per figure, 1 to 1000 (default 5; the median is reported)
  --write FILE   also replace this benchmark's section in FILE (e.g. BENCHMARKS.md)
Model files come from $RT2_SHARED (default ../shared); Embree from $RT2_EMBREE_BENCH or
target/peers/bench_embree (make -C ../shared/peers BUILD=$PWD/target/peers).";

/// One benchmark: it returns the Markdown section it measured.
type Bench = fn(&Args) -> Result<String>;

struct Args {
    runs: usize,
    write: Option<PathBuf>,
}

pub fn run(args: &[OsString]) -> Result<()> {
    let mut what = None;
    let mut a = Args {
        runs: 5,
        write: None,
    };
    let mut args = Reader::new(args);
    while let Some(arg) = args.next_arg() {
        match arg? {
            Arg::Flag(x @ "--runs") => a.runs = args.parse(x)?,
            Arg::Flag(x @ "--write") => a.write = Some(args.path(x)?),
            Arg::Flag("-h" | "--help") => return say(USAGE),
            Arg::Positional(s) => crate::args::set_once(&mut what, s, "benchmark")?,
            Arg::Flag(s) => {
                return Err(Error::invalid_argument(format!(
                    "unknown option '{s}'\n{USAGE}"
                )))
            }
        }
    }
    // A median needs a run: 0 is refused (as render refuses --samples 0), not taken as 1. A
    // thousand runs of the slowest figure already take hours.
    rt2::error::check_range("--runs", a.runs, 1..=1000)?;
    // Before any benchmark: a bad --write target found only after a run of many minutes
    // wastes the run (as `render` checks -o first).
    if let Some(path) = &a.write {
        check_writable(path)?;
    }
    let what = what.map_or(Ok("all"), crate::args::utf8)?;
    let sections: Vec<(&str, Bench)> = match what {
        "frames" => vec![("frames", frames::frames)],
        "build" => vec![("build", build::build)],
        "rays" => vec![("rays", rays::rays)],
        "tables" => vec![("tables", tables::tables)],
        "streams" => vec![("streams", streams::streams)],
        "gpu" => vec![("gpu", gpu::gpu)],
        "chart" => vec![("chart", chart::chart)],
        "memory" => vec![("memory", memory::memory)],
        "all" => vec![
            ("frames", frames::frames),
            ("build", build::build),
            ("rays", rays::rays),
            ("tables", tables::tables),
            ("streams", streams::streams),
            ("gpu", gpu::gpu),
            ("chart", chart::chart),
            ("memory", memory::memory),
        ],
        _ => {
            return Err(Error::invalid_argument(format!(
                "unknown benchmark '{what}'\n{USAGE}"
            )))
        }
    };
    for (name, f) in sections {
        let body = f(&a)?;
        let text = format!(
            "Machine: {}. Command: `cargo run --release {}--bin rt2 -- bench {name} --runs {}`.\n\n{body}",
            machine(),
            if name == "chart" { "--features chart " } else { "" },
            a.runs
        );
        // The file first: it keeps the measurement if stdout's reader has gone (`| head`).
        if let Some(path) = &a.write {
            replace_section(path, name, &text)?;
        }
        say(format_args!("\n{text}"))?;
    }
    Ok(())
}

fn shared() -> PathBuf {
    std::env::var_os("RT2_SHARED")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from("../shared"))
}

fn machine() -> String {
    let cpu = std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("model name"))
                .map(|l| l.split(':').nth(1).unwrap_or("").trim().to_string())
        })
        .unwrap_or_else(|| "unknown CPU".into());
    let cores = std::thread::available_parallelism().map_or(0, |n| n.get());
    format!("{cpu}, {cores} cores")
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(|a, b| a.total_cmp(b));
    v[v.len() / 2]
}

/// Median wall time in ms of `runs` calls of `f` after one warm-up call.
fn time_ms(runs: usize, mut f: impl FnMut()) -> f64 {
    f();
    median(
        (0..runs)
            .map(|_| {
                let t = Instant::now();
                f();
                t.elapsed().as_secs_f64() * 1e3
            })
            .collect(),
    )
}

/// Fails unless `path` can take a section later: it is readable text and opens for
/// appending, which does not truncate it; or it is missing and can be created (it is, and
/// removed again: a folder may exist and still refuse new files).
fn check_writable(path: &Path) -> Result<()> {
    read_benchmarks(path)?;
    let folder = path.parent().filter(|p| !p.as_os_str().is_empty());
    if !path.exists() {
        if folder.is_some_and(|f| !f.is_dir()) {
            return Err(Error::io(format!(
                "{}: its folder does not exist",
                path.display()
            )));
        }
        return std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(path)
            .and_then(|_| std::fs::remove_file(path))
            .map_err(|e| Error::io(format!("cannot create {}: {e}", path.display())));
    }
    std::fs::OpenOptions::new()
        .append(true)
        .open(path)
        .map(drop)
        .map_err(|e| Error::io(format!("cannot write {}: {e}", path.display())))
}

/// The text of the benchmark file `path`; only a missing file starts empty: any other failure
/// (not UTF-8, unreadable) must not lead to overwriting the file with one section.
fn read_benchmarks(path: &Path) -> Result<String> {
    match std::fs::read_to_string(path) {
        Ok(old) => Ok(old),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok("# Benchmarks\n".into()),
        Err(e) => Err(Error::io(format!("cannot read {}: {e}", path.display()))),
    }
}

/// Replaces the text between `<!-- bench:NAME -->` markers in `path` (appending if absent).
fn replace_section(path: &Path, name: &str, text: &str) -> Result<()> {
    let (open, close) = (
        format!("<!-- bench:{name} -->"),
        format!("<!-- /bench:{name} -->"),
    );
    let old = read_benchmarks(path)?;
    let block = format!("{open}\n{text}\n{close}");
    let new = match (old.find(&open), old.find(&close)) {
        (Some(a), Some(b)) if b > a => format!("{}{block}{}", &old[..a], &old[b + close.len()..]),
        _ => format!("{}\n{block}\n", old.trim_end()),
    };
    std::fs::write(path, new)
        .map_err(|e| Error::io(format!("cannot write {}: {e}", path.display())))
}

fn mib(bytes: usize) -> f64 {
    bytes as f64 / 1048576.0
}

/// A mesh from the shared models as a scene with one object.
fn model_scene(name: &str) -> Result<Option<Scene>> {
    let path = shared().join("models").join(name);
    if !path.exists() {
        warn(format_args!(
            "bench: {} is missing; skipped",
            path.display()
        ));
        return Ok(None);
    }
    let mesh = loaders::load_mesh(&path)?;
    let mut s = Scene::new();
    s.add_object(
        Shape::Mesh {
            positions: mesh.positions,
            triangles: mesh.triangles,
        },
        0,
    )?;
    Ok(Some(s))
}

fn embree_harness() -> Option<PathBuf> {
    let p = std::env::var_os("RT2_EMBREE_BENCH")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from("target/peers/bench_embree"));
    p.exists().then_some(p)
}

/// The peers' ray set generator (`rt2gen`), built beside Embree's harness.
fn ray_generator() -> Option<PathBuf> {
    embree_harness()
        .map(|h| h.with_file_name("rt2gen"))
        .filter(|p| p.exists())
}

/// Runs Embree's harness with `runs` runs on each of `threads` (its `--threads` list, e.g.
/// "1,2") and returns its TSV rows (split into fields).
fn embree_rows(mesh: &Path, rays: &[PathBuf], runs: usize, threads: &str) -> Vec<Vec<String>> {
    let Some(exe) = embree_harness() else {
        warn("bench: Embree's harness is not built; Embree columns are empty");
        return Vec::new();
    };
    let tsv = std::env::temp_dir().join(format!("rt2-embree-{}.tsv", std::process::id()));
    let _ = std::fs::remove_file(&tsv);
    let status = Command::new(exe)
        .arg(mesh)
        .args(rays)
        .args(["--runs", &runs.to_string(), "--threads", threads, "--tsv"])
        .arg(&tsv)
        .stdout(std::process::Stdio::null())
        .status();
    if !status.is_ok_and(|s| s.success()) {
        warn("bench: Embree's harness failed");
        return Vec::new();
    }
    let text = std::fs::read_to_string(&tsv).unwrap_or_default();
    let _ = std::fs::remove_file(&tsv);
    text.lines()
        .map(|l| l.split('\t').map(str::to_string).collect())
        .collect()
}

/// The first ray set of `kind` (e.g. "incoherent") for `model` in the shared ray sets.
fn find_set(model: &str, kind: &str) -> Option<PathBuf> {
    let dir = shared().join("raysets").join(model);
    let found = std::fs::read_dir(&dir).ok().and_then(|d| {
        d.filter_map(|e| e.ok().map(|e| e.path())).find(|p| {
            p.file_name().is_some_and(|n| {
                let n = n.to_string_lossy();
                n.starts_with(&format!("{kind}_")) && n.ends_with(".rays")
            })
        })
    });
    if found.is_none() {
        warn(format_args!(
            "bench: no {kind}_*.rays in {}; skipped",
            dir.display()
        ));
    }
    found
}

#[cfg(test)]
mod tests {
    /// A benchmark file that cannot be read as text is an error and stays as it was; a
    /// missing one is started.
    #[test]
    fn replace_section_never_overwrites_a_file_it_could_not_read() {
        let dir = std::env::temp_dir().join(format!("rt2-bench-test-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let binary = dir.join("binary.md");
        std::fs::write(&binary, b"\xff\xfe not UTF-8").unwrap();
        assert!(super::replace_section(&binary, "x", "new").is_err());
        assert_eq!(std::fs::read(&binary).unwrap(), b"\xff\xfe not UTF-8");

        let missing = dir.join("missing.md");
        let _ = std::fs::remove_file(&missing);
        super::replace_section(&missing, "x", "new").unwrap();
        let text = std::fs::read_to_string(&missing).unwrap();
        assert!(text.starts_with("# Benchmarks") && text.contains("<!-- bench:x -->\nnew\n"));
    }
}
