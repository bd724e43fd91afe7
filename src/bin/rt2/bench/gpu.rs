//! `rt2 bench gpu`: the thesis' table 2 on the GPU backend, both render paths, against the CPU.

use super::{shared_model, time_ms, Args};
use crate::load_scene;
use rt2::context::Context;
use rt2::cpu::traverse::Traversal;
use rt2::dispatch::BackendRequest;
use rt2::error::{Error, Result};
use rt2::frame::Frame;
use rt2::render::{GpuPathRequest, RenderOptions};
use std::fmt::Write as _;
use std::path::Path;

/// Thesis table 2 on the GPU backend: ms per frame for every traversal (AUTO render path),
/// then megakernel against wavefront and the GPU against the CPU (both at their AUTO
/// traversal). A software adapter (lavapipe) is labelled as such and renders a quarter of
/// the thesis' frame side (1/16 of the pixels): it shows the kernels work, not GPU speed.
pub(super) fn gpu(a: &Args) -> Result<String> {
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
        names.extend(shared_model(a, m).map(|p| p.display().to_string()));
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
            time_ms(a.runs, || ctx.render(c, &l.camera, &opts, &mut frame))
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
