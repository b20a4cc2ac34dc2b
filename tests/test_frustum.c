/*
 * test_frustum.c — frustum queries must answer exactly like single rays:
 * for every pixel, t, u, v (bit patterns), prim and the any-hit flag of
 * kdr_frustum_trace in MULTI4 and SINGLE mode (and of the SSE2 group code
 * called directly, which AVX2 machines would otherwise never run) equal
 * kdr_intersect1 / kdr_occluded1 of kdr_camera_ray.
 *
 * Scenes: every adversarial kind of the stress generator (shared faces,
 * triangles in split planes, closed meshes, slivers, far offsets, mixed
 * scales, soup) and, with an argument (the ladder directory), the real
 * scenes prepared by scenes/fetch. Cameras: random eyes outside and inside
 * the box, views along the axes (with odd image sizes a pixel column and
 * row have direction components exactly 0, so tiles straddle an axis),
 * eyes exactly on split planes read from the tree (some looking along the
 * plane, so rays lie in it), eyes 10^4 scene sizes away, fields of view
 * from 0.01 to 179.5 degrees. Images of odd sizes with partial tiles,
 * tiles of 4, 5, 8, 16 and 64, traced in chunks of 1..7 tiles so lane sets
 * are partial and ranges disjoint. One scene is also checked directly
 * against Embree (with --caps NAME, its explained classes bounded:
 * tests/support/caps.h); argument errors and the image-size limit too.
 *
 *   test_frustum [--caps NAME] [LADDER_DIR]
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "caps.h"
#include "compare.h"
#include "kd_frustum.h"
#include "kd_internal.h"
#include "kdray.h"
#include "ladder.h"
#include "oracle.h"
#include "stress.h"
#define CHECK_PRINT_MAX 20
#include "check.h"

static long g_pixels;
static stress_rng g_rng;

static float rnd01(void) { return stress_rng_float(&g_rng); }
static float rnd_in(float a, float b) { return a + (b - a) * rnd01(); }

/* ---- one camera ------------------------------------------------------------- */

typedef struct image {
    float *t, *u, *v;
    int32_t *prim;
    uint8_t *hit;
} image;

static void image_alloc(image *im, size_t n) {
    im->t = malloc(n * sizeof *im->t);
    im->u = malloc(n * sizeof *im->u);
    im->v = malloc(n * sizeof *im->v);
    im->prim = malloc(n * sizeof *im->prim);
    im->hit = malloc(n);
    if (!im->t || !im->u || !im->v || !im->prim || !im->hit) {
        fprintf(stderr, "out of memory\n");
        exit(2);
    }
}

static void image_free(image *im) {
    free(im->t);
    free(im->u);
    free(im->v);
    free(im->prim);
    free(im->hit);
}

/* Fills with a pattern no answer has, so unwritten pixels show. */
static void image_poison(image *im, size_t n) {
    memset(im->t, 0xA5, n * sizeof *im->t);
    memset(im->u, 0xA5, n * sizeof *im->u);
    memset(im->v, 0xA5, n * sizeof *im->v);
    memset(im->prim, 0xA5, n * sizeof *im->prim);
    memset(im->hit, 0xA5, n);
}

static void reference(const kdr_scene *s, const kdr_camera *cam, image *ref) {
    for (uint32_t py = 0; py < cam->height; py++) {
        for (uint32_t px = 0; px < cam->width; px++) {
            const size_t i = (size_t)py * cam->width + px;
            kdr_ray ray;
            kdr_hit h;
            kdr_camera_ray(cam, px, py, &ray);
            kdr_intersect1(s, &ray, &h, NULL);
            ref->t[i] = h.t;
            ref->u[i] = h.u;
            ref->v[i] = h.v;
            ref->prim[i] = h.prim;
            ref->hit[i] = (uint8_t)kdr_occluded1(s, &ray, NULL);
        }
    }
}

static int same_bits(float a, float b) { return memcmp(&a, &b, sizeof a) == 0; }

static void compare(const char *what, const kdr_camera *cam, uint32_t tile,
                    int mode, kdr_query q, const image *ref, const image *got) {
    for (size_t i = 0; i < (size_t)cam->width * cam->height; i++) {
        int ok;
        if (q == KDR_ANY)
            ok = ref->hit[i] == got->hit[i];
        else
            ok = ref->prim[i] == got->prim[i] && same_bits(ref->t[i], got->t[i]) &&
                 same_bits(ref->u[i], got->u[i]) && same_bits(ref->v[i], got->v[i]);
        if (!ok) {
            FAIL("%s: %ux%u tile %u mode %d %s pixel (%zu, %zu): "
                 "ref prim %d t %a hit %d, frustum prim %d t %a hit %d\n"
                 "  eye %a %a %a target %a %a %a up %a %a %a fov %a\n",
                 what, cam->width, cam->height, tile, mode,
                 q == KDR_ANY ? "any" : "closest", i % cam->width,
                 i / cam->width, ref->prim[i], ref->t[i], ref->hit[i],
                 got->prim[i], got->t[i], got->hit[i], cam->eye[0], cam->eye[1],
                 cam->eye[2], cam->target[0], cam->target[1], cam->target[2],
                 cam->up[0], cam->up[1], cam->up[2], cam->fov_y_deg);
            return;
        }
    }
}

/* Variants beyond the public modes: the 4-wide (SSE2) group code called
 * directly, so it is tested on AVX2 machines too (lanes 4 and 1). */
#define VARIANT_SSE_MULTI4 10
#define VARIANT_SSE_SINGLE 11

static int trace_range(const kdr_scene *s, const kdr_camera *cam, uint32_t tile,
                       size_t first, size_t n, kdr_query q, int mode,
                       kdr_hits *out) {
    if (mode < VARIANT_SSE_MULTI4)
        return kdr_frustum_trace(s, cam, tile, first, n, q, (kdr_frustum_mode)mode,
                                 out, NULL);
    kd_camera_basis b;
    kd_camera_basis_init(cam, &b);
    return kd_frustum_trace_tiles4(s, cam, &b, tile, first, n, q,
                                   mode == VARIANT_SSE_MULTI4 ? 4 : 1, out, NULL);
}

/* Traces the whole image in chunks of 1..7 tiles. */
static void trace_chunked(const kdr_scene *s, const kdr_camera *cam,
                          uint32_t tile, int mode, kdr_query q, image *got) {
    const size_t ntiles = kdr_frustum_tile_count(cam, tile);
    kdr_hits out = {got->t, got->prim, got->u, got->v, got->hit};
    for (size_t k = 0; k < ntiles;) {
        size_t n = 1 + (size_t)(stress_rng_next(&g_rng) % 7);
        if (n > ntiles - k)
            n = ntiles - k;
        int rc = trace_range(s, cam, tile, k, n, q, mode, &out);
        if (rc != KDR_OK) {
            FAIL("kdr_frustum_trace returned %d\n", rc);
            return;
        }
        k += n;
    }
}

static void check_camera(const char *what, const kdr_scene *s,
                         const kdr_camera *cam) {
    static const uint32_t tiles[] = {4, 5, 8, 16, 64};
    static const int modes[] = {KDR_FRUSTUM_MULTI4, KDR_FRUSTUM_SINGLE,
                                VARIANT_SSE_MULTI4, VARIANT_SSE_SINGLE};
    const size_t n = (size_t)cam->width * cam->height;
    image ref, got;
    if (kdr_camera_validate(cam) != KDR_OK)
        return; /* a random up happened to be parallel: skip */
    image_alloc(&ref, n);
    image_alloc(&got, n);
    reference(s, cam, &ref);
    for (size_t ti = 0; ti < sizeof tiles / sizeof *tiles; ti++) {
        for (int m = 0; m < 4; m++) {
            for (int q = 0; q < 2; q++) {
                image_poison(&got, n);
                trace_chunked(s, cam, tiles[ti], modes[m], (kdr_query)q, &got);
                compare(what, cam, tiles[ti], modes[m], (kdr_query)q, &ref, &got);
            }
        }
    }
    g_pixels += (long)n;
    image_free(&ref);
    image_free(&got);
}

/* ---- cameras ---------------------------------------------------------------- */

static const uint32_t sizes[][2] = {{37, 23}, {16, 16}, {1, 1}, {5, 64},
                                    {64, 5},  {70, 33}, {9, 9},  {23, 41}};

static void random_point(const kdr_bounds *b, float scale, float p[3]) {
    for (int a = 0; a < 3; a++) {
        const float c = 0.5f * (b->min[a] + b->max[a]);
        const float h = 0.5f * (b->max[a] - b->min[a]) * scale;
        p[a] = c + rnd_in(-h, h);
    }
}

static void camera_init(kdr_camera *cam, int k) {
    static const float fovs[] = {60.0f, 30.0f, 90.0f, 2.0f, 150.0f, 45.0f, 179.5f, 0.01f};
    memset(cam, 0, sizeof *cam);
    cam->up[1] = 1.0f;
    cam->fov_y_deg = fovs[k % 8];
    cam->width = sizes[k % 8][0];
    cam->height = sizes[k % 8][1];
}

/* Eye outside the box looking at a random point inside it. */
static void camera_outside(const kdr_bounds *b, int k, kdr_camera *cam) {
    camera_init(cam, k);
    float dir[3];
    stress_rng_dir(&g_rng, dir);
    const float c[3] = {0.5f * (b->min[0] + b->max[0]), 0.5f * (b->min[1] + b->max[1]),
                        0.5f * (b->min[2] + b->max[2])};
    float diag = 0.0f;
    for (int a = 0; a < 3; a++)
        diag = fmaxf(diag, b->max[a] - b->min[a]);
    for (int a = 0; a < 3; a++)
        cam->eye[a] = c[a] + dir[a] * diag * (k % 5 == 4 ? 1e4f : rnd_in(0.8f, 2.0f));
    random_point(b, 0.5f, cam->target);
    stress_rng_dir(&g_rng, cam->up);
}

/* Eye inside the box, random view. */
static void camera_inside(const kdr_bounds *b, int k, kdr_camera *cam) {
    camera_init(cam, k);
    random_point(b, 0.9f, cam->eye);
    random_point(b, 1.0f, cam->target);
    stress_rng_dir(&g_rng, cam->up);
}

/* View along axis k % 3 (either sign), up along the next axis. */
static void camera_axis(const kdr_bounds *b, int k, kdr_camera *cam) {
    const int a = k % 3, s = (k / 3) % 2 ? 1 : -1;
    camera_init(cam, k);
    random_point(b, (k / 6) % 2 ? 0.8f : 2.5f, cam->eye);
    memcpy(cam->target, cam->eye, sizeof cam->eye);
    cam->target[a] += (float)s;
    cam->up[0] = cam->up[1] = cam->up[2] = 0.0f;
    cam->up[(a + 1) % 3] = 1.0f;
}

/* Eye exactly on the split plane of interior node `node`; every other
 * camera looks along the plane (up = the plane's normal). */
static void camera_on_split(const kdr_scene *s, uint32_t node, int k,
                            kdr_camera *cam) {
    const kd_node *n = &s->nodes[node];
    const int a = kd_axis(n);
    kdr_bounds b;
    kdr_scene_bounds(s, &b);
    camera_init(cam, k);
    random_point(&b, 0.9f, cam->eye);
    cam->eye[a] = n->u.split;
    random_point(&b, 1.0f, cam->target);
    if (k % 2) {
        cam->target[a] = n->u.split;
        cam->up[0] = cam->up[1] = cam->up[2] = 0.0f;
        cam->up[a] = 1.0f;
    }
}

static void check_scene(const char *name, const float *tris, size_t ntris,
                        int ncams) {
    kdr_scene *s = NULL;
    kdr_bounds b;
    char what[128];
    if (kdr_scene_build(tris, ntris, NULL, NULL, NULL, &s) != KDR_OK) {
        FAIL("%s: build failed\n", name);
        return;
    }
    kdr_scene_bounds(s, &b);
    const int failures0 = failures;
    for (int k = 0; k < ncams; k++) {
        kdr_camera cam;
        snprintf(what, sizeof what, "%s cam %d", name, k);
        switch (k % 4) {
        case 0: camera_outside(&b, k / 4, &cam); break;
        case 1: camera_inside(&b, k / 4, &cam); break;
        case 2: camera_axis(&b, k / 4, &cam); break;
        default:
            if (s->nnodes == 0 || kd_is_leaf(&s->nodes[0])) {
                camera_inside(&b, k / 4, &cam);
                break;
            }
            /* the root's plane first, then random interior nodes */
            uint32_t node = 0;
            for (int tries = 0; k > 3 && tries < 64; tries++) {
                uint32_t c = (uint32_t)(stress_rng_next(&g_rng) % s->nnodes);
                if (!kd_is_leaf(&s->nodes[c])) {
                    node = c;
                    break;
                }
            }
            camera_on_split(s, node, k / 4, &cam);
        }
        check_camera(what, s, &cam);
    }
    printf("%-24s %7zu tris, %2d cameras: %s\n", name, ntris, ncams,
           failures == failures0 ? "ok" : "MISMATCH");
    kdr_scene_free(s);
}

/* ---- Embree, camera maths, arguments ---------------------------------------- */

/* One scene against Embree directly (equality with Embree otherwise follows
 * from single rays = Embree, tested by the oracle suites). */
static void check_embree(const stress_scene *sc, const char *caps) {
    kdr_scene *s = NULL;
    oracle_opts oo;
    oracle_opts_judge(&oo);
    oracle *o = oracle_create(sc->tris, sc->ntris, &oo);
    kdr_bounds b;
    cmp_tally tally;
    if (!o || kdr_scene_build(sc->tris, sc->ntris, NULL, NULL, NULL, &s) != KDR_OK) {
        FAIL("embree check: set-up failed\n");
        oracle_free(o);
        return;
    }
    kdr_scene_bounds(s, &b);
    cmp_tally_init(&tally);
    for (int k = 0; k < 6; k++) {
        kdr_camera cam;
        image got;
        (k % 2 ? camera_inside : camera_outside)(&b, k, &cam);
        if (kdr_camera_validate(&cam) != KDR_OK)
            continue;
        const size_t n = (size_t)cam.width * cam.height;
        image_alloc(&got, n);
        trace_chunked(s, &cam, 8, KDR_FRUSTUM_MULTI4, KDR_CLOSEST, &got);
        for (size_t i = 0; i < n; i++) {
            kdr_ray ray;
            kdr_hit kd = {got.t[i], got.u[i], got.v[i], got.prim[i]}, em;
            double err = 0.0;
            kdr_camera_ray(&cam, (uint32_t)(i % cam.width), (uint32_t)(i / cam.width), &ray);
            oracle_intersect1(o, &ray, &em);
            cmp_class c = cmp_closest(sc->tris, sc->ntris, &ray, &kd, &em, &err);
            cmp_tally_add(&tally, &ray, c, err, em.prim >= 0);
        }
        image_free(&got);
    }
    cmp_tally_print(stdout, "frustum vs embree", &tally);
    if (caps_check(stdout, caps, "frustum vs embree", &tally) != 0)
        FAIL("frustum vs embree: an explained class over its cap\n");
    if (cmp_tally_unexplained(&tally)) {
        cmp_tally_print_bad(stderr, "frustum vs embree", &tally);
        FAIL("frustum vs embree: unexplained differences\n");
    }
    kdr_scene_free(s);
    oracle_free(o);
}

/* kdr_camera_ray against the API formula evaluated in double. */
static void check_camera_math(void) {
    const kdr_camera cam = {{1, 2, 3}, {4, -2, 7}, {0, 1, 0}, 50.0f, 33, 17};
    double f[3], r[3], u[3], len = 0.0, rl = 0.0;
    for (int a = 0; a < 3; a++) {
        f[a] = (double)cam.target[a] - cam.eye[a];
        len += f[a] * f[a];
    }
    for (int a = 0; a < 3; a++)
        f[a] /= sqrt(len);
    r[0] = f[1] * cam.up[2] - f[2] * cam.up[1];
    r[1] = f[2] * cam.up[0] - f[0] * cam.up[2];
    r[2] = f[0] * cam.up[1] - f[1] * cam.up[0];
    for (int a = 0; a < 3; a++)
        rl += r[a] * r[a];
    for (int a = 0; a < 3; a++)
        r[a] /= sqrt(rl);
    u[0] = r[1] * f[2] - r[2] * f[1];
    u[1] = r[2] * f[0] - r[0] * f[2];
    u[2] = r[0] * f[1] - r[1] * f[0];
    const double h = tan(25.0 * 3.14159265358979323846 / 180.0), asp = 33.0 / 17.0;
    for (uint32_t py = 0; py < cam.height; py += 4) {
        for (uint32_t px = 0; px < cam.width; px += 4) {
            kdr_ray ray;
            kdr_camera_ray(&cam, px, py, &ray);
            const double sx = (2.0 * (px + 0.5) / cam.width - 1.0) * h * asp;
            const double sy = (1.0 - 2.0 * (py + 0.5) / cam.height) * h;
            for (int a = 0; a < 3; a++) {
                const double d = f[a] + sx * r[a] + sy * u[a];
                if (fabs(d - ray.dir[a]) > 1e-6 || ray.org[a] != cam.eye[a])
                    FAIL("camera ray (%u, %u) axis %d: %a vs %a\n", px, py, a,
                         ray.dir[a], d);
            }
            if (ray.tmin != 0.0f || ray.tmax != INFINITY)
                FAIL("camera ray interval [%g, %g]\n", ray.tmin, ray.tmax);
        }
    }
}

static void check_args(const kdr_scene *s) {
    kdr_camera cam = {{0, 0, -5}, {0, 0, 0}, {0, 1, 0}, 60.0f, 20, 10};
    float t[200], u[200], v[200];
    int32_t prim[200];
    uint8_t hit[200];
    kdr_hits out = {t, prim, u, v, hit}, none = {0};
    const size_t nt = kdr_frustum_tile_count(&cam, 8);
    if (nt != 6)
        FAIL("tile count %zu, want 6\n", nt);
    struct {
        uint32_t tile;
        size_t first, count;
        int mode;
        kdr_hits *out;
        int want;
    } cases[] = {
        {8, 0, 6, KDR_FRUSTUM_MULTI4, &out, KDR_OK},
        {8, 6, 0, KDR_FRUSTUM_MULTI4, &out, KDR_OK},
        {3, 0, 1, KDR_FRUSTUM_MULTI4, &out, KDR_EINVAL},
        {65, 0, 1, KDR_FRUSTUM_SINGLE, &out, KDR_EINVAL},
        {8, 5, 2, KDR_FRUSTUM_MULTI4, &out, KDR_EINVAL},
        {8, 7, 0, KDR_FRUSTUM_MULTI4, &out, KDR_EINVAL},
        {8, 0, 1, 3, &out, KDR_EINVAL},
        {8, 0, 1, KDR_FRUSTUM_MULTI4, &none, KDR_EINVAL},
    };
    for (size_t k = 0; k < sizeof cases / sizeof *cases; k++) {
        int rc = kdr_frustum_trace(s, &cam, cases[k].tile, cases[k].first,
                                   cases[k].count, KDR_CLOSEST,
                                   (kdr_frustum_mode)cases[k].mode, cases[k].out, NULL);
        if (rc != cases[k].want)
            FAIL("argument case %zu: got %d want %d\n", k, rc, cases[k].want);
    }
    kdr_camera huge = cam;
    huge.width = huge.height = 65536; /* 2^32 pixels: over the limit */
    if (kdr_frustum_trace(s, &huge, 8, 0, 1, KDR_CLOSEST, KDR_FRUSTUM_MULTI4, &out,
                          NULL) != KDR_ERANGE)
        FAIL("a 2^32-pixel image was accepted\n");
    kdr_camera bad[6];
    for (int k = 0; k < 6; k++)
        bad[k] = cam;
    bad[0].fov_y_deg = 180.0f;
    bad[1].fov_y_deg = 0.0f;
    bad[2].width = 0;
    memcpy(bad[3].target, bad[3].eye, sizeof bad[3].eye);
    bad[4].up[1] = 0.0f;
    bad[4].up[2] = 1.0f; /* parallel to the view */
    bad[5].eye[0] = NAN;
    for (int k = 0; k < 6; k++)
        if (kdr_camera_validate(&bad[k]) != KDR_EINVAL ||
            kdr_frustum_trace(s, &bad[k], 8, 0, 1, KDR_CLOSEST, KDR_FRUSTUM_MULTI4,
                              &out, NULL) != KDR_EINVAL)
            FAIL("bad camera %d accepted\n", k);
}

/* ---- main ------------------------------------------------------------------- */

/* Returns 0 when there is no ladder to check (scenes_fetch did not run:
 * the fixture's own failure reports that). */
static int check_ladder(const char *dir) {
    ladder_entry *e = NULL;
    char err[256];
    const int n = ladder_read(dir, &e, err, sizeof err);
    if (n < 0) {
        printf("ladder: %s\n", err);
        return 0;
    }
    for (int k = 0; k < n; k++) {
        float *tris = NULL;
        size_t ntris = 0;
        if (ladder_load(&e[k], &tris, &ntris, err, sizeof err) != 0) {
            FAIL("ladder %s: %s\n", e[k].name, err);
            continue;
        }
        check_scene(e[k].name, tris, ntris, 12);
        free(tris);
    }
    free(e);
    return 1;
}

int main(int argc, char **argv) {
    const char *caps = caps_arg(&argc, argv);
    stress_rng_seed(&g_rng, 20261123);
    check_camera_math();
    if (argc > 1) {
        if (!check_ladder(argv[1]))
            return 77; /* no ladder: a failure under ctest */
    } else {
        for (int kind = 0; kind < STRESS_NSCENES; kind++) {
            stress_scene sc;
            if (stress_scene_make((stress_scene_kind)kind, 7 + (uint64_t)kind, &sc) != 0) {
                FAIL("stress scene %d: out of memory\n", kind);
                continue;
            }
            check_scene(stress_scene_name((stress_scene_kind)kind), sc.tris,
                        sc.ntris, 48);
            if (kind == STRESS_CLOSED_MESHES) {
                kdr_scene *s = NULL;
                check_embree(&sc, caps);
                if (kdr_scene_build(sc.tris, sc.ntris, NULL, NULL, NULL, &s) == KDR_OK)
                    check_args(s);
                kdr_scene_free(s);
            }
            stress_scene_free(&sc);
        }
        check_scene("empty", NULL, 0, 4);
    }
    printf("%ld pixels compared; %d failures\n", g_pixels, failures);
    return failures ? 1 : 0;
}
