/* spheres.c: a few spheres on a checkered plane, one of them a mirror, two lights; renders
 * 640x360 and saves a PNG (argv[1], default spheres.png).
 *
 * The checks recompute what some pixels must show from the scene description alone: the
 * primary ray through the pixel centre (pinhole camera, vertical field of view, aspect from
 * the frame), analytic sphere hits, Phong shading with hard shadows from point lights
 * without distance falloff (as rt2.h documents) and the mirror term of the material. Exits 1
 * if any pixel disagrees, or any call fails.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>

#include "rt2.h"
#include "vec3.h"

#define W 640
#define H 360
/* 8-bit tolerance: 8-bit rounding (0.5), float differences (<0.5), and up to a half-pixel
 * difference in where the library places its ray inside the pixel, which at the chosen pixels
 * (sphere centres, 1 pixel = 0.016 scene units at distance 7) changes n.l by < 1%, i.e. < 3/255. */
#define TOL 6

static void check(rt2_status s, const char *what) {
    if (s != RT2_STATUS_OK) {
        fprintf(stderr, "spheres: %s failed: %s: %s\n", what, rt2_status_string(s), rt2_last_error_message());
        exit(1);
    }
}


typedef struct { v3 center; float radius; rt2_material m; uint32_t material_id; } sphere;

static const v3 EYE = {0.0f, 2.0f, 7.0f}, TARGET = {0.0f, 0.75f, 0.0f}, UP = {0.0f, 1.0f, 0.0f};
static const float FOV_Y = 45.0f;
static const float BACKGROUND[3] = {0.2f, 0.3f, 0.5f};
static const v3 LIGHT_POS[2] = {{5.0f, 8.0f, 5.0f}, {-6.0f, 5.0f, 4.0f}};
static const float LIGHT_INTENSITY[2] = {0.6f, 0.35f};

#define NS 4
static sphere S[NS];

/* Nearest sphere hit along o + t d (d unit) with t in (tmin, tmax); -1 if none. */
static int hit_sphere(v3 o, v3 d, float tmin, float tmax, float *t_out) {
    int best = -1;
    for (int i = 0; i < NS; i++) {
        v3 oc = sub(o, S[i].center);
        float b = dot(oc, d), c = dot(oc, oc) - S[i].radius * S[i].radius, disc = b * b - c;
        if (disc < 0.0f) continue;
        float q = sqrtf(disc);
        float t = -b - q > tmin ? -b - q : -b + q;
        if (t > tmin && t < tmax) { tmax = t; best = i; }
    }
    *t_out = tmax;
    return best;
}

/* Primary ray through the centre of pixel (px, py), y down from the top-left. */
static v3 primary_dir(int px, int py) {
    v3 f = norm(sub(TARGET, EYE)), r = norm(cross(f, UP)), u = cross(r, f);
    float half_h = tanf(FOV_Y * 0.5f * 3.14159265f / 180.0f), half_w = half_h * (float)W / (float)H;
    float nx = 2.0f * ((float)px + 0.5f) / W - 1.0f, ny = 1.0f - 2.0f * ((float)py + 0.5f) / H;
    return norm(add(f, add(mul(r, nx * half_w), mul(u, ny * half_h))));
}

/* Pixel position of a world point (the inverse of primary_dir). */
static void project(v3 p, int *px, int *py) {
    v3 f = norm(sub(TARGET, EYE)), r = norm(cross(f, UP)), u = cross(r, f), d = sub(p, EYE);
    float half_h = tanf(FOV_Y * 0.5f * 3.14159265f / 180.0f), half_w = half_h * (float)W / (float)H;
    float z = dot(d, f);
    *px = (int)floorf((dot(d, r) / (z * half_w) + 1.0f) * 0.5f * W);
    *py = (int)floorf((1.0f - dot(d, u) / (z * half_h)) * 0.5f * H);
}

/* Reference colour of a ray that hits sphere `i` first; rays leaving the scene get the
 * background. `ok` is cleared if the path meets the plane, whose checker colour this reference
 * does not model (the chosen pixels avoid that). */
static v3 shade(v3 o, v3 d, int depth, int *ok) {
    float t;
    int i = hit_sphere(o, d, 1e-4f, INFINITY, &t);
    if (i < 0) {
        if (d.y < 0.0f) *ok = 0; /* would hit the plane y = 0 */
        return v(BACKGROUND[0], BACKGROUND[1], BACKGROUND[2]);
    }
    const rt2_material *m = &S[i].m;
    v3 p = add(o, mul(d, t)), n = norm(sub(p, S[i].center)), base = v(m->color[0], m->color[1], m->color[2]);
    v3 local = mul(base, m->ambient);
    for (int l = 0; l < 2; l++) {
        v3 to = sub(LIGHT_POS[l], p);
        float dist = sqrtf(dot(to, to)), ts;
        v3 ld = mul(to, 1.0f / dist);
        float ndotl = dot(n, ld);
        if (ndotl <= 0.0f || hit_sphere(p, ld, 1e-3f, dist, &ts) >= 0) continue;
        v3 refl = sub(mul(n, 2.0f * dot(ld, n)), ld);
        float spec = powf(fmaxf(dot(refl, mul(d, -1.0f)), 0.0f), m->shininess);
        local = add(local, mul(add(mul(base, m->diffuse * ndotl), v(m->specular * spec, m->specular * spec, m->specular * spec)),
                               LIGHT_INTENSITY[l]));
    }
    v3 c = mul(local, 1.0f - m->reflectivity);
    if (m->reflectivity > 0.0f && depth < 6) {
        v3 rd = sub(d, mul(n, 2.0f * dot(d, n)));
        c = add(c, mul(shade(p, rd, depth + 1, ok), m->reflectivity));
    }
    return c;
}

static int failures = 0;

static int to8(float c) { return (int)(fminf(fmaxf(c, 0.0f), 1.0f) * 255.0f + 0.5f); }

static void expect_pixel(const uint8_t *pixels, int px, int py, v3 want, const char *what) {
    const uint8_t *p = pixels + 4 * ((size_t)py * W + px);
    int w[3] = {to8(want.x), to8(want.y), to8(want.z)};
    int good = 1;
    for (int k = 0; k < 3; k++) good &= abs((int)p[k] - w[k]) <= TOL;
    printf("%-34s pixel (%3d,%3d) = %3u %3u %3u, expected %3d %3d %3d (+-%d): %s\n", what, px, py, p[0], p[1], p[2],
           w[0], w[1], w[2], TOL, good ? "ok" : "WRONG");
    failures += !good;
}

int main(int argc, char **argv) {
    const char *out_path = argc > 1 ? argv[1] : "spheres.png";
    rt2_context *ctx = NULL;
    rt2_scene *scene = NULL;
    rt2_camera *camera = NULL;
    rt2_frame *frame = NULL;
    check(rt2_context_create(NULL, &ctx), "rt2_context_create");
    check(rt2_scene_create(ctx, &scene), "rt2_scene_create");

    const float colors[NS][3] = {{0.9f, 0.15f, 0.1f}, {0.1f, 0.8f, 0.2f}, {0.95f, 0.95f, 0.95f}, {0.15f, 0.25f, 0.9f}};
    const v3 centers[NS] = {{-1.8f, 0.75f, 0.0f}, {1.8f, 0.75f, 0.0f}, {0.0f, 1.0f, -1.5f}, {0.4f, 0.4f, 1.6f}};
    const float radii[NS] = {0.75f, 0.75f, 1.0f, 0.4f};
    for (int i = 0; i < NS; i++) {
        S[i].center = centers[i];
        S[i].radius = radii[i];
        S[i].m = rt2_material_default();
        for (int k = 0; k < 3; k++) S[i].m.color[k] = colors[i][k];
        S[i].m.ambient = 0.1f;
        S[i].m.diffuse = 0.8f;
        S[i].m.specular = 0.4f;
        S[i].m.shininess = 40.0f;
        S[i].m.reflectivity = i == 2 ? 0.8f : 0.0f; /* sphere 2 is the mirror */
        check(rt2_scene_add_material(scene, &S[i].m, &S[i].material_id), "rt2_scene_add_material");
        const float c[3] = {centers[i].x, centers[i].y, centers[i].z};
        check(rt2_scene_add_sphere(scene, c, radii[i], S[i].material_id, NULL), "rt2_scene_add_sphere");
    }
    rt2_material floor_m = rt2_material_default();
    floor_m.checker = 1;
    floor_m.color[0] = floor_m.color[1] = floor_m.color[2] = 0.9f;
    floor_m.checker_color[0] = floor_m.checker_color[1] = floor_m.checker_color[2] = 0.2f;
    floor_m.checker_scale = 1.0f;
    uint32_t floor_id = 0;
    check(rt2_scene_add_material(scene, &floor_m, &floor_id), "rt2_scene_add_material (floor)");
    const float up[3] = {0.0f, 1.0f, 0.0f};
    check(rt2_scene_add_plane(scene, up, 0.0f, floor_id, NULL), "rt2_scene_add_plane");
    for (int l = 0; l < 2; l++) {
        const float pos[3] = {LIGHT_POS[l].x, LIGHT_POS[l].y, LIGHT_POS[l].z}, white[3] = {1.0f, 1.0f, 1.0f};
        check(rt2_scene_add_point_light(scene, pos, white, LIGHT_INTENSITY[l], NULL), "rt2_scene_add_point_light");
    }
    check(rt2_scene_commit(scene), "rt2_scene_commit");

    check(rt2_camera_create(&camera), "rt2_camera_create");
    const float eye[3] = {EYE.x, EYE.y, EYE.z}, target[3] = {TARGET.x, TARGET.y, TARGET.z};
    check(rt2_camera_look_at(camera, eye, target, up), "rt2_camera_look_at");
    check(rt2_camera_set_fov(camera, FOV_Y), "rt2_camera_set_fov");
    check(rt2_frame_create(W, H, &frame), "rt2_frame_create");
    rt2_render_options options = rt2_render_options_default();
    for (int k = 0; k < 3; k++) options.background[k] = BACKGROUND[k];
    check(rt2_render(ctx, scene, camera, &options, frame), "rt2_render");
    check(rt2_frame_save_png(frame, out_path), "rt2_frame_save_png");
    printf("spheres: wrote %s (%dx%d)\n", out_path, W, H);

    const uint8_t *pixels = rt2_frame_pixels(frame);
    if (pixels == NULL) {
        fprintf(stderr, "spheres: rt2_frame_pixels failed: %s\n", rt2_last_error_message());
        return 1;
    }
    /* Each sphere at the pixel where its centre projects: the ray there must hit that sphere. */
    const char *names[NS] = {"red sphere (centre)", "green sphere (centre)", "mirror sphere (centre)", "blue sphere (centre)"};
    for (int i = 0; i < NS; i++) {
        int px, py, ok = 1;
        float t;
        project(S[i].center, &px, &py);
        v3 d = primary_dir(px, py);
        if (hit_sphere(EYE, d, 0.0f, INFINITY, &t) != i) {
            printf("%s: hidden by another sphere at (%d,%d), not checked\n", names[i], px, py);
            continue;
        }
        v3 want = shade(EYE, d, 1, &ok);
        if (ok) expect_pixel(pixels, px, py, want, names[i]);
    }
    /* Top-left corner: the camera's top row looks above the horizon (pitch down 10.1 deg, half
     * the field of view 22.5 deg), so that ray meets neither the plane nor a sphere. */
    {
        float t;
        v3 d = primary_dir(0, 0);
        if (d.y <= 0.0f || hit_sphere(EYE, d, 0.0f, INFINITY, &t) >= 0) {
            printf("scene set-up error: the top-left ray hits something\n");
            failures++;
        } else {
            expect_pixel(pixels, 0, 0, v(BACKGROUND[0], BACKGROUND[1], BACKGROUND[2]), "sky (top-left corner)");
        }
    }
    /* Bottom centre: the ray hits the plane in front of the spheres; it is lit (not sky). */
    {
        const uint8_t *p = pixels + 4 * ((size_t)(H - 1) * W + W / 2);
        int sky = abs(p[0] - to8(BACKGROUND[0])) <= TOL && abs(p[1] - to8(BACKGROUND[1])) <= TOL &&
                  abs(p[2] - to8(BACKGROUND[2])) <= TOL;
        printf("%-34s pixel (%3d,%3d) = %3u %3u %3u, must not be the sky: %s\n", "floor (bottom centre)", W / 2, H - 1, p[0],
               p[1], p[2], sky ? "WRONG" : "ok");
        failures += sky;
    }

    rt2_frame_destroy(frame);
    rt2_camera_destroy(camera);
    rt2_scene_destroy(scene);
    rt2_context_destroy(ctx);
    if (failures) {
        fprintf(stderr, "spheres: %d pixel checks failed\n", failures);
        return 1;
    }
    printf("spheres: OK\n");
    return 0;
}
