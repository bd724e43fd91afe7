//! Versioned descriptors and enums of the C API. Callers start from `rt2_*_default()` and
//! change fields, so fields can be added later. Enum-typed fields are `uint32_t` on the wire
//! and checked, because an out-of-range C enum value must be an error, not undefined behaviour.

use super::ffi::{enum_error, versioned};
use crate::cpu::query::QueryMode;
use crate::cpu::traverse::Traversal;
use crate::dispatch::BackendRequest;
use crate::error::{Error, Result};
use crate::kdtree::{BuildOptions, Builder, Layout};
use crate::precision::{Intersector, OffsetMode};
use crate::render::{GpuPathRequest, RenderOptions, Schedule, Transparency};
use crate::scene::{Checker, Material};
use glam::Vec3;

/// Where tracing runs (`rt2_context_desc.backend`).
#[repr(u32)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Rt2Backend {
    /// A hardware GPU if there is one, else the CPU. AUTO never picks a software adapter
    /// (lavapipe, SwiftShader, WARP): with only such an adapter it traces on the CPU.
    Auto = 0,
    Cpu = 1,
    /// The GPU, a software adapter included. On Mesa's lavapipe (llvmpipe) some jobs fail
    /// with `RT2_STATUS_BACKEND_UNAVAILABLE`: the driver ends every loop of a shader
    /// invocation once the invocation has run 65535 loop iterations in all (its
    /// `LP_MAX_TGSI_LOOP_ITERATIONS`), counted per SIMD group of invocations that run in
    /// lockstep (aligned groups of 8 rays or pixels with llvmpipe's usual 256-bit vectors).
    /// A ray whose traversal (node steps plus primitive tests, roughly) needs about 65k
    /// iterations, e.g. through a leaf of 70,000 overlapping primitives, would get a wrong hit
    /// or a miss, and so would the other rays of its group that were not done yet; a
    /// megakernel pixel counts all its samples and bounces (with `RT2_GPU_PATH_AUTO` and more
    /// than one sample, a software adapter takes the wavefront path, which traces one ray per
    /// invocation). The kernels detect the cut (their last loop stops early too), and such a
    /// query or render returns that status, saying the driver cut its rays or pixels short,
    /// with no answers written (but those of a query's earlier steps of up to 2^20 rays: see
    /// `rt2_intersect`). Hardware drivers have no such budget.
    Gpu = 2,
}

/// kd-tree traversal algorithm (`rt2_render_options.traversal`, `rt2_query_options.traversal`);
/// RT² thesis §2.4. On the CPU it applies to single rays: the PACKET and STREAM query modes
/// and the BREADTH_FIRST render schedule (streams) always take the standard order.
#[repr(u32)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Rt2Traversal {
    /// The library picks per scene and backend: standard on the CPU; on the GPU ropes++ when
    /// the scene's tree has ropes (built on request), else standard.
    Auto = 0,
    Standard = 1,
    KdRestart = 2,
    PushDown = 3,
    ShortStack = 4,
    PushDownShortStack = 5,
    Ropes = 6,
    RopesPlusPlus = 7,
}

/// How a batch of rays is traced (`rt2_query_options.mode`). Every mode returns the same closest
/// hits, bit for bit, with either intersector; they differ in speed (`rt2 bench streams`). The
/// leaf tests of packets and streams are SIMD with either intersector.
#[repr(u32)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Rt2QueryMode {
    /// One ray at a time with `rt2_query_options.traversal`.
    Single = 0,
    /// Packets of one octant (Wald) as wide as the CPU runs: 16 rays with AVX-512, 8 with
    /// AVX2, else 4; standard traversal order. Rays that form a camera image in scanline order
    /// (found in the rays) are packed in tiles, 4×4, 4×2 or 2×2, else N consecutive rays.
    Packet = 1,
    /// The n-ray traversal of the vectorised-traversal paper: all rays of a stream at once, in
    /// streams of one octant: at most 32768 rays when they come in runs of one octant
    /// (`cpu::query::STREAM_MAX`), else about one ray per leaf of the scene's tree, 32768 to
    /// 262144 (`cpu::query::incoherent_stream_max`).
    Stream = 2,
    /// The library chooses per batch (per step of up to 2^20 rays for a longer one; see
    /// `rt2_intersect`) (default): PACKET for 8 rays or more that come in runs of
    /// one octant (16 rays long on average or more), as a camera's rays in scanline order do;
    /// STREAM for 128 rays or more in mixed octants (incoherent); SINGLE for smaller batches
    /// and whenever `traversal` names another traversal than STANDARD or AUTO.
    /// `rt2_context_properties.auto_choice` says which it took and why.
    Auto = 3,
}

/// How transparent materials pass light (`rt2_render_options.transparency`).
#[repr(u32)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Rt2Transparency {
    /// RT² mode: rays continue unbent.
    Straight = 0,
    /// Snell refraction with Fresnel reflection (Schlick's approximation, taken with the
    /// cosine on the less dense side: the reflected share rises continuously to all of it at
    /// the critical angle).
    Refract = 1,
}

/// The order in which the CPU renderer traces rays (`rt2_render_options.schedule`). Both give the
/// same image up to the last bit of a sum (see `rt2_render_options.schedule`).
#[repr(u32)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Rt2Schedule {
    /// Pixel by pixel, one ray at a time (default).
    DepthFirst = 0,
    /// Wavefronts: all primary rays, then all shadow rays, then all secondary rays, as streams.
    BreadthFirst = 1,
}

/// GPU render path (`rt2_render_options.gpu_path`); RT² thesis §3.3. Ignored on the CPU.
#[repr(u32)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Rt2GpuPath {
    /// The library picks MEGAKERNEL for `max_depth` 1 (no secondary rays), else WAVEFRONT
    /// when at least half the primitives reflect or transmit and MEGAKERNEL otherwise; but on
    /// a software adapter (lavapipe) it takes WAVEFRONT whenever a pixel has more than one
    /// sample, as a megakernel pixel of many samples may exceed the driver's loop budget
    /// (`RT2_BACKEND_GPU`).
    Auto = 0,
    /// One kernel traces every ray of a pixel.
    Megakernel = 1,
    /// One kernel per bounce; live rays compacted by a parallel prefix sum.
    Wavefront = 2,
}

/// kd-tree builder (`rt2_build_options.builder`).
#[repr(u32)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Rt2Builder {
    /// Surface Area Heuristic with perfect splits (RT²).
    Sah = 0,
    /// Splits at the voxel centre (the vectorised-traversal paper).
    Midpoint = 1,
}

/// Node order in memory (`rt2_build_options.layout`).
#[repr(u32)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Rt2Layout {
    DepthFirst = 0,
    /// Cache-oblivious van Emde Boas order.
    VanEmdeBoas = 1,
}

/// Ray–triangle test (`rt2_query_options.intersector`, `rt2_render_options.intersector`).
#[repr(u32)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Rt2Intersector {
    /// Möller–Trumbore: fastest; a ray through a shared edge or vertex may slip through.
    MollerTrumbore = 0,
    /// Woop, Benthin & Wald 2013: no ray slips through shared edges or vertices of a closed
    /// mesh; a per-ray set-up and a few more operations per test.
    Watertight = 1,
}

/// Where secondary rays start (`rt2_render_options.offset_mode`).
#[repr(u32)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Rt2OffsetMode {
    /// A fixed offset of 1e-5 x the scene diagonal along the normal. The diagonal is that of
    /// the bounded primitives' box (planes excluded; 1 for a scene of planes only): a plane
    /// far from small objects gets acne (plane y = 100 with one sphere of radius 1e-3 at the
    /// origin: no pixel of the plane lit). ROBUST has no such limit.
    Epsilon = 0,
    /// Wächter & Binder 2019: hit point recomputed on the surface, moved a few ULPs along
    /// the geometric normal (scale-aware).
    Robust = 1,
    /// Start on the recomputed hit point and ignore the primitive just hit (robust offset for
    /// rays entering a curved primitive).
    ExcludePrim = 2,
}

pub(crate) fn intersector_from(v: u32) -> Result<Intersector> {
    match v {
        0 => Ok(Intersector::MollerTrumbore),
        1 => Ok(Intersector::Watertight),
        _ => Err(enum_error("rt2_intersector", v)),
    }
}

pub(crate) fn intersector_to(i: Intersector) -> u32 {
    match i {
        Intersector::MollerTrumbore => Rt2Intersector::MollerTrumbore as u32,
        Intersector::Watertight => Rt2Intersector::Watertight as u32,
    }
}

fn offset_mode_from(v: u32) -> Result<OffsetMode> {
    match v {
        0 => Ok(OffsetMode::Epsilon),
        1 => Ok(OffsetMode::Robust),
        2 => Ok(OffsetMode::ExcludePrim),
        _ => Err(enum_error("rt2_offset_mode", v)),
    }
}

fn offset_mode_to(m: OffsetMode) -> u32 {
    match m {
        OffsetMode::Epsilon => Rt2OffsetMode::Epsilon as u32,
        OffsetMode::Robust => Rt2OffsetMode::Robust as u32,
        OffsetMode::ExcludePrim => Rt2OffsetMode::ExcludePrim as u32,
    }
}

pub(crate) fn backend_from(v: u32) -> Result<BackendRequest> {
    match v {
        0 => Ok(BackendRequest::Auto),
        1 => Ok(BackendRequest::Cpu),
        2 => Ok(BackendRequest::Gpu),
        _ => Err(enum_error("rt2_backend", v)),
    }
}

/// A query mode; `None` is AUTO.
pub(crate) fn query_mode_from(v: u32) -> Result<Option<QueryMode>> {
    match v {
        0 => Ok(Some(QueryMode::Single)),
        1 => Ok(Some(QueryMode::Packet)),
        2 => Ok(Some(QueryMode::Stream)),
        3 => Ok(None),
        _ => Err(enum_error("rt2_query_mode", v)),
    }
}

pub(crate) fn traversal_from(v: u32) -> Result<Option<Traversal>> {
    use Traversal::*;
    Ok(Some(match v {
        0 => return Ok(None),
        1 => Standard,
        2 => KdRestart,
        3 => PushDown,
        4 => ShortStack,
        5 => PushDownShortStack,
        6 => Ropes,
        7 => RopesPlusPlus,
        _ => return Err(enum_error("rt2_traversal", v)),
    }))
}

/// Creation parameters of a context.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct rt2_context_desc {
    /// `sizeof(rt2_context_desc)`: start from `rt2_context_desc_default()`, which sets it.
    pub struct_size: u32,
    /// An `rt2_backend` value. Default AUTO; the `RT2_BACKEND` environment variable overrides.
    pub backend: u32,
    /// Worker threads; 0 (default) uses every core, or `RAYON_NUM_THREADS` when that holds a
    /// positive count; at most 1024 either way. Commits, renders and ray batches of more
    /// than 4096 rays run on them; a smaller batch runs on the thread that
    /// calls `rt2_intersect` or `rt2_occluded`, so several calling threads trace at once
    /// whatever this says.
    pub threads: u32,
}

versioned!(rt2_context_desc);

/// A context descriptor with the defaults filled in.
#[no_mangle]
pub extern "C" fn rt2_context_desc_default() -> rt2_context_desc {
    rt2_context_desc {
        struct_size: std::mem::size_of::<rt2_context_desc>() as u32,
        backend: Rt2Backend::Auto as u32,
        threads: 0,
    }
}

/// A Phong/Whitted material. Colours are linear RGB in [0, inf); the terms in [0, 1];
/// `reflectivity + transparency <= 1`.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct rt2_material {
    /// `sizeof(rt2_material)`: start from `rt2_material_default()`, which sets it.
    pub struct_size: u32,
    pub color: [f32; 3],
    pub ambient: f32,
    pub diffuse: f32,
    pub specular: f32,
    /// Phong exponent, >= 0.
    pub shininess: f32,
    /// Fraction of light carried by the mirror ray.
    pub reflectivity: f32,
    /// Fraction of light carried by the transmitted ray. Shadows stay hard, as in Whitted's
    /// model: a shadow ray stops at any object, so a transparent one casts a full shadow.
    pub transparency: f32,
    /// Index of refraction (> 0, with a finite reciprocal: at least about 2.94e-39), used with
    /// `RT2_TRANSPARENCY_REFRACT`. The side a ray enters is the side its normal points to
    /// (outside a solid, in front of a plane or triangle), and the ray stays bent until it
    /// leaves through a surface from behind: a lone transparent triangle or plane bends rays
    /// as the face of a solid would, not as a thin pane.
    pub ior: f32,
    /// Non-zero: a world-space checkerboard of `color` and `checker_color`. A surface point
    /// takes the colour of the square just behind it (inside a solid, behind a plane's or
    /// triangle's normal), the same seen from either side.
    pub checker: u32,
    pub checker_color: [f32; 3],
    /// Edge length of one checker square (> 0).
    pub checker_scale: f32,
}

versioned!(rt2_material);

impl From<&Material> for rt2_material {
    fn from(m: &Material) -> Self {
        let c = m.checker.unwrap_or(Checker {
            color2: Vec3::ZERO,
            scale: 1.0,
        });
        rt2_material {
            struct_size: std::mem::size_of::<rt2_material>() as u32,
            color: m.color.to_array(),
            ambient: m.ambient,
            diffuse: m.diffuse,
            specular: m.specular,
            shininess: m.shininess,
            reflectivity: m.reflectivity,
            transparency: m.transparency,
            ior: m.ior,
            checker: m.checker.is_some() as u32,
            checker_color: c.color2.to_array(),
            checker_scale: c.scale,
        }
    }
}

impl rt2_material {
    pub(crate) fn to_material(self) -> Result<Material> {
        let m = Material {
            color: Vec3::from(self.color),
            ambient: self.ambient,
            diffuse: self.diffuse,
            specular: self.specular,
            shininess: self.shininess,
            reflectivity: self.reflectivity,
            transparency: self.transparency,
            ior: self.ior,
            checker: (self.checker != 0).then_some(Checker {
                color2: Vec3::from(self.checker_color),
                scale: self.checker_scale,
            }),
        };
        m.validate()?;
        Ok(m)
    }
}

/// The default material, also material 0 of every scene: grey (colour 0.8), ambient 0.1,
/// diffuse 0.9, specular 0.3, shininess 32, neither reflective nor transparent, ior 1.5, no
/// checkerboard.
#[no_mangle]
pub extern "C" fn rt2_material_default() -> rt2_material {
    (&Material::default()).into()
}

/// kd-tree build parameters of a scene (`rt2_scene_set_build_options`).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct rt2_build_options {
    /// `sizeof(rt2_build_options)`: start from `rt2_build_options_default()`, which sets it.
    pub struct_size: u32,
    /// An `rt2_builder` value (default SAH).
    pub builder: u32,
    /// An `rt2_layout` value (default depth-first).
    pub layout: u32,
    /// Maximum tree depth, at most 64; 0 (default) picks one from the primitive count.
    pub max_depth: u32,
    /// Midpoint builder: stop splitting at this many primitives, or before where a split
    /// would leave every primitive in both children (default 4). Checked (>= 1) with either
    /// builder, though SAH does not read it.
    pub leaf_size: u32,
    /// SAH cost of a traversal step relative to a primitive test (> 0, default 3): larger values
    /// give a smaller tree, built faster, with fewer and fuller leaves; smaller ones (down to
    /// about 1.5) trade memory for a few per cent more coherent single rays.
    pub traversal_cost: f32,
    /// SAH factor, in [0, 1), on the cost of a split that leaves one side empty (nothing inside
    /// it; primitives touching the plane are kept on both sides) (default 0.8): the smaller,
    /// the more eagerly empty space is cut off; 0 makes such splits free.
    pub empty_bonus: f32,
    /// Non-zero: build ropes now (they are also built on demand by rope traversals).
    pub ropes: u32,
}

versioned!(rt2_build_options);

impl From<&BuildOptions> for rt2_build_options {
    fn from(o: &BuildOptions) -> Self {
        rt2_build_options {
            struct_size: std::mem::size_of::<rt2_build_options>() as u32,
            builder: match o.builder {
                Builder::Sah => Rt2Builder::Sah as u32,
                Builder::Midpoint => Rt2Builder::Midpoint as u32,
            },
            layout: match o.layout {
                Layout::DepthFirst => Rt2Layout::DepthFirst as u32,
                Layout::VanEmdeBoas => Rt2Layout::VanEmdeBoas as u32,
            },
            max_depth: o.max_depth.unwrap_or(0),
            leaf_size: o.leaf_size,
            traversal_cost: o.traversal_cost,
            empty_bonus: o.empty_bonus,
            ropes: o.ropes as u32,
        }
    }
}

impl rt2_build_options {
    pub(crate) fn to_options(self) -> Result<BuildOptions> {
        let bad = Error::invalid_argument;
        let builder = match self.builder {
            0 => Builder::Sah,
            1 => Builder::Midpoint,
            v => return Err(enum_error("rt2_builder", v)),
        };
        let layout = match self.layout {
            0 => Layout::DepthFirst,
            1 => Layout::VanEmdeBoas,
            v => return Err(enum_error("rt2_layout", v)),
        };
        if self.max_depth > 64 {
            return Err(bad(format!("max_depth is {} (at most 64)", self.max_depth)));
        }
        if self.leaf_size == 0 {
            return Err(bad("leaf_size is 0 (must be >= 1)".into()));
        }
        if !(self.traversal_cost.is_finite() && self.traversal_cost > 0.0) {
            return Err(bad(format!(
                "traversal_cost is {:?} (must be > 0)",
                self.traversal_cost
            )));
        }
        if !(0.0..1.0).contains(&self.empty_bonus) {
            return Err(bad(format!(
                "empty_bonus is {:?} (must be in [0, 1))",
                self.empty_bonus
            )));
        }
        Ok(BuildOptions {
            builder,
            layout,
            max_depth: (self.max_depth != 0).then_some(self.max_depth),
            leaf_size: self.leaf_size,
            traversal_cost: self.traversal_cost,
            empty_bonus: self.empty_bonus,
            ropes: self.ropes != 0,
            ..BuildOptions::default()
        })
    }
}

/// Default kd-tree build options (SAH with perfect splits, depth-first).
#[no_mangle]
pub extern "C" fn rt2_build_options_default() -> rt2_build_options {
    (&BuildOptions::default()).into()
}

/// Per-call render parameters (`rt2_render`).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct rt2_render_options {
    /// `sizeof(rt2_render_options)`: start from `rt2_render_options_default()`, which sets it.
    pub struct_size: u32,
    /// Longest chain of rays from the eye, 1..=64 (default 6; 1 = ray casting with shadows).
    /// A chain also ends where a reflected or refracted ray's weight in its pixel falls below
    /// 1/512 divided by the scene's brightest radiance (lights, materials and background, at
    /// least 1 and at most 16): such rays change no 8-bit pixel, except in scenes brighter than
    /// 16, where each may still be worth up to 1/8192 of that brightness.
    pub max_depth: u32,
    /// Samples per pixel, 1..=1024 (default 1).
    pub samples: u32,
    /// An `rt2_traversal` value (default AUTO).
    pub traversal: u32,
    /// Entries of the short stack, 1..=32 (default 3, as in RT²).
    pub short_stack_size: u32,
    /// An `rt2_transparency` value (default REFRACT).
    pub transparency: u32,
    /// Colour of rays that leave the scene, linear RGB (default 0.05, 0.05, 0.08).
    pub background: [f32; 3],
    /// An `rt2_schedule` value (default DEPTH_FIRST). BREADTH_FIRST adds each pixel's
    /// contributions in another order, so a channel may differ by 1/255 on a few pixels.
    pub schedule: u32,
    /// An `rt2_gpu_path` value (default AUTO).
    pub gpu_path: u32,
    /// An `rt2_intersector` value (default MOLLER_TRUMBORE).
    pub intersector: u32,
    /// An `rt2_offset_mode` value (default EPSILON).
    pub offset_mode: u32,
}

versioned!(rt2_render_options);

impl rt2_render_options {
    pub(crate) fn to_options(self) -> Result<RenderOptions> {
        let transparency = match self.transparency {
            0 => Transparency::Straight,
            1 => Transparency::Refract,
            v => return Err(enum_error("rt2_transparency", v)),
        };
        let schedule = match self.schedule {
            0 => Schedule::DepthFirst,
            1 => Schedule::BreadthFirst,
            v => return Err(enum_error("rt2_schedule", v)),
        };
        let gpu_path = match self.gpu_path {
            0 => GpuPathRequest::Auto,
            1 => GpuPathRequest::Megakernel,
            2 => GpuPathRequest::Wavefront,
            v => return Err(enum_error("rt2_gpu_path", v)),
        };
        let options = RenderOptions {
            gpu_path,
            schedule,
            max_depth: self.max_depth,
            samples: self.samples,
            traversal: traversal_from(self.traversal)?,
            short_stack_size: self.short_stack_size as usize,
            transparency,
            background: Vec3::from(self.background),
            intersector: intersector_from(self.intersector)?,
            offset_mode: offset_mode_from(self.offset_mode)?,
        };
        options.validate()?;
        Ok(options)
    }
}

/// Default render options (depth 6, 1 sample, AUTO traversal, refraction).
#[no_mangle]
pub extern "C" fn rt2_render_options_default() -> rt2_render_options {
    let d = RenderOptions::default();
    rt2_render_options {
        struct_size: std::mem::size_of::<rt2_render_options>() as u32,
        max_depth: d.max_depth,
        samples: d.samples,
        traversal: Rt2Traversal::Auto as u32,
        short_stack_size: d.short_stack_size as u32,
        transparency: Rt2Transparency::Refract as u32,
        background: d.background.to_array(),
        schedule: Rt2Schedule::DepthFirst as u32,
        gpu_path: Rt2GpuPath::Auto as u32,
        intersector: intersector_to(d.intersector),
        offset_mode: offset_mode_to(d.offset_mode),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn precision_fields_convert_and_reject_unknown_values() -> Result<()> {
        let mut o = rt2_render_options_default();
        let d = o.to_options()?;
        assert_eq!(
            (d.intersector, d.offset_mode),
            (Intersector::MollerTrumbore, OffsetMode::Epsilon)
        );
        o.intersector = Rt2Intersector::Watertight as u32;
        o.offset_mode = Rt2OffsetMode::ExcludePrim as u32;
        let r = o.to_options()?;
        assert_eq!(
            (r.intersector, r.offset_mode),
            (Intersector::Watertight, OffsetMode::ExcludePrim)
        );
        o.offset_mode = 3;
        assert!(o.to_options().is_err());
        o.offset_mode = 1;
        o.intersector = 2;
        assert!(o.to_options().is_err());
        Ok(())
    }
}
