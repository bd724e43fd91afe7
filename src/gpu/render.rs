//! Whitted frames on the GPU, by either render path of thesis §3.3:
//!
//! - **megakernel**: one thread per pixel runs the whole iterative ray loop;
//! - **wavefront**: one kernel launch per bounce over the rays still alive, which are
//!   compacted after every bounce by a parallel prefix sum over their child slots, so that
//!   no thread idles on a pixel whose rays have all ended (up to 30% faster in the thesis
//!   for scenes with many reflective objects).
//!
//! With several devices each renders a band of rows and the bands are gathered (the
//! thesis' dual-GPU set-up). A device renders its band in chunks that fit its bindings.

use super::device::{lock_cache, Device, Gpu};
use super::kernels::Program;
use super::layout::{GpuItem, GpuParams, GpuScanParams};
use super::{GpuError, GpuResult};
use crate::camera::Camera;
use crate::cpu::traverse::Traversal;
use crate::fallible::{self, Fallible};
use crate::frame::Frame;
use crate::precision::OffsetMode;
use crate::render::{RenderOptions, Transparency};
use crate::scene::Committed;

/// Which render path of thesis §3.3 runs a frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GpuPath {
    Megakernel,
    Wavefront,
}

impl GpuPath {
    pub fn name(self) -> &'static str {
        match self {
            GpuPath::Megakernel => "megakernel",
            GpuPath::Wavefront => "wavefront",
        }
    }
}

/// Most pixels of one chunk of rows, whatever the adapter's binding limit allows: each chunk's
/// pixels are read back through two host copies, which then stay small next to the frame (a
/// whole 4 GiB frame in one chunk needed several times the frame in host memory). 8192² and
/// smaller frames are still one chunk.
const CHUNK_PIXELS: u64 = 1 << 26;

/// Items of one chunk's wave queue per pixel: a pixel's ray tree may widen (refraction plus
/// reflection); wider waves make the chunk fall back to the megakernel.
const QUEUE_PER_PIXEL: u64 = 2;

/// Renders `frame`; `traversal` and `path` are already decided.
pub(crate) fn render(
    gpu: &Gpu,
    scene: &Committed,
    camera: &Camera,
    opts: &RenderOptions,
    traversal: Traversal,
    path: GpuPath,
    frame: &mut Frame,
) -> GpuResult<()> {
    let (w, h) = (frame.width(), frame.height());
    let [eye, forward, right, up] = camera.rays(w, h).packed();
    let base = GpuParams {
        eye,
        forward,
        right,
        up,
        background: {
            let b = opts.background;
            [b.x, b.y, b.z, 1e-5 * scene.scale()]
        },
        width: w,
        height: h,
        samples: opts.samples,
        max_depth: opts.max_depth,
        refract: (opts.transparency == Transparency::Refract) as u32,
        offset_mode: match opts.offset_mode {
            OffsetMode::Epsilon => 0,
            OffsetMode::Robust => 1,
            OffsetMode::ExcludePrim => 2,
        },
        scale: scene.scale(),
        min_weight: crate::cpu::whitted::min_weight(scene, opts),
        short_stack: opts.short_stack_size as u32,
        ..GpuParams::default()
    };
    let n = gpu.devices.len() as u32;
    let bands: Vec<(u32, u32)> = (0..n).map(|k| (h * k / n, h * (k + 1) / n)).collect();
    let (pixels, mask) = frame.pixels_and_mask_mut();
    let results: Vec<GpuResult<Vec<u32>>> = std::thread::scope(|s| {
        let jobs: Vec<_> = gpu
            .devices
            .iter()
            .zip(&bands)
            .map(|(dev, &(a, b))| {
                let job = Job {
                    dev,
                    scene,
                    base,
                    traversal,
                    mask,
                };
                s.spawn(move || job.rows(a, b, path))
            })
            .collect();
        jobs.into_iter()
            .map(|j| {
                j.join()
                    .unwrap_or_else(|_| Err(GpuError::Other(panicked())))
            })
            .collect()
    });
    // Nothing is written unless every band arrived: a failed frame is left as it was.
    let results = results.into_iter().collect::<GpuResult<Vec<_>>>()?;
    // Every pixel the frame shows, with its index in the frame (masked ones are left alone).
    let shown = || {
        bands
            .iter()
            .zip(&results)
            .flat_map(|((a, _), band)| {
                let first = *a as usize * w as usize;
                band.iter().enumerate().map(move |(i, &px)| (first + i, px))
            })
            .filter(|&(idx, _)| mask.is_none_or(|m| m[idx] != 0))
    };
    // The kernels mark a pixel whose work the driver cut short with alpha 0
    // (`loops_ran_to_the_end`): such a frame is not shown, and AUTO renders it on the CPU.
    let cut = shown().filter(|&(_, px)| px >> 24 == 0).count();
    if cut > 0 {
        return Err(GpuError::cut_short(cut, "pixels"));
    }
    for (idx, px) in shown() {
        pixels[4 * idx..4 * idx + 4].copy_from_slice(&px.to_le_bytes());
    }
    Ok(())
}

fn panicked() -> crate::error::Error {
    crate::error::Error::new(
        crate::error::Rt2Status::Internal,
        "a GPU render thread panicked",
    )
}

/// One device's share of a frame.
struct Job<'a> {
    dev: &'a Device,
    scene: &'a Committed,
    base: GpuParams,
    traversal: Traversal,
    mask: Option<&'a [u8]>,
}

impl Job<'_> {
    /// Rows `[a, b)` as packed RGBA8, in chunks that fit the device.
    fn rows(&self, a: u32, b: u32, path: GpuPath) -> GpuResult<Vec<u32>> {
        let dev = self.dev;
        let _job = dev.begin_job()?;
        let pipelines = dev.pipelines(self.traversal, Program::Render)?;
        let mut cache = lock_cache(&dev.scene);
        let scene_group = cache.sync(dev, self.scene)?;
        let base = cache.job(self.base);
        // The bind group keeps the scene's buffers alive: other jobs may use the device now.
        drop(cache);
        let w = base.width as u64;
        // Largest per-pixel binding: the frame (4 bytes) or the wave's child slots.
        let per_pixel = match path {
            GpuPath::Megakernel => 4,
            GpuPath::Wavefront => 2 * QUEUE_PER_PIXEL * std::mem::size_of::<GpuItem>() as u64,
        };
        let chunk_px = (dev.max_binding() / per_pixel)
            .min(CHUNK_PIXELS)
            .min(dev.max_threads() / 4);
        let chunk_rows = (chunk_px / w).max(1) as u32;
        let band = ((b - a) as u64 * w) as usize;
        let mut out = Vec::new();
        // The band's pixels on the host: a failed allocation is OUT_OF_MEMORY (AUTO falls back
        // to the CPU), never an abort (a 32768² frame is 4 GiB).
        out.try_reserve_exact(band).map_err(|_| {
            GpuError::OutOfMemory(format!("{} bytes for the frame's read-back", 4 * band))
        })?;
        let mut row = a;
        while row < b {
            let rows = chunk_rows.min(b - row);
            let params = GpuParams {
                row0: row,
                count: rows * base.width,
                ..base
            };
            let mask = self.mask_words(row, rows)?;
            let px = match path {
                GpuPath::Megakernel => {
                    self.megakernel(&pipelines[0], &scene_group, params, &mask)?
                }
                GpuPath::Wavefront => {
                    match self.wavefront(&pipelines[1..], &scene_group, params, &mask) {
                        Ok(px) => px,
                        // A ray tree wider than the queue: this chunk goes to the megakernel.
                        Err(GpuError::Limits(_)) => {
                            self.megakernel(&pipelines[0], &scene_group, params, &mask)?
                        }
                        Err(e) => return Err(e),
                    }
                }
            };
            out.extend_from_slice(&px);
            row += rows;
        }
        Ok(out)
    }

    /// The HUD mask of `rows` rows from `row0`, one word per pixel (empty: no mask).
    fn mask_words(&self, row0: u32, rows: u32) -> Fallible<Vec<u32>> {
        let w = self.base.width as usize;
        self.mask.map_or(Ok(Vec::new()), |m| {
            fallible::collect(
                m[row0 as usize * w..(row0 + rows) as usize * w]
                    .iter()
                    .map(|&b| b as u32),
            )
        })
    }

    fn megakernel(
        &self,
        pipeline: &wgpu::ComputePipeline,
        scene: &wgpu::BindGroup,
        mut params: GpuParams,
        mask: &[u32],
    ) -> GpuResult<Vec<u32>> {
        let dev = self.dev;
        params.has_mask = !mask.is_empty() as u32;
        let n = params.count as u64;
        let frame = dev.scratch("frame", 4 * n, wgpu::BufferUsages::COPY_SRC)?;
        let mask_buf = dev.upload(
            "mask",
            bytemuck::cast_slice(mask),
            wgpu::BufferUsages::empty(),
        );
        let uniform = dev.uniform(&params);
        let io = dev.bind(&dev.layouts.mega_io, &[&uniform, &frame, &mask_buf]);
        let mut enc = dev.device.create_command_encoder(&Default::default());
        dev.dispatch(&mut enc, pipeline, &[scene, &io], n);
        let bytes = dev.read_back(enc, &frame, 0, 4 * n)?;
        Ok(fallible::copied(bytemuck::cast_slice(&bytes))?)
    }

    /// `pipes`: generate, trace, accumulate, compact, finalize.
    fn wavefront(
        &self,
        pipes: &[wgpu::ComputePipeline],
        scene: &wgpu::BindGroup,
        mut params: GpuParams,
        mask: &[u32],
    ) -> GpuResult<Vec<u32>> {
        let dev = self.dev;
        params.has_mask = !mask.is_empty() as u32;
        let n = params.count as u64;
        let item = std::mem::size_of::<GpuItem>() as u64;
        let cap = QUEUE_PER_PIXEL * n;
        let copy = wgpu::BufferUsages::COPY_SRC;
        let none = wgpu::BufferUsages::empty();
        let frame = dev.scratch("frame", 4 * n, copy)?;
        let mask_buf = dev.upload("mask", bytemuck::cast_slice(mask), none);
        let queue = dev.scratch("wave queue", item * cap, none)?;
        let slots = dev.scratch("wave slots", item * 2 * cap, none)?;
        let scan = Scan::new(dev, 2 * cap)?;
        let contrib = dev.scratch("wave colours", 16 * cap, none)?;
        let accum = dev.scratch("pixel sums", 16 * n, none)?;
        let io = |p: &GpuParams| {
            let u = dev.uniform(p);
            dev.bind(
                &dev.layouts.wave_io,
                &[
                    &u,
                    &frame,
                    &mask_buf,
                    &queue,
                    &slots,
                    &scan.levels[0],
                    &contrib,
                    &accum,
                ],
            )
        };
        let [generate, trace, accumulate, compact, finalize] = pipes else {
            return Err(GpuError::Other(crate::error::Error::new(
                crate::error::Rt2Status::Internal,
                format!("the wavefront program has {} kernels, not 5", pipes.len()),
            )));
        };
        for s in 0..params.samples {
            let p = GpuParams {
                sample: s,
                ..params
            };
            let mut enc = dev.device.create_command_encoder(&Default::default());
            dev.dispatch(&mut enc, generate, &[scene, &io(&p)], n);
            let mut count = scan.compact(&mut enc, compact, scene, &io, p, 2 * n, dev)?;
            while count > 0 {
                if count as u64 > cap {
                    return Err(GpuError::Limits(format!(
                        "{count} rays in one wave exceed the queue of {cap}"
                    )));
                }
                let p = GpuParams {
                    count,
                    sample: s,
                    ..params
                };
                let g = io(&p);
                let mut enc = dev.device.create_command_encoder(&Default::default());
                dev.dispatch(&mut enc, trace, &[scene, &g], count as u64);
                dev.dispatch(&mut enc, accumulate, &[scene, &g], count as u64);
                count = scan.compact(&mut enc, compact, scene, &io, p, 2 * count as u64, dev)?;
            }
        }
        let mut enc = dev.device.create_command_encoder(&Default::default());
        dev.dispatch(&mut enc, finalize, &[scene, &io(&params)], n);
        let bytes = dev.read_back(enc, &frame, 0, 4 * n)?;
        Ok(fallible::copied(bytemuck::cast_slice(&bytes))?)
    }
}

/// The levels of the multi-level prefix sum: level 0 holds the slot flags, level k+1 one
/// total per 64 elements of level k.
struct Scan {
    levels: Vec<wgpu::Buffer>,
    pipes: std::sync::Arc<Vec<wgpu::ComputePipeline>>,
}

impl Scan {
    fn new(dev: &Device, max: u64) -> GpuResult<Self> {
        let mut levels = vec![dev.scratch("scan", 4 * max, wgpu::BufferUsages::COPY_SRC)?];
        let mut n = max;
        while n > 1 {
            n = n.div_ceil(64);
            levels.push(dev.scratch("scan sums", 4 * n, wgpu::BufferUsages::empty())?);
        }
        Ok(Scan {
            levels,
            pipes: dev.scan_pipelines()?,
        })
    }

    /// Scans the `slots` flags, moves the live slots to the queue (`compact`), submits and
    /// returns how many there are: the next wave's size, which sets its dispatch.
    #[allow(clippy::too_many_arguments)]
    fn compact(
        &self,
        enc: &mut wgpu::CommandEncoder,
        compact: &wgpu::ComputePipeline,
        scene: &wgpu::BindGroup,
        io: &dyn Fn(&GpuParams) -> wgpu::BindGroup,
        p: GpuParams,
        slots: u64,
        dev: &Device,
    ) -> GpuResult<u32> {
        let mut sizes = vec![slots];
        while *sizes.last().unwrap_or(&1) > 64 {
            let s = sizes.last().copied().unwrap_or(1).div_ceil(64);
            sizes.push(s);
        }
        let group = |k: usize, count: u64| {
            let u = dev.uniform(&GpuScanParams {
                count: count as u32,
                ..Default::default()
            });
            dev.bind(
                &dev.layouts.scan_io,
                &[&u, &self.levels[k], &self.levels[k + 1]],
            )
        };
        for (k, &s) in sizes.iter().enumerate() {
            dev.dispatch(enc, &self.pipes[0], &[&group(k, s)], s);
        }
        for k in (0..sizes.len() - 1).rev() {
            dev.dispatch(enc, &self.pipes[1], &[&group(k, sizes[k])], sizes[k]);
        }
        let cp = GpuParams {
            count: slots as u32,
            ..p
        };
        dev.dispatch(enc, compact, &[scene, &io(&cp)], slots);
        let e = std::mem::replace(enc, dev.device.create_command_encoder(&Default::default()));
        let total = dev.read_back(e, &self.levels[0], 4 * (slots - 1), 4)?;
        Ok(u32::from_le_bytes([total[0], total[1], total[2], total[3]]))
    }
}
