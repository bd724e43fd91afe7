//! Analytic primitives: spheres, ellipsoids, axis-aligned boxes and planes. They stay
//! analytic (never tessellated): a sphere costs 16 bytes where a mesh of it costs kilobytes.

use super::{power_of_two_scale, unit, Aabb, Ray};
use glam::{Mat3, Vec3};

/// Nearest intersection in `[tmin, tmax)` of the ray `o + t d` (relative to the centre) with
/// the sphere of squared radius `r2`. The discriminant is taken from the distance of the
/// centre to the line, `r² - |o - (o·d/d·d) d|²` (Haines et al., "Precision improvements for
/// ray/sphere intersection", Ray Tracing Gems ch. 7), not from `b² - a c`, which cancels
/// catastrophically far from the sphere; the roots use Numerical Recipes' `q` form. That
/// distance still has an error of about ulp(|o|), too much in a thin ellipsoid's stretched
/// unit space: `line` lets the ellipsoid supply it ([`Line`]).
///
/// Directions need not be unit length, but the test squares them: `d·d` overflows for `|d|`
/// past about 1e19 and underflows below about 1e-19, and `d·d · r²` overflows sooner for a
/// large sphere (radius 1e5 at `|d|` = 1e15 "hit" at `t` = 0). Where either leaves the normal
/// range, or `o·d` overflows (an ellipsoid 1e-19 thin stretches both `o` and `d` by 1e19 in
/// its unit space: `d·d` stays normal, `o·d` does not, and such rays missed), the direction is
/// scaled by a power of two into [1, 2) for its largest component and the roots scaled back
/// (`scaled_sphere_roots`). Every step is homogeneous in `d` and a power of two scales
/// exactly, so the roots are those the unscaled direction gives wherever nothing over- or
/// underflows. Those rays keep the unscaled operations: scaling every ray made the
/// spheres1 render 15% slower (1 thread), the range check costs it about 5%. Inlined: called
/// across a function boundary, the origin went through memory and the render took 60% longer.
#[inline(always)]
fn sphere_root(o: Vec3, d: Vec3, line: Line, r2: f32, tmin: f32, tmax: f32) -> Option<f32> {
    let a = d.length_squared();
    let b = o.dot(d);
    let (t0, t1) = if a.is_normal() && (a * r2).is_normal() && b.is_finite() {
        sphere_roots(o, d, line, a, b, r2)?
    } else {
        scaled_sphere_roots(o, d, line, r2)?
    };
    [t0, t1].into_iter().find(|&t| t >= tmin && t < tmax)
}

/// Where [`sphere_roots`] takes the squared distance of the centre from the ray's line.
#[derive(Clone, Copy)]
enum Line {
    /// `|o - (o·d / d·d) d|²`, from the origin and direction themselves (spheres).
    Projected,
    /// Computed by the caller, which has a better conditioned way than `o` and `d` allow (an
    /// ellipsoid's unit space, [`Ellipsoid::line_distance2`]). Unchanged by scaling `d`.
    Distance2(f32),
}

/// [`sphere_roots`] for a direction far from unit length: solved for `d` scaled by a power of
/// two, roots scaled back.
#[cold]
fn scaled_sphere_roots(o: Vec3, d: Vec3, line: Line, r2: f32) -> Option<(f32, f32)> {
    let s = power_of_two_scale(d.abs().max_element())?;
    let d = d * s;
    let (t0, t1) = sphere_roots(o, d, line, d.length_squared(), o.dot(d), r2)?;
    Some((t0 * s, t1 * s))
}

/// Both roots of the ray `o + t d` with the sphere of squared radius `r2`, ascending (`a` is
/// `d·d`, `b` is `o·d`).
#[inline(always)]
fn sphere_roots(o: Vec3, d: Vec3, line: Line, a: f32, b: f32, r2: f32) -> Option<(f32, f32)> {
    if a == 0.0 {
        return None;
    }
    let l2 = match line {
        Line::Projected => (o - (b / a) * d).length_squared(),
        Line::Distance2(l2) => l2,
    };
    let disc = a * (r2 - l2);
    if disc < 0.0 {
        return None;
    }
    let c = o.length_squared() - r2;
    let q = -(b + b.signum() * disc.sqrt());
    let (t0, t1) = (q / a, if q != 0.0 { c / q } else { q / a });
    Some(if t0 > t1 { (t1, t0) } else { (t0, t1) })
}

#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct Sphere {
    pub center: [f32; 3],
    pub radius: f32,
}

impl Sphere {
    pub fn bounds(&self) -> Aabb {
        let c = Vec3::from(self.center);
        Aabb::new(c - self.radius, c + self.radius)
    }

    /// The sphere's box cut by the voxel, or empty when no point of the voxel lies in the
    /// sphere (the voxel's point nearest the centre is farther than the radius). Not the box of
    /// the sphere's part inside the voxel: a corner of this box may lie far from the surface.
    pub fn clipped_bounds(&self, voxel: &Aabb) -> Aabb {
        let b = self.bounds().intersection(*voxel);
        if b.is_empty() {
            return b;
        }
        let c = Vec3::from(self.center);
        // The closest voxel point must lie inside the sphere for any overlap.
        let closest = c.clamp(voxel.min, voxel.max);
        if (closest - c).length_squared() > self.radius * self.radius {
            return Aabb::EMPTY;
        }
        b
    }

    pub fn intersect(&self, ray: &Ray, tmax: f32) -> Option<f32> {
        let oc = ray.org - Vec3::from(self.center);
        let r2 = self.radius * self.radius;
        sphere_root(oc, ray.dir, Line::Projected, r2, ray.tmin, tmax)
    }

    pub fn normal(&self, p: Vec3) -> Vec3 {
        (p - Vec3::from(self.center)).normalize_or_zero()
    }
}

/// An ellipsoid as the image of the unit sphere under `x = center + M s`; stored as the
/// inverse map, which is what intersection and normals need, and with what the intersection
/// derives from that map alone (the scale `sigma` and the cofactors `cof` of
/// `Self::line_distance2`), computed once in [`Self::new`]: per ray they took a quarter of
/// the test's time (27.6 against 20.2 ns a test on random rays, one thread). 100 bytes (60
/// without them); the GPU reads the same layout.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct Ellipsoid {
    pub center: [f32; 3],
    /// Column-major `M⁻¹`.
    pub inv: [f32; 9],
    /// Half extents of the bounding box, derived from `M` when created.
    pub half: [f32; 3],
    /// `σ`, the power of two that brings the largest entry of `M⁻¹` into [1, 2), or into
    /// [2, 4) where that power would be subnormal (entries past 2^127, from a nearly singular
    /// map): 2^-126 rather than 2^-127, as GPUs may flush a subnormal divisor to zero.
    pub sigma: f32,
    /// Column-major cofactor matrix of `σ M⁻¹`: row `i` is the cross product of the other two
    /// rows of `σ M⁻¹`, in cyclic order.
    pub cof: [f32; 9],
}

impl Ellipsoid {
    /// `m` maps the unit sphere onto the ellipsoid (columns = semi-axes). `None` when it is
    /// singular or its inverse or bounds do not fit in `f32`.
    ///
    /// The inverse is taken of `m` with unit-length columns and scaled back: the determinant
    /// and cofactors of `m` itself overflow or underflow for semi-axes far from 1 (radii 1e13
    /// have determinant 1e39), although the ellipsoid and its inverse are representable. It is
    /// taken in f64: in f32 the products cancel when the columns are nearly parallel (a needle
    /// 1e-5 thick turned between two rotations had an inverse 5x too large and was missed).
    pub fn new(center: Vec3, m: Mat3) -> Option<Self> {
        let lengths = Vec3::new(m.x_axis.length(), m.y_axis.length(), m.z_axis.length());
        if !(lengths.min_element() > 0.0 && lengths.is_finite()) {
            return None;
        }
        let unit = (m * Mat3::from_diagonal(lengths.recip())).as_dmat3();
        // Finite: the columns are unit vectors (and f64 holds any product of their entries).
        if unit.determinant() == 0.0 {
            return None;
        }
        // M = U D, so M⁻¹ = D⁻¹ U⁻¹: row i of U⁻¹ divided by the length of column i.
        let inv = Mat3::from_diagonal(lengths.recip()) * unit.inverse().as_mat3();
        // Extent along axis i is the length of row i of M.
        let half = Vec3::new(m.row(0).length(), m.row(1).length(), m.row(2).length());
        if !(inv.is_finite() && half.is_finite() && center.is_finite()) {
            return None;
        }
        let largest = (inv.x_axis.abs().max(inv.y_axis.abs()))
            .max(inv.z_axis.abs())
            .max_element();
        let sigma = power_of_two_scale(largest)?.max(f32::MIN_POSITIVE);
        let a = inv * sigma;
        let [r0, r1, r2] = [a.row(0), a.row(1), a.row(2)];
        let cof = Mat3::from_cols(r1.cross(r2), r2.cross(r0), r0.cross(r1)).transpose();
        Some(Ellipsoid {
            center: center.to_array(),
            inv: inv.to_cols_array(),
            half: half.to_array(),
            sigma,
            cof: cof.to_cols_array(),
        })
    }

    pub fn bounds(&self) -> Aabb {
        let c = Vec3::from(self.center);
        let h = Vec3::from(self.half);
        Aabb::new(c - h, c + h)
    }

    /// The ray against the unit sphere in the ellipsoid's unit space (`M⁻¹ (x - center)`),
    /// except for the centre-to-line distance, which comes from `Self::line_distance2`.
    pub fn intersect(&self, ray: &Ray, tmax: f32) -> Option<f32> {
        let inv = Mat3::from_cols_array(&self.inv);
        let o = ray.org - Vec3::from(self.center);
        let d = inv * ray.dir;
        let line = Line::Distance2(self.line_distance2(o, ray.dir, d));
        sphere_root(inv * o, d, line, 1.0, ray.tmin, tmax)
    }

    /// Squared distance of the centre from the line `o + t d` (`o` relative to the centre) in
    /// unit space: `|o_u × d_u|² / |d_u|²` for `o_u = M⁻¹ o`, `d_u = M⁻¹ d` (`du`).
    ///
    /// Not `|o_u - (o_u·d_u / d_u·d_u) d_u|²`, as for spheres: unit space stretches a thin
    /// ellipsoid's short axis, so seen from a few units `o_u` is about distance / thickness
    /// long (5e8 for radii (1, 1e-8, 1)) and that difference cancels to an error of about
    /// ulp(5e8) = 32 against the radius 1: a third of the rays aimed inside the disc missed.
    /// Here the cross product is taken in world space, where it is well conditioned, and
    /// carried over by the cofactor matrix: `(A o) × (A d) = cof(A) (o × d)` for any `A`
    /// (`self.cof`, made in [`Self::new`]).
    ///
    /// Range: `A` is `σ M⁻¹` (`self.sigma`), and `o` is scaled by `1/σ`, which leaves the
    /// ratio unchanged: unscaled, the cofactors (products of two entries of `M⁻¹`) overflow
    /// for a needle (two radii of 1e-20: 1e40, every ray missed) and turn subnormal for radii
    /// near the largest accepted (about 1e19). The numerator and denominator are scaled by the
    /// largest component of `σ d_u` before they are squared, as in [`sphere_root`]. The
    /// direction is scaled by its own power of two first (a long one would overflow the cross
    /// product), which leaves the ratio unchanged too. A degenerate input gives infinity: no
    /// hit.
    ///
    /// The cross product is taken from the line's point nearest the centre, not from `o`:
    /// for a ray along a needle's axis `o` is nearly parallel to `d`, `o × d` cancels to its
    /// rounding in every direction, and the cofactors multiply the part along the axis by up
    /// to 1/thickness² (a needle 1e-5 thick was missed by a ray down its axis). The nearest
    /// point is orthogonal to `d`, so its cross product does not cancel.
    #[inline(always)]
    fn line_distance2(&self, o: Vec3, d: Vec3, du: Vec3) -> f32 {
        let Some(kd) = power_of_two_scale(d.abs().max_element()) else {
            return f32::INFINITY;
        };
        let sigma = self.sigma;
        let (o, d) = (o / sigma, d * kd);
        let nearest = o - d * (o.dot(d) / d.dot(d));
        // An origin near the end of f32's range overflows the dot product: `o` as it is.
        let o = if nearest.is_finite() { nearest } else { o };
        let w = Mat3::from_cols_array(&self.cof) * o.cross(d);
        let du = du * sigma * kd;
        let Some(k) = power_of_two_scale(du.abs().max_element()) else {
            return f32::INFINITY;
        };
        (w * k).length_squared() / (du * k).length_squared()
    }

    pub fn normal(&self, p: Vec3) -> Vec3 {
        let inv = Mat3::from_cols_array(&self.inv);
        quadric_normal(inv, inv * (p - Vec3::from(self.center)))
    }
}

/// The outward unit normal of the quadric `|M⁻¹ x| = 1` (`inv` = `M⁻¹`) at the point whose
/// unit-space position is `u` (`M⁻¹ x`): the gradient `M⁻ᵀ u`, normalised. `inv` is about
/// 1 / the semi-axis: below about 5e-20 the gradient's square overflows (normalize_or_zero
/// gave zero); `unit` divides by the largest component first. Elsewhere the plain
/// normalisation, bit for bit. Zero where the gradient is zero or not finite.
fn quadric_normal(inv: Mat3, u: Vec3) -> Vec3 {
    let g = inv.transpose() * u;
    if g.length_squared().is_normal() {
        return g.normalize_or_zero();
    }
    unit(g).unwrap_or(Vec3::ZERO)
}

/// The renderer's surface of a hit on the quadric `|M⁻¹ x| = 1` (`inv` = `M⁻¹`, `x` relative
/// to the centre; a sphere's is `I / r`), in f32: the point, relative to the centre, and the
/// outward unit normal, for the ray `oc + s d` (`oc`: its origin relative to the centre) hit
/// at `t` with window start `tmin`. `shade.wgsl`'s `resolve_quadric` is its twin, operation
/// for operation, so that GPU renders match the CPU's.
///
/// Why not the world point `org + t d`: it is rounded to the ULP of its coordinates, which
/// far from the origin is a large part of a small shape (seen from a few radii, a unit
/// sphere's normal was 0.02 rad off on average at 1e6 from the origin, a rotated ellipsoid's
/// up to 0.8 rad; re-solved, both stay within about 1e-5 rad of f64). Relative to
/// the centre, `q = oc + t d` carries only the rounding of `oc` (exact where the ray starts
/// near the shape: `org - c` of two nearby floats is exact) and of the sum, both small
/// against the shape when the viewer is near it. The rounding of `t` lies along the ray, so
/// the ray is re-solved from `q` (in unit space, `M⁻¹ q` about 1 long: well conditioned;
/// `M⁻¹ d` scaled by a power of two) and the root nearest `q` taken. As `f64`'s
/// `quadric_surface` in `primitives.rs` (whose doc gives the cases): where the chord is
/// within the rounding of `t` (a shape thinner than that), the entry if the ray starts
/// outside, else the exit; where rounding puts the line just past the rim (a grazing ray),
/// its point nearest the centre in unit space. The normal is the gradient at that point,
/// taken in unit space (`M⁻¹ q + s M⁻¹ d`), not from the rounded point. `None` where the
/// direction is zero or a result is not finite (the caller then keeps `org + t d`).
pub fn resolve_quadric(inv: Mat3, oc: Vec3, d: Vec3, t: f32, tmin: f32) -> Option<(Vec3, Vec3)> {
    let q = oc + t * d;
    let (u, du) = (inv * q, inv * d);
    let k = power_of_two_scale(du.abs().max_element())?;
    let dk = du * k;
    let a = dk.length_squared();
    let roots = sphere_roots(u, dk, Line::Projected, a, u.dot(dk), 1.0);
    let roots = roots.map(|(s0, s1)| (s0 * k, s1 * k));
    let s = match roots {
        Some((s0, s1)) if s1 - s0 <= 4.0 * t.abs() * f32::EPSILON => {
            let start = (inv * (oc + tmin * d)).length_squared();
            let entering = !tmin.is_finite() || start > 1.0 || start.is_nan();
            if entering {
                s0
            } else {
                s1
            }
        }
        Some((s0, s1)) if s1.abs() < s0.abs() => s1,
        Some((s0, _)) => s0,
        None => -(u.dot(dk) / a) * k,
    };
    let point = q + s * d;
    let normal = quadric_normal(inv, u + s * du);
    (point.is_finite() && normal != Vec3::ZERO).then_some((point, normal))
}

/// Solid axis-aligned box; a ray starting inside hits its exit face.
pub fn box_intersect(b: &Aabb, ray: &Ray, tmax: f32) -> Option<f32> {
    let inv = ray.dir.recip();
    let (t0, t1) = b.clip_ray(ray.org, inv, f32::NEG_INFINITY, f32::INFINITY)?;
    [t0, t1].into_iter().find(|&t| t >= ray.tmin && t < tmax)
}

/// The box face nearest to `p`: its axis, and whether it is the `max` face. Nearest by
/// distance, not by distance relative to the box's size: a point on a face is nearer to it
/// than to any other face up to the rounding of its coordinates, even on a box of zero
/// thickness (the faces of the flat axis then tie at distance 0, and `max` is taken).
fn box_face(b: &Aabb, p: Vec3) -> (usize, bool) {
    let (below, above) = (p - b.min, b.max - p);
    let gap = below.min(above);
    let axis = if gap.x <= gap.y && gap.x <= gap.z {
        0
    } else if gap.y <= gap.z {
        1
    } else {
        2
    };
    (axis, above[axis] <= below[axis])
}

/// Outward normal of the box face nearest to `p`.
pub fn box_normal(b: &Aabb, p: Vec3) -> Vec3 {
    let (axis, max) = box_face(b, p);
    let mut n = Vec3::ZERO;
    n[axis] = if max { 1.0 } else { -1.0 };
    n
}

/// `p`, a point near the box's surface, moved onto the face nearest to it.
pub fn box_on_surface(b: &Aabb, p: Vec3) -> Vec3 {
    let (axis, max) = box_face(b, p);
    let mut q = p.clamp(b.min, b.max);
    q[axis] = if max { b.max[axis] } else { b.min[axis] };
    q
}

/// The infinite plane `normal · x = offset`. Unbounded, so it lives outside the kd-tree and
/// every ray tests it directly (one test per ray; a tree cannot bound it anyway).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct Plane {
    pub normal: [f32; 3],
    pub offset: f32,
}

impl Plane {
    pub fn intersect(&self, ray: &Ray, tmax: f32) -> Option<f32> {
        let n = Vec3::from(self.normal);
        let denom = n.dot(ray.dir);
        if denom == 0.0 {
            return None;
        }
        let t = (self.offset - n.dot(ray.org)) / denom;
        (t >= ray.tmin && t < tmax).then_some(t)
    }

    /// `p`, a point near the plane, projected onto it (the normal is unit length). A point
    /// beyond the f32 range (a grazing hit so far away that `org + t dir` overflows) is kept
    /// as it is: projecting its infinite coordinates would make them NaN.
    pub fn on_surface(&self, p: Vec3) -> Vec3 {
        if !p.is_finite() {
            return p;
        }
        let n = Vec3::from(self.normal);
        p - (n.dot(p) - self.offset) * n
    }
}
