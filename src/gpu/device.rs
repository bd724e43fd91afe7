//! Adapters and devices: instance over the backends wgpu supports here (`WGPU_BACKEND`
//! honoured), adapter choice (discrete first; `RT2_ADAPTER` picks by name), limits read from
//! the adapter and respected, and the small helpers every job uses (buffers, dispatch sizes,
//! read-back). wgpu reports errors outside error scopes through a handler that panics by
//! default; each device records them instead (out of memory apart from the rest, and a lost
//! device through its own callback), and every job checks the record.

use super::faults::{lock_faults, Faults, InjectedFault, JobFaults};
use super::kernels::{self, Program};
use super::scene::SceneCache;
use super::{GpuError, GpuResult};
use crate::cpu::traverse::Traversal;
use crate::error::{Error, Result, Rt2Status};
use std::collections::HashMap;
use std::sync::{Arc, Mutex, MutexGuard};

/// How the GPU backend picks and uses adapters.
#[derive(Clone, Debug, Default)]
pub struct GpuOptions {
    /// Only adapters whose name contains this (case-insensitive); `RT2_ADAPTER` sets it.
    pub adapter: Option<String>,
    /// Logical devices to open on the chosen adapter (0: one per adapter). More than one
    /// splits frames across them as several GPUs would (how the split is tested on one GPU).
    pub logical_devices: usize,
    /// Let AUTO use a software adapter (tests only: lavapipe is slower than the CPU path, and
    /// its loop budget of 65535 iterations per invocation cuts long traversals short, which
    /// sends such jobs to the CPU: `dispatch::SOFTWARE_LOOP_BUDGET`).
    pub auto_accepts_software: bool,
    /// Lower the storage binding limit (tests of the AUTO fallback on small limits).
    pub max_binding_override: Option<u64>,
}

impl GpuOptions {
    /// The defaults with `RT2_ADAPTER` and `RT2_GPU_DEVICES` applied; an error for a value
    /// that is set but unreadable (see the `env` module).
    pub fn from_env() -> Result<Self> {
        Ok(GpuOptions {
            adapter: crate::env::var("RT2_ADAPTER")?,
            logical_devices: logical_devices(crate::env::var("RT2_GPU_DEVICES")?.as_deref())?,
            ..GpuOptions::default()
        })
    }
}

/// Most logical devices `RT2_GPU_DEVICES` may ask for: a test knob (frames split across
/// devices), where a typo of 100000 took minutes opening devices and would overflow the band
/// arithmetic.
const MAX_LOGICAL_DEVICES: usize = 64;

/// `RT2_GPU_DEVICES`: a count in 1..=[`MAX_LOGICAL_DEVICES`], returned as is; unset or empty
/// gives 0, the default of one device per adapter. An explicit 0 (no device) is an error
/// like any other bad count, not silently the default.
fn logical_devices(value: Option<&str>) -> Result<usize> {
    let n = match value.map(str::trim) {
        None | Some("") => 0,
        Some(v) => v
            .parse()
            .ok()
            .filter(|n| (1..=MAX_LOGICAL_DEVICES).contains(n))
            .ok_or_else(|| {
                Error::invalid_argument(format!(
                    "RT2_GPU_DEVICES is '{v}' (expected a count of logical devices in \
                 1..={MAX_LOGICAL_DEVICES}; unset, one device per adapter)"
                ))
            })?,
    };
    Ok(n)
}

/// The pipelines of one module, in the order of its entry-point list.
pub(crate) type Pipelines = Arc<Vec<wgpu::ComputePipeline>>;

/// The least bytes a buffer holds: wgpu rejects empty bindings and binds an array only where
/// one element fits, so an empty scene array is uploaded as one zeroed element (never read, the
/// counts are in the parameters). The largest element is an `Ellipsoid` (100 bytes); a layout
/// test checks every storage array of the kernels against this.
pub(crate) const MIN_BUFFER_BYTES: u64 = 128;

/// Storage buffers one kernel binds at most: 13 scene arrays + 7 wavefront buffers (a query
/// binds 4).
const STORAGE_BUFFERS_NEEDED: u32 = 20;

/// Bind group layouts shared by all kernels of a device.
pub(crate) struct Layouts {
    pub scene: wgpu::BindGroupLayout,
    pub query: wgpu::PipelineLayout,
    pub query_io: wgpu::BindGroupLayout,
    pub mega: wgpu::PipelineLayout,
    pub mega_io: wgpu::BindGroupLayout,
    pub wave: wgpu::PipelineLayout,
    pub wave_io: wgpu::BindGroupLayout,
    pub scan: wgpu::PipelineLayout,
    pub scan_io: wgpu::BindGroupLayout,
}

/// One logical device with its queue, limits, compiled kernels and uploaded scene.
pub struct Device {
    pub name: String,
    pub(crate) device: wgpu::Device,
    pub(crate) queue: wgpu::Queue,
    pub(crate) limits: wgpu::Limits,
    pub(crate) layouts: Layouts,
    pipelines: Mutex<HashMap<(Traversal, Program), Pipelines>>,
    scan: Mutex<Option<Pipelines>>,
    /// What wgpu reported outside error scopes since the last check.
    faults: Arc<Mutex<Faults>>,
    /// The committed scene as uploaded; one job at a time uses a device.
    pub(crate) scene: Mutex<SceneCache>,
    max_binding_override: Option<u64>,
}

/// The devices of a context.
pub struct Gpu {
    pub devices: Vec<Device>,
    /// "name (type, backend)" of the adapter(s), for the context's reason.
    pub description: String,
    /// Whether the adapter is a CPU implementation (lavapipe, SwiftShader, WARP).
    pub software: bool,
}

fn rank(t: wgpu::DeviceType) -> u8 {
    match t {
        wgpu::DeviceType::DiscreteGpu => 0,
        wgpu::DeviceType::IntegratedGpu => 1,
        wgpu::DeviceType::VirtualGpu => 2,
        wgpu::DeviceType::Other => 3,
        wgpu::DeviceType::Cpu => 4,
    }
}

/// Finds adapters and opens devices. `Err` carries the reason no GPU is usable; with
/// `accept_software` false, a software adapter is such a reason (it is slower than RT2's CPU
/// path) and no device is created for it.
pub fn open(opts: &GpuOptions, accept_software: bool) -> std::result::Result<Gpu, String> {
    let mut desc = wgpu::InstanceDescriptor::new_without_display_handle();
    desc.backends = wgpu::Backends::from_env().unwrap_or(wgpu::Backends::all());
    let backends = desc.backends;
    let instance = wgpu::Instance::new(desc);
    let mut adapters = pollster::block_on(instance.enumerate_adapters(backends));
    if adapters.is_empty() {
        // RT2 builds wgpu with Vulkan only: WGPU_BACKEND naming another backend finds nothing.
        return Err(match std::env::var("WGPU_BACKEND") {
            Ok(v) => format!(
                "no GPU adapter was found among the backends WGPU_BACKEND={v} allows (RT2 \
                 drives Vulkan only)"
            ),
            Err(_) => "no GPU adapter was found (wgpu found no Vulkan driver)".into(),
        });
    }
    if let Some(want) = &opts.adapter {
        let want = want.to_lowercase();
        let names: Vec<String> = adapters.iter().map(|a| a.get_info().name).collect();
        adapters.retain(|a| a.get_info().name.to_lowercase().contains(&want));
        if adapters.is_empty() {
            return Err(format!(
                "RT2_ADAPTER='{want}' matches none of the adapters ({})",
                names.join(", ")
            ));
        }
    }
    adapters.sort_by_key(|a| rank(a.get_info().device_type));
    // Several GPUs of the best kind share frames; a software adapter never joins hardware.
    let best = adapters[0].get_info().device_type;
    if best == wgpu::DeviceType::Cpu && !accept_software {
        let i = adapters[0].get_info();
        return Err(format!(
            "the only adapter, {} ({:?}, {:?}), is a software one, slower than RT2's CPU path",
            i.name, i.device_type, i.backend
        ));
    }
    adapters.retain(|a| a.get_info().device_type == best);
    let chosen: Vec<&wgpu::Adapter> = if opts.logical_devices > 0 {
        vec![&adapters[0]; opts.logical_devices]
    } else {
        adapters.iter().collect()
    };
    let results = chosen
        .into_iter()
        .map(|a| open_device(a, opts).map(|d| (a.get_info(), d)))
        .collect();
    let (opened, failed) = keep_opened(results)?;
    let info = opened[0].0.clone();
    let devices: Vec<Device> = opened.into_iter().map(|(_, d)| d).collect();
    let mut description = format!(
        "{} x{} ({:?}, {:?})",
        info.name,
        devices.len(),
        info.device_type,
        info.backend
    );
    if !failed.is_empty() {
        description += &format!("; skipped: {}", failed.join("; "));
    }
    Ok(Gpu {
        description,
        software: best == wgpu::DeviceType::Cpu,
        devices,
    })
}

/// Splits the outcome of opening each chosen adapter into the devices that opened and the
/// reasons of those that did not: one adapter refusing a device (a driver fault, limits too
/// small) does not keep the others from tracing. `Err`, with every reason, when none opened.
fn keep_opened<T>(
    results: Vec<std::result::Result<T, String>>,
) -> std::result::Result<(Vec<T>, Vec<String>), String> {
    let (mut opened, mut failed) = (Vec::new(), Vec::new());
    for r in results {
        match r {
            Ok(d) => opened.push(d),
            Err(why) => failed.push(why),
        }
    }
    if opened.is_empty() {
        return Err(if failed.is_empty() {
            "no adapter was left to open".into()
        } else {
            format!("no adapter opened a device: {}", failed.join("; "))
        });
    }
    Ok((opened, failed))
}

fn open_device(adapter: &wgpu::Adapter, opts: &GpuOptions) -> std::result::Result<Device, String> {
    let info = adapter.get_info();
    let limits = adapter.limits();
    if limits.max_storage_buffers_per_shader_stage < STORAGE_BUFFERS_NEEDED
        || limits.max_bind_groups < 2
    {
        return Err(format!(
            "adapter {} allows {} storage buffers per shader stage; RT2's kernels need {}",
            info.name, limits.max_storage_buffers_per_shader_stage, STORAGE_BUFFERS_NEEDED
        ));
    }
    let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
        label: Some("rt2"),
        required_features: wgpu::Features::empty(),
        // Everything the adapter offers: large scenes need its full storage binding size.
        required_limits: limits.clone(),
        ..Default::default()
    }))
    .map_err(|e| format!("adapter {} refused a device: {e}", info.name))?;
    let faults = Faults::watch(&device);
    let layouts = make_layouts(&device);
    Ok(Device {
        name: info.name,
        device,
        queue,
        limits,
        layouts,
        pipelines: Mutex::new(HashMap::new()),
        scan: Mutex::new(None),
        faults,
        scene: Mutex::new(SceneCache::default()),
        max_binding_override: opts.max_binding_override,
    })
}

fn storage(binding: u32, read_only: bool) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Storage { read_only },
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    }
}

fn uniform(binding: u32) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Uniform,
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    }
}

/// The bind group layouts; every binding is documented where the WGSL declares it
/// (common.wgsl for the scene, query.wgsl, render.wgsl and scan.wgsl for the rest).
fn make_layouts(d: &wgpu::Device) -> Layouts {
    let bgl = |label: &str, entries: &[wgpu::BindGroupLayoutEntry]| {
        d.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some(label),
            entries,
        })
    };
    let pl = |label: &str, groups: &[&wgpu::BindGroupLayout]| {
        let groups: Vec<Option<&wgpu::BindGroupLayout>> = groups.iter().map(|g| Some(*g)).collect();
        d.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some(label),
            bind_group_layouts: &groups,
            immediate_size: 0,
        })
    };
    // Group 0: the 13 scene arrays, read-only.
    let scene_entries: Vec<_> = (0..13).map(|b| storage(b, true)).collect();
    let scene = bgl("scene", &scene_entries);
    // Group 1 of the queries: params, rays (read), hits and stats (written), exclusions (read).
    let query_io = bgl(
        "query io",
        &[
            uniform(0),
            storage(1, true),
            storage(2, false),
            storage(3, false),
            storage(4, true),
        ],
    );
    // Group 1 of the megakernel: params, frame (written), mask (read).
    let mega_io = bgl(
        "megakernel io",
        &[uniform(0), storage(1, false), storage(2, true)],
    );
    // Group 1 of the wavefront kernels: params, frame, mask, queue, slots, scan, contrib, accum.
    let mut wave_entries = vec![uniform(0), storage(1, false), storage(2, true)];
    wave_entries.extend((3..8).map(|b| storage(b, false)));
    let wave_io = bgl("wavefront io", &wave_entries);
    // The prefix sum: params, the level, its block sums.
    let scan_io = bgl(
        "scan io",
        &[uniform(0), storage(1, false), storage(2, false)],
    );
    Layouts {
        query: pl("query", &[&scene, &query_io]),
        mega: pl("megakernel", &[&scene, &mega_io]),
        wave: pl("wavefront", &[&scene, &wave_io]),
        scan: pl("scan", &[&scan_io]),
        scene,
        query_io,
        mega_io,
        wave_io,
        scan_io,
    }
}

/// Entry points of each program, in the order `pipelines` returns them.
pub(crate) const QUERY_ENTRIES: [&str; 2] = ["intersect_main", "occluded_main"];
pub(crate) const MEGA_ENTRY: &str = "megakernel";
pub(crate) const WAVE_ENTRIES: [&str; 5] = [
    "wave_generate",
    "wave_trace",
    "wave_accumulate",
    "wave_compact",
    "wave_finalize",
];

impl Device {
    /// Largest storage binding, in bytes: what one buffer of the scene or a job may hold.
    pub fn max_binding(&self) -> u64 {
        let l = self
            .limits
            .max_storage_buffer_binding_size
            .min(self.limits.max_buffer_size);
        self.max_binding_override.map_or(l, |o| o.min(l))
    }

    /// The pipelines of a traversal's program, compiled on first use. Render: megakernel
    /// first, then [`WAVE_ENTRIES`].
    pub(crate) fn pipelines(&self, t: Traversal, p: Program) -> Result<Pipelines> {
        let mut cache = lock_cache(&self.pipelines);
        if let Some(v) = cache.get(&(t, p)) {
            return Ok(v.clone());
        }
        let src = kernels::source(t, p);
        let label = format!("{} {p:?}", t.name());
        let v = match p {
            Program::Query => kernels::create_pipelines(
                &self.device,
                &label,
                &src,
                &self.layouts.query,
                &QUERY_ENTRIES,
            )?,
            Program::Render => {
                let mut v = kernels::create_pipelines(
                    &self.device,
                    &label,
                    &src,
                    &self.layouts.mega,
                    &[MEGA_ENTRY],
                )?;
                v.extend(kernels::create_pipelines(
                    &self.device,
                    &label,
                    &src,
                    &self.layouts.wave,
                    &WAVE_ENTRIES,
                )?);
                v
            }
        };
        let v = Arc::new(v);
        cache.insert((t, p), v.clone());
        Ok(v)
    }

    /// Scene arrays re-sent by the last job (names as in common.wgsl): how the upload cache
    /// is observed.
    pub fn last_uploads(&self) -> Vec<&'static str> {
        lock_cache(&self.scene).last_uploads.clone()
    }

    /// `scan_local`, `scan_add`.
    pub(crate) fn scan_pipelines(&self) -> Result<Pipelines> {
        let mut cache = lock_cache(&self.scan);
        if let Some(v) = &*cache {
            return Ok(v.clone());
        }
        let v = Arc::new(kernels::create_pipelines(
            &self.device,
            "scan",
            kernels::SCAN,
            &self.layouts.scan,
            &["scan_local", "scan_add"],
        )?);
        *cache = Some(v.clone());
        Ok(v)
    }

    /// A storage buffer holding `bytes` (at least [`MIN_BUFFER_BYTES`]).
    pub(crate) fn upload(
        &self,
        label: &str,
        bytes: &[u8],
        extra: wgpu::BufferUsages,
    ) -> wgpu::Buffer {
        self.buffer_with(label, bytes, wgpu::BufferUsages::STORAGE | extra)
    }

    pub(crate) fn uniform<T: bytemuck::Pod>(&self, v: &T) -> wgpu::Buffer {
        self.buffer_with("params", bytemuck::bytes_of(v), wgpu::BufferUsages::UNIFORM)
    }

    /// A buffer filled through the queue (sent before the next submission). Not
    /// `create_buffer_init`: its mapping panics on a lost device, where this write is an
    /// error the next check reports.
    fn buffer_with(&self, label: &str, bytes: &[u8], usage: wgpu::BufferUsages) -> wgpu::Buffer {
        let size = (bytes.len() as u64)
            .max(MIN_BUFFER_BYTES)
            .next_multiple_of(4);
        let buffer = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size,
            usage: usage | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let whole = bytes.len() / 4 * 4;
        self.queue.write_buffer(&buffer, 0, &bytes[..whole]);
        if whole < bytes.len() {
            let mut tail = [0u8; 4];
            tail[..bytes.len() - whole].copy_from_slice(&bytes[whole..]);
            self.queue.write_buffer(&buffer, whole as u64, &tail);
        }
        buffer
    }

    /// An uninitialised storage buffer of `bytes` (rounded up to 64), checked against the
    /// binding limit.
    pub(crate) fn scratch(
        &self,
        label: &str,
        bytes: u64,
        extra: wgpu::BufferUsages,
    ) -> GpuResult<wgpu::Buffer> {
        let size = bytes.max(64).next_multiple_of(4);
        if size > self.max_binding() {
            return Err(GpuError::Limits(format!(
                "{label} needs {size} bytes, more than the {} bytes a storage binding of {} may hold",
                self.max_binding(),
                self.name
            )));
        }
        Ok(self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size,
            usage: wgpu::BufferUsages::STORAGE | extra,
            mapped_at_creation: false,
        }))
    }

    pub(crate) fn bind(
        &self,
        layout: &wgpu::BindGroupLayout,
        buffers: &[&wgpu::Buffer],
    ) -> wgpu::BindGroup {
        let entries: Vec<_> = buffers
            .iter()
            .enumerate()
            .map(|(i, b)| wgpu::BindGroupEntry {
                binding: i as u32,
                resource: b.as_entire_binding(),
            })
            .collect();
        self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: None,
            layout,
            entries: &entries,
        })
    }

    /// Records a dispatch of `threads` threads (64 per workgroup), as a 2-D grid when the
    /// per-dimension limit requires it (kernels read their index with `flat_id`).
    pub(crate) fn dispatch(
        &self,
        enc: &mut wgpu::CommandEncoder,
        pipeline: &wgpu::ComputePipeline,
        groups: &[&wgpu::BindGroup],
        threads: u64,
    ) {
        if threads == 0 {
            return;
        }
        let wg = threads.div_ceil(64);
        let max = self.limits.max_compute_workgroups_per_dimension.max(1) as u64;
        let x = wg.min(max);
        let y = wg.div_ceil(x);
        let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor::default());
        pass.set_pipeline(pipeline);
        for (i, g) in groups.iter().enumerate() {
            pass.set_bind_group(i as u32, Some(*g), &[]);
        }
        pass.dispatch_workgroups(x as u32, y as u32, 1);
    }

    /// Most threads one dispatch may run (the 2-D grid's bound).
    pub(crate) fn max_threads(&self) -> u64 {
        let max = self.limits.max_compute_workgroups_per_dimension as u64;
        max * max * 64
    }

    /// Submits `enc` after copying `src` into a mappable buffer, waits, returns the bytes.
    pub(crate) fn read_back(
        &self,
        mut enc: wgpu::CommandEncoder,
        src: &wgpu::Buffer,
        offset: u64,
        bytes: u64,
    ) -> GpuResult<Vec<u8>> {
        let staging = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("read back"),
            size: bytes.max(4),
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        if bytes > 0 {
            enc.copy_buffer_to_buffer(src, offset, &staging, 0, bytes);
        }
        self.queue.submit([enc.finish()]);
        let slice = staging.slice(..);
        let (tx, rx) = std::sync::mpsc::channel();
        slice.map_async(wgpu::MapMode::Read, move |r| {
            let _ = tx.send(r);
        });
        self.device
            .poll(wgpu::PollType::wait_indefinitely())
            .map_err(|e| gpu_error(format!("waiting for {}: {e}", self.name)))?;
        self.check()?;
        match rx.recv() {
            Ok(Ok(())) => {}
            Ok(Err(e)) => return Err(gpu_error(format!("mapping a result buffer: {e}")).into()),
            Err(_) => return Err(gpu_error("the result buffer was never mapped".into()).into()),
        }
        let view = slice
            .get_mapped_range()
            .map_err(|e| gpu_error(format!("reading a result buffer: {e}")))?;
        let out = crate::fallible::copied(&view[..bytes as usize]);
        drop(view);
        staging.unmap();
        Ok(out?)
    }

    /// Turns what wgpu reported outside error scopes, for this thread's calls, into the job's
    /// error: out of memory and a lost device are [`GpuError::OutOfMemory`] and
    /// [`GpuError::Lost`] (AUTO runs the job on the CPU), anything else (a validation error of
    /// a job: a bug) an internal error.
    pub(crate) fn check(&self) -> GpuResult<()> {
        let pending = {
            let f = lock_faults(&self.faults);
            f.errors.iter().any(Faults::checked_here)
        };
        if pending {
            // wgpu reports a loss from `destroy` (or a driver) only when the device is polled,
            // and a call on the lost device before that is an error like any other.
            let _ = self.device.poll(wgpu::PollType::Poll);
        }
        let mut f = lock_faults(&self.faults);
        let mine = f.take(Faults::checked_here);
        let out_of_memory = mine.iter().any(|e| e.out_of_memory);
        let errors = mine
            .into_iter()
            .map(|e| e.message)
            .collect::<Vec<_>>()
            .join("; ");
        if let Some(why) = &f.lost {
            return Err(GpuError::Lost(format!(
                "the GPU device {} was lost ({why})",
                self.name
            )));
        }
        if out_of_memory {
            return Err(GpuError::OutOfMemory(format!(
                "the GPU device {} ran out of memory ({errors})",
                self.name
            )));
        }
        if errors.is_empty() {
            return Ok(());
        }
        Err(gpu_error(format!("{}: {errors}", self.name)).into())
    }

    /// Starts a job on this thread: fails at once on a lost device, before the job records
    /// work it cannot run (wgpu ignores calls on a lost device rather than reporting them).
    /// Errors of this thread still pending belong to an earlier job that failed before its
    /// check, and are dropped; so are the job's own when the returned guard is.
    pub(crate) fn begin_job(&self) -> GpuResult<JobFaults<'_>> {
        let mut f = lock_faults(&self.faults);
        f.drop_thread_errors();
        match &f.lost {
            Some(why) => Err(GpuError::Lost(format!(
                "the GPU device {} was lost ({why})",
                self.name
            ))),
            None => Ok(JobFaults(&self.faults)),
        }
    }

    /// Test hook: makes the device fail the way a driver does, through the same callbacks, so
    /// that the next check of a job sees it. No real allocation fails on demand, and no test
    /// may unplug the GPU; `Lost` really loses the device (it cannot be used again).
    #[doc(hidden)]
    pub fn inject_fault(&self, fault: InjectedFault) {
        match fault {
            InjectedFault::OutOfMemory => {
                let source = "injected by a test: the allocation failed".into();
                lock_faults(&self.faults).record(wgpu::Error::OutOfMemory { source }, None);
            }
            InjectedFault::Lost => self.device.destroy(),
        }
    }
}

fn gpu_error(m: String) -> Error {
    Error::new(Rt2Status::Internal, format!("GPU error: {m}"))
}

/// Locks one of a device's caches (compiled kernels, the uploaded scene) whatever a panic left
/// in it. A panic is a bug, caught at the C boundary, and may leave a cache half updated: a
/// poisoned cache is emptied and rebuilt by its next user, where failing on the poisoned lock
/// would fail every later GPU job of the context, under AUTO too (no CPU fallback for a bug).
pub(crate) fn lock_cache<T: Default>(cache: &Mutex<T>) -> MutexGuard<'_, T> {
    cache.lock().unwrap_or_else(|poisoned| {
        let mut guard = poisoned.into_inner();
        *guard = T::default();
        cache.clear_poison();
        guard
    })
}

/// The GPU of the unit tests (any adapter, software ones included), or `None`, said aloud,
/// when there is none; with `RT2_REQUIRE_GPU=1` (CI, on lavapipe) a missing adapter fails.
#[cfg(test)]
pub(crate) fn open_for_tests() -> Option<Gpu> {
    match open(&Default::default(), true) {
        Ok(g) => Some(g),
        Err(why) => {
            assert!(
                std::env::var("RT2_REQUIRE_GPU").as_deref() != Ok("1"),
                "{why}"
            );
            eprintln!("SKIPPED (no GPU adapter): {why}");
            None
        }
    }
}

#[cfg(test)]
mod tests {
    use super::keep_opened;

    /// A device shared by jobs on several threads: each thread's check reports the errors of
    /// its own wgpu calls only (wgpu reports them on the calling thread), so one job's failure
    /// is not another's; a job drops what its thread's failed job left when it starts, and its
    /// own unchecked errors when it ends; an injected fault goes to the next check on any
    /// thread.
    #[test]
    fn each_thread_checks_its_own_errors() {
        let Some(gpu) = super::open_for_tests() else {
            return;
        };
        let dev = &gpu.devices[0];
        // A validation error: mappable for reading and a storage buffer at once.
        let bad = || {
            dev.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("bad usage"),
                size: 64,
                usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::STORAGE,
                mapped_at_creation: false,
            })
        };
        std::thread::scope(|s| {
            s.spawn(|| {
                let _b = bad();
            })
            .join()
            .unwrap();
        });
        // The spawned thread's error stays with it (it never checked): not this thread's.
        assert!(dev.check().is_ok());
        let _b = bad();
        let e = dev
            .check()
            .expect_err("this thread's own error")
            .into_error();
        assert!(e.message.contains("bad usage"), "{}", e.message);
        assert!(dev.check().is_ok(), "taken once");

        let _b = bad();
        let job = dev.begin_job().unwrap();
        assert!(
            dev.check().is_ok(),
            "a new job drops its thread's stale errors"
        );
        let _b = bad();
        drop(job);
        assert!(
            dev.check().is_ok(),
            "and its own unchecked ones when it ends"
        );

        dev.inject_fault(super::InjectedFault::OutOfMemory);
        let other = std::thread::scope(|s| s.spawn(|| dev.check().is_err()).join().unwrap());
        assert!(other, "an injected fault goes to any thread");
        assert!(dev.check().is_ok());
    }

    /// A panic while a device's lock was held (a bug, caught at the C boundary) leaves the
    /// device usable: the next job finds every lock poisoned and still answers, with the
    /// caches rebuilt. Failing on the poisoned locks instead failed every later GPU job of the
    /// context for good.
    #[test]
    fn a_panic_under_a_lock_does_not_break_the_device() {
        use crate::cpu::traverse::Traversal;
        use crate::geometry::{Hit, Ray};
        use glam::Vec3;
        let Some(gpu) = super::open_for_tests() else {
            return;
        };
        let dev = &gpu.devices[0];
        let scene = crate::scene::unit_sphere();
        let c = scene.committed().unwrap();
        let ray = Ray::new(Vec3::new(0.0, 0.0, 5.0), -Vec3::Z, 0.0, f32::INFINITY);
        let query = |hits: &mut [Hit]| {
            let how = Traversal::Standard;
            crate::gpu::query::run(dev, c, (&[ray], None), how, 8, Some(hits), None)
        };
        let mut hits = [Hit::MISS];
        query(&mut hits).unwrap();
        assert_eq!(
            hits[0].t, 4.0,
            "the sphere is hit before the locks are poisoned"
        );

        std::thread::scope(|s| {
            s.spawn(|| {
                let _locks = (
                    dev.scene.lock(),
                    dev.pipelines.lock(),
                    dev.scan.lock(),
                    dev.faults.lock(),
                );
                panic!("a bug while the device's locks are held");
            })
            .join()
            .expect_err("the thread panicked");
        });
        assert!(dev.scene.is_poisoned() && dev.faults.is_poisoned());
        let mut hits = [Hit::MISS];
        query(&mut hits).expect("the device answers after the panic");
        assert_eq!(hits[0].t, 4.0);
        assert!(!dev.scene.is_poisoned(), "the scene cache was rebuilt");
        assert!(
            dev.last_uploads().contains(&"nodes"),
            "{:?}",
            dev.last_uploads()
        );
    }

    /// Adapters that refuse a device are skipped with their reasons; only when none opens
    /// does opening fail, with every reason.
    #[test]
    fn open_keeps_the_adapters_that_open() {
        let results = vec![
            Err("adapter A refused a device: lost".to_string()),
            Ok(1),
            Err("adapter C allows 8 storage buffers per shader stage".to_string()),
            Ok(3),
        ];
        let (opened, failed) = keep_opened(results).unwrap();
        assert_eq!(opened, vec![1, 3]);
        assert_eq!(failed.len(), 2);
        assert!(failed[0].contains("adapter A") && failed[1].contains("adapter C"));

        let none: Vec<Result<u32, String>> =
            vec![Err("adapter A: x".into()), Err("adapter B: y".into())];
        let why = keep_opened(none).unwrap_err();
        assert!(
            why.contains("no adapter opened")
                && why.contains("adapter A: x")
                && why.contains("adapter B: y"),
            "{why}"
        );
        assert!(keep_opened::<u32>(Vec::new()).is_err());
    }

    #[test]
    fn a_device_count_that_does_not_parse_is_an_error() {
        assert_eq!(super::logical_devices(None).unwrap(), 0);
        assert_eq!(super::logical_devices(Some("")).unwrap(), 0);
        assert_eq!(super::logical_devices(Some(" 2 ")).unwrap(), 2);
        assert_eq!(super::logical_devices(Some("64")).unwrap(), 64);
        assert_eq!(super::logical_devices(Some("1")).unwrap(), 1);
        for bad in ["0", "two", "-1", "2x", "1e3", "65", "100000"] {
            let e = super::logical_devices(Some(bad)).unwrap_err();
            assert!(e.message.contains(bad), "{bad}: {}", e.message);
        }
    }
}
