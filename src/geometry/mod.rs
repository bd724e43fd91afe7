//! The geometric vocabulary shared by every layer: rays and hits, boxes, and the
//! primitive set a committed scene is made of.

mod aabb;
mod analytic;
mod primitives;
mod ray;
mod triangle;

pub use aabb::Aabb;
pub use analytic::{box_intersect, box_normal, Ellipsoid, Plane, Sphere};
pub use primitives::{PrimKind, PrimitiveSet, RayTest};
pub use ray::{Hit, PrimIndex, Ray, TraversalStats, INVALID};
pub use triangle::{Triangle, TriangleTest};
