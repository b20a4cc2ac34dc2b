/*
 * bench_harness.c — the driver and helpers of bench.h. Scenes come from the
 * ladder (tests/support/ladder.h), so benchmarks and accuracy tests run on
 * exactly the same files; the kd-tree is built once per scene and shared by
 * all sections.
 */
#define _POSIX_C_SOURCE 200809L
#include "bench.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "ladder.h"
#include "stress.h"

#define MAX_SELECT 16

struct bench_csv {
    FILE *f;
};

double bench_now_ms(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec * 1e3 + (double)ts.tv_nsec * 1e-6;
}

double bench_cpu_ms(void) {
    struct timespec ts;
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
    return (double)ts.tv_sec * 1e3 + (double)ts.tv_nsec * 1e-6;
}

/* ---- rays ------------------------------------------------------------------ */

size_t bench_camera_rays(const kdr_scene *kd, size_t n, kdr_camera *cam,
                         kdr_ray *out) {
    kdr_bounds b;
    kdr_scene_bounds(kd, &b);
    const float diag = kdr_scene_diagonal(kd);
    static const float view[3] = {0.55f, 0.35f, 0.75f}; /* |view| ~ 1 */
    uint32_t side = (uint32_t)sqrt((double)n);
    if (side == 0)
        side = 1;
    memset(cam, 0, sizeof *cam);
    cam->up[1] = 1.0f;
    cam->fov_y_deg = 45.0f;
    cam->width = cam->height = side;
    for (int k = 0; k < 3; k++) {
        cam->target[k] = 0.5f * (b.min[k] + b.max[k]);
        cam->eye[k] = cam->target[k] + 1.1f * diag * view[k];
    }
    size_t i = 0;
    for (uint32_t y = 0; y < side && i < n; y++)
        for (uint32_t x = 0; x < side && i < n; x++)
            kdr_camera_ray(cam, x, y, &out[i++]);
    return i;
}

void bench_random_rays(const kdr_scene *kd, uint64_t seed, size_t n,
                       kdr_ray *out) {
    kdr_bounds b;
    kdr_scene_bounds(kd, &b);
    stress_rng r;
    stress_rng_seed(&r, seed);
    for (size_t i = 0; i < n; i++) {
        for (int k = 0; k < 3; k++)
            out[i].org[k] = b.min[k] + (b.max[k] - b.min[k]) * stress_rng_float(&r);
        stress_rng_dir(&r, out[i].dir);
        out[i].tmin = 0.0f;
        out[i].tmax = INFINITY;
    }
}

/* A point on triangle tri with its unit geometric normal. */
static void surface_point(const float *tri, stress_rng *r, float p[3],
                          float nrm[3]) {
    float a = stress_rng_float(r), c = stress_rng_float(r);
    if (a + c > 1.0f) {
        a = 1.0f - a;
        c = 1.0f - c;
    }
    float e1[3], e2[3];
    for (int k = 0; k < 3; k++) {
        e1[k] = tri[3 + k] - tri[k];
        e2[k] = tri[6 + k] - tri[k];
        p[k] = tri[k] + a * e1[k] + c * e2[k];
    }
    nrm[0] = e1[1] * e2[2] - e1[2] * e2[1];
    nrm[1] = e1[2] * e2[0] - e1[0] * e2[2];
    nrm[2] = e1[0] * e2[1] - e1[1] * e2[0];
    const float len = sqrtf(nrm[0] * nrm[0] + nrm[1] * nrm[1] + nrm[2] * nrm[2]);
    for (int k = 0; k < 3; k++)
        nrm[k] = len > 0 ? nrm[k] / len : (k == 1);
}

void bench_ao_rays(const kdr_scene *kd, uint64_t seed, size_t n,
                   size_t per_point, kdr_ray *out) {
    const size_t ntris = kdr_scene_triangle_count(kd);
    const float reach = 0.1f * kdr_scene_diagonal(kd);
    stress_rng r;
    stress_rng_seed(&r, seed);
    float p[3] = {0, 0, 0}, nrm[3] = {0, 1, 0};
    for (size_t i = 0; i < n; i++) {
        if (i % (per_point ? per_point : 1) == 0 && ntris)
            surface_point(kdr_scene_triangle(kd, stress_rng_next(&r) % ntris),
                          &r, p, nrm);
        float d[3];
        stress_rng_dir(&r, d);
        const float s = d[0] * nrm[0] + d[1] * nrm[1] + d[2] * nrm[2];
        for (int k = 0; k < 3; k++) {
            out[i].org[k] = p[k];
            out[i].dir[k] = s < 0 ? -d[k] : d[k];
        }
        out[i].tmin = 1e-4f * reach;
        out[i].tmax = reach;
    }
}

/* ---- tracing ----------------------------------------------------------------- */

static void embree_pass(RTCScene sc, const kdr_ray *rays, size_t n, int any,
                        size_t *hits) {
    struct RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    size_t h = 0;
    for (size_t i = 0; i < n; i++) {
        struct RTCRayHit rh;
        rh.ray.org_x = rays[i].org[0];
        rh.ray.org_y = rays[i].org[1];
        rh.ray.org_z = rays[i].org[2];
        rh.ray.dir_x = rays[i].dir[0];
        rh.ray.dir_y = rays[i].dir[1];
        rh.ray.dir_z = rays[i].dir[2];
        rh.ray.tnear = rays[i].tmin;
        rh.ray.tfar = rays[i].tmax;
        rh.ray.time = 0.0f;
        rh.ray.mask = 0xFFFFFFFFu;
        rh.ray.id = 0;
        rh.ray.flags = 0;
        if (any) {
            rtcOccluded1(sc, &ctx, &rh.ray);
            h += rh.ray.tfar == -INFINITY;
        } else {
            rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
            rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
            rtcIntersect1(sc, &ctx, &rh);
            h += rh.hit.geomID != RTC_INVALID_GEOMETRY_ID;
        }
    }
    *hits = h;
}

static void kd_pass(const kdr_scene *kd, const kdr_ray *rays, size_t n,
                    int any, size_t *hits) {
    size_t h = 0;
    for (size_t i = 0; i < n; i++) {
        if (any) {
            h += (size_t)kdr_occluded1(kd, &rays[i], NULL);
        } else {
            kdr_hit hit;
            h += (size_t)kdr_intersect1(kd, &rays[i], &hit, NULL);
        }
    }
    *hits = h;
}

double bench_embree_mrays(RTCScene sc, const kdr_ray *rays, size_t n, int any,
                          int repeat, size_t *hits) {
    double best = INFINITY;
    size_t h = 0;
    for (int r = 0; r < (repeat > 0 ? repeat : 1); r++) {
        const double t0 = bench_cpu_ms();
        embree_pass(sc, rays, n, any, &h);
        best = fmin(best, bench_cpu_ms() - t0);
    }
    if (hits)
        *hits = h;
    return best > 0 ? (double)n / (best * 1e3) : 0.0;
}

double bench_kd_mrays(const kdr_scene *kd, const kdr_ray *rays, size_t n,
                      int any, int repeat, size_t *hits) {
    double best = INFINITY;
    size_t h = 0;
    for (int r = 0; r < (repeat > 0 ? repeat : 1); r++) {
        const double t0 = bench_cpu_ms();
        kd_pass(kd, rays, n, any, &h);
        best = fmin(best, bench_cpu_ms() - t0);
    }
    if (hits)
        *hits = h;
    return best > 0 ? (double)n / (best * 1e3) : 0.0;
}

/* ---- CSV ---------------------------------------------------------------------- */

void bench_csv_row(bench_csv *csv, const char *section,
                   const bench_scene *scene, const char *metric, double value) {
    if (!csv || !csv->f)
        return;
    fprintf(csv->f, "%s,%s,%zu,%s,%.6g\n", section, scene->name, scene->ntris,
            metric, value);
    fflush(csv->f);
}

/* ---- driver --------------------------------------------------------------------- */

typedef struct driver {
    const char *dir, *csv_path;
    size_t max_tris;
    const char *only[MAX_SELECT], *sections[MAX_SELECT];
    int nonly, nsections;
    bench_opts opts;
} driver;

static int selected(const char *const *list, int n, const char *name) {
    if (n == 0)
        return 1;
    for (int i = 0; i < n; i++)
        if (strcmp(list[i], name) == 0)
            return 1;
    return 0;
}

static int parse_flags(int argc, char **argv, driver *d) {
    d->dir = ladder_default_dir();
    d->max_tris = (size_t)-1;
    d->opts.rays = BENCH_DEFAULT_RAYS;
    d->opts.repeat = BENCH_DEFAULT_REPEAT;
    for (int i = 1; i < argc; i++) {
        const char *f = argv[i], *v = i + 1 < argc ? argv[i + 1] : NULL;
        if (!v)
            return -1;
        if (strcmp(f, "--dir") == 0)
            d->dir = v;
        else if (strcmp(f, "--csv") == 0)
            d->csv_path = v;
        else if (strcmp(f, "--rays") == 0)
            d->opts.rays = strtoul(v, NULL, 10);
        else if (strcmp(f, "--repeat") == 0)
            d->opts.repeat = atoi(v);
        else if (strcmp(f, "--max-tris") == 0)
            d->max_tris = strtoul(v, NULL, 10);
        else if (strcmp(f, "--only") == 0 && d->nonly < MAX_SELECT)
            d->only[d->nonly++] = v;
        else if (strcmp(f, "--section") == 0 && d->nsections < MAX_SELECT)
            d->sections[d->nsections++] = v;
        else
            return -1;
        i++;
    }
    return d->opts.rays > 0 ? 0 : -1;
}

static int run_scene(const driver *d, const ladder_entry *e,
                     const bench_section *sections, size_t nsections,
                     bench_csv *csv) {
    char err[512];
    float *tris;
    size_t ntris;
    if (ladder_load(e, &tris, &ntris, err, sizeof err) != 0) {
        fprintf(stderr, "%s\n", err);
        return -1;
    }
    kdr_scene *kd;
    const double t0 = bench_cpu_ms();
    const int rc = kdr_scene_build(tris, ntris, NULL, NULL, NULL, &kd);
    const double build_ms = bench_cpu_ms() - t0;
    if (rc != KDR_OK) {
        fprintf(stderr, "%s: kdr_scene_build: %s\n", e->name, kdr_strerror(rc));
        free(tris);
        return -1;
    }
    const bench_scene s = {e->name, tris, ntris, kd, build_ms};
    int fail = 0;
    for (size_t i = 0; i < nsections; i++)
        if (selected(d->sections, d->nsections, sections[i].name))
            fail |= sections[i].run(&s, &d->opts, csv) != 0;
    kdr_scene_free(kd);
    free(tris);
    return fail ? -1 : 0;
}

int bench_main(int argc, char **argv, const bench_section *sections,
               size_t nsections) {
    driver d;
    memset(&d, 0, sizeof d);
    if (parse_flags(argc, argv, &d) != 0) {
        fprintf(stderr, "usage: %s [--dir DIR] [--rays N] [--max-tris N] "
                        "[--only SCENE]... [--repeat R] [--csv PATH] "
                        "[--section NAME]...\n", argv[0]);
        return 2;
    }
    ladder_entry *v;
    char err[512];
    const int n = ladder_read(d.dir, &v, err, sizeof err);
    if (n < 0) {
        fprintf(stderr, "%s\n", err);
        return 1;
    }
    bench_csv csv = {NULL};
    if (d.csv_path && !(csv.f = fopen(d.csv_path, "w"))) {
        fprintf(stderr, "%s: cannot write\n", d.csv_path);
        free(v);
        return 1;
    }
    if (csv.f)
        fprintf(csv.f, "section,scene,triangles,metric,value\n");
    int fail = 0;
    for (int i = 0; i < n; i++)
        if (v[i].triangles <= d.max_tris &&
            selected(d.only, d.nonly, v[i].name))
            fail |= run_scene(&d, &v[i], sections, nsections, &csv) != 0;
    if (csv.f)
        fclose(csv.f);
    free(v);
    return fail;
}
