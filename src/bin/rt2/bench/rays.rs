//! `rt2 bench rays`: Mrays/s of every single-ray traversal on the shared ray sets at 1 and 2
//! threads, with their agreement with Embree's hits and Embree's own speed beside.

use super::{embree_rows, model_scene, shared, time_ms, Args};
use rt2::context::{Context, QueryOptions};
use rt2::cpu::traverse::Traversal;
use rt2::dispatch::BackendRequest;
use rt2::error::{Error, Result};
use rt2::geometry::{Hit, Ray};
use rt2::rayset::{self, HitRecord};
use std::ffi::CString;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

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
            // One C call per ray, as Embree's `intersect1` rows are and as a user porting a
            // loop of `rtcIntersect1` would write it: the C boundary's and the dispatch layer's
            // cost per call on top of the ray.
            let model_path = shared().join("models").join(format!("{model}.ply"));
            let mrays = c_call_per_ray(&model_path, &rays, a.runs)?;
            writeln!(
                out,
                "| {model} {stem} | RT2 default options, a C call per ray | {mrays:.2} | | | | | |"
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

/// Mrays/s of `rays` traced with one `rt2_intersect` call each (default options, a CPU context
/// of one thread), the median of `runs` passes.
fn c_call_per_ray(model: &Path, rays: &[Ray], runs: usize) -> Result<f64> {
    use rt2::api::*;
    use rt2::error::Rt2Status;
    let fail = |what: &str, s: Rt2Status| {
        // SAFETY: the library's last error message is a NUL-terminated string it owns.
        let why = unsafe { std::ffi::CStr::from_ptr(rt2_last_error_message()) };
        Error::new(s, format!("bench: {what}: {}", why.to_string_lossy()))
    };
    let path = CString::new(model.as_os_str().as_encoded_bytes())
        .map_err(|e| Error::invalid_argument(format!("{}: {e}", model.display())))?;
    let c_rays: Vec<rt2_ray> = rays
        .iter()
        .map(|r| rt2_ray {
            org: r.org.to_array(),
            tmin: r.tmin,
            dir: r.dir.to_array(),
            tmax: r.tmax,
        })
        .collect();
    let mut desc = rt2_context_desc_default();
    desc.backend = Rt2Backend::Cpu as u32;
    desc.threads = 1;
    let (mut ctx, mut scene) = (std::ptr::null_mut(), std::ptr::null_mut());
    // SAFETY: every pointer passed is a live local or a handle these calls made; the handles
    // are destroyed before returning, on every path.
    unsafe {
        let s = rt2_context_create(&desc, &mut ctx);
        if s != Rt2Status::Ok {
            return Err(fail("rt2_context_create", s));
        }
        let mut traced = || -> Result<f64> {
            let s = rt2_scene_create(ctx, &mut scene);
            if s != Rt2Status::Ok {
                return Err(fail("rt2_scene_create", s));
            }
            let s = rt2_scene_load_file(scene, path.as_ptr(), 0, std::ptr::null_mut());
            if s != Rt2Status::Ok {
                return Err(fail("rt2_scene_load_file", s));
            }
            let s = rt2_scene_commit(scene);
            if s != Rt2Status::Ok {
                return Err(fail("rt2_scene_commit", s));
            }
            let opts = rt2_query_options_default();
            let mut hit = std::mem::zeroed::<rt2_hit>();
            // A failed call would be timed as a traced ray: the last failure is reported.
            let mut status = Rt2Status::Ok;
            let ms = time_ms(runs, || {
                for r in &c_rays {
                    let s = rt2_intersect(ctx, scene, r, 1, &mut hit, &opts, std::ptr::null_mut());
                    if s != Rt2Status::Ok {
                        status = s;
                    }
                }
            });
            if status != Rt2Status::Ok {
                return Err(fail("rt2_intersect", status));
            }
            Ok(c_rays.len() as f64 / ms / 1e3)
        };
        let mrays = traced();
        rt2_scene_destroy(scene);
        rt2_context_destroy(ctx);
        mrays
    }
}
