//! Every structure the GPU reads or writes, as `#[repr(C)]` Pod types (CONVENTIONS.md: one
//! layout module). The kd-tree arrays (`KdNode`, `prim_indices`, the packed rope words and their `RankWord`s) and the
//! primitive arrays (`Triangle`, `Sphere`, `Ellipsoid`, `Plane`) are uploaded byte-for-byte as
//! the CPU holds them (DESIGN.md §2, "one tree format, two backends"); only boxes (glam `Vec3`
//! inside `Aabb`), materials and lights need a GPU form. The tests at the end parse the WGSL
//! and compare every size and member offset with these structs.

use crate::geometry::Aabb;
use crate::scene::{Material, PointLight};
use bytemuck::{Pod, Zeroable};

pub use crate::geometry::{Ellipsoid, Plane, Sphere, Triangle};
pub use crate::kdtree::{KdNode, RankWord};

/// A box as six floats (`Aabb` holds glam vectors, whose layout is not a GPU contract).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct GpuAabb {
    pub min: [f32; 3],
    pub max: [f32; 3],
}

impl From<&Aabb> for GpuAabb {
    fn from(b: &Aabb) -> Self {
        GpuAabb {
            min: b.min.to_array(),
            max: b.max.to_array(),
        }
    }
}

/// A material with the checker folded in (`checker == 0`: plain colour).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct GpuMaterial {
    pub color: [f32; 3],
    pub ambient: f32,
    pub diffuse: f32,
    pub specular: f32,
    pub shininess: f32,
    pub reflectivity: f32,
    pub transparency: f32,
    pub ior: f32,
    pub checker: u32,
    pub color2: [f32; 3],
    pub scale: f32,
    pub pad: u32,
}

impl From<&Material> for GpuMaterial {
    fn from(m: &Material) -> Self {
        let (checker, color2, scale) = match m.checker {
            Some(c) => (1, c.color2.to_array(), c.scale),
            None => (0, [0.0; 3], 1.0),
        };
        GpuMaterial {
            color: m.color.to_array(),
            ambient: m.ambient,
            diffuse: m.diffuse,
            specular: m.specular,
            shininess: m.shininess,
            reflectivity: m.reflectivity,
            transparency: m.transparency,
            ior: m.ior,
            checker,
            color2,
            scale,
            pad: 0,
        }
    }
}

#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct GpuLight {
    pub position: [f32; 3],
    pub intensity: f32,
    pub color: [f32; 3],
    pub pad: f32,
}

impl From<&PointLight> for GpuLight {
    fn from(l: &PointLight) -> Self {
        GpuLight {
            position: l.position.to_array(),
            intensity: l.intensity,
            color: l.color.to_array(),
            pad: 0.0,
        }
    }
}

/// One query ray: the `.rays` record and `rt2_ray` (origin, tmin, direction, tmax).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct GpuRay {
    pub org: [f32; 3],
    pub tmin: f32,
    pub dir: [f32; 3],
    pub tmax: f32,
}

/// A query's answer: closest hit (`prim == INVALID` for a miss, `t` then `+inf`) or, for
/// `occluded`, `prim != INVALID` when blocked.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct GpuHit {
    pub t: f32,
    pub u: f32,
    pub v: f32,
    pub prim: u32,
}

/// Iterations the kernels' last loop asks for (`GpuParams::probe_trips`): it stops after one
/// when the driver's loop budget ran out before it, and `loops_ran_to_the_end` asks whether it
/// came round a second time, so this must stay 2.
pub const PROBE_TRIPS: u32 = 2;

/// Per-ray work counters (thesis table 1), summed on the host in 64 bits.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct GpuStats {
    pub nodes: u32,
    pub leaves: u32,
    pub prims: u32,
    /// 1 when the driver cut the ray's traversal short (`loops_ran_to_the_end` in the kernels).
    pub cut: u32,
}

/// A ray still to trace in the wavefront path: where it goes, what it carries and for which
/// pixel. Secondary rays always have `tmin = 0`, `tmax = inf`, so those are not stored.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct GpuItem {
    pub org: [f32; 3],
    pub pixel: u32,
    pub dir: [f32; 3],
    pub depth: u32,
    pub weight: [f32; 3],
    /// The primitive the ray ignores (`OffsetMode::ExcludePrim`; `INVALID` for none).
    pub skip: u32,
    /// The leaf of `org` where its parent located it (ropes++: a mirror ray leaves from
    /// where the parent's shadow rays did), else `INVALID`: the kernel locates it.
    pub start: u32,
}

/// The one uniform block of the traversal kernels (queries and renders): scene sizes, the
/// camera and the frame part this dispatch covers. `vec4`s keep the uniform layout rules
/// (16-byte alignment of vectors) trivially equal on both sides.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct GpuParams {
    pub bounds_min: [f32; 4],
    pub bounds_max: [f32; 4],
    /// xyz eye, w aperture.
    pub eye: [f32; 4],
    /// xyz forward, w focus distance.
    pub forward: [f32; 4],
    /// xyz right, w half width of the image plane.
    pub right: [f32; 4],
    /// xyz up, w half height.
    pub up: [f32; 4],
    /// rgb background, w the secondary-ray offset (`Tracer::eps`).
    pub background: [f32; 4],
    /// Triangles, spheres, ellipsoids, boxes: the kind boundaries of the global index.
    pub n_tri: u32,
    pub n_sph: u32,
    pub n_ell: u32,
    pub n_box: u32,
    pub n_planes: u32,
    pub n_leaves: u32,
    pub n_lights: u32,
    pub short_stack: u32,
    /// Rays of a query, items of a wave, pixels of a frame chunk.
    pub count: u32,
    pub width: u32,
    pub height: u32,
    /// First image row of this chunk.
    pub row0: u32,
    pub samples: u32,
    /// Sample index of a wavefront pass.
    pub sample: u32,
    pub max_depth: u32,
    /// 0 straight transparency, 1 refraction.
    pub refract: u32,
    pub has_mask: u32,
    /// Bits per rope in the packed rope words (`RopeLinks::bits`; 0 without ropes).
    pub rope_bits: u32,
    /// 1 when a query's rays each ignore a primitive (its `excludes` buffer).
    pub excluding: u32,
    /// A render's `OffsetMode` (0 epsilon, 1 robust, 2 exclude-prim).
    pub offset_mode: u32,
    /// The scene diagonal, for the robust offset near the origin (`Tracer::scale`).
    pub scale: f32,
    /// Rays of smaller weight are not traced (`cpu::whitted::min_weight`).
    pub min_weight: f32,
    /// Iterations of the kernels' last loop, which tells whether the driver cut the job short
    /// (`loops_ran_to_the_end`): [`PROBE_TRIPS`], a run-time value so that it is not unrolled.
    pub probe_trips: u32,
    // A scalar, not an array: uniform arrays need a 16-byte stride.
    pub pad3: u32,
}

/// Uniform block of the prefix-sum kernels.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct GpuScanParams {
    /// Elements of the level being scanned.
    pub count: u32,
    pub pad0: u32,
    pub pad1: u32,
    pub pad2: u32,
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::mem::{offset_of, size_of};
    use wgpu::naga;

    /// (size, member offsets) of a WGSL struct as naga lays it out.
    fn wgsl_layout(source: &str, name: &str) -> (u32, Vec<(String, u32)>) {
        let module = naga::front::wgsl::parse_str(source).expect("WGSL parses");
        let mut layouter = naga::proc::Layouter::default();
        layouter.update(module.to_ctx()).expect("layout");
        let (handle, ty) = module
            .types
            .iter()
            .find(|(_, t)| t.name.as_deref() == Some(name))
            .unwrap_or_else(|| panic!("struct {name} in the WGSL"));
        let naga::TypeInner::Struct { members, .. } = &ty.inner else {
            panic!("{name} is not a struct");
        };
        let offsets = members
            .iter()
            .map(|m| (m.name.clone().unwrap_or_default(), m.offset))
            .collect();
        (layouter[handle].size, offsets)
    }

    /// Asserts size and offsets; `rust` lists (member, offset) in declaration order.
    fn check(name: &str, size: usize, rust: &[(&str, usize)]) {
        let src = super::super::kernels::prelude_for_layout_tests();
        let (wsize, woffsets) = wgsl_layout(&src, name);
        assert_eq!(wsize as usize, size, "size of {name}");
        let w: Vec<(String, usize)> = woffsets.into_iter().map(|(n, o)| (n, o as usize)).collect();
        let r: Vec<(String, usize)> = rust.iter().map(|(n, o)| (n.to_string(), *o)).collect();
        assert_eq!(w, r, "members of {name}");
    }

    macro_rules! layout {
        ($wgsl:literal, $t:ty, [$($f:ident),*]) => {
            check($wgsl, size_of::<$t>(), &[$((stringify!($f), offset_of!($t, $f))),*])
        };
    }

    #[test]
    fn host_structs_match_wgsl() {
        layout!("KdNode", KdNode, [split, bits]);
        layout!("RankWord", RankWord, [leaf_bits, before]);
        layout!("Triangle", Triangle, [v0, e1, e2]);
        layout!("Sphere", Sphere, [center, radius]);
        layout!("Ellipsoid", Ellipsoid, [center, inv, half, sigma, cof]);
        layout!("Aabb", GpuAabb, [min, max]);
        layout!("Plane", Plane, [normal, offset]);
        layout!(
            "Material",
            GpuMaterial,
            [
                color,
                ambient,
                diffuse,
                specular,
                shininess,
                reflectivity,
                transparency,
                ior,
                checker,
                color2,
                scale,
                pad
            ]
        );
        layout!("Light", GpuLight, [position, intensity, color, pad]);
        layout!("RayIn", GpuRay, [org, tmin, dir, tmax]);
        layout!("HitOut", GpuHit, [t, u, v, prim]);
        layout!("StatsOut", GpuStats, [nodes, leaves, prims, cut]);
        layout!(
            "Item",
            GpuItem,
            [org, pixel, dir, depth, weight, skip, start]
        );
        layout!(
            "Params",
            GpuParams,
            [
                bounds_min,
                bounds_max,
                eye,
                forward,
                right,
                up,
                background,
                n_tri,
                n_sph,
                n_ell,
                n_box,
                n_planes,
                n_leaves,
                n_lights,
                short_stack,
                count,
                width,
                height,
                row0,
                samples,
                sample,
                max_depth,
                refract,
                has_mask,
                rope_bits,
                excluding,
                offset_mode,
                scale,
                min_weight,
                probe_trips,
                pad3
            ]
        );
    }

    /// One element of every storage array the kernels bind fits in the smallest buffer
    /// (`MIN_BUFFER_BYTES`): an empty array is uploaded as that, and wgpu refuses to bind a
    /// buffer shorter than one element.
    #[test]
    fn one_element_of_every_storage_array_fits_the_smallest_buffer() {
        use super::super::device::MIN_BUFFER_BYTES;
        use super::super::kernels::{source, Program, SCAN};
        use crate::cpu::traverse::Traversal;
        let query = source(Traversal::Standard, Program::Query);
        let render = source(Traversal::Standard, Program::Render);
        for src in [query.as_str(), render.as_str(), SCAN] {
            let module = naga::front::wgsl::parse_str(src).expect("WGSL parses");
            for (_, var) in module.global_variables.iter() {
                if let (naga::AddressSpace::Storage { .. }, naga::TypeInner::Array { stride, .. }) =
                    (var.space, &module.types[var.ty].inner)
                {
                    assert!(
                        u64::from(*stride) <= MIN_BUFFER_BYTES,
                        "{:?}: {stride} bytes an element",
                        var.name
                    );
                }
            }
        }
    }

    #[test]
    fn scan_params_match_wgsl() {
        let src = super::super::kernels::SCAN;
        let (size, offsets) = wgsl_layout(src, "ScanParams");
        assert_eq!(size as usize, size_of::<GpuScanParams>());
        let rust = [
            ("count", offset_of!(GpuScanParams, count)),
            ("pad0", offset_of!(GpuScanParams, pad0)),
            ("pad1", offset_of!(GpuScanParams, pad1)),
            ("pad2", offset_of!(GpuScanParams, pad2)),
        ];
        let rust: Vec<(String, u32)> = rust
            .iter()
            .map(|(n, o)| (n.to_string(), *o as u32))
            .collect();
        assert_eq!(offsets, rust);
    }
}
