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

/// Writes `rays` as a ray-set file that [`read_rays`] (and the peers' tools) read back as they
/// were.
pub fn write_rays(path: &Path, rays: &[Ray]) -> Result<()> {
    let count = u32::try_from(rays.len())
        .map_err(|_| Error::invalid_argument("a ray-set file holds at most 2^32 - 1 rays"))?;
    let mut bytes = Vec::with_capacity(16 + 32 * rays.len());
    bytes.extend(RAYS_MAGIC);
    bytes.extend(1u32.to_le_bytes());
    bytes.extend(count.to_le_bytes());
    for r in rays {
        let (o, d) = (r.org, r.dir);
        for v in [o.x, o.y, o.z, r.tmin, d.x, d.y, d.z, r.tmax] {
            bytes.extend(v.to_le_bytes());
        }
    }
    std::fs::write(path, bytes)
        .map_err(|e| Error::io(format!("cannot write {}: {e}", path.display())))
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
    /// The same primitive, `|Δt| > eps·diag`: one of the two computed the hit wrongly.
    pub t_disagreements: usize,
}

impl Agreement {
    /// Rays on which the two disagree for real (hit/miss, a different surface, or another
    /// distance to the same primitive).
    pub fn disagreements(&self) -> usize {
        self.a_only + self.b_only + self.mismatches + self.t_disagreements
    }
}

/// Compares two hit lists with `rt2cmp`'s rule (`tol = eps · diag`, default eps 1e-4). A `t`
/// that is NaN on either side counts as further than `tol`.
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
            // `<=` rather than `>` so that a NaN distance is not within tol.
            (true, true) => match (x.prim == y.prim, (x.t - y.t).abs() <= tol) {
                (false, false) => g.mismatches += 1,
                (false, true) => g.ties += 1,
                (true, false) => g.t_disagreements += 1,
                (true, true) => {}
            },
            (false, false) => {}
        }
    }
    g
}

#[cfg(test)]
mod tests {
    use super::*;

    fn hit(prim: u32, t: f32) -> HitRecord {
        HitRecord {
            t,
            prim,
            u: 0.25,
            v: 0.25,
        }
    }

    /// One record pair of each of `rt2cmp`'s cases (tol = 1e-4 · 10 = 1e-3), each counted
    /// where that tool counts it, and only the real disagreements in `disagreements`; a NaN
    /// `t`, which `rt2cmp` lets pass (`dt > tol` is false), is deliberately a disagreement.
    #[test]
    fn each_case_is_counted_as_rt2cmp_counts_it() {
        let miss = hit(u32::MAX, f32::INFINITY);
        let pairs = [
            (hit(1, 2.0), hit(1, 2.0)),      // agree
            (hit(1, 2.0), hit(1, 2.0005)),   // same prim within tol: agree
            (hit(1, 2.0), hit(1, 2.5)),      // same prim, t off: disagreement
            (hit(1, 2.0), hit(1, f32::NAN)), // same prim, NaN t: disagreement
            (hit(1, 2.0), hit(2, 2.0005)),   // shared edge: tie
            (hit(1, 2.0), hit(2, 3.0)),      // another surface: mismatch
            (hit(1, 2.0), miss),             // a only
            (miss, hit(2, 3.0)),             // b only
            (miss, miss),                    // agree
        ];
        let (a, b): (Vec<_>, Vec<_>) = pairs.into_iter().unzip();
        let g = compare(&a, &b, 10.0, 1e-4);
        let want = Agreement {
            rays: 9,
            a_only: 1,
            b_only: 1,
            mismatches: 1,
            ties: 1,
            t_disagreements: 2,
        };
        assert_eq!(g, want);
        assert_eq!(g.disagreements(), 5);
        // The shorter list bounds the count.
        assert_eq!(compare(&a[..3], &b, 10.0, 1e-4).rays, 3);
    }
}
