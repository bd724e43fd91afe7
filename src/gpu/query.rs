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
    hits: Option<&mut [Hit]>,
    occluded: Option<&mut [bool]>,
) -> GpuResult<TraversalStats> {
    let _job = dev.begin_job()?;
    let pipelines = dev.pipelines(traversal, Program::Query)?;
    let pipeline = &pipelines[if hits.is_some() { 0 } else { 1 }];
    trace(
        dev,
        pipeline,
        scene,
        (rays, exclude),
        short_stack,
        hits,
        occluded,
    )
}

/// [`run`] with the kernel `pipeline` (of the query layout, a job already begun).
fn trace(
    dev: &Device,
    pipeline: &wgpu::ComputePipeline,
    scene: &Committed,
    (rays, exclude): (&[Ray], Option<&[PrimIndex]>),
    short_stack: usize,
    mut hits: Option<&mut [Hit]>,
    mut occluded: Option<&mut [bool]>,
) -> GpuResult<TraversalStats> {
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

#[cfg(test)]
mod tests {
    use super::super::device::open_for_tests;
    use super::super::kernels::{create_pipelines, source};
    use super::*;
    use glam::Vec3;

    /// Entry points over the ropes++ query module: rays started at the leaf of their origin, as
    /// the render starts its secondary rays (`start_leaf`, then ropes_pp.wgsl's `walk_start`), or
    /// given the leaf of the point opposite the origin across the scene's centre, which mostly
    /// does not hold it.
    const STARTED: &str = "
fn started(i: u32, p: vec3<f32>) {
    var r = load_ray(i);
    r.start = start_leaf(p);
    var st = Stats(0u, 0u, 0u);
    let h = closest_hit(r, &st);
    hits[i] = HitOut(h.t, h.u, h.v, h.prim);
    stats[i] = StatsOut(st.nodes, st.leaves, st.prims, select(1u, 0u, loops_ran_to_the_end()));
}
@compute @workgroup_size(64)
fn origin_leaf_main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_id) lid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = flat_id(wid, lid, nwg);
    if (i < params.count) { started(i, v3(rays[i].org)); }
}
@compute @workgroup_size(64)
fn opposite_leaf_main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_id) lid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = flat_id(wid, lid, nwg);
    if (i < params.count) { started(i, params.bounds_min.xyz + params.bounds_max.xyz - v3(rays[i].org)); }
}
";

    /// The GPU's ropes++ start in the leaf of a ray's origin (the thesis' algorithm 8; the
    /// render's secondary rays take it): rays from points inside spheres2's scene get the hits
    /// of the walk from the root, bit for bit, visiting fewer nodes; given a leaf that does not
    /// hold their origin they fall back to the root, and still get the same hits.
    #[test]
    fn ropes_plus_plus_starts_rays_in_the_leaf_of_their_origin() {
        let Some(gpu) = open_for_tests() else {
            return;
        };
        let dev = &gpu.devices[0];
        let mut b = crate::scene::builtin::by_name("spheres2").unwrap();
        b.scene.commit().unwrap();
        b.scene.ensure_ropes().unwrap();
        let c = b.scene.committed().unwrap();
        let mut rng = crate::rng::Rng(7);
        let mut unit = || Vec3::new(rng.unit(), rng.unit(), rng.unit());
        let rays: Vec<Ray> = (0..4096)
            .map(|_| {
                let org = c.bounds.min + unit() * (c.bounds.max - c.bounds.min);
                let dir = (2.0 * unit() - Vec3::ONE).normalize();
                Ray::new(org, dir, 0.0, f32::INFINITY)
            })
            .collect();
        let how = Traversal::RopesPlusPlus;
        let trace_with = |pipeline: Option<&wgpu::ComputePipeline>| {
            let mut hits = vec![Hit::MISS; rays.len()];
            let stats = match pipeline {
                Some(p) => trace(dev, p, c, (&rays, None), 3, Some(&mut hits), None),
                None => run(dev, c, (&rays, None), how, 3, Some(&mut hits), None),
            };
            (hits, stats.unwrap().nodes_visited)
        };
        let src = format!("{}\n{STARTED}", source(how, Program::Query));
        let entries = ["origin_leaf_main", "opposite_leaf_main"];
        let p =
            create_pipelines(&dev.device, "started", &src, &dev.layouts.query, &entries).unwrap();
        let (want, from_root) = trace_with(None);
        let (origin, from_origin) = trace_with(Some(&p[0]));
        let (opposite, from_opposite) = trace_with(Some(&p[1]));
        assert!(want.iter().filter(|h| h.is_hit()).count() > 1000);
        assert!(origin == want, "hits from the origin's leaf");
        assert!(opposite == want, "hits after a wrong start leaf");
        println!("nodes: {from_origin} from the origin's leaf, {from_root} from the root");
        assert!(from_origin < from_root);
        assert!(from_origin < from_opposite);
    }
}
