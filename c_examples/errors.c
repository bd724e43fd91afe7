/* errors.c: every error path of the C API a caller can hit. For each call it checks the exact
 * status, that rt2_last_error_message() is non-empty (and names the culprit where rt2.h
 * promises so), that outputs were not written and that the objects were left unchanged.
 * Prints one line per check and "N passed, M failed"; exits 1 if any check failed.
 *
 *   ./errors [TMPDIR]   (a malformed .ply file is written there; default /tmp)
 */
#define _POSIX_C_SOURCE 200809L /* setenv, unsetenv, strdup */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "rt2.h"

static int passed = 0, failed = 0;

static void report(int ok, const char *what, const char *detail) {
    printf("%s %s%s%s\n", ok ? "pass" : "FAIL", what, detail ? ": " : "", detail ? detail : "");
    if (ok) passed++; else failed++;
}

/* The call returned `want`, and if that is an error, a non-empty message containing `needle`. */
static int expect(rt2_status got, rt2_status want, const char *needle, const char *what) {
    char detail[512];
    const char *msg = rt2_last_error_message();
    int ok = got == want;
    if (ok && want != RT2_STATUS_OK) ok = msg != NULL && msg[0] != '\0' && (needle == NULL || strstr(msg, needle) != NULL);
    snprintf(detail, sizeof detail, "%s (want %s)%s%s%s", rt2_status_string(got), rt2_status_string(want),
             want != RT2_STATUS_OK ? ", message \"" : "", want != RT2_STATUS_OK && msg ? msg : "",
             want != RT2_STATUS_OK ? "\"" : "");
    report(ok, what, detail);
    return ok;
}

/* Set-up calls that must succeed; the program cannot go on otherwise. */
static void must(rt2_status s, const char *what) {
    if (s != RT2_STATUS_OK) {
        fprintf(stderr, "errors: set-up call %s failed: %s: %s\n", what, rt2_status_string(s), rt2_last_error_message());
        printf("%d passed, %d failed\n", passed, failed + 1);
        exit(1);
    }
}

/* Runs after main returns, when this thread's storage is already torn down (as in a C++ static
 * destructor): a failing call must still return its status rather than abort. Silent on
 * success (the summary stays the last line of the output); exits 3 on failure. */
static rt2_context *exit_ctx; /* asked for its properties during exit, then destroyed */
static void call_during_exit(void) {
    rt2_status s = rt2_scene_commit(NULL);
    const char *msg = rt2_last_error_message();
    if (s != RT2_STATUS_INVALID_ARGUMENT || msg == NULL) {
        printf("FAIL rt2_scene_commit(NULL) during exit: %s\n", rt2_status_string(s));
        fflush(stdout);
        _Exit(3);
    }
    fprintf(stderr, "rt2_scene_commit(NULL) during exit: %s, message \"%s\"\n", rt2_status_string(s), msg);
    /* rt2_context_info keeps per-thread copies of its texts, gone by now: still OK, with a note
     * in place of each copy. */
    rt2_context_properties props = {.struct_size = sizeof props};
    s = rt2_context_info(exit_ctx, &props);
    if (s != RT2_STATUS_OK || props.reason == NULL || props.auto_choice == NULL) {
        printf("FAIL rt2_context_info during exit: %s\n", rt2_status_string(s));
        fflush(stdout);
        _Exit(3);
    }
    fprintf(stderr, "rt2_context_info during exit: %s, auto_choice \"%s\"\n", rt2_status_string(s), props.auto_choice);
    rt2_context_destroy(exit_ctx);
}

/* The parts of the statistics that depend only on the scene's content (not on timing). */
static int same_stats(const rt2_scene_statistics *a, const rt2_scene_statistics *b) {
    return a->object_count == b->object_count && a->triangle_count == b->triangle_count &&
           a->sphere_count == b->sphere_count && a->plane_count == b->plane_count && a->box_count == b->box_count &&
           a->ellipsoid_count == b->ellipsoid_count && a->node_count == b->node_count &&
           a->leaf_count == b->leaf_count && a->bytes_primitives == b->bytes_primitives;
}

int main(int argc, char **argv) {
    const char *tmpdir = argc > 1 ? argv[1] : "/tmp";
    atexit(call_during_exit);
    /* A sentinel that no rt2 call returns: outputs must still hold it after a failure. */
    static int sentinel_storage;
    void *const SENTINEL = &sentinel_storage;
    const uint32_t ID_SENTINEL = 0xdeadbeefu;
    const float origin[3] = {0.0f, 0.0f, 0.0f}, white[3] = {1.0f, 1.0f, 1.0f};

    /* ---- An environment variable that is set but unreadable is an error, not ignored ---- */
    {
        const char *saved = getenv("RT2_BACKEND");
        char *copy = saved ? strdup(saved) : NULL;
        setenv("RT2_BACKEND", "\xff\xfe", 1);
        rt2_context *never = NULL;
        expect(rt2_context_create(NULL, &never), RT2_STATUS_INVALID_ARGUMENT, "RT2_BACKEND",
               "rt2_context_create(RT2_BACKEND not UTF-8)");
        report(never == NULL, "  ... *out untouched", NULL);
        if (copy) {
            setenv("RT2_BACKEND", copy, 1);
            free(copy);
        } else {
            unsetenv("RT2_BACKEND");
        }
    }

    /* ---- NULL outputs and handles at creation ---- */
    expect(rt2_context_create(NULL, NULL), RT2_STATUS_INVALID_ARGUMENT, "out", "rt2_context_create(out = NULL)");
    rt2_context *ctx = (rt2_context *)SENTINEL;
    rt2_context_desc desc = rt2_context_desc_default();
    desc.struct_size = 4; /* wrong struct_size */
    expect(rt2_context_create(&desc, &ctx), RT2_STATUS_INVALID_ARGUMENT, "struct_size", "rt2_context_create(wrong struct_size)");
    report(ctx == (rt2_context *)SENTINEL, "  ... *out untouched", NULL);
    desc = rt2_context_desc_default();
    desc.threads = 1025;
    expect(rt2_context_create(&desc, &ctx), RT2_STATUS_INVALID_ARGUMENT, "threads", "rt2_context_create(threads 1025)");
    report(ctx == (rt2_context *)SENTINEL, "  ... *out untouched", NULL);
    desc = rt2_context_desc_default();
    desc.backend = 99; /* unknown enum value */
    expect(rt2_context_create(&desc, &ctx), RT2_STATUS_INVALID_ARGUMENT, "99", "rt2_context_create(backend = 99)");
    report(ctx == (rt2_context *)SENTINEL, "  ... *out untouched", NULL);
    desc = rt2_context_desc_default();
    desc.backend = RT2_BACKEND_CPU;
    must(rt2_context_create(&desc, &ctx), "rt2_context_create");

    rt2_context_properties props;
    memset(&props, 0, sizeof props);
    props.struct_size = 4;
    expect(rt2_context_info(ctx, &props), RT2_STATUS_INVALID_ARGUMENT, "sizeof(rt2_context_properties)",
           "rt2_context_info(wrong struct_size)");
    report(props.reason == NULL && props.fallback == NULL && props.auto_choice == NULL && props.threads == 0,
           "  ... *out untouched", NULL);
    expect(rt2_context_info(NULL, &props), RT2_STATUS_INVALID_ARGUMENT, "ctx", "rt2_context_info(ctx = NULL)");

    rt2_scene *scene = (rt2_scene *)SENTINEL;
    expect(rt2_scene_create(NULL, &scene), RT2_STATUS_INVALID_ARGUMENT, "ctx", "rt2_scene_create(ctx = NULL)");
    report(scene == (rt2_scene *)SENTINEL, "  ... *out untouched", NULL);
    expect(rt2_scene_create(ctx, NULL), RT2_STATUS_INVALID_ARGUMENT, "out", "rt2_scene_create(out = NULL)");
    expect(rt2_camera_create(NULL), RT2_STATUS_INVALID_ARGUMENT, "out", "rt2_camera_create(out = NULL)");
    expect(rt2_frame_create(8, 8, NULL), RT2_STATUS_INVALID_ARGUMENT, "out", "rt2_frame_create(out = NULL)");
    must(rt2_scene_create(ctx, &scene), "rt2_scene_create");

    /* ---- Frames: zero-sized and huge ---- */
    rt2_frame *frame = (rt2_frame *)SENTINEL;
    expect(rt2_frame_create(0, 16, &frame), RT2_STATUS_INVALID_ARGUMENT, NULL, "rt2_frame_create(0 x 16)");
    expect(rt2_frame_create(16, 0, &frame), RT2_STATUS_INVALID_ARGUMENT, NULL, "rt2_frame_create(16 x 0)");
    /* rt2.h: each side must be in 1..=32768. */
    expect(rt2_frame_create(32769, 16, &frame), RT2_STATUS_INVALID_ARGUMENT, NULL, "rt2_frame_create(32769 x 16)");
    expect(rt2_frame_create(UINT32_MAX, UINT32_MAX, &frame), RT2_STATUS_INVALID_ARGUMENT, NULL,
           "rt2_frame_create(4294967295 x 4294967295)");
    report(frame == (rt2_frame *)SENTINEL, "  ... *out untouched", NULL);
    must(rt2_frame_create(16, 12, &frame), "rt2_frame_create");
    uint32_t fw = ID_SENTINEL, fh = ID_SENTINEL;
    expect(rt2_frame_size(frame, NULL, &fh), RT2_STATUS_INVALID_ARGUMENT, "width", "rt2_frame_size(width = NULL)");
    report(fh == ID_SENTINEL, "  ... height untouched", NULL);
    expect(rt2_frame_size(NULL, &fw, &fh), RT2_STATUS_INVALID_ARGUMENT, "frame", "rt2_frame_size(frame = NULL)");
    expect(rt2_frame_set_mask(NULL, NULL), RT2_STATUS_INVALID_ARGUMENT, "frame", "rt2_frame_set_mask(frame = NULL)");
    report(rt2_frame_pixels(NULL) == NULL && rt2_last_error_message()[0] != '\0', "rt2_frame_pixels(NULL) is NULL with a message",
           NULL);
    expect(rt2_frame_save_png(frame, NULL), RT2_STATUS_INVALID_ARGUMENT, "path", "rt2_frame_save_png(path = NULL)");
    {
        char jpg[512], nofolder[512];
        snprintf(jpg, sizeof jpg, "%s/errors-frame.jpg", tmpdir);
        snprintf(nofolder, sizeof nofolder, "%s/no-such-folder/errors-frame.png", tmpdir);
        expect(rt2_frame_save_png(frame, jpg), RT2_STATUS_INVALID_ARGUMENT, ".png", "rt2_frame_save_png(a .jpg name)");
        expect(rt2_frame_save_png(frame, nofolder), RT2_STATUS_IO, "folder", "rt2_frame_save_png(a missing folder)");
        expect(rt2_frame_save_png(frame, tmpdir), RT2_STATUS_INVALID_ARGUMENT, ".png",
               "rt2_frame_save_png(a folder's name, no .png)");
    }

    /* ---- Camera ---- */
    rt2_camera *camera = NULL;
    must(rt2_camera_create(&camera), "rt2_camera_create");
    const float eye[3] = {0.0f, 0.0f, 5.0f}, up_parallel[3] = {0.0f, 0.0f, 1.0f}, nan3[3] = {NAN, 0.0f, 0.0f};
    const float up[3] = {0.0f, 1.0f, 0.0f};
    expect(rt2_camera_look_at(camera, eye, origin, up_parallel), RT2_STATUS_INVALID_ARGUMENT, "up",
           "rt2_camera_look_at(up parallel to the view)");
    expect(rt2_camera_look_at(camera, nan3, origin, up), RT2_STATUS_INVALID_ARGUMENT, "eye", "rt2_camera_look_at(eye NaN)");
    {
        /* Finite but far apart: the view direction overflows to infinity. */
        const float far_eye[3] = {3e38f, 0.0f, 0.0f}, far_target[3] = {-3e38f, 0.0f, 0.0f};
        expect(rt2_camera_look_at(camera, far_eye, far_target, up), RT2_STATUS_INVALID_ARGUMENT, "target",
               "rt2_camera_look_at(eye 3e38, target -3e38)");
    }
    expect(rt2_camera_look_at(NULL, eye, origin, up), RT2_STATUS_INVALID_ARGUMENT, "camera", "rt2_camera_look_at(camera = NULL)");
    expect(rt2_camera_look_at(camera, eye, NULL, up), RT2_STATUS_INVALID_ARGUMENT, "target", "rt2_camera_look_at(target = NULL)");
    expect(rt2_camera_set_fov(camera, 180.0f), RT2_STATUS_INVALID_ARGUMENT, NULL, "rt2_camera_set_fov(180)");
    expect(rt2_camera_set_fov(camera, NAN), RT2_STATUS_INVALID_ARGUMENT, NULL, "rt2_camera_set_fov(NaN)");
    expect(rt2_camera_set_lens(camera, -1.0f, 1.0f), RT2_STATUS_INVALID_ARGUMENT, "aperture", "rt2_camera_set_lens(aperture -1)");

    /* ---- Scene edits: ids continue after failures ---- */
    uint32_t id = ID_SENTINEL, id2 = ID_SENTINEL;
    must(rt2_scene_add_sphere(scene, origin, 1.0f, 0, &id), "rt2_scene_add_sphere");
    const uint32_t first = id;
    id = ID_SENTINEL;
    const float nan_center[3] = {0.0f, NAN, 0.0f};
    expect(rt2_scene_add_sphere(scene, nan_center, 1.0f, 0, &id), RT2_STATUS_INVALID_ARGUMENT, "center",
           "rt2_scene_add_sphere(center NaN)");
    expect(rt2_scene_add_sphere(scene, origin, -1.0f, 0, &id), RT2_STATUS_INVALID_ARGUMENT, "radius",
           "rt2_scene_add_sphere(radius -1)");
    expect(rt2_scene_add_sphere(scene, origin, INFINITY, 0, &id), RT2_STATUS_INVALID_ARGUMENT, "radius",
           "rt2_scene_add_sphere(radius inf)");
    expect(rt2_scene_add_sphere(scene, origin, 1.0f, 77, &id), RT2_STATUS_INVALID_ARGUMENT, "material",
           "rt2_scene_add_sphere(material 77 does not exist)");
    expect(rt2_scene_add_sphere(scene, NULL, 1.0f, 0, &id), RT2_STATUS_INVALID_ARGUMENT, "center",
           "rt2_scene_add_sphere(center = NULL)");
    expect(rt2_scene_add_sphere(NULL, origin, 1.0f, 0, &id), RT2_STATUS_INVALID_ARGUMENT, "scene",
           "rt2_scene_add_sphere(scene = NULL)");
    report(id == ID_SENTINEL, "  ... *out_object untouched by the failures", NULL);

    const float tri[9] = {0, 0, 0, 1, 0, 0, 0, 1, 0};
    const uint32_t bad_idx[3] = {0, 1, 3}; /* 3 is out of range for 3 vertices */
    expect(rt2_scene_add_mesh(scene, tri, 3, bad_idx, 1, 0, &id), RT2_STATUS_INVALID_ARGUMENT, "indices",
           "rt2_scene_add_mesh(index 3 of 3 vertices)");
    const float tri_nan[9] = {0, 0, 0, 1, NAN, 0, 0, 1, 0};
    const uint32_t idx[3] = {0, 1, 2};
    expect(rt2_scene_add_mesh(scene, tri_nan, 3, idx, 1, 0, &id), RT2_STATUS_INVALID_ARGUMENT, "positions[vertex 1][1]",
           "rt2_scene_add_mesh(a NaN coordinate)");
    expect(rt2_scene_add_mesh(scene, NULL, 3, idx, 1, 0, &id), RT2_STATUS_INVALID_ARGUMENT, "positions",
           "rt2_scene_add_mesh(positions = NULL, 3 vertices)");
    expect(rt2_scene_add_mesh(scene, tri, SIZE_MAX, idx, 1, 0, &id), RT2_STATUS_INVALID_ARGUMENT, "vertex_count",
           "rt2_scene_add_mesh(vertex_count SIZE_MAX overflows)");
    const float bmin[3] = {1, 1, 1}, bmax[3] = {0, 2, 2};
    expect(rt2_scene_add_box(scene, bmin, bmax, 0, &id), RT2_STATUS_INVALID_ARGUMENT, "min", "rt2_scene_add_box(min > max)");
    const float zero[3] = {0, 0, 0};
    expect(rt2_scene_add_plane(scene, zero, 0.0f, 0, &id), RT2_STATUS_INVALID_ARGUMENT, "normal",
           "rt2_scene_add_plane(normal 0)");
    const float neg_radii[3] = {1, -1, 1};
    expect(rt2_scene_add_ellipsoid(scene, origin, neg_radii, 0, &id), RT2_STATUS_INVALID_ARGUMENT, "radii",
           "rt2_scene_add_ellipsoid(radius -1)");
    const float black_neg[3] = {1, -0.5f, 1};
    expect(rt2_scene_add_point_light(scene, eye, black_neg, 1.0f, &id), RT2_STATUS_INVALID_ARGUMENT, "rgb",
           "rt2_scene_add_point_light(negative colour)");
    expect(rt2_scene_add_point_light(scene, eye, white, NAN, &id), RT2_STATUS_INVALID_ARGUMENT, "intensity",
           "rt2_scene_add_point_light(intensity NaN)");
    rt2_material mat = rt2_material_default();
    mat.struct_size = 0;
    expect(rt2_scene_add_material(scene, &mat, &id), RT2_STATUS_INVALID_ARGUMENT, "struct_size",
           "rt2_scene_add_material(struct_size 0)");
    mat = rt2_material_default();
    mat.reflectivity = 0.8f;
    mat.transparency = 0.8f; /* sum above 1 */
    expect(rt2_scene_add_material(scene, &mat, &id), RT2_STATUS_INVALID_ARGUMENT, NULL,
           "rt2_scene_add_material(reflectivity + transparency > 1)");
    expect(rt2_scene_add_material(scene, NULL, &id), RT2_STATUS_INVALID_ARGUMENT, "material", "rt2_scene_add_material(NULL)");
    const float ident[12] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0}, singular[12] = {0};
    expect(rt2_scene_set_transform(scene, 5, ident), RT2_STATUS_INVALID_ARGUMENT, "object",
           "rt2_scene_set_transform(object 5 does not exist)");
    expect(rt2_scene_set_enabled(scene, 5, 0), RT2_STATUS_INVALID_ARGUMENT, "object",
           "rt2_scene_set_enabled(object 5 does not exist)");
    expect(rt2_scene_set_transform(scene, first, singular), RT2_STATUS_INVALID_ARGUMENT, "singular",
           "rt2_scene_set_transform(singular matrix)");
    {
        /* Invertible on paper, but its determinant (1e60) overflows float: its inverse is unusable. */
        const float huge_scale[12] = {1e30f, 0, 0, 0, 0, 1e30f, 0, 0, 0, 0, 1, 0};
        expect(rt2_scene_set_transform(scene, first, huge_scale), RT2_STATUS_INVALID_ARGUMENT, "out of range",
               "rt2_scene_set_transform(scales 1e30, 1e30, 1)");
    }
    rt2_build_options bo = rt2_build_options_default();
    bo.builder = 42;
    expect(rt2_scene_set_build_options(scene, &bo), RT2_STATUS_INVALID_ARGUMENT, "42", "rt2_scene_set_build_options(builder 42)");
    bo = rt2_build_options_default();
    bo.struct_size += 4;
    expect(rt2_scene_set_build_options(scene, &bo), RT2_STATUS_INVALID_ARGUMENT, "struct_size",
           "rt2_scene_set_build_options(wrong struct_size)");
    report(id == ID_SENTINEL, "  ... no failed call wrote its id", NULL);
    must(rt2_scene_add_sphere(scene, origin, 0.5f, 0, &id2), "rt2_scene_add_sphere (second)");
    {
        char d[96];
        snprintf(d, sizeof d, "first %u, next %u", first, id2);
        report(id2 == first + 1, "object ids continue after failed adds", d);
    }

    /* ---- Files ---- */
    char missing[512], bad[512];
    snprintf(missing, sizeof missing, "%s/rt2-errors-no-such-file.ply", tmpdir);
    remove(missing);
    expect(rt2_scene_load_file(scene, missing, 0, &id), RT2_STATUS_IO, "rt2-errors-no-such-file.ply",
           "rt2_scene_load_file(missing file)");
    snprintf(bad, sizeof bad, "%s/rt2-errors-malformed.ply", tmpdir);
    FILE *f = fopen(bad, "w");
    if (f == NULL) {
        report(0, "writing the malformed test file", bad);
    } else {
        /* Declares 3 vertices and 1 face, but the second vertex is not a number. */
        fputs("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
              "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 zero 0\n0 1 0\n3 0 1 2\n",
              f);
        fclose(f);
        expect(rt2_scene_load_file(scene, bad, 0, &id), RT2_STATUS_PARSE, "rt2-errors-malformed.ply",
               "rt2_scene_load_file(malformed .ply)");
        remove(bad);
    }
    expect(rt2_scene_load_file(scene, NULL, 0, &id), RT2_STATUS_INVALID_ARGUMENT, "path", "rt2_scene_load_file(path = NULL)");
    report(id == ID_SENTINEL, "  ... *out_object untouched", NULL);

    /* ---- Render and stats before commit ---- */
    rt2_scene_statistics st = {0}, st2 = {0};
    st.struct_size = sizeof st;
    expect(rt2_render(ctx, scene, camera, NULL, frame), RT2_STATUS_INVALID_OPERATION, "commit", "rt2_render before commit");
    expect(rt2_scene_stats(scene, &st), RT2_STATUS_INVALID_OPERATION, "commit", "rt2_scene_stats before commit");
    const float light[3] = {0.0f, 4.0f, 4.0f};
    must(rt2_scene_add_point_light(scene, light, white, 1.0f, NULL), "rt2_scene_add_point_light");
    must(rt2_scene_commit(scene), "rt2_scene_commit");
    expect(rt2_scene_commit(NULL), RT2_STATUS_INVALID_ARGUMENT, "scene", "rt2_scene_commit(NULL)");
    expect(rt2_scene_stats(scene, NULL), RT2_STATUS_INVALID_ARGUMENT, "out", "rt2_scene_stats(out = NULL)");
    st.struct_size = 8;
    /* Output structs have no _default(): the message must say what to set instead. */
    expect(rt2_scene_stats(scene, &st), RT2_STATUS_INVALID_ARGUMENT, "sizeof(rt2_scene_statistics)",
           "rt2_scene_stats(wrong struct_size)");
    report(st.object_count == 0 && st.struct_size == 8, "  ... *out untouched", NULL);
    st.struct_size = sizeof st;
    must(rt2_scene_stats(scene, &st), "rt2_scene_stats");
    {
        char d[96];
        snprintf(d, sizeof d, "%u objects, %u spheres (2 spheres were added successfully)", st.object_count, st.sphere_count);
        report(st.object_count == 2 && st.sphere_count == 2, "stats count only the successful adds", d);
    }

    /* ---- Render options: unknown enums, wrong struct_size, out of range ---- */
    rt2_render_options o = rt2_render_options_default();
    o.traversal = 1000;
    expect(rt2_render(ctx, scene, camera, &o, frame), RT2_STATUS_INVALID_ARGUMENT, "1000", "rt2_render(traversal 1000)");
    o = rt2_render_options_default();
    o.transparency = 7;
    expect(rt2_render(ctx, scene, camera, &o, frame), RT2_STATUS_INVALID_ARGUMENT, "7", "rt2_render(transparency 7)");
    o = rt2_render_options_default();
    o.struct_size = 0;
    expect(rt2_render(ctx, scene, camera, &o, frame), RT2_STATUS_INVALID_ARGUMENT, "struct_size", "rt2_render(struct_size 0)");
    o = rt2_render_options_default();
    o.samples = 0;
    expect(rt2_render(ctx, scene, camera, &o, frame), RT2_STATUS_INVALID_ARGUMENT, "samples", "rt2_render(samples 0)");
    o = rt2_render_options_default();
    o.background[1] = NAN;
    expect(rt2_render(ctx, scene, camera, &o, frame), RT2_STATUS_INVALID_ARGUMENT, "background", "rt2_render(background NaN)");
    {
        /* A caller built against an older header whose options struct was 8 bytes: only those
         * 8 bytes are its own. Under valgrind (scripts/sanitize.sh) reading past them is an
         * error, so the size must be checked before the rest is read. */
        uint32_t *older = malloc(2 * sizeof(uint32_t));
        if (older == NULL) must(RT2_STATUS_OUT_OF_MEMORY, "malloc");
        older[0] = 2 * sizeof(uint32_t);
        older[1] = 1;
        expect(rt2_render(ctx, scene, camera, (const rt2_render_options *)older, frame), RT2_STATUS_INVALID_ARGUMENT,
               "struct_size", "rt2_render(an older header's 8-byte options)");
        expect(rt2_scene_set_build_options(scene, (const rt2_build_options *)older), RT2_STATUS_INVALID_ARGUMENT,
               "struct_size", "rt2_scene_set_build_options(an older header's 8-byte options)");
        expect(rt2_scene_add_material(scene, (const rt2_material *)older, NULL), RT2_STATUS_INVALID_ARGUMENT,
               "struct_size", "rt2_scene_add_material(an older header's 8-byte material)");
        rt2_context *never = NULL;
        expect(rt2_context_create((const rt2_context_desc *)older, &never), RT2_STATUS_INVALID_ARGUMENT,
               "struct_size", "rt2_context_create(an older header's 8-byte descriptor)");
        free(older);
    }
    expect(rt2_render(NULL, scene, camera, NULL, frame), RT2_STATUS_INVALID_ARGUMENT, "ctx", "rt2_render(ctx = NULL)");
    expect(rt2_render(ctx, NULL, camera, NULL, frame), RT2_STATUS_INVALID_ARGUMENT, "scene", "rt2_render(scene = NULL)");
    expect(rt2_render(ctx, scene, NULL, NULL, frame), RT2_STATUS_INVALID_ARGUMENT, "camera", "rt2_render(camera = NULL)");
    expect(rt2_render(ctx, scene, camera, NULL, NULL), RT2_STATUS_INVALID_ARGUMENT, "frame", "rt2_render(frame = NULL)");
    {
        const uint8_t *px = rt2_frame_pixels(frame);
        int untouched = px != NULL;
        for (int i = 0; px && i < 16 * 12 * 4; i++) untouched &= px[i] == 0;
        report(untouched, "failed renders left the frame untouched (transparent black)", NULL);
    }

    {
        /* Refused options (out of range, with the ropes traversal and the watertight test, which
         * build ropes and exact vertices on first use) leave the scene as it was: the options
         * are checked before anything is built. */
        rt2_scene_statistics before = {0}, after = {0};
        before.struct_size = after.struct_size = sizeof before;
        must(rt2_scene_stats(scene, &before), "rt2_scene_stats (before refused options)");
        rt2_render_options bf = rt2_render_options_default();
        bf.traversal = RT2_TRAVERSAL_ROPES;
        bf.intersector = RT2_INTERSECTOR_WATERTIGHT;
        bf.schedule = RT2_SCHEDULE_BREADTH_FIRST;
        bf.samples = 0;
        expect(rt2_render(ctx, scene, camera, &bf, frame), RT2_STATUS_INVALID_ARGUMENT, "samples",
               "rt2_render(breadth-first, watertight, ropes, 0 samples)");
        rt2_query_options q = rt2_query_options_default();
        q.traversal = RT2_TRAVERSAL_ROPES;
        q.intersector = RT2_INTERSECTOR_WATERTIGHT;
        q.mode = RT2_QUERY_MODE_PACKET;
        q.short_stack_size = 33;
        const rt2_ray ray = {{0.0f, 0.0f, 5.0f}, 0.0f, {0.0f, 0.0f, -1.0f}, INFINITY};
        rt2_hit hit;
        expect(rt2_intersect(ctx, scene, &ray, 1, &hit, &q, NULL), RT2_STATUS_INVALID_ARGUMENT,
               "short_stack_size", "rt2_intersect(packets, watertight, ropes, short stack 33)");
        /* So is a query whose ray excludes a primitive the scene lacks: it builds no lookup
         * either. */
        const rt2_hit nowhere = {0.0f, 0.0f, 0.0f, 99u, 0u};
        q.short_stack_size = 3;
        q.intersector = RT2_INTERSECTOR_MOLLER_TRUMBORE;
        q.exclude = &nowhere;
        expect(rt2_intersect(ctx, scene, &ray, 1, &hit, &q, NULL), RT2_STATUS_INVALID_ARGUMENT, "exclude",
               "rt2_intersect(packets, ropes, excluding object 99)");
        must(rt2_scene_stats(scene, &after), "rt2_scene_stats (after refused options)");
        char d[192];
        snprintf(d, sizeof d, "ropes %llu -> %llu bytes, primitives %llu -> %llu bytes, lookup %llu -> %llu bytes",
                 (unsigned long long)before.bytes_ropes, (unsigned long long)after.bytes_ropes,
                 (unsigned long long)before.bytes_primitives, (unsigned long long)after.bytes_primitives,
                 (unsigned long long)before.bytes_prim_lookup, (unsigned long long)after.bytes_prim_lookup);
        report(before.bytes_ropes == after.bytes_ropes && before.bytes_primitives == after.bytes_primitives &&
                   before.bytes_prim_lookup == after.bytes_prim_lookup,
               "  ... the refused calls left the scene's memory unchanged", d);
    }

    /* Failed edits did not invalidate the commit: stats unchanged and rendering works. */
    expect(rt2_scene_add_sphere(scene, origin, -2.0f, 0, &id), RT2_STATUS_INVALID_ARGUMENT, "radius",
           "rt2_scene_add_sphere(radius -2) after commit");
    st2.struct_size = sizeof st2;
    expect(rt2_scene_stats(scene, &st2), RT2_STATUS_OK, NULL, "rt2_scene_stats after a failed edit");
    report(same_stats(&st, &st2), "  ... stats unchanged by the failed edit", NULL);
    expect(rt2_render(ctx, scene, camera, NULL, frame), RT2_STATUS_OK, NULL, "rt2_render after a failed edit");

    /* ---- A successful edit without commit ---- */
    must(rt2_scene_add_sphere(scene, light, 0.1f, 0, &id), "rt2_scene_add_sphere (third)");
    report(id == id2 + 1, "object ids continue after the render", NULL);
    expect(rt2_render(ctx, scene, camera, NULL, frame), RT2_STATUS_INVALID_OPERATION, "commit",
           "rt2_render after an edit without commit");
    expect(rt2_scene_stats(scene, &st2), RT2_STATUS_INVALID_OPERATION, "commit", "rt2_scene_stats after an edit without commit");
    must(rt2_scene_commit(scene), "rt2_scene_commit (again)");
    expect(rt2_render(ctx, scene, camera, NULL, frame), RT2_STATUS_OK, NULL, "rt2_render after commit");
    /* A backend asked for by name never falls back: `fallback` is NULL after a render (rt2.h). */
    props.struct_size = sizeof props;
    props.fallback = (const char *)SENTINEL;
    props.auto_choice = (const char *)SENTINEL;
    expect(rt2_context_info(ctx, &props), RT2_STATUS_OK, NULL, "rt2_context_info after a render");
    report(props.backend != RT2_BACKEND_AUTO && props.reason != NULL && props.fallback == NULL,
           "  ... a backend, a reason, no fallback", props.reason);
    /* The render left the traversal to AUTO (NULL options): `auto_choice` says which and why. */
    int written = props.auto_choice != NULL && props.auto_choice != (const char *)SENTINEL;
    report(written && strstr(props.auto_choice, "traversal standard: ") != NULL, "  ... AUTO's traversal and why",
           written ? props.auto_choice : NULL);

    /* ---- A removed object: gone at the next commit; its id is refused from then on, saying
     * so, and changes nothing; ids are not reused ---- */
    const uint32_t removed = id;
    must(rt2_scene_remove(scene, removed), "rt2_scene_remove (the third sphere)");
    expect(rt2_render(ctx, scene, camera, NULL, frame), RT2_STATUS_INVALID_OPERATION, "commit",
           "rt2_render after a removal without commit");
    must(rt2_scene_commit(scene), "rt2_scene_commit (after the removal)");
    expect(rt2_scene_remove(scene, removed), RT2_STATUS_INVALID_ARGUMENT, "removed", "rt2_scene_remove(removed object)");
    expect(rt2_scene_set_enabled(scene, removed, 1), RT2_STATUS_INVALID_ARGUMENT, "removed",
           "rt2_scene_set_enabled(removed object)");
    expect(rt2_scene_set_transform(scene, removed, ident), RT2_STATUS_INVALID_ARGUMENT, "removed",
           "rt2_scene_set_transform(removed object)");
    {
        const rt2_ray ray = {{0.0f, 0.0f, 5.0f}, 0.0f, {0.0f, 0.0f, -1.0f}, INFINITY};
        const rt2_hit gone = {1.0f, 0.0f, 0.0f, removed, 0u};
        rt2_hit hit = {0.0f, 0.0f, 0.0f, 7u, 7u};
        rt2_query_options q = rt2_query_options_default();
        q.exclude = &gone;
        expect(rt2_intersect(ctx, scene, &ray, 1, &hit, &q, NULL), RT2_STATUS_INVALID_ARGUMENT, "removed",
               "rt2_intersect(excluding a removed object's primitive)");
        rt2_surface surface = {{7.0f, 7.0f, 7.0f}, {7.0f, 7.0f, 7.0f}, 7u};
        expect(rt2_hit_surfaces(scene, &ray, &gone, 1, &surface), RT2_STATUS_INVALID_ARGUMENT, "removed",
               "rt2_hit_surfaces(a hit on a removed object)");
        report(hit.object == 7u && surface.material == 7u, "  ... hit and surface untouched", NULL);
    }
    expect(rt2_scene_remove(scene, 99), RT2_STATUS_INVALID_ARGUMENT, "object", "rt2_scene_remove(object 99 does not exist)");
    expect(rt2_scene_remove(NULL, 0), RT2_STATUS_INVALID_ARGUMENT, "scene", "rt2_scene_remove(NULL)");
    expect(rt2_render(ctx, scene, camera, NULL, frame), RT2_STATUS_OK, NULL, "rt2_render after the refused calls");
    expect(rt2_scene_stats(scene, &st2), RT2_STATUS_OK, NULL, "rt2_scene_stats after the removal");
    report(same_stats(&st, &st2), "  ... the scene is the one before the third sphere was added", NULL);
    must(rt2_scene_add_sphere(scene, light, 0.1f, 0, &id), "rt2_scene_add_sphere (after the removal)");
    report(id == removed + 1, "  ... a new id, not the removed one", NULL);
    must(rt2_scene_commit(scene), "rt2_scene_commit (after the add)");

    /* ---- destroy(NULL) is a no-op; the process survives and later calls still work ---- */
    rt2_context_destroy(NULL);
    rt2_scene_destroy(NULL);
    rt2_camera_destroy(NULL);
    rt2_frame_destroy(NULL);
    report(1, "rt2_*_destroy(NULL) returned", NULL);
    report(strcmp(rt2_status_string(9999), "RT2_STATUS_UNKNOWN") == 0, "rt2_status_string(9999) is RT2_STATUS_UNKNOWN", NULL);

    /* ---- The scene keeps its context alive: destroy the context first, then commit and render
     * the scene (rt2_render takes a context for the work: a second one). ---- */
    rt2_context_destroy(ctx);
    ctx = NULL;
    must(rt2_scene_add_sphere(scene, origin, 0.25f, 0, NULL), "rt2_scene_add_sphere after its context was destroyed");
    expect(rt2_scene_commit(scene), RT2_STATUS_OK, NULL, "rt2_scene_commit after its context was destroyed");
    rt2_context *ctx2 = NULL;
    must(rt2_context_create(NULL, &ctx2), "rt2_context_create (second)");
    expect(rt2_render(ctx2, scene, camera, NULL, frame), RT2_STATUS_OK, NULL, "rt2_render of that scene with a second context");
    {
        const uint8_t *px = rt2_frame_pixels(frame);
        /* The camera's default view: the centre ray hits the sphere at the origin. */
        const uint8_t *c = px ? px + 4 * (6 * 16 + 8) : NULL;
        report(c != NULL && c[3] == 255, "  ... the frame was rendered", NULL);
    }

    rt2_frame_destroy(frame);
    rt2_camera_destroy(camera);
    rt2_scene_destroy(scene);
    /* Asked again from `call_during_exit`: this thread has asked before, so its copies exist. */
    rt2_context_properties props2 = {.struct_size = sizeof props2};
    expect(rt2_context_info(ctx2, &props2), RT2_STATUS_OK, NULL, "rt2_context_info of the second context");
    exit_ctx = ctx2;
    printf("%d passed, %d failed\n", passed, failed);
    return failed == 0 ? 0 : 1;
}
