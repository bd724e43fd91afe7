//! The committed scene on a device: the flat kd-tree and primitive arrays uploaded
//! byte-for-byte, plus what shading reads. Uploaded once per commit, and then only the arrays
//! whose bytes changed (a material edit does not re-send a million triangles); ropes follow
//! when a rope traversal first needs them.

use super::device::Device;
use super::layout::{GpuAabb, GpuLight, GpuMaterial, GpuParams};
use super::{GpuError, GpuResult};
use crate::scene::Committed;
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

/// The arrays of `c` in binding order, as bytes.
fn arrays(c: &Committed) -> Vec<Vec<u8>> {
    let t = &c.tree;
    let p = &c.prims;
    let bytes = |s: &[u8]| s.to_vec();
    let boxes: Vec<GpuAabb> = p.boxes.iter().map(GpuAabb::from).collect();
    let (rank, links, leaf_boxes): (Vec<u8>, Vec<u8>, Vec<GpuAabb>) = match &t.ropes {
        Some(r) => (
            bytemuck::cast_slice(&r.rank).to_vec(),
            bytemuck::cast_slice(&r.links.words).to_vec(),
            r.leaf_bounds.iter().map(GpuAabb::from).collect(),
        ),
        None => (Vec::new(), Vec::new(), Vec::new()),
    };
    let prim_material: Vec<u32> = c
        .origins
        .iter()
        .map(|o| c.object_material[o.object as usize])
        .collect();
    let materials: Vec<GpuMaterial> = c.materials.iter().map(GpuMaterial::from).collect();
    let lights: Vec<GpuLight> = c.lights.iter().map(GpuLight::from).collect();
    vec![
        bytes(bytemuck::cast_slice(&t.nodes)),
        rank,
        bytes(bytemuck::cast_slice(&t.prim_indices)),
        bytes(bytemuck::cast_slice(&p.triangles)),
        bytes(bytemuck::cast_slice(&p.spheres)),
        bytes(bytemuck::cast_slice(&p.ellipsoids)),
        bytes(bytemuck::cast_slice(&boxes)),
        bytes(bytemuck::cast_slice(&p.planes)),
        links,
        bytes(bytemuck::cast_slice(&leaf_boxes)),
        bytes(bytemuck::cast_slice(&prim_material)),
        bytes(bytemuck::cast_slice(&materials)),
        bytes(bytemuck::cast_slice(&lights)),
    ]
}

impl SceneCache {
    /// A job's parameters with the scene's part (bounds and counts) filled in.
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
            ..job
        }
    }

    /// Makes the device's copy match `c`. `Limits` when an array exceeds a storage binding.
    pub fn sync(&mut self, dev: &Device, c: &Committed) -> GpuResult<()> {
        let key = (c.id, c.tree.ropes.is_some());
        if self.key == Some(key) && self.bind_group.is_some() {
            self.last_uploads.clear();
            return Ok(());
        }
        let data = arrays(c);
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
        self.bind_group = Some(dev.bind(&dev.layouts.scene, &buffers));
        self.params = scene_params(c);
        self.key = Some(key);
        if let Err(e) = dev.check() {
            // A buffer that failed (out of memory) must not be taken for the scene next time.
            *self = SceneCache::default();
            return Err(e);
        }
        Ok(())
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
