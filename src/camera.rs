//! The pinhole / thin-lens camera. Zoom (field of view) and focus are parameters of primary
//! rays only, as in the thesis; the aspect ratio comes from the frame.

use crate::error::{Error, Result};
use crate::geometry::{unit, Ray};
use glam::{Vec2, Vec3};

/// The largest aperture and focus distance: a lens ray's direction spans at most about the
/// two, and its squared length must stay within f32 (1e36 against `f32::MAX` = 3.4e38).
pub const LENS_MAX: f32 = 1e18;

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    pub eye: Vec3,
    pub target: Vec3,
    pub up: Vec3,
    /// Vertical field of view in degrees.
    pub fov_y: f32,
    /// Lens diameter; 0 is a pinhole (no depth of field).
    pub aperture: f32,
    /// Distance from the eye to the plane in focus.
    pub focus_distance: f32,
}

impl Default for Camera {
    fn default() -> Self {
        Camera {
            eye: Vec3::new(0.0, 0.0, 5.0),
            target: Vec3::ZERO,
            up: Vec3::Y,
            fov_y: 45.0,
            aperture: 0.0,
            focus_distance: 1.0,
        }
    }
}

/// The camera's basis and image-plane scale, computed once per frame.
#[derive(Clone, Copy, Debug)]
pub struct CameraRays {
    eye: Vec3,
    forward: Vec3,
    right: Vec3,
    up: Vec3,
    half_h: f32,
    half_w: f32,
    aperture: f32,
    focus: f32,
}

impl Camera {
    pub fn look_at(&mut self, eye: Vec3, target: Vec3, up: Vec3) -> Result<()> {
        for (n, v) in [("eye", eye), ("target", target), ("up", up)] {
            if !v.is_finite() {
                return Err(Error::invalid_argument(format!(
                    "{n} is {:?} (must be finite)",
                    v.to_array()
                )));
            }
        }
        // The basis is built from the unit view direction and up, as `rays` builds it
        // (`geometry::unit`: an `up` of 1e-23, normalised directly, gave NaN rays).
        let f = target - eye;
        if !f.is_finite() {
            return Err(Error::invalid_argument(format!(
                "eye {:?} and target {:?} are too far apart (their difference overflows)",
                eye.to_array(),
                target.to_array()
            )));
        }
        let Some(forward) = unit(f) else {
            return Err(Error::invalid_argument("eye and target are the same point"));
        };
        if unit(up).is_none_or(|u| forward.cross(u).length_squared() <= 1e-12) {
            return Err(Error::invalid_argument(
                "up is zero or parallel to the view direction",
            ));
        }
        self.eye = eye;
        self.target = target;
        self.up = up;
        Ok(())
    }

    pub fn set_fov(&mut self, degrees: f32) -> Result<()> {
        if !(degrees > 0.0 && degrees < 180.0) {
            return Err(Error::invalid_argument(format!(
                "vertical_degrees is {degrees:?} (must be in (0, 180))"
            )));
        }
        self.fov_y = degrees;
        Ok(())
    }

    /// The thin lens. Both lengths are at most [`LENS_MAX`]: a lens ray's direction is
    /// normalised by its squared length, and on the GPU one longer than about 1e19 overflows
    /// to a zero direction (an aperture of 3e38 gave a blank image with an OK status).
    pub fn set_lens(&mut self, aperture: f32, focus_distance: f32) -> Result<()> {
        if !(0.0..=LENS_MAX).contains(&aperture) {
            return Err(Error::invalid_argument(format!(
                "aperture is {aperture:?} (must be in [0, {LENS_MAX:e}])"
            )));
        }
        if !(focus_distance > 0.0 && focus_distance <= LENS_MAX) {
            return Err(Error::invalid_argument(format!(
                "focus_distance is {focus_distance:?} (must be in (0, {LENS_MAX:e}])"
            )));
        }
        self.aperture = aperture;
        self.focus_distance = focus_distance;
        Ok(())
    }

    /// Ray generator for a `width` × `height` image.
    pub fn rays(&self, width: u32, height: u32) -> CameraRays {
        // NaN rays for a camera `look_at` would refuse (its fields are public).
        let unit_or_nan = |v: Vec3| unit(v).unwrap_or(Vec3::NAN);
        let forward = unit_or_nan(self.target - self.eye);
        // With `up` a few microradians off the view, the cross product is that short and its
        // rounding tilts it out of the plane across the view by up to a degree: taken back
        // into that plane, the basis stays orthonormal.
        let right = forward.cross(unit_or_nan(self.up)).normalize();
        let right = (right - right.dot(forward) * forward).normalize();
        let up = right.cross(forward);
        let half_h = (self.fov_y.to_radians() * 0.5).tan();
        CameraRays {
            eye: self.eye,
            forward,
            right,
            up,
            half_h,
            half_w: half_h * width as f32 / height as f32,
            aperture: self.aperture,
            focus: self.focus_distance,
        }
    }
}

impl CameraRays {
    /// The generator as the GPU's parameters take it: eye + aperture, forward + focus
    /// distance, right + half width, up + half height.
    pub fn packed(&self) -> [[f32; 4]; 4] {
        let v = |a: Vec3, w: f32| [a.x, a.y, a.z, w];
        [
            v(self.eye, self.aperture),
            v(self.forward, self.focus),
            v(self.right, self.half_w),
            v(self.up, self.half_h),
        ]
    }

    /// Primary ray through image point `pixel` (in pixels, y down, (0,0) = top-left corner).
    /// `lens` is a point in the unit square used for depth of field.
    pub fn ray(&self, pixel: Vec2, size: Vec2, lens: Vec2) -> Ray {
        let ndc = Vec2::new(2.0 * pixel.x / size.x - 1.0, 1.0 - 2.0 * pixel.y / size.y);
        let dir = (self.forward + ndc.x * self.half_w * self.right + ndc.y * self.half_h * self.up)
            .normalize();
        if self.aperture == 0.0 {
            return Ray::new(self.eye, dir, 0.0, f32::INFINITY);
        }
        // Thin lens: rays from a disk sample converge on the focus plane.
        let focus_point = self.eye + dir * (self.focus / dir.dot(self.forward));
        let r = 0.5 * self.aperture * lens.x.sqrt();
        let phi = std::f32::consts::TAU * lens.y;
        let org = self.eye + r * (phi.cos() * self.right + phi.sin() * self.up);
        // A lens too small to move the ray off the eye, with a focus too near to move the
        // focus point off it (1e-45 each), leaves no direction: the pinhole's ray is the
        // limit (`camera_ray` in shade.wgsl does the same).
        match (focus_point - org).try_normalize() {
            Some(lens_dir) => Ray::new(org, lens_dir, 0.0, f32::INFINITY),
            None => Ray::new(self.eye, dir, 0.0, f32::INFINITY),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Lenses whose rays f32 cannot hold are refused and change nothing; a lens of 1e-45
    /// gives the pinhole's rays (it gave a zero direction, a blank image, with an OK status).
    #[test]
    fn lens_extremes_are_refused_or_give_the_pinhole_limit() {
        let mut c = Camera::default();
        c.set_lens(0.5, 4.0).unwrap();
        for (aperture, focus) in [
            (3e38, 6.0),
            (0.5, 2e18),
            (f32::NAN, 6.0),
            (-1.0, 6.0),
            (0.5, 0.0),
        ] {
            assert!(
                c.set_lens(aperture, focus).is_err(),
                "({aperture}, {focus})"
            );
            assert_eq!((c.aperture, c.focus_distance), (0.5, 4.0));
        }
        c.set_lens(LENS_MAX, LENS_MAX).unwrap();
        let size = Vec2::new(64.0, 48.0);
        let pinhole = Camera::default().rays(64, 48);
        c.set_lens(1e-45, 1e-45).unwrap();
        let tiny = c.rays(64, 48);
        for (p, lens) in [
            (Vec2::new(0.5, 0.5), Vec2::new(0.3, 0.7)),
            (Vec2::new(40.5, 7.5), Vec2::ONE),
        ] {
            let (a, b) = (tiny.ray(p, size, lens), pinhole.ray(p, size, lens));
            assert!(a.dir.is_normalized() && a.org.is_finite(), "{a:?}");
            assert!(
                a.dir.abs_diff_eq(b.dir, 1e-6) && a.org.abs_diff_eq(b.org, 1e-6),
                "{a:?} {b:?}"
            );
        }
    }

    /// Only the directions of the view and of `up` matter: a tiny or huge `up`, or an eye a
    /// hair from its target, gives the rays of the unit vectors (before, `up` = 1e-23 passed
    /// `look_at` and gave NaN rays, a blank frame). Zero and parallel `up` are refused.
    #[test]
    fn the_basis_depends_on_directions_only() {
        let size = Vec2::new(64.0, 48.0);
        let pixels = [
            Vec2::new(0.5, 0.5),
            Vec2::new(40.5, 7.5),
            Vec2::new(63.5, 47.5),
        ];
        let rays_of = |eye: Vec3, target: Vec3, up: Vec3| -> Vec<Vec3> {
            let mut c = Camera::default();
            c.look_at(eye, target, up).unwrap();
            let r = c.rays(64, 48);
            pixels
                .iter()
                .map(|&p| r.ray(p, size, Vec2::splat(0.5)).dir.normalize())
                .collect()
        };
        let (eye, up) = (Vec3::new(0.0, 0.0, 5.0), Vec3::new(1.0, 0.2, 0.0));
        let want = rays_of(eye, Vec3::ZERO, up);
        for (e, t, u) in [
            (eye, Vec3::ZERO, up * 1e-23),
            (eye, Vec3::ZERO, up * 1e30),
            (Vec3::new(0.0, 0.0, 5e-30), Vec3::ZERO, up),
        ] {
            for (a, b) in rays_of(e, t, u).iter().zip(&want) {
                assert!(a.abs_diff_eq(*b, 1e-6), "eye {e}, up {u}: {a} against {b}");
            }
        }
        let mut c = Camera::default();
        for bad in [
            Vec3::ZERO,
            Vec3::new(0.0, 0.0, -1e-30),
            Vec3::new(0.0, 0.0, 3.0),
        ] {
            assert!(c.look_at(eye, Vec3::ZERO, bad).is_err(), "up {bad}");
        }
        assert_eq!(c, Camera::default(), "a refused look_at changed the camera");
    }

    /// An `up` just off the view direction (1 to 21 microradians, which `look_at` accepts)
    /// still gives an orthonormal basis; before, `right` leaned up to 1.2 degrees towards the
    /// view (a helper's 20,000 random views), skewing the image.
    #[test]
    fn the_basis_is_orthonormal_when_up_is_nearly_the_view() {
        let mut rng = crate::rng::Rng(5);
        let mut worst = 0.0f32;
        for _ in 0..20_000 {
            let mut v = || rng.unit() * 2.0 - 1.0;
            let forward = Vec3::new(v(), v(), v()).normalize();
            let across = forward.any_orthonormal_vector();
            let up = forward + (1e-6 + 2e-5 * v().abs()) * across;
            let mut c = Camera::default();
            if c.look_at(Vec3::ZERO, forward * 3.0, up).is_err() {
                continue;
            }
            let r = c.rays(64, 48);
            worst = worst
                .max(r.right.dot(r.forward).abs())
                .max(r.up.dot(r.forward).abs())
                .max(r.right.dot(r.up).abs())
                .max((r.right.length() - 1.0).abs());
        }
        assert!(worst < 1e-6, "worst deviation {worst}");
    }
}
