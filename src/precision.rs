//! Precision modes: which ray–triangle test the intersection core runs, and how secondary
//! rays leave a surface. Speed against accuracy is charted by `rt2 bench chart`
//! (BENCHMARKS.md); what each mode guarantees and costs is written on its variant.

use glam::Vec3;

/// The ray–triangle test of every traversal (`TraverseOptions::intersector`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Intersector {
    /// Möller & Trumbore (1997) on the stored `v0, e1, e2`. Fastest (no per-ray set-up).
    /// Guarantees nothing at shared edges and vertices: the edge tests of two neighbours are
    /// rounded differently, so a ray through an edge can slip between them (a "leak"; measured
    /// by `tests/precision.rs` and the chart).
    #[default]
    MollerTrumbore,
    /// Woop, Benthin & Wald (2013), "Watertight ray/triangle intersection": the triangle is
    /// sheared into the ray's space (a per-ray `kx, ky, kz, Sx, Sy, Sz`, computed once per
    /// ray) and tested with 2D edge functions, recomputed in f64 when one is exactly zero.
    /// Guarantees that a ray through a shared edge or vertex of a closed mesh hits at least
    /// one of the triangles (never both missed): the test reads the exact corners
    /// (`Scene::ensure_exact_vertices`), the scene box is padded, and the kd-tree lists a
    /// primitive in every leaf it touches (conservative leaf membership), so every traversal
    /// keeps the guarantee (`tests/precision.rs`). Costs the per-ray set-up, a few more
    /// operations per test and 36 bytes per triangle for the exact corners.
    Watertight,
}

impl Intersector {
    pub const ALL: [Intersector; 2] = [Intersector::MollerTrumbore, Intersector::Watertight];

    pub fn name(self) -> &'static str {
        match self {
            Intersector::MollerTrumbore => "moller-trumbore",
            Intersector::Watertight => "watertight",
        }
    }

    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|i| i.name() == name)
    }
}

/// Where secondary rays (shadow, reflection, refraction) start.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum OffsetMode {
    /// `p + 1e-5 · scene diagonal · n` from `org + t · dir`. One multiply-add; fails on
    /// details smaller than the epsilon (light leaks through thin walls, missed contact
    /// shadows) and at coordinates far larger than the scene (acne when the error of `p`
    /// exceeds the epsilon).
    #[default]
    Epsilon,
    /// Wächter & Binder (2019), "A fast and robust method for avoiding self-intersection"
    /// (Ray Tracing Gems ch. 6): the hit point is recomputed on the surface (barycentrics for
    /// triangles, the ray re-solved relative to the centre for spheres and ellipsoids:
    /// `PrimitiveSet::shading_surface`) and moved a fixed number of ULPs along the
    /// geometric normal, so the offset follows the magnitude of the coordinates, not the
    /// scene: no self-intersection at any scale, and offsets of a few ULPs instead of a
    /// scene-sized epsilon (near the origin, where ULPs vanish, `2^-16 ·` scene diagonal).
    Robust,
    /// The ray starts exactly on the recomputed hit point and ignores the primitive just hit.
    /// Exact for flat primitives (a triangle or plane cannot be hit twice); a ray that enters
    /// a curved primitive (refraction into a sphere) must hit it again, so it takes the
    /// robust offset instead. Neighbouring triangles are not excluded: a ray leaving a
    /// concave edge can still hit the neighbour at `t ≈ 0` (measured as acne by the chart).
    ExcludePrim,
}

impl OffsetMode {
    pub const ALL: [OffsetMode; 3] = [
        OffsetMode::Epsilon,
        OffsetMode::Robust,
        OffsetMode::ExcludePrim,
    ];

    pub fn name(self) -> &'static str {
        match self {
            OffsetMode::Epsilon => "epsilon",
            OffsetMode::Robust => "robust",
            OffsetMode::ExcludePrim => "exclude-prim",
        }
    }

    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|m| m.name() == name)
    }
}

/// Wächter & Binder's `offset_ray` (Ray Tracing Gems, listing 6-1): moves `p` along the unit
/// normal `n` (pointing to the side the new ray leaves into) by 256 ULPs of each coordinate,
/// or by `2^-16 · scale` for coordinates below `scale / 32`, where ULPs become smaller than
/// the error of a point computed from the geometry. The paper's constants are those of a
/// scene of unit size; `scale` (the scene diagonal) keeps them right for a scene of 1e-7 or
/// 1e7 units.
pub fn offset_ray_origin(p: Vec3, n: Vec3, scale: f32) -> Vec3 {
    const ORIGIN: f32 = 1.0 / 32.0;
    const FLOAT_SCALE: f32 = 1.0 / 65536.0;
    const INT_SCALE: f32 = 256.0;
    let mut out = p;
    for a in 0..3 {
        out[a] = if p[a].abs() < ORIGIN * scale {
            p[a] + FLOAT_SCALE * scale * n[a]
        } else {
            // Adding to the bit pattern moves away from zero for either sign of `p`; the
            // offset's sign follows the normal's relative to `p`'s.
            let of_i = (INT_SCALE * n[a]) as i32;
            let of_i = if p[a] < 0.0 { -of_i } else { of_i };
            f32::from_bits((p[a].to_bits() as i32).wrapping_add(of_i) as u32)
        };
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip() {
        for i in Intersector::ALL {
            assert_eq!(Intersector::from_name(i.name()), Some(i));
        }
        for m in OffsetMode::ALL {
            assert_eq!(OffsetMode::from_name(m.name()), Some(m));
        }
    }

    #[test]
    fn robust_offset_moves_along_the_normal_at_every_scale() {
        for scale in [1e-7f32, 1e-2, 1.0, 1e3, 1e7] {
            for sign in [1.0f32, -1.0] {
                let p = Vec3::new(0.7, -1.3, 2.1) * scale * sign;
                let n = Vec3::new(0.6, 0.0, -0.8);
                let q = offset_ray_origin(p, n, scale);
                let d = q - p;
                // On the side of the normal, and small: at most ~256 ULPs or 2^-16.
                assert!(d.dot(n) > 0.0, "scale {scale}: {p} -> {q}");
                let bound = (p.abs().max_element() * 256.0 * f32::EPSILON).max(scale / 32768.0);
                assert!(d.length() <= bound, "scale {scale}: moved {}", d.length());
                assert_eq!(q.y, p.y, "no move along a zero normal component");
            }
        }
    }
}
