//! PSNR of renders of every built-in scene with each offset mode and intersector, against the
//! CPU's watertight, robust-offset render.

use super::{Backends, Engine};
use rt2::context::Context;
use rt2::cpu::query::QueryMode;
use rt2::cpu::traverse::Traversal;
use rt2::error::Result;
use rt2::precision::{Intersector, OffsetMode};
use rt2::render::RenderOptions;
use rt2::scene::builtin;
use std::fmt::Write as _;

/// Size of the PSNR renders: half the README's 1376x768 in each direction.
const PSNR_SIZE: (u32, u32) = (688, 384);

/// PSNR of renders of every built-in scene with each offset mode (and each intersector where
/// the scene has triangles; on the GPU: Möller–Trumbore, the one it has), standard
/// traversal, against the CPU render with the watertight test and the robust offset.
pub(super) fn psnr_table(b: &Backends) -> Result<String> {
    let (w, h) = PSNR_SIZE;
    let mut out = format!(
        "\n#### Renders against a reference render\n\n\
         Every built-in scene at {w}x{h} and its own depth, standard traversal; PSNR in dB of \
         the RGB channels against the CPU render with the watertight test and the robust offset \
         (inf: identical), and in brackets the pixels that differ. Only triangles have two \
         intersectors: scenes without any show one row. The GPU kernels have Möller–Trumbore \
         only. This table measures how far the modes move an image from each other; \
         against an independent f64 brute-force tracer (spheres, plane, two lights, \
         reflection; `cargo test --release --test render_reference -- --nocapture`) every \
         offset mode scores above 62 dB in both schedules.\n\n| scene | mode | intersector |"
    );
    for mode in OffsetMode::ALL {
        write!(out, " {} |", mode.name()).ok();
    }
    out.push_str("\n|---|---|---|");
    out.push_str(&"---|".repeat(OffsetMode::ALL.len()));
    out.push('\n');
    for name in builtin::NAMES {
        let mut scene = builtin::by_name(name)?;
        b.cpu.install(|| scene.scene.commit())?;
        scene.scene.ensure_exact_vertices()?;
        let c = scene.scene.committed()?;
        let render = |ctx: &Context, intersector, offset_mode| -> Result<Vec<u8>> {
            let opts = RenderOptions {
                max_depth: scene.max_depth,
                traversal: Some(Traversal::Standard),
                intersector,
                offset_mode,
                ..RenderOptions::default()
            };
            let mut frame = rt2::frame::Frame::new(w, h)?;
            ctx.render(c, &scene.camera, &opts, &mut frame)?;
            Ok(frame.pixels().to_vec())
        };
        let reference = render(&b.cpu, Intersector::Watertight, OffsetMode::Robust)?;
        let intersectors: &[Intersector] = if c.prims.triangles.is_empty() {
            &[Intersector::MollerTrumbore]
        } else {
            &Intersector::ALL
        };
        let mut rows: Vec<(Engine, &Context, Intersector)> = intersectors
            .iter()
            .map(|&i| (Engine::Cpu(QueryMode::Single), &b.cpu, i))
            .collect();
        if let Some(g) = &b.gpu {
            rows.push((Engine::Gpu, g, Intersector::MollerTrumbore));
        }
        for (engine, ctx, intersector) in rows {
            let shown = if c.prims.triangles.is_empty() {
                "any (no triangles)"
            } else {
                intersector.name()
            };
            write!(out, "| {name} | {} | {shown} |", engine.name()).ok();
            for mode in OffsetMode::ALL {
                let (db, differ) = psnr(&render(ctx, intersector, mode)?, &reference);
                write!(out, " {db:.1} ({differ}) |").ok();
            }
            out.push('\n');
        }
    }
    Ok(out)
}

/// PSNR in dB of the RGB channels of RGBA image `img` against `reference` (inf when they are
/// equal), and how many pixels differ in RGB. Alpha is left out: it is 255 in every render.
fn psnr(img: &[u8], reference: &[u8]) -> (f64, usize) {
    let (mut se, mut n, mut differ) = (0.0f64, 0usize, 0usize);
    for (p, q) in img.chunks_exact(4).zip(reference.chunks_exact(4)) {
        differ += (p[..3] != q[..3]) as usize;
        for k in 0..3 {
            se += (p[k] as f64 - q[k] as f64).powi(2);
            n += 1;
        }
    }
    let db = 10.0 * (255.0f64 * 255.0 / (se / n.max(1) as f64)).log10();
    (db, differ)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn psnr_is_over_rgb_and_counts_differing_pixels() {
        let a = [10u8, 20, 30, 255, 0, 0, 0, 255];
        assert_eq!(psnr(&a, &a), (f64::INFINITY, 0));
        // Alpha is not an image channel here.
        let mut b = a;
        b[3] = 0;
        assert_eq!(psnr(&b, &a), (f64::INFINITY, 0));
        // One of 6 channels off by 255: MSE = 255² / 6, PSNR = 10 log10(6) dB.
        b[4] = 255;
        let (db, differ) = psnr(&b, &a);
        assert!((db - 10.0 * 6f64.log10()).abs() < 1e-12, "{db}");
        assert_eq!(differ, 1);
    }
}
