//! Batch ray queries on the GPU: one thread per ray, the batch cut into pieces that fit the
//! device's storage bindings. Runs on the context's first device.

use super::device::{lock_cache, Device};
use super::kernels::Program;
use super::layout::{GpuHit, GpuParams, GpuRay, GpuStats};
use super::{GpuError, GpuResult};
use crate::cpu::traverse::Traversal;
use crate::fallible;
use crate::geometry::{Hit, PrimIndex, Ray, TraversalStats};
use crate::scene::Committed;

/// Closest hits (`hits = Some`) or any-hit flags (`occluded = Some`) of `rays`, ray `i`
/// ignoring primitive `exclude[i]` when `exclude` is given.
pub(crate) fn run(
    dev: &Device,
    scene: &Committed,
    (rays, exclude): (&[Ray], Option<&[PrimIndex]>),
    traversal: Traversal,
    short_stack: usize,
    mut hits: Option<&mut [Hit]>,
    mut occluded: Option<&mut [bool]>,
) -> GpuResult<TraversalStats> {
    let _job = dev.begin_job()?;
    let pipelines = dev.pipelines(traversal, Program::Query)?;
    let pipeline = &pipelines[if hits.is_some() { 0 } else { 1 }];
    let mut cache = lock_cache(&dev.scene);
    let scene_group = &cache.sync(dev, scene)?;
    // Hits and statistics are 16 bytes per ray, rays 32: the ray buffer sets the piece.
    let align = dev.limits.min_storage_buffer_offset_alignment as u64;
    let per = (dev.max_binding().saturating_sub(align) / std::mem::size_of::<GpuRay>() as u64)
        .min(dev.max_threads())
        .max(1) as usize;
    let mut stats = TraversalStats::default();
    for (k, piece) in rays.chunks(per).enumerate() {
        let gpu_rays: Vec<GpuRay> = fallible::collect(piece.iter().map(gpu_ray))?;
        let params = cache.job(GpuParams {
            count: piece.len() as u32,
            short_stack: short_stack as u32,
            excluding: exclude.is_some() as u32,
            ..GpuParams::default()
        });
        let n = piece.len() as u64;
        let ray_buf = dev.upload(
            "rays",
            bytemuck::cast_slice(&gpu_rays),
            wgpu::BufferUsages::empty(),
        );
        // Without exclusions the shader reads none: the rays stand in for the binding.
        let exclude_buf = exclude.map(|e| {
            let e = &e[k * per..][..piece.len()];
            dev.upload(
                "excludes",
                bytemuck::cast_slice(e),
                wgpu::BufferUsages::empty(),
            )
        });
        // Hits then stats in one buffer, so that one read-back brings both.
        let hit_bytes = 16 * n;
        let stat_offset = hit_bytes.next_multiple_of(align);
        let out = dev.scratch(
            "hits",
            stat_offset + hit_bytes,
            wgpu::BufferUsages::COPY_SRC,
        )?;
        let hit_view = wgpu::BufferBinding {
            buffer: &out,
            offset: 0,
            size: wgpu::BufferSize::new(hit_bytes),
        };
        let stat_view = wgpu::BufferBinding {
            buffer: &out,
            offset: stat_offset,
            size: wgpu::BufferSize::new(hit_bytes),
        };
        let uniform = dev.uniform(&params);
        let io = dev.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("query io"),
            layout: &dev.layouts.query_io,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: uniform.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: ray_buf.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 2,
                    resource: wgpu::BindingResource::Buffer(hit_view),
                },
                wgpu::BindGroupEntry {
                    binding: 3,
                    resource: wgpu::BindingResource::Buffer(stat_view.clone()),
                },
                wgpu::BindGroupEntry {
                    binding: 4,
                    resource: exclude_buf.as_ref().unwrap_or(&ray_buf).as_entire_binding(),
                },
            ],
        });
        let mut enc = dev.device.create_command_encoder(&Default::default());
        dev.dispatch(&mut enc, pipeline, &[scene_group, &io], n);
        let bytes = dev.read_back(enc, &out, 0, stat_view.offset + hit_bytes)?;
        let gh: &[GpuHit] = bytemuck::cast_slice(&bytes[..hit_bytes as usize]);
        let gs: &[GpuStats] = bytemuck::cast_slice(&bytes[stat_view.offset as usize..]);
        // Answers that may be wrong are not answers, and are not written: the piece is checked
        // before its hits reach `hits` (a refused one-piece job leaves them as they were; the
        // earlier pieces of a longer one stay written, as on any failure part-way). AUTO
        // traces the batch on the CPU.
        let cut = gs.iter().filter(|s| s.cut != 0).count();
        if cut > 0 {
            return Err(GpuError::cut_short(cut, "rays"));
        }
        let base = k * per;
        for (i, h) in gh.iter().enumerate() {
            if let Some(out) = hits.as_deref_mut() {
                out[base + i] = Hit {
                    t: h.t,
                    u: h.u,
                    v: h.v,
                    prim: h.prim,
                };
            }
            if let Some(out) = occluded.as_deref_mut() {
                out[base + i] = h.prim != crate::geometry::INVALID;
            }
        }
        for s in gs {
            stats.nodes_visited += s.nodes as u64;
            stats.leaves_visited += s.leaves as u64;
            stats.prim_tests += s.prims as u64;
        }
    }
    Ok(stats)
}

/// A degenerate ray (NaN, infinities, zero direction, empty window) becomes an empty window:
/// the kernel checks too, but its NaN tests must not be the only guard against compilers
/// that assume finite math. (`Context` has scaled directions far from unit length.)
fn gpu_ray(r: &Ray) -> GpuRay {
    if r.is_degenerate() {
        return GpuRay {
            org: [0.0; 3],
            tmin: 1.0,
            dir: [1.0, 0.0, 0.0],
            tmax: 0.0,
        };
    }
    GpuRay {
        org: r.org.to_array(),
        tmin: r.tmin,
        dir: r.dir.to_array(),
        tmax: r.tmax,
    }
}
