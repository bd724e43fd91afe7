//! Objects as the user gave them (shape in object space + transform) and their placement
//! into world space at commit. Analytic shapes stay analytic under transforms: a sphere under
//! a non-uniform scale becomes an ellipsoid, never a mesh.

use crate::error::{Error, Result};
use crate::geometry::{Aabb, Ellipsoid, Plane, PrimitiveSet, Sphere, Triangle};
use glam::{Affine3A, Mat3, Vec3};

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

    /// Whether `t` keeps this shape representable. Boxes are axis-aligned, so they accept
    /// only transforms whose linear part maps axes onto axes.
    pub fn accepts(&self, t: &Affine3A) -> Result<()> {
        if let Shape::Box { .. } = self {
            let m = Mat3::from(t.matrix3);
            let axis_aligned =
                (0..3).all(|c| m.col(c).to_array().iter().filter(|v| **v != 0.0).count() == 1);
            if !axis_aligned {
                return Err(Error::unsupported(
                    "boxes are axis-aligned: their transform may only translate, scale and swap axes",
                ));
            }
        }
        Ok(())
    }
}

#[derive(Clone, Debug, PartialEq)]
pub struct Object {
    pub shape: Shape,
    pub material: u32,
    pub transform: Affine3A,
}

/// Where a global primitive index came from, for hits reported to the caller.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PrimOrigin {
    pub object: u32,
    pub prim: u32,
}

/// The world-space corners of a mesh object's triangles, in file order (none for other shapes).
fn world_triangles(obj: &Object) -> Vec<[Vec3; 3]> {
    let Shape::Mesh {
        positions,
        triangles,
    } = &obj.shape
    else {
        return Vec::new();
    };
    let world: Vec<Vec3> = positions
        .iter()
        .map(|&p| obj.transform.transform_point3(p))
        .collect();
    triangles
        .iter()
        .map(|tri| tri.map(|i| world[i as usize]))
        .collect()
}

/// The exact corners of every triangle of `objects`, in the order [`place`] gives the
/// triangles (`PrimitiveSet::vertices`, for the watertight test).
pub fn triangle_corners(objects: &[Object]) -> Vec<[[f32; 3]; 3]> {
    objects
        .iter()
        .flat_map(world_triangles)
        .map(|t| t.map(|v| v.to_array()))
        .collect()
}

/// Appends the world-space primitives of `obj` to `set`; `origins` receives one entry per
/// bounded primitive, `plane_origins` per plane (they are indexed after the bounded ones).
pub fn place(
    obj: &Object,
    object_id: u32,
    set: &mut PrimitiveSet,
    origins: &mut [Vec<PrimOrigin>],
) {
    let t = obj.transform;
    let lin = Mat3::from(t.matrix3);
    let one = PrimOrigin {
        object: object_id,
        prim: 0,
    };
    match &obj.shape {
        Shape::Mesh { .. } => {
            for (k, [a, b, c]) in world_triangles(obj).into_iter().enumerate() {
                set.triangles.push(Triangle::from_vertices(a, b, c));
                origins[0].push(PrimOrigin {
                    object: object_id,
                    prim: k as u32,
                });
            }
        }
        Shape::Sphere { center, radius } => {
            let c = t.transform_point3(*center);
            let cols = [lin.x_axis, lin.y_axis, lin.z_axis].map(|v| v.length());
            let similarity = (lin.transpose() * lin
                - Mat3::from_diagonal(Vec3::splat(cols[0] * cols[0])))
            .to_cols_array()
            .iter()
            .all(|e| e.abs() <= 1e-6 * cols[0] * cols[0]);
            if similarity {
                set.spheres.push(Sphere {
                    center: c.to_array(),
                    radius: radius * cols[0],
                });
                origins[1].push(one);
            } else if let Some(e) = Ellipsoid::new(c, lin * *radius) {
                set.ellipsoids.push(e);
                origins[2].push(one);
            }
        }
        Shape::Ellipsoid { center, radii } => {
            if let Some(e) = Ellipsoid::new(
                t.transform_point3(*center),
                lin * Mat3::from_diagonal(*radii),
            ) {
                set.ellipsoids.push(e);
                origins[2].push(one);
            }
        }
        Shape::Box { min, max } => {
            let (a, b) = (t.transform_point3(*min), t.transform_point3(*max));
            set.boxes.push(Aabb::new(a.min(b), a.max(b)));
            origins[3].push(one);
        }
        Shape::Plane { normal, offset } => {
            let n = (lin.inverse().transpose() * *normal).normalize();
            let p0 = t.transform_point3(*normal * (*offset / normal.length_squared()));
            set.planes.push(Plane {
                normal: n.to_array(),
                offset: n.dot(p0),
            });
            origins[4].push(one);
        }
    }
}
