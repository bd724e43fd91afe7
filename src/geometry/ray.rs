//! The ray and hit vocabulary shared by every traversal, backend and the C API.

use super::power_of_two_scale;
use glam::Vec3;

/// A ray segment `org + t * dir`, `t` in `[tmin, tmax)` (a hit at exactly `tmax` does not count,
/// as in `../shared/raysets`). Eight floats in this order (`repr(C)`): the SIMD leaf tests read
/// a batch of rays as rows of floats (`cpu::simd::RayLanes::gather`).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct Ray {
    pub org: Vec3,
    pub dir: Vec3,
    pub tmin: f32,
    pub tmax: f32,
}

impl Ray {
    /// The ray `org + t * dir` over `[tmin, tmax)`, its window starting at `-f32::MAX` at the
    /// earliest: a hit is a point of the ray, at a finite `t`. Every primitive test accepts
    /// `t >= tmin`, so a window open to `-inf` let through a crossing whose `t` overflowed to
    /// `-inf` (a direction of 1e-45, or products near `f32::MAX`), where `+inf` at the other
    /// end was already excluded by `t < tmax`.
    pub fn new(org: Vec3, dir: Vec3, tmin: f32, tmax: f32) -> Self {
        Ray {
            org,
            dir,
            tmin: finite_start(tmin),
            tmax,
        }
    }

    pub fn at(&self, t: f32) -> Vec3 {
        self.org + t * self.dir
    }

    /// The power of two by which the queries scale this ray's direction, if its largest
    /// component lies outside `[2^-10, 2^10]` (and the ray is not degenerate): into [1, 2),
    /// or (0, 2) for a subnormal one (see [`power_of_two_scale`]). The primitive tests
    /// multiply the direction by edges or by itself; far from unit length those products
    /// leave f32's normal range (a triangle 1e-8 across was missed along a direction 1e-25
    /// long, the watertight test put a triangle 1e-6 across at `t = 0` along one 1e30 long).
    /// A power of two scales exactly wherever the scaled values stay normal, so a scaled ray's
    /// hits are then the unscaled one's, bit for bit. (A component more than 2^126 times
    /// smaller than the largest loses bits: they are below anything a hit can resolve at that
    /// length. A window end that the scale makes subnormal is rounded so that the scaled
    /// window admits exactly the hits the caller's does: see [`Ray::scaled`].)
    pub(crate) fn direction_scale(&self) -> Option<f32> {
        const NEAR_UNIT: std::ops::RangeInclusive<f32> = 1.0 / 1024.0..=1024.0;
        let m = self.dir.abs().max_element();
        if NEAR_UNIT.contains(&m) || self.is_degenerate() {
            return None;
        }
        power_of_two_scale(m)
    }

    /// This (non-degenerate) ray with its direction multiplied by the power of two `s` and
    /// its window divided by it, so that `t' * s` of a hit on it is the hit's `t` on this
    /// ray. The window lies within `±f32::MAX / s` and `±f32::MAX`: every hit's `t'` and
    /// `t' * s` are finite. Both ends are rounded up onto f32 ([`div_up`]): `t' * s` is then
    /// in `[tmin, tmax)` exactly when `t'` is in the scaled window (rounded to nearest, a
    /// `tmin` of 1e-26 under a scale of 2^66 became 0, and a hit at `t = 0` was reported).
    /// The GPU flushes subnormals to zero, so there such an end still reads as 0.
    pub(crate) fn scaled(&self, s: f32) -> Ray {
        Ray {
            org: self.org,
            dir: self.dir * s,
            tmin: finite_start(div_up(self.tmin, s)),
            tmax: div_up(self.tmax.min(f32::MAX), s),
        }
    }

    /// Rays that can never hit anything: NaN or infinite components, a zero
    /// direction, NaN bounds or `tmin > tmax`. They are defined misses, never errors.
    pub fn is_degenerate(&self) -> bool {
        !self.org.is_finite()
            || !self.dir.is_finite()
            || self.dir == Vec3::ZERO
            || self.tmin.is_nan()
            || self.tmax.is_nan()
            || self.tmin > self.tmax
    }
}

/// `x / s` for a power of two `s`, rounded up to the next f32 where the quotient is inexact
/// (subnormal): the least f32 `q` with `q * s >= x`, so that for every f32 `t`, `t >= q`
/// exactly when `t * s >= x` (`t * s` is exact: `s` is a power of two). Both window ends
/// need it: `t * s < tmax` holds exactly when `t < q` too.
fn div_up(x: f32, s: f32) -> f32 {
    let q = x / s;
    if q * s < x {
        q.next_up()
    } else {
        q
    }
}

/// `tmin`, or `-f32::MAX` for `-inf` (NaN stays NaN: such a ray is degenerate).
fn finite_start(tmin: f32) -> f32 {
    if tmin == f32::NEG_INFINITY {
        -f32::MAX
    } else {
        tmin
    }
}

/// Index of a primitive inside the committed scene's primitive set.
pub type PrimIndex = u32;

/// Marks "no primitive" in hits and rope links.
pub const INVALID: u32 = u32::MAX;

/// The closest hit found so far: `t`, barycentrics (`u` weighs vertex 1, `v` vertex 2, as in
/// `../shared/raysets`) and the primitive index (`INVALID` while none). Both refer to the
/// committed primitive set: the vertices are those of the stored triangle, which for a
/// mirrored mesh has the mesh's corners 1 and 2 swapped (`Object::mirrors`). `rt2_intersect`
/// reports the object, its own primitive index and the mesh's own barycentrics.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    pub t: f32,
    pub u: f32,
    pub v: f32,
    pub prim: PrimIndex,
}

impl Hit {
    pub const MISS: Hit = Hit {
        t: f32::INFINITY,
        u: 0.0,
        v: 0.0,
        prim: INVALID,
    };

    pub fn is_hit(&self) -> bool {
        self.prim != INVALID
    }

    /// Exclusive upper bound for candidate `t`s: the ray's `tmax`, or just above the current
    /// hit so that an equal-`t` candidate still reaches [`Hit::offer`]'s tie rule.
    #[inline]
    pub fn bound(&self, ray: &Ray) -> f32 {
        if self.t < ray.tmax {
            self.t.next_up()
        } else {
            ray.tmax
        }
    }

    /// Keeps the closest candidate; equal `t` goes to the lowest primitive index, so that every
    /// traversal order reports the same primitive (the tie rule of DESIGN.md §2).
    pub fn offer(&mut self, t: f32, u: f32, v: f32, prim: PrimIndex) -> bool {
        if t < self.t || (t == self.t && prim < self.prim) {
            *self = Hit { t, u, v, prim };
            true
        } else {
            false
        }
    }
}

/// Work counters of the thesis' table 1, summed over a batch when statistics are asked for.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct TraversalStats {
    pub nodes_visited: u64,
    pub leaves_visited: u64,
    pub prim_tests: u64,
}

impl TraversalStats {
    pub fn add(&mut self, o: &TraversalStats) {
        self.nodes_visited += o.nodes_visited;
        self.leaves_visited += o.leaves_visited;
        self.prim_tests += o.prim_tests;
    }
}
