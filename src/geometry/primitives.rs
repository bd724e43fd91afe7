//! All bounded primitives of a committed scene, kind by kind in flat arrays (a sphere costs
//! 16 bytes, a triangle 36), addressed by one global index: triangles first, then spheres,
//! ellipsoids and boxes. Leaves of the kd-tree list these indices. Planes are unbounded and
//! kept apart (see [`Plane`]).

use super::triangle::watertight;
use super::{
    box_intersect, box_normal, box_on_surface, resolve_quadric, Aabb, Clipped, Ellipsoid, Hit,
    Plane, PrimIndex, Ray, Sphere, Triangle, TriangleTest,
};
use crate::precision::Intersector;
use glam::{DMat3, DVec3, Mat3, Vec3};

/// What the intersection core needs per ray besides the ray itself, prepared once per ray:
/// the triangle test with its per-ray set-up, and the primitive to ignore (the one a
/// secondary ray leaves, for `OffsetMode::ExcludePrim`; `INVALID` for none).
#[derive(Clone, Copy, Debug)]
pub struct RayTest {
    pub triangle: TriangleTest,
    pub exclude: PrimIndex,
}

impl RayTest {
    pub fn new(ray: &Ray, intersector: Intersector, exclude: PrimIndex) -> Self {
        RayTest {
            triangle: TriangleTest::new(ray, intersector),
            exclude,
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PrimKind {
    Triangle,
    Sphere,
    Ellipsoid,
    Box,
}

#[derive(Clone, Debug, Default)]
pub struct PrimitiveSet {
    pub triangles: Vec<Triangle>,
    pub spheres: Vec<Sphere>,
    pub ellipsoids: Vec<Ellipsoid>,
    pub boxes: Vec<Aabb>,
    /// Exact corners of each triangle, only when the watertight test is asked for
    /// (`Scene::ensure_exact_vertices`); empty otherwise, and the test then rebuilds them as
    /// `v0 + e1`, which is not bit-exact at shared vertices.
    pub vertices: Vec<[[f32; 3]; 3]>,
    /// Unbounded primitives, tested by every ray outside the tree. Their global index
    /// continues after the bounded ones.
    pub planes: Vec<Plane>,
}

impl PrimitiveSet {
    /// Number of bounded primitives (the ones the kd-tree holds).
    pub fn len(&self) -> usize {
        self.triangles.len() + self.spheres.len() + self.ellipsoids.len() + self.boxes.len()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0 && self.planes.is_empty()
    }

    /// Kind of a global index and the index inside that kind's array.
    #[inline]
    pub fn locate(&self, i: usize) -> (PrimKind, usize) {
        let mut i = i;
        for (kind, n) in [
            (PrimKind::Triangle, self.triangles.len()),
            (PrimKind::Sphere, self.spheres.len()),
            (PrimKind::Ellipsoid, self.ellipsoids.len()),
        ] {
            if i < n {
                return (kind, i);
            }
            i -= n;
        }
        (PrimKind::Box, i)
    }

    /// Bounds of primitive `i`, which the tree holds it by: empty for a triangle of no area
    /// ([`Triangle::is_degenerate`]), which is then left out of the tree and never hit.
    pub fn bounds(&self, i: usize) -> Aabb {
        match self.locate(i) {
            (PrimKind::Triangle, k) if self.triangles[k].is_degenerate() => Aabb::EMPTY,
            (PrimKind::Triangle, k) => self.triangles[k].bounds(),
            (PrimKind::Sphere, k) => self.spheres[k].bounds(),
            (PrimKind::Ellipsoid, k) => self.ellipsoids[k].bounds(),
            (PrimKind::Box, k) => self.boxes[k],
        }
    }

    /// Bounds of the part of primitive `i` inside `voxel` (perfect splits). Ellipsoids and
    /// boxes use their box clipped to the voxel, which is exact for boxes and tight enough for
    /// ellipsoids; only a clipped triangle's faces may be padded.
    pub fn clipped_bounds(&self, i: usize, voxel: &Aabb) -> Clipped {
        match self.locate(i) {
            (PrimKind::Triangle, k) => self.triangles[k].clipped_bounds(voxel),
            (PrimKind::Sphere, k) => Clipped::exact(self.spheres[k].clipped_bounds(voxel)),
            _ => Clipped::exact(self.bounds(i).intersection(*voxel)),
        }
    }

    /// Bounds of all bounded primitives.
    pub fn scene_bounds(&self) -> Aabb {
        (0..self.len()).fold(Aabb::EMPTY, |b, i| b.union(self.bounds(i)))
    }

    /// Tests bounded primitive `i` and keeps the hit if it is the closest so far: the one
    /// intersection core of every traversal.
    #[inline]
    pub fn intersect(&self, i: u32, ray: &Ray, test: &RayTest, hit: &mut Hit) -> bool {
        if i == test.exclude {
            return false;
        }
        let tmax = hit.bound(ray);
        let found = match self.locate(i as usize) {
            (PrimKind::Triangle, k) => match test.triangle {
                TriangleTest::Watertight { k: axes, s } => watertight(
                    self.triangle_rows(k, Intersector::Watertight),
                    ray,
                    axes,
                    s,
                    tmax,
                ),
                TriangleTest::MollerTrumbore => {
                    self.triangles[k].intersect(ray, &test.triangle, tmax)
                }
            },
            (PrimKind::Sphere, k) => self.spheres[k].intersect(ray, tmax).map(|t| (t, 0.0, 0.0)),
            (PrimKind::Ellipsoid, k) => self.ellipsoids[k]
                .intersect(ray, tmax)
                .map(|t| (t, 0.0, 0.0)),
            (PrimKind::Box, k) => box_intersect(&self.boxes[k], ray, tmax).map(|t| (t, 0.0, 0.0)),
        };
        match found {
            Some((t, u, v)) => hit.offer(t, u, v, i),
            None => false,
        }
    }

    /// What `intersector`'s test reads of triangle `k`, as three rows: Möller–Trumbore's
    /// `v0, e1, e2`, or the watertight test's corners (the exact ones when kept, rebuilt as
    /// `v0 + e1`, `v0 + e2` otherwise).
    #[inline(always)]
    pub fn triangle_rows(&self, k: usize, intersector: Intersector) -> [[f32; 3]; 3] {
        let [a, b, c] = *self.stored_rows(k, intersector);
        if self.rebuilds_corners(intersector) {
            let add = |p: [f32; 3], e: [f32; 3]| [p[0] + e[0], p[1] + e[1], p[2] + e[2]];
            [a, add(a, b), add(a, c)]
        } else {
            [a, b, c]
        }
    }

    /// The rows [`Self::triangle_rows`] starts from, as stored: the exact corners, or the
    /// triangle's `v0, e1, e2` (a reference, so that SIMD blocks gather them lane by lane).
    #[inline(always)]
    pub fn stored_rows(&self, k: usize, intersector: Intersector) -> &[[f32; 3]; 3] {
        if intersector == Intersector::Watertight && !self.rebuilds_corners(intersector) {
            &self.vertices[k]
        } else {
            bytemuck::cast_ref(&self.triangles[k])
        }
    }

    /// Whether [`Self::triangle_rows`] rebuilds the corners from the stored rows (`v0 + e1`,
    /// `v0 + e2`): the watertight test without exact corners for every triangle (all or none,
    /// so that a SIMD block of triangles reads one kind of row).
    #[inline(always)]
    pub fn rebuilds_corners(&self, intersector: Intersector) -> bool {
        intersector == Intersector::Watertight && self.vertices.len() != self.triangles.len()
    }

    /// Tests every plane (they are outside the tree); plane `k` has global index `len() + k`.
    pub fn intersect_planes(&self, ray: &Ray, test: &RayTest, hit: &mut Hit) {
        let base = self.len() as u32;
        for (k, p) in self.planes.iter().enumerate() {
            if base + k as u32 == test.exclude {
                continue;
            }
            if let Some(t) = p.intersect(ray, hit.bound(ray)) {
                hit.offer(t, 0.0, 0.0, base + k as u32);
            }
        }
    }

    /// Geometric normal (not oriented towards the ray) at hit point `p` of primitive `i`.
    pub fn normal(&self, i: u32, p: Vec3) -> Vec3 {
        let i = i as usize;
        if i >= self.len() {
            return Vec3::from(self.planes[i - self.len()].normal).normalize_or_zero();
        }
        match self.locate(i) {
            (PrimKind::Triangle, k) => self.triangles[k].unit_normal(),
            (PrimKind::Sphere, k) => self.spheres[k].normal(p),
            (PrimKind::Ellipsoid, k) => self.ellipsoids[k].normal(p),
            (PrimKind::Box, k) => box_normal(&self.boxes[k], p),
        }
    }

    /// Whether primitive `i` is flat (a triangle or a plane): a ray leaving it cannot hit it
    /// again, on either side.
    pub fn is_flat(&self, i: u32) -> bool {
        let i = i as usize;
        i >= self.len() || self.locate(i).0 == PrimKind::Triangle
    }

    /// The surface of `hit` the renderer shades (`Tracer::surface`; `shade.wgsl`'s
    /// `shading_surface` is its twin): the point, and the geometric normal (not oriented
    /// towards the ray), both in f32. The point is `org + t·dir` where `on_surface` is false
    /// (the fixed-epsilon offset, whose renders keep it), else recomputed on the surface for
    /// the robust offset, as `org + t·dir` carries the error of `t` times the ray's length,
    /// which from far away exceeds the offset: from the barycentrics for triangles (exact up
    /// to one rounding per coordinate), projected onto a plane, snapped onto a box's face. A
    /// sphere's or ellipsoid's point and normal are re-solved relative to its centre
    /// ([`resolve_quadric`]) whatever `on_surface` says: from the rounded world point the
    /// normal of a unit sphere 1e6 from the origin was 0.02 rad off on average (0.05 at worst)
    /// and of a rotated ellipsoid up to 0.8 rad (`tests/render_reference.rs` measures both).
    pub fn shading_surface(&self, hit: &Hit, ray: &Ray, on_surface: bool) -> (Vec3, Vec3) {
        let p = ray.at(hit.t);
        if let Some((q, n)) = self.quadric_surface_f32(hit, ray) {
            return (if on_surface { q } else { p }, n);
        }
        let p = if on_surface {
            self.flat_point(hit, p)
        } else {
            p
        };
        (p, self.normal(hit.prim, p))
    }

    /// [`resolve_quadric`] for a sphere or ellipsoid, in world space; `None` for other kinds.
    fn quadric_surface_f32(&self, hit: &Hit, ray: &Ray) -> Option<(Vec3, Vec3)> {
        let i = hit.prim as usize;
        let (inv, center) = match (i < self.len()).then(|| self.locate(i))? {
            (PrimKind::Sphere, k) => {
                let s = &self.spheres[k];
                (Mat3::from_diagonal(Vec3::splat(1.0 / s.radius)), s.center)
            }
            (PrimKind::Ellipsoid, k) => {
                let e = &self.ellipsoids[k];
                (Mat3::from_cols_array(&e.inv), e.center)
            }
            _ => return None,
        };
        let c = Vec3::from(center);
        let (q, n) = resolve_quadric(inv, ray.org - c, ray.dir, hit.t, ray.tmin)?;
        let p = c + q;
        p.is_finite().then_some((p, n))
    }

    /// `p` (`org + t·dir` of `hit`) recomputed on the surface of a triangle, plane or box
    /// ([`Self::shading_surface`]); kept for a sphere or ellipsoid whose re-solve failed.
    fn flat_point(&self, hit: &Hit, p: Vec3) -> Vec3 {
        let i = hit.prim as usize;
        if i >= self.len() {
            return self.planes[i - self.len()].on_surface(p);
        }
        match self.locate(i) {
            (PrimKind::Triangle, k) => {
                let t = &self.triangles[k];
                Vec3::from(t.v0) + hit.u * Vec3::from(t.e1) + hit.v * Vec3::from(t.e2)
            }
            (PrimKind::Box, k) => box_on_surface(&self.boxes[k], p),
            _ => p,
        }
    }

    /// The surface of one hit for `Committed::hit_surface`: [`Self::shading_surface`] on the
    /// surface, but a sphere's or ellipsoid's point is recomputed in f64 relative to its
    /// centre (`quadric_surface`): in f32, even relative to the centre, the normals of
    /// shapes 1e-5 across seen from 3 units were 0.05 rad off. A box thinner than rounding
    /// takes the face the ray meets (`thin_box_surface`).
    pub fn surface_at(&self, hit: &Hit, ray: &Ray) -> (Vec3, Vec3) {
        let i = hit.prim as usize;
        let exact = match (i < self.len()).then(|| self.locate(i)) {
            Some((PrimKind::Sphere, k)) => {
                let s = &self.spheres[k];
                let inv = DMat3::from_diagonal(DVec3::splat(1.0 / s.radius as f64));
                quadric_surface(inv, s.center, hit, ray)
            }
            Some((PrimKind::Ellipsoid, k)) => {
                let e = &self.ellipsoids[k];
                quadric_surface(Mat3::from_cols_array(&e.inv).as_dmat3(), e.center, hit, ray)
            }
            Some((PrimKind::Box, k)) => thin_box_surface(&self.boxes[k], hit, ray),
            _ => None,
        };
        exact.unwrap_or_else(|| self.shading_surface(hit, ray, true))
    }

    /// Bytes held by each kind's array, for the memory report.
    pub fn bytes(&self) -> usize {
        use std::mem::size_of;
        self.triangles.len() * size_of::<Triangle>()
            + self.spheres.len() * size_of::<Sphere>()
            + self.ellipsoids.len() * size_of::<Ellipsoid>()
            + self.boxes.len() * size_of::<Aabb>()
            + self.planes.len() * size_of::<Plane>()
            + self.vertices.len() * size_of::<[[f32; 3]; 3]>()
    }
}

/// The point and outward unit normal of `ray`'s hit at `hit.t` on the quadric `|M⁻¹ (x - c)| = 1`
/// (`inv` = `M⁻¹`: a sphere's is `I / r`), in f64, where `(org - c) + t dir` is exact (in f32
/// its rounding, about an ULP of `org - c`, lies across the ray as much as along it: spheres
/// of radius 1e-7 seen from 3 units had a fifth of their normals facing away from the ray).
/// The point is moved along the ray onto the surface by the root nearest it, or, where the
/// chord is within the rounding of `t` (a shape thinner than an ULP of the distance: either
/// sheet is at the same f32 `t`), by the entry if the ray starts (at `tmin`) outside, else
/// the exit: the root the query must have found. A grazing ray (an f32 `t` just past the rim)
/// takes the point of the line nearest the surface. Where `q` lies so far off (in unit space)
/// that f64 cannot place the line against the shape, [`line_lost_surface`] answers. `None`
/// where a step is not finite.
fn quadric_surface(inv: DMat3, center: [f32; 3], hit: &Hit, ray: &Ray) -> Option<(Vec3, Vec3)> {
    let oc = ray.org.as_dvec3() - Vec3::from(center).as_dvec3();
    let d = ray.dir.as_dvec3();
    let q = oc + hit.t as f64 * d;
    let (u, du) = (inv * q, inv * d);
    let a = du.length_squared();
    if !(a > 0.0 && a.is_finite() && u.is_finite()) {
        return None;
    }
    let start = (inv * (oc + ray.tmin as f64 * d)).length_squared();
    let entering = !ray.tmin.is_finite() || start > 1.0 || start.is_nan();
    // The line's offset from the centre, `u - (b/a) du` below, is good to about |u| ULPs:
    // past an eighth of the unit shape it is noise (a quarter of such hits got a normal
    // facing away from the ray), and the root it gives no answer.
    if u.length() * f64::EPSILON > 0.125 {
        return line_lost_surface(inv, center, hit, ray, (u, du), entering);
    }
    let b = u.dot(du);
    let disc = a * (1.0 - (u - (b / a) * du).length_squared());
    let s = if disc >= 0.0 {
        let h = disc.sqrt();
        let (s0, s1) = ((-b - h) / a, (-b + h) / a);
        let rounding = 4.0 * (hit.t.abs() * f32::EPSILON) as f64;
        match s1 - s0 <= rounding {
            true if entering => s0,
            true => s1,
            false if s1.abs() < s0.abs() => s1,
            false => s0,
        }
    } else {
        -b / a
    };
    let p = (q + s * d).as_vec3();
    let g = inv.transpose() * (u + s * du);
    let len = g.length();
    (len > 0.0 && len.is_finite() && p.is_finite())
        .then(|| (p + Vec3::from(center), (g / len).as_vec3()))
}

/// [`quadric_surface`] where `q` lies so far from the shape that f64 cannot place the line
/// against it (a ray from 1e38 away with a direction 1e36 long: the last bit of `t` moves the
/// point by 1e31), yet within the rounding of the query's f32 operands: the line's offset
/// from the centre is lost, and the query's hit cannot be placed on the surface from it. The
/// point is then the one the ray's direction alone gives, the entry (or, for a ray starting
/// inside, the exit) of a line through the centre: `∓ M⁻¹d / |M⁻¹d|` in unit space, with its
/// outward normal. `None` for a `q` further off than that rounding (a `t` no query returns,
/// such as 3e38 on a unit sphere a few units away) or a result that is not finite.
fn line_lost_surface(
    inv: DMat3,
    center: [f32; 3],
    hit: &Hit,
    ray: &Ray,
    (u, du): (DVec3, DVec3),
    entering: bool,
) -> Option<(Vec3, Vec3)> {
    let c = Vec3::from(center).as_dvec3();
    // How far f32 rounding of `t`, the origin and the centre can move `q` in world space,
    // and (through the map's Frobenius norm, a bound of its largest stretch) in unit space.
    let world = 4.0
        * f32::EPSILON as f64
        * (hit.t.abs() as f64 * ray.dir.as_dvec3().length()
            + ray.org.as_dvec3().abs().max_element()
            + c.abs().max_element());
    let stretch =
        (inv.x_axis.length_squared() + inv.y_axis.length_squared() + inv.z_axis.length_squared())
            .sqrt();
    // All finite (the caller checked `u`; `t`, the ray and the map are finite).
    if u.length() > 1.0 + world * stretch {
        return None;
    }
    let unit = du.normalize() * if entering { -1.0 } else { 1.0 };
    let p = (c + inv.inverse() * unit).as_vec3();
    let g = inv.transpose() * unit;
    let len = g.length();
    (len > 0.0 && len.is_finite() && p.is_finite()).then(|| (p, (g / len).as_vec3()))
}

/// The face of a box thinner than the rounding of `org + t dir` across its flat axis (a box
/// 1e-7 thick seen from 3 units away: the point lands on either face, and ties go to the max
/// face, so half the hits got the far face's point and normal): the face the ray meets, the
/// entry if it starts (at `tmin`) outside, else the exit. `None` where the nearest face is
/// not in doubt ([`box_on_surface`] and [`box_normal`] then).
fn thin_box_surface(b: &Aabb, hit: &Hit, ray: &Ray) -> Option<(Vec3, Vec3)> {
    let p = ray.at(hit.t);
    let n = box_normal(b, p);
    let axis = (0..3).find(|&a| n[a] != 0.0)?;
    let tol =
        (-20f32).exp2() * (ray.org.abs().max_element() + (hit.t * ray.dir).abs().max_element());
    let extent = b.max[axis] - b.min[axis];
    if extent > tol || extent.is_nan() || ray.dir[axis] == 0.0 {
        return None;
    }
    let start = if ray.tmin.is_finite() {
        ray.org + ray.tmin * ray.dir
    } else {
        Vec3::INFINITY
    };
    let inside = start.cmpge(b.min).all() && start.cmple(b.max).all();
    let max = (ray.dir[axis] < 0.0) != inside;
    let mut q = p.clamp(b.min, b.max);
    q[axis] = if max { b.max[axis] } else { b.min[axis] };
    let mut normal = Vec3::ZERO;
    normal[axis] = if max { 1.0 } else { -1.0 };
    Some((q, normal))
}
