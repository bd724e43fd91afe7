//! `rt2 bench streams`: the three tables of the vectorised-traversal paper (seeds/000: coherent
//! Mrays/s, coherent frames per second, incoherent Mrays/s; n-rays / 4-rays / 1-ray) on the
//! Bunny, Dragon and Snowden bust, with the paper's figures beside, plus 1376×768 frames, the
//! shared ray sets (diffuse included), Embree's single rays and 8-ray packets measured in the
//! same run, the lane widths and the stream's ray stack memory.

use super::{
    embree_harness, embree_rows, median, model_scene, paired_ratio, ray_generator, ray_sets,
    shared, Args, EmbreeRow, MAX_RUNS_LARGE,
};
use rt2::context::{Context, QueryOptions};
use rt2::cpu::query::{self, QueryMode, STREAM_CHUNK, STREAM_MAX};
use rt2::cpu::ray_order::RayOrder;
use rt2::cpu::simd::Width;
use rt2::cpu::traverse::{Traversal, TraverseOptions};
use rt2::cpu::{stream, RayTests};
use rt2::dispatch::{choose_query_mode, BackendRequest};
use rt2::error::Result;
use rt2::geometry::{Hit, Ray};
use rt2::rayset;
use rt2::scene::Committed;
use std::fmt::Write as _;
use std::time::Instant;

/// The paper's figures (Pentium-M, 256², Mrays/s: n-rays / 4-rays / 1-ray). Its third model is
/// the Buddha; the Snowden bust stands in for it here.
const PAPER_COHERENT: [(&str, [f64; 3]); 3] = [
    ("bunny", [0.72, 0.58, 0.24]),
    ("dragon", [0.51, 0.42, 0.19]),
    ("snowden", [0.56, 0.45, 0.23]),
];
const PAPER_INCOHERENT: [(&str, [f64; 3]); 3] = [
    ("bunny", [0.39, 0.18, 0.13]),
    ("dragon", [0.28, 0.15, 0.11]),
    ("snowden", [0.27, 0.15, 0.11]),
];

/// Frames of the orbit animation (the paper's 100).
const FRAMES: usize = 100;
/// Rays of the incoherent batches: the size of the bunny's shared set, and eight times that,
/// which on the dragon's tree fills one stream per octant ([`query::incoherent_stream_max`]).
const INCOHERENT_RAYS: [usize; 2] = [262_144, 2_097_152];
/// Frames of the 1376×768 orbit (fewer: each is 16× the rays of a 256² frame).
const WIDE_FRAMES: usize = 10;

/// The three modes in the paper's column order: n-rays, packets (4-rays; the default width here,
/// with 4-lane packets measured beside), 1-ray.
const MODES: [QueryMode; 3] = [QueryMode::Stream, QueryMode::Packet, QueryMode::Single];

/// Primary rays of an orbit frame: the camera of `../shared/raysets` (60° vertical field of view,
/// eye at 0.9·diag from the centre, direction (0.3, 0.35, 1)) turned by `angle` about +y.
fn orbit_rays(c: &Committed, w: u32, h: u32, angle: f32) -> Vec<Ray> {
    use glam::Vec3;
    let (centre, diag) = (c.bounds.center(), c.bounds.diagonal());
    let d0 = Vec3::new(0.3, 0.35, 1.0).normalize();
    let (s, co) = angle.sin_cos();
    let eye = centre + 0.9 * diag * Vec3::new(co * d0.x + s * d0.z, d0.y, -s * d0.x + co * d0.z);
    let f = (centre - eye).normalize();
    let r = f.cross(Vec3::Y).normalize();
    let u = r.cross(f);
    let th = (30f32).to_radians().tan();
    let aspect = w as f32 / h as f32;
    (0..h)
        .flat_map(|j| {
            (0..w).map(move |i| {
                let x = (2.0 * (i as f32 + 0.5) / w as f32 - 1.0) * th * aspect;
                let y = (1.0 - 2.0 * (j as f32 + 0.5) / h as f32) * th;
                Ray::new(eye, (f + x * r + y * u).normalize(), 0.0, f32::INFINITY)
            })
        })
        .collect()
}

/// Incoherent rays as the paper and `../shared/raysets` define them: origin and direction from
/// two uniform points on the bounding sphere (the library's SplitMix64 here; the sets use PCG32).
fn incoherent_rays(c: &Committed, n: usize) -> Vec<Ray> {
    use glam::Vec3;
    let mut rng = rt2::rng::Rng(0x5eed);
    let (centre, radius) = (c.bounds.center(), 0.5 * c.bounds.diagonal());
    let mut point = || {
        let z = 2.0 * rng.unit() - 1.0;
        let phi = std::f32::consts::TAU * rng.unit();
        let r = (1.0 - z * z).max(0.0).sqrt();
        centre + radius * Vec3::new(r * phi.cos(), r * phi.sin(), z)
    };
    (0..n)
        .map(|_| {
            let (p1, p2) = (point(), point());
            Ray::new(p1, (p2 - p1).normalize(), 0.0, f32::INFINITY)
        })
        .collect()
}

/// `runs` timed passes (after a warm-up) tracing every batch once, for each of `configs` (a
/// mode and a lane width), on `ctx`'s threads: [`timed_runs`] with every config on the same
/// batches.
fn seconds(
    ctx: &Context,
    c: &Committed,
    batches: &[Vec<Ray>],
    configs: &[(QueryMode, Width)],
    runs: usize,
) -> Result<Timings> {
    let jobs: Vec<Job> = configs
        .iter()
        .map(|&config| (batches, Some(config)))
        .collect();
    timed_runs(ctx, c, &jobs, runs, || Ok(false))
}

/// A timed job: batches traced once each per pass, in one mode and lane width, or (`None`)
/// through `Context::intersect` with the default options, whose mode is AUTO's choice.
type Job<'a> = (&'a [Vec<Ray>], Option<(QueryMode, Width)>);

/// Seconds of every timed run of each job: `self.0[job][run]`.
struct Timings(Vec<Vec<f64>>);

impl Timings {
    /// The job's median time, as Embree's harness reports: with the fastest run here against
    /// Embree's median, the ratios leaned towards RT2.
    fn median(&self, job: usize) -> f64 {
        median(self.0[job].clone())
    }

    /// How many times as fast job `a` is as job `b`: the median over the runs of `b`'s time
    /// over `a`'s in the same run. A busy spell of this shared machine slows both jobs of a
    /// run, so the ratio of one run's pair moves less than the ratio of the two medians,
    /// which may come from different runs.
    fn speedup(&self, a: usize, b: usize) -> f64 {
        paired_ratio(&self.0[b], &self.0[a])
    }
}

/// `runs` timed passes of each job (after a warm-up pass of each), on `ctx`'s threads. Each
/// run calls `each_run` (the peer's run, where one is timed beside; it says whether it ran,
/// and its failure ends the timing),
/// makes one more warm-up pass after a peer's run, and then times the jobs batch by batch:
/// the first batch of every job, then the second of every job, and so on, the jobs in turn
/// forwards and backwards (so that none always runs on the caches another left).
/// The load of this shared machine changes within seconds; timed a whole job after another,
/// the 100-frame orbit's modes each took a second or more, and two runs of the bench differed
/// by up to 25% in a ratio. Interleaved, a busy spell slows every job of a run about alike.
/// Without the warm-up after Embree's harness, the job timed first after it (a shared set's
/// 4-lane streams) ran at a quarter to two thirds of its speed timed alone.
fn timed_runs(
    ctx: &Context,
    c: &Committed,
    jobs: &[Job],
    runs: usize,
    mut each_run: impl FnMut() -> Result<bool>,
) -> Result<Timings> {
    let longest = jobs
        .iter()
        .flat_map(|j| j.0.iter().map(Vec::len))
        .max()
        .unwrap_or(0);
    let batches = jobs.iter().map(|j| j.0.len()).max().unwrap_or(0);
    let mut hits = vec![Hit::MISS; longest];
    let opts = TraverseOptions::default();
    let mut failed = None;
    // Seconds of one batch of one job (none when the job has fewer batches).
    let mut time = |&(batches, config): &Job, i: usize| {
        let Some(b) = batches.get(i) else {
            return 0.0;
        };
        let hits = &mut hits[..b.len()];
        let t = Instant::now();
        match config {
            Some((mode, width)) => {
                let how = Traversal::Standard;
                ctx.install(|| query::trace(c, (b, None), hits, how, &opts, mode, width));
            }
            None => {
                // The first failure is kept and returned once the timing is done.
                let done = ctx.intersect(c, b, hits, &QueryOptions::default());
                failed = failed.take().or(done.err());
            }
        }
        t.elapsed().as_secs_f64()
    };
    let mut pass = |times: &mut [f64]| {
        for i in 0..batches {
            for k in 0..jobs.len() {
                let j = if i % 2 == 0 { k } else { jobs.len() - 1 - k };
                times[j] += time(&jobs[j], i);
            }
        }
    };
    pass(&mut vec![0.0; jobs.len()]);
    let mut times = vec![Vec::with_capacity(runs); jobs.len()];
    for _ in 0..runs {
        if each_run()? {
            pass(&mut vec![0.0; jobs.len()]);
        }
        let mut run = vec![0.0; jobs.len()];
        pass(&mut run);
        for (t, r) in times.iter_mut().zip(run) {
            t.push(r);
        }
    }
    failed.map_or(Ok(Timings(times)), Err)
}

/// The paper's three modes at the default width ([`MODES`]), then 4-lane packets.
fn with_packets4(width: Width) -> [(QueryMode, Width); 4] {
    [
        (MODES[0], width),
        (MODES[1], width),
        (MODES[2], width),
        (QueryMode::Packet, Width::W4),
    ]
}

fn rays_of(batches: &[Vec<Ray>]) -> f64 {
    batches.iter().map(Vec::len).sum::<usize>() as f64
}

pub(super) fn streams(a: &Args) -> Result<String> {
    let width = Width::best();
    let one = Context::new(BackendRequest::Cpu, 1)?;
    let mut out = format!(
        "### All rays at once: n-ray streams, packets and single rays (CPU, 1 thread)\n\n\
         Modes: **n-rays** = `QueryMode::Stream`, **packets** = `QueryMode::Packet` at the \
         default width ({w} lanes), **packets ×4** = 4-lane packets (Wald's, the paper's 4-rays \
         column), **1-ray** = `QueryMode::Single` with the standard traversal; all return \
         bit-identical hits. Packets take rays that form a camera image in scanline order \
         (the orbit frames, the primary sets) in tiles of the image, which RT2 finds in the \
         rays (4×4 at 16 lanes, 2×2 at 4; `ray_order`); Embree's harness packs 8 consecutive \
         rays for its `intersect8`. Streams: rays that come in runs of one octant (a camera's, in \
         scanline order) are cut in their order into streams of at most {hi} rays \
         (`STREAM_MAX`): longer streams of coherent rays outgrow the caches; rays in mixed \
         octants are sorted by octant and cut into streams of one octant, at most about one ray \
         per leaf of the tree, {hi} to {inco} rays (`incoherent_stream_max`). Trees: SAH \
         with perfect splits (the library default; the paper used midpoint trees); on Linux \
         their arrays lie on transparent huge pages, as Embree's do (`huge_pages`). Paper: \
         Pentium-M, 1 core; its third model is the Buddha, the Snowden bust stands in for it. \
         Everything is measured in this run, on a shared machine whose load changes \
         within seconds. Each run times the modes frame by frame \
         (each frame in every mode before the next frame), and on a shared set right after one \
         run of Embree's harness on that set; each speed is the median of the timed runs, as \
         Embree's harness reports, and each ratio the median of the runs' own ratios (both \
         speeds of a ratio from the same run). Timed a whole mode after another, two runs of \
         the bench once differed by up to 25% in a ratio of two medians. Timed regions: RT2's \
         modes trace rays made beforehand and store their hits (AUTO: one \
         `Context::intersect` call); Embree's harness times its loop that fills each \
         `RTCRayHit` from the ray record, traces it and stores the hit record: a dozen stores \
         a ray that RT2's timings leave out.\n\n",
        w = width.lanes(),
        hi = STREAM_MAX,
        inco = query::INCOHERENT_STREAM_MAX
    );
    let mut t1 = String::from(
        "#### Table 1 — coherent rays: 100-frame orbit at 256², Mrays/s (paper beside)\n\n\
         | model | triangles | n-rays | packets | packets ×4 | 1-ray | n-rays / packets | n-rays / packets ×4 | n-rays / 1-ray | paper n / 4 / 1 |\n\
         |---|---|---|---|---|---|---|---|---|---|\n",
    );
    let mut t2 = String::from(
        "#### Table 2 — the same animation in frames per second\n\n\
         | model | n-rays fps | packets fps | packets ×4 fps | 1-ray fps | paper fps n / 4 / 1 |\n|---|---|---|---|---|---|\n",
    );
    let mut t3 = String::from(
        "#### Table 3 — incoherent rays (two uniform points on the bounding sphere), Mrays/s\n\n\
         Rays per stream: the rays of one octant (about an eighth of the batch), up to the \
         tree's `incoherent_stream_max`.\n\n\
         | model | rays | rays per stream | n-rays | packets | packets ×4 | 1-ray | n-rays / 1-ray | paper n / 4 / 1 |\n\
         |---|---|---|---|---|---|---|---|---|\n",
    );
    let mut wide = String::from(
        "#### 1376×768 orbit (10 frames), Mrays/s\n\n\
         | model | n-rays | packets | 1-ray | n-rays / packets | n-rays / 1-ray |\n|---|---|---|---|---|---|\n",
    );
    let mut mem = String::from(
        "#### Ray stack memory of one stream (peak of the reused ray stack; ray arrays = origins, reciprocal directions, finished flags)\n\n\
         | workload | ray stack KiB | ray arrays KiB | bytes per ray |\n|---|---|---|---|\n",
    );
    for model in ["bunny", "dragon", "snowden"] {
        let Some(mut scene) = model_scene(a, &format!("{model}.ply"))? else {
            continue;
        };
        scene.commit()?;
        let c = scene.committed()?;
        let tris = c.prims.len();
        let orbit: Vec<Vec<Ray>> = (0..FRAMES)
            .map(|k| {
                orbit_rays(
                    c,
                    256,
                    256,
                    std::f32::consts::TAU * k as f32 / FRAMES as f32,
                )
            })
            .collect();
        // Jobs: n-rays, packets, 1-ray, packets ×4.
        let t = seconds(&one, c, &orbit, &with_packets4(width), a.runs)?;
        let mr: Vec<f64> = (0..4)
            .map(|j| rays_of(&orbit) / t.median(j) / 1e6)
            .collect();
        let paper = PAPER_COHERENT.iter().find(|p| p.0 == model).map(|p| p.1);
        let fmt3 = |p: Option<[f64; 3]>, scale: f64| {
            p.map_or("—".into(), |p| {
                format!(
                    "{:.2} / {:.2} / {:.2}",
                    p[0] * scale,
                    p[1] * scale,
                    p[2] * scale
                )
            })
        };
        writeln!(
            t1,
            "| {model} | {tris} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2}× | {:.2}× | {:.2}× | {} |",
            mr[0],
            mr[1],
            mr[3],
            mr[2],
            t.speedup(0, 1),
            t.speedup(0, 3),
            t.speedup(0, 2),
            fmt3(paper, 1.0)
        )
        .ok();
        let frame_rays = 256.0 * 256.0 / 1e6;
        writeln!(
            t2,
            "| {model} | {:.1} | {:.1} | {:.1} | {:.1} | {} |",
            FRAMES as f64 / t.median(0),
            FRAMES as f64 / t.median(1),
            FRAMES as f64 / t.median(3),
            FRAMES as f64 / t.median(2),
            fmt3(paper, 1.0 / frame_rays)
        )
        .ok();
        let paper = PAPER_INCOHERENT.iter().find(|p| p.0 == model).map(|p| p.1);
        let inco = incoherent_rays(c, INCOHERENT_RAYS[INCOHERENT_RAYS.len() - 1]);
        for n in INCOHERENT_RAYS {
            let batch = [inco[..n].to_vec()];
            let t = seconds(&one, c, &batch, &with_packets4(width), a.runs)?;
            let mi: Vec<f64> = (0..4).map(|j| n as f64 / t.median(j) / 1e6).collect();
            writeln!(
                t3,
                "| {model} | {n} | {} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2}× | {} |",
                n.div_ceil(8).min(query::incoherent_stream_max(&c.tree)),
                mi[0],
                mi[1],
                mi[3],
                mi[2],
                t.speedup(0, 2),
                fmt3(paper, 1.0)
            )
            .ok();
        }
        let big: Vec<Vec<Ray>> = (0..WIDE_FRAMES)
            .map(|k| {
                let angle = std::f32::consts::TAU * k as f32 / WIDE_FRAMES as f32;
                orbit_rays(c, 1376, 768, angle)
            })
            .collect();
        let configs = MODES.map(|m| (m, width));
        let t = seconds(&one, c, &big, &configs, a.runs.min(MAX_RUNS_LARGE))?;
        let mw: Vec<f64> = (0..3).map(|j| rays_of(&big) / t.median(j) / 1e6).collect();
        writeln!(
            wide,
            "| {model} | {:.2} | {:.2} | {:.2} | {:.2}× | {:.2}× |",
            mw[0],
            mw[1],
            mw[2],
            t.speedup(0, 1),
            t.speedup(0, 2)
        )
        .ok();
        // Incoherent streams as `query` cuts them: rays of one octant (all directions positive).
        let octant: Vec<Ray> = inco
            .iter()
            .filter(|r| r.dir.cmpge(glam::Vec3::ZERO).all())
            .copied()
            .collect();
        let incoherent_max = query::incoherent_stream_max(&c.tree);
        let incoherent_sizes = [STREAM_CHUNK, STREAM_MAX, incoherent_max];
        // A tree of at most `STREAM_MAX` leaves cuts incoherent streams at `STREAM_MAX` too.
        let incoherent_sizes = if incoherent_max > STREAM_MAX {
            &incoherent_sizes[..]
        } else {
            &incoherent_sizes[..2]
        };
        for (what, rays, sizes) in [
            ("256² frame", &orbit[0], &[STREAM_CHUNK, STREAM_MAX][..]),
            ("incoherent, one octant", &octant, incoherent_sizes),
        ] {
            for &size in sizes {
                let chunk = &rays[..size.min(rays.len())];
                let mut hits = vec![Hit::MISS; chunk.len()];
                let rays = (chunk, RayOrder::AsGiven);
                let (_, m) =
                    stream::intersect(&c.tree, &c.prims, rays, RayTests::PLAIN, &mut hits, width);
                writeln!(
                    mem,
                    "| {model} {what} ({} rays) | {:.0} | {:.0} | {:.0} |",
                    chunk.len(),
                    m.ray_stack_bytes as f64 / 1024.0,
                    m.ray_array_bytes as f64 / 1024.0,
                    (m.ray_stack_bytes + m.ray_array_bytes) as f64 / chunk.len() as f64
                )
                .ok();
            }
        }
    }
    out += &t1;
    out += "\n";
    out += &t2;
    out += "\n";
    out += &t3;
    out += "\n";
    out += &wide;
    out += "\n";
    out += &raysets(a, &one)?;
    out += "\n";
    out += &mem;
    Ok(out)
}

/// The primary rays of the shared sets' camera at 1024², the resolution of the Embree
/// figures (the shared sets are 512²), made by the peers' `rt2gen` in a temporary folder:
/// `None`, noted in `a`, when it is not built or fails.
fn primary_1024(a: &Args, mesh: &std::path::Path) -> Option<std::path::PathBuf> {
    let Some(generator) = ray_generator(a) else {
        a.skip("the peers' rt2gen (not built; the bunny's 1024² primary row left out)");
        return None;
    };
    let dir = std::env::temp_dir().join(format!("rt2-primary-1024-{}", std::process::id()));
    std::fs::create_dir_all(&dir).ok()?;
    let made = std::process::Command::new(generator)
        .arg(mesh)
        .arg(&dir)
        .args(["--res", "1024", "--incoherent", "1"])
        .stdout(std::process::Stdio::null())
        .status()
        .is_ok_and(|s| s.success());
    let set = dir.join("primary_1048576.rays");
    if !(made && set.exists()) {
        a.skip("the bunny's 1024² primary set (rt2gen made none; its row left out)");
        let _ = std::fs::remove_dir_all(&dir);
        return None;
    }
    Some(set)
}

/// The shared ray sets (bunny, dragon) in every mode and lane width, Embree beside, and the
/// bunny's primary rays at 1024² when the peers' generator is built.
fn raysets(a: &Args, one: &Context) -> Result<String> {
    let mut out = String::from(
        "#### Shared ray sets (`../shared/raysets`; `primary_1048576` is the bunny's camera at 1024², the issue's resolution, made by the peers' `rt2gen`), Mrays/s, 1 thread, Embree 3 measured in the same run\n\n\
         AUTO: `rt2_intersect`'s default options (`Context::intersect`, mode AUTO), with the mode it chose.\n\n\
         | set | n-rays ×4 | n-rays ×8 | n-rays ×16 | packets ×4 | packets ×8 | packets ×16 | 1-ray | AUTO | Embree `intersect1` | Embree `intersect8(coherent)` | best / Embree 1 | best / Embree 8 |\n\
         |---|---|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    for model in ["bunny", "dragon"] {
        let Some(mut scene) = model_scene(a, &format!("{model}.ply"))? else {
            continue;
        };
        scene.commit()?;
        let c = scene.committed()?;
        let mut sets = ray_sets(a, model, &["primary", "incoherent", "diffuse"]);
        let generated = if model == "bunny" {
            primary_1024(a, &shared().join("models/bunny.ply"))
        } else {
            None
        };
        sets.extend(generated.clone());
        let rays: Vec<Vec<Vec<Ray>>> = sets
            .iter()
            .map(|set| Ok(vec![rayset::read_rays(set)?]))
            .collect::<Result<_>>()?;
        // Streams and packets at every width (None where the CPU lacks it), then single rays.
        let columns: Vec<Option<(QueryMode, Width)>> = [QueryMode::Stream, QueryMode::Packet]
            .iter()
            .flat_map(|&m| Width::ALL.map(|w| w.supported().then_some((m, w))))
            .chain([Some((QueryMode::Single, Width::W4))])
            .collect();
        // Every config, then AUTO (`None`).
        let configs: Vec<Option<(QueryMode, Width)>> = columns
            .iter()
            .flatten()
            .map(|&c| Some(c))
            .chain([None])
            .collect();
        let mesh = shared().join("models").join(format!("{model}.ply"));
        let peer = embree_harness(a).is_some();
        for (set, rays) in sets.iter().zip(&rays) {
            let stem = set
                .file_stem()
                .map_or(String::new(), |s| s.to_string_lossy().into());
            let mut row = format!("| {model} {stem} |");
            // Each run: Embree's harness on this set, then every config of RT2 on it. Embree's
            // rows of each run are kept apart so that each pairs with RT2's run after it.
            let jobs: Vec<Job> = configs.iter().map(|&c| (rays.as_slice(), c)).collect();
            let mut embree: Vec<Vec<EmbreeRow>> = Vec::new();
            let t = timed_runs(one, c, &jobs, a.runs, || {
                if peer {
                    embree.push(embree_rows(a, &mesh, std::slice::from_ref(set), 1, "1")?);
                }
                Ok(peer)
            })?;
            let mrays = |j: usize| rays_of(rays) / t.median(j) / 1e6;
            let mut j = 0;
            // The fastest config by its median, and its Mrays/s in each run.
            let mut best: Option<(f64, usize)> = None;
            for column in &columns {
                if column.is_none() {
                    row += " — |";
                    continue;
                }
                let m = mrays(j);
                if best.is_none_or(|(b, _)| m > b) {
                    best = Some((m, j));
                }
                write!(row, " {m:.2} |").ok();
                j += 1;
            }
            let best_runs: Vec<f64> = best.map_or(Vec::new(), |(_, b)| {
                t.0[b].iter().map(|s| rays_of(rays) / s / 1e6).collect()
            });
            // AUTO's figure, and the mode it chose (the context's own choice; a set is one
            // batch, traced with the standard traversal).
            let auto = mrays(j);
            let (chosen, _) = choose_query_mode(&rays[0], None, Traversal::Standard);
            write!(row, " {auto:.2} ({}) |", chosen.name()).ok();
            // Embree's one-thread Mrays/s of this set and mode in each run (`None` where its
            // harness gave no row).
            let find = |mode: &str| -> Vec<Option<f64>> {
                embree
                    .iter()
                    .map(|rows| rows.iter().find_map(|r| r.speed(&stem, mode, 1)))
                    .collect()
            };
            // Embree's median, and the best config's speed over Embree's paired run by run
            // (runs where Embree gave no figure left out).
            let versus = |mode: &str| -> Option<(f64, f64)> {
                let pairs: (Vec<f64>, Vec<f64>) = find(mode)
                    .into_iter()
                    .zip(&best_runs)
                    .filter_map(|(e, &ours)| e.map(|e| (ours, e)))
                    .unzip();
                (!pairs.1.is_empty())
                    .then(|| (median(pairs.1.clone()), paired_ratio(&pairs.0, &pairs.1)))
            };
            let (e1, e8) = (versus("intersect1"), versus("intersect8(coherent)"));
            let cell = |x: Option<(f64, f64)>| x.map_or("—".into(), |(e, _)| format!("{e:.2}"));
            let ratio = |x: Option<(f64, f64)>| x.map_or("—".into(), |(_, r)| format!("{r:.2}×"));
            writeln!(
                row,
                " {} | {} | {} | {} |",
                cell(e1),
                cell(e8),
                ratio(e1),
                ratio(e8)
            )
            .ok();
            out += &row;
        }
        if let Some(dir) = generated.as_deref().and_then(std::path::Path::parent) {
            let _ = std::fs::remove_dir_all(dir);
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A ratio pairs the two speeds of each run: busy spells that slow one side in one run and
    /// the other side in another leave the run-by-run ratio where it was, where the ratio of the
    /// two medians (here 1/6) takes each side's median from a different run.
    #[test]
    fn ratios_pair_the_runs() {
        let (ours, peer) = ([1.0, 1.0, 3.0], [2.0, 6.0, 6.0]);
        assert_eq!(paired_ratio(&ours, &peer), 0.5);
        let t = Timings(vec![peer.to_vec(), ours.to_vec()]);
        // Job 1 takes half job 0's time in the runs that pair them: twice as fast.
        assert_eq!(t.speedup(1, 0), 2.0);
        assert_eq!(t.median(0), 6.0);
    }
}
