//! Scenes built in code, so the README commands need no files: a small showcase and the
//! sphere scenes of the thesis' table 2 (same kinds and counts).

use super::{Checker, Material, PointLight, Scene, Shape};
use crate::camera::Camera;
use crate::error::{Error, Result};
use crate::rng::Rng;
use glam::{Affine3A, Vec3};

/// A built-in scene with the camera and trace depth it is meant to be seen with.
pub struct Builtin {
    pub scene: Scene,
    pub camera: Camera,
    pub max_depth: u32,
}

pub const NAMES: [&str; 4] = ["default", "spheres1", "spheres2", "spheres3"];

pub fn by_name(name: &str) -> Result<Builtin> {
    match name {
        "default" => showcase(),
        "spheres1" => spheres1(),
        "spheres2" => spheres2(),
        "spheres3" => spheres3(),
        _ => Err(Error::invalid_argument(format!(
            "unknown built-in scene '{name}' (known: {})",
            NAMES.join(", ")
        ))),
    }
}

/// A bright random colour for a built-in scene's material.
fn color(rng: &mut Rng) -> Vec3 {
    Vec3::new(
        rng.range(0.2, 1.0),
        rng.range(0.2, 1.0),
        rng.range(0.2, 1.0),
    )
}

fn two_lights(scene: &mut Scene, at: [Vec3; 2]) -> Result<()> {
    for p in at {
        scene.add_light(PointLight {
            position: p,
            color: Vec3::ONE,
            intensity: 0.6,
        })?;
    }
    Ok(())
}

fn camera(eye: Vec3, target: Vec3, fov: f32) -> Result<Camera> {
    let mut c = Camera::default();
    c.look_at(eye, target, Vec3::Y)?;
    c.set_fov(fov)?;
    Ok(c)
}

fn checkered_floor(scene: &mut Scene, y: f32, scale: f32, reflectivity: f32) -> Result<()> {
    let floor = scene.add_material(Material {
        color: Vec3::splat(0.9),
        reflectivity,
        checker: Some(Checker {
            color2: Vec3::splat(0.15),
            scale,
        }),
        ..Material::default()
    })?;
    scene.add_object(
        Shape::Plane {
            normal: Vec3::Y,
            offset: y,
        },
        floor,
    )?;
    Ok(())
}

/// Random spheres in a box, each with its own material drawn from `material`.
fn random_spheres(
    scene: &mut Scene,
    rng: &mut Rng,
    count: usize,
    lo: Vec3,
    hi: Vec3,
    radius: (f32, f32),
    mut material: impl FnMut(&mut Rng) -> Material,
) -> Result<()> {
    let palette: Vec<u32> = (0..16)
        .map(|_| scene.add_material(material(rng)))
        .collect::<Result<_>>()?;
    for _ in 0..count {
        let center = Vec3::new(
            rng.range(lo.x, hi.x),
            rng.range(lo.y, hi.y),
            rng.range(lo.z, hi.z),
        );
        let m = palette[(rng.unit() * 16.0) as usize % 16];
        scene.add_object(
            Shape::Sphere {
                center,
                radius: rng.range(radius.0, radius.1),
            },
            m,
        )?;
    }
    Ok(())
}

/// A small showcase of every primitive kind and material feature.
fn showcase() -> Result<Builtin> {
    let mut s = Scene::new();
    checkered_floor(&mut s, 0.0, 1.0, 0.2)?;
    let red = s.add_material(Material {
        color: Vec3::new(0.9, 0.2, 0.2),
        ..Material::default()
    })?;
    let mirror = s.add_material(Material {
        color: Vec3::splat(0.9),
        reflectivity: 0.8,
        ..Material::default()
    })?;
    let glass = s.add_material(Material {
        color: Vec3::ONE,
        transparency: 0.9,
        specular: 0.8,
        shininess: 128.0,
        ior: 1.5,
        ..Material::default()
    })?;
    let blue = s.add_material(Material {
        color: Vec3::new(0.2, 0.4, 0.9),
        ..Material::default()
    })?;
    let gold = s.add_material(Material {
        color: Vec3::new(0.9, 0.7, 0.2),
        reflectivity: 0.3,
        ..Material::default()
    })?;
    s.add_object(
        Shape::Sphere {
            center: Vec3::new(-1.5, 1.0, 0.0),
            radius: 1.0,
        },
        mirror,
    )?;
    s.add_object(
        Shape::Sphere {
            center: Vec3::new(0.8, 0.8, 1.2),
            radius: 0.8,
        },
        glass,
    )?;
    s.add_object(
        Shape::Box {
            min: Vec3::new(1.2, 0.0, -1.5),
            max: Vec3::new(2.4, 1.2, -0.3),
        },
        red,
    )?;
    let e = s.add_object(
        Shape::Ellipsoid {
            center: Vec3::ZERO,
            radii: Vec3::new(0.4, 0.9, 0.4),
        },
        blue,
    )?;
    s.set_transform(e, Affine3A::from_translation(Vec3::new(-0.2, 0.9, -1.8)))?;
    // A square pyramid as a triangle mesh.
    let apex = Vec3::new(3.2, 1.6, 1.0);
    let base = [
        Vec3::new(2.6, 0.0, 0.4),
        Vec3::new(3.8, 0.0, 0.4),
        Vec3::new(3.8, 0.0, 1.6),
        Vec3::new(2.6, 0.0, 1.6),
    ];
    let mut positions = base.to_vec();
    positions.push(apex);
    let triangles = vec![
        [0, 1, 4],
        [1, 2, 4],
        [2, 3, 4],
        [3, 0, 4],
        [0, 2, 1],
        [0, 3, 2],
    ];
    s.add_object(
        Shape::Mesh {
            positions,
            triangles,
        },
        gold,
    )?;
    two_lights(
        &mut s,
        [Vec3::new(-4.0, 6.0, 5.0), Vec3::new(5.0, 5.0, 3.0)],
    )?;
    Ok(Builtin {
        scene: s,
        camera: camera(Vec3::new(0.5, 3.0, 7.5), Vec3::new(0.4, 0.7, 0.0), 45.0)?,
        max_depth: 6,
    })
}

/// Thesis "Spheres1": 1.2 million spheres, ray casting (depth 1).
fn spheres1() -> Result<Builtin> {
    let mut s = Scene::new();
    let mut rng = Rng(1);
    random_spheres(
        &mut s,
        &mut rng,
        1_200_000,
        Vec3::splat(-50.0),
        Vec3::splat(50.0),
        (0.05, 0.25),
        |r| Material {
            color: color(r),
            ..Material::default()
        },
    )?;
    two_lights(
        &mut s,
        [
            Vec3::new(-80.0, 120.0, 150.0),
            Vec3::new(120.0, 80.0, 100.0),
        ],
    )?;
    Ok(Builtin {
        scene: s,
        camera: camera(Vec3::new(0.0, 0.0, 140.0), Vec3::ZERO, 45.0)?,
        max_depth: 1,
    })
}

/// Thesis "Spheres2": 5,000 mostly reflective spheres, depth 6.
fn spheres2() -> Result<Builtin> {
    let mut s = Scene::new();
    let mut rng = Rng(2);
    random_spheres(
        &mut s,
        &mut rng,
        5_000,
        Vec3::splat(-20.0),
        Vec3::splat(20.0),
        (0.2, 0.9),
        |r| Material {
            color: color(r),
            reflectivity: r.range(0.2, 0.7),
            ..Material::default()
        },
    )?;
    two_lights(
        &mut s,
        [Vec3::new(-30.0, 50.0, 60.0), Vec3::new(50.0, 30.0, 40.0)],
    )?;
    Ok(Builtin {
        scene: s,
        camera: camera(Vec3::new(0.0, 5.0, 60.0), Vec3::ZERO, 45.0)?,
        max_depth: 6,
    })
}

/// Thesis "Spheres3": 1,000 spheres over a checkered plane, two lights, shadows, depth 6.
fn spheres3() -> Result<Builtin> {
    let mut s = Scene::new();
    let mut rng = Rng(3);
    checkered_floor(&mut s, 0.0, 2.0, 0.3)?;
    random_spheres(
        &mut s,
        &mut rng,
        1_000,
        Vec3::new(-30.0, 0.5, -30.0),
        Vec3::new(30.0, 8.0, 30.0),
        (0.3, 1.2),
        |r| Material {
            color: color(r),
            reflectivity: r.range(0.0, 0.6),
            ..Material::default()
        },
    )?;
    two_lights(
        &mut s,
        [Vec3::new(-20.0, 40.0, 30.0), Vec3::new(30.0, 30.0, 20.0)],
    )?;
    Ok(Builtin {
        scene: s,
        camera: camera(Vec3::new(0.0, 18.0, 50.0), Vec3::new(0.0, 2.0, 0.0), 45.0)?,
        max_depth: 6,
    })
}
