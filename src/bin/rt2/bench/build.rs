//! `rt2 bench build`: kd-tree build time and memory of both builders at 1 and 2 threads, Embree's
//! builds beside, and what two build options do to speed: the node layout and the SAH's
//! traversal cost.

use super::{
    embree_harness, embree_rows, find_set, median, mib, model_scene, paired_ratio, shared, time_ms,
    Args, EmbreeRow, MAX_RUNS_LARGE,
};
use rt2::context::{Context, QueryOptions};
use rt2::cpu::query::QueryMode;
use rt2::cpu::traverse::Traversal;
use rt2::dispatch::BackendRequest;
use rt2::error::Result;
use rt2::geometry::{Hit, Ray};
use rt2::kdtree::{BuildOptions, Builder, Layout};
use rt2::rayset;
use rt2::scene::Scene;
use std::fmt::Write as _;

pub(super) fn build(a: &Args) -> Result<String> {
    let mut out = String::from(
        "### kd-tree build (median ms) and memory\n\n\
         | model | triangles | builder | 1 thread ms | 2 threads ms | nodes | tree MiB | bytes/triangle | SAH cost |\n\
         |---|---|---|---|---|---|---|---|---|\n",
    );
    let mut embree = String::new();
    let mut ratios = String::new();
    for model in ["bunny.ply", "snowden.ply", "dragon.ply"] {
        let Some(mut scene) = model_scene(a, model)? else {
            continue;
        };
        let tris = scene.objects()[0]
            .as_ref()
            .map_or(0, |o| o.shape.prim_count());
        // The dragon's builds take seconds each.
        let runs = if tris > 500_000 {
            a.runs.min(MAX_RUNS_LARGE)
        } else {
            a.runs
        };
        for builder in [Builder::Sah, Builder::Midpoint] {
            scene.set_build_options(BuildOptions {
                builder,
                ..BuildOptions::default()
            });
            let mut ms = [0.0; 2];
            for (k, threads) in [1u32, 2].into_iter().enumerate() {
                let ctx = Context::new(BackendRequest::Cpu, threads)?;
                ms[k] = median_build_ms(&ctx, &mut scene, runs)?;
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
        if let Some((ratio, rows)) = versus_embree(a, &mut scene, model, runs)? {
            ratios += &ratio;
            embree += &rows;
        }
    }
    if !ratios.is_empty() {
        out += "\nSAH with perfect splits on 2 threads against Embree 3 on every hardware thread \
                (RT2 ms / Embree ms), run by run: each run times one build of RT2's, then one \
                of each of Embree's (after its warm-up build), and the ratio is the median of \
                the runs' own ratios. Embree's \
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
        out += "\nEmbree 3 in the same run (median over the runs above):\n\n\
                | model | build | threads | median ms | MiB |\n|---|---|---|---|---|\n";
        out += &embree;
    }
    Ok(out)
}

/// RT2's SAH build of `scene` (the shared `model`) on 2 threads against Embree's builds of
/// it, `runs` runs each of one RT2 build and then one run of Embree's harness (which builds
/// each kind once on one thread and on every hardware thread, after a warm-up build). Returns
/// the ratio row (RT2 ms over Embree's multi-threaded ms, the median of the runs' own ratios)
/// and Embree's rows (median ms and MiB of each build); `None` without the harness.
fn versus_embree(
    a: &Args,
    scene: &mut Scene,
    model: &str,
    runs: usize,
) -> Result<Option<(String, String)>> {
    if embree_harness(a).is_none() {
        return Ok(None);
    }
    // The harness traces a ray set after its builds: one ray from the model's centre (the
    // builder table's last commit has its bounds), written here, takes it no time (and the
    // Snowden bust has no shared sets).
    let centre = scene.committed()?.bounds.center();
    scene.set_build_options(BuildOptions::default());
    let ctx = Context::new(BackendRequest::Cpu, 2)?;
    let one_ray = std::env::temp_dir().join(format!("rt2-build-{}.rays", std::process::id()));
    rayset::write_rays(
        &one_ray,
        &[Ray::new(centre, glam::Vec3::Z, 0.0, f32::INFINITY)],
    )?;
    let mesh = shared().join("models").join(model);
    let mut ours = Vec::with_capacity(runs);
    let mut theirs: Vec<EmbreeBuild> = Vec::new();
    let mut timed = || -> Result<()> {
        for _ in 0..runs {
            ours.push(median_build_ms(&ctx, scene, 1)?);
            for row in embree_rows(a, &mesh, std::slice::from_ref(&one_ray), 1, "1")? {
                if let EmbreeRow::Build {
                    name,
                    threads,
                    bytes,
                    ms,
                } = row
                {
                    match theirs
                        .iter_mut()
                        .find(|b| b.name == name && b.threads == threads)
                    {
                        Some(b) => b.ms.push(ms),
                        None => theirs.push(EmbreeBuild {
                            name,
                            threads,
                            ms: vec![ms],
                            bytes,
                        }),
                    }
                }
            }
        }
        Ok(())
    };
    let done = timed();
    let _ = std::fs::remove_file(&one_ray);
    done?;
    let ours_ms = median(ours.clone());
    let ratio = |name: &str| {
        theirs
            .iter()
            .find(|b| b.name == name && b.threads > 1 && b.ms.len() == runs)
            .map_or("—".into(), |b| {
                format!("{:.2}x ({} threads)", paired_ratio(&ours, &b.ms), b.threads)
            })
    };
    let ratio_row = format!(
        "| {model} | {ours_ms:.1} | {} | {} |\n",
        ratio("high(non-robust)"),
        ratio("robust+high")
    );
    let mut rows = String::new();
    for b in &theirs {
        writeln!(
            rows,
            "| {model} | {} | {} | {:.2} | {:.2} |",
            b.name,
            b.threads,
            median(b.ms.clone()),
            mib(b.bytes as usize)
        )
        .ok();
    }
    Ok(Some((ratio_row, rows)))
}

/// One of Embree's builds (a kind on a number of threads) over the runs of [`versus_embree`]:
/// its time in each run, and the memory it held (the same in every run).
struct EmbreeBuild {
    name: String,
    threads: u32,
    ms: Vec<f64>,
    bytes: u64,
}

/// Median tree build time of `runs` commits of `scene` on `ctx`'s threads; a failed build is
/// an error (the scene would keep its last tree, whose time would be reported).
fn median_build_ms(ctx: &Context, scene: &mut Scene, runs: usize) -> Result<f64> {
    let mut ms = Vec::with_capacity(runs);
    for _ in 0..runs {
        ctx.install(|| scene.rebuild())?;
        ms.push(scene.committed()?.tree.stats.build_ms as f64);
    }
    Ok(median(ms))
}

/// The SAH's traversal cost `K_T` trades memory and build time against speed: a larger `K_T`
/// makes fewer, fuller leaves. For the bunny and the dragon: tree size with and without ropes,
/// build time (2 threads), and Mrays/s (1 thread, standard traversal) of single rays, packets
/// and streams on the incoherent and primary sets.
fn traversal_cost_effect(a: &Args) -> Result<String> {
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
        let Some(mut scene) = model_scene(a, &format!("{model}.ply"))? else {
            continue;
        };
        // A missing set leaves its columns empty ("—"), so every row keeps its cells.
        let sets: Vec<Option<Vec<Ray>>> = ["incoherent", "primary"]
            .iter()
            .map(|kind| {
                find_set(a, model, kind)
                    .map(|p| rayset::read_rays(&p))
                    .transpose()
            })
            .collect::<Result<_>>()?;
        for traversal_cost in [1.0, 1.5, 2.0, 2.5, 3.0, 4.0] {
            let options = BuildOptions {
                traversal_cost,
                ..BuildOptions::default()
            };
            scene.set_build_options(options);
            let build_ms = median_build_ms(&build_ctx, &mut scene, a.runs.min(MAX_RUNS_LARGE))?;
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
                    let Some(rays) = rays else {
                        row += " — |";
                        continue;
                    };
                    let q = QueryOptions {
                        traversal: Some(Traversal::Standard),
                        mode: Some(mode),
                        ..QueryOptions::default()
                    };
                    let mut hits = vec![Hit::MISS; rays.len()];
                    let ms = time_ms(a.runs, || ctx.intersect(c, rays, &mut hits, &q).map(drop))?;
                    write!(row, " {:.2} |", rays.len() as f64 / ms / 1e3).ok();
                }
            }
            writeln!(out, "{row}").ok();
        }
    }
    Ok(out)
}

/// Effect of the van Emde Boas node order on traversal speed: the standard traversal on the
/// bunny's incoherent and primary sets, 1 thread, depth-first vs van Emde Boas trees.
fn layout_effect(a: &Args) -> Result<String> {
    let Some(mut scene) = model_scene(a, "bunny.ply")? else {
        return Ok(String::new());
    };
    let ctx = Context::new(BackendRequest::Cpu, 1)?;
    let mut out = String::from(
        "\nEffect of the node layout (bunny, standard traversal, 1 thread, Mrays/s):\n\n\
         | set | depth-first | van Emde Boas |\n|---|---|---|\n",
    );
    for kind in ["incoherent", "primary"] {
        let Some(path) = find_set(a, "bunny", kind) else {
            continue;
        };
        let rays = rayset::read_rays(&path)?;
        let set = path
            .file_stem()
            .map_or(String::new(), |s| s.to_string_lossy().into());
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
                mode: Some(QueryMode::Single),
                ..QueryOptions::default()
            };
            let mut hits = vec![Hit::MISS; rays.len()];
            let ms = time_ms(a.runs, || ctx.intersect(c, &rays, &mut hits, &q).map(drop))?;
            write!(row, " {:.2} |", rays.len() as f64 / ms / 1e3).ok();
        }
        writeln!(out, "{row}").ok();
    }
    Ok(out)
}
