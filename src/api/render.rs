//! `rt2_render`: one frame of Whitted ray tracing through the dispatch layer.

use super::camera::rt2_camera;
use super::context::rt2_context;
use super::ffi::{guard, handle, handle_mut, read_versioned};
use super::frame::rt2_frame;
use super::options::rt2_render_options;
use super::scene::rt2_scene;
use crate::error::Rt2Status;
use crate::render::RenderOptions;

/// Renders `scene` seen by `camera` into `frame` (its aspect ratio sets the image's).
/// `options` may be NULL for the defaults. The scene must be committed after its last edit
/// (else INVALID_OPERATION). Any number of renders of one scene may run at once, each into
/// its own frame.
///
/// # Safety
/// Handles are live; `options` is NULL or points to an `rt2_render_options`.
#[no_mangle]
pub unsafe extern "C" fn rt2_render(
    ctx: *const rt2_context,
    scene: *const rt2_scene,
    camera: *const rt2_camera,
    options: *const rt2_render_options,
    frame: *mut rt2_frame,
) -> Rt2Status {
    guard(|| {
        let c = handle(ctx, "ctx")?;
        let s = handle(scene, "scene")?;
        let cam = handle(camera, "camera")?;
        let opts = if options.is_null() {
            RenderOptions::default()
        } else {
            read_versioned(options)?.to_options()?
        };
        let f = handle_mut(frame, "frame")?;
        // A render the backend refuses is refused before anything is built for it.
        c.inner.check_render(&opts)?;
        // `to_options` validated the options (defaults are valid): refused ones never reach
        // the ropes or exact vertices built here, so a failed call leaves the scene as it was.
        let guard = s.prepared(
            opts.traversal.is_some_and(|t| t.needs_ropes()),
            opts.intersector == crate::precision::Intersector::Watertight,
        )?;
        let committed = guard.committed()?;
        c.inner.render(committed, &cam.camera, &opts, &mut f.frame)
    })
}
