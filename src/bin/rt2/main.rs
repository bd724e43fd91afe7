//! The `rt2` command line: `render` draws a built-in scene or a model file to a PNG, `bench`
//! measures (see `rt2 bench --help`).

mod args;
mod bench;
mod output;

use args::{Arg, Reader};
use glam::Vec3;
use output::{say, warn};
use rt2::camera::Camera;
use rt2::context::Context;
use rt2::cpu::traverse::Traversal;
use rt2::dispatch::BackendRequest;
use rt2::error::{Error, Result};
use rt2::frame::Frame;
use rt2::kdtree::{BuildOptions, Builder};
use rt2::precision::{Intersector, OffsetMode};
use rt2::render::{RenderOptions, Transparency};
use rt2::scene::{builtin, loaders, Material, PointLight, Scene, Shape};
use std::ffi::{OsStr, OsString};
use std::path::{Path, PathBuf};
use std::time::Instant;

const USAGE: &str = "usage:
  rt2 render [SCENE|MODEL] [options]   render to a PNG
      SCENE: default (when none is given), spheres1, spheres2, spheres3;
      MODEL: a .ply or .obj file
      -o, --output FILE     PNG to write (default: rt2.png)
      -s, --size WxH        image size (default: 1376x768, the thesis' resolution)
      --backend B           auto, cpu or gpu (default: auto; RT2_BACKEND, when set, overrides
                            it, as it does every program's context)
      --traversal T         auto, standard, kd-restart, push-down, short-stack,
                            push-down-short-stack, ropes, ropes++ (default: auto)
      --depth N             maximum ray depth (default: the scene's: 6, or 1 for spheres1
                            and for a model, primary and shadow rays only)
      --samples N           samples per pixel (default: 1)
      --straight            RT² transparency (no refraction)
      --intersector I       moller-trumbore or watertight (default: moller-trumbore)
      --offset M            secondary-ray origins: epsilon, robust, exclude-prim (default: epsilon)
      --threads N           worker threads (default: all cores)
      --builder B           sah (default, perfect splits) or midpoint
  rt2 bench [frames|build|rays|tables|streams|gpu|chart|memory|all]    measure (rt2 bench --help)
  rt2 help | --help | -h               this text
  rt2 --version | -V                   the library's version";

fn main() {
    // `args_os`, not `args`: a model or output path need not be UTF-8 (and `args` panics).
    let args: Vec<OsString> = std::env::args_os().skip(1).collect();
    if let Err(e) = run(&args) {
        warn(format_args!("rt2: {}", e.message));
        std::process::exit(1);
    }
}

/// Runs the command that `args` (without the program's name) ask for.
fn run(args: &[OsString]) -> Result<()> {
    let Some((command, rest)) = args.split_first() else {
        return Err(Error::invalid_argument(format!(
            "no command given\n{USAGE}"
        )));
    };
    match args::utf8(command)? {
        "render" => render(rest),
        "bench" => bench::run(rest),
        "help" | "-h" | "--help" => say(USAGE),
        "-V" | "--version" => say(format_args!("rt2 {}", env!("CARGO_PKG_VERSION"))),
        other => Err(Error::invalid_argument(format!(
            "unknown command '{other}'\n{USAGE}"
        ))),
    }
}

/// A scene ready to render: the model files get a material, two lights and a camera framing
/// them like the ray sets of `../shared/raysets` do.
pub struct Loaded {
    pub scene: Scene,
    pub camera: Camera,
    pub max_depth: u32,
}

/// Refuses a name that is neither a built-in scene nor a file name with an extension (the
/// model loaders go by it), naming the built-in scenes: a mistyped scene name is not a model.
fn check_scene_name(name: &OsStr) -> Result<()> {
    if Path::new(name).extension().is_none() && !builtin::NAMES.iter().any(|&n| n == name) {
        return Err(Error::invalid_argument(format!(
            "unknown scene '{}': the built-in scenes are {}; a model is a .ply or .obj file",
            name.to_string_lossy(),
            builtin::NAMES.join(", ")
        )));
    }
    Ok(())
}

/// A built-in scene by name, or else the model file at that path.
pub fn load_scene(name: impl AsRef<OsStr>) -> Result<Loaded> {
    let name = name.as_ref();
    check_scene_name(name)?;
    if let Some(builtin) = name.to_str().filter(|n| builtin::NAMES.contains(n)) {
        let b = builtin::by_name(builtin)?;
        return Ok(Loaded {
            scene: b.scene,
            camera: b.camera,
            max_depth: b.max_depth,
        });
    }
    let mesh = loaders::load_mesh(Path::new(name))?;
    let bounds = rt2::geometry::Aabb::from_points(&mesh.positions);
    let (c, diag) = (bounds.center(), bounds.diagonal().max(1e-6));
    let mut scene = Scene::new();
    let m = scene.add_material(Material {
        color: Vec3::new(0.85, 0.8, 0.7),
        ..Material::default()
    })?;
    scene.add_object(
        Shape::Mesh {
            positions: mesh.positions,
            triangles: mesh.triangles,
        },
        m,
    )?;
    for offset in [Vec3::new(0.5, 1.0, 0.3), Vec3::new(-0.8, 0.6, 1.0)] {
        scene.add_light(PointLight {
            position: c + diag * offset,
            color: Vec3::ONE,
            intensity: 0.6,
        })?;
    }
    let mut camera = Camera::default();
    camera.look_at(
        c + 0.9 * diag * Vec3::new(0.3, 0.35, 1.0).normalize(),
        c,
        Vec3::Y,
    )?;
    camera.set_fov(60.0)?;
    Ok(Loaded {
        scene,
        camera,
        max_depth: 1,
    })
}

/// `WIDTHxHEIGHT` as numbers; the message quotes the whole value (`10x10x10`), not the part
/// that failed to parse.
fn parse_size(flag: &str, size: &str) -> Result<(u32, u32)> {
    size.split_once('x')
        .and_then(|(w, h)| Some((w.parse().ok()?, h.parse().ok()?)))
        .ok_or_else(|| {
            Error::invalid_argument(format!(
                "{flag}: expected WIDTHxHEIGHT (e.g. 1376x768), got '{size}'"
            ))
        })
}

fn render(args: &[OsString]) -> Result<()> {
    let mut name = None;
    let mut output = PathBuf::from("rt2.png");
    let (mut width, mut height) = (1376u32, 768u32);
    let mut backend = BackendRequest::Auto;
    let mut opts = RenderOptions::default();
    let mut depth = None;
    let mut threads = 0u32;
    let mut builder = Builder::Sah;
    let mut args = Reader::new(args);
    while let Some(arg) = args.next_arg() {
        let a = match arg? {
            Arg::Positional(s) => {
                args::set_once(&mut name, s, "scene")?;
                continue;
            }
            Arg::Flag(a) => a,
        };
        match a {
            "-h" | "--help" => return say(USAGE),
            "-o" | "--output" => output = args.path(a)?,
            "-s" | "--size" => (width, height) = parse_size(a, args.text(a)?)?,
            "--backend" => {
                let b = args.text(a)?;
                backend = BackendRequest::parse(b)
                    .ok_or_else(|| Error::invalid_argument(format!("unknown backend '{b}'")))?;
            }
            "--traversal" => {
                let t = args.text(a)?;
                opts.traversal = match t {
                    "auto" => None,
                    _ => Some(Traversal::from_name(t).ok_or_else(|| {
                        Error::invalid_argument(format!("unknown traversal '{t}'"))
                    })?),
                };
            }
            "--depth" => depth = Some(args.parse(a)?),
            "--samples" => opts.samples = args.parse(a)?,
            "--threads" => threads = args.parse(a)?,
            "--straight" => opts.transparency = Transparency::Straight,
            "--builder" => {
                builder = match args.text(a)? {
                    "sah" => Builder::Sah,
                    "midpoint" => Builder::Midpoint,
                    b => return Err(Error::invalid_argument(format!("unknown builder '{b}'"))),
                };
            }
            "--intersector" => {
                let i = args.text(a)?;
                opts.intersector = Intersector::from_name(i)
                    .ok_or_else(|| Error::invalid_argument(format!("unknown intersector '{i}'")))?;
            }
            "--offset" => {
                let m = args.text(a)?;
                opts.offset_mode = OffsetMode::from_name(m)
                    .ok_or_else(|| Error::invalid_argument(format!("unknown offset mode '{m}'")))?;
            }
            s => {
                return Err(Error::invalid_argument(format!(
                    "unknown option '{s}'\n{USAGE}"
                )))
            }
        }
    }
    let name = name.unwrap_or(OsStr::new("default"));
    // Before any work: a bad output path, option or size found after a long load, commit or
    // render wastes it (the render checks the options again, with the scene's depth).
    rt2::frame::check_png_path(&output)?;
    check_scene_name(name)?;
    if let Some(d) = depth {
        opts.max_depth = d;
    }
    opts.validate()?;
    let mut frame = Frame::new(width, height)?;
    let ctx = Context::new(backend, threads)?;
    let t0 = Instant::now();
    let mut loaded = load_scene(name)?;
    let load_ms = t0.elapsed().as_secs_f64() * 1e3;
    opts.max_depth = depth.unwrap_or(loaded.max_depth);
    loaded.scene.set_build_options(BuildOptions {
        builder,
        ..loaded.scene.build_options()
    });
    ctx.install(|| loaded.scene.commit())?;
    if opts.traversal.is_some_and(|t| t.needs_ropes()) {
        loaded.scene.ensure_ropes()?;
    }
    if opts.intersector == Intersector::Watertight {
        loaded.scene.ensure_exact_vertices()?;
    }
    let committed = loaded.scene.committed()?;
    let t1 = Instant::now();
    ctx.render(committed, &loaded.camera, &opts, &mut frame)?;
    let ms = t1.elapsed().as_secs_f64() * 1e3;
    frame.save_png(&output)?;
    let primary = width as f64 * height as f64 * opts.samples as f64;
    let (name, output) = (name.to_string_lossy(), output.display());
    say(format_args!(
        "{name}: {} primitives, load {load_ms:.1} ms, commit {:.1} ms (tree {:.1} ms, {} nodes)",
        committed.prims.len() + committed.prims.planes.len(),
        committed.commit_ms,
        committed.tree.stats.build_ms,
        committed.tree.stats.node_count
    ))?;
    say(format_args!(
        "rendered {width}x{height} on {} threads ({}): {ms:.1} ms, {:.2} M primary rays/s -> {output}",
        ctx.threads(),
        ctx.decision().reason,
        primary / ms / 1e3
    ))
}
