//! Materials and lights: the Phong/Whitted parameters of the RT² thesis.

use glam::Vec3;

/// A checkerboard of two colours in world space (the thesis' checkered plane).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Checker {
    pub color2: Vec3,
    /// Edge length of one square.
    pub scale: f32,
}

/// Phong terms plus the Whitted ray weights. Reflectivity and transparency are the fractions
/// of light carried by the mirror and transmitted rays; the local Phong colour gets the rest.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Material {
    pub color: Vec3,
    pub ambient: f32,
    pub diffuse: f32,
    pub specular: f32,
    pub shininess: f32,
    pub reflectivity: f32,
    pub transparency: f32,
    /// Index of refraction; used only when the render refracts.
    pub ior: f32,
    pub checker: Option<Checker>,
}

impl Default for Material {
    fn default() -> Self {
        Material {
            color: Vec3::splat(0.8),
            ambient: 0.1,
            diffuse: 0.9,
            specular: 0.3,
            shininess: 32.0,
            reflectivity: 0.0,
            transparency: 0.0,
            ior: 1.5,
            checker: None,
        }
    }
}

impl Material {
    /// Base colour at world point `p`.
    pub fn color_at(&self, p: Vec3) -> Vec3 {
        match self.checker {
            Some(c) => {
                let q = (p / c.scale).floor();
                if (q.x + q.y + q.z).rem_euclid(2.0) < 1.0 {
                    self.color
                } else {
                    c.color2
                }
            }
            None => self.color,
        }
    }
}

/// A point light; no distance falloff, as in the thesis' Whitted renderer.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PointLight {
    pub position: Vec3,
    pub color: Vec3,
    pub intensity: f32,
}
