//! `rt2 bench chart`: speed against accuracy for every traversal × intersector (ray queries)
//! and traversal × intersector × offset mode (secondary rays) on the CPU backend one ray at a
//! time, plus packets, streams and the GPU backend where they apply, measured against an
//! independent f64 reference (brute force over the exact triangle corners), and the chart of
//! it (docs/chart.svg, docs/chart.png; needs `--features chart`).

#[cfg(feature = "chart")]
mod plot;
mod psnr;
mod queries;
mod secondary;

use super::Args;
use crate::output::warn;
use rt2::context::{Context, QueryOptions};
use rt2::cpu::query::QueryMode;
use rt2::cpu::traverse::Traversal;
use rt2::dispatch::BackendRequest;
use rt2::error::Result;
use rt2::precision::Intersector;
use std::fmt::Write as _;
use std::time::Instant;

/// Who traces a method's rays.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Engine {
    /// The CPU backend in one of its query modes. Packets and streams follow the standard
    /// traversal's order, with either intersector.
    Cpu(QueryMode),
    /// The GPU backend: Möller–Trumbore only.
    Gpu,
}

impl Engine {
    /// The engines of the chart, in the order of its tables and legend.
    const ALL: [Engine; 4] = [
        Engine::Cpu(QueryMode::Single),
        Engine::Cpu(QueryMode::Packet),
        Engine::Cpu(QueryMode::Stream),
        Engine::Gpu,
    ];

    fn name(self) -> &'static str {
        match self {
            Engine::Cpu(m) => m.name(),
            Engine::Gpu => "gpu",
        }
    }

    /// The traversals × intersectors measured with this engine. One ray at a time: all of
    /// them. Packets and streams: their traversal order with each intersector. The GPU: every
    /// traversal kernel, Möller–Trumbore.
    fn methods(self) -> Vec<(Traversal, Intersector)> {
        match self {
            Engine::Cpu(QueryMode::Single) => Traversal::ALL
                .into_iter()
                .flat_map(|t| Intersector::ALL.map(|i| (t, i)))
                .collect(),
            Engine::Cpu(_) => Intersector::ALL.map(|i| (Traversal::Standard, i)).to_vec(),
            Engine::Gpu => Traversal::ALL
                .map(|t| (t, Intersector::MollerTrumbore))
                .to_vec(),
        }
    }

    /// A method's name in the tables and on the chart: one ray at a time keeps the bare
    /// "traversal intersector".
    fn label(self, how: Traversal, intersector: Intersector) -> String {
        match self {
            Engine::Cpu(QueryMode::Single) => format!("{} {}", how.name(), intersector.name()),
            Engine::Cpu(m) => format!("{} {}", m.name(), intersector.name()),
            Engine::Gpu => format!("gpu {} {}", how.name(), intersector.name()),
        }
    }

    fn query(self, how: Traversal, intersector: Intersector) -> QueryOptions {
        QueryOptions {
            traversal: Some(how),
            intersector,
            mode: match self {
                Engine::Cpu(m) => Some(m),
                Engine::Gpu => Some(QueryMode::Single),
            },
            ..QueryOptions::default()
        }
    }
}

/// The contexts the chart measures with: the CPU's, and the GPU's when an adapter opens.
struct Backends {
    cpu: Context,
    gpu: Option<Context>,
    /// The adapter and whether it is software, or why there is no GPU point.
    gpu_note: String,
}

impl Backends {
    fn open() -> Result<Self> {
        let cpu = Context::new(BackendRequest::Cpu, 0)?;
        let (gpu, gpu_note) = match Context::new(BackendRequest::Gpu, 0) {
            Ok(ctx) => match ctx.gpu().map(|g| (g.software, g.description.clone())) {
                Some((true, name)) => {
                    let lavapipe = if name.contains("llvmpipe") {
                        ", Mesa lavapipe"
                    } else {
                        ""
                    };
                    let note = format!(
                        "{name} (SOFTWARE adapter{lavapipe}: a CPU-emulated GPU on the same \
                         cores, not representative of GPU speed)"
                    );
                    (Some(ctx), note)
                }
                Some((false, name)) => (Some(ctx), format!("{name} (hardware adapter)")),
                // RT2_BACKEND=cpu overrides the request.
                None => (
                    None,
                    "none: RT2_BACKEND keeps the context on the CPU".into(),
                ),
            },
            Err(e) => (
                None,
                format!("no adapter ({}); the GPU points are skipped", e.message),
            ),
        };
        Ok(Backends { cpu, gpu, gpu_note })
    }

    /// The GPU's name in the chart's legend: the adapter's name and its kind.
    fn gpu_legend(&self) -> Option<String> {
        let g = self.gpu.as_ref()?.gpu()?;
        let name = g.description.split(" (").next().unwrap_or("adapter");
        let kind = match (g.software, name.contains("llvmpipe")) {
            (true, true) => "software: lavapipe",
            (true, false) => "software",
            (false, _) => "hardware",
        };
        Some(format!("{name}, {kind}"))
    }

    /// The engines that can run here, with their context.
    fn engines(&self) -> Vec<(Engine, &Context)> {
        Engine::ALL
            .into_iter()
            .filter_map(|e| match e {
                Engine::Gpu => self.gpu.as_ref().map(|g| (e, g)),
                Engine::Cpu(_) => Some((e, &self.cpu)),
            })
            .collect()
    }
}

/// One method measured on one ray set (or summed over the placements of the stress scene).
#[derive(Clone, Debug)]
pub(super) struct Point {
    pub set: &'static str,
    pub method: String,
    /// Its marker on the chart (read only when the chart is drawn: `--features chart`).
    #[cfg_attr(not(feature = "chart"), allow(dead_code))]
    pub engine: Engine,
    pub mrays: f64,
    /// Failures per million rays: false misses + false hits + wrong primitives (ray queries),
    /// self-intersections (secondary rays).
    pub error: f64,
}

/// The points no other point beats in both speed and error (lower error, higher Mrays/s),
/// by increasing error.
pub(super) fn pareto(points: &[Point]) -> Vec<Point> {
    let mut sorted: Vec<&Point> = points.iter().collect();
    sorted.sort_by(|a, b| {
        a.error
            .total_cmp(&b.error)
            .then(b.mrays.total_cmp(&a.mrays))
    });
    let mut front: Vec<Point> = Vec::new();
    for p in sorted {
        if front.last().is_none_or(|f| p.mrays > f.mrays) {
            front.push(p.clone());
        }
    }
    front
}

/// The sets of `points`, in order of first appearance.
fn sets_of(points: &[Point]) -> Vec<&'static str> {
    let mut sets: Vec<&'static str> = Vec::new();
    for p in points {
        if !sets.contains(&p.set) {
            sets.push(p.set);
        }
    }
    sets
}

/// The Pareto front of each set (methods are compared on the same rays only).
fn fronts(points: &[Point]) -> Vec<Vec<Point>> {
    sets_of(points)
        .into_iter()
        .map(|set| {
            let of_set: Vec<Point> = points.iter().filter(|p| p.set == set).cloned().collect();
            pareto(&of_set)
        })
        .collect()
}

fn front_table(title: &str, points: &[Point]) -> String {
    let mut s = format!(
        "\nPareto fronts, {title} (per set):\n\n| set | method | Mrays/s | failures /M |\n|---|---|---|---|\n"
    );
    for p in fronts(points).iter().flatten() {
        writeln!(
            s,
            "| {} | {} | {:.2} | {:.0} |",
            p.set, p.method, p.mrays, p.error
        )
        .ok();
    }
    s
}

pub(super) fn chart(a: &Args) -> Result<String> {
    let b = Backends::open()?;
    let t0 = Instant::now();
    let (qp, qt) = queries::queries(a, &b)?;
    let (sp, st) = secondary::secondary(a, &b)?;
    let psnr = psnr::psnr_table(&b)?;
    let secs = t0.elapsed().as_secs_f64();
    warn(format_args!("bench chart: measured in {secs:.0} s"));
    let images = draw(
        a,
        &[("Ray queries", &qp), ("Secondary rays (shadow)", &sp)],
        b.gpu_legend().as_deref(),
    );
    Ok(format!(
        "### Speed against accuracy (CPU and GPU backends)\n\n\
         ![speed against accuracy](docs/chart.png)\n\n{images}\n\n\
         Modes (the `mode` column; marker on the chart): **single** = `QueryMode::Single`, one ray \
         at a time, every traversal × intersector (circles); **packet** = `QueryMode::Packet` \
         (triangles) and **stream** = `QueryMode::Stream` (squares), which follow the standard \
         traversal's order with either intersector (both tested on 16 rays or triangles at \
         once in the leaves, where the CPU has AVX-512); **gpu** = the GPU backend (diamonds), every traversal \
         kernel, Möller–Trumbore only (the one its kernels have), every offset mode; its \
         Möller–Trumbore rounds differently from the CPU's near edges (Vulkan lets a division \
         be off by 2.5 ULP and a shader compiler fuse multiply-adds), so its leak count on the \
         stress set differs a little from the CPU's. GPU: {}. Colour: the ray set; filled: \
         watertight test. \
         Mrays/s with all cores (median of the runs) on a shared machine: speeds are \
         noisy (compare points measured in the same run), the error counts are exact. Measured in {secs:.0} s.\n\n\
         Errors against an f64 brute force over the exact triangle corners (a watertight test in f64, \
         closed edges; a neighbour hit at the same distance is a tie, not an error). Failures = false misses (leaks) + false hits + wrong \
         primitive, per million rays; leaks are rays from inside a closed mesh whose first hit is \
         not that mesh (exact: no reference needed). The stress scene (closed uv sphere, torus, cube of \
         triangles; all closed) at scale 1e-7, 1, 1e7 and 1e4 from the origin: rays from inside \
         to every vertex and edge midpoint and axis-parallel with every sign of zero (all must \
         hit, and must hit the mesh they start in), and rays grazing the sphere's silhouette \
         (checked against the reference).\n\n{qt}{}\n\
         #### Secondary-ray origins\n\n\
         192×192 primary rays onto the stress meshes on a floor, at the origin and 1e3 away, one \
         shadow ray each; on the lit side of a convex object (sphere, cube, floor) a shadow ray \
         that hits its own object is a self-intersection (acne), per million such shadow rays. \
         They include silhouette edges where the primary ray's closest hit is the back face \
         sharing the edge (the tie goes to the lower index): the shading side then points into \
         the object and every offset mode starts inside it. Single: each pixel's shadow ray \
         right after its primary ray (the depth-first schedule). Packet, stream and gpu: all \
         primary rays as one batch query, the shadow origins computed on the host, then all \
         shadow rays as another (the breadth-first schedule), each shadow ray with its \
         excluded primitive under exclude-prim (`Context::intersect_excluding`, \
         `rt2_query_options.exclude`).\n\n{st}{}{psnr}",
        b.gpu_note,
        front_table("ray queries", &qp),
        front_table("secondary rays", &sp)
    ))
}

#[cfg(feature = "chart")]
fn draw(a: &Args, panels: &[(&str, &Vec<Point>)], gpu: Option<&str>) -> String {
    match plot::draw(panels, gpu) {
        Ok(()) => {
            "Chart: [docs/chart.svg](docs/chart.svg), [docs/chart.png](docs/chart.png).".into()
        }
        Err(e) => {
            a.skip(format_args!("the chart's images (not drawn: {e})"));
            format!("(chart not drawn: {e})")
        }
    }
}

#[cfg(not(feature = "chart"))]
fn draw(a: &Args, _: &[(&str, &Vec<Point>)], _: Option<&str>) -> String {
    a.skip("the chart's images (built without the `chart` feature: none drawn)");
    "(chart not drawn: build with `--features chart`)".into()
}
