//! Axis-aligned bounding boxes: voxels of the kd-tree and bounds of primitives.

use glam::Vec3;

/// An axis-aligned box. The empty box has `min = +inf`, `max = -inf`, so that
/// `union` with it is the identity and it overlaps nothing.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Aabb {
    pub min: Vec3,
    pub max: Vec3,
}

impl Aabb {
    pub const EMPTY: Aabb = Aabb {
        min: Vec3::splat(f32::INFINITY),
        max: Vec3::splat(f32::NEG_INFINITY),
    };

    pub fn new(min: Vec3, max: Vec3) -> Self {
        Aabb { min, max }
    }

    pub fn from_points(points: &[Vec3]) -> Self {
        points.iter().fold(Aabb::EMPTY, |b, &p| b.grow(p))
    }

    pub fn grow(self, p: Vec3) -> Self {
        Aabb::new(self.min.min(p), self.max.max(p))
    }

    pub fn union(self, o: Aabb) -> Self {
        Aabb::new(self.min.min(o.min), self.max.max(o.max))
    }

    /// The common part of two boxes; empty when they do not touch.
    pub fn intersection(self, o: Aabb) -> Self {
        let b = Aabb::new(self.min.max(o.min), self.max.min(o.max));
        if b.is_empty() {
            Aabb::EMPTY
        } else {
            b
        }
    }

    /// True when some axis has `min > max` (a flat box with `min == max` is not empty).
    pub fn is_empty(&self) -> bool {
        self.min.cmpgt(self.max).any()
    }

    /// True when both corners are finite (a box the tree can hold).
    pub fn is_finite(&self) -> bool {
        self.min.is_finite() && self.max.is_finite()
    }

    pub fn extent(&self) -> Vec3 {
        (self.max - self.min).max(Vec3::ZERO)
    }

    /// Halves before adding: `min + max` overflows for boxes beyond about 1.7e38, and the
    /// midpoint builder, splitting at an infinite centre, made such a scene one leaf.
    pub fn center(&self) -> Vec3 {
        0.5 * self.min + 0.5 * self.max
    }

    pub fn diagonal(&self) -> f32 {
        if self.is_empty() {
            0.0
        } else {
            self.extent().length()
        }
    }

    /// The power of two that brings this box's largest coordinate magnitude into `[1, 2)` (1
    /// for an empty or infinite box). Lengths and areas of boxes inside it, scaled by it, are
    /// neither infinite nor zero: a box 1e19 wide has an area past `f32::MAX`, which made
    /// every SAH split cost NaN. A power of two scales exactly, so ratios of scaled areas are
    /// bit for bit those of unscaled ones wherever those are finite.
    pub fn unit_scale(&self) -> f32 {
        let m = self.min.abs().max(self.max.abs()).max_element();
        match super::power_of_two_scale(m) {
            Some(s) if !self.is_empty() => s,
            _ => 1.0,
        }
    }

    /// The extent scaled by `scale`, computed from the scaled corners (so that a box from
    /// -3e38 to 3e38 has a finite scaled extent).
    pub fn scaled_extent(&self, scale: f32) -> Vec3 {
        (self.max * scale - self.min * scale).max(Vec3::ZERO)
    }

    /// The surface area of the box scaled by `scale` (see [`Aabb::unit_scale`]).
    pub fn scaled_surface_area(&self, scale: f32) -> f32 {
        if self.is_empty() {
            return 0.0;
        }
        let e = self.scaled_extent(scale);
        2.0 * (e.x * e.y + e.y * e.z + e.z * e.x)
    }

    /// Closed-interval overlap test: boxes that only share a face overlap.
    pub fn overlaps(&self, o: &Aabb) -> bool {
        !self.is_empty()
            && !o.is_empty()
            && self.min.cmple(o.max).all()
            && o.min.cmple(self.max).all()
    }

    pub fn contains_point(&self, p: Vec3) -> bool {
        self.min.cmple(p).all() && p.cmple(self.max).all()
    }

    /// Slab test: the parametric interval `[t0, t1]` of the ray inside the closed box, clamped
    /// to `[tmin, tmax]`, or `None` when the ray misses it. Each slab's near and far planes are
    /// chosen by the sign of `inv_dir` (so by the sign of a zero direction component too): a ray
    /// lying in a face plane gets a NaN distance there, which compares false and clips nothing,
    /// so it is inside the closed slab for `+0.0` and `-0.0` alike.
    pub fn clip_ray(&self, org: Vec3, inv_dir: Vec3, tmin: f32, tmax: f32) -> Option<(f32, f32)> {
        let mut t0 = tmin;
        let mut t1 = tmax;
        for a in 0..3 {
            let ta = (self.min[a] - org[a]) * inv_dir[a];
            let tb = (self.max[a] - org[a]) * inv_dir[a];
            let (near, far) = if inv_dir[a].is_sign_positive() {
                (ta, tb)
            } else {
                (tb, ta)
            };
            if near > t0 {
                t0 = near;
            }
            if far < t1 {
                t1 = far;
            }
        }
        (t0 <= t1).then_some((t0, t1))
    }
}

/// Bounds of a primitive's part inside a voxel, for the kd-tree builders. `padded` has bit
/// `2 * axis` (min face) or `2 * axis + 1` (max face) set where the face was moved out by a
/// few ULPs to cover rounding: no geometry lies there, so the SAH does not split there.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Clipped {
    pub bounds: Aabb,
    pub padded: u8,
}

impl Clipped {
    /// Bounds whose every face is where the geometry is.
    pub fn exact(bounds: Aabb) -> Self {
        Clipped { bounds, padded: 0 }
    }
}
