//! Triangles, stored as `v0` and two edges so that Möller–Trumbore needs no subtraction
//! of vertices per test (the precomputation of the vectorised-traversal paper), and the two
//! ray–triangle tests of [`crate::precision::Intersector`].

use super::{Aabb, Clipped, Ray};
use crate::precision::Intersector;
use glam::Vec3;

/// The per-ray part of a triangle test, computed once per ray (Woop et al.'s shear: the
/// dominant axis `kz` of the direction, the two others in an order that keeps the winding,
/// and the shear constants `Sx, Sy, Sz`).
#[derive(Clone, Copy, Debug)]
pub enum TriangleTest {
    MollerTrumbore,
    Watertight { k: [u32; 3], s: [f32; 3] },
}

impl TriangleTest {
    pub fn new(ray: &Ray, intersector: Intersector) -> Self {
        match intersector {
            Intersector::MollerTrumbore => TriangleTest::MollerTrumbore,
            Intersector::Watertight => {
                let (k, s) = shear_axes(ray.dir.to_array());
                TriangleTest::Watertight { k, s }
            }
        }
    }

    /// The intersector this is the per-ray part of.
    pub fn intersector(&self) -> Intersector {
        match self {
            TriangleTest::MollerTrumbore => Intersector::MollerTrumbore,
            TriangleTest::Watertight { .. } => Intersector::Watertight,
        }
    }
}

/// Woop et al.'s per-ray setup for direction `d`: the axes `[kx, ky, kz]` and the shear
/// constants. Written with selects rather than indexing, so that a loop over lanes (N rays
/// at once, `cpu::simd::RayLanes`) vectorises; `kz` is the first axis of largest `|d|`.
#[inline(always)]
pub(crate) fn shear_axes(d: [f32; 3]) -> ([u32; 3], [f32; 3]) {
    // No `array::map` here or below: its closure is not always inlined, and these run inside
    // the SIMD kernels, where a call is compiled without their target features.
    let a = [d[0].abs(), d[1].abs(), d[2].abs()];
    let (m, i) = if a[1] > a[0] { (a[1], 1) } else { (a[0], 0) };
    let kz = if a[2] > m { 2 } else { i };
    let (kx, ky) = ((kz + 1) % 3, (kz + 2) % 3);
    let dz = pick(d, kz);
    let (kx, ky) = if dz < 0.0 { (ky, kx) } else { (kx, ky) };
    let s = [pick(d, kx) / dz, pick(d, ky) / dz, 1.0 / dz];
    ([kx, ky, kz], s)
}

/// `p[k]` as selects (see [`shear_axes`]).
#[inline(always)]
pub(crate) fn pick(p: [f32; 3], k: u32) -> f32 {
    if k == 0 {
        p[0]
    } else if k == 1 {
        p[1]
    } else {
        p[2]
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

    /// The unit normal along `e1 × e2`, or zero. The length squares the cross product, which
    /// underflows for edges below about 1e-10 and overflows above about 1e10: triangles 1e-12
    /// and 1e11 across were hit but had zero normals. And the f32 cross product of the edges
    /// of a sliver (its largest angle near a straight one, `sin θ` from it) cancels: each
    /// component is off by about 2^-23 of `|e1| |e2|`, the direction by about `2^-23 / sin θ`
    /// (0.02 rad at `sin θ` = 2e-6, which the tree still holds: it drops them below 2^-21).
    /// There the cross product is taken in f64, where the products of f32 values are exact
    /// and none under- or overflows; elsewhere (`sin² θ` above 2^-12: the direction within
    /// about 1e-5) the plain normalisation, bit for bit.
    pub fn unit_normal(&self) -> Vec3 {
        let n = self.normal();
        let l2 = n.length_squared();
        let (e1, e2) = (
            Vec3::from(self.e1).as_dvec3(),
            Vec3::from(self.e2).as_dvec3(),
        );
        let (a2, b2) = (e1.length_squared(), e2.length_squared());
        if l2.is_normal() && l2 as f64 >= (-12f64).exp2() * a2 * b2 {
            return n.normalize_or_zero();
        }
        let m = e1.cross(e2);
        let len = m.length();
        if !(len > 0.0 && len.is_finite()) {
            return Vec3::ZERO;
        }
        (m / len).as_vec3()
    }

    /// Whether the triangle has no area up to rounding: its largest angle within 2^-21 of a
    /// straight one, i.e. `|e1 × e2|` (twice its area, taken in f64, where the products of
    /// f32 values are exact) at most 2^-21 times the product of its two shortest sides. Its
    /// corners then lie on one line but for rounding, as a corner computed as the midpoint of
    /// the two others (triangle strips, T-junction repairs) leaves them, and both tests divide
    /// by an area that is all rounding: Möller–Trumbore "hit" such a triangle 68 units away
    /// from it (it was 1 unit long), and both intersectors answered rays aimed at a quad's
    /// diagonal with the zero-area triangle lying on it, up to a third of the way in front of
    /// the quad. The tree leaves them out ([`super::PrimitiveSet::bounds`]), so no method hits
    /// them. The largest angle, not the one at `v0`: a needle, whose angle at its tip is tiny
    /// but whose area is real, is a part of a closed mesh (a needle listed tip first was left
    /// out, and rays leaked through the gap).
    pub fn is_degenerate(&self) -> bool {
        let (e1, e2) = (
            Vec3::from(self.e1).as_dvec3(),
            Vec3::from(self.e2).as_dvec3(),
        );
        let mut sides = [e1.length(), e2.length(), (e2 - e1).length()];
        sides.sort_by(f64::total_cmp);
        e1.cross(e2).length() <= (-21f64).exp2() * sides[0] * sides[1]
    }

    /// The test `how` asks for, on this triangle's corners as stored (`v0`, `v0 + e1`,
    /// `v0 + e2`). Returns `(t, u, v)` with `tmin <= t < tmax`. A scene's watertight test reads
    /// the exact corners its mesh gave instead, which the edge form does not always give back
    /// bit for bit (`PrimitiveSet::intersect`); Möller–Trumbore reads the edges either way.
    #[inline]
    pub fn intersect(&self, ray: &Ray, how: &TriangleTest, tmax: f32) -> Option<(f32, f32, f32)> {
        match how {
            TriangleTest::MollerTrumbore => self.moller_trumbore(ray, tmax),
            TriangleTest::Watertight { k, s } => {
                watertight(self.vertices().map(|v| v.to_array()), ray, *k, *s, tmax)
            }
        }
    }

    /// Möller–Trumbore (1997). Exactly degenerate triangles have `det == 0` here and are never
    /// hit; the tree leaves out those of no area up to rounding ([`Self::is_degenerate`]),
    /// whose `det` is noise.
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
        // Written so that a NaN `v` (an overflowing `dir · q`, from components near f32::MAX)
        // is a miss, as a NaN `u` is above.
        if !(v >= 0.0 && u + v <= 1.0) {
            return None;
        }
        let t = e2.dot(q) * inv;
        (t >= ray.tmin && t < tmax).then_some((t, u, v))
    }

    /// Bounds of the part of the triangle inside `voxel` (Sutherland–Hodgman clipping against
    /// the six slabs): the "perfect splits" of Havran's thesis used by the SAH builder.
    pub fn clipped_bounds(&self, voxel: &Aabb) -> Clipped {
        let bounds = self.bounds();
        if !bounds.overlaps(voxel) {
            return Clipped::exact(Aabb::EMPTY);
        }
        if voxel.contains_point(bounds.min) && voxel.contains_point(bounds.max) {
            return Clipped::exact(bounds);
        }
        // A triangle cut by six planes has at most 9 corners: fixed arrays, no allocation
        // (the SAH builder clips every straddling triangle at every level). Corners are plain
        // arrays so that the axis indexes them directly; `exact` has bit `k` set where
        // coordinate `k` of the corner is the true one (see the padding below).
        let mut poly = [[0f32; 3]; 9];
        let mut next = [[0f32; 3]; 9];
        let mut exact = [0u8; 9];
        let mut next_exact = [0u8; 9];
        for (corner, v) in poly.iter_mut().zip(self.vertices()) {
            *corner = v.to_array();
        }
        exact[..3].fill(0b111);
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
                let (mut a, mut a_exact) = (poly[len - 1], exact[len - 1]);
                for (&b, &b_exact) in poly[..len].iter().zip(&exact[..len]) {
                    if inside(&a) != inside(&b) {
                        let t = (plane - a[axis]) / (b[axis] - a[axis]);
                        let mut p = [0f32; 3];
                        // A coordinate the edge keeps constant comes out exactly (`t * 0`).
                        let mut p_exact = 1 << axis;
                        for k in 0..3 {
                            p[k] = a[k] + t * (b[k] - a[k]);
                            if a[k] == b[k] {
                                p_exact |= a_exact & b_exact & (1 << k);
                            }
                        }
                        p[axis] = plane; // exact on the plane despite rounding
                        next[n] = p;
                        next_exact[n] = p_exact;
                        n += 1;
                    }
                    if inside(&b) {
                        next[n] = b;
                        next_exact[n] = b_exact;
                        n += 1;
                    }
                    (a, a_exact) = (b, b_exact);
                }
                if n == 0 {
                    return Clipped::exact(Aabb::EMPTY);
                }
                std::mem::swap(&mut poly, &mut next);
                std::mem::swap(&mut exact, &mut next_exact);
                len = n;
            }
        }
        // The interpolated corners are off the true edge by rounding, in either direction, and
        // two triangles sharing the edge round differently: their coordinates are padded by a
        // few ULPs so that the box is conservative (a triangle must be listed in every leaf its
        // true part touches, or a ray through the shared edge can miss it there;
        // `tests/precision.rs`); the pad follows the largest coordinate, as the error of the
        // ray's position does. The box is then clamped back to the voxel.
        //
        // A padded face lies where no geometry is, a few ULPs off it: it must not become a
        // split plane. The SAH would cut off a slab that thin holding only the geometry next
        // to it, and a ray from ten times the scene's size away, whose split distances cannot
        // tell the slab's two faces apart, skips it (`tests/traversals.rs`: 79% of the rays
        // aimed at a floor from 100 units away missed it). So exact coordinates (a vertex's,
        // the cutting plane's, one an edge keeps constant) are not padded, and the faces
        // that are padded are marked (`Clipped::padded`) for the builder.
        let corners = &poly[..len];
        let magnitude = corners.iter().flatten().fold(0.0f32, |m, c| m.max(c.abs()));
        let pad = 4.0 * f32::EPSILON * magnitude;
        let (mut padded_box, mut plain) = (Aabb::EMPTY, Aabb::EMPTY);
        for (c, &e) in corners.iter().zip(&exact[..len]) {
            let err =
                Vec3::from_array([0, 1, 2].map(|k| if e & (1 << k) != 0 { 0.0 } else { pad }));
            let c = Vec3::from(*c);
            padded_box = padded_box.grow(c - err).grow(c + err);
            plain = plain.grow(c);
        }
        let mut padded = 0;
        for k in 0..3 {
            padded |= u8::from(padded_box.min[k] < plain.min[k]) << (2 * k);
            padded |= u8::from(padded_box.max[k] > plain.max[k]) << (2 * k + 1);
        }
        Clipped {
            bounds: padded_box.intersection(*voxel),
            padded,
        }
    }
}

/// Woop, Benthin & Wald (2013), algorithm of their figure 3 with both faces accepted.
/// The edge functions `U, V, W` of the sheared vertices decide inside/outside; one that is
/// exactly zero is recomputed in f64, where the products are exact, so two triangles
/// sharing an edge always see opposite signs (or zero) for it. Exactly degenerate triangles
/// have `U + V + W == 0` and are never hit; the tree leaves out those of no area up to
/// rounding ([`Triangle::is_degenerate`]).
#[inline]
pub(crate) fn watertight(
    corners: [[f32; 3]; 3],
    ray: &Ray,
    k: [u32; 3],
    s: [f32; 3],
    tmax: f32,
) -> Option<(f32, f32, f32)> {
    let sheared = Sheared::new(corners, ray.org.to_array(), k, s);
    let mut uvw = sheared.edges();
    if uvw.contains(&0.0) {
        uvw = sheared.edges_exact();
    }
    let (t, u, v) = sheared.hit(uvw, s[2], ray.tmin, tmax);
    (t < f32::INFINITY).then_some((t, u, v))
}

/// [`watertight`] with the f32 edge functions only, for one SIMD lane: `(t, u, v)` with
/// `t = inf` for a miss, and whether an edge function is exactly zero, in which case the
/// answer is not final: the lane must take [`watertight`], which redoes it in f64. The
/// operations are [`watertight`]'s, in the same order, so the lanes' answers are its bits.
#[inline(always)]
pub(crate) fn watertight_f32(
    corners: [[f32; 3]; 3],
    org: [f32; 3],
    k: [u32; 3],
    s: [f32; 3],
    tmin: f32,
    tmax: f32,
) -> (f32, f32, f32, bool) {
    let sheared = Sheared::new(corners, org, k, s);
    let uvw = sheared.edges();
    let (t, u, v) = sheared.hit(uvw, s[2], tmin, tmax);
    (t, u, v, uvw[0] == 0.0 || uvw[1] == 0.0 || uvw[2] == 0.0)
}

/// The corners `a, b, c` relative to the ray's origin in the ray's sheared frame: `x`, `y`
/// across the ray (sheared), `z` along its dominant axis (not yet scaled by `Sz`).
struct Sheared {
    x: [f32; 3],
    y: [f32; 3],
    z: [f32; 3],
}

impl Sheared {
    #[inline(always)]
    fn new(corners: [[f32; 3]; 3], org: [f32; 3], k: [u32; 3], s: [f32; 3]) -> Self {
        let rel = |i: usize| {
            let c = corners[i];
            [c[0] - org[0], c[1] - org[1], c[2] - org[2]]
        };
        let (a, b, c) = (rel(0), rel(1), rel(2));
        let z = [pick(a, k[2]), pick(b, k[2]), pick(c, k[2])];
        let across = |p: [f32; 3], i: usize, axis: usize| pick(p, k[axis]) - s[axis] * z[i];
        Sheared {
            x: [across(a, 0, 0), across(b, 1, 0), across(c, 2, 0)],
            y: [across(a, 0, 1), across(b, 1, 1), across(c, 2, 1)],
            z,
        }
    }

    /// The edge functions `U, V, W` in f32.
    #[inline(always)]
    fn edges(&self) -> [f32; 3] {
        let ([ax, bx, cx], [ay, by, cy]) = (self.x, self.y);
        [cx * by - cy * bx, ax * cy - ay * cx, bx * ay - by * ax]
    }

    /// The edge functions in f64, where the products of f32 values are exact.
    fn edges_exact(&self) -> [f32; 3] {
        let ([ax, bx, cx], [ay, by, cy]) = (self.x, self.y);
        let [ax, bx, cx, ay, by, cy] = [ax, bx, cx, ay, by, cy].map(f64::from);
        [
            (cx * by - cy * bx) as f32,
            (ax * cy - ay * cx) as f32,
            (bx * ay - by * ax) as f32,
        ]
    }

    /// The rest of the test from the edge functions `uvw`, without branches: `(t, u, v)` with
    /// `t = inf` unless the ray crosses the triangle in `[tmin, tmax)`.
    #[inline(always)]
    fn hit(&self, [u, v, w]: [f32; 3], sz: f32, tmin: f32, tmax: f32) -> (f32, f32, f32) {
        let outside = (u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0);
        let det = u + v + w;
        let [az, bz, cz] = self.z;
        let t_scaled = sz * (u * az + v * bz + w * cz);
        let inv = 1.0 / det;
        let t = t_scaled * inv;
        let ok = !outside & (det != 0.0) & det.is_finite() & (t >= tmin) & (t < tmax);
        // `u` weighs vertex 1 (`b`) and `v` vertex 2 (`c`), as Möller–Trumbore's.
        (if ok { t } else { f32::INFINITY }, v * inv, w * inv)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A ray from near `f32::MAX` (a C-API probe's, its direction scaled by 2^-127 into
    /// [1, 2) as a query scales it) whose `dir · q` overflows to `inf - inf`: the NaN `v`
    /// passed the rejection `v < 0 || u + v > 1` (false for NaN) as a hit. A miss now, or at
    /// least no hit with a non-finite `t`, `u` or `v`.
    #[test]
    fn an_overflowing_v_is_never_a_hit() {
        let tri = Triangle::from_vertices(
            Vec3::new(0.9241147, 0.030079365, -0.27529728),
            Vec3::new(0.19805574, -0.98177326, 0.7719383),
            Vec3::new(0.78650093, -1.3763561, 1.047344),
        );
        let big = f32::from_bits(0x7f61_b1e6);
        let dir = Vec3::new(-f32::from_bits(0x3f8d_8e30), big, -big) * f32::from_bits(0x0040_0000);
        let ray = Ray::new(Vec3::new(-0.0, -big, big), dir, 0.0, f32::INFINITY);
        let hit = tri.intersect(&ray, &TriangleTest::MollerTrumbore, f32::INFINITY);
        assert!(
            hit.is_none_or(|(t, u, v)| [t, u, v].iter().all(|x| x.is_finite())),
            "{hit:?}"
        );
    }

    /// One triangle at scales from 1e-30 to 1e18: the unit normal of the triangle at unit
    /// scale, (2, 3, 6) / 7 for this one, whatever the scale; at unit scale the plain
    /// normalisation's bits.
    #[test]
    fn unit_normals_at_any_scale() {
        let (a, b, c) = (
            Vec3::ZERO,
            Vec3::new(3.0, 0.0, -1.0),
            Vec3::new(0.0, 2.0, -1.0),
        );
        let want = Vec3::new(2.0, 3.0, 6.0) / 7.0;
        let wrong: Vec<_> = [1e-30f32, 1e-12, 1e-6, 1.0, 1e11, 1e18]
            .into_iter()
            .map(|s| {
                (
                    s,
                    Triangle::from_vertices(a * s, b * s, c * s).unit_normal(),
                )
            })
            .filter(|(_, n)| (*n - want).length() >= 1e-6)
            .collect();
        assert!(wrong.is_empty(), "(scale, normal): {wrong:?}");
        let t = Triangle::from_vertices(a, b, c);
        assert_eq!(t.unit_normal(), t.normal().normalize_or_zero());
    }
}
