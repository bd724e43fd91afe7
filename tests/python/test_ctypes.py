"""Drives librt2 through ctypes, as a Python user would.

The library path comes from the RT2_LIBRARY environment variable (tests/python_ctypes.rs sets
it to the librt2.so that `cargo test` built). Exits non-zero on the first failed check.
"""

import ctypes
import os
import sys

RT2_STATUS_OK = 0
RT2_STATUS_INVALID_ARGUMENT = 1


class RenderOptions(ctypes.Structure):
    # Mirrors rt2_render_options in include/rt2.h.
    _fields_ = [
        ("struct_size", ctypes.c_uint32),
        ("max_depth", ctypes.c_uint32),
        ("samples", ctypes.c_uint32),
        ("traversal", ctypes.c_uint32),
        ("short_stack_size", ctypes.c_uint32),
        ("transparency", ctypes.c_uint32),
        ("background", ctypes.c_float * 3),
        ("schedule", ctypes.c_uint32),
        ("gpu_path", ctypes.c_uint32),
        ("intersector", ctypes.c_uint32),
        ("offset_mode", ctypes.c_uint32),
    ]


class Ray(ctypes.Structure):
    # Mirrors rt2_ray.
    _fields_ = [
        ("org", ctypes.c_float * 3),
        ("tmin", ctypes.c_float),
        ("dir", ctypes.c_float * 3),
        ("tmax", ctypes.c_float),
    ]


class Hit(ctypes.Structure):
    # Mirrors rt2_hit.
    _fields_ = [
        ("t", ctypes.c_float),
        ("u", ctypes.c_float),
        ("v", ctypes.c_float),
        ("object", ctypes.c_uint32),
        ("prim", ctypes.c_uint32),
    ]


RT2_INVALID_ID = 0xFFFFFFFF


def load(path):
    lib = ctypes.CDLL(path)
    p = ctypes.c_void_p
    pp = ctypes.POINTER(ctypes.c_void_p)
    f3 = ctypes.POINTER(ctypes.c_float)
    u32 = ctypes.c_uint32
    sigs = {
        "rt2_context_create": ([p, pp], u32),
        "rt2_context_destroy": ([p], None),
        "rt2_scene_create": ([p, pp], u32),
        "rt2_scene_destroy": ([p], None),
        "rt2_scene_add_sphere": ([p, f3, ctypes.c_float, u32, ctypes.POINTER(u32)], u32),
        "rt2_scene_add_point_light": ([p, f3, f3, ctypes.c_float, ctypes.POINTER(u32)], u32),
        "rt2_scene_commit": ([p], u32),
        "rt2_camera_create": ([pp], u32),
        "rt2_camera_destroy": ([p], None),
        "rt2_frame_create": ([u32, u32, pp], u32),
        "rt2_frame_destroy": ([p], None),
        "rt2_frame_pixels": ([p], ctypes.POINTER(ctypes.c_uint8)),
        "rt2_render_options_default": ([], RenderOptions),
        "rt2_render": ([p, p, p, ctypes.POINTER(RenderOptions), p], u32),
        # Arrays of structs and a size_t count: the classic ctypes pitfalls (a count declared
        # as c_int would be read with garbage in its upper half on x86-64).
        "rt2_intersect": ([p, p, ctypes.POINTER(Ray), ctypes.c_size_t, ctypes.POINTER(Hit), p, p], u32),
        "rt2_occluded": ([p, p, ctypes.POINTER(Ray), ctypes.c_size_t, ctypes.POINTER(ctypes.c_uint8), p, p], u32),
        "rt2_status_string": ([u32], ctypes.c_char_p),
        "rt2_last_error_message": ([], ctypes.c_char_p),
    }
    for name, (args, res) in sigs.items():
        fn = getattr(lib, name)
        fn.argtypes = args
        fn.restype = res
    return lib


def vec3(x, y, z):
    return (ctypes.c_float * 3)(x, y, z)


def main():
    path = os.environ.get("RT2_LIBRARY")
    if not path:
        sys.exit("RT2_LIBRARY is not set (path of librt2.so)")
    lib = load(path)

    def ok(status, what):
        if status != RT2_STATUS_OK:
            msg = lib.rt2_last_error_message().decode()
            sys.exit(f"{what} failed: {lib.rt2_status_string(status).decode()}: {msg}")

    ctx, scene, camera, frame = (ctypes.c_void_p() for _ in range(4))
    ok(lib.rt2_context_create(None, ctypes.byref(ctx)), "rt2_context_create")
    ok(lib.rt2_scene_create(ctx, ctypes.byref(scene)), "rt2_scene_create")
    obj = ctypes.c_uint32(0)
    ok(lib.rt2_scene_add_sphere(scene, vec3(0, 0, 0), 1.0, 0, ctypes.byref(obj)), "rt2_scene_add_sphere")
    ok(lib.rt2_scene_add_point_light(scene, vec3(2, 3, 5), vec3(1, 1, 1), 1.0, None), "rt2_scene_add_point_light")
    ok(lib.rt2_scene_commit(scene), "rt2_scene_commit")
    ok(lib.rt2_camera_create(ctypes.byref(camera)), "rt2_camera_create")
    ok(lib.rt2_frame_create(32, 32, ctypes.byref(frame)), "rt2_frame_create")
    opts = lib.rt2_render_options_default()
    assert opts.struct_size == ctypes.sizeof(RenderOptions), (
        f"struct_size {opts.struct_size} != sizeof {ctypes.sizeof(RenderOptions)}: the Python mirror is stale"
    )
    # A background of our own: its exact bytes in the corners check the mirror's field
    # offsets (0.2, 0.4, 0.6 times 255 are whole numbers; frames hold linear values).
    opts.background[0], opts.background[1], opts.background[2] = 0.2, 0.4, 0.6
    ok(lib.rt2_render(ctx, scene, camera, ctypes.byref(opts), frame), "rt2_render")

    px = lib.rt2_frame_pixels(frame)
    assert px, "rt2_frame_pixels returned NULL"

    def pixel(x, y):
        i = 4 * (y * 32 + x)
        return tuple(px[i + k] for k in range(4))

    # Default camera at (0,0,5) looking at the origin with a 45 deg vertical field of view:
    # the unit sphere, seen under asin(1/5) either side of the axis, covers
    # tan(asin(0.2)) / tan(22.5 deg) = 0.49 of the half-height, about 16 of the 32 rows.
    background = (51, 102, 153, 255)
    centre, corner = pixel(16, 16), pixel(0, 0)
    print(f"centre {centre}, corner {corner}")
    assert corner == background, f"corner {corner}, expected the background {background}"
    assert centre[0] == centre[1] == centre[2] and 0 < centre[0] < 255 and centre[3] == 255, (
        f"centre {centre}: a lit grey sphere expected"
    )
    rows = sum(pixel(16, y) != background for y in range(32))
    assert 15 <= rows <= 17, f"the sphere spans {rows} rows of column 16, expected about 16"

    # Queries: the camera's axis hits the sphere at t = 4, a parallel ray 2 to the side
    # misses, and a ray from the centre leaves it at t = 1.
    rays = (Ray * 3)(
        Ray(vec3(0, 0, 5), 0.0, vec3(0, 0, -1), float("inf")),
        Ray(vec3(2, 0, 5), 0.0, vec3(0, 0, -1), float("inf")),
        Ray(vec3(0, 0, 0), 0.0, vec3(1, 0, 0), float("inf")),
    )
    hits = (Hit * 3)()
    ok(lib.rt2_intersect(ctx, scene, rays, 3, hits, None, None), "rt2_intersect")
    got = [(round(h.t, 5), h.object) for h in hits]
    assert got[0] == (4.0, obj.value) and got[2] == (1.0, obj.value), f"hits {got}"
    assert hits[1].object == RT2_INVALID_ID, f"the side ray hit object {hits[1].object}"
    occluded = (ctypes.c_uint8 * 3)()
    ok(lib.rt2_occluded(ctx, scene, rays, 3, occluded, None, None), "rt2_occluded")
    assert list(occluded) == [1, 0, 1], f"occluded {list(occluded)}"

    # An invalid call: a negative radius.
    status = lib.rt2_scene_add_sphere(scene, vec3(0, 0, 0), -1.0, 0, None)
    msg = lib.rt2_last_error_message().decode()
    assert status == RT2_STATUS_INVALID_ARGUMENT, f"negative radius gave {lib.rt2_status_string(status).decode()}"
    assert msg, "no error message for the negative radius"
    print(f"negative radius: {lib.rt2_status_string(status).decode()}: {msg}")

    lib.rt2_frame_destroy(frame)
    lib.rt2_camera_destroy(camera)
    lib.rt2_scene_destroy(scene)
    lib.rt2_context_destroy(ctx)
    print("test_ctypes: OK")


if __name__ == "__main__":
    main()
