/* load_model.c: loads a .ply/.obj model, prints its triangle count and kd-tree statistics
 * (rt2_scene_stats), renders it to a PNG and prints where the render ran (rt2_context_info).
 *
 *   ./load_model MODEL [OUT.png] [cx cy cz size]
 *
 * MODEL e.g. ../../shared/models/bunny.ply; OUT.png defaults to model.png. The camera looks
 * at (cx, cy, cz) from the +z side, far enough that a cube of edge `size` fills about half the
 * image height; the defaults frame the Stanford bunny (bounding box from shared/models/README.md).
 * Exit codes: 0 success, 1 an rt2 call failed, 2 bad arguments or the model file is missing.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>

#include "rt2.h"

#define W 200
#define H 150

static void check(rt2_status s, const char *what) {
    if (s != RT2_STATUS_OK) {
        fprintf(stderr, "load_model: %s failed: %s: %s\n", what, rt2_status_string(s), rt2_last_error_message());
        exit(1);
    }
}

int main(int argc, char **argv) {
    if (argc < 2 || (argc > 3 && argc != 7)) {
        fprintf(stderr, "usage: %s MODEL.ply|MODEL.obj [OUT.png] [cx cy cz size]\n", argv[0]);
        return 2;
    }
    const char *model = argv[1], *out_path = argc > 2 ? argv[2] : "model.png";
    /* Bunny bounding box [-0.0947, 0.0330, -0.0619]..[0.0610, 0.1873, 0.0588]: centre and edge. */
    float center[3] = {-0.0168f, 0.1102f, -0.0015f}, size = 0.156f;
    if (argc == 7) {
        float v[4];
        for (int k = 0; k < 4; k++) {
            char *end = NULL;
            v[k] = strtof(argv[3 + k], &end);
            if (end == argv[3 + k] || *end != '\0' || !isfinite(v[k])) {
                fprintf(stderr, "load_model: '%s' is not a finite number\n", argv[3 + k]);
                return 2;
            }
        }
        if (!(v[3] > 0.0f)) {
            fprintf(stderr, "load_model: size must be positive, not %s\n", argv[6]);
            return 2;
        }
        for (int k = 0; k < 3; k++) center[k] = v[k];
        size = v[3];
    }
    FILE *f = fopen(model, "rb");
    if (f == NULL) {
        fprintf(stderr, "load_model: model file %s is missing or unreadable\n", model);
        return 2;
    }
    fclose(f);

    rt2_context *ctx = NULL;
    rt2_scene *scene = NULL;
    rt2_camera *camera = NULL;
    rt2_frame *frame = NULL;
    check(rt2_context_create(NULL, &ctx), "rt2_context_create");
    check(rt2_scene_create(ctx, &scene), "rt2_scene_create");
    uint32_t object = 0;
    check(rt2_scene_load_file(scene, model, 0, &object), "rt2_scene_load_file");
    /* Key light above-right-front of the model, fill light from the left. */
    const float key[3] = {center[0] + 2.0f * size, center[1] + 3.0f * size, center[2] + 4.0f * size};
    const float fill[3] = {center[0] - 4.0f * size, center[1] + size, center[2] + 2.0f * size};
    const float white[3] = {1.0f, 1.0f, 1.0f};
    check(rt2_scene_add_point_light(scene, key, white, 0.8f, NULL), "rt2_scene_add_point_light (key)");
    check(rt2_scene_add_point_light(scene, fill, white, 0.3f, NULL), "rt2_scene_add_point_light (fill)");
    check(rt2_scene_commit(scene), "rt2_scene_commit");

    rt2_scene_statistics st = {0};
    st.struct_size = sizeof st;
    check(rt2_scene_stats(scene, &st), "rt2_scene_stats");
    printf("model: %s\n", model);
    printf("triangles: %u\n", st.triangle_count);
    printf("kd-tree: %u nodes, %u leaves (%u empty), max depth %u, avg leaf depth %.2f, "
           "avg prims/leaf %.2f, SAH cost %.2f\n",
           st.node_count, st.leaf_count, st.empty_leaf_count, st.max_depth, st.avg_leaf_depth, st.avg_prims_per_leaf,
           st.sah_cost);
    printf("memory: nodes %llu B, leaf lists %llu B, primitives %llu B\n", (unsigned long long)st.bytes_nodes,
           (unsigned long long)st.bytes_leaf_lists, (unsigned long long)st.bytes_primitives);
    printf("times: build %.2f ms, commit %.2f ms\n", st.build_ms, st.commit_ms);
    if (st.triangle_count == 0) {
        fprintf(stderr, "load_model: %s has no triangles\n", model);
        return 1;
    }

    /* 45 deg vertical field of view: at distance D the image is 2 D tan(22.5 deg) = 0.83 D
     * high, so D = 2.4 size shows a model of height `size` over about half the image. */
    const float fov = 45.0f, dist = 2.4f * size;
    const float eye[3] = {center[0], center[1], center[2] + dist}, up[3] = {0.0f, 1.0f, 0.0f};
    check(rt2_camera_create(&camera), "rt2_camera_create");
    check(rt2_camera_look_at(camera, eye, center, up), "rt2_camera_look_at");
    check(rt2_camera_set_fov(camera, fov), "rt2_camera_set_fov");
    check(rt2_frame_create(W, H, &frame), "rt2_frame_create");
    rt2_render_options options = rt2_render_options_default();
    options.background[0] = 0.0f;
    options.background[1] = 0.0f;
    options.background[2] = 0.0f;
    check(rt2_render(ctx, scene, camera, &options, frame), "rt2_render");
    /* Where the render ran and why: an AUTO context on a GPU runs a model too large for the
     * device's buffers on the CPU and says so in `fallback`. */
    rt2_context_properties props = {0};
    props.struct_size = sizeof props;
    check(rt2_context_info(ctx, &props), "rt2_context_info");
    printf("backend: %s (%s)\n", props.backend == RT2_BACKEND_GPU ? "GPU" : "CPU", props.reason);
    if (props.fallback != NULL) printf("this render ran on the CPU: %s\n", props.fallback);
    check(rt2_frame_save_png(frame, out_path), "rt2_frame_save_png");

    /* Count pixels that are not the black background: the model must show. */
    const uint8_t *px = rt2_frame_pixels(frame);
    if (px == NULL) {
        fprintf(stderr, "load_model: rt2_frame_pixels failed: %s\n", rt2_last_error_message());
        return 1;
    }
    size_t lit = 0;
    for (size_t i = 0; i < (size_t)W * H; i++) lit += (px[4 * i] | px[4 * i + 1] | px[4 * i + 2]) != 0;
    printf("wrote %s (%dx%d), %zu of %d pixels show the model\n", out_path, W, H, lit, W * H);

    rt2_frame_destroy(frame);
    rt2_camera_destroy(camera);
    rt2_scene_destroy(scene);
    rt2_context_destroy(ctx);
    if (lit == 0) {
        fprintf(stderr, "load_model: the render shows nothing but background\n");
        return 1;
    }
    printf("load_model: OK\n");
    return 0;
}
