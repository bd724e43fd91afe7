//! `rt2_intersect` / `rt2_occluded`: batch ray queries in the record layout of
//! `../shared/raysets` (like Embree's rtcIntersect1M), run by the context's thread pool.

use super::context::rt2_context;
use super::ffi::{
    check_disjoint, check_out, guard, handle, read_versioned, slice, slice_mut, versioned,
    write_out,
};
use super::options::{
    intersector_from, intersector_to, query_mode_from, traversal_from, Rt2QueryMode,
};
use super::scene::rt2_scene;
use crate::context::QueryOptions;
use crate::cpu::query::QueryMode;
use crate::cpu::ray_order::{self, whole_bands};
use crate::dispatch::{choose_query_mode, Backend};
use crate::error::{Error, Rt2Status};
use crate::fallible;
use crate::geometry::{Hit, PrimIndex, Ray, TraversalStats, INVALID};
use crate::scene::PrimLookup;
use glam::Vec3;

/// One ray: `org + t * dir` for `t` in `[tmin, tmax)` (32 bytes, the `.rays` record). The
/// interval is half-open: a hit at exactly `tmax` does not count (Embree's `[tnear, tfar]` is
/// closed). `tmax = +inf` and `tmin = -inf` are accepted, and a negative `tmin` returns hits
/// behind the origin (the closest hit is the one of smallest `t`, not nearest the origin).
/// Every hit has a finite `t`: a crossing beyond `±FLT_MAX` along the ray (a direction of
/// 1e-45 reaches only 3e-7 from its origin) is a miss, whatever the window. A ray with a NaN
/// or infinite component of `org` or `dir`, a zero `dir`, a NaN `tmin` or `tmax`, or
/// `tmin > tmax` is a miss, not an error.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct rt2_ray {
    pub org: [f32; 3],
    pub tmin: f32,
    pub dir: [f32; 3],
    pub tmax: f32,
}

/// The closest hit of one ray. A miss has `t = +inf` and `object = prim = RT2_INVALID_ID`.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct rt2_hit {
    pub t: f32,
    /// Barycentric weight of the triangle's vertex 1 (0 for analytic primitives).
    pub u: f32,
    /// Barycentric weight of vertex 2.
    pub v: f32,
    /// Object id as returned by the `rt2_scene_add_*` call.
    pub object: u32,
    /// Triangle index inside a mesh (file face order for loaded meshes); 0 otherwise.
    pub prim: u32,
}

impl rt2_hit {
    /// The miss record's ids: no object, no primitive.
    pub(crate) fn is_miss(&self) -> bool {
        self.object == RT2_INVALID_ID && self.prim == RT2_INVALID_ID
    }
}

/// Per-call options of the ray queries.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct rt2_query_options {
    /// `sizeof(rt2_query_options)`: start from `rt2_query_options_default()`, which sets it.
    pub struct_size: u32,
    /// An `rt2_traversal` value (default AUTO).
    pub traversal: u32,
    /// Entries of the short stack, 1..=32 (default 3).
    pub short_stack_size: u32,
    /// An `rt2_query_mode` value (default AUTO; a zeroed struct says SINGLE). PACKET and STREAM
    /// follow the standard traversal's order whatever `traversal` says, and return the same
    /// hits. The GPU ignores `mode` and honours `traversal` (a job an AUTO context moves to the
    /// CPU takes `mode`).
    pub mode: u32,
    /// An `rt2_intersector` value (default MOLLER_TRUMBORE).
    pub intersector: u32,
    /// NULL (default), or one hit per ray: ray i ignores the primitive `exclude[i]` names by
    /// its `object` and `prim` (`t`, `u`, `v` are not read), e.g. the hit a secondary ray
    /// leaves (the exclude-prim offset of renders). A miss (both `RT2_INVALID_ID`) excludes
    /// nothing, nor does a primitive of a disabled object (`rt2_scene_set_enabled`); a removed
    /// object's id (`rt2_scene_remove`, said so in the message) and any other id the scene
    /// lacks is an INVALID_ARGUMENT. Every mode and the GPU honour it. It may be
    /// the call's own `hits` array (read whole before any hit is written). The first use
    /// builds a lookup of 4 bytes per primitive. A sphere, ellipsoid or box is one primitive,
    /// excluded whole: a ray that starts on a sphere and excludes it does not find the
    /// sphere's far side (the EXCLUDE_PRIM offset of renders gives such rays the robust offset
    /// instead).
    pub exclude: *const rt2_hit,
}

versioned!(rt2_query_options);

/// Work done by a query (the thesis' table 1 counters), summed over the batch and counted per
/// ray: a packet or stream step counts one node visit for each of its active rays. A
/// closest-hit query (`rt2_intersect`) in PACKET or STREAM mode therefore reports what SINGLE
/// reports with the standard traversal, and one on the GPU what the CPU reports with the same
/// traversal; other traversals visit other nodes. An any-hit query (`rt2_occluded`) counts,
/// in every mode and on the GPU, the same nodes and leaves and, for each ray, the primitives
/// of a leaf up to the first in its way (equal on the shared bunny and dragon ray sets), but
/// for leaves that hold triangles and other primitives together: PACKET and STREAM may test
/// such a leaf's triangles first, and stop at another primitive than SINGLE (so under AUTO
/// the count there depends on the mode it chose for the batch).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct rt2_query_stats {
    pub nodes_visited: u64,
    pub leaves_visited: u64,
    pub prim_tests: u64,
}

/// Default query options (AUTO traversal, AUTO mode).
#[no_mangle]
pub extern "C" fn rt2_query_options_default() -> rt2_query_options {
    let d = QueryOptions::default();
    rt2_query_options {
        struct_size: std::mem::size_of::<rt2_query_options>() as u32,
        traversal: 0,
        short_stack_size: d.short_stack_size as u32,
        mode: Rt2QueryMode::Auto as u32,
        intersector: intersector_to(d.intersector),
        exclude: std::ptr::null(),
    }
}

/// Marks "no object / no primitive" in hits.
pub const RT2_INVALID_ID: u32 = u32::MAX;

impl From<&rt2_ray> for Ray {
    fn from(r: &rt2_ray) -> Self {
        Ray::new(Vec3::from(r.org), Vec3::from(r.dir), r.tmin, r.tmax)
    }
}

/// The query options, and the per-ray exclusions (NULL for none).
unsafe fn query_options(
    opt: *const rt2_query_options,
) -> crate::error::Result<(QueryOptions, *const rt2_hit)> {
    if opt.is_null() {
        return Ok((QueryOptions::default(), std::ptr::null()));
    }
    let o = read_versioned(opt)?;
    let q = QueryOptions {
        traversal: traversal_from(o.traversal)?,
        short_stack_size: o.short_stack_size as usize,
        mode: query_mode_from(o.mode)?,
        intersector: intersector_from(o.intersector)?,
    };
    q.validate()?;
    Ok((q, o.exclude))
}

/// The primitives `exclude` names as the library's indices (4 bytes per ray, a fifth of the
/// hits' size; refused as OUT_OF_MEMORY when that much cannot be had), once every entry is
/// checked, and the placement they belong to (`Committed::placement`). Builds the scene's
/// lookup on first use, under the write lock; later queries only read.
fn excluded_all(
    scene: &super::scene::rt2_scene,
    exclude: &[rt2_hit],
) -> crate::error::Result<(Vec<PrimIndex>, u64)> {
    let mut global = fallible::with_capacity(exclude.len()).map_err(|_| {
        Error::out_of_memory(format!(
            "no memory for the {} excluded primitives of opt.exclude",
            exclude.len()
        ))
    })?;
    scene.with_lookup(true, |c, lookup| {
        for (i, h) in exclude.iter().enumerate() {
            global.push(match h.is_miss() {
                true => INVALID,
                false => named_prim(lookup, "opt.exclude", i, h)?,
            });
        }
        Ok((global, c.placement))
    })
}

/// The global index of the primitive that hit `h` (not a miss), entry `i` of the caller's
/// array `what`, names: `INVALID` for a primitive of a disabled object (the id is the
/// scene's; the committed scene left it out); an error naming the entry if the scene lacks it,
/// saying so when its object was removed.
pub(crate) fn named_prim(
    lookup: &PrimLookup,
    what: &str,
    i: usize,
    h: &rt2_hit,
) -> crate::error::Result<PrimIndex> {
    lookup.get(h.object, h.prim).ok_or_else(|| {
        if lookup.removed(h.object) {
            return Error::invalid_argument(format!(
                "{what}[{i}] names object {}, which was removed (rt2_scene_remove)",
                h.object
            ));
        }
        Error::invalid_argument(format!(
            "{what}[{i}] names object {} primitive {}, which the scene lacks (a miss has \
             both ids RT2_INVALID_ID)",
            h.object, h.prim
        ))
    })
}

/// Rays converted and traced per step of a C query. The library's own copies (rays in its
/// layout, hits before they are written out) then stay bounded whatever `count` the caller
/// passes: for a billion rays, whole copies would be tens of GB, and a failed allocation
/// aborts the process.
const QUERY_CHUNK: usize = 1 << 20;

/// Most rays a query stages on the stack rather than on the heap: a loop of one-ray calls (a
/// port of `rtcIntersect1`) then allocates nothing per call. The two heap copies (rays and
/// answers) were a fifth of the instructions of a one-ray call that hits nothing (callgrind:
/// 1958 -> 1571); 16 would cost a one-ray call 90 more, to fill the larger arrays.
const SMALL_STEP: usize = 8;

/// A copy of one step's rays or answers in the library's types: on the stack for up to
/// [`SMALL_STEP`] of them, else on the heap (reused from step to step).
struct Staging<T> {
    small: [T; SMALL_STEP],
    large: Vec<T>,
}

impl<T: Copy> Staging<T> {
    /// `unset` fills the stack array until [`Staging::hold`] overwrites it. Inlined, so that
    /// the array is built in place: moved out of a call, it cost a copy of itself.
    #[inline(always)]
    fn new(unset: T) -> Self {
        Staging {
            small: [unset; SMALL_STEP],
            large: Vec::new(),
        }
    }

    /// `items`, staged.
    #[inline(always)]
    fn hold(&mut self, items: impl ExactSizeIterator<Item = T>) -> &mut [T] {
        let n = items.len();
        if n <= SMALL_STEP {
            self.small.iter_mut().zip(items).for_each(|(to, x)| *to = x);
            return &mut self.small[..n];
        }
        self.large.clear();
        self.large.extend(items);
        &mut self.large
    }
}

/// Shared prologue of both queries: checks, ropes on demand, the committed scene; then the
/// rays in steps of [`QUERY_CHUNK`]. It takes the C call's arguments as they are, hence their
/// number; `between` runs where another thread's commit could come between reading the
/// exclusions and tracing (`rt2_scene::prepared`), a no-op but in the tests.
#[allow(clippy::too_many_arguments)]
unsafe fn run_query<T>(
    ctx: *const rt2_context,
    scene: *const rt2_scene,
    rays: *const rt2_ray,
    count: usize,
    (out, out_name): (*mut T, &str),
    opt: *const rt2_query_options,
    stats: *mut rt2_query_stats,
    f: impl Fn(
        &crate::context::Context,
        &crate::scene::Committed,
        (&[Ray], Option<&[PrimIndex]>),
        &mut [T],
        &QueryOptions,
    ) -> crate::error::Result<TraversalStats>,
    between: impl Fn(),
) -> Rt2Status {
    guard(|| {
        let c = handle(ctx, "ctx")?;
        let s = handle(scene, "scene")?;
        let (q, exclude) = query_options(opt)?;
        let rays = slice(rays, count, "rays")?;
        // The outputs checked now (NULL, size, alignment), the hits borrowed below once the
        // exclusions are read (and only once they are known not to overlap the rays: a `&mut`
        // over the rays while `rays` is borrowed would be undefined behaviour, even unused).
        slice(out as *const T, count, out_name)?;
        // The hits are written while the rays are read (one step at a time).
        check_disjoint((out, count, out_name), (rays.as_ptr(), count, "rays"))?;
        if !stats.is_null() {
            check_out(stats, "stats")?;
            // Written last, while the rays are still borrowed and over the finished hits.
            check_disjoint((stats, 1, "stats"), (rays.as_ptr(), count, "rays"))?;
            check_disjoint((stats, 1, "stats"), (out, count, out_name))?;
        }
        // A job the backend refuses is refused before anything is built for it.
        c.inner.check_query(&q)?;
        // The exclusions, read whole before the output is borrowed: `exclude` may be the very
        // array the hits go to (ray i leaving hit i). Every entry is checked before anything
        // is written or built.
        let exclude = match exclude.is_null() || count == 0 {
            true => None,
            false => Some(excluded_all(s, slice(exclude, count, "opt.exclude")?)?),
        };
        // `query_options` validated the options (defaults are valid): refused ones never reach
        // the ropes or exact vertices built here, so a failed call leaves the scene as it was.
        // Ropes (about 3x the tree) serve a rope traversal of single rays, and any GPU job
        // (its kernels take the traversal whatever the mode); the CPU's packets and streams
        // follow the standard order and never read them.
        // Whether a rope traversal runs one ray at a time does not depend on the batch
        // (`dispatch::choose_query_mode`: AUTO takes single rays for it), so it is asked here
        // with none.
        let ropes = q.traversal.is_some_and(|t| {
            t.needs_ropes()
                && (choose_query_mode(&[], q.mode, t).0 == QueryMode::Single
                    || c.inner.decision().backend == Backend::Gpu)
        });
        let guard = s.prepared_with(
            ropes,
            q.intersector == crate::precision::Intersector::Watertight,
            between,
        )?;
        let committed = guard.committed()?;
        let out = slice_mut(out, count, out_name)?;
        if exclude
            .as_ref()
            .is_some_and(|(_, id)| *id != committed.placement)
        {
            // Another thread committed between the lookup and the trace.
            return Err(Error::invalid_operation(
                "the scene was committed again while this query read opt.exclude: its \
                 primitives may be numbered differently now; query again",
            ));
        }
        let exclude = exclude.map(|(e, _)| e);
        let mut st = TraversalStats::default();
        let mut step = Staging::new(Ray::new(Vec3::ZERO, Vec3::ZERO, 0.0, 0.0));
        // Steps of whole bands of an image's rows: each step's packets then take the image in
        // tiles, as one call over the whole image would (`cpu::ray_order`). A batch of one
        // step needs no look: `cpu::query` finds its rows itself.
        let size = if rays.len() > QUERY_CHUNK {
            let order = ray_order::detect_in(rays.len(), |i| Ray::from(&rays[i]));
            whole_bands(order, QUERY_CHUNK)
        } else {
            QUERY_CHUNK
        };
        for (k, (rays, out)) in rays.chunks(size).zip(out.chunks_mut(size)).enumerate() {
            let step = step.hold(rays.iter().map(Ray::from));
            let step_exclude = exclude.as_ref().map(|e| &e[k * size..][..rays.len()]);
            st.add(&f(&c.inner, committed, (step, step_exclude), out, &q)?);
        }
        if !stats.is_null() {
            write_out(
                stats,
                "stats",
                rt2_query_stats {
                    nodes_visited: st.nodes_visited,
                    leaves_visited: st.leaves_visited,
                    prim_tests: st.prim_tests,
                },
            )?;
        }
        Ok(())
    })
}

/// Closest hits of `count` rays into `hits`. `opt` may be NULL (defaults); `stats` may be NULL
/// (not collected). Rays are traced in steps of at most 2^20 (whole bands of four rows when they
/// are a camera image in scanline order, so that packets take the image in tiles across the
/// steps): on failure `hits` is untouched unless the backend failed part-way (internal error,
/// GPU lost or out of memory, or on lavapipe a later step's rays cut short by the driver:
/// `RT2_BACKEND_GPU`), which leaves the earlier steps' hits written.
///
/// `hits` overlapping `rays` is an INVALID_ARGUMENT (`opt->exclude` may be `hits` itself).
///
/// # Safety
/// Handles are live; `rays` and `hits` hold `count` elements (may be NULL when count is 0).
#[no_mangle]
pub unsafe extern "C" fn rt2_intersect(
    ctx: *const rt2_context,
    scene: *const rt2_scene,
    rays: *const rt2_ray,
    count: usize,
    hits: *mut rt2_hit,
    opt: *const rt2_query_options,
    stats: *mut rt2_query_stats,
) -> Rt2Status {
    run_query(
        ctx,
        scene,
        rays,
        count,
        (hits, "hits"),
        opt,
        stats,
        |c, committed, (rays, exclude), out, q| {
            let mut staged = Staging::new(Hit::MISS);
            let inner = staged.hold(std::iter::repeat_n(Hit::MISS, rays.len()));
            let st = match exclude {
                None => c.intersect(committed, rays, inner, q)?,
                Some(e) => c.intersect_excluding(committed, rays, e, inner, q)?,
            };
            for (h, o) in inner.iter().zip(out.iter_mut()) {
                *o = if h.is_hit() {
                    let origin = committed.origins[h.prim as usize];
                    let (u, v) = committed.object_uv(origin.object, h.u, h.v);
                    rt2_hit {
                        t: h.t,
                        u,
                        v,
                        object: origin.object,
                        prim: origin.prim,
                    }
                } else {
                    rt2_hit {
                        t: f32::INFINITY,
                        u: 0.0,
                        v: 0.0,
                        object: RT2_INVALID_ID,
                        prim: RT2_INVALID_ID,
                    }
                };
            }
            Ok(st)
        },
        || {},
    )
}

/// Any-hit queries: `occluded[i]` becomes 1 when something lies in ray i's `[tmin, tmax)`,
/// else 0 (shadow rays). Failures leave `occluded` as `rt2_intersect` leaves `hits`;
/// `occluded` overlapping `rays` is an INVALID_ARGUMENT.
///
/// # Safety
/// Handles are live; `rays` and `occluded` hold `count` elements (may be NULL when count is 0).
#[no_mangle]
pub unsafe extern "C" fn rt2_occluded(
    ctx: *const rt2_context,
    scene: *const rt2_scene,
    rays: *const rt2_ray,
    count: usize,
    occluded: *mut u8,
    opt: *const rt2_query_options,
    stats: *mut rt2_query_stats,
) -> Rt2Status {
    run_query(
        ctx,
        scene,
        rays,
        count,
        (occluded, "occluded"),
        opt,
        stats,
        |c, committed, (rays, exclude), out, q| {
            let mut staged = Staging::new(false);
            let inner = staged.hold(std::iter::repeat_n(false, rays.len()));
            let st = match exclude {
                None => c.occluded(committed, rays, inner, q)?,
                Some(e) => c.occluded_excluding(committed, rays, e, inner, q)?,
            };
            for (b, o) in inner.iter().zip(out.iter_mut()) {
                *o = *b as u8;
            }
            Ok(st)
        },
        || {},
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::api::scene::tests::{destroy, triangle_scene};
    use crate::api::{rt2_last_error_message, Rt2Intersector, RT2_INVALID_ID};
    use std::cell::Cell;
    use std::ffi::CStr;
    use std::ptr::null_mut;

    /// A rebuilding commit by another thread after the exclusions were read (here while a
    /// watertight query builds its exact corners) may renumber the primitives: the query fails with
    /// INVALID_OPERATION and writes nothing, rather than exclude by the old numbering. A
    /// commit of new lights alone keeps the numbering, and the query runs.
    #[test]
    fn a_commit_after_the_exclusions_were_read_fails_the_query() {
        let made = triangle_scene();
        let (ctx, scene) = made;
        unsafe {
            let ray = rt2_ray {
                org: [0.2, 0.2, 1.0],
                tmin: 0.0,
                dir: [0.0, 0.0, -1.0],
                tmax: f32::INFINITY,
            };
            let triangle = rt2_hit {
                t: 0.0,
                u: 0.0,
                v: 0.0,
                object: 0,
                prim: 0,
            };
            let mut opt = rt2_query_options_default();
            opt.intersector = Rt2Intersector::Watertight as u32;
            opt.exclude = &triangle;
            let untouched = rt2_hit {
                t: -1.0,
                ..triangle
            };
            let s = &*scene;
            // The query, with `edit` committed by "another thread" while it builds the exact
            // corners; a traced ray's hit gets `t` = inf.
            let query_while = |edit: &dyn Fn(&mut crate::scene::Scene)| {
                let (mut hit, edited) = (untouched, Cell::new(false));
                let st = run_query(
                    ctx,
                    scene,
                    &ray,
                    1,
                    (&mut hit as *mut rt2_hit, "hits"),
                    &opt,
                    null_mut(),
                    |_, _, _, out, _| {
                        out[0].t = f32::INFINITY;
                        Ok(TraversalStats::default())
                    },
                    || {
                        if !edited.replace(true) {
                            edit(&mut s.write());
                        }
                    },
                );
                assert!(edited.get(), "the commit did not happen");
                (st, hit)
            };
            let (st, hit) = query_while(&|w| w.rebuild().unwrap());
            let message = CStr::from_ptr(rt2_last_error_message()).to_string_lossy();
            assert_eq!(st, Rt2Status::InvalidOperation, "{message}");
            assert!(message.contains("committed again"), "{message}");
            assert_eq!((hit.t, hit.object), (untouched.t, untouched.object));
            // Asked again, the query runs: the one triangle excluded, a miss.
            let mut hit = untouched;
            let st = rt2_intersect(ctx, scene, &ray, 1, &mut hit, &opt, null_mut());
            assert_eq!((st, hit.object), (Rt2Status::Ok, RT2_INVALID_ID));

            // A commit of a new light alone keeps the numbering: the query runs. (Refused
            // before, as the commit's id changed.) A rebuild first drops the exact corners,
            // for the query to build them again and commit while it does.
            s.write().rebuild().unwrap();
            let (st, hit) = query_while(&|w| {
                let light = crate::scene::PointLight {
                    position: Vec3::ONE,
                    color: Vec3::ONE,
                    intensity: 1.0,
                };
                w.add_light(light).unwrap();
                w.commit().unwrap();
            });
            assert_eq!((st, hit.t), (Rt2Status::Ok, f32::INFINITY), "traced");
        }
        destroy(made);
    }
}
