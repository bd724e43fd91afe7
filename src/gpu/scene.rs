//! The committed scene on a device: the flat kd-tree and primitive arrays uploaded
//! byte-for-byte, plus what shading reads. Uploaded once per commit, and then only the arrays
//! whose bytes changed (a material edit does not re-send a million triangles); ropes follow
//! when a rope traversal first needs them.

use super::device::Device;
use super::layout::{GpuAabb, GpuLight, GpuMaterial, GpuParams, PROBE_TRIPS};
use super::{GpuError, GpuResult};
use crate::fallible::{self, Fallible};
use crate::geometry::Aabb;
use crate::scene::Committed;
use std::borrow::Cow;
use std::hash::{DefaultHasher, Hasher};

/// Scene arrays in binding order (common.wgsl, group 0).
const NAMES: [&str; 13] = [
    "nodes",
    "leaf_rank",
    "prim_indices",
    "triangles",
    "spheres",
    "ellipsoids",
    "boxes",
    "planes",
    "ropes",
    "leaf_boxes",
    "prim_material",
    "materials",
    "lights",
];

struct Uploaded {
    len: usize,
    hash: u64,
    buffer: wgpu::Buffer,
}

/// What a device holds of the last scene it traced.
#[derive(Default)]
pub(crate) struct SceneCache {
    /// Commit id and whether ropes were present when the arrays were last compared.
    key: Option<(u64, bool)>,
    arrays: Vec<Option<Uploaded>>,
    pub bind_group: Option<wgpu::BindGroup>,
    /// The scene part of every kernel's parameters (see [`SceneCache::job`]).
    params: GpuParams,
    /// Arrays re-sent by the last sync (tests check that unchanged ones are not).
    pub last_uploads: Vec<&'static str>,
}

fn hash(bytes: &[u8]) -> u64 {
    let mut h = DefaultHasher::new();
    h.write(bytes);
    h.finish()
}

/// The arrays of `c` in binding order, as bytes: the ones in the device's layout already are
/// borrowed (the tree, the triangles: no host copy of a large scene), the others converted
/// into new arrays, allocated fallibly (`OutOfMemory` instead of an abort).
fn arrays(c: &Committed) -> Fallible<Vec<Cow<'_, [u8]>>> {
    let t = &c.tree;
    let p = &c.prims;
    let (rank, links, leaf_bounds): (&[u8], &[u8], &[Aabb]) = match &t.ropes {
        Some(r) => (
            bytemuck::cast_slice(&r.rank),
            bytemuck::cast_slice(&r.links.words),
            &r.leaf_bounds,
        ),
        None => (&[], &[], &[]),
    };
    Ok(vec![
        Cow::Borrowed(bytemuck::cast_slice(&t.nodes)),
        Cow::Borrowed(rank),
        Cow::Borrowed(bytemuck::cast_slice(&t.prim_indices)),
        Cow::Borrowed(bytemuck::cast_slice(&p.triangles)),
        Cow::Borrowed(bytemuck::cast_slice(&p.spheres)),
        Cow::Borrowed(bytemuck::cast_slice(&p.ellipsoids)),
        converted(p.boxes.iter().map(GpuAabb::from))?,
        Cow::Borrowed(bytemuck::cast_slice(&p.planes)),
        Cow::Borrowed(links),
        converted(leaf_bounds.iter().map(GpuAabb::from))?,
        converted(
            c.origins
                .iter()
                .map(|o| c.object_material[o.object as usize]),
        )?,
        converted(c.materials.iter().map(GpuMaterial::from))?,
        converted(c.lights.iter().map(GpuLight::from))?,
    ])
}

/// The bytes of `items` in the device's layout.
fn converted<T: bytemuck::Pod>(
    items: impl ExactSizeIterator<Item = T>,
) -> Fallible<Cow<'static, [u8]>> {
    let mut bytes = fallible::with_capacity(items.len() * std::mem::size_of::<T>())?;
    for x in items {
        bytes.extend_from_slice(bytemuck::bytes_of(&x));
    }
    Ok(Cow::Owned(bytes))
}

impl SceneCache {
    /// A job's parameters with the scene's part (bounds and counts) and the loop probe's
    /// iterations filled in.
    pub fn job(&self, job: GpuParams) -> GpuParams {
        let s = &self.params;
        GpuParams {
            bounds_min: s.bounds_min,
            bounds_max: s.bounds_max,
            n_tri: s.n_tri,
            n_sph: s.n_sph,
            n_ell: s.n_ell,
            n_box: s.n_box,
            n_planes: s.n_planes,
            n_leaves: s.n_leaves,
            n_lights: s.n_lights,
            rope_bits: s.rope_bits,
            probe_trips: PROBE_TRIPS,
            ..job
        }
    }

    /// Makes the device's copy match `c`, and returns the bind group of its arrays. `Limits`
    /// when an array exceeds a storage binding.
    pub fn sync(&mut self, dev: &Device, c: &Committed) -> GpuResult<wgpu::BindGroup> {
        let key = (c.id, c.tree.ropes.is_some());
        if let (true, Some(group)) = (self.key == Some(key), &self.bind_group) {
            self.last_uploads.clear();
            return Ok(group.clone());
        }
        let data = arrays(c).map_err(|_| {
            GpuError::OutOfMemory("no host memory to convert the scene for the device".into())
        })?;
        for (name, d) in NAMES.iter().zip(&data) {
            if d.len() as u64 > dev.max_binding() {
                return Err(GpuError::Limits(format!(
                    "the scene's {name} take {} bytes, more than the {} bytes a storage binding of {} may hold",
                    d.len(),
                    dev.max_binding(),
                    dev.name
                )));
            }
        }
        self.arrays.resize_with(NAMES.len(), || None);
        self.last_uploads.clear();
        for (i, d) in data.iter().enumerate() {
            let h = hash(d);
            let same = self.arrays[i]
                .as_ref()
                .is_some_and(|u| u.len == d.len() && u.hash == h);
            if !same {
                self.arrays[i] = Some(Uploaded {
                    len: d.len(),
                    hash: h,
                    buffer: dev.upload(NAMES[i], d, wgpu::BufferUsages::empty()),
                });
                self.last_uploads.push(NAMES[i]);
            }
        }
        let buffers: Vec<&wgpu::Buffer> = self.arrays.iter().flatten().map(|u| &u.buffer).collect();
        let group = dev.bind(&dev.layouts.scene, &buffers);
        self.bind_group = Some(group.clone());
        self.params = scene_params(c);
        self.key = Some(key);
        if let Err(e) = dev.check() {
            // A buffer that failed (out of memory) must not be taken for the scene next time.
            *self = SceneCache::default();
            return Err(e);
        }
        Ok(group)
    }
}

fn scene_params(c: &Committed) -> GpuParams {
    let b = &c.tree.bounds;
    let p = &c.prims;
    GpuParams {
        bounds_min: [b.min.x, b.min.y, b.min.z, 0.0],
        bounds_max: [b.max.x, b.max.y, b.max.z, 0.0],
        n_tri: p.triangles.len() as u32,
        n_sph: p.spheres.len() as u32,
        n_ell: p.ellipsoids.len() as u32,
        n_box: p.boxes.len() as u32,
        n_planes: p.planes.len() as u32,
        n_leaves: c.tree.leaf_count() as u32,
        rope_bits: c.tree.ropes.as_ref().map_or(0, |r| r.links.bits),
        n_lights: c.lights.len() as u32,
        ..GpuParams::default()
    }
}
