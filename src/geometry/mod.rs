//! The geometric vocabulary shared by every layer: rays and hits, boxes, the primitive set a
//! committed scene is made of, and the scaling that keeps their `f32` arithmetic in range.

mod aabb;
mod analytic;
mod primitives;
mod ray;
mod scale;
mod triangle;

pub use aabb::{Aabb, Clipped};
pub use analytic::{
    box_intersect, box_normal, box_on_surface, resolve_quadric, Ellipsoid, Plane, Sphere,
};
pub use primitives::{PrimKind, PrimitiveSet, RayTest};
pub use ray::{Hit, PrimIndex, Ray, TraversalStats, INVALID};
pub use scale::{power_of_two_scale, unit};
pub(crate) use triangle::{shear_axes, watertight, watertight_f32};
pub use triangle::{Triangle, TriangleTest};
