//! `rt2_camera`: look-at pinhole or thin-lens camera. Calls on one camera must not overlap
//! with edits of it from another thread; a camera may be read by concurrent renders.

use super::ffi::{array, check_out, destroy, guard, handle_mut, handle_type, write_out, Handle};
use crate::camera::Camera;
use crate::error::Rt2Status;
use glam::Vec3;

/// Opaque camera handle. Defaults: eye (0,0,5) looking at the origin, up +Y, 45° vertical
/// field of view, pinhole.
#[repr(C)]
pub struct rt2_camera {
    /// First field of every handle, so checking it never reads past a handle of another type.
    magic: u64,
    pub(crate) camera: Camera,
}

handle_type!(rt2_camera, 0x7274_325f_6361_6d00);

/// Creates a camera with the defaults: eye (0, 0, 5) looking at the origin, up +y, a vertical
/// field of view of 45 degrees, a pinhole lens (aperture 0, focus distance 1).
///
/// # Safety
/// `out` points to writable storage.
#[no_mangle]
pub unsafe extern "C" fn rt2_camera_create(out: *mut *mut rt2_camera) -> Rt2Status {
    guard(|| {
        check_out(out, "out")?;
        let h = Box::new(rt2_camera {
            magic: rt2_camera::MAGIC,
            camera: Camera::default(),
        });
        write_out(out, "out", Box::into_raw(h))
    })
}

/// Frees a camera. NULL is a no-op.
///
/// # Safety
/// `camera` is NULL or a camera not yet destroyed.
#[no_mangle]
pub unsafe extern "C" fn rt2_camera_destroy(camera: *mut rt2_camera) {
    guard(|| {
        destroy(camera);
        Ok(())
    });
}

/// Places the camera at `eye` looking at `target`; `up` must not be parallel to the view, and
/// points to the top of the image (pixel row 0).
///
/// # Safety
/// `camera` is a live camera; the arrays hold 3 floats each.
#[no_mangle]
pub unsafe extern "C" fn rt2_camera_look_at(
    camera: *mut rt2_camera,
    eye: *const f32,
    target: *const f32,
    up: *const f32,
) -> Rt2Status {
    guard(|| {
        let c = handle_mut(camera, "camera")?;
        let [eye, target, up] = [(eye, "eye"), (target, "target"), (up, "up")]
            .map(|(p, n)| array::<f32, 3>(p, n).map(Vec3::from));
        c.camera.look_at(eye?, target?, up?)
    })
}

/// Sets the vertical field of view in degrees, in (0, 180) (zoom). Ray directions are f32,
/// which resolve angles to a few 1e-8 radians: below about 2e-6° times the image height in
/// pixels (0.0015° at 768 rows) neighbouring rows can get the same ray, and the image shows
/// bands rather than finer detail (a view off the axes, 768 rows: all rows distinct at
/// 0.004°, 587 of 768 at 0.001°, 7 at 1e-5°).
///
/// # Safety
/// `camera` is a live camera.
#[no_mangle]
pub unsafe extern "C" fn rt2_camera_set_fov(
    camera: *mut rt2_camera,
    vertical_degrees: f32,
) -> Rt2Status {
    guard(|| {
        handle_mut(camera, "camera")?
            .camera
            .set_fov(vertical_degrees)
    })
}

/// Sets the thin lens: `aperture` is the lens diameter (0 = pinhole), `focus_distance` the
/// distance of the sharp plane (> 0). Depth of field needs several samples per pixel.
/// INVALID_ARGUMENT (and the camera unchanged) for a NaN or negative aperture, a NaN,
/// negative or zero focus distance, or either length above 1e18 (a lens ray's squared length
/// must fit in f32). A lens too small to move a ray off the eye at that focus gives the
/// pinhole's rays.
///
/// # Safety
/// `camera` is a live camera.
#[no_mangle]
pub unsafe extern "C" fn rt2_camera_set_lens(
    camera: *mut rt2_camera,
    aperture: f32,
    focus_distance: f32,
) -> Rt2Status {
    guard(|| {
        handle_mut(camera, "camera")?
            .camera
            .set_lens(aperture, focus_distance)
    })
}
