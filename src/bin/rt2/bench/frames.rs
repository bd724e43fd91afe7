//! `rt2 bench frames`: ms per 1376×768 Whitted frame on the CPU (spheres3 and the bunny), with
//! commit time and memory, and the RT² per-frame rebuild of moving objects.

use super::{mib, shared_model, time_ms, Args};
use crate::load_scene;
use rt2::context::Context;
use rt2::dispatch::BackendRequest;
use rt2::error::Result;
use rt2::frame::Frame;
use rt2::render::RenderOptions;
use std::fmt::Write as _;
use std::path::Path;

pub(super) fn frames(a: &Args) -> Result<String> {
    let ctx = Context::new(BackendRequest::Cpu, 0)?;
    let mut out = String::from(
        "### Whitted frames on the CPU (1376x768, 1 sample, AUTO traversal)\n\n\
         | scene | primitives | commit ms | ms/frame (median) | M primary rays/s | nodes MiB | leaf lists MiB | primitives MiB |\n\
         |---|---|---|---|---|---|---|---|\n",
    );
    let mut names = vec!["spheres3".to_string()];
    names.extend(shared_model(a, "bunny.ply").map(|p| p.display().to_string()));
    for name in names {
        let mut l = load_scene(&name)?;
        let opts = RenderOptions {
            max_depth: l.max_depth,
            ..RenderOptions::default()
        };
        let commit_ms = time_ms(a.runs, || ctx.install(|| l.scene.rebuild()))?;
        let c = l.scene.committed()?;
        let mut frame = Frame::new(1376, 768)?;
        let ms = time_ms(a.runs, || ctx.render(c, &l.camera, &opts, &mut frame))?;
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
    let moved = objects / 10;
    let mut frame = 0u32;
    let ms = time_ms(a.runs, || {
        frame += 1;
        // A tenth of the objects, a different tenth each frame.
        for o in (frame % 10..objects).step_by(10).take(moved as usize) {
            let dy = 0.1 * ((frame + o) % 7) as f32;
            l.scene.set_transform(
                o,
                glam::Affine3A::from_translation(glam::Vec3::new(0.0, dy, 0.0)),
            )?;
        }
        ctx.install(|| l.scene.commit())
    })?;
    Ok(format!(
        "\nMoving objects (RT² per-frame rebuild): spheres3 with {moved} of its {objects} objects moved per frame, \
         set_transform + commit: {ms:.2} ms per frame (median).\n"
    ))
}
