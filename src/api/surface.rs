//! `rt2_hit_surfaces`: what shading the hits of `rt2_intersect` needs beyond the hit itself
//! (Embree puts the geometric normal in every `RTCHit`; here it is asked for in a batch): the
//! point on the surface, the geometric normal and the material, from the committed scene.

use super::ffi::{check_disjoint, guard, handle, slice, slice_mut};
use super::query::{named_prim, rt2_hit, rt2_ray, RT2_INVALID_ID};
use super::scene::rt2_scene;
use crate::error::{Error, Result, Rt2Status};
use crate::geometry::{Hit, PrimKind, Ray, INVALID};
use crate::scene::{Committed, HitSurface, PrimLookup};

/// The surface at one hit, in world space (28 bytes).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct rt2_surface {
    /// The hit point recomputed on the primitive, not `org + t * dir`: from the hit's `u`, `v`
    /// on triangles; `org + t * dir` moved onto the sphere, ellipsoid, box face or plane
    /// otherwise (the robust offset's point, README "Precision modes"; on spheres and
    /// ellipsoids taken relative to the centre, `(org - center) + t * dir`, which keeps the
    /// normal accurate far from the origin). A plane met so far away that the point lies
    /// beyond the f32 range has infinite coordinates there.
    pub position: [f32; 3],
    /// The geometric normal, unit length and not turned towards the ray: outward on spheres,
    /// ellipsoids and boxes; a plane's `normal` as added; on a triangle, the side of
    /// `(v1 - v0) × (v2 - v0)` of its corners as given. An object's transform carries it by
    /// its inverse transpose (a mirroring one included: a closed mesh stays outward).
    pub normal: [f32; 3],
    /// The material id of the hit's object.
    pub material: u32,
}

/// What a miss gets: every coordinate 0 (a zero normal) and material `RT2_INVALID_ID`.
const NO_SURFACE: rt2_surface = rt2_surface {
    position: [0.0; 3],
    normal: [0.0; 3],
    material: RT2_INVALID_ID,
};

/// The surfaces at `count` hits: `surfaces[i]` for `hits[i]`, the closest hit of `rays[i]` by
/// `rt2_intersect` (any context, mode or backend) on this scene's current commit. Ids stay
/// the same across commits, but an object moved since the query is answered as it is now
/// (its surface, off the ray), which this call cannot tell from a hit of the current commit;
/// a hit on an object disabled or removed since is refused. A miss (`object = prim =
/// RT2_INVALID_ID`) gets zero `position` and `normal` and material `RT2_INVALID_ID`, not an
/// error.
///
/// Every entry is checked before anything is written; on any error `surfaces` is untouched:
/// INVALID_ARGUMENT for a hit naming an object or primitive the committed scene lacks (a disabled
/// object's too, and a removed one's, which the message says), a hit with a non-finite `t`, `u` or
/// `v`, a triangle hit whose `u`, `v` lie outside the triangle (beyond 1e-4 of rounding) or a ray
/// that always misses (a non-finite `org` or `dir`, a zero `dir`, a NaN `tmin` or
/// `tmax`, `tmin > tmax`; a query never returns such a hit), a hit whose point is too far from its
/// sphere or ellipsoid to be put on the surface (a `t` no query returns: 3e38 on a unit sphere 5
/// units away; a point that far off which the rounding of a huge ray explains, as for a direction
/// 1e36 long, is answered with the entry of a line through the centre along the ray), NULL
/// arrays when `count > 0`, `surfaces` overlapping `rays` or `hits`, or a bad
/// handle; INVALID_OPERATION for a scene never committed or edited since its commit. `count = 0`
/// with NULL arrays is fine (the scene is still checked, as `rt2_intersect` does). Runs on the
/// calling thread under the scene's read lock, like a query, and allocates nothing but the lookup
/// of `rt2_query_options.exclude`: the first call that names a primitive builds it under the write
/// lock (4 bytes per primitive, kept until a commit places the objects again: `bytes_prim_lookup`).
///
/// # Safety
/// `scene` is a live scene; `rays`, `hits` and `surfaces` hold `count` elements (may be NULL
/// when count is 0).
#[no_mangle]
pub unsafe extern "C" fn rt2_hit_surfaces(
    scene: *const rt2_scene,
    rays: *const rt2_ray,
    hits: *const rt2_hit,
    count: usize,
    surfaces: *mut rt2_surface,
) -> Rt2Status {
    guard(|| {
        let s = handle(scene, "scene")?;
        let rays = slice(rays, count, "rays")?;
        let hits = slice(hits, count, "hits")?;
        slice(surfaces, count, "surfaces")?;
        check_disjoint(
            (surfaces, count, "surfaces"),
            (rays.as_ptr(), count, "rays"),
        )?;
        check_disjoint(
            (surfaces, count, "surfaces"),
            (hits.as_ptr(), count, "hits"),
        )?;
        let out = slice_mut(surfaces, count, "surfaces")?;
        let named = hits.iter().any(|h| !h.is_miss());
        s.with_lookup(named, |c, lookup| {
            // Every entry checked (its surface computed) before any is written, then computed
            // again while writing, where keeping the surfaces would allocate per call. That
            // cost 1.17x the time of checking the hits alone on the bunny's hits and 1.7x on
            // spheres' (1024² rays, one thread); checking only the kinds whose normal can be
            // missing cost more on the bunny (1.3x: the check reads every triangle).
            for (i, (r, h)) in rays.iter().zip(hits).enumerate() {
                surface(c, lookup, i, &Ray::from(r), h)?;
            }
            for (i, ((r, h), o)) in rays.iter().zip(hits).zip(out.iter_mut()).enumerate() {
                *o = surface(c, lookup, i, &Ray::from(r), h)?.map_or(NO_SURFACE, |s| rt2_surface {
                    position: s.position.to_array(),
                    normal: s.normal.to_array(),
                    material: s.material,
                });
            }
            Ok(())
        })
    })
}

/// Entry `i`'s surface (`None` for a miss), once its hit is checked. A hit without a unit
/// normal (`Committed::hit_surface`) is refused rather than answered with a zero normal.
fn surface(
    c: &Committed,
    lookup: &PrimLookup,
    i: usize,
    ray: &Ray,
    h: &rt2_hit,
) -> Result<Option<HitSurface>> {
    let surface = |hit| {
        c.hit_surface(ray, &hit).ok_or_else(|| {
            Error::invalid_argument(format!(
                "hits[{i}] at t = {:?} on object {} primitive {}: that point of rays[{i}] cannot \
                 be put on the primitive's surface (no query returns such a hit)",
                h.t, h.object, h.prim
            ))
        })
    };
    library_hit(c, lookup, i, ray, h)?.map(surface).transpose()
}

/// How far a triangle hit's barycentrics may lie outside the triangle: the intersectors'
/// rounding (the watertight test divides by the sum of its edge functions) stays far inside it,
/// and weights past it name a point off the triangle, which `surface_at` would extrapolate.
const BARYCENTRIC_SLACK: f32 = 1e-4;

/// Whether barycentric weights `u`, `v` (and `1 - u - v`) name a point of the triangle.
fn within_triangle(u: f32, v: f32) -> bool {
    u >= -BARYCENTRIC_SLACK && v >= -BARYCENTRIC_SLACK && u + v <= 1.0 + BARYCENTRIC_SLACK
}

/// Entry `i`'s hit in the library's numbering (`None` for a miss), once checked.
fn library_hit(
    c: &Committed,
    lookup: &PrimLookup,
    i: usize,
    ray: &Ray,
    h: &rt2_hit,
) -> Result<Option<Hit>> {
    if h.is_miss() {
        return Ok(None);
    }
    let prim = named_prim(lookup, "hits", i, h)?;
    if prim == INVALID {
        return Err(Error::invalid_argument(format!(
            "hits[{i}] names object {} primitive {}, whose object is disabled in the committed \
             scene (rt2_scene_set_enabled): no query of this commit hits it",
            h.object, h.prim
        )));
    }
    if ![h.t, h.u, h.v].iter().all(|x| x.is_finite()) {
        return Err(Error::invalid_argument(format!(
            "hits[{i}] has t = {:?}, u = {:?}, v = {:?}: a hit has finite ones",
            h.t, h.u, h.v
        )));
    }
    let triangle = matches!(c.prims.locate(prim as usize).0, PrimKind::Triangle);
    if triangle && !within_triangle(h.u, h.v) {
        return Err(Error::invalid_argument(format!(
            "hits[{i}] has u = {:?}, v = {:?} on a triangle: a point of it has u, v >= 0 and \
             u + v <= 1 (no query returns such a hit)",
            h.u, h.v
        )));
    }
    if ray.is_degenerate() {
        return Err(Error::invalid_argument(format!(
            "rays[{i}] has org {}, dir {}, window [{}, {}), but hits[{i}] is a hit: a ray with \
             a non-finite or zero direction, a non-finite origin, a NaN window end or \
             tmin > tmax misses",
            ray.org, ray.dir, ray.tmin, ray.tmax
        )));
    }
    let (u, v) = c.object_uv(h.object, h.u, h.v);
    Ok(Some(Hit { t: h.t, u, v, prim }))
}
