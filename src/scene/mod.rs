//! The scene model: objects, materials and lights as the user described them, and the
//! committed form (world-space primitive set + kd-tree) that the backends trace.
//!
//! Every edit validates first and changes nothing on error. Edits mark what they made stale;
//! `commit` rebuilds the tree after objects were added or removed, transforms, the objects'
//! enabled state or build options changed (the RT² per-frame rebuild when objects move), and
//! only what changed otherwise.

pub mod builtin;
pub mod loaders;
mod locality;
mod lookup;
mod material;
mod object;
mod surface;
pub mod tessellate;

pub use lookup::PrimLookup;
pub use material::{Checker, Material, PointLight};
pub use object::{Object, PrimOrigin, Shape};
pub use surface::HitSurface;

use crate::error::{Error, Result};
use crate::fallible::{self, TryGrow};
use crate::geometry::{Aabb, PrimitiveSet};
use crate::kdtree::{self, BuildOptions, KdTree};
use glam::{Affine3A, Vec3};
use std::time::Instant;

/// A scene as edited through the API. Material 0 always exists (the default material).
#[derive(Debug)]
pub struct Scene {
    materials: Vec<Material>,
    lights: Vec<PointLight>,
    /// By id; `None` where the object was removed ([`Scene::remove`]): ids are never reused,
    /// so a removed object leaves its slot here and an entry in the committed per-object
    /// arrays. Boxed, so that a slot is a pointer (8 bytes) rather than an `Object` (128): a
    /// program that streamed a million objects through a scene kept 128 MB of empty slots,
    /// which every commit walked.
    objects: Vec<Option<Box<Object>>>,
    /// Primitives of all objects, kept so that adding an object is O(1) (summing over the
    /// objects made the 1.2 M spheres of Spheres1 quadratic: minutes to build the scene).
    prim_count: usize,
    build: BuildOptions,
    committed: Option<Committed>,
    stale: Stale,
}

/// What the edits since the last commit made stale: what the next commit redoes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
enum Stale {
    /// Nothing: a commit keeps the committed scene as it is.
    Nothing,
    /// Materials or lights were added: a commit replaces their arrays and keeps the placed
    /// primitives, the tree and what was built on it (ropes, exact corners, the lookup).
    Shading,
    /// Objects added or removed, transforms, enabled state or build options: a commit places
    /// and builds everything again.
    Geometry,
}

/// What the backends trace; read-only while renders run.
#[derive(Debug)]
pub struct Committed {
    pub prims: PrimitiveSet,
    pub tree: KdTree,
    /// Object and per-object index of each global primitive (bounded ones, then planes).
    pub origins: Vec<PrimOrigin>,
    /// The inverse of `origins`, empty until asked for (`Scene::ensure_prim_lookup`).
    pub lookup: PrimLookup,
    /// Each object's material, by object id (a removed id's entry is 0, and no primitive
    /// names it).
    pub object_material: Vec<u32>,
    /// Whether each object's transform mirrors ([`object::Object::mirrors`]; false for a
    /// removed id): its triangles' hits have `u` and `v` swapped.
    pub object_mirrors: Vec<bool>,
    pub materials: Vec<Material>,
    pub lights: Vec<PointLight>,
    /// Bounds of the bounded primitives (planes excluded); sets the scale of ray offsets.
    pub bounds: Aabb,
    /// Time to place primitives in world space and build the tree.
    pub commit_ms: f32,
    /// Unique per commit in this process: the GPU backend re-checks its copy when it changes.
    pub id: u64,
    /// The `id` of the commit that placed the primitives: kept by a commit of new materials
    /// and lights alone, which leaves their numbering (and the lookup) as it was.
    pub placement: u64,
}

/// A new `Committed::id`, unique in this process.
fn next_commit_id() -> u64 {
    static NEXT: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(1);
    NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed)
}

impl Committed {
    /// Asks for huge pages under the arrays every traversal reads at random (see
    /// [`crate::huge_pages`]): the tree's nodes and leaf lists, the bounded primitives and
    /// their exact corners, and the ropes when the build made them. Arrays under 2 MiB are
    /// passed over there. Ropes and corners built later on demand are advised as they are
    /// made ([`Scene::ensure_ropes`], [`Scene::ensure_exact_vertices`]), not everything again.
    fn advise_huge_pages(&self) {
        use crate::huge_pages::advise;
        let p = &self.prims;
        advise(&self.tree.nodes);
        advise(&self.tree.prim_indices);
        advise(&p.triangles);
        advise(&p.vertices);
        advise(&p.spheres);
        advise(&p.ellipsoids);
        advise(&p.boxes);
        self.advise_rope_pages();
    }

    /// [`Self::advise_huge_pages`] for the ropes' arrays alone.
    fn advise_rope_pages(&self) {
        use crate::huge_pages::advise;
        if let Some(r) = &self.tree.ropes {
            advise(&r.links.words);
            advise(&r.leaf_bounds);
            advise(&r.rank);
        }
    }

    pub fn material_of(&self, prim: u32) -> &Material {
        let object = self.origins[prim as usize].object as usize;
        &self.materials[self.object_material[object] as usize]
    }

    /// Barycentrics `(u, v)` of a hit on a triangle of `object`, between the stored
    /// triangle's corner order and the mesh's own: swapped for a mirrored object, whose
    /// triangles are stored with corners 1 and 2 swapped ([`Object::mirrors`]). A swap is its
    /// own inverse, so this converts either way.
    pub fn object_uv(&self, object: u32, u: f32, v: f32) -> (f32, f32) {
        if self.object_mirrors[object as usize] {
            (v, u)
        } else {
            (u, v)
        }
    }

    /// A length that scales with the scene, for offsets of secondary-ray origins.
    pub fn scale(&self) -> f32 {
        let d = self.bounds.diagonal();
        if d.is_finite() && d > 0.0 {
            d
        } else {
            1.0
        }
    }
}

impl Default for Scene {
    fn default() -> Self {
        Scene {
            materials: vec![Material::default()],
            lights: Vec::new(),
            objects: Vec::new(),
            prim_count: 0,
            build: BuildOptions::default(),
            committed: None,
            stale: Stale::Geometry,
        }
    }
}

fn check_finite(name: &str, v: &[f32]) -> Result<()> {
    match v.iter().position(|x| !x.is_finite()) {
        Some(i) => Err(Error::invalid_argument(format!(
            "{name}[{i}] is {:?} (must be finite)",
            v[i]
        ))),
        None => Ok(()),
    }
}

fn check_color(name: &str, c: Vec3) -> Result<()> {
    check_finite(name, &c.to_array())?;
    if c.min_element() < 0.0 {
        return Err(Error::invalid_argument(format!(
            "{name} has a negative component: {:?}",
            c.to_array()
        )));
    }
    Ok(())
}

fn check_unit_range(name: &str, v: f32) -> Result<()> {
    if !(0.0..=1.0).contains(&v) {
        return Err(Error::invalid_argument(format!(
            "{name} is {v:?} (must be in [0, 1])"
        )));
    }
    Ok(())
}

impl Material {
    pub fn validate(&self) -> Result<()> {
        check_color("material.color", self.color)?;
        for (name, v) in [
            ("material.ambient", self.ambient),
            ("material.diffuse", self.diffuse),
            ("material.specular", self.specular),
            ("material.reflectivity", self.reflectivity),
            ("material.transparency", self.transparency),
        ] {
            check_unit_range(name, v)?;
        }
        if self.reflectivity + self.transparency > 1.0 {
            return Err(Error::invalid_argument(format!(
                "material.reflectivity + material.transparency is {:?} (must be at most 1)",
                self.reflectivity + self.transparency
            )));
        }
        if !(self.shininess.is_finite() && self.shininess >= 0.0) {
            return Err(Error::invalid_argument(format!(
                "material.shininess is {:?} (must be >= 0)",
                self.shininess
            )));
        }
        // The refraction divides by it: an ior of 1e-45 made the ratio infinite (black pixels).
        if !(self.ior.is_finite() && self.ior > 0.0 && self.ior.recip().is_finite()) {
            return Err(Error::invalid_argument(format!(
                "material.ior is {:?} (must be > 0, with a finite reciprocal)",
                self.ior
            )));
        }
        if let Some(c) = self.checker {
            check_color("material.checker_color", c.color2)?;
            if !(c.scale.is_finite() && c.scale > 0.0) {
                return Err(Error::invalid_argument(format!(
                    "material.checker_scale is {:?} (must be > 0)",
                    c.scale
                )));
            }
        }
        Ok(())
    }
}

impl Shape {
    pub fn validate(&self) -> Result<()> {
        match self {
            Shape::Mesh {
                positions,
                triangles,
            } => {
                // The name is formatted only for the vertex at fault (not once per vertex).
                if let Some(i) = positions.iter().position(|p| !p.is_finite()) {
                    check_finite(&format!("positions[vertex {i}]"), &positions[i].to_array())?;
                }
                for (t, tri) in triangles.iter().enumerate() {
                    if let Some(k) = tri.iter().position(|&v| v as usize >= positions.len()) {
                        return Err(Error::invalid_argument(format!(
                            "indices[{}] (triangle {t}, corner {k}) is {}, but the mesh has {} vertices",
                            3 * t + k,
                            tri[k],
                            positions.len()
                        )));
                    }
                }
            }
            Shape::Sphere { center, radius } => {
                check_finite("center", &center.to_array())?;
                if !(radius.is_finite() && *radius > 0.0) {
                    return Err(Error::invalid_argument(format!(
                        "radius is {radius:?} (must be finite and > 0)"
                    )));
                }
            }
            Shape::Ellipsoid { center, radii } => {
                check_finite("center", &center.to_array())?;
                check_finite("radii", &radii.to_array())?;
                if radii.min_element() <= 0.0 {
                    return Err(Error::invalid_argument(format!(
                        "radii are {:?} (each must be > 0)",
                        radii.to_array()
                    )));
                }
            }
            Shape::Box { min, max } => {
                check_finite("min", &min.to_array())?;
                check_finite("max", &max.to_array())?;
                if min.cmpgt(*max).any() {
                    return Err(Error::invalid_argument(format!(
                        "box min {:?} exceeds max {:?}",
                        min.to_array(),
                        max.to_array()
                    )));
                }
            }
            Shape::Plane { normal, offset } => {
                check_finite("normal", &normal.to_array())?;
                check_finite("offset", &[*offset])?;
                if *normal == Vec3::ZERO {
                    return Err(Error::invalid_argument("normal is the zero vector"));
                }
            }
        }
        Ok(())
    }
}

impl Scene {
    pub fn new() -> Self {
        Self::default()
    }

    pub fn materials(&self) -> &[Material] {
        &self.materials
    }

    /// The objects by id, `None` where one was removed.
    pub fn objects(&self) -> &[Option<Box<Object>>] {
        &self.objects
    }

    /// How many objects the scene holds: those added and not removed, disabled ones too.
    pub fn object_count(&self) -> usize {
        self.objects.iter().flatten().count()
    }

    pub fn lights(&self) -> &[PointLight] {
        &self.lights
    }

    pub fn build_options(&self) -> BuildOptions {
        self.build
    }

    pub fn add_material(&mut self, m: Material) -> Result<u32> {
        m.validate()?;
        self.materials.push(m);
        self.stale = self.stale.max(Stale::Shading);
        Ok(self.materials.len() as u32 - 1)
    }

    pub fn add_light(&mut self, l: PointLight) -> Result<u32> {
        check_finite("position", &l.position.to_array())?;
        check_color("rgb", l.color)?;
        if !(l.intensity.is_finite() && l.intensity >= 0.0) {
            return Err(Error::invalid_argument(format!(
                "intensity is {:?} (must be finite and >= 0)",
                l.intensity
            )));
        }
        self.lights.push(l);
        self.stale = self.stale.max(Stale::Shading);
        Ok(self.lights.len() as u32 - 1)
    }

    pub fn add_object(&mut self, shape: Shape, material: u32) -> Result<u32> {
        shape.validate()?;
        if material as usize >= self.materials.len() {
            return Err(Error::invalid_argument(format!(
                "material is {material}, but the scene's materials are 0 to {}",
                self.materials.len() - 1
            )));
        }
        if self.prim_count + shape.prim_count() >= (1 << 30) {
            return Err(Error::unsupported(
                "a scene holds fewer than 2^30 primitives",
            ));
        }
        object::check(&shape, &Affine3A::IDENTITY)?;
        let id = next_object_id(self.objects.len())?;
        let prims = shape.prim_count();
        // Fallible: a program streaming objects in and out grows this array without bound (8
        // bytes per removed id), and a failed doubling aborted the process.
        self.objects
            .try_push(Some(Box::new(Object {
                shape,
                material,
                transform: Affine3A::IDENTITY,
                enabled: true,
            })))
            .map_err(|_| {
                Error::out_of_memory(format!(
                    "out of memory for object ids (the scene gave {id}); nothing was added"
                ))
            })?;
        self.prim_count += prims;
        self.stale = Stale::Geometry;
        Ok(id)
    }

    /// Object `object`, or an error saying whether the id was removed or never given.
    fn object(&self, object: u32) -> Result<&Object> {
        match self.objects.get(object as usize) {
            Some(Some(o)) => Ok(&**o),
            slot => Err(no_object(object, self.objects.len(), slot.is_some())),
        }
    }

    /// [`Self::object`], mutable.
    fn object_mut(&mut self, object: u32) -> Result<&mut Object> {
        let issued = self.objects.len();
        match self.objects.get_mut(object as usize) {
            Some(Some(o)) => Ok(&mut **o),
            slot => Err(no_object(object, issued, slot.is_some())),
        }
    }

    /// Sets an object's object-to-world transform (replacing the previous one), whether the
    /// object is enabled or not.
    pub fn set_transform(&mut self, object: u32, t: Affine3A) -> Result<()> {
        let obj = self.object(object)?;
        check_finite("transform", &t.to_cols_array())?;
        let det = object::determinant(&t);
        if det == 0.0 || det.abs() > f32::MAX as f64 {
            // An overflowing determinant makes the inverse (normals, ellipsoids) unusable too.
            return Err(Error::invalid_argument(format!(
                "transform is singular or its scale is out of range (its 3x3 part has \
                 determinant {det:e}, must be non-zero and within f32's range)"
            )));
        }
        // Placement refuses what a shape cannot take (a box turned off its axes, one that
        // leaves f32), as a commit would.
        object::check(&obj.shape, &t)?;
        self.object_mut(object)?.transform = t;
        self.stale = Stale::Geometry;
        Ok(())
    }

    /// Enables or disables an object (Embree's `rtcEnableGeometry` / `rtcDisableGeometry`):
    /// from the next commit a disabled object is left out of the primitives and the tree, so
    /// nothing hits it, and the scene traces as one built without it; its id, shape, material
    /// and transform stay (a transform set meanwhile applies when it is enabled again). Setting
    /// the state an object already has is no edit: the next commit keeps what it would have
    /// kept.
    pub fn set_enabled(&mut self, object: u32, enabled: bool) -> Result<()> {
        let obj = self.object_mut(object)?;
        if obj.enabled != enabled {
            obj.enabled = enabled;
            self.stale = Stale::Geometry;
        }
        Ok(())
    }

    /// Removes an object (Embree's `rtcDetachGeometry`): its shape (a mesh's vertices and
    /// triangles) is freed now; its placed primitives, tree entries and lookup entries at the
    /// next commit, which builds the scene without it (until then the last commit stays, as
    /// after any edit, and a commit that fails keeps it). Its id is never given again, and
    /// every call naming it is refused saying it was removed; other ids stay as they were. A
    /// disabled object can be removed too.
    pub fn remove(&mut self, object: u32) -> Result<()> {
        let prims = self.object(object)?.shape.prim_count();
        self.objects[object as usize] = None;
        self.prim_count -= prims;
        self.stale = Stale::Geometry;
        Ok(())
    }

    pub fn set_build_options(&mut self, opts: BuildOptions) {
        self.build = opts;
        self.stale = Stale::Geometry;
    }

    /// Makes the committed scene match the edits: nothing to do when there were none; new
    /// material and light arrays when only those were added (a rebuild of the dragon for a
    /// light took 3.8 s); else [`Self::rebuild`]. A commit that cannot have the memory it
    /// needs fails with `OutOfMemory` and leaves the last commit in place (see
    /// [`crate::fallible`]).
    pub fn commit(&mut self) -> Result<()> {
        match (&mut self.committed, self.stale) {
            (Some(_), Stale::Nothing) => {}
            (Some(c), Stale::Shading) => {
                let start = Instant::now();
                let materials = fallible::collect(self.materials.iter().cloned())?;
                let lights = fallible::collect(self.lights.iter().cloned())?;
                c.materials = materials;
                c.lights = lights;
                c.commit_ms = start.elapsed().as_secs_f32() * 1e3;
                c.id = next_commit_id();
            }
            _ => return self.rebuild(),
        }
        self.stale = Stale::Nothing;
        Ok(())
    }

    /// Places every enabled object in world space and builds the kd-tree, whatever changed:
    /// what a commit does after objects, transforms, enabled state or build options changed,
    /// and what the benchmarks time as a build. Fails as [`Self::commit`] does.
    pub fn rebuild(&mut self) -> Result<()> {
        let start = Instant::now();
        let enabled = || {
            let objects = self.objects.iter().enumerate();
            objects.filter_map(|(id, o)| Some((id, o.as_deref().filter(|o| o.enabled)?)))
        };
        // Room for the triangles, known exactly, taken before placing (growing by doubling
        // could take twice as much); the other kinds grow as they are placed.
        let triangles: usize = enabled()
            .map(|(_, o)| match &o.shape {
                Shape::Mesh { triangles, .. } => triangles.len(),
                _ => 0,
            })
            .sum();
        let mut prims = PrimitiveSet {
            triangles: fallible::with_capacity(triangles)?,
            ..PrimitiveSet::default()
        };
        // One origin list per kind, concatenated in the order of the global index.
        let mut by_kind: [Vec<PrimOrigin>; 5] = Default::default();
        by_kind[0] = fallible::with_capacity(triangles)?;
        for (id, obj) in enabled() {
            object::place(obj, id as u32, &mut prims, &mut by_kind)?;
        }
        let mut origins = fallible::with_capacity(by_kind.iter().map(Vec::len).sum())?;
        for list in &by_kind {
            origins.extend_from_slice(list);
        }
        let mut tree = kdtree::build(&prims, &self.build)?;
        locality::renumber(&mut prims, &mut origins, &mut tree)?;
        let id = next_commit_id();
        let committed = Committed {
            bounds: prims.scene_bounds(),
            prims,
            tree,
            origins,
            lookup: PrimLookup::default(),
            object_material: fallible::collect(
                self.objects
                    .iter()
                    .map(|o| o.as_deref().map_or(0, |o| o.material)),
            )?,
            object_mirrors: fallible::collect(
                self.objects
                    .iter()
                    .map(|o| o.as_deref().is_some_and(Object::mirrors)),
            )?,
            materials: fallible::collect(self.materials.iter().cloned())?,
            lights: fallible::collect(self.lights.iter().cloned())?,
            commit_ms: start.elapsed().as_secs_f32() * 1e3,
            id,
            placement: id,
        };
        committed.advise_huge_pages();
        self.committed = Some(committed);
        self.stale = Stale::Nothing;
        Ok(())
    }

    /// Builds the ropes of the committed tree if a rope traversal needs them and they are not
    /// there yet (ropes cost about 3x the tree, so they are made only on request).
    pub fn ensure_ropes(&mut self) -> Result<()> {
        self.committed()?;
        if let Some(c) = self.committed.as_mut().filter(|c| c.tree.ropes.is_none()) {
            c.tree.ensure_ropes()?;
            c.advise_rope_pages();
        }
        Ok(())
    }

    /// Keeps the exact corners of the committed triangles beside their edge form (36 bytes per
    /// triangle), which the watertight test needs to be watertight: `v0 + e1` does not
    /// reproduce a shared vertex bit for bit. Built on demand, like ropes.
    pub fn ensure_exact_vertices(&mut self) -> Result<()> {
        self.committed()?;
        if let Some(c) = &mut self.committed {
            if c.prims.vertices.len() != c.prims.triangles.len() {
                // The corners come in placement order (object by object, file order; disabled
                // or removed objects place none); the committed triangles are renumbered (`locality`):
                // their origins say where each one was placed.
                let corners = object::triangle_corners(&self.objects)?;
                let mut first = fallible::with_capacity(self.objects.len())?;
                let mut placed = 0;
                for obj in &self.objects {
                    first.push(placed);
                    if let Some(Object {
                        enabled: true,
                        shape: Shape::Mesh { triangles, .. },
                        ..
                    }) = obj.as_deref()
                    {
                        placed += triangles.len();
                    }
                }
                c.prims.vertices = fallible::collect(
                    c.origins[..c.prims.triangles.len()]
                        .iter()
                        .map(|o| corners[first[o.object as usize] + o.prim as usize]),
                )?;
                crate::huge_pages::advise(&c.prims.vertices);
            }
        }
        Ok(())
    }

    /// Builds the committed scene's [`PrimLookup`] if it is not there yet (4 bytes per
    /// primitive, for callers that name primitives by their public ids) and runs `f` on the
    /// committed scene and its lookup. A new lookup is kept only when `f` succeeds, so a
    /// refused call leaves the scene as it was.
    pub fn ensure_prim_lookup<R>(
        &mut self,
        f: impl FnOnce(&Committed, &PrimLookup) -> Result<R>,
    ) -> Result<R> {
        let c = self.committed()?;
        if !c.lookup.is_empty() {
            return f(c, &c.lookup);
        }
        let counts = self
            .objects
            .iter()
            .map(|o| Some(o.as_deref()?.shape.prim_count()));
        let lookup = PrimLookup::new(&c.origins, counts)?;
        let r = f(c, &lookup)?;
        self.committed_mut()?.lookup = lookup;
        Ok(r)
    }

    /// The committed scene, or an error if there is none or it is older than the last edit.
    pub fn committed(&self) -> Result<&Committed> {
        match (&self.committed, self.stale) {
            (Some(c), Stale::Nothing) => Ok(c),
            (committed, _) => Err(not_committed(committed.is_some())),
        }
    }

    /// [`Self::committed`], mutable: for what is built on the committed scene on demand.
    fn committed_mut(&mut self) -> Result<&mut Committed> {
        match (&mut self.committed, self.stale) {
            (Some(c), Stale::Nothing) => Ok(c),
            (committed, _) => Err(not_committed(committed.is_some())),
        }
    }
}

/// The id of the next object after `issued` ids, or an error once they are used up. Ids are
/// never reused, so a program streaming objects in and out (8 bytes per removed id) can reach
/// 2^32 - 1, which is `RT2_INVALID_ID` (a miss), after which `issued as u32` wrapped to id 0.
fn next_object_id(issued: usize) -> Result<u32> {
    match u32::try_from(issued) {
        Ok(id) if id < u32::MAX => Ok(id),
        _ => Err(Error::unsupported(format!(
            "the scene has given {issued} object ids, the most it can (ids are not reused)"
        ))),
    }
}

/// The error for an `object` id that names no object: removed, or past the `issued` ids.
fn no_object(object: u32, issued: usize, removed: bool) -> Error {
    Error::invalid_argument(if removed {
        format!("object is {object}, which was removed (rt2_scene_remove): ids are not reused")
    } else {
        format!("object is {object}, but the scene has given only {issued} object ids")
    })
}

/// Why a scene has no current commit: never committed, or edited since.
fn not_committed(was_committed: bool) -> Error {
    Error::invalid_operation(if was_committed {
        "the scene was modified after its last commit: call rt2_scene_commit first"
    } else {
        "the scene was never committed: call rt2_scene_commit first"
    })
}

/// A committed scene of one sphere of radius 1 at the origin: the unit tests' smallest scene
/// with a known hit (a ray from (0, 0, 5) along -z meets it at t = 4).
#[cfg(test)]
pub(crate) fn unit_sphere() -> Scene {
    let mut s = Scene::new();
    let sphere = Shape::Sphere {
        center: glam::Vec3::ZERO,
        radius: 1.0,
    };
    s.add_object(sphere, 0).expect("a valid sphere");
    s.commit().expect("a one-sphere commit");
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A commit asks for huge pages under its arrays (`Committed::advise_huge_pages`): the
    /// 2 MiB pages inside 200,000 triangles (7 MiB) are marked where the kernel has transparent
    /// huge pages.
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    #[test]
    fn commits_advise_huge_pages() {
        let n = 200_000u32;
        let positions = (0..n)
            .flat_map(|i| {
                let p = Vec3::new((i % 500) as f32, (i / 500) as f32, (i % 7) as f32);
                [p, p + Vec3::X * 0.5, p + Vec3::Y * 0.5]
            })
            .collect();
        let triangles = (0..n).map(|i| [3 * i, 3 * i + 1, 3 * i + 2]).collect();
        let mut scene = Scene::new();
        scene
            .add_object(
                Shape::Mesh {
                    positions,
                    triangles,
                },
                0,
            )
            .unwrap();
        scene.commit().unwrap();
        let c = scene.committed().unwrap();
        let bytes = std::mem::size_of_val(c.prims.triangles.as_slice());
        assert!(bytes >= 4 << 20, "{bytes} bytes of triangles");
        let inside = (c.prims.triangles.as_ptr() as usize).next_multiple_of(2 << 20);
        let (marked, thp) = crate::huge_pages::marked(inside);
        assert_eq!(marked, thp);
    }

    /// Object ids run out before `RT2_INVALID_ID` (the miss id) and never wrap around to 0.
    #[test]
    fn object_ids_stop_before_the_miss_id() {
        assert_eq!(next_object_id(0).unwrap(), 0);
        assert_eq!(next_object_id(u32::MAX as usize - 1).unwrap(), u32::MAX - 1);
        for issued in [u32::MAX as usize, u32::MAX as usize + 1, usize::MAX] {
            let e = next_object_id(issued).unwrap_err();
            assert_eq!(e.status, crate::error::Rt2Status::Unsupported, "{issued}");
        }
    }

    /// Each field out of its range is refused, and the scene keeps only its default material.
    #[test]
    fn materials_out_of_range_are_refused() {
        let bad = [
            Material {
                ior: 1e-45,
                ..Material::default()
            },
            Material {
                ior: 0.0,
                ..Material::default()
            },
            Material {
                ior: f32::INFINITY,
                ..Material::default()
            },
            Material {
                diffuse: 1.5,
                ..Material::default()
            },
            Material {
                shininess: f32::NAN,
                ..Material::default()
            },
            Material {
                reflectivity: 0.6,
                transparency: 0.6,
                ..Material::default()
            },
        ];
        let mut s = Scene::new();
        for m in bad {
            let e = s.add_material(m).unwrap_err();
            assert_eq!(e.status, crate::error::Rt2Status::InvalidArgument, "{m:?}");
        }
        assert_eq!(s.materials().len(), 1);
        // The smallest normal float is accepted (its reciprocal is 8.5e37).
        let ior = f32::MIN_POSITIVE;
        assert_eq!(
            s.add_material(Material {
                ior,
                ..Material::default()
            })
            .unwrap(),
            1
        );
    }
}
