//! `rt2 bench build`: kd-tree build time and memory of both builders at 1 and 2 threads, Embree's
//! builds beside, and what two build options do to speed: the node layout and the SAH's
//! traversal cost.

use super::{embree_rows, find_set, median, mib, model_scene, shared, time_ms, Args};
use crate::output::warn;
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
        let Some(scene) = model_scene(model)? else {
            continue;
        };
        let mut scene = scene;
        let tris = scene.objects()[0]
            .as_ref()
            .map_or(0, |o| o.shape.prim_count());
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
            for r in embree_rows(
                &shared().join("models").join(model),
                &[shadow],
                a.runs,
                "1,2",
            ) {
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
                let _ = ctx.install(|| scene.rebuild());
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
                        mode: Some(mode),
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
            warn(format_args!(
                "bench: {} is missing; skipped",
                path.display()
            ));
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
                mode: Some(QueryMode::Single),
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
