//! `rt2 bench`: the measurements quoted in BENCHMARKS.md. Every figure is a median of several
//! runs; Embree (the peer of `../shared/peers`) is measured in the same invocation when its
//! harness is built, so ratios compare like with like on a noisy shared machine.

mod chart;
mod streams;

use crate::load_scene;
use rt2::context::{Context, QueryOptions};
use rt2::cpu::traverse::Traversal;
use rt2::dispatch::BackendRequest;
use rt2::error::{Error, Result};
use rt2::frame::Frame;
use rt2::geometry::{Hit, Ray};
use rt2::kdtree::{BuildOptions, Builder, Layout};
use rt2::rayset::{self, HitRecord};
use rt2::render::{GpuPathRequest, RenderOptions};
use rt2::scene::{loaders, Scene, Shape};
use std::fmt::Write as _;
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
  --runs N       timed runs per figure (default 5; the median is reported)
  --write FILE   also replace this benchmark's section in FILE (e.g. BENCHMARKS.md)
Model files come from $RT2_SHARED (default ../shared); Embree from $RT2_EMBREE_BENCH or
target/peers/bench_embree (make -C ../shared/peers BUILD=$PWD/target/peers).";

/// One benchmark: it returns the Markdown section it measured.
type Bench = fn(&Args) -> Result<String>;

struct Args {
    runs: usize,
    write: Option<PathBuf>,
}

pub fn run(args: &[String]) -> Result<()> {
    let mut what = "all".to_string();
    let mut a = Args {
        runs: 5,
        write: None,
    };
    let mut it = args.iter();
    while let Some(x) = it.next() {
        match x.as_str() {
            "--runs" => a.runs = crate::parse(x, it.next())?,
            "--write" => a.write = Some(PathBuf::from(crate::parse::<String>(x, it.next())?)),
            "-h" | "--help" => {
                println!("{USAGE}");
                return Ok(());
            }
            s if !s.starts_with('-') => what = s.to_string(),
            s => {
                return Err(Error::invalid_argument(format!(
                    "unknown option '{s}'\n{USAGE}"
                )))
            }
        }
    }
    a.runs = a.runs.max(1);
    let sections: Vec<(&str, Bench)> = match what.as_str() {
        "frames" => vec![("frames", frames)],
        "build" => vec![("build", build)],
        "rays" => vec![("rays", rays)],
        "tables" => vec![("tables", tables)],
        "streams" => vec![("streams", streams::streams)],
        "gpu" => vec![("gpu", gpu)],
        "chart" => vec![("chart", chart::chart)],
        "memory" => vec![("memory", chart::memory)],
        "all" => vec![
            ("frames", frames),
            ("build", build),
            ("rays", rays),
            ("tables", tables),
            ("streams", streams::streams),
            ("gpu", gpu),
            ("chart", chart::chart),
            ("memory", chart::memory),
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
        println!("\n{text}");
        if let Some(path) = &a.write {
            replace_section(path, name, &text)?;
        }
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

/// Replaces the text between `<!-- bench:NAME -->` markers in `path` (appending if absent).
fn replace_section(path: &Path, name: &str, text: &str) -> Result<()> {
    let (open, close) = (
        format!("<!-- bench:{name} -->"),
        format!("<!-- /bench:{name} -->"),
    );
    // Only a missing file starts empty: any other failure (not UTF-8, unreadable) must not
    // lead to overwriting the file with one section.
    let old = match std::fs::read_to_string(path) {
        Ok(old) => old,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => "# Benchmarks\n".into(),
        Err(e) => return Err(Error::io(format!("cannot read {}: {e}", path.display()))),
    };
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

fn frames(a: &Args) -> Result<String> {
    let ctx = Context::new(BackendRequest::Cpu, 0)?;
    let mut out = String::from(
        "### Whitted frames on the CPU (1376x768, 1 sample, AUTO traversal)\n\n\
         | scene | primitives | commit ms | ms/frame (median) | M primary rays/s | nodes MiB | leaf lists MiB | primitives MiB |\n\
         |---|---|---|---|---|---|---|---|\n",
    );
    let bunny = shared().join("models/bunny.ply");
    let mut names = vec!["spheres3".to_string()];
    if bunny.exists() {
        names.push(bunny.display().to_string());
    } else {
        eprintln!(
            "bench frames: {} is missing; the bunny row is skipped",
            bunny.display()
        );
    }
    for name in names {
        let mut l = load_scene(&name)?;
        let opts = RenderOptions {
            max_depth: l.max_depth,
            ..RenderOptions::default()
        };
        let commit_ms = time_ms(a.runs, || {
            let _ = ctx.install(|| l.scene.commit());
        });
        let c = l.scene.committed()?;
        let mut frame = Frame::new(1376, 768)?;
        let ms = time_ms(a.runs, || {
            let _ = ctx.render(c, &l.camera, &opts, &mut frame);
        });
        let label = Path::new(&name)
            .file_stem()
            .map_or(name.clone(), |s| s.to_string_lossy().into());
        writeln!(
            out,
            "| {label} (depth {}) | {} | {commit_ms:.1} | {ms:.1} | {:.2} | {:.2} | {:.2} | {:.2} |",
            l.max_depth,
            c.prims.len() + c.prims.planes.len(),
            1376.0 * 768.0 / ms / 1e3,
            mib(c.tree.node_bytes()),
            mib(c.tree.leaf_list_bytes()),
            mib(c.prims.bytes())
        )
        .ok();
    }
    out += &moving_objects(a, &ctx)?;
    Ok(out)
}

/// The RT² per-frame rebuild: every frame moves a tenth of spheres3's spheres
/// (`set_transform`) and commits, which rebuilds the whole tree.
fn moving_objects(a: &Args, ctx: &Context) -> Result<String> {
    let mut l = load_scene("spheres3")?;
    let objects = l.scene.objects().len() as u32;
    let mut frame = 0u32;
    let ms = time_ms(a.runs, || {
        frame += 1;
        for o in (frame % 10..objects).step_by(10) {
            let dy = 0.1 * ((frame + o) % 7) as f32;
            let _ = l.scene.set_transform(
                o,
                glam::Affine3A::from_translation(glam::Vec3::new(0.0, dy, 0.0)),
            );
        }
        let _ = ctx.install(|| l.scene.commit());
    });
    Ok(format!(
        "\nMoving objects (RT² per-frame rebuild): spheres3 with {} of its {objects} objects moved per frame, \
         set_transform + commit: {ms:.2} ms per frame (median).\n",
        objects / 10
    ))
}

/// A mesh from the shared models as a scene with one object.
fn model_scene(name: &str) -> Result<Option<Scene>> {
    let path = shared().join("models").join(name);
    if !path.exists() {
        eprintln!("bench: {} is missing; skipped", path.display());
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

/// Runs Embree's harness and returns its TSV rows (split into fields).
fn embree_rows(mesh: &Path, rays: &[PathBuf], runs: usize) -> Vec<Vec<String>> {
    let Some(exe) = embree_harness() else {
        eprintln!("bench: Embree's harness is not built; Embree columns are empty");
        return Vec::new();
    };
    let tsv = std::env::temp_dir().join(format!("rt2-embree-{}.tsv", std::process::id()));
    let _ = std::fs::remove_file(&tsv);
    let status = Command::new(exe)
        .arg(mesh)
        .args(rays)
        .args(["--runs", &runs.to_string(), "--threads", "1,2", "--tsv"])
        .arg(&tsv)
        .stdout(std::process::Stdio::null())
        .status();
    if !status.is_ok_and(|s| s.success()) {
        eprintln!("bench: Embree's harness failed");
        return Vec::new();
    }
    let text = std::fs::read_to_string(&tsv).unwrap_or_default();
    let _ = std::fs::remove_file(&tsv);
    text.lines()
        .map(|l| l.split('\t').map(str::to_string).collect())
        .collect()
}

fn build(a: &Args) -> Result<String> {
    let mut out = String::from(
        "### kd-tree build (median ms) and memory\n\n\
         | model | triangles | builder | 1 thread ms | 2 threads ms | nodes | tree MiB | bytes/triangle | SAH cost |\n\
         |---|---|---|---|---|---|---|---|---|\n",
    );
    let mut embree = String::new();
    let mut ratios = String::new();
    for model in ["bunny.ply", "snowden.ply", "dragon.ply"] {
        let Some(scene) = model_scene(model)? else {
            continue;
        };
        let mut scene = scene;
        let tris = scene.objects()[0].shape.prim_count();
        let mut sah_ms = f64::NAN;
        for builder in [Builder::Sah, Builder::Midpoint] {
            scene.set_build_options(BuildOptions {
                builder,
                ..BuildOptions::default()
            });
            let mut ms = [0.0; 2];
            for (k, threads) in [1u32, 2].into_iter().enumerate() {
                let ctx = Context::new(BackendRequest::Cpu, threads)?;
                let runs = if tris > 500_000 {
                    a.runs.min(3)
                } else {
                    a.runs
                };
                ms[k] = median_build_ms(&ctx, &mut scene, runs);
            }
            if builder == Builder::Sah {
                sah_ms = ms[1];
            }
            let c = scene.committed()?;
            let bytes = c.tree.node_bytes() + c.tree.leaf_list_bytes();
            writeln!(
                out,
                "| {model} | {tris} | {builder:?} | {:.1} | {:.1} | {} | {:.2} | {:.1} | {:.1} |",
                ms[0],
                ms[1],
                c.tree.stats.node_count,
                mib(bytes),
                bytes as f64 / tris as f64,
                c.tree.stats.sah_cost
            )
            .ok();
        }
        if let Some(shadow) = find_set(model.trim_end_matches(".ply"), "shadow") {
            // Embree's multi-threaded medians by build name, for the ratios: the harness builds
            // with one thread and with every hardware thread.
            let mut many = std::collections::HashMap::new();
            for r in embree_rows(&shared().join("models").join(model), &[shadow], a.runs) {
                if r.get(2).is_some_and(|s| s == "BUILD") {
                    let threads: u32 = r[4].parse().unwrap_or(1);
                    if threads > 1 {
                        let ms = r[6].parse::<f64>().unwrap_or(f64::NAN);
                        many.insert(r[3].clone(), (threads, ms));
                    }
                    writeln!(
                        embree,
                        "| {model} | {} | {} | {} | {:.2} |",
                        r[3],
                        r[4],
                        r[6],
                        r[5].parse::<f64>().unwrap_or(0.0) / 1048576.0
                    )
                    .ok();
                }
            }
            let ratio = |name: &str| {
                many.get(name).map_or("—".into(), |&(t, e)| {
                    format!("{:.2}x ({t} threads)", sah_ms / e)
                })
            };
            if !many.is_empty() {
                writeln!(
                    ratios,
                    "| {model} | {sah_ms:.1} | {} | {} |",
                    ratio("high(non-robust)"),
                    ratio("robust+high")
                )
                .ok();
            }
        }
    }
    if !ratios.is_empty() {
        out += "\nSAH with perfect splits on 2 threads against Embree 3 on every hardware thread \
                (RT2 ms / Embree ms). Embree's \
                high-quality build is `RTC_BUILD_QUALITY_HIGH` without `RTC_SCENE_FLAG_ROBUST`: \
                an SBVH, whose spatial splits are the BVH analogue of perfect splits. With the \
                ROBUST flag Embree 3.13 ignores the quality and runs its static SAH builder \
                (`../shared/peers/src/bench_embree.cpp`), which makes no spatial splits.\n\n\
                | model | RT2 SAH 2 threads ms | vs Embree high (SBVH) | vs Embree robust (static SAH) |\n\
                |---|---|---|---|\n";
        out += &ratios;
    }
    out += &layout_effect(a)?;
    out += &traversal_cost_effect(a)?;
    if !embree.is_empty() {
        out += "\nEmbree 3 in the same run:\n\n| model | build | threads | median ms | MiB |\n|---|---|---|---|---|\n";
        out += &embree;
    }
    Ok(out)
}

/// Median tree build time of `runs` commits of `scene` on `ctx`'s threads (NaN for a failed
/// commit).
fn median_build_ms(ctx: &Context, scene: &mut Scene, runs: usize) -> f64 {
    median(
        (0..runs)
            .map(|_| {
                let _ = ctx.install(|| scene.commit());
                scene
                    .committed()
                    .map_or(f64::NAN, |c| c.tree.stats.build_ms as f64)
            })
            .collect(),
    )
}

/// The SAH's traversal cost `K_T` trades memory and build time against speed: a larger `K_T`
/// makes fewer, fuller leaves. For the bunny and the dragon: tree size with and without ropes,
/// build time (2 threads), and Mrays/s (1 thread, standard traversal) of single rays, packets
/// and streams on the incoherent and primary sets.
fn traversal_cost_effect(a: &Args) -> Result<String> {
    use rt2::cpu::query::QueryMode;
    let mut out = String::from(
        "\nEffect of the SAH traversal cost K_T (intersection cost 1; default marked *): tree \
         size, build time (2 threads) and Mrays/s (1 thread, standard traversal) on the \
         incoherent (inc) and primary (pri) sets:\n\n\
         | model | K_T | nodes | refs/leaf | tree MiB | with ropes MiB | ropes / plain | build ms | \
         inc single | inc packets | inc stream | pri single | pri packets | pri stream |\n\
         |---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    let (build_ctx, ctx) = (
        Context::new(BackendRequest::Cpu, 2)?,
        Context::new(BackendRequest::Cpu, 1)?,
    );
    for model in ["bunny", "dragon"] {
        let Some(mut scene) = model_scene(&format!("{model}.ply"))? else {
            continue;
        };
        let sets: Vec<Vec<Ray>> = ["incoherent", "primary"]
            .iter()
            .filter_map(|kind| find_set(model, kind))
            .filter_map(|path| rayset::read_rays(&path).ok())
            .collect();
        for traversal_cost in [1.0, 1.5, 2.0, 2.5, 3.0, 4.0] {
            let options = BuildOptions {
                traversal_cost,
                ..BuildOptions::default()
            };
            scene.set_build_options(options);
            let build_ms = median_build_ms(&build_ctx, &mut scene, a.runs.min(3));
            scene.ensure_ropes()?;
            let c = scene.committed()?;
            let plain = c.tree.node_bytes() + c.tree.leaf_list_bytes();
            let ropes = plain + c.tree.rope_bytes() + c.tree.leaf_box_bytes();
            let default = if traversal_cost == BuildOptions::default().traversal_cost {
                "*"
            } else {
                ""
            };
            let mut row = format!(
                "| {model} | {traversal_cost}{default} | {} | {:.2} | {:.2} | {:.2} | {:.2}x | {build_ms:.0} |",
                c.tree.stats.node_count,
                c.tree.stats.avg_prims_per_leaf,
                mib(plain),
                mib(ropes),
                ropes as f64 / plain as f64,
            );
            for rays in &sets {
                for mode in [QueryMode::Single, QueryMode::Packet, QueryMode::Stream] {
                    let q = QueryOptions {
                        traversal: Some(Traversal::Standard),
                        mode,
                        ..QueryOptions::default()
                    };
                    let mut hits = vec![Hit::MISS; rays.len()];
                    let ms = time_ms(a.runs, || {
                        let _ = ctx.intersect(c, rays, &mut hits, &q);
                    });
                    write!(row, " {:.2} |", rays.len() as f64 / ms / 1e3).ok();
                }
            }
            writeln!(out, "{row}").ok();
        }
    }
    Ok(out)
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
        eprintln!("bench: no {kind}_*.rays in {}; skipped", dir.display());
    }
    found
}

/// Effect of the van Emde Boas node order on traversal speed: the standard traversal on the
/// bunny's incoherent and primary sets, 1 thread, depth-first vs van Emde Boas trees.
fn layout_effect(a: &Args) -> Result<String> {
    let Some(mut scene) = model_scene("bunny.ply")? else {
        return Ok(String::new());
    };
    let ctx = Context::new(BackendRequest::Cpu, 1)?;
    let mut out = String::from(
        "\nEffect of the node layout (bunny, standard traversal, 1 thread, Mrays/s):\n\n\
         | set | depth-first | van Emde Boas |\n|---|---|---|\n",
    );
    for set in ["incoherent_262144", "primary_262144"] {
        let path = shared().join("raysets/bunny").join(format!("{set}.rays"));
        let Ok(rays) = rayset::read_rays(&path) else {
            eprintln!("bench: {} is missing; skipped", path.display());
            continue;
        };
        let mut row = format!("| {set} |");
        for layout in [Layout::DepthFirst, Layout::VanEmdeBoas] {
            scene.set_build_options(BuildOptions {
                layout,
                ..BuildOptions::default()
            });
            scene.commit()?;
            let c = scene.committed()?;
            let q = QueryOptions {
                traversal: Some(Traversal::Standard),
                ..QueryOptions::default()
            };
            let mut hits = vec![Hit::MISS; rays.len()];
            let ms = time_ms(a.runs, || {
                let _ = ctx.intersect(c, &rays, &mut hits, &q);
            });
            write!(row, " {:.2} |", rays.len() as f64 / ms / 1e3).ok();
        }
        writeln!(out, "{row}").ok();
    }
    Ok(out)
}

fn rays(a: &Args) -> Result<String> {
    let mut out = String::from(
        "### Ray queries on the shared ray sets (single rays, CPU)\n\n\
         Disagreement with Embree's hits counts hit/miss differences and different triangles with \
         |Δt| > 1e-4·diag (`rt2cmp`'s rule); ties on shared edges are not disagreements.\n\n\
         | set | method | 1 thread Mrays/s | 2 threads Mrays/s | nodes/ray | leaves/ray | tests/ray | disagreements |\n\
         |---|---|---|---|---|---|---|---|\n",
    );
    for model in ["bunny", "dragon"] {
        let Some(mut scene) = model_scene(&format!("{model}.ply"))? else {
            continue;
        };
        scene.commit()?;
        scene.ensure_ropes()?;
        let c = scene.committed()?;
        let diag = c.bounds.diagonal();
        let dir = shared().join("raysets").join(model);
        let mut sets: Vec<PathBuf> = std::fs::read_dir(&dir)
            .map_err(|e| Error::io(format!("{}: {e}", dir.display())))?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.extension().is_some_and(|x| x == "rays"))
            .collect();
        sets.sort();
        let embree = embree_rows(
            &shared().join("models").join(format!("{model}.ply")),
            &sets,
            a.runs,
        );
        for set in &sets {
            let rays: Vec<Ray> = rayset::read_rays(set)?;
            let stem = set
                .file_stem()
                .map_or(String::new(), |s| s.to_string_lossy().into());
            let reference = rayset::read_hits(&set.with_extension("embree.hits")).ok();
            for how in Traversal::ALL {
                let q = QueryOptions {
                    traversal: Some(how),
                    ..QueryOptions::default()
                };
                let mut hits = vec![Hit::MISS; rays.len()];
                let mut mrays = [0.0; 2];
                let mut stats = Default::default();
                for (k, threads) in [1u32, 2].into_iter().enumerate() {
                    let ctx = Context::new(BackendRequest::Cpu, threads)?;
                    let ms = time_ms(a.runs, || {
                        stats = ctx.intersect(c, &rays, &mut hits, &q).unwrap_or_default();
                    });
                    mrays[k] = rays.len() as f64 / ms / 1e3;
                }
                let mine: Vec<HitRecord> = hits.iter().map(|h| HitRecord::of(h, c)).collect();
                let agree = reference.as_ref().map_or("no reference".into(), |r| {
                    let g = rayset::compare(&mine, r, diag, 1e-4);
                    format!("{} of {} ({} ties)", g.disagreements(), g.rays, g.ties)
                });
                let n = rays.len() as f64;
                writeln!(
                    out,
                    "| {model} {stem} | RT2 {} | {:.2} | {:.2} | {:.1} | {:.1} | {:.1} | {agree} |",
                    how.name(),
                    mrays[0],
                    mrays[1],
                    stats.nodes_visited as f64 / n,
                    stats.leaves_visited as f64 / n,
                    stats.prim_tests as f64 / n
                )
                .ok();
            }
            for r in embree
                .iter()
                .filter(|r| r.get(2).is_some_and(|s| *s == stem))
            {
                if r[4] == "1" || r[3] == "intersect1" {
                    writeln!(
                        out,
                        "| {model} {stem} | Embree {} ({} thr) | {} | | | | | reference |",
                        r[3], r[4], r[7]
                    )
                    .ok();
                }
            }
        }
    }
    Ok(out)
}

/// The thesis' figures (GTX 295, 1376x768, 2 lights, Phong; DESIGN.md §1): nodes visited per
/// ray on the Bunny (table 1) and ms per frame of the best traversal (table 2).
const THESIS_NODES_BUNNY: [(&str, &str); 7] = [
    ("standard", "18.3"),
    ("kd-restart", "63.3"),
    ("push-down", "55.2"),
    ("short-stack", "43.3"),
    ("push-down-short-stack", "38.5"),
    ("ropes", "18.6"),
    ("ropes++", "-"),
];

fn thesis_ms(scene: &str) -> &'static str {
    match scene {
        "bunny" => "12.18 (ropes++), 13.91 (standard)",
        "dragon" => "22.19",
        "spheres1" => "5.61",
        "spheres2" => "34.5",
        "spheres3" => "35.93",
        _ => "-",
    }
}

fn thesis_memory(scene: &str) -> &'static str {
    match scene {
        "bunny" => "7.7 / 5.8 / 19",
        "dragon" => "17.2 / 15.3 / 47.1",
        _ => "-",
    }
}

fn tables(a: &Args) -> Result<String> {
    let (w, h) = (1376u32, 768u32);
    let ctx = Context::new(BackendRequest::Cpu, 0)?;
    let mut scenes: Vec<String> = Vec::new();
    for model in ["bunny", "dragon", "snowden"] {
        let p = shared().join("models").join(format!("{model}.ply"));
        if p.exists() {
            scenes.push(p.display().to_string());
        } else {
            eprintln!("bench tables: {} is missing; skipped", p.display());
        }
    }
    scenes.extend(["spheres1", "spheres2", "spheres3"].map(String::from));
    let mut t1 = String::from(
        "### Thesis table 1 on the CPU: nodes visited per primary ray (1376x768) and tree memory\n\n\
         Memory: plain tree (nodes + leaf lists, what the stack and restart traversals read) and \
         with ropes (+ 6 packed ropes and a box per leaf, and 2 bits per node to number the leaves). The thesis' memory column is standard / \
         stackless / ropes in MB; its nodes per ray are for the Bunny.\n\n\
         | scene | primitives | traversal | nodes/ray | leaves/ray | tests/ray | thesis nodes/ray | tree MiB | with ropes MiB | thesis MB |\n\
         |---|---|---|---|---|---|---|---|---|---|\n",
    );
    let mut t2 = String::from(
        "### Thesis table 2 on the CPU: ms per 1376x768 frame (median), 2 lights, Phong\n\n\
         | scene | depth | standard | kd-restart | push-down | short-stack | push-down-short-stack | ropes | ropes++ | thesis GPU ms |\n\
         |---|---|---|---|---|---|---|---|---|---|\n",
    );
    for name in scenes {
        let mut l = load_scene(&name)?;
        ctx.install(|| l.scene.commit())?;
        l.scene.ensure_ropes()?;
        let c = l.scene.committed()?;
        let label: String = Path::new(&name)
            .file_stem()
            .map_or(name.clone(), |s| s.to_string_lossy().into());
        let cam = l.camera.rays(w, h);
        let size = glam::Vec2::new(w as f32, h as f32);
        let rays: Vec<Ray> = (0..w * h)
            .map(|i| {
                let px = glam::Vec2::new((i % w) as f32 + 0.5, (i / w) as f32 + 0.5);
                cam.ray(px, size, glam::Vec2::splat(0.5))
            })
            .collect();
        let plain = c.tree.node_bytes() + c.tree.leaf_list_bytes();
        let ropes = plain + c.tree.rope_bytes() + c.tree.leaf_box_bytes();
        let runs = if c.prims.len() > 500_000 {
            a.runs.min(3)
        } else {
            a.runs
        };
        let mut row = format!("| {label} | {} |", l.max_depth);
        for (how, (_, thesis_nodes)) in Traversal::ALL.into_iter().zip(THESIS_NODES_BUNNY) {
            let q = QueryOptions {
                traversal: Some(how),
                ..QueryOptions::default()
            };
            let mut hits = vec![Hit::MISS; rays.len()];
            let st = ctx.intersect(c, &rays, &mut hits, &q)?;
            let n = rays.len() as f64;
            writeln!(
                t1,
                "| {label} | {} | {} | {:.1} | {:.2} | {:.1} | {} | {:.2} | {:.2} | {} |",
                c.prims.len() + c.prims.planes.len(),
                how.name(),
                st.nodes_visited as f64 / n,
                st.leaves_visited as f64 / n,
                st.prim_tests as f64 / n,
                if label == "bunny" { thesis_nodes } else { "-" },
                mib(plain),
                mib(ropes),
                thesis_memory(&label)
            )
            .ok();
            let opts = RenderOptions {
                max_depth: l.max_depth,
                traversal: Some(how),
                ..RenderOptions::default()
            };
            let mut frame = Frame::new(w, h)?;
            let ms = time_ms(runs, || {
                let _ = ctx.render(c, &l.camera, &opts, &mut frame);
            });
            write!(row, " {ms:.1} |").ok();
        }
        writeln!(t2, "{row} {} |", thesis_ms(&label)).ok();
    }
    Ok(format!("{t1}\n{t2}"))
}

/// Thesis table 2 on the GPU backend: ms per frame for every traversal (AUTO render path),
/// then megakernel against wavefront and the GPU against the CPU (both at their AUTO
/// traversal). A software adapter (lavapipe) is labelled as such and renders a quarter of
/// the thesis' frame side (1/16 of the pixels): it shows the kernels work, not GPU speed.
fn gpu(a: &Args) -> Result<String> {
    let ctx = match Context::new(BackendRequest::Gpu, 0) {
        Ok(c) => c,
        Err(e) => {
            return Ok(format!(
                "### GPU backend\n\nNo GPU adapter: {}\n",
                e.message
            ))
        }
    };
    let g = ctx
        .gpu()
        .ok_or_else(|| Error::invalid_operation("no GPU devices"))?;
    let (w, h) = if g.software { (344, 192) } else { (1376, 768) };
    let cpu = Context::new(BackendRequest::Cpu, 0)?;
    let kind = if g.software {
        "SOFTWARE adapter: CPU-emulated GPU, not representative of GPU speed"
    } else {
        "hardware adapter"
    };
    let mut out = format!(
        "### GPU backend: thesis table 2 (ms per {w}x{h} frame, 1 sample, AUTO render path)\n\n\
         Adapter: {} ({kind}).\n\n| scene |",
        g.description
    );
    for t in Traversal::ALL {
        write!(out, " {} |", t.name()).ok();
    }
    out.push_str("\n|---|");
    out.push_str(&"---|".repeat(Traversal::ALL.len()));
    out.push('\n');
    let mut paths = String::from(
        "\n| scene | megakernel ms | wavefront ms | GPU (AUTO) ms | CPU (AUTO) ms | GPU vs CPU |\n|---|---|---|---|---|---|\n",
    );
    let mut names: Vec<String> = Vec::new();
    for m in ["bunny.ply", "dragon.ply", "snowden.ply"] {
        let p = shared().join("models").join(m);
        if p.exists() {
            names.push(p.display().to_string());
        } else {
            eprintln!("bench gpu: {} is missing; skipped", p.display());
        }
    }
    names.extend(["spheres1", "spheres2", "spheres3"].map(String::from));
    for name in names {
        let mut l = load_scene(&name)?;
        l.scene.commit()?;
        l.scene.ensure_ropes()?;
        let c = l.scene.committed()?;
        let label = Path::new(&name)
            .file_stem()
            .map_or(name.clone(), |s| s.to_string_lossy().into());
        let mut frame = Frame::new(w, h)?;
        let base = RenderOptions {
            max_depth: l.max_depth,
            ..RenderOptions::default()
        };
        let mut time = |ctx: &Context, opts: RenderOptions| -> Result<f64> {
            ctx.render(c, &l.camera, &opts, &mut frame)?;
            Ok(time_ms(a.runs, || {
                let _ = ctx.render(c, &l.camera, &opts, &mut frame);
            }))
        };
        write!(out, "| {label} (depth {}) |", l.max_depth).ok();
        for t in Traversal::ALL {
            let ms = time(
                &ctx,
                RenderOptions {
                    traversal: Some(t),
                    ..base
                },
            )?;
            write!(out, " {ms:.1} |").ok();
        }
        out.push('\n');
        let mega = time(
            &ctx,
            RenderOptions {
                gpu_path: GpuPathRequest::Megakernel,
                ..base
            },
        )?;
        let wave = time(
            &ctx,
            RenderOptions {
                gpu_path: GpuPathRequest::Wavefront,
                ..base
            },
        )?;
        let auto = time(&ctx, base)?;
        let on_cpu = time(&cpu, base)?;
        writeln!(
            paths,
            "| {label} | {mega:.1} | {wave:.1} | {auto:.1} | {on_cpu:.1} | {:.2}x |",
            on_cpu / auto
        )
        .ok();
    }
    out.push_str(&paths);
    out.push_str(
        "\nAUTO on the GPU: ropes++ when the tree has ropes (here it has), render path by the \
         share of reflective primitives. CPU: the context's pool, every core. Medians of \
         `--runs` frames after one warm-up frame (which also compiles the kernels).\n",
    );
    Ok(out)
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
