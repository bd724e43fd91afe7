//! The surface at a hit, for callers that shade the hits of their own queries (Embree hands
//! the geometric normal to every hit; here it is asked for): the point recomputed on the
//! primitive, the geometric normal and the material. The primitive methods that give the
//! renderer its shading point (`cpu::whitted`), on the world-space primitives that placement
//! made (normals of transformed objects already by the inverse transpose); but spheres and
//! ellipsoids are taken relative to their centre in f64, where the renderer does it in f32
//! (`PrimitiveSet::surface_at`).

use super::Committed;
use crate::geometry::{Hit, Ray};
use glam::Vec3;

/// Where a hit lies and which way its surface faces, in world space.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HitSurface {
    /// The hit point recomputed on the primitive: from the barycentrics on triangles,
    /// `org + t·dir` moved onto the surface otherwise, on the side the ray meets
    /// (`PrimitiveSet::surface_at`).
    pub position: Vec3,
    /// Unit geometric normal, not turned towards the ray: outward for spheres, ellipsoids and
    /// boxes, the plane's own normal, the side of `(v1 - v0) × (v2 - v0)` of the mesh's
    /// corners for triangles (kept under a mirroring transform).
    pub normal: Vec3,
    /// The material id of the primitive's object.
    pub material: u32,
}

impl Committed {
    /// The surface at `hit`, a hit of `ray` by a query of this commit, in the library's
    /// numbering (`Context::intersect`'s hits: the global primitive and the stored triangle's
    /// barycentrics). `None` for a miss, a primitive this commit lacks, or a point that has no
    /// unit normal: one that cannot be put on the surface (a `t` so far off a sphere or
    /// ellipsoid that the point is lost to rounding, further than the rounding of the ray's
    /// f32 values explains), or on a triangle of no area; no query returns such a hit.
    pub fn hit_surface(&self, ray: &Ray, hit: &Hit) -> Option<HitSurface> {
        let origin = self.origins.get(hit.prim as usize)?;
        let (position, normal) = self.prims.surface_at(hit, ray);
        (normal != Vec3::ZERO).then_some(HitSurface {
            position,
            normal,
            material: self.object_material[origin.object as usize],
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The unit sphere's hit from (0, 0, 5) along -z is (0, 0, 1) with normal +z and the
    /// default material; a miss and an index past the commit have no surface.
    #[test]
    fn a_hit_has_a_surface_and_a_miss_none() {
        let scene = super::super::unit_sphere();
        let c = scene.committed().unwrap();
        let ray = Ray::new(Vec3::new(0.0, 0.0, 5.0), Vec3::NEG_Z, 0.0, f32::INFINITY);
        let hit = Hit {
            t: 4.0,
            u: 0.0,
            v: 0.0,
            prim: 0,
        };
        let s = c.hit_surface(&ray, &hit).unwrap();
        assert_eq!((s.position, s.normal, s.material), (Vec3::Z, Vec3::Z, 0));
        assert_eq!(c.hit_surface(&ray, &Hit::MISS), None);
        let past = Hit { prim: 1, ..hit };
        assert_eq!(c.hit_surface(&ray, &past), None);
    }
}
