//! `rt2 bench memory`: bytes per primitive of each part of each scene, beside a tessellation of
//! its analytic primitives (the person we build for: model no more than a scene needs).

use super::{mib, model_scene, Args};
use rt2::error::Result;
use rt2::scene::{builtin, tessellate, Scene};
use std::fmt::Write as _;

/// Bytes per primitive of each part of each built-in scene and the bunny, and what the same
/// analytic primitives would cost tessellated (a 16×32 uv sphere per sphere: 960 triangles).
pub(super) fn memory(a: &Args) -> Result<String> {
    let tess = tessellate::uv_sphere(16, 32);
    let tri_bytes = std::mem::size_of::<rt2::geometry::Triangle>();
    let per_sphere = tess.triangles.len() * tri_bytes;
    let mut out = format!(
        "### Memory: bytes per primitive of each part\n\n\
         Total = what a committed scene holds (primitives, nodes, leaf lists). Built only on \
         demand, and shown at what they cost then: ropes + leaf boxes (rope traversals), exact \
         triangle corners (watertight test). Tessellated: every sphere or ellipsoid as a \
         closed {}-triangle uv sphere ({per_sphere} B of triangles, before any tree).\n\n\
         | scene | primitives | kinds | primitive arrays B/prim | tree nodes B/prim | leaf lists B/prim | on demand: ropes + leaf boxes B/prim | on demand: exact corners B/prim | total MiB | tessellated triangles MiB |\n\
         |---|---|---|---|---|---|---|---|---|---|\n",
        tess.triangles.len()
    );
    let mut scenes: Vec<(String, Scene)> = Vec::new();
    for name in builtin::NAMES {
        scenes.push((name.to_string(), builtin::by_name(name)?.scene));
    }
    if let Some(s) = model_scene(a, "bunny.ply")? {
        scenes.push(("bunny".into(), s));
    }
    for (name, mut s) in scenes {
        s.commit()?;
        let plain = s.committed()?.prims.bytes();
        // The on-demand parts, built here to report what they cost when asked for.
        s.ensure_ropes()?;
        s.ensure_exact_vertices()?;
        let c = s.committed()?;
        let p = &c.prims;
        let n = (p.len() + p.planes.len()).max(1) as f64;
        let kinds = format!(
            "{} tri, {} sph, {} ell, {} box, {} plane",
            p.triangles.len(),
            p.spheres.len(),
            p.ellipsoids.len(),
            p.boxes.len(),
            p.planes.len()
        );
        let parts = [
            plain,
            c.tree.node_bytes(),
            c.tree.leaf_list_bytes(),
            c.tree.rope_bytes() + c.tree.leaf_box_bytes(),
            p.vertices.len() * 36,
        ];
        let analytic = p.spheres.len() + p.ellipsoids.len();
        writeln!(
            out,
            "| {name} | {} | {kinds} | {:.1} | {:.1} | {:.1} | {:.1} | {:.1} | {:.2} | {} |",
            n,
            parts[0] as f64 / n,
            parts[1] as f64 / n,
            parts[2] as f64 / n,
            parts[3] as f64 / n,
            parts[4] as f64 / n,
            mib(parts[..3].iter().sum()),
            if analytic > 0 {
                format!(
                    "{:.1}",
                    mib(analytic * per_sphere + p.triangles.len() * tri_bytes)
                )
            } else {
                "-".into()
            }
        )
        .ok();
    }
    Ok(out)
}
