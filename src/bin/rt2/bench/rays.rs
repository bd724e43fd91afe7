//! `rt2 bench rays`: Mrays/s of every single-ray traversal on the shared ray sets at 1 and 2
//! threads, with their agreement with Embree's hits and Embree's own speed beside.

use super::{embree_rows, model_scene, shared, time_ms, Args};
use rt2::context::{Context, QueryOptions};
use rt2::cpu::traverse::Traversal;
use rt2::dispatch::BackendRequest;
use rt2::error::{Error, Result};
use rt2::geometry::{Hit, Ray};
use rt2::rayset::{self, HitRecord};
use std::fmt::Write as _;
use std::path::PathBuf;

pub(super) fn rays(a: &Args) -> Result<String> {
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
            // One call per ray, as Embree's `intersect1` rows are and as a user porting a loop
            // of `rtcIntersect1` would call it: the dispatch layer's cost per call on top.
            let ctx = Context::new(BackendRequest::Cpu, 1)?;
            let q = QueryOptions {
                traversal: Some(Traversal::Standard),
                ..QueryOptions::default()
            };
            let mut hits = vec![Hit::MISS; rays.len()];
            let ms = time_ms(a.runs, || {
                for (r, h) in rays.iter().zip(&mut hits) {
                    let (r, h) = (std::slice::from_ref(r), std::slice::from_mut(h));
                    ctx.intersect(c, r, h, &q).ok();
                }
            });
            writeln!(
                out,
                "| {model} {stem} | RT2 standard, a call per ray | {:.2} | | | | | |",
                rays.len() as f64 / ms / 1e3
            )
            .ok();
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
