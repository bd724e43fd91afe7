//! Objects as the user gave them (shape in object space + transform) and their placement
//! into world space at commit. Analytic shapes stay analytic under transforms: a sphere under
//! a non-uniform scale becomes an ellipsoid, never a mesh.

use crate::error::{Error, Result};
use crate::fallible::{Fallible, TryGrow};
use crate::geometry::{Aabb, Ellipsoid, Plane, PrimitiveSet, Sphere, Triangle};
use glam::{Affine3A, DVec3, Mat3, Vec3};

#[derive(Clone, Debug, PartialEq)]
pub enum Shape {
    Mesh {
        positions: Vec<Vec3>,
        triangles: Vec<[u32; 3]>,
    },
    Sphere {
        center: Vec3,
        radius: f32,
    },
    /// Axis-aligned ellipsoid with semi-axes `radii` (a transform may rotate it).
    Ellipsoid {
        center: Vec3,
        radii: Vec3,
    },
    Box {
        min: Vec3,
        max: Vec3,
    },
    Plane {
        normal: Vec3,
        offset: f32,
    },
}

impl Shape {
    /// Number of primitives this shape contributes.
    pub fn prim_count(&self) -> usize {
        match self {
            Shape::Mesh { triangles, .. } => triangles.len(),
            _ => 1,
        }
    }
}

#[derive(Clone, Debug, PartialEq)]
pub struct Object {
    pub shape: Shape,
    pub material: u32,
    pub transform: Affine3A,
    /// Whether commits place the object (`Scene::set_enabled`): a disabled one keeps its id,
    /// shape, material and transform but is left out of the primitives and the tree.
    pub enabled: bool,
}

impl Object {
    /// Whether the transform mirrors (a negative determinant). A mirrored mesh's triangles
    /// are placed with corners 1 and 2 swapped, so that the world-space winding, and with it
    /// the normal `e1 × e2` the renderer takes for outward (refraction enters and leaves by
    /// it), stays that of the mesh as given; hits report `u` and `v` swapped back.
    pub fn mirrors(&self) -> bool {
        mirrors(&self.transform)
    }
}

/// `t` with the entries of its linear part that are rounding set to zero, for a box: each
/// column must have one entry, and others at most 2^-20 of it are taken for rounding (a
/// quarter turn built with `cosf` and `sinf` has a cosine of -4.4e-8, not 0, and was
/// refused). Zeroed, not kept: an entry of 2^-20 would tilt a face by that much of the box's
/// extent along another axis, many times the thickness of a flat box. The columns' entries
/// must lie on three different axes: a shear whose large entry shares a row with another
/// column's (x' = x + 2^21 y) would otherwise be left singular, the box flattened. An error
/// otherwise.
fn axis_aligned(t: &Affine3A) -> Result<Affine3A> {
    let refuse = |why: String| {
        Err(Error::unsupported(format!(
            "boxes are axis-aligned: their transform may only translate, scale and swap axes, \
             but {why}"
        )))
    };
    let mut m = Mat3::from(t.matrix3);
    let mut axes = 0;
    for c in 0..3 {
        let col = m.col(c);
        let keep = col
            .abs()
            .cmpgt(Vec3::splat(col.abs().max_element() * (-20f32).exp2()));
        if keep.bitmask().count_ones() != 1 {
            return refuse(format!(
                "column {c} of its 3x3 part is {:?}",
                col.to_array()
            ));
        }
        if axes & keep.bitmask() != 0 {
            return refuse(format!(
                "column {c} of its 3x3 part, {:?}, lies on the same axis as an earlier column",
                col.to_array()
            ));
        }
        axes |= keep.bitmask();
        *m.col_mut(c) = Vec3::select(keep, col, Vec3::ZERO);
    }
    Ok(Affine3A::from_mat3_translation(m, t.translation.into()))
}

/// Whether `t` mirrors (see [`Object::mirrors`]); one test for the placement of the
/// triangles, their exact corners and the hits' barycentrics.
fn mirrors(t: &Affine3A) -> bool {
    determinant(t) < 0.0
}

/// The determinant of `t`'s 3x3 part: its sign exact (0 only for a singular map), its value
/// within an ulp or so. In f32 its products cancel for a nearly singular map that a scene
/// graph easily makes (a rotation, a scale of 1e-5 on two axes, another rotation: -1.4e-10
/// where it is +1.0e-10), flipping the sign that says whether the map mirrors, or giving 0
/// for a map that is not singular. Summed in f64 they still can: a product of three f32
/// entries takes 72 bits, and a map with two equal columns came out 7.1e-15 (taken for not
/// singular), one whose determinant is +6.8e-14 came out -5.3e-13 (taken for a mirror).
/// So the f64 sum is kept only where its error bound says its sign is right; otherwise the
/// six products are split exactly into two f64 each and summed exactly
/// ([`exact_determinant`]). In f64 no product of f32 entries overflows or underflows.
pub(crate) fn determinant(t: &Affine3A) -> f64 {
    let m = Mat3::from(t.matrix3).as_dmat3();
    let (x, y, z) = (m.x_axis, m.y_axis, m.z_axis);
    let det = m.determinant();
    // `z · (x × y)`: each cross term is a difference of exact products, rounded once, then
    // three products and two sums: at most 4 roundings of terms bounded by the permanent.
    let (xa, ya) = (x.abs(), y.abs());
    let permanent = z.abs().dot(DVec3::new(
        xa.y * ya.z + ya.y * xa.z,
        xa.z * ya.x + ya.z * xa.x,
        xa.x * ya.y + ya.x * xa.y,
    ));
    if det.abs() > 8.0 * f64::EPSILON * permanent {
        return det;
    }
    exact_determinant([x, y, z].map(|c| c.to_array()))
}

/// The determinant of the columns `c` (f32 values), summed exactly: each of its six products
/// is `a b` (exact in f64: 48 bits) times `c`, split into the rounded product and its exact
/// error (an FMA), and the twelve parts are added into a nonoverlapping expansion (Shewchuk's
/// Grow-Expansion), whose largest part has the sign of the sum.
fn exact_determinant(c: [[f64; 3]; 3]) -> f64 {
    let two_sum = |a: f64, b: f64| {
        let s = a + b;
        let bv = s - a;
        (s, (a - (s - bv)) + (b - bv))
    };
    let mut parts = [0.0f64; 12];
    let mut n = 0;
    for (i, j, k, sign) in [
        (0, 1, 2, 1.0),
        (1, 2, 0, 1.0),
        (2, 0, 1, 1.0),
        (0, 2, 1, -1.0),
        (1, 0, 2, -1.0),
        (2, 1, 0, -1.0),
    ] {
        let ab = sign * c[0][i] * c[1][j];
        let p = ab * c[2][k];
        for b in [ab.mul_add(c[2][k], -p), p] {
            let mut q = b;
            for h in &mut parts[..n] {
                (q, *h) = two_sum(q, *h);
            }
            parts[n] = q;
            n += 1;
        }
    }
    // Smallest parts first; the largest nonzero part decides the sign (a sum rounded onto 0
    // or across it, which nonoverlapping parts all but rule out, falls back to it).
    let sum: f64 = parts.iter().sum();
    match parts.iter().rev().find(|&&p| p != 0.0) {
        Some(&top) if sum == 0.0 || sum.signum() != top.signum() => top,
        _ => sum,
    }
}

/// Where a global primitive index came from, for hits reported to the caller.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PrimOrigin {
    pub object: u32,
    pub prim: u32,
}

/// The world-space corners of triangle `tri` of a mesh placed by `t`. Each corner is placed
/// on its own (nothing is allocated): checking a mesh of any size then needs no memory, and
/// the corners come out bit-identical to placing every vertex once.
fn world_corners(positions: &[Vec3], tri: &[u32; 3], t: &Affine3A, mirrors: bool) -> [Vec3; 3] {
    let [a, b, c] = tri.map(|i| t.transform_point3(positions[i as usize]));
    if mirrors {
        [a, c, b]
    } else {
        [a, b, c]
    }
}

/// The exact corners of every triangle of the enabled `objects` (`None`: removed), in the
/// order [`place`] gives the triangles (`PrimitiveSet::vertices`, for the watertight test).
pub fn triangle_corners(objects: &[Option<Box<Object>>]) -> Fallible<Vec<[[f32; 3]; 3]>> {
    let mut out = Vec::new();
    for obj in objects.iter().flatten().filter(|o| o.enabled) {
        if let Shape::Mesh {
            positions,
            triangles,
        } = &obj.shape
        {
            out.try_extend(triangles.iter().map(|tri| {
                world_corners(positions, tri, &obj.transform, obj.mirrors()).map(|v| v.to_array())
            }))?;
        }
    }
    Ok(out)
}

/// One world-space primitive, as [`place_shape`] hands it on (a triangle with its index in
/// the mesh).
enum Placed {
    Triangle(u32, Triangle),
    Sphere(Sphere),
    Ellipsoid(Ellipsoid),
    Box(Aabb),
    Plane(Plane),
}

/// Appends the world-space primitives of `obj` to `set`, and where each came from to the
/// origin list of its kind, `origins[k]` for triangles, spheres, ellipsoids, boxes and planes
/// in turn (the commit concatenates them in that order: the order of the global index).
///
/// Fails when a primitive cannot be represented in world space (see [`check`]), having
/// appended the primitives before it: the commit then drops the whole set. The scene checks
/// every object when it is added or moved, so a commit never meets one.
pub fn place(
    obj: &Object,
    object_id: u32,
    set: &mut PrimitiveSet,
    origins: &mut [Vec<PrimOrigin>],
) -> Result<()> {
    place_shape(&obj.shape, &obj.transform, |p| {
        let (kind, prim) = match p {
            Placed::Triangle(k, t) => {
                set.triangles.try_push(t)?;
                (0, k)
            }
            Placed::Sphere(s) => {
                set.spheres.try_push(s)?;
                (1, 0)
            }
            Placed::Ellipsoid(e) => {
                set.ellipsoids.try_push(e)?;
                (2, 0)
            }
            Placed::Box(b) => {
                set.boxes.try_push(b)?;
                (3, 0)
            }
            Placed::Plane(p) => {
                set.planes.try_push(p)?;
                (4, 0)
            }
        };
        origins[kind].try_push(PrimOrigin {
            object: object_id,
            prim,
        })
    })
}

/// The one placement algorithm: hands each world-space primitive of `shape` placed by `t` to
/// `emit`, in order (a mesh's triangles in file order), after checking that it fits. Stops at
/// the first primitive that does not fit; primitives handed on before stay handed on.
fn place_shape(
    shape: &Shape,
    t: &Affine3A,
    mut emit: impl FnMut(Placed) -> Fallible<()>,
) -> Result<()> {
    let lin = Mat3::from(t.matrix3);
    match shape {
        Shape::Mesh {
            positions,
            triangles,
        } => {
            let mirrored = mirrors(t);
            for (k, tri) in triangles.iter().enumerate() {
                let [a, b, c] = world_corners(positions, tri, t, mirrored);
                let triangle = Triangle::from_vertices(a, b, c);
                if !triangle_fits(&triangle) {
                    return Err(Error::invalid_argument(format!(
                        "triangle {k} of the mesh does not fit in f32 in world space: its \
                         corners {:?}, its edges or the product of their lengths overflow",
                        [a, b, c].map(|v| v.to_array())
                    )));
                }
                emit(Placed::Triangle(k as u32, triangle))?;
            }
        }
        Shape::Sphere { center, radius } => {
            let c = t.transform_point3(*center);
            let cols = [lin.x_axis, lin.y_axis, lin.z_axis].map(|v| v.length());
            // Compared at unit scale, so that a large scale does not overflow the test.
            let unit = lin * (1.0 / cols[0]);
            let similarity = (unit.transpose() * unit - Mat3::IDENTITY)
                .to_cols_array()
                .iter()
                .all(|e| e.abs() <= 1e-6);
            if similarity {
                let sphere = Sphere {
                    center: c.to_array(),
                    radius: radius * cols[0],
                };
                // The intersection squares the radius: it must neither overflow nor vanish.
                let r2 = sphere.radius * sphere.radius;
                if !(r2.is_normal() && sphere.bounds().is_finite()) {
                    return Err(Error::invalid_argument(format!(
                        "the sphere does not fit in f32 in world space: centre {:?}, radius {:?} \
                         (its bounds and the square of its radius must be finite and non-zero)",
                        c.to_array(),
                        sphere.radius
                    )));
                }
                emit(Placed::Sphere(sphere))?;
            } else {
                emit(Placed::Ellipsoid(ellipsoid(c, lin * *radius, "sphere")?))?;
            }
        }
        Shape::Ellipsoid { center, radii } => {
            let m = lin * Mat3::from_diagonal(*radii);
            emit(Placed::Ellipsoid(ellipsoid(
                t.transform_point3(*center),
                m,
                "ellipsoid",
            )?))?;
        }
        Shape::Box { min, max } => {
            let t = axis_aligned(t)?;
            let (a, b) = (t.transform_point3(*min), t.transform_point3(*max));
            let bounds = Aabb::new(a.min(b), a.max(b));
            if !bounds.is_finite() {
                return Err(Error::invalid_argument(format!(
                    "the box does not fit in f32 in world space: corners {:?} and {:?}",
                    a.to_array(),
                    b.to_array()
                )));
            }
            emit(Placed::Box(bounds))?;
        }
        Shape::Plane { normal, offset } => {
            emit(Placed::Plane(plane(t, *normal, *offset)?))?;
        }
    }
    Ok(())
}

/// Whether `shape` placed by `t` fits in world space: every primitive finite, so that the tree
/// holds it and rays can hit it. Without this check an object the user added would be counted
/// but left out of the tree (its bounds overflow) or never hit (a singular ellipsoid, a NaN
/// plane), with no error.
///
/// Runs the placement itself (one algorithm, so the check cannot drift from what a commit
/// builds) but keeps nothing: primitives are checked one at a time, so checking a mesh needs
/// no memory beyond the mesh (materialising it would double a large mesh's footprint).
pub fn check(shape: &Shape, t: &Affine3A) -> Result<()> {
    place_shape(shape, t, |_| Ok(()))
}

/// Whether a triangle's stored corner, the edges it stores and the corners rebuilt from them
/// (its bounds) are finite, and the product of its edge lengths fits in f32. Möller–Trumbore's
/// determinant multiplies the two edges (and the direction): past that product it overflows
/// for most directions, always along the normal, and the triangle is all but never hit (edges
/// of about 1.8e19 and more).
fn triangle_fits(t: &Triangle) -> bool {
    let (e1, e2) = (Vec3::from(t.e1), Vec3::from(t.e2));
    e1.is_finite()
        && e2.is_finite()
        && e1.as_dvec3().length() * e2.as_dvec3().length() <= f32::MAX as f64
        && t.bounds().is_finite()
}

fn ellipsoid(center: Vec3, m: Mat3, what: &str) -> Result<Ellipsoid> {
    Ellipsoid::new(center, m)
        .filter(|e| e.bounds().is_finite())
        .ok_or_else(|| {
            Error::invalid_argument(format!(
                "the {what} does not fit in f32 in world space: centre {:?}, semi-axes \
                 {:?} (its inverse or its bounds overflow or underflow)",
                center.to_array(),
                m.to_cols_array_2d()
            ))
        })
}

/// The world-space plane of `normal · x = offset` under `t`. `normal` may have any non-zero
/// finite length (as documented): the plane equation is scaled to unit size before anything
/// is squared, and the inverse transpose is taken in f64, where a nearly singular map (see
/// [`determinant`]) keeps the normal's side and the inverse of any f32 map is finite.
fn plane(t: &Affine3A, normal: Vec3, offset: f32) -> Result<Plane> {
    let fail = || {
        Error::invalid_argument(format!(
            "the plane normal {:?} . x = {offset:?} does not fit in f32 in world space",
            normal.to_array()
        ))
    };
    let m = normal.abs().max_element();
    let (n, d) = (normal / m, offset / m);
    let lin = Mat3::from(t.matrix3).as_dmat3();
    let world = (lin.inverse().transpose() * n.as_dvec3())
        .try_normalize()
        .ok_or_else(fail)?
        .as_vec3();
    let p0 = t.transform_point3(n * (d / n.length_squared()));
    let offset = world.dot(p0);
    if !(d.is_finite() && p0.is_finite() && offset.is_finite()) {
        return Err(fail());
    }
    Ok(Plane {
        normal: world.to_array(),
        offset,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    /// Maps of columns `x`, `y`, `x + d e_k` (`x`'s entry `k` moved an ulp or two): nearly
    /// singular, with entries spread over 2^±12. The determinant is `d (x × y)_k`, whose sign
    /// f64 gets exactly (`d` is an exact difference of f32, each cross product term an exact
    /// product); and with `d = 0` (two equal columns), zero. [`determinant`] agrees on every
    /// one, where the f64 sum alone gave a wrong sign, or a non-zero one for equal columns.
    #[test]
    fn the_determinant_has_the_sign_of_the_exact_one() {
        let mut rng = Rng(7);
        let mut entry = || {
            let e = (rng.index(25) as f32 - 12.0).exp2();
            (rng.unit() * 2.0 - 1.0) * e
        };
        for _ in 0..100_000 {
            let x = Vec3::new(entry(), entry(), entry());
            let y = Vec3::new(entry(), entry(), entry());
            let k = (x.x.to_bits() % 3) as usize;
            let mut z = x;
            let ulps = [0i32, 1, -1, 2][(y.x.to_bits() % 4) as usize];
            z[k] = f32::from_bits((z[k].to_bits() as i32 + ulps) as u32);
            let (xd, yd) = (x.as_dvec3(), y.as_dvec3());
            let cross_k = xd.cross(yd)[k];
            let want = (z[k] as f64 - x[k] as f64) * cross_k;
            let t = Affine3A::from_mat3(Mat3::from_cols(x, y, z));
            let got = determinant(&t);
            assert_eq!(
                (got > 0.0, got < 0.0),
                (want > 0.0, want < 0.0),
                "{x} {y} {z}: {got:e}, want the sign of {want:e}"
            );
        }
    }
}
