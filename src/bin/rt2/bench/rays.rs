//! `rt2 bench rays`: Mrays/s of every single-ray traversal on the shared ray sets at 1 and 2
//! threads, with their agreement with Embree's hits and Embree's own speed beside.

use super::{embree_rows, model_scene, ray_sets, shared, time_ms, Args, EmbreeRow};
use rt2::context::{Context, QueryOptions};
use rt2::cpu::query::QueryMode;
use rt2::cpu::traverse::Traversal;
use rt2::dispatch::BackendRequest;
use rt2::error::{Error, Result, Rt2Status};
use rt2::geometry::{Hit, Ray};
use rt2::rayset::{self, HitRecord};
use std::ffi::CString;
use std::fmt::Write as _;
use std::path::Path;

pub(super) fn rays(a: &Args) -> Result<String> {
    let mut out = String::from(
        "### Ray queries on the shared ray sets (single rays, CPU)\n\n\
         Disagreement with Embree's hits counts hit/miss differences and different triangles with \
         |Δt| > 1e-4·diag (`rt2cmp`'s rule); ties on shared edges are not disagreements.\n\n\
         | set | method | 1 thread Mrays/s | 2 threads Mrays/s | nodes/ray | leaves/ray | tests/ray | disagreements |\n\
         |---|---|---|---|---|---|---|---|\n",
    );
    for model in ["bunny", "dragon"] {
        let Some(mut scene) = model_scene(a, &format!("{model}.ply"))? else {
            continue;
        };
        scene.commit()?;
        scene.ensure_ropes()?;
        let c = scene.committed()?;
        let diag = c.bounds.diagonal();
        let sets = ray_sets(a, model, &["diffuse", "incoherent", "primary", "shadow"]);
        if sets.is_empty() {
            continue;
        }
        let embree = embree_rows(
            a,
            &shared().join("models").join(format!("{model}.ply")),
            &sets,
            a.runs,
            "1,2",
        )?;
        let c_scene = CScene::load(&shared().join("models").join(format!("{model}.ply")))?;
        for set in &sets {
            let rays: Vec<Ray> = rayset::read_rays(set)?;
            let stem = set
                .file_stem()
                .map_or(String::new(), |s| s.to_string_lossy().into());
            let reference = rayset::read_hits(&set.with_extension("embree.hits")).ok();
            for how in Traversal::ALL {
                let q = QueryOptions {
                    traversal: Some(how),
                    mode: Some(QueryMode::Single),
                    ..QueryOptions::default()
                };
                let mut hits = vec![Hit::MISS; rays.len()];
                let mut mrays = [0.0; 2];
                let mut stats = Default::default();
                for (k, threads) in [1u32, 2].into_iter().enumerate() {
                    let ctx = Context::new(BackendRequest::Cpu, threads)?;
                    let ms = time_ms(a.runs, || {
                        stats = ctx.intersect(c, &rays, &mut hits, &q)?;
                        Ok(())
                    })?;
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
            // cost per call on top of the ray, and with two threads calling at once, what
            // they share.
            let m1 = c_scene.calls_per_ray(&rays, 1, a.runs)?;
            let m2 = c_scene.calls_per_ray(&rays, 2, a.runs)?;
            writeln!(
                out,
                "| {model} {stem} | RT2 default options, a C call per ray | {m1:.2} | {m2:.2} | | | | |"
            )
            .ok();
            // Embree's speeds of this set, a row per mode in the harness' order, each thread
            // count in its column. Its hits file is the one-thread `intersect1` on the traced
            // (robust) scene.
            let mut modes: Vec<&str> = Vec::new();
            for r in &embree {
                if let EmbreeRow::Trace { set, mode, .. } = r {
                    if *set == stem && !modes.contains(&mode.as_str()) {
                        modes.push(mode);
                    }
                }
            }
            for mode in modes {
                let speed = |threads| {
                    embree
                        .iter()
                        .find_map(|r| r.speed(&stem, mode, threads))
                        .map_or(String::new(), |m| format!("{m:.2}"))
                };
                let reference = if mode == "intersect1" {
                    "reference"
                } else {
                    ""
                };
                writeln!(
                    out,
                    "| {model} {stem} | Embree {mode} | {} | {} | | | | {reference} |",
                    speed(1),
                    speed(2)
                )
                .ok();
            }
        }
    }
    Ok(out)
}

/// A model loaded and committed through the C API on a CPU context of one thread (a one-ray
/// call runs on its caller's thread), for the row of one C call per ray; destroyed on drop.
struct CScene {
    ctx: *mut rt2::api::rt2_context,
    scene: *mut rt2::api::rt2_scene,
}

// SAFETY: the C API lets any number of threads use a context and query a committed scene at
// once (rt2.h, "Threads"); the handles are only destroyed on drop, after every thread joined.
unsafe impl Sync for CScene {}

impl CScene {
    fn load(model: &Path) -> Result<Self> {
        use rt2::api::*;
        let path = CString::new(model.as_os_str().as_encoded_bytes())
            .map_err(|e| Error::invalid_argument(format!("{}: {e}", model.display())))?;
        let mut desc = rt2_context_desc_default();
        desc.backend = Rt2Backend::Cpu as u32;
        desc.threads = 1;
        let mut s = CScene {
            ctx: std::ptr::null_mut(),
            scene: std::ptr::null_mut(),
        };
        // SAFETY: pointers to live locals and the handles these calls make, which `s` destroys
        // on drop (NULL ones too) on every path.
        unsafe {
            c_status("rt2_context_create", rt2_context_create(&desc, &mut s.ctx))?;
            c_status("rt2_scene_create", rt2_scene_create(s.ctx, &mut s.scene))?;
            let st = rt2_scene_load_file(s.scene, path.as_ptr(), 0, std::ptr::null_mut());
            c_status("rt2_scene_load_file", st)?;
            c_status("rt2_scene_commit", rt2_scene_commit(s.scene))?;
        }
        Ok(s)
    }

    /// Mrays/s of `rays` traced with one `rt2_intersect` call each (default options) by
    /// `threads` threads at once, each calling for its share of the rays on the same context
    /// and scene (as threads of a renderer would), the median of `runs` passes.
    fn calls_per_ray(&self, rays: &[Ray], threads: usize, runs: usize) -> Result<f64> {
        use rt2::api::*;
        let c_rays: Vec<rt2_ray> = rays
            .iter()
            .map(|r| rt2_ray {
                org: r.org.to_array(),
                tmin: r.tmin,
                dir: r.dir.to_array(),
                tmax: r.tmax,
            })
            .collect();
        // A failed call would be timed as a traced ray: the first failure ends the timing, its
        // message read on the thread whose call failed (the library keeps it per thread).
        let calls = |share: &[rt2_ray]| -> Result<()> {
            let opts = rt2_query_options_default();
            // SAFETY: a plain C struct of numbers.
            let mut hit = unsafe { std::mem::zeroed::<rt2_hit>() };
            for r in share {
                // SAFETY: live handles, one ray and one hit.
                let s = unsafe {
                    rt2_intersect(
                        self.ctx,
                        self.scene,
                        r,
                        1,
                        &mut hit,
                        &opts,
                        std::ptr::null_mut(),
                    )
                };
                c_status("rt2_intersect", s)?;
            }
            Ok(())
        };
        let ms = time_ms(runs, || {
            std::thread::scope(|s| {
                let shares: Vec<_> = c_rays
                    .chunks(c_rays.len().div_ceil(threads).max(1))
                    .map(|share| s.spawn(move || calls(share)))
                    .collect();
                shares.into_iter().try_for_each(|share| {
                    share.join().unwrap_or_else(|_| {
                        Err(Error::new(
                            Rt2Status::Internal,
                            "bench: a thread calling rt2_intersect panicked",
                        ))
                    })
                })
            })
        })?;
        Ok(c_rays.len() as f64 / ms / 1e3)
    }
}

impl Drop for CScene {
    fn drop(&mut self) {
        // SAFETY: handles made by `load` (or NULL, which both calls accept).
        unsafe {
            rt2::api::rt2_scene_destroy(self.scene);
            rt2::api::rt2_context_destroy(self.ctx);
        }
    }
}

/// An error for a failed C call `what`, with the library's message.
fn c_status(what: &str, s: Rt2Status) -> Result<()> {
    if s == Rt2Status::Ok {
        return Ok(());
    }
    // SAFETY: the library's last error message is a NUL-terminated string it owns.
    let why = unsafe { std::ffi::CStr::from_ptr(rt2::api::rt2_last_error_message()) };
    Err(Error::new(
        s,
        format!("bench: {what}: {}", why.to_string_lossy()),
    ))
}
