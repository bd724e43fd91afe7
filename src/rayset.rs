//! Reader and writer of the ray-set files of `../shared/raysets` (`RT2RAYS` / `RT2HITS`,
//! little-endian; the format is defined in `../shared/raysets/README.md`), and the agreement
//! rule of `../shared/peers/src/rt2cmp.cpp` used to compare hits with Embree's.

use crate::error::{Error, Result};
use crate::geometry::{Hit, Ray};
use crate::scene::Committed;
use glam::Vec3;
use std::path::Path;

const RAYS_MAGIC: &[u8; 8] = b"RT2RAYS\0";
const HITS_MAGIC: &[u8; 8] = b"RT2HITS\0";

/// One record of a `.hits` file: `prim == u32::MAX` is a miss.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HitRecord {
    pub t: f32,
    pub prim: u32,
    pub u: f32,
    pub v: f32,
}

impl HitRecord {
    /// The record of `h` in a committed single-mesh scene: `prim` is the triangle's index in
    /// the mesh, as in the ray-set files (the committed scene numbers its primitives for
    /// locality; their origins give the mesh's numbers back).
    pub fn of(h: &Hit, scene: &Committed) -> Self {
        HitRecord {
            t: h.t,
            prim: match scene.origins.get(h.prim as usize) {
                Some(o) if h.is_hit() => o.prim,
                _ => u32::MAX,
            },
            u: h.u,
            v: h.v,
        }
    }
}

fn records<'a>(bytes: &'a [u8], magic: &[u8; 8], rec: usize, path: &Path) -> Result<&'a [u8]> {
    let bad = |what: &str| Error::parse(format!("{}: {what}", path.display()));
    if bytes.len() < 16 || &bytes[..8] != magic {
        return Err(bad("not a ray-set file (bad magic)"));
    }
    let word = |o: usize| u32::from_le_bytes([bytes[o], bytes[o + 1], bytes[o + 2], bytes[o + 3]]);
    if word(8) != 1 {
        return Err(bad(&format!("version {} (expected 1)", word(8))));
    }
    let count = word(12) as usize;
    let body = &bytes[16..];
    if body.len() != count * rec {
        return Err(bad(&format!(
            "{count} records announced, {} bytes of records found",
            body.len()
        )));
    }
    Ok(body)
}

fn f32s(chunk: &[u8]) -> impl Iterator<Item = f32> + '_ {
    chunk
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
}

fn read(path: &Path) -> Result<Vec<u8>> {
    std::fs::read(path).map_err(|e| Error::io(format!("cannot read {}: {e}", path.display())))
}

pub fn read_rays(path: &Path) -> Result<Vec<Ray>> {
    let bytes = read(path)?;
    let body = records(&bytes, RAYS_MAGIC, 32, path)?;
    Ok(body
        .chunks_exact(32)
        .map(|r| {
            let v: Vec<f32> = f32s(r).collect();
            Ray::new(
                Vec3::new(v[0], v[1], v[2]),
                Vec3::new(v[4], v[5], v[6]),
                v[3],
                v[7],
            )
        })
        .collect())
}

pub fn read_hits(path: &Path) -> Result<Vec<HitRecord>> {
    let bytes = read(path)?;
    let body = records(&bytes, HITS_MAGIC, 16, path)?;
    Ok(body
        .chunks_exact(16)
        .map(|r| {
            let w = |o: usize| [r[o], r[o + 1], r[o + 2], r[o + 3]];
            HitRecord {
                t: f32::from_le_bytes(w(0)),
                prim: u32::from_le_bytes(w(4)),
                u: f32::from_le_bytes(w(8)),
                v: f32::from_le_bytes(w(12)),
            }
        })
        .collect())
}

/// Counts of [`compare`], named as `rt2cmp` prints them.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Agreement {
    pub rays: usize,
    /// Hit by `a` only / by `b` only.
    pub a_only: usize,
    pub b_only: usize,
    /// Both hit, different primitives, `|Δt| > eps·diag`.
    pub mismatches: usize,
    /// Different primitives within `eps·diag`: a shared edge or vertex, either answer right.
    pub ties: usize,
}

impl Agreement {
    /// Rays on which the two disagree for real (hit/miss or a different surface).
    pub fn disagreements(&self) -> usize {
        self.a_only + self.b_only + self.mismatches
    }
}

/// Compares two hit lists with `rt2cmp`'s rule (`tol = eps · diag`, default eps 1e-4).
pub fn compare(a: &[HitRecord], b: &[HitRecord], diag: f32, eps: f32) -> Agreement {
    let tol = eps * diag;
    let mut g = Agreement {
        rays: a.len().min(b.len()),
        ..Agreement::default()
    };
    for (x, y) in a.iter().zip(b) {
        match (x.prim != u32::MAX, y.prim != u32::MAX) {
            (true, false) => g.a_only += 1,
            (false, true) => g.b_only += 1,
            (true, true) if x.prim != y.prim => {
                if (x.t - y.t).abs() > tol {
                    g.mismatches += 1;
                } else {
                    g.ties += 1;
                }
            }
            _ => {}
        }
    }
    g
}
