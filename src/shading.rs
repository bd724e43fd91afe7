//! Whitted shading math, written once for the CPU (the WGSL kernels mirror it): Phong with
//! point lights, mirror directions, Snell refraction and Schlick's Fresnel approximation.

use crate::scene::{Material, PointLight};
use glam::Vec3;

/// Phong contribution of one light at point `p` with unit normal `n` facing the viewer,
/// `view` the unit direction from `p` towards the viewer, `base` the material colour there.
pub fn phong(m: &Material, base: Vec3, p: Vec3, n: Vec3, view: Vec3, light: &PointLight) -> Vec3 {
    let l = direction_to(light.position - p);
    let ndotl = n.dot(l);
    // A light switched off (intensity 0) adds nothing, even where the product of the colours
    // overflows (a colour of 1e30 under a light of 1e10 made inf · 0 = NaN: a black pixel).
    if ndotl <= 0.0 || light.intensity == 0.0 {
        return Vec3::ZERO;
    }
    let r = reflect(-l, n);
    let spec = r.dot(view).max(0.0).powf(m.shininess);
    (m.diffuse * ndotl * base + Vec3::splat(m.specular * spec)) * light.color * light.intensity
}

/// `v` normalised as `normalize_or_zero` does where `|v|²` is a normal float (bit for bit the
/// GPU's `unit_or_zero`), else divided by its largest component first: a light 2e19 away
/// squared to infinity and lit nothing.
pub fn direction_to(v: Vec3) -> Vec3 {
    if v.length_squared().is_normal() {
        v.normalize_or_zero()
    } else {
        crate::geometry::unit(v).unwrap_or(Vec3::ZERO)
    }
}

/// `|v|`, also where `|v|²` leaves the normal range (a light 2e19 away).
pub fn distance(v: Vec3) -> f32 {
    let l2 = v.length_squared();
    if l2.is_normal() {
        return l2.sqrt();
    }
    let m = v.abs().max_element();
    if !(m > 0.0 && m.is_finite()) {
        return m;
    }
    m * (v / m).length()
}

/// Mirror direction of `d` about the unit normal `n`.
pub fn reflect(d: Vec3, n: Vec3) -> Vec3 {
    d - 2.0 * d.dot(n) * n
}

/// Refraction of unit `d` through a surface with unit normal `n` facing against `d`,
/// `eta` = n_from / n_to: the refracted direction and the Fresnel reflectance there
/// ([`schlick`]); `None` on total internal reflection.
pub fn refract(d: Vec3, n: Vec3, eta: f32) -> Option<(Vec3, f32)> {
    let cos_i = -d.dot(n);
    let sin2_t = eta * eta * (1.0 - cos_i * cos_i).max(0.0);
    if sin2_t > 1.0 {
        return None;
    }
    let cos_t = (1.0 - sin2_t).sqrt();
    let t = (eta * d + (eta * cos_i - cos_t) * n).normalize();
    Some((t, schlick(cos_i, cos_t, eta)))
}

/// Schlick's approximation of the Fresnel reflectance of a surface crossed with index ratio
/// `eta` = n_from / n_to, incidence cosine `cos_i` and transmission cosine `cos_t`. It takes
/// the cosine on the less dense side (the larger angle): the incident one entering a denser
/// medium, the transmitted one leaving it. With the incident one on the way out too, a ray
/// leaving glass reflected about 4% at every angle and then all of it past the critical
/// angle: a hard ring inside glass objects, where the reflectance rises steeply but
/// continuously to 1 (exact Fresnel: 0.23 at 39.8° inside glass of index 1.5).
pub fn schlick(cos_i: f32, cos_t: f32, eta: f32) -> f32 {
    let cos = if eta > 1.0 { cos_t } else { cos_i };
    let r0 = ((1.0 - eta) / (1.0 + eta)).powi(2);
    r0 + (1.0 - r0) * (1.0 - cos.clamp(0.0, 1.0)).powi(5)
}
