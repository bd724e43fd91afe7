//! `rt2 bench tables`: the RT² thesis' tables 1 and 2 on the CPU (nodes visited per ray, tree
//! memory, ms per frame for every traversal) beside the thesis' figures.

use super::{mib, shared_model, time_ms, Args, MAX_RUNS_LARGE};
use crate::load_scene;
use rt2::context::{Context, QueryOptions};
use rt2::cpu::query::QueryMode;
use rt2::cpu::traverse::Traversal;
use rt2::dispatch::BackendRequest;
use rt2::error::Result;
use rt2::frame::Frame;
use rt2::geometry::{Hit, Ray};
use rt2::render::RenderOptions;
use std::fmt::Write as _;
use std::path::Path;

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

pub(super) fn tables(a: &Args) -> Result<String> {
    let (w, h) = (1376u32, 768u32);
    let ctx = Context::new(BackendRequest::Cpu, 0)?;
    let mut scenes: Vec<String> = Vec::new();
    for model in ["bunny", "dragon", "snowden"] {
        scenes.extend(shared_model(a, &format!("{model}.ply")).map(|p| p.display().to_string()));
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
            a.runs.min(MAX_RUNS_LARGE)
        } else {
            a.runs
        };
        let mut row = format!("| {label} | {} |", l.max_depth);
        for (how, (_, thesis_nodes)) in Traversal::ALL.into_iter().zip(THESIS_NODES_BUNNY) {
            let q = QueryOptions {
                traversal: Some(how),
                mode: Some(QueryMode::Single),
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
            let ms = time_ms(runs, || ctx.render(c, &l.camera, &opts, &mut frame))?;
            write!(row, " {ms:.1} |").ok();
        }
        writeln!(t2, "{row} {} |", thesis_ms(&label)).ok();
    }
    Ok(format!("{t1}\n{t2}"))
}
