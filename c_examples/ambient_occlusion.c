/* ambient_occlusion.c: the ray query API instead of rt2_render. A ground, a wall, a box and a
 * sphere are shaded by ambient occlusion from the program's own rays:
 *   1. one camera ray per pixel -> rt2_intersect (closest hits);
 *   2. the surface at every hit (point on the surface, geometric normal) -> rt2_hit_surfaces;
 *   3. from every hit, S rays over the hemisphere around the surface normal (cosine-weighted)
 *      -> rt2_occluded, each ray ignoring the primitive it leaves (rt2_query_options.exclude
 *      = the camera hit): no epsilon offset, and no ray hits the triangle it starts on (a
 *      coplanar neighbour still can, near a shared edge: the exclude-prim limit in README.md;
 *      the ground here is one triangle).
 * Both run in each query mode (SINGLE: one ray at a time; PACKET: 4/8/16-ray packets; STREAM:
 * the n-ray traversal, all rays of an octant at once), which must agree bit for bit; the
 * program prints each mode's speed on this scene.
 *
 *   ./ambient_occlusion [OUT.pgm] [SAMPLES]
 *
 * Writes the AO image as a binary PGM (default ambient_occlusion.pgm; sky black, 255 = open),
 * SAMPLES rays per pixel (default 8). Exit codes: 0 success, 1 an rt2 call or a check
 * failed, 2 bad arguments.
 *
 * Checks, each printed with ": ok":
 *  - the three modes return the same hits and the same occlusion flags;
 *  - at points on the ground in front of the wall (height WALL_H, distance d), the occluded
 *    fraction of cosine-weighted rays without a length limit matches the view factor of an
 *    infinitely long wall, (1 - d / sqrt(d^2 + WALL_H^2)) / 2 (the box and the sphere behind
 *    the wall are no taller than it, so no ray from the front reaches them);
 *  - the same rays without the exclusion all report the ground they start on (t = 0 is in
 *    [tmin, tmax) for tmin = 0): what the exclusion is for;
 *  - every pixel showing ground more than AO_RADIUS in front of the wall is exactly 255.
 */
#define _POSIX_C_SOURCE 199309L
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "rt2.h"
#include "vec3.h"

#define W 256
#define H 144
#define L 100.0f       /* the ground and the wall reach this far: "infinite" next to WALL_H */
#define WALL_H 1.0f    /* the wall is the plane x = 0, from y = 0 to WALL_H */
#define AO_RADIUS 1.5f /* length of the image's occlusion rays */
#define PROBE_RAYS 4096

static void check(rt2_status s, const char *what) {
    if (s != RT2_STATUS_OK) {
        fprintf(stderr, "ambient_occlusion: %s failed: %s: %s\n", what, rt2_status_string(s), rt2_last_error_message());
        exit(1);
    }
}

/* Allocates or exits. */
static void *alloc(size_t count, size_t size) {
    /* calloc(0, ...) may return NULL: that is no allocation failure. */
    void *p = calloc(count > 0 ? count : 1, size);
    if (p == NULL) {
        fprintf(stderr, "ambient_occlusion: out of memory\n");
        exit(1);
    }
    return p;
}


static rt2_ray ray(v3 o, v3 d, float tmax) {
    rt2_ray r = {{o.x, o.y, o.z}, 0.0f, {d.x, d.y, d.z}, tmax};
    return r;
}

/* The scene. The ground is one triangle covering [-L, L]^2 (no shared edge for a ray leaving it to hit);
 * behind the wall (x > 0) stand a box of height 0.8 and a sphere of radius 0.5. */
static const float GROUND_POS[] = {-L, 0, -L, 3 * L, 0, -L, -L, 0, 3 * L};
static const uint32_t GROUND_IDX[] = {0, 2, 1};
static const float WALL_POS[] = {0, 0, -L, 0, 0, L, 0, WALL_H, L, 0, WALL_H, -L};
static const uint32_t WALL_IDX[] = {0, 1, 2, 0, 2, 3};
static const float BOX_POS[] = {1.5f, 0, -1.5f, 2.3f, 0, -1.5f, 2.3f, 0.8f, -1.5f, 1.5f, 0.8f, -1.5f,
                                1.5f, 0, -0.7f, 2.3f, 0, -0.7f, 2.3f, 0.8f, -0.7f, 1.5f, 0.8f, -0.7f};
static const uint32_t BOX_IDX[] = {0, 1, 2, 0, 2, 3, 4, 6, 5, 4, 7, 6, 0, 4, 5, 0, 5, 1,
                                   3, 2, 6, 3, 6, 7, 0, 3, 7, 0, 7, 4, 1, 5, 6, 1, 6, 2};
static const float SPHERE_C[3] = {2.0f, 0.5f, 1.0f}, SPHERE_R = 0.5f;

enum { GROUND, WALL, BOX, SPHERE, OBJECTS };
static uint32_t ID[OBJECTS]; /* object ids the library returned */

/* splitmix64: a fixed sequence, so every run (and every mode) traces the same rays. */
static uint64_t rng_state = 0x5eed;
static float uniform(void) {
    uint64_t z = (rng_state += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return (float)((z ^ (z >> 31)) >> 40) / 16777216.0f;
}

/* A cosine-weighted direction around unit n (Malley's method; the basis of Duff et al. 2017). */
static v3 cosine_dir(v3 n) {
    float sign = n.z >= 0 ? 1.0f : -1.0f, a = -1.0f / (sign + n.z), b = n.x * n.y * a;
    v3 t = v(1.0f + sign * n.x * n.x * a, sign * b, -sign * n.x), s = v(b, sign + n.y * n.y * a, -n.y);
    float u1 = uniform(), phi = 6.2831853f * uniform(), r = sqrtf(u1);
    return norm(add(add(mul(t, r * cosf(phi)), mul(s, r * sinf(phi))), mul(n, sqrtf(1.0f - u1))));
}

static double now(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return ts.tv_sec + 1e-9 * ts.tv_nsec;
}

static int failures = 0;
static void report(int ok, const char *what) {
    printf("%s: %s\n", what, ok ? "ok" : "FAILED");
    failures += !ok;
}

static const uint32_t MODES[3] = {RT2_QUERY_MODE_SINGLE, RT2_QUERY_MODE_PACKET, RT2_QUERY_MODE_STREAM};
static const char *MODE_NAMES[3] = {"single", "packet", "stream"};

/* The occlusion flags of `rays` (each ignoring exclude[i], or nothing when exclude is NULL) in
 * every mode; returns mode SINGLE's flags and reports whether the modes agree. */
static uint8_t *occluded_all_modes(const rt2_context *ctx, const rt2_scene *scene, const rt2_ray *rays, size_t n,
                                   const rt2_hit *exclude, const char *what) {
    uint8_t *flags[3];
    int same = 1;
    for (int m = 0; m < 3; m++) {
        rt2_query_options q = rt2_query_options_default();
        q.mode = MODES[m];
        q.exclude = exclude;
        flags[m] = alloc(n, 1);
        double t0 = now();
        check(rt2_occluded(ctx, scene, rays, n, flags[m], &q, NULL), "rt2_occluded");
        printf("  %-20s %-6s %8.2f Mrays/s\n", what, MODE_NAMES[m], n / (now() - t0) / 1e6);
        if (m > 0) {
            same &= memcmp(flags[0], flags[m], n) == 0;
            free(flags[m]);
        }
    }
    char line[128];
    snprintf(line, sizeof line, "%s: the three modes agree", what);
    report(same, line);
    return flags[0];
}

int main(int argc, char **argv) {
    if (argc > 3) {
        fprintf(stderr, "usage: %s [OUT.pgm] [SAMPLES]\n", argv[0]);
        return 2;
    }
    const char *out_path = argc > 1 ? argv[1] : "ambient_occlusion.pgm";
    char *end = NULL;
    long parsed = argc > 2 ? strtol(argv[2], &end, 10) : 8;
    if ((argc > 2 && (end == argv[2] || *end != '\0')) || parsed < 1 || parsed > 4096) {
        fprintf(stderr, "ambient_occlusion: SAMPLES must be 1..4096\n");
        return 2;
    }
    const int samples = (int)parsed;

    /* A CPU context: the query modes PACKET and STREAM are CPU traversals. (RT2_BACKEND=gpu
     * overrides it; the GPU kernels take the exclusions too, one ray per thread in every mode.) */
    rt2_context_desc desc = rt2_context_desc_default();
    desc.backend = RT2_BACKEND_CPU;
    rt2_context *ctx = NULL;
    rt2_scene *scene = NULL;
    check(rt2_context_create(&desc, &ctx), "rt2_context_create");
    check(rt2_scene_create(ctx, &scene), "rt2_scene_create");
    check(rt2_scene_add_mesh(scene, GROUND_POS, 3, GROUND_IDX, 1, 0, &ID[GROUND]), "rt2_scene_add_mesh (ground)");
    check(rt2_scene_add_mesh(scene, WALL_POS, 4, WALL_IDX, 2, 0, &ID[WALL]), "rt2_scene_add_mesh (wall)");
    check(rt2_scene_add_mesh(scene, BOX_POS, 8, BOX_IDX, 12, 0, &ID[BOX]), "rt2_scene_add_mesh (box)");
    check(rt2_scene_add_sphere(scene, SPHERE_C, SPHERE_R, 0, &ID[SPHERE]), "rt2_scene_add_sphere");
    check(rt2_scene_commit(scene), "rt2_scene_commit");

    /* Probes: points on the ground in front of the wall, PROBE_RAYS unlimited rays each. */
    const float distances[4] = {0.25f, 0.5f, 1.0f, 2.0f};
    rt2_ray *probe = alloc(PROBE_RAYS, sizeof *probe);
    rt2_hit *ground = alloc(PROBE_RAYS, sizeof *ground);
    for (int k = 0; k < 4; k++) {
        float d = distances[k];
        for (int i = 0; i < PROBE_RAYS; i++) {
            probe[i] = ray(v(-d, 0.0f, 0.37f), cosine_dir(v(0, 1, 0)), INFINITY);
            rt2_hit h = {0.0f, 0.0f, 0.0f, ID[GROUND], 0};
            ground[i] = h;
        }
        char what[64];
        snprintf(what, sizeof what, "probe d=%.2f", d);
        uint8_t *occ = occluded_all_modes(ctx, scene, probe, PROBE_RAYS, ground, what);
        int hit = 0;
        for (int i = 0; i < PROBE_RAYS; i++) hit += occ[i];
        double want = 0.5 * (1.0 - d / sqrt((double)d * d + (double)WALL_H * WALL_H));
        double got = (double)hit / PROBE_RAYS, sigma = sqrt(want * (1.0 - want) / PROBE_RAYS);
        char line[160];
        snprintf(line, sizeof line, "%s: occluded %.4f, view factor %.4f (4 sigma = %.4f)", what, got, want, 4 * sigma);
        report(fabs(got - want) <= 4 * sigma + 1e-3, line);
        free(occ);
        if (k == 0) {
            uint8_t *self = occluded_all_modes(ctx, scene, probe, PROBE_RAYS, NULL, "probe, no exclusion");
            int n = 0;
            for (int i = 0; i < PROBE_RAYS; i++) n += self[i];
            snprintf(line, sizeof line, "without the exclusion %d of %d rays hit the ground they leave", n, PROBE_RAYS);
            report(n == PROBE_RAYS, line);
            free(self);
        }
    }
    free(probe);
    free(ground);

    /* The image: camera rays, then `samples` occlusion rays from every hit. */
    const v3 eye = v(-3.0f, 3.5f, 4.0f), target = v(1.2f, 0.2f, -0.2f);
    const v3 f = norm(sub(target, eye)), r = norm(cross(f, v(0, 1, 0))), u = cross(r, f);
    const float half_h = tanf(25.0f * 3.14159265f / 180.0f), half_w = half_h * W / H;
    rt2_ray *cam = alloc(W * H, sizeof *cam);
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++) {
            float nx = 2.0f * (x + 0.5f) / W - 1.0f, ny = 1.0f - 2.0f * (y + 0.5f) / H;
            cam[y * W + x] = ray(eye, norm(add(f, add(mul(r, nx * half_w), mul(u, ny * half_h)))), INFINITY);
        }
    rt2_hit *hits[3];
    int same = 1;
    for (int m = 0; m < 3; m++) {
        rt2_query_options q = rt2_query_options_default();
        q.mode = MODES[m];
        hits[m] = alloc(W * H, sizeof(rt2_hit));
        double t0 = now();
        check(rt2_intersect(ctx, scene, cam, W * H, hits[m], &q, NULL), "rt2_intersect");
        printf("  %-20s %-6s %8.2f Mrays/s\n", "camera rays", MODE_NAMES[m], W * H / (now() - t0) / 1e6);
        same &= m == 0 || memcmp(hits[0], hits[m], W * H * sizeof(rt2_hit)) == 0;
    }
    report(same, "camera rays: the three modes agree");

    /* Where each camera ray hit and which way the surface faces there (outward, or the side
     * of the triangle's winding: turned towards the camera below). */
    rt2_surface *surf = alloc(W * H, sizeof *surf);
    check(rt2_hit_surfaces(scene, cam, hits[0], W * H, surf), "rt2_hit_surfaces");
    size_t n_ao = 0;
    for (int p = 0; p < W * H; p++) n_ao += hits[0][p].object != RT2_INVALID_ID;
    n_ao *= samples;
    rt2_ray *ao = alloc(n_ao, sizeof *ao);
    rt2_hit *leaves = alloc(n_ao, sizeof *leaves);
    size_t k = 0;
    for (int p = 0; p < W * H; p++) {
        const rt2_hit *h = &hits[0][p];
        if (h->object == RT2_INVALID_ID) continue;
        v3 pos = at(surf[p].position), n = at(surf[p].normal);
        if (dot(n, at(cam[p].dir)) > 0) n = mul(n, -1.0f);
        for (int s = 0; s < samples; s++, k++) {
            ao[k] = ray(pos, cosine_dir(n), AO_RADIUS);
            leaves[k] = *h;
        }
    }
    uint8_t *occ = occluded_all_modes(ctx, scene, ao, n_ao, leaves, "occlusion rays");

    /* The image, and the open ground: hits on the ground more than AO_RADIUS before the wall. */
    uint8_t *image = alloc(W * H, 1);
    int open = 0, open_exact = 0;
    k = 0;
    for (int p = 0; p < W * H; p++) {
        const rt2_hit *h = &hits[0][p];
        if (h->object == RT2_INVALID_ID) continue;
        int visible = 0;
        for (int s = 0; s < samples; s++, k++) visible += !occ[k];
        image[p] = (uint8_t)((255 * visible + samples / 2) / samples);
        float x = surf[p].position[0];
        if (h->object == ID[GROUND] && x < -AO_RADIUS - 0.01f) {
            open++;
            open_exact += visible == samples;
        }
    }
    char line[128];
    snprintf(line, sizeof line, "open ground: %d of %d pixels unoccluded", open_exact, open);
    report(open > W * H / 10 && open_exact == open, line);

    FILE *out = fopen(out_path, "wb");
    int written = out != NULL && fprintf(out, "P5\n%d %d\n255\n", W, H) > 0 && fwrite(image, 1, W * H, out) == W * H;
    if (out == NULL || fclose(out) != 0 || !written) {
        fprintf(stderr, "ambient_occlusion: cannot write %s\n", out_path);
        failures++;
    } else {
        printf("wrote %s (%dx%d, %d rays per pixel)\n", out_path, W, H, samples);
    }

    free(image);
    free(occ);
    free(leaves);
    free(ao);
    free(surf);
    for (int m = 0; m < 3; m++) free(hits[m]);
    free(cam);
    rt2_scene_destroy(scene);
    rt2_context_destroy(ctx);
    if (failures == 0) printf("ambient_occlusion: OK\n");
    return failures == 0 ? 0 : 1;
}
