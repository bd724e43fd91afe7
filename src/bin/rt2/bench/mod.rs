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
use std::cell::RefCell;
use std::ffi::OsString;
use std::fmt::Display;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

const USAGE: &str = "usage: rt2 bench [frames|build|rays|tables|streams|gpu|chart|memory|all] [--runs N] [--write FILE]
  (no name: all of them, which takes hours)
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
  --runs N       timed runs per figure, 1 to 1000 (default 5; the median is reported); figures
                 that take seconds a run (the dragon's builds and frames, the K_T sweep's
                 builds, the 1376x768 orbit) take at most 3
  --write FILE   also replace this benchmark's section in FILE (e.g. BENCHMARKS.md); a section
                 measured without some of its inputs (a model, a ray set, Embree) is not written
Model files come from $RT2_SHARED (default ../shared); Embree from $RT2_EMBREE_BENCH or
target/peers/bench_embree (make -C ../shared/peers BUILD=$PWD/target/peers).";

/// One benchmark: it returns the Markdown section it measured.
type Bench = fn(&Args) -> Result<String>;

struct Args {
    runs: usize,
    write: Option<PathBuf>,
    /// What the running benchmark went without (a model, a ray set, a peer): said on stderr as
    /// it is found, and a section measured without something is not written to `write` (it
    /// would replace a complete section with one missing rows or columns).
    missing: RefCell<Vec<String>>,
}

impl Args {
    /// Notes that the running benchmark goes without `what` (which says what it leaves out).
    /// Said once however often it is found (a peer missing for every model).
    fn skip(&self, what: impl Display) {
        let what = what.to_string();
        let mut missing = self.missing.borrow_mut();
        if !missing.contains(&what) {
            warn(format_args!("bench: {what}"));
            missing.push(what);
        }
    }
}

pub fn run(args: &[OsString]) -> Result<()> {
    let mut what = None;
    let mut a = Args {
        runs: 5,
        write: None,
        missing: RefCell::default(),
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
    let mut unwritten = Vec::new();
    for (name, f) in sections {
        let body = f(&a)?;
        let missing = a.missing.take();
        let incomplete = if missing.is_empty() {
            String::new()
        } else {
            format!(
                "**Incomplete**, measured without: {}.\n\n",
                missing.join("; ")
            )
        };
        // `memory` times nothing: its command takes no runs.
        let runs = match name {
            "memory" => String::new(),
            _ => format!(" --runs {}", a.runs),
        };
        let text = format!(
            "Machine: {}. Command: `cargo run --release {}--bin rt2 -- bench {name}{runs}`.\n\n{incomplete}{body}",
            machine(),
            if name == "chart" { "--features chart " } else { "" },
        );
        // The file first: it keeps the measurement if stdout's reader has gone (`| head`).
        match &a.write {
            Some(path) if missing.is_empty() => replace_section(path, name, &text)?,
            Some(_) => unwritten.push(name),
            None => {}
        }
        say(format_args!("\n{text}"))?;
    }
    match (&a.write, unwritten.is_empty()) {
        (Some(path), false) => Err(Error::io(format!(
            "bench {}: measured without some of its inputs (said above); {} keeps its section",
            unwritten.join(", "),
            path.display()
        ))),
        _ => Ok(()),
    }
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

/// Most timed runs of a figure that takes seconds a run (the dragon's builds and frames, the
/// K_T sweep's builds, the 1376×768 orbit): `--runs` above it counts for the other figures.
const MAX_RUNS_LARGE: usize = 3;

/// The median of `v` (not empty): the middle value, or the mean of the two middle ones for an
/// even count, as Embree's harness takes it (`rt2io.h`).
fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(|a, b| a.total_cmp(b));
    let m = v.len() / 2;
    if v.len().is_multiple_of(2) {
        0.5 * (v[m - 1] + v[m])
    } else {
        v[m]
    }
}

/// The median over runs of `x[run] / y[run]`: a busy spell of this shared machine slows both
/// sides of a run, so the ratio of one run's pair moves less than the ratio of two medians,
/// which may come from different runs.
fn paired_ratio(x: &[f64], y: &[f64]) -> f64 {
    median(x.iter().zip(y).map(|(x, y)| x / y).collect())
}

/// Median wall time in ms of `runs` calls of `f` after one warm-up call; the first failure
/// ends the timing and is returned (a failed call would be timed as work done).
fn time_ms(runs: usize, mut f: impl FnMut() -> Result<()>) -> Result<f64> {
    f()?;
    let mut times = Vec::with_capacity(runs);
    for _ in 0..runs {
        let t = Instant::now();
        f()?;
        times.push(t.elapsed().as_secs_f64() * 1e3);
    }
    Ok(median(times))
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

/// `path` if it exists; else `None`, noted in `a` with what its absence leaves out.
fn present(a: &Args, path: PathBuf, left_out: &str) -> Option<PathBuf> {
    if path.exists() {
        return Some(path);
    }
    a.skip(format_args!("{} ({left_out})", path.display()));
    None
}

/// The shared model `name` (e.g. "bunny.ply"), if it is there ([`present`]).
fn shared_model(a: &Args, name: &str) -> Option<PathBuf> {
    present(
        a,
        shared().join("models").join(name),
        "missing; its rows skipped",
    )
}

/// A mesh from the shared models as a scene with one object (`None`, noted in `a`, when the
/// model is missing).
fn model_scene(a: &Args, name: &str) -> Result<Option<Scene>> {
    let Some(path) = shared_model(a, name) else {
        return Ok(None);
    };
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

/// Embree's harness, if it is built ([`present`]: its columns stay empty without it).
fn embree_harness(a: &Args) -> Option<PathBuf> {
    let path = std::env::var_os("RT2_EMBREE_BENCH")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from("target/peers/bench_embree"));
    present(
        a,
        path,
        "Embree's harness, not built; its columns are empty",
    )
}

/// The peers' ray set generator (`rt2gen`), built beside Embree's harness.
fn ray_generator(a: &Args) -> Option<PathBuf> {
    embree_harness(a)
        .map(|h| h.with_file_name("rt2gen"))
        .filter(|p| p.exists())
}

/// One row of the TSV that Embree's harness writes (`Reporter` in
/// `../shared/peers/src/bench_common.h`), its numbers read.
#[derive(Clone, Debug, PartialEq)]
enum EmbreeRow {
    /// `peer mesh set mode threads rays median_ms Mrays/s others runs_ms`.
    Trace {
        set: String,
        mode: String,
        threads: u32,
        mrays: f64,
    },
    /// `peer mesh BUILD name threads bytes median_ms - others runs_ms`.
    Build {
        name: String,
        threads: u32,
        bytes: u64,
        ms: f64,
    },
}

impl EmbreeRow {
    /// Reads one TSV line; a line short of fields or with a number that is not one is an
    /// error, never a zero or a NaN in a table.
    fn parse(line: &str) -> Result<Self> {
        let f: Vec<&str> = line.split('\t').collect();
        let bad = |what: &str| {
            Error::parse(format!(
                "bench: Embree's harness wrote a row without {what}: {line:?}"
            ))
        };
        if f.len() < 9 {
            return Err(bad("all of its 9 fields"));
        }
        let positive = |k: usize, what: &str| {
            f[k].parse::<f64>()
                .ok()
                .filter(|x| x.is_finite() && *x > 0.0)
                .ok_or_else(|| bad(what))
        };
        let threads = f[4]
            .parse::<u32>()
            .ok()
            .filter(|&t| t > 0)
            .ok_or_else(|| bad("a thread count"))?;
        Ok(if f[2] == "BUILD" {
            EmbreeRow::Build {
                name: f[3].into(),
                threads,
                bytes: f[5].parse().map_err(|_| bad("a byte count"))?,
                ms: positive(6, "a time in ms")?,
            }
        } else {
            EmbreeRow::Trace {
                set: f[2].into(),
                mode: f[3].into(),
                threads,
                mrays: positive(7, "a speed in Mrays/s")?,
            }
        })
    }

    /// Mrays/s of a trace of `set` in `mode` on `threads` threads.
    fn speed(&self, set: &str, mode: &str, threads: u32) -> Option<f64> {
        match self {
            EmbreeRow::Trace {
                set: s,
                mode: m,
                threads: t,
                mrays,
            } if s == set && m == mode && *t == threads => Some(*mrays),
            _ => None,
        }
    }
}

/// Runs Embree's harness with `runs` runs on each of `threads` (its `--threads` list, e.g.
/// "1,2") and returns its rows; none (noted in `a`) where the harness is not built. A harness
/// that fails, writes nothing or writes what is not its TSV is an error.
fn embree_rows(
    a: &Args,
    mesh: &Path,
    rays: &[PathBuf],
    runs: usize,
    threads: &str,
) -> Result<Vec<EmbreeRow>> {
    let Some(exe) = embree_harness(a) else {
        return Ok(Vec::new());
    };
    let tsv = std::env::temp_dir().join(format!("rt2-embree-{}.tsv", std::process::id()));
    let _ = std::fs::remove_file(&tsv);
    let status = Command::new(&exe)
        .arg(mesh)
        .args(rays)
        .args(["--runs", &runs.to_string(), "--threads", threads, "--tsv"])
        .arg(&tsv)
        .stdout(std::process::Stdio::null())
        .status()
        .map_err(|e| Error::io(format!("bench: cannot run {}: {e}", exe.display())))?;
    // Read and removed before the status is looked at: a failed run may have started the file.
    let text = std::fs::read_to_string(&tsv);
    let _ = std::fs::remove_file(&tsv);
    if !status.success() {
        return Err(Error::io(format!(
            "bench: Embree's harness {} failed ({status}) on {}",
            exe.display(),
            mesh.display()
        )));
    }
    let text = text.map_err(|e| {
        Error::io(format!(
            "bench: Embree's harness {} wrote no results ({}: {e})",
            exe.display(),
            tsv.display()
        ))
    })?;
    let rows = text
        .lines()
        .map(EmbreeRow::parse)
        .collect::<Result<Vec<_>>>()?;
    if rows.is_empty() {
        return Err(Error::io(format!(
            "bench: Embree's harness {} wrote no results",
            exe.display()
        )));
    }
    Ok(rows)
}

/// The shared ray sets of `model` whose names start with one of `kinds` and an underscore
/// (e.g. "incoherent" for `incoherent_262144.rays`), sorted by name; none, noted in `a`, when
/// there are none.
fn ray_sets(a: &Args, model: &str, kinds: &[&str]) -> Vec<PathBuf> {
    let dir = shared().join("raysets").join(model);
    let mut sets: Vec<PathBuf> = std::fs::read_dir(&dir)
        .map(|d| {
            d.filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| {
                    p.extension().is_some_and(|x| x == "rays")
                        && p.file_name().is_some_and(|n| {
                            let n = n.to_string_lossy();
                            kinds.iter().any(|k| n.starts_with(&format!("{k}_")))
                        })
                })
                .collect()
        })
        .unwrap_or_default();
    sets.sort();
    if sets.is_empty() {
        a.skip(format_args!(
            "{}_*.rays in {} (none there; their figures skipped)",
            kinds.join("|"),
            dir.display()
        ));
    }
    sets
}

/// The first ray set of `kind` for `model` ([`ray_sets`]).
fn find_set(a: &Args, model: &str, kind: &str) -> Option<PathBuf> {
    ray_sets(a, model, &[kind]).into_iter().next()
}

#[cfg(test)]
mod tests {
    /// An even count's median is the mean of the two middle values, as Embree's harness takes
    /// it (it was the upper one: with `--runs 2`, always the slower run).
    #[test]
    fn an_even_count_has_the_mean_of_its_middle_values_for_median() {
        assert_eq!(super::median(vec![4.0, 1.0, 3.0, 2.0]), 2.5);
        assert_eq!(super::median(vec![30.0, 10.0]), 20.0);
        assert_eq!(super::median(vec![3.0, 1.0, 2.0]), 2.0);
    }

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
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
