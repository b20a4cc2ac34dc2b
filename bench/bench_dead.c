/*
 * bench_dead.c — kdray-bench-dead: what rays that cannot hit cost in
 * kdr_trace_batch (docs/TRAVERSAL.md, "Rays that cannot be traced"). Not a test.
 *
 *   kdray-bench-dead [--set NAME] [--rays N] [--tris N] [--repeat R]
 *
 * A soup of small triangles in [-1, 1]^3 and N rays (default 65536) of one
 * set, traced closest-hit in ONE kdr_trace_batch call (AUTO mode), R times;
 * prints the thread CPU time per ray (best of R) and the misses (exit 1
 * when a ray of the first four sets hits). Sets:
 *   interval  bench_service's "transport only" row: one origin, random
 *             directions, tmin 1 > tmax 0 shared by all (stride 0)
 *   perray    the same with per-ray tmin 1 > tmax 0 and per-ray origins
 *   away      valid rays from outside the box pointing away from it
 *   nan       a NaN direction component per ray
 *   camera    live rays: one origin, a pinhole camera's directions
 *   random    live rays: per-ray origins in the box, random directions
 * Without --set it runs them all. For repeatable instruction counts:
 *   valgrind --tool=callgrind --toggle-collect=kdr_trace_batch \
 *       kdray-bench-dead --set interval --repeat 1
 * (the scene build and the ray set-up are not counted).
 */
#define _POSIX_C_SOURCE 200809L
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "kdray.h"

static uint64_t g_rng = 0x9E3779B97F4A7C15ull;
static float rnd01(void) {
    g_rng ^= g_rng << 13, g_rng ^= g_rng >> 7, g_rng ^= g_rng << 17;
    return (float)(g_rng >> 40) * 0x1p-24f;
}
static float rnd_in(float a, float b) { return a + (b - a) * rnd01(); }

static double cpu_s(void) {
    struct timespec ts;
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

static const char *const set_names[] = {"interval", "perray", "away",
                                        "nan",      "camera", "random"};
#define NSETS (sizeof set_names / sizeof set_names[0])

typedef struct rays {
    size_t n;
    float *org, *dir, *tmin, *tmax;
    kdr_ray_batch b;
} rays;

static void rnd_dir(float d[3]) {
    const float z = rnd_in(-1.0f, 1.0f), ph = rnd_in(0.0f, 6.2831853f);
    const float r = sqrtf(1.0f - z * z);
    d[0] = r * cosf(ph), d[1] = r * sinf(ph), d[2] = z;
}

static rays make_rays(int set, size_t n) {
    rays r = {n,
              malloc(3 * n * sizeof(float)),
              malloc(3 * n * sizeof(float)),
              malloc(n * sizeof(float)),
              malloc(n * sizeof(float)),
              {0}};
    size_t org_stride = 3, t_stride = 1;
    for (size_t i = 0; i < n; i++) {
        float *o = r.org + 3 * i, *d = r.dir + 3 * i;
        r.tmin[i] = 0.0f, r.tmax[i] = INFINITY;
        for (int k = 0; k < 3; k++)
            o[k] = rnd_in(-1.0f, 1.0f);
        rnd_dir(d);
        switch (set) {
        case 0: /* interval: shared origin and interval */
            r.tmin[i] = 1.0f, r.tmax[i] = 0.0f;
            break;
        case 1:
            r.tmin[i] = 1.0f, r.tmax[i] = 0.0f;
            break;
        case 2: /* outside on a random axis, moving away on it */
        {
            const int k = (int)(rnd01() * 2.999f);
            const float s = rnd01() < 0.5f ? -1.0f : 1.0f;
            o[k] = s * rnd_in(1.5f, 3.0f);
            d[k] = s * (0.2f + fabsf(d[k]));
            break;
        }
        case 3:
            d[(int)(rnd01() * 2.999f)] = NAN;
            break;
        case 4: /* camera at (0, 0, 3) looking down -z, 256 x n/256 */
        {
            const float x = (float)(i % 256) / 128.0f - 1.0f;
            const float y = (float)(i / 256) / (float)(n / 256) * 2.0f - 1.0f;
            o[0] = 0.0f, o[1] = 0.0f, o[2] = 3.0f;
            d[0] = 0.5f * x, d[1] = 0.5f * y, d[2] = -1.0f;
            break;
        }
        default:
            break;
        }
    }
    if (set == 0 || set == 4) org_stride = 0;
    if (set == 0) t_stride = 0;
    r.b =
        (kdr_ray_batch){n, r.org, org_stride, r.dir, r.tmin, t_stride, r.tmax, t_stride};
    return r;
}

int main(int argc, char **argv) {
    size_t nrays = 65536, ntris = 36000;
    int repeat = 5, only = -1;
    for (int i = 1; i + 1 < argc; i += 2) {
        if (strcmp(argv[i], "--rays") == 0)
            nrays = strtoul(argv[i + 1], NULL, 10);
        else if (strcmp(argv[i], "--tris") == 0)
            ntris = strtoul(argv[i + 1], NULL, 10);
        else if (strcmp(argv[i], "--repeat") == 0)
            repeat = atoi(argv[i + 1]);
        else if (strcmp(argv[i], "--set") == 0) {
            only = 0;
            while ((size_t)only < NSETS && strcmp(set_names[only], argv[i + 1]) != 0)
                only++;
            if ((size_t)only == NSETS) only = -2;
        } else
            only = -2;
    }
    if (argc % 2 == 0 || only == -2 || nrays < 256 || ntris == 0 || repeat < 1) {
        fprintf(stderr,
                "usage: %s [--set interval|perray|away|nan|camera|random] "
                "[--rays N] [--tris N] [--repeat R]\n",
                argv[0]);
        return 2;
    }
    float *tris = malloc(ntris * 9 * sizeof(float));
    for (size_t i = 0; i < ntris; i++) {
        float c[3];
        for (int k = 0; k < 3; k++)
            c[k] = rnd_in(-1.0f, 1.0f);
        for (int j = 0; j < 9; j++)
            tris[9 * i + j] = c[j % 3] + rnd_in(-0.03f, 0.03f);
    }
    kdr_scene *s = NULL;
    if (kdr_scene_build(tris, ntris, NULL, NULL, NULL, &s) != KDR_OK) {
        fprintf(stderr, "scene build failed\n");
        return 1;
    }
    float *t = malloc(nrays * 4), *u = malloc(nrays * 4), *v = malloc(nrays * 4);
    int32_t *prim = malloc(nrays * 4);
    uint8_t *hit = malloc(nrays);
    kdr_hits h = {t, prim, u, v, hit};
    printf("%zu triangles, %zu rays per call, best of %d\n", ntris, nrays, repeat);
    int fail = 0;
    for (size_t set = 0; set < NSETS; set++) {
        if (only >= 0 && (size_t)only != set) continue;
        rays r = make_rays((int)set, nrays);
        double best = INFINITY;
        for (int k = 0; k < repeat; k++) {
            const double t0 = cpu_s();
            kdr_trace_batch(s, &r.b, 0, nrays, KDR_CLOSEST, KDR_TRAV_AUTO, &h, NULL);
            const double dt = cpu_s() - t0;
            best = dt < best ? dt : best;
        }
        size_t miss = 0;
        for (size_t i = 0; i < nrays; i++)
            miss += prim[i] < 0;
        printf("%-9s %8.1f ns/ray  %zu of %zu miss\n", set_names[set],
               1e9 * best / (double)nrays, miss, nrays);
        if (set < 4 && miss != nrays) { /* the first four cannot hit */
            fprintf(stderr, "FAIL: %s: %zu rays hit\n", set_names[set], nrays - miss);
            fail = 1;
        }
        free(r.org), free(r.dir), free(r.tmin), free(r.tmax);
    }
    kdr_scene_free(s);
    free(tris), free(t), free(u), free(v), free(prim), free(hit);
    return fail;
}
