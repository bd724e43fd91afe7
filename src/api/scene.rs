//! `rt2_scene`: geometry, materials and lights. Edits and commit take the scene's write lock
//! and renders its read lock, so concurrent calls never corrupt it: committed scenes may be
//! rendered and queried from many threads at once; an edit waits for running renders.

use super::context::rt2_context;
use super::ffi::{
    array, check_out, destroy, guard, handle, handle_type, path_arg, read_versioned, slice,
    write_out, Handle,
};
use super::options::{rt2_build_options, rt2_material};
use crate::context::Context;
use crate::error::{Error, Result, Rt2Status};
use crate::fallible;
use crate::precision::Intersector;
use crate::read_mostly::{ReadGuard, ReadMostly, WriteGuard};
use crate::scene::{loaders, Committed, PointLight, PrimLookup, Scene, Shape};
use glam::{Affine3A, Mat3, Vec3};
use std::sync::Arc;

/// Opaque scene handle. Material 0 exists from the start (the default material).
#[repr(C)]
pub struct rt2_scene {
    /// First field of every handle, so checking it never reads past a handle of another type.
    magic: u64,
    pub(crate) context: Arc<Context>,
    /// Read by every query and render, written by edits and commits ([`ReadMostly`]: threads
    /// querying at once share no lock word).
    scene: ReadMostly<Scene>,
}

// A scene commits on its context's worker threads.
handle_type!(rt2_scene, 0x7274_325f_7363_6e00, |s: &rt2_scene| s
    .context
    .same_process());

impl rt2_scene {
    /// A panic while holding the lock leaves the scene as it was before the failed edit (all
    /// edits validate before they change anything), so a poisoned lock is still usable.
    pub(crate) fn read(&self) -> ReadGuard<'_, Scene> {
        self.scene.read()
    }

    pub(crate) fn write(&self) -> WriteGuard<'_, Scene> {
        self.scene.write()
    }

    /// The committed scene under the read lock, with what a job needs that is built on demand:
    /// ropes for a rope traversal, exact corners for the watertight test. They are built under
    /// the write lock, then checked again under the read lock the job runs under: another
    /// thread may commit in between, and a new commit has neither (a watertight job would
    /// then run on corners rebuilt from the edges, unsound, with nothing to say so). Gives up
    /// after a few such commits in a row.
    pub(crate) fn prepared(&self, ropes: bool, watertight: bool) -> Result<ReadGuard<'_, Scene>> {
        self.prepared_with(ropes, watertight, || {})
    }

    /// [`rt2_scene::prepared`], calling `between` each time it has built what was missing and
    /// holds no lock: where the tests commit, as another thread may.
    pub(crate) fn prepared_with(
        &self,
        ropes: bool,
        watertight: bool,
        between: impl Fn(),
    ) -> Result<ReadGuard<'_, Scene>> {
        for _ in 0..PREPARE_ROUNDS {
            let guard = self.read();
            let c = guard.committed()?;
            let has_ropes = !ropes || c.tree.ropes.is_some();
            let has_corners = !watertight || !c.prims.rebuilds_corners(Intersector::Watertight);
            if has_ropes && has_corners {
                return Ok(guard);
            }
            drop(guard);
            let mut scene = self.write();
            if ropes {
                scene.ensure_ropes()?;
            }
            if watertight {
                scene.ensure_exact_vertices()?;
            }
            drop(scene);
            between();
        }
        Err(Error::invalid_operation(format!(
            "the scene was committed {PREPARE_ROUNDS} times by other threads while this job \
             built its ropes or exact corners; run it again"
        )))
    }

    /// Runs `f` on the committed scene and its [`PrimLookup`] (the public `(object, prim)` ids
    /// to the library's), for calls that take hits. With `build`, a lookup not yet built is
    /// built first, under the write lock, where `f` then runs too: no commit comes between,
    /// and the lookup is kept only when `f` succeeds. Otherwise (the lookup is there, or `f`
    /// reads no ids: the lookup may be empty) under the read lock, as queries run.
    pub(crate) fn with_lookup<R>(
        &self,
        build: bool,
        f: impl FnOnce(&Committed, &PrimLookup) -> Result<R>,
    ) -> Result<R> {
        {
            let r = self.read();
            let c = r.committed()?;
            if !build || !c.lookup.is_empty() {
                return f(c, &c.lookup);
            }
        }
        self.write().ensure_prim_lookup(f)
    }
}

/// Rounds of [`rt2_scene::prepared`] before it gives up.
const PREPARE_ROUNDS: usize = 8;

/// Runs an edit that yields an id, writing the id only on success.
unsafe fn edit_with_id(
    scene: *mut rt2_scene,
    out: (*mut u32, &str),
    f: impl FnOnce(&mut Scene) -> Result<u32>,
) -> Rt2Status {
    prepare_and_edit(scene, out, || Ok(()), |s, ()| f(s))
}

/// [`edit_with_id`] with a `prepare` step run before the scene is locked (reading a file can
/// take any time, and renders and edits of the scene must not wait for it).
unsafe fn prepare_and_edit<P>(
    scene: *mut rt2_scene,
    (out_id, out_name): (*mut u32, &str),
    prepare: impl FnOnce() -> Result<P>,
    f: impl FnOnce(&mut Scene, P) -> Result<u32>,
) -> Rt2Status {
    guard(|| {
        let s = handle(scene, "scene")?;
        // Optional: NULL when the caller does not want the id.
        let out_id = (!out_id.is_null()).then_some(out_id);
        if let Some(out) = out_id {
            check_out(out, out_name)?;
        }
        let prepared = prepare()?;
        let id = f(&mut s.write(), prepared)?;
        if let Some(out) = out_id {
            write_out(out, out_name, id)?;
        }
        Ok(())
    })
}

/// Creates an empty scene that keeps `ctx` alive: its commits run on `ctx`'s worker threads,
/// also after `rt2_context_destroy(ctx)`. Renders and queries of the scene may pass any live
/// context of the process, CPU or GPU, not only `ctx`.
///
/// Material 0, the default material (`rt2_material_default`), exists from the start.
/// Objects (of every `rt2_scene_add_*` shape and `rt2_scene_load_file`), materials and lights
/// are numbered from 0 in the order added, each kind on its own. An object can be removed
/// (`rt2_scene_remove`; its id is not given again), disabled and enabled again
/// (`rt2_scene_set_enabled`) and its transform changed (`rt2_scene_set_transform`):
/// materials, lights and an object's material are fixed once added, and cannot be removed.
/// A scene gives at most 2^32 - 1 object ids (0 to `RT2_INVALID_ID` - 1), removed ones
/// included: an add past them is UNSUPPORTED, and one whose id's slot (8 bytes) cannot be
/// allocated is OUT_OF_MEMORY, with nothing added. It holds fewer than 2^30 primitives at
/// once (a triangle each, one per analytic shape; removed objects' no longer count): an add
/// that would reach 2^30 is UNSUPPORTED too.
///
/// # Safety
/// `ctx` is a live context; `out` is writable.
#[no_mangle]
pub unsafe extern "C" fn rt2_scene_create(
    ctx: *const rt2_context,
    out: *mut *mut rt2_scene,
) -> Rt2Status {
    guard(|| {
        let c = handle(ctx, "ctx")?;
        check_out(out, "out")?;
        let h = Box::new(rt2_scene {
            magic: rt2_scene::MAGIC,
            context: c.inner.clone(),
            scene: ReadMostly::new(Scene::new()),
        });
        write_out(out, "out", Box::into_raw(h))
    })
}

/// Frees a scene. NULL is a no-op. Must not overlap with other calls on the scene.
///
/// # Safety
/// `scene` is NULL or a scene not yet destroyed.
#[no_mangle]
pub unsafe extern "C" fn rt2_scene_destroy(scene: *mut rt2_scene) {
    guard(|| {
        destroy(scene);
        Ok(())
    });
}

/// Adds a material; `*out_id` (may be NULL) receives its id (the first is 1: material 0 is
/// the default). A material cannot be changed once added.
///
/// # Safety
/// `scene` is a live scene; `material` points to an `rt2_material`.
#[no_mangle]
pub unsafe extern "C" fn rt2_scene_add_material(
    scene: *mut rt2_scene,
    material: *const rt2_material,
    out_id: *mut u32,
) -> Rt2Status {
    edit_with_id(scene, (out_id, "out_id"), |s| {
        if material.is_null() {
            return Err(Error::invalid_argument("material is NULL"));
        }
        s.add_material(read_versioned(material)?.to_material()?)
    })
}

/// Adds a point light at `position` with colour `rgb` (>= 0) scaled by `intensity` (>= 0);
/// `*out_id` (may be NULL) receives its id, numbered from 0 apart from object ids (no call
/// takes it yet: a light cannot be changed once added). Light does not fall off with
/// distance: a surface facing the light is lit alike at any distance. Without lights,
/// surfaces are lit by their material's ambient term only.
///
/// # Safety
/// `scene` is a live scene; the arrays hold 3 floats.
#[no_mangle]
pub unsafe extern "C" fn rt2_scene_add_point_light(
    scene: *mut rt2_scene,
    position: *const f32,
    rgb: *const f32,
    intensity: f32,
    out_id: *mut u32,
) -> Rt2Status {
    edit_with_id(scene, (out_id, "out_id"), |s| {
        let position = Vec3::from(array::<f32, 3>(position, "position")?);
        let color = Vec3::from(array::<f32, 3>(rgb, "rgb")?);
        s.add_light(PointLight {
            position,
            color,
            intensity,
        })
    })
}

/// Adds a triangle mesh: `vertex_count` xyz positions and `triangle_count` index triples.
/// The data is copied. `*out_object` (may be NULL) receives the object id. A mesh of no
/// triangles (with or without vertices) is an object too, which nothing hits, as in Embree.
///
/// `RT2_STATUS_INVALID_ARGUMENT` (and nothing added) for a non-finite position, an index past
/// `vertex_count`, or a triangle that does not fit in f32 in world space: its corners, its
/// edges or the product of its edge lengths overflow (README, "Range").
///
/// # Safety
/// `positions` holds 3 × vertex_count floats, `indices` 3 × triangle_count integers.
#[no_mangle]
pub unsafe extern "C" fn rt2_scene_add_mesh(
    scene: *mut rt2_scene,
    positions: *const f32,
    vertex_count: usize,
    indices: *const u32,
    triangle_count: usize,
    material: u32,
    out_object: *mut u32,
) -> Rt2Status {
    edit_with_id(scene, (out_object, "out_object"), |s| {
        let n3 = |n: usize, what: &str| {
            n.checked_mul(3)
                .ok_or_else(|| Error::invalid_argument(format!("{what} overflows")))
        };
        let p = slice(
            positions,
            n3(vertex_count, "vertex_count")?,
            "positions (3 x vertex_count floats)",
        )?;
        let i = slice(
            indices,
            n3(triangle_count, "triangle_count")?,
            "indices (3 x triangle_count integers)",
        )?;
        if vertex_count > u32::MAX as usize {
            return Err(Error::invalid_argument("vertex_count exceeds 2^32 - 1"));
        }
        let shape = Shape::Mesh {
            positions: fallible::collect(p.chunks_exact(3).map(Vec3::from_slice))?,
            triangles: fallible::collect(i.chunks_exact(3).map(|t| [t[0], t[1], t[2]]))?,
        };
        s.add_object(shape, material)
    })
}

/// Adds a sphere (radius > 0). It stays analytic. INVALID_ARGUMENT (and nothing added) also
/// for one that does not fit in f32 in world space: the square of its radius must be a normal
/// f32 (a radius from about 1.1e-19 to 1.8e19) and its bounds finite (README, "Range").
///
/// # Safety
/// `scene` is a live scene; `center` holds 3 floats.
#[no_mangle]
pub unsafe extern "C" fn rt2_scene_add_sphere(
    scene: *mut rt2_scene,
    center: *const f32,
    radius: f32,
    material: u32,
    out_object: *mut u32,
) -> Rt2Status {
    edit_with_id(scene, (out_object, "out_object"), |s| {
        let center = Vec3::from(array::<f32, 3>(center, "center")?);
        s.add_object(Shape::Sphere { center, radius }, material)
    })
}

/// Adds an axis-aligned ellipsoid with semi-axes `radii` (each > 0); a transform may rotate it.
/// INVALID_ARGUMENT (and nothing added) also for one that does not fit in f32 in world space:
/// each semi-axis squared must neither overflow nor vanish (semi-axes from about 2.7e-23 to
/// 1.8e19), and its bounds and inverse map must be finite (README, "Range").
///
/// # Safety
/// `scene` is a live scene; `center` and `radii` hold 3 floats.
#[no_mangle]
pub unsafe extern "C" fn rt2_scene_add_ellipsoid(
    scene: *mut rt2_scene,
    center: *const f32,
    radii: *const f32,
    material: u32,
    out_object: *mut u32,
) -> Rt2Status {
    edit_with_id(scene, (out_object, "out_object"), |s| {
        let center = Vec3::from(array::<f32, 3>(center, "center")?);
        let radii = Vec3::from(array::<f32, 3>(radii, "radii")?);
        s.add_object(Shape::Ellipsoid { center, radii }, material)
    })
}

/// Adds a solid axis-aligned box from `min` to `max` (componentwise `min <= max`).
///
/// # Safety
/// `scene` is a live scene; `min` and `max` hold 3 floats.
#[no_mangle]
pub unsafe extern "C" fn rt2_scene_add_box(
    scene: *mut rt2_scene,
    min: *const f32,
    max: *const f32,
    material: u32,
    out_object: *mut u32,
) -> Rt2Status {
    edit_with_id(scene, (out_object, "out_object"), |s| {
        let min = Vec3::from(array::<f32, 3>(min, "min")?);
        let max = Vec3::from(array::<f32, 3>(max, "max")?);
        s.add_object(Shape::Box { min, max }, material)
    })
}

/// Adds the infinite plane `dot(normal, x) = offset` (`normal` non-zero, any length).
/// INVALID_ARGUMENT (and nothing added) also for a plane that does not fit in f32 in world
/// space: `offset` divided by the normal's largest component must be finite (normal
/// `(1e-45, 0, 0)` with offset 1 is refused).
///
/// # Safety
/// `scene` is a live scene; `normal` holds 3 floats.
#[no_mangle]
pub unsafe extern "C" fn rt2_scene_add_plane(
    scene: *mut rt2_scene,
    normal: *const f32,
    offset: f32,
    material: u32,
    out_object: *mut u32,
) -> Rt2Status {
    edit_with_id(scene, (out_object, "out_object"), |s| {
        let normal = Vec3::from(array::<f32, 3>(normal, "normal")?);
        s.add_object(Shape::Plane { normal, offset }, material)
    })
}

/// Loads a triangle mesh from a `.ply` (ASCII or binary) or `.obj` file as one object. The
/// extension alone picks the format (`.ply` or `.obj`, any case; the contents are not sniffed)
/// and is checked first (after an empty path, INVALID_ARGUMENT): any other extension, or none,
/// is UNSUPPORTED before the path is looked at, even for a missing file or a directory. Then only regular files are read: a missing
/// file, a FIFO, device or directory is an IO error. Parse errors name the file and the line or
/// byte offset at fault. Triangles keep the file's face order (polygons are fan-triangulated);
/// a file without faces is a PARSE error, whatever its format. PLY: `vertex` x, y, z and the
/// `face` element's `vertex_indices` (or `vertex_index`) are read and other properties and
/// elements skipped, except another element of vertex index lists (`tristrips`), a PARSE error
/// rather than dropped. OBJ: positions (`v`) and faces
/// (`f`) are read; normals, texture coordinates, free-form parameter vertices (`vp`), object
/// and group names, smoothing and merging groups (`o`, `g`, `s`, `mg`), materials and the
/// other render attributes (`usemap`, `maplib`, `lod`, `bevel`, `c_interp`, `d_interp`,
/// `shadow_obj`, `trace_obj`), points and
/// lines (no surface) are skipped; free-form curves and surfaces (`cstype`, `curv`, `surf`...)
/// and any other statement are a PARSE error rather than dropped. Geometry that
/// `rt2_scene_add_mesh` would refuse (a triangle that does not fit in f32) is INVALID_ARGUMENT,
/// naming the file and the triangle (in face order). The file is read
/// and parsed before the scene is locked, so other calls on the scene do not wait for a slow
/// file.
///
/// # Safety
/// `scene` is a live scene; `path` is a NUL-terminated string.
#[no_mangle]
pub unsafe extern "C" fn rt2_scene_load_file(
    scene: *mut rt2_scene,
    path: *const std::ffi::c_char,
    material: u32,
    out_object: *mut u32,
) -> Rt2Status {
    prepare_and_edit(
        scene,
        (out_object, "out_object"),
        || {
            let path = path_arg(path, "path")?;
            loaders::load_mesh(&path).map(|mesh| (path, mesh))
        },
        |s, (path, mesh)| {
            let shape = Shape::Mesh {
                positions: mesh.positions,
                triangles: mesh.triangles,
            };
            s.add_object(shape, material).map_err(|e| Error {
                message: format!("{}: {}", path.display(), e.message),
                ..e
            })
        },
    )
}

/// Sets an object's object-to-world transform: a row-major 3×4 matrix `[R | t]` (12 floats),
/// replacing the previous one. Takes effect at the next commit (the per-frame rebuild), and
/// may be set on a disabled object (it is placed so when enabled again).
/// Boxes accept only transforms that keep them axis-aligned (each column of `R` one entry;
/// others at most 2^-20 of it are taken for rounding and set to zero, as in a quarter turn
/// made with `cosf`).
///
/// On error the object keeps its transform: INVALID_ARGUMENT for an object id the scene does
/// not hold (never issued or removed), a non-finite entry, a singular `R` or one whose
/// determinant overflows, a placement that leaves f32 (README, "Range"), NULL `m3x4` or a bad
/// handle; UNSUPPORTED for a box given a transform that turns it off its axes.
///
/// # Safety
/// `scene` is a live scene; `m3x4` holds 12 floats.
#[no_mangle]
pub unsafe extern "C" fn rt2_scene_set_transform(
    scene: *mut rt2_scene,
    object: u32,
    m3x4: *const f32,
) -> Rt2Status {
    guard(|| {
        let s = handle(scene, "scene")?;
        let m = array::<f32, 12>(m3x4, "m3x4")?;
        let lin = Mat3::from_cols_array(&[m[0], m[4], m[8], m[1], m[5], m[9], m[2], m[6], m[10]]);
        let t = Affine3A::from_mat3_translation(lin, Vec3::new(m[3], m[7], m[11]));
        s.write().set_transform(object, t)
    })
}

/// Enables (`enabled` non-zero) or disables (`enabled` 0) an object, like Embree's
/// `rtcEnableGeometry` / `rtcDisableGeometry`; objects are enabled when added. Takes effect at
/// the next commit, which builds the kd-tree again (the scene is stale until then). From that
/// commit on, a disabled object is left out of the tree: no ray of `rt2_intersect` or
/// `rt2_occluded` (every mode and traversal, CPU and GPU) hits it, it casts no shadow and is
/// not rendered, and the scene traces as one built without it. Its id and every other id stay
/// as they were; it keeps its shape, material and transform (`rt2_scene_set_transform` still
/// applies to it), and once enabled and committed again it is hit exactly as before. An
/// `rt2_query_options.exclude` entry may name its primitives: they are still the scene's, and
/// exclude nothing. `rt2_scene_stats` counts it in `object_count`, and its primitives in
/// `bytes_prim_lookup` only (not in the primitive counts, the tree or its bytes). A scene whose
/// objects are all disabled traces as an empty one (every ray misses).
///
/// Setting the state the object already has changes nothing: the scene stays committed if it
/// was, and the next commit keeps the tree. INVALID_ARGUMENT (and nothing changed) for an
/// `object` the scene lacks.
///
/// # Safety
/// `scene` is a live scene.
#[no_mangle]
pub unsafe extern "C" fn rt2_scene_set_enabled(
    scene: *mut rt2_scene,
    object: u32,
    enabled: u32,
) -> Rt2Status {
    guard(|| {
        let s = handle(scene, "scene")?;
        s.write().set_enabled(object, enabled != 0)
    })
}

/// Removes an object, like Embree's `rtcDetachGeometry`, for programs that stream objects in
/// and out. Its shape (a mesh's vertices and triangles) is freed at the call; its placed
/// primitives and its entries in the kd-tree and in the primitive lookup of
/// `rt2_query_options.exclude` at the next commit, which is needed as after any edit (the
/// scene is stale until then: renders and queries are INVALID_OPERATION) and builds the
/// kd-tree again. From that commit on the scene traces, shadows and renders exactly as one
/// built without the object. A disabled object can be removed.
///
/// Ids are never reused: every other object keeps its id, and later adds get new ones. Every
/// later call naming the removed id (`rt2_scene_set_transform`, `rt2_scene_set_enabled`,
/// `rt2_scene_remove`, `rt2_query_options.exclude` entries, `rt2_hit_surfaces` hits) is
/// INVALID_ARGUMENT with a message saying it was removed, and changes nothing. What stays of
/// it, whatever its size, is its id's slot: about 25 bytes (on x86-64: 8 in the scene, 5 in
/// the commit, and 12 in the primitive lookup once built, `bytes_prim_lookup`), which every
/// commit walks (a scene through which a million objects passed commits about 1.6 ms
/// slower).
/// `rt2_scene_stats` of the next commit no longer counts it in `object_count`.
///
/// INVALID_ARGUMENT (and nothing changed) for an `object` the scene never gave, or a removed
/// one.
///
/// # Safety
/// `scene` is a live scene.
#[no_mangle]
pub unsafe extern "C" fn rt2_scene_remove(scene: *mut rt2_scene, object: u32) -> Rt2Status {
    guard(|| {
        let s = handle(scene, "scene")?;
        s.write().remove(object)
    })
}

/// Sets how the kd-tree is built; takes effect at the next commit.
///
/// # Safety
/// `scene` is a live scene; `options` points to an `rt2_build_options`.
#[no_mangle]
pub unsafe extern "C" fn rt2_scene_set_build_options(
    scene: *mut rt2_scene,
    options: *const rt2_build_options,
) -> Rt2Status {
    guard(|| {
        let s = handle(scene, "scene")?;
        if options.is_null() {
            return Err(Error::invalid_argument("options is NULL"));
        }
        let o = read_versioned(options)?.to_options()?;
        s.write().set_build_options(o);
        Ok(())
    })
}

/// Builds the acceleration structure. Rendering needs a commit after the last edit. A commit
/// after objects were added or removed, transforms, enabled states or build options changed
/// places every enabled object and builds the kd-tree again; one after only materials or
/// lights were added keeps the tree; one after no edit does nothing.
/// `RT2_STATUS_OUT_OF_MEMORY` when the placed primitives or the kd-tree cannot be allocated:
/// the scene then keeps its last commit (or none) and its edits, and can be committed again.
///
/// # Safety
/// `scene` is a live scene.
#[no_mangle]
pub unsafe extern "C" fn rt2_scene_commit(scene: *mut rt2_scene) -> Rt2Status {
    guard(|| {
        let s = handle(scene, "scene")?;
        let ctx = s.context.clone();
        let mut w = s.write();
        let scene: &mut Scene = &mut w;
        ctx.install(|| scene.commit())
    })
}

/// Size and memory of a committed scene (`rt2_scene_stats`). Bytes are exact sizes of the
/// arrays the backends read. `object_count` counts the objects the scene holds: every object
/// added and not removed (`rt2_scene_remove`), disabled ones too; the primitive counts and the
/// tree are what the commit placed: the enabled objects' primitives (`rt2_scene_set_enabled`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default)]
pub struct rt2_scene_statistics {
    /// Set to `sizeof(rt2_scene_statistics)` before the call.
    pub struct_size: u32,
    pub object_count: u32,
    pub triangle_count: u32,
    pub sphere_count: u32,
    pub ellipsoid_count: u32,
    pub box_count: u32,
    pub plane_count: u32,
    pub node_count: u32,
    pub leaf_count: u32,
    pub empty_leaf_count: u32,
    pub max_depth: u32,
    pub avg_leaf_depth: f32,
    /// Mean primitive references per non-empty leaf.
    pub avg_prims_per_leaf: f32,
    pub sah_cost: f32,
    /// Time of the tree build alone.
    pub build_ms: f32,
    /// Time of the last commit: world-space placement and build, or only the new material and
    /// light arrays when nothing else changed (`build_ms` is then the tree's, as built).
    pub commit_ms: f32,
    /// 8 bytes per node; a leaf node holds its primitive range.
    pub bytes_nodes: u64,
    /// The leaves' primitive indices, 4 bytes each.
    pub bytes_leaf_lists: u64,
    /// Ropes (6 per leaf, packed at the bits a node index needs: 12-16 bytes per leaf for
    /// 16-21 bits) and the rank words that number the leaves for them (2 bits per node); 0
    /// until a rope traversal needs them.
    pub bytes_ropes: u64,
    pub bytes_leaf_boxes: u64,
    pub bytes_primitives: u64,
    /// The lookup from `(object, prim)` to the library's primitive index that
    /// `rt2_query_options.exclude` and `rt2_hit_surfaces` need: 4 bytes per primitive of every
    /// object (disabled ones too, not removed ones), a `size_t` per object id given (removed
    /// ones too) and one more, and 4 bytes per removed id; 0 until a query names primitives
    /// to exclude or surfaces are asked for a hit.
    pub bytes_prim_lookup: u64,
}

/// Statistics of the committed scene. Fails with INVALID_OPERATION before the first commit
/// or after an edit.
///
/// # Safety
/// `scene` is a live scene; `out` points to an `rt2_scene_statistics` whose `struct_size` is set.
#[no_mangle]
pub unsafe extern "C" fn rt2_scene_stats(
    scene: *const rt2_scene,
    out: *mut rt2_scene_statistics,
) -> Rt2Status {
    guard(|| {
        let s = handle(scene, "scene")?;
        check_out(out, "out")?;
        super::ffi::check_struct_size::<rt2_scene_statistics>(
            (*out).struct_size,
            "rt2_scene_statistics",
        )?;
        let r = s.read();
        let c = r.committed()?;
        let t = &c.tree;
        let st = t.stats;
        let stats = rt2_scene_statistics {
            struct_size: std::mem::size_of::<rt2_scene_statistics>() as u32,
            object_count: r.object_count() as u32,
            triangle_count: c.prims.triangles.len() as u32,
            sphere_count: c.prims.spheres.len() as u32,
            ellipsoid_count: c.prims.ellipsoids.len() as u32,
            box_count: c.prims.boxes.len() as u32,
            plane_count: c.prims.planes.len() as u32,
            node_count: st.node_count,
            leaf_count: st.leaf_count,
            empty_leaf_count: st.empty_leaf_count,
            max_depth: st.max_depth,
            avg_leaf_depth: st.avg_leaf_depth,
            avg_prims_per_leaf: st.avg_prims_per_leaf,
            sah_cost: st.sah_cost,
            build_ms: st.build_ms,
            commit_ms: c.commit_ms,
            bytes_nodes: t.node_bytes() as u64,
            bytes_leaf_lists: t.leaf_list_bytes() as u64,
            bytes_ropes: t.rope_bytes() as u64,
            bytes_leaf_boxes: t.leaf_box_bytes() as u64,
            bytes_primitives: c.prims.bytes() as u64,
            bytes_prim_lookup: c.lookup.bytes() as u64,
        };
        write_out(out, "out", stats)
    })
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::api::context::rt2_context_create;
    use std::cell::Cell;
    use std::ptr::{null, null_mut};

    /// A context and a committed scene of one triangle in the z = 0 plane, (0,0,0) (1,0,0)
    /// (0,1,0), through the C API (for the tests of this module and `api::query`).
    pub(crate) fn triangle_scene() -> (*mut rt2_context, *mut rt2_scene) {
        unsafe {
            let mut ctx = null_mut();
            assert_eq!(rt2_context_create(null(), &mut ctx), Rt2Status::Ok);
            let mut scene = null_mut();
            assert_eq!(rt2_scene_create(ctx, &mut scene), Rt2Status::Ok);
            let p = [0.0f32, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0];
            let st = rt2_scene_add_mesh(
                scene,
                p.as_ptr(),
                3,
                [0u32, 1, 2].as_ptr(),
                1,
                0,
                null_mut(),
            );
            assert_eq!(st, Rt2Status::Ok);
            assert_eq!(rt2_scene_commit(scene), Rt2Status::Ok);
            (ctx, scene)
        }
    }

    /// Destroys what [`triangle_scene`] made.
    pub(crate) fn destroy((ctx, scene): (*mut rt2_context, *mut rt2_scene)) {
        unsafe {
            rt2_scene_destroy(scene);
            crate::api::context::rt2_context_destroy(ctx);
        }
    }

    /// Another thread's commit that rebuilds the tree (after an edit of its geometry) right
    /// after the corners and ropes were built, which drops them: the scene handed out still
    /// has both, built again.
    #[test]
    fn what_a_commit_drops_before_the_job_reads_is_built_again() {
        let made = triangle_scene();
        let s = unsafe { &*made.1 };
        let commits = Cell::new(0);
        let commit_twice = || {
            if commits.get() < 2 {
                s.write().rebuild().unwrap();
                commits.set(commits.get() + 1);
            }
        };
        {
            let guard = s.prepared_with(true, true, commit_twice).unwrap();
            let c = guard.committed().unwrap();
            assert!(c.tree.ropes.is_some(), "no ropes");
            assert!(
                !c.prims.rebuilds_corners(Intersector::Watertight),
                "no exact corners"
            );
        }
        assert_eq!(commits.get(), 2, "the commits did not happen");
        destroy(made);
    }

    /// Rebuilding commits after every build: the job gives up with INVALID_OPERATION, and the
    /// scene works.
    #[test]
    fn endless_commits_make_the_job_give_up() {
        let made = triangle_scene();
        let s = unsafe { &*made.1 };
        let e = s
            .prepared_with(false, true, || s.write().rebuild().unwrap())
            .map(|_| ())
            .unwrap_err();
        assert_eq!(e.status, Rt2Status::InvalidOperation, "{}", e.message);
        assert!(e.message.contains("run it again"), "{}", e.message);
        assert!(s.prepared(false, true).is_ok());
        destroy(made);
    }
}
