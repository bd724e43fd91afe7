//! Triangles, stored as `v0` and two edges so that Möller–Trumbore needs no subtraction
//! of vertices per test (the precomputation of the vectorised-traversal paper), and the two
//! ray–triangle tests of [`crate::precision::Intersector`].

use super::{Aabb, Ray};
use crate::precision::Intersector;
use glam::{DVec2, Vec3};

/// The per-ray part of a triangle test, computed once per ray (Woop et al.'s shear: the
/// dominant axis `kz` of the direction, the two others in an order that keeps the winding,
/// and the shear constants `Sx, Sy, Sz`).
#[derive(Clone, Copy, Debug)]
pub enum TriangleTest {
    MollerTrumbore,
    Watertight { k: [usize; 3], s: Vec3 },
}

impl TriangleTest {
    pub fn new(ray: &Ray, intersector: Intersector) -> Self {
        match intersector {
            Intersector::MollerTrumbore => TriangleTest::MollerTrumbore,
            Intersector::Watertight => {
                let kz = ray.dir.abs().max_position();
                let (mut kx, mut ky) = ((kz + 1) % 3, (kz + 2) % 3);
                if ray.dir[kz] < 0.0 {
                    std::mem::swap(&mut kx, &mut ky);
                }
                let d = ray.dir;
                TriangleTest::Watertight {
                    k: [kx, ky, kz],
                    s: Vec3::new(d[kx] / d[kz], d[ky] / d[kz], 1.0 / d[kz]),
                }
            }
        }
    }
}

#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct Triangle {
    pub v0: [f32; 3],
    pub e1: [f32; 3],
    pub e2: [f32; 3],
}

impl Triangle {
    pub fn from_vertices(a: Vec3, b: Vec3, c: Vec3) -> Self {
        Triangle {
            v0: a.to_array(),
            e1: (b - a).to_array(),
            e2: (c - a).to_array(),
        }
    }

    pub fn vertices(&self) -> [Vec3; 3] {
        let v0 = Vec3::from(self.v0);
        [v0, v0 + Vec3::from(self.e1), v0 + Vec3::from(self.e2)]
    }

    pub fn bounds(&self) -> Aabb {
        Aabb::from_points(&self.vertices())
    }

    /// Unnormalised geometric normal `e1 × e2` (zero for degenerate triangles).
    pub fn normal(&self) -> Vec3 {
        Vec3::from(self.e1).cross(Vec3::from(self.e2))
    }

    /// The test `how` asks for. Returns `(t, u, v)` with `tmin <= t < tmax`.
    #[inline]
    pub fn intersect(&self, ray: &Ray, how: &TriangleTest, tmax: f32) -> Option<(f32, f32, f32)> {
        match how {
            TriangleTest::MollerTrumbore => self.moller_trumbore(ray, tmax),
            TriangleTest::Watertight { k, s } => watertight(self.vertices(), ray, *k, *s, tmax),
        }
    }

    /// Möller–Trumbore (1997). Degenerate (zero-area) triangles have `det == 0` and are never
    /// hit.
    #[inline]
    fn moller_trumbore(&self, ray: &Ray, tmax: f32) -> Option<(f32, f32, f32)> {
        let e1 = Vec3::from(self.e1);
        let e2 = Vec3::from(self.e2);
        let p = ray.dir.cross(e2);
        let det = e1.dot(p);
        if det == 0.0 || !det.is_finite() {
            return None;
        }
        let inv = 1.0 / det;
        let s = ray.org - Vec3::from(self.v0);
        let u = s.dot(p) * inv;
        if !(0.0..=1.0).contains(&u) {
            return None;
        }
        let q = s.cross(e1);
        let v = ray.dir.dot(q) * inv;
        if v < 0.0 || u + v > 1.0 {
            return None;
        }
        let t = e2.dot(q) * inv;
        (t >= ray.tmin && t < tmax).then_some((t, u, v))
    }

    /// Bounds of the part of the triangle inside `voxel` (Sutherland–Hodgman clipping against
    /// the six slabs): the "perfect splits" of Havran's thesis used by the SAH builder.
    pub fn clipped_bounds(&self, voxel: &Aabb) -> Aabb {
        let bounds = self.bounds();
        if !bounds.overlaps(voxel) {
            return Aabb::EMPTY;
        }
        if voxel.contains_point(bounds.min) && voxel.contains_point(bounds.max) {
            return bounds;
        }
        // A triangle cut by six planes has at most 9 corners: fixed arrays, no allocation
        // (the SAH builder clips every straddling triangle at every level). Corners are plain
        // arrays so that the axis indexes them directly.
        let mut poly = [[0f32; 3]; 9];
        let mut next = [[0f32; 3]; 9];
        for (corner, v) in poly.iter_mut().zip(self.vertices()) {
            *corner = v.to_array();
        }
        let mut len = 3;
        for axis in 0..3 {
            for (plane, keep_below) in [(voxel.min[axis], false), (voxel.max[axis], true)] {
                // A plane the triangle does not cross leaves the polygon as it is: skipping it
                // is exact, and most clips of the builder cross one or two planes of six.
                let crossed = if keep_below {
                    bounds.max[axis] > plane
                } else {
                    bounds.min[axis] < plane
                };
                if !crossed {
                    continue;
                }
                let inside = |p: &[f32; 3]| {
                    if keep_below {
                        p[axis] <= plane
                    } else {
                        p[axis] >= plane
                    }
                };
                let mut n = 0;
                // Each edge runs from `a` to `b` in the polygon's order, so that a shared edge
                // is cut at the same point whichever corner the loop starts from.
                let mut a = poly[len - 1];
                for &b in &poly[..len] {
                    if inside(&a) != inside(&b) {
                        let t = (plane - a[axis]) / (b[axis] - a[axis]);
                        let mut p = [0f32; 3];
                        for k in 0..3 {
                            p[k] = a[k] + t * (b[k] - a[k]);
                        }
                        p[axis] = plane; // exact on the plane despite rounding
                        next[n] = p;
                        n += 1;
                    }
                    if inside(&b) {
                        next[n] = b;
                        n += 1;
                    }
                    a = b;
                }
                if n == 0 {
                    return Aabb::EMPTY;
                }
                std::mem::swap(&mut poly, &mut next);
                len = n;
            }
        }
        // The interpolated corners are off the true edge by rounding, in either direction, and
        // two triangles sharing the edge round differently: the box is padded by a few ULPs so
        // that it is conservative (a triangle must be listed in every leaf its true part
        // touches, or a ray through the shared edge can miss it there; `tests/precision.rs`); the
        // pad follows the largest coordinate, as the error of the ray's position does,
        // then clamped back to the voxel.
        let b = poly[..len]
            .iter()
            .fold(Aabb::EMPTY, |b, &p| b.grow(Vec3::from(p)));
        let pad = 4.0 * f32::EPSILON * b.min.abs().max(b.max.abs()).max_element();
        Aabb::new(b.min - pad, b.max + pad).intersection(*voxel)
    }
}

/// Woop, Benthin & Wald (2013), algorithm of their figure 3 with both faces accepted.
/// The edge functions `U, V, W` of the sheared vertices decide inside/outside; one that is
/// exactly zero is recomputed in f64, where the products are exact, so two triangles
/// sharing an edge always see opposite signs (or zero) for it. Degenerate triangles have
/// `U + V + W == 0` and are never hit.
#[inline]
pub(super) fn watertight(
    corners: [Vec3; 3],
    ray: &Ray,
    k: [usize; 3],
    s: Vec3,
    tmax: f32,
) -> Option<(f32, f32, f32)> {
    let [kx, ky, kz] = k;
    let [a, b, c] = corners.map(|p| p - ray.org);
    let shear = |p: Vec3| (p[kx] - s.x * p[kz], p[ky] - s.y * p[kz]);
    let ((ax, ay), (bx, by), (cx, cy)) = (shear(a), shear(b), shear(c));
    let mut u = cx * by - cy * bx;
    let mut v = ax * cy - ay * cx;
    let mut w = bx * ay - by * ax;
    if u == 0.0 || v == 0.0 || w == 0.0 {
        let cross = |p: (f32, f32), q: (f32, f32)| {
            let (p, q) = (
                DVec2::new(p.0 as f64, p.1 as f64),
                DVec2::new(q.0 as f64, q.1 as f64),
            );
            (p.x * q.y - p.y * q.x) as f32
        };
        u = cross((cx, cy), (bx, by));
        v = cross((ax, ay), (cx, cy));
        w = cross((bx, by), (ax, ay));
    }
    if (u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0) {
        return None;
    }
    let det = u + v + w;
    if det == 0.0 || !det.is_finite() {
        return None;
    }
    let t_scaled = s.z * (u * a[kz] + v * b[kz] + w * c[kz]);
    let inv = 1.0 / det;
    let t = t_scaled * inv;
    // `u` weighs vertex 1 (`b`) and `v` vertex 2 (`c`), as Möller–Trumbore's.
    (t >= ray.tmin && t < tmax).then_some((t, v * inv, w * inv))
}
