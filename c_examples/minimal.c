/* Build (from c_examples/, after `cargo build --release` in the repository root):
 *   cc -std=c99 -Wall -Wextra -I../include minimal.c -o minimal -L../target/release -lrt2 -Wl,-rpath,"$PWD/../target/release"
 * Run: ./minimal
 *
 * The first rung of the ladder: one triangle seen by the default camera, rendered at 64x48.
 * Prints the colour of the centre pixel and exits non-zero unless the triangle is there.
 */
#include <stdio.h>
#include <stdlib.h>

#include "rt2.h"

/* Prints the failed call with the library's status name and message, then exits 1. */
static void check(rt2_status s, const char *what) {
    if (s != RT2_STATUS_OK) {
        fprintf(stderr, "minimal: %s failed: %s: %s\n", what, rt2_status_string(s), rt2_last_error_message());
        exit(1);
    }
}

int main(void) {
    rt2_context *ctx = NULL;
    rt2_scene *scene = NULL;
    rt2_camera *camera = NULL;
    rt2_frame *frame = NULL;
    check(rt2_context_create(NULL, &ctx), "rt2_context_create");
    check(rt2_scene_create(ctx, &scene), "rt2_scene_create");

    /* A triangle around the origin in the z = 0 plane, facing the default camera at (0,0,5). */
    const float positions[] = {-1.0f, -1.0f, 0.0f, 1.0f, -1.0f, 0.0f, 0.0f, 1.0f, 0.0f};
    const uint32_t indices[] = {0, 1, 2};
    uint32_t object = 0;
    check(rt2_scene_add_mesh(scene, positions, 3, indices, 1, 0, &object), "rt2_scene_add_mesh");
    /* A white light at the camera, so the triangle's face is lit head-on. */
    const float light_pos[3] = {0.0f, 0.0f, 5.0f}, white[3] = {1.0f, 1.0f, 1.0f};
    check(rt2_scene_add_point_light(scene, light_pos, white, 1.0f, NULL), "rt2_scene_add_point_light");
    check(rt2_scene_commit(scene), "rt2_scene_commit");

    check(rt2_camera_create(&camera), "rt2_camera_create"); /* defaults: eye (0,0,5), looking at the origin */
    const uint32_t width = 64, height = 48;
    check(rt2_frame_create(width, height, &frame), "rt2_frame_create");

    /* A pure blue background: the default material is grey, so its red channel tells them apart. */
    rt2_render_options options = rt2_render_options_default();
    options.background[0] = 0.0f;
    options.background[1] = 0.0f;
    options.background[2] = 1.0f;
    check(rt2_render(ctx, scene, camera, &options, frame), "rt2_render");

    const uint8_t *pixels = rt2_frame_pixels(frame);
    if (pixels == NULL) {
        fprintf(stderr, "minimal: rt2_frame_pixels returned NULL: %s\n", rt2_last_error_message());
        return 1;
    }
    const uint8_t *c = pixels + 4 * ((size_t)(height / 2) * width + width / 2);
    printf("centre pixel (%u, %u): r=%u g=%u b=%u a=%u\n", width / 2, height / 2, c[0], c[1], c[2], c[3]);

    /* The centre ray hits the triangle (it contains the origin), so the pixel is grey, not blue. */
    int ok = c[0] > 0 && c[0] == c[1] && c[3] == 255;
    if (!ok) {
        fprintf(stderr, "minimal: the centre pixel is not the lit grey triangle (background is 0,0,255)\n");
    }
    rt2_frame_destroy(frame);
    rt2_camera_destroy(camera);
    rt2_scene_destroy(scene);
    rt2_context_destroy(ctx);
    if (ok) {
        printf("minimal: OK\n");
    }
    return ok ? 0 : 1;
}
