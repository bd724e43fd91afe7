//! Layer 2: decides where each operation runs and records why (RT² fig. 11's control layer).
//! Tree builds always run on the CPU (as in the thesis); tracing goes to the GPU when one is
//! usable, otherwise to the CPU. `RT2_BACKEND=cpu|gpu|auto` overrides the caller's choice.

use crate::cpu::query::{octant_runs_at_least, QueryMode};
use crate::cpu::traverse::Traversal;
use crate::error::{Error, Result, Rt2Status};
use crate::gpu::{self, Gpu, GpuOptions, GpuPath};
use crate::render::{GpuPathRequest, RenderOptions};
use crate::scene::Committed;

/// Backend requested by a caller.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BackendRequest {
    Auto,
    Cpu,
    Gpu,
}

/// Where tracing runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Backend {
    Cpu,
    Gpu,
}

/// A decision and the reason for it, reported by `rt2_context_info`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Decision {
    pub backend: Backend,
    pub reason: String,
    /// Chosen by AUTO: a job the GPU cannot hold (device limits) then runs on the CPU.
    pub auto: bool,
}

impl BackendRequest {
    pub fn parse(s: &str) -> Option<Self> {
        match s.trim().to_ascii_lowercase().as_str() {
            "auto" => Some(BackendRequest::Auto),
            "cpu" => Some(BackendRequest::Cpu),
            "gpu" => Some(BackendRequest::Gpu),
            _ => None,
        }
    }
}

/// Resolves the backend for a new context. `env` is the value of `RT2_BACKEND`, if set.
/// Returns the GPU devices when tracing goes there.
pub fn decide_backend(
    requested: BackendRequest,
    env: Option<&str>,
    gpu_opts: &GpuOptions,
) -> Result<(Decision, Option<Gpu>)> {
    let (request, source) = match env {
        Some(v) => match BackendRequest::parse(v) {
            Some(r) => (r, format!("RT2_BACKEND={v}")),
            None => {
                return Err(Error::invalid_argument(format!(
                    "RT2_BACKEND is '{v}' (expected cpu, gpu or auto)"
                )))
            }
        },
        None => (requested, "the context descriptor".to_string()),
    };
    let cpu = |reason: String, auto: bool| {
        Ok((
            Decision {
                backend: Backend::Cpu,
                reason,
                auto,
            },
            None,
        ))
    };
    match request {
        BackendRequest::Cpu => cpu(format!("CPU requested by {source}"), false),
        BackendRequest::Gpu => match gpu::open(gpu_opts, true) {
            // Explicitly requested, a software adapter is accepted (that is how CI tests).
            Ok(g) => Ok((
                Decision {
                    backend: Backend::Gpu,
                    reason: format!("GPU requested by {source}: {}", g.description),
                    auto: false,
                },
                Some(g),
            )),
            Err(why) => Err(Error::new(
                Rt2Status::BackendUnavailable,
                format!("GPU requested by {source}, but {why}"),
            )),
        },
        BackendRequest::Auto => match gpu::open(gpu_opts, gpu_opts.auto_accepts_software) {
            Ok(g) => Ok((
                Decision {
                    backend: Backend::Gpu,
                    reason: format!("AUTO from {source}: tracing on {}", g.description),
                    auto: true,
                },
                Some(g),
            )),
            Err(why) => cpu(
                format!("AUTO from {source}: {why}, so tracing runs on the CPU"),
                true,
            ),
        },
    }
}

/// The traversal AUTO picks on the GPU, and why. A rope traversal asked for on a tree without
/// ropes runs as standard, as on the CPU (`Traversal::needs_ropes`: same hits): the kernels
/// would read ropes that were never uploaded. (The C API builds ropes before such a job.)
pub fn choose_gpu_traversal(
    scene: &Committed,
    requested: Option<Traversal>,
) -> (Traversal, &'static str) {
    match requested {
        Some(t) if t.needs_ropes() && scene.tree.ropes.is_none() => (
            Traversal::Standard,
            "a rope traversal was requested, but the tree has no ropes",
        ),
        Some(t) => (t, "requested by the caller"),
        // Thesis table 2: ropes++ is the fastest GPU traversal in every scene.
        None if scene.tree.ropes.is_some() => (
            Traversal::RopesPlusPlus,
            "ropes++ is the fastest GPU traversal (thesis table 2) and the tree has ropes",
        ),
        // Without ropes (3x the tree memory, built only on request), the standard stack
        // visits the fewest nodes (thesis table 1); a 64-entry private stack fits a thread.
        None => (
            Traversal::Standard,
            "the tree has no ropes, and standard visits the fewest nodes of the stack methods \
             (thesis table 1)",
        ),
    }
}

/// The loop iterations Mesa's llvmpipe (lavapipe) allows one shader invocation, counted over
/// all its loops and per SIMD group of invocations (8 under AVX2): gallivm's
/// `LP_MAX_TGSI_LOOP_ITERATIONS`. Beyond it every loop exits early and the dispatch still
/// succeeds, with wrong answers; the kernels' last loop finds out (`loops_ran_to_the_end` in
/// `shaders/common.wgsl`), and the job fails as beyond the device's limits
/// (`gpu::GpuError::cut_short`): AUTO runs it on the CPU. Hardware drivers have no such
/// budget.
pub const SOFTWARE_LOOP_BUDGET: u32 = 65_535;

/// The render path AUTO picks on the GPU (thesis §3.3), and why. `software`: the adapter is a
/// CPU implementation ([`crate::gpu::Gpu::software`]), where a megakernel invocation that
/// loops over several samples of a pixel may exhaust [`SOFTWARE_LOOP_BUDGET`] (on lavapipe
/// 128 samples of a 400-sphere leaf do, and the frame is refused, or rendered on the CPU under
/// AUTO: `tests/gpu.rs`); the wavefront path dispatches each sample and bounce on its own, so
/// one invocation traces one ray and the GPU keeps the frame (unless a chunk's ray tree
/// outgrows the wave queue and that chunk takes the megakernel after all).
pub fn choose_gpu_path(
    scene: &Committed,
    opts: &RenderOptions,
    software: bool,
) -> (GpuPath, String) {
    match opts.gpu_path {
        GpuPathRequest::Megakernel => (GpuPath::Megakernel, "requested by the caller".into()),
        GpuPathRequest::Wavefront => (GpuPath::Wavefront, "requested by the caller".into()),
        GpuPathRequest::Auto if software && opts.samples > 1 => (
            GpuPath::Wavefront,
            format!(
                "the adapter is a software one, whose driver (llvmpipe) ends every loop of a \
                 shader invocation after {SOFTWARE_LOOP_BUDGET} iterations in all, and the \
                 megakernel would loop over {} samples per pixel in one invocation; the \
                 wavefront path dispatches each sample and bounce apart",
                opts.samples
            ),
        ),
        GpuPathRequest::Auto => {
            // Thesis: the megakernel for primary rays with few reflections; one kernel per
            // bounce, with compaction, pays off when most objects spawn secondary rays.
            let secondary = scene
                .origins
                .iter()
                .filter(|o| {
                    let m = &scene.materials[scene.object_material[o.object as usize] as usize];
                    m.reflectivity > 0.0 || m.transparency > 0.0
                })
                .count();
            let total = scene.origins.len();
            if opts.max_depth <= 1 {
                (
                    GpuPath::Megakernel,
                    format!("max_depth {} spawns no secondary rays", opts.max_depth),
                )
            } else if 2 * secondary >= total.max(1) {
                (
                    GpuPath::Wavefront,
                    format!(
                        "{secondary} of {total} primitives reflect or transmit, so most rays \
                         spawn secondary rays (thesis §3.3)"
                    ),
                )
            } else {
                (
                    GpuPath::Megakernel,
                    format!(
                        "{secondary} of {total} primitives reflect or transmit, so few rays \
                         spawn secondary rays (thesis §3.3)"
                    ),
                )
            }
        }
    }
}

/// The traversal AUTO picks for a scene on the CPU, and why.
pub fn choose_traversal(
    _scene: &Committed,
    requested: Option<Traversal>,
) -> (Traversal, &'static str) {
    match requested {
        Some(t) => (t, "requested by the caller"),
        // On a CPU the stack costs nothing: the standard traversal visits the fewest nodes of
        // the stack-based and restart methods (thesis table 1) and needs no ropes, which cost
        // about 3x the tree memory.
        None => (
            Traversal::Standard,
            "a CPU's stack is cheap, and standard visits the fewest nodes (thesis table 1) \
             and needs no ropes",
        ),
    }
}

/// Rays per octant run, on average, from which AUTO takes a batch for a camera's (coherent):
/// a 16-ray packet, AVX-512's, then mostly fills from one run. Scanline rows change octant
/// twice (at the centre column and the row's end): images 64 pixels wide or more pass (one
/// change in 32 pairs; at 32 pixels, one in 16, the test is a coin toss).
pub const AUTO_PACKET_RUN: usize = 16;

/// Fewest coherent rays (in octant runs of [`AUTO_PACKET_RUN`]) AUTO traces as packets: on the
/// bunny's primary rays, in batches of 8 through `Context::intersect`, packets ran at 1.4×
/// single rays, and at 0.8× in batches of 4.
pub const AUTO_PACKET_MIN: usize = 8;

/// Fewest incoherent rays AUTO traces as a stream: on the bunny's and the dragon's incoherent
/// rays streams caught up with single rays in batches of about 128 (0.7–1.0× below 100 rays,
/// 1.3–1.5× from 4096).
pub const AUTO_STREAM_MIN: usize = 128;

/// The query mode AUTO picks for a batch of rays on the CPU, and why. Every mode returns the
/// same hits, so the choice is one of speed alone (`rt2 bench streams`, one thread): packets
/// for rays that come in runs of one octant, as a camera's do (on primary rays 16-lane
/// packets ran at 1.1–1.4× streams and 1.6–2.9× single rays); streams for rays in mixed
/// octants (on incoherent and diffuse rays at 1.1–1.8× packets and 1.2–2.3× single rays);
/// single rays for batches too small to pay for a batch's setup. Packets and streams walk the
/// tree in the standard traversal's order, so a batch whose `traversal` (the one that will
/// run, [`choose_traversal`]'s) is another runs one ray at a time.
pub fn choose_query_mode(
    rays: &[crate::geometry::Ray],
    requested: Option<QueryMode>,
    traversal: Traversal,
) -> (QueryMode, &'static str) {
    let coherent = || octant_runs_at_least(rays, AUTO_PACKET_RUN);
    match requested {
        Some(m) => (m, "requested by the caller"),
        None if traversal != Traversal::Standard => (
            QueryMode::Single,
            "the requested traversal runs one ray at a time (packets and streams take the \
             standard traversal's order)",
        ),
        _ if rays.len() < AUTO_PACKET_MIN => {
            (QueryMode::Single, "too few rays to pay for a batch's setup")
        }
        _ if coherent() => (
            QueryMode::Packet,
            "the rays come in runs of one octant, as a camera's do: neighbours share nodes",
        ),
        _ if rays.len() < AUTO_STREAM_MIN => (
            QueryMode::Single,
            "too few incoherent rays to pay for a stream's setup",
        ),
        _ => (
            QueryMode::Stream,
            "the rays change octant often (incoherent): all of them walk the tree's top at once",
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{Material, Scene, Shape};
    use glam::Vec3;

    /// `mirrors` of `n` spheres reflect, the rest are matte.
    fn spheres(n: u32, mirrors: u32) -> Scene {
        let mut s = Scene::new();
        let matte = s.add_material(Material::default()).unwrap();
        let mirror = s
            .add_material(Material {
                reflectivity: 0.5,
                ..Material::default()
            })
            .unwrap();
        for i in 0..n {
            let shape = Shape::Sphere {
                center: Vec3::X * 3.0 * i as f32,
                radius: 1.0,
            };
            s.add_object(shape, if i < mirrors { mirror } else { matte })
                .unwrap();
        }
        s.commit().unwrap();
        s
    }

    #[test]
    fn auto_gpu_path_is_wavefront_when_most_primitives_spawn_rays() {
        let opts = RenderOptions::default();
        assert!(opts.max_depth > 1);
        let path =
            |s: &Scene, o: &RenderOptions| choose_gpu_path(s.committed().unwrap(), o, false).0;
        assert_eq!(path(&spheres(4, 2), &opts), GpuPath::Wavefront);
        let why = choose_gpu_path(spheres(4, 1).committed().unwrap(), &opts, false).1;
        assert!(why.starts_with("1 of 4 primitives reflect"), "{why}");
        assert_eq!(path(&spheres(4, 1), &opts), GpuPath::Megakernel);
        let casting = RenderOptions {
            max_depth: 1,
            ..opts
        };
        assert_eq!(path(&spheres(4, 4), &casting), GpuPath::Megakernel);
        let asked = RenderOptions {
            gpu_path: GpuPathRequest::Megakernel,
            ..opts
        };
        assert_eq!(path(&spheres(4, 4), &asked), GpuPath::Megakernel);
    }

    /// On a software adapter AUTO takes the wavefront path for several samples per pixel
    /// (llvmpipe's loop budget would cut the megakernel's pixels short), whatever the scene
    /// and depth; one sample, a hardware adapter or a path the caller chose are unchanged.
    #[test]
    fn auto_gpu_path_is_wavefront_for_samples_on_a_software_adapter() {
        let s = spheres(4, 0);
        let c = s.committed().unwrap();
        let many = RenderOptions {
            samples: 2,
            max_depth: 1,
            ..RenderOptions::default()
        };
        let (path, why) = choose_gpu_path(c, &many, true);
        assert_eq!(path, GpuPath::Wavefront);
        assert!(why.contains("software") && why.contains("65535"), "{why}");
        assert_eq!(choose_gpu_path(c, &many, false).0, GpuPath::Megakernel);
        let one = RenderOptions { samples: 1, ..many };
        assert_eq!(choose_gpu_path(c, &one, true).0, GpuPath::Megakernel);
        let asked = RenderOptions {
            gpu_path: GpuPathRequest::Megakernel,
            ..many
        };
        assert_eq!(choose_gpu_path(c, &asked, true).0, GpuPath::Megakernel);
    }

    #[test]
    fn auto_gpu_traversal_is_ropes_pp_when_the_tree_has_ropes() {
        let mut s = spheres(8, 0);
        let pick = |s: &Scene| choose_gpu_traversal(s.committed().unwrap(), None).0;
        assert_eq!(pick(&s), Traversal::Standard);
        s.ensure_ropes().unwrap();
        assert_eq!(pick(&s), Traversal::RopesPlusPlus);
        let asked = choose_gpu_traversal(s.committed().unwrap(), Some(Traversal::KdRestart));
        assert_eq!(asked.0, Traversal::KdRestart);
        for rope in [Traversal::Ropes, Traversal::RopesPlusPlus] {
            assert_eq!(
                choose_gpu_traversal(s.committed().unwrap(), Some(rope)).0,
                rope
            );
            let ropeless = spheres(8, 0);
            let asked = choose_gpu_traversal(ropeless.committed().unwrap(), Some(rope));
            assert_eq!(asked.0, Traversal::Standard, "{rope:?} without ropes");
        }
        assert_eq!(
            choose_traversal(s.committed().unwrap(), None).0,
            Traversal::Standard
        );
    }

    /// `n` rays from the origin: in runs of `run` rays of one octant (the direction's signs
    /// change from run to run), or each in the next octant for `run` = 1.
    fn rays_in_runs(n: usize, run: usize) -> Vec<crate::geometry::Ray> {
        (0..n)
            .map(|i| {
                let o = (i / run) % 8;
                let sign = |bit: usize| if o >> bit & 1 == 1 { -1.0 } else { 1.0 };
                let dir = Vec3::new(sign(0) * 0.3, sign(1) * 0.2, sign(2));
                crate::geometry::Ray::new(Vec3::ZERO, dir, 0.0, f32::INFINITY)
            })
            .collect()
    }

    /// AUTO traces camera-like batches (long octant runs) in packets from 8 rays on,
    /// incoherent ones as streams from 128 rays on, smaller batches and other traversals one
    /// ray at a time, and takes the caller's mode as given.
    #[test]
    fn auto_query_mode_follows_coherence_size_and_traversal() {
        let pick =
            |rays: &[crate::geometry::Ray]| choose_query_mode(rays, None, Traversal::Standard).0;
        let camera = rays_in_runs(4096, 512);
        let mixed = rays_in_runs(4096, 1);
        assert_eq!(pick(&camera), QueryMode::Packet);
        assert_eq!(pick(&mixed), QueryMode::Stream);
        assert_eq!(pick(&camera[..AUTO_PACKET_MIN]), QueryMode::Packet);
        assert_eq!(pick(&camera[..AUTO_PACKET_MIN - 1]), QueryMode::Single);
        assert_eq!(pick(&mixed[..AUTO_STREAM_MIN]), QueryMode::Stream);
        assert_eq!(pick(&mixed[..AUTO_STREAM_MIN - 1]), QueryMode::Single);
        for t in Traversal::ALL
            .into_iter()
            .filter(|&t| t != Traversal::Standard)
        {
            let (mode, why) = choose_query_mode(&mixed, None, t);
            assert_eq!(mode, QueryMode::Single, "{t:?}");
            assert!(why.contains("standard traversal's order"), "{why}");
        }
        let asked = Some(QueryMode::Stream);
        assert_eq!(
            choose_query_mode(&camera, asked, Traversal::Standard),
            (QueryMode::Stream, "requested by the caller")
        );
    }

    /// The octant-run test for runs of 64 passes a batch whose octant changes at one neighbour
    /// pair in 64 or fewer: exactly in a batch of up to 1025 rays, from 1024 sampled pairs in a
    /// larger one (a million rays in runs of 256 pass, in runs of 16 or 1 they do not).
    #[test]
    fn octant_runs_are_judged_from_samples() {
        for (n, run, long) in [
            (1, 1, true),
            (64, 64, true),
            (129, 64, true),
            (64, 32, false),
            (1025, 1, false),
            (1 << 20, 256, true),
            (1 << 20, 16, false),
            (1 << 20, 1, false),
        ] {
            let rays = rays_in_runs(n, run);
            assert_eq!(
                octant_runs_at_least(&rays, 64),
                long,
                "{n} rays in runs of {run}"
            );
        }
        assert!(octant_runs_at_least(&[], 64));
    }

    /// A pinhole camera's rays in scanline order change octant at the centre column and at
    /// the end of each row: two pairs in a row. Samples spaced evenly by a row's length would
    /// all fall on one column (both changes or neither), and a Weyl sequence's bunched into a
    /// few columns for the sizes from 1920×1104 on (the samples' old positions failed them).
    /// The first sizes pass the streams' test (runs of 64), the narrow ones AUTO's (runs of 16).
    #[test]
    fn camera_rays_in_scanline_order_are_long_runs() {
        let sizes = [
            (1024, 1024, 64),
            (512, 512, 64),
            (1376, 768, 64),
            (1920, 1104, 64),
        ]
        .into_iter()
        .chain([
            (1024, 1008, 64),
            (1280, 828, 64),
            (64, 323, 16),
            (64, 421, 16),
        ])
        .chain([(64, 615, 16), (64, 646, 16), (64, 842, 16), (128, 421, 16)]);
        for (w, h, run) in sizes {
            let rays: Vec<crate::geometry::Ray> = (0..w * h)
                .map(|i| {
                    let (x, y) = ((i % w) as f32, (i / w) as f32);
                    let dir = Vec3::new(x + 0.5 - w as f32 / 2.0, h as f32 / 2.0 - y - 0.5, -900.0);
                    crate::geometry::Ray::new(Vec3::ZERO, dir, 0.0, f32::INFINITY)
                })
                .collect();
            assert!(octant_runs_at_least(&rays, run), "{w}x{h} runs of {run}");
            // Shuffled (every 7919th ray in turn) the same rays are incoherent.
            let shuffled: Vec<_> = (0..rays.len())
                .map(|k| rays[k * 7919 % rays.len()])
                .collect();
            assert!(!octant_runs_at_least(&shuffled, run), "{w}x{h} shuffled");
        }
    }
}
