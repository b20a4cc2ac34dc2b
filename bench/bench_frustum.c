/*
 * bench_frustum.c — single-threaded throughput of full-frame primary rays:
 * per-ray kd traversal, 4-wide omni-directional bundles (shared origin,
 * pixels in 2x2 blocks), single-frustum and four-frustum traversal (ray
 * groups of 4x2 with AVX2, else 2x2), and
 * Embree 3 rtcIntersect1 / rtcIntersect8 (coherent context, 4x2 pixel
 * packets), all on the same camera rays in the same run. Prints Mrays/s,
 * nodes visited per ray (kd), a tile-size sweep of both frustum modes, and
 * the ratios the task asks for (4-frustum / single-frustum, 4-frustum /
 * Embree rtcIntersect1), as geometric means over the cameras.
 *
 * Times are the calling thread's CPU time (CLOCK_THREAD_CPUTIME_ID), so
 * other processes sharing the cores do not skew the ratios.
 *
 * Embree's scene is built like the test oracle's (RTC_SCENE_FLAG_ROBUST,
 * high quality) and, for the record, also without ROBUST; FTZ/DAZ off for
 * both sides.
 *
 * Usage: kdray_bench_frustum [bench.h flags: --dir, --rays N (pixels per
 *   frame, default 1000000 → 1000x1000), --only SCENE, --repeat R, --csv]
 *   over the scene ladder (bench.h).
 */
#define _POSIX_C_SOURCE 200809L
#include <embree3/rtcore.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "bench.h"
#include "kdray.h"
#include "oracle.h"

/* Workload tuning, in one place. */
#define DEFAULT_TILE 8

static int g_repeat = BENCH_DEFAULT_REPEAT; /* best of; set from bench.h --repeat */
#define NCAMS 3

static double now_s(void) {
    struct timespec ts;
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
    return (double)ts.tv_sec + (double)ts.tv_nsec * 1e-9;
}

typedef struct frame {
    const kdr_scene *s;
    const kdr_camera *cam;
    size_t n;
    float *t, *u, *v, *dirs;
    int32_t *prim;
} frame;

typedef struct result {
    double mrays;
    double nodes_per_ray;
    double tris_per_ray;
    double hit_checksum; /* sum of prims + 1, to compare methods */
} result;

static double checksum(const frame *f) {
    double c = 0.0;
    for (size_t i = 0; i < f->n; i++)
        c += f->prim[i] + 1;
    return c;
}

/* ---- kd methods ------------------------------------------------------------- */

static result run_frustum(frame *f, uint32_t tile, kdr_frustum_mode mode) {
    kdr_hits out = {f->t, f->prim, f->u, f->v, NULL};
    result r = {0, 0, 0, 0};
    double best = 1e30;
    for (int rep = 0; rep < g_repeat; rep++) {
        kdr_trav_stats st = {0};
        const double t0 = now_s();
        kdr_frustum_trace(f->s, f->cam, tile, 0, kdr_frustum_tile_count(f->cam, tile),
                          KDR_CLOSEST, mode, &out, &st);
        const double dt = now_s() - t0;
        if (dt < best)
            best = dt;
        r.nodes_per_ray = (double)st.nodes_visited / (double)f->n;
        r.tris_per_ray = (double)st.tri_tests / (double)f->n;
    }
    r.mrays = (double)f->n / best * 1e-6;
    r.hit_checksum = checksum(f);
    return r;
}

/* Directions in 2x2 pixel blocks (row-major blocks), so each bundle of 4 is
 * a compact screen square; results land in block order (checksum only). */
static void block_dirs(frame *f, uint32_t bw, uint32_t bh) {
    size_t k = 0;
    for (uint32_t by = 0; by < f->cam->height; by += bh)
        for (uint32_t bx = 0; bx < f->cam->width; bx += bw)
            for (uint32_t j = 0; j < bw * bh; j++) {
                kdr_ray ray;
                kdr_camera_ray(f->cam, bx + j % bw, by + j / bw, &ray);
                memcpy(&f->dirs[3 * k++], ray.dir, sizeof ray.dir);
            }
}

static result run_bundle(frame *f, kdr_trav_mode mode) {
    const float tmin = 0.0f, tmax = INFINITY;
    const kdr_ray_batch b = {f->n, f->cam->eye, 0, f->dirs, &tmin, 0, &tmax, 0};
    kdr_hits out = {f->t, f->prim, f->u, f->v, NULL};
    result r = {0, 0, 0, 0};
    double best = 1e30;
    for (int rep = 0; rep < g_repeat; rep++) {
        kdr_trav_stats st = {0};
        const double t0 = now_s();
        kdr_trace_batch(f->s, &b, 0, f->n, KDR_CLOSEST, mode, &out, &st);
        const double dt = now_s() - t0;
        if (dt < best)
            best = dt;
        r.nodes_per_ray = (double)st.nodes_visited / (double)f->n;
        r.tris_per_ray = (double)st.tri_tests / (double)f->n;
    }
    r.mrays = (double)f->n / best * 1e-6;
    r.hit_checksum = checksum(f);
    return r;
}

/* ---- Embree ----------------------------------------------------------------- */

static result run_embree1(frame *f, RTCScene scene) {
    struct RTCIntersectContext ctx;
    result r = {0, 0, 0, 0};
    double best = 1e30;
    for (int rep = 0; rep < g_repeat; rep++) {
        const double t0 = now_s();
        rtcInitIntersectContext(&ctx);
        ctx.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
        for (size_t i = 0; i < f->n; i++) {
            struct RTCRayHit rh;
            const float *d = &f->dirs[3 * i];
            rh.ray = (struct RTCRay){f->cam->eye[0], f->cam->eye[1], f->cam->eye[2], 0.0f,
                                     d[0], d[1], d[2], 0.0f, INFINITY, (unsigned)-1,
                                     (unsigned)i, 0};
            rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
            rtcIntersect1(scene, &ctx, &rh);
            f->prim[i] = rh.hit.geomID == RTC_INVALID_GEOMETRY_ID ? -1 : (int32_t)rh.hit.primID;
        }
        const double dt = now_s() - t0;
        if (dt < best)
            best = dt;
    }
    r.mrays = (double)f->n / best * 1e-6;
    r.hit_checksum = checksum(f);
    return r;
}

/* Packets of 8 = 4x2 pixel blocks (dirs must be in that order). */
static result run_embree8(frame *f, RTCScene scene) {
    struct RTCIntersectContext ctx;
    _Alignas(32) struct RTCRayHit8 rh;
    _Alignas(32) int valid[8];
    result r = {0, 0, 0, 0};
    double best = 1e30;
    for (int j = 0; j < 8; j++)
        valid[j] = -1;
    for (int rep = 0; rep < g_repeat; rep++) {
        const double t0 = now_s();
        rtcInitIntersectContext(&ctx);
        ctx.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
        for (size_t i = 0; i < f->n; i += 8) {
            for (int j = 0; j < 8; j++) {
                const float *d = &f->dirs[3 * (i + (size_t)j)];
                rh.ray.org_x[j] = f->cam->eye[0];
                rh.ray.org_y[j] = f->cam->eye[1];
                rh.ray.org_z[j] = f->cam->eye[2];
                rh.ray.dir_x[j] = d[0];
                rh.ray.dir_y[j] = d[1];
                rh.ray.dir_z[j] = d[2];
                rh.ray.tnear[j] = 0.0f;
                rh.ray.tfar[j] = INFINITY;
                rh.ray.mask[j] = (unsigned)-1;
                rh.ray.flags[j] = 0;
                rh.ray.time[j] = 0.0f;
                rh.hit.geomID[j] = RTC_INVALID_GEOMETRY_ID;
            }
            rtcIntersect8(valid, scene, &ctx, &rh);
            for (int j = 0; j < 8; j++)
                f->prim[i + (size_t)j] = rh.hit.geomID[j] == RTC_INVALID_GEOMETRY_ID
                                             ? -1 : (int32_t)rh.hit.primID[j];
        }
        const double dt = now_s() - t0;
        if (dt < best)
            best = dt;
    }
    r.mrays = (double)f->n / best * 1e-6;
    r.hit_checksum = checksum(f);
    return r;
}

/* ---- cameras and scenes ----------------------------------------------------- */

/* Camera k: 0 = front view from outside, 1 = diagonal from outside, 2 =
 * inside the box near its centre. */
static void make_camera(const kdr_bounds *b, int k, uint32_t size, kdr_camera *cam) {
    float c[3], ext[3];
    for (int a = 0; a < 3; a++) {
        c[a] = 0.5f * (b->min[a] + b->max[a]);
        ext[a] = b->max[a] - b->min[a];
    }
    const float diag = sqrtf(ext[0] * ext[0] + ext[1] * ext[1] + ext[2] * ext[2]);
    static const float off[NCAMS][3] = {{0.0f, 0.1f, 1.1f}, {0.8f, 0.6f, 0.7f}, {0.05f, 0.02f, 0.1f}};
    memset(cam, 0, sizeof *cam);
    for (int a = 0; a < 3; a++) {
        cam->eye[a] = c[a] + off[k][a] * diag;
        cam->target[a] = c[a];
    }
    if (k == 2)
        cam->target[0] += diag; /* look sideways from inside */
    cam->up[1] = 1.0f;
    cam->fov_y_deg = k == 2 ? 70.0f : 45.0f;
    cam->width = cam->height = size;
}

typedef struct method {
    const char *name;
    double sum_log, sum_nodes;
} method;

enum { M_RAYS, M_BUNDLE4, M_FR1, M_FR4, M_EMB1, M_EMB8, M_EMB1_FAST, M_COUNT };

/* tile sweep 4..64: sums of log Mrays/s, [tile][single, multi4] */
#define NSWEEP 5
static double g_sweep[NSWEEP][2];
static method g_m[M_COUNT] = {{"kd per ray", 0, 0},           {"kd bundle4 (2x2)", 0, 0},
                              {"kd 1-frustum", 0, 0},         {"kd 4-frustum", 0, 0},
                              {"embree rtcIntersect1", 0, 0}, {"embree rtcIntersect8", 0, 0},
                              {"embree 1 (not robust)", 0, 0}};
static int g_ncams;

static const char *const g_metric[M_COUNT] = {"rays", "bundle4", "frustum1", "frustum4",
                                              "embree1", "embree8", "embree1_fast"};

/* One ladder scene: square frames of about opts->rays pixels. */
static int frustum_section(const bench_scene *sc, const bench_opts *opts,
                           bench_csv *csv) {
    const kdr_scene *s = sc->kd;
    const uint32_t size = (uint32_t)sqrt((double)opts->rays) & ~7u;
    method *m = g_m;
    oracle_opts oo;
    kdr_bounds b;
    g_repeat = opts->repeat;
    if (size < 8)
        return 1;
    oracle_opts_default(&oo);
    oo.device_config = BENCH_EMBREE_CONFIG;
    oracle *emb = oracle_create(sc->tris, sc->ntris, &oo);
    oo.robust = 0;
    oracle *emb_fast = oracle_create(sc->tris, sc->ntris, &oo);
    if (!emb || !emb_fast) {
        oracle_free(emb);
        oracle_free(emb_fast);
        return 1;
    }
    kdr_scene_bounds(s, &b);
    printf("\n== %s: %zu triangles, %ux%u, tile %d unless noted\n", sc->name, sc->ntris,
           size, size, DEFAULT_TILE);
    frame f = {.s = s, .n = (size_t)size * size};
    f.t = malloc(f.n * sizeof *f.t);
    f.u = malloc(f.n * sizeof *f.u);
    f.v = malloc(f.n * sizeof *f.v);
    f.prim = malloc(f.n * sizeof *f.prim);
    f.dirs = malloc(3 * f.n * sizeof *f.dirs);
    for (int k = 0; k < NCAMS; k++) {
        kdr_camera cam;
        result r[M_COUNT];
        make_camera(&b, k, size, &cam);
        f.cam = &cam;
        r[M_RAYS] = run_frustum(&f, DEFAULT_TILE, KDR_FRUSTUM_RAYS);
        r[M_FR1] = run_frustum(&f, DEFAULT_TILE, KDR_FRUSTUM_SINGLE);
        r[M_FR4] = run_frustum(&f, DEFAULT_TILE, KDR_FRUSTUM_MULTI4);
        block_dirs(&f, 2, 2);
        r[M_BUNDLE4] = run_bundle(&f, KDR_TRAV_BUNDLE4);
        block_dirs(&f, 4, 2);
        r[M_EMB1] = run_embree1(&f, oracle_rtc_scene(emb));
        r[M_EMB1_FAST] = run_embree1(&f, oracle_rtc_scene(emb_fast));
        r[M_EMB8] = run_embree8(&f, oracle_rtc_scene(emb));
        printf("camera %d (eye %.3g %.3g %.3g):\n", k, cam.eye[0], cam.eye[1], cam.eye[2]);
        for (int j = 0; j < M_COUNT; j++) {
            printf("  %-26s %7.2f Mrays/s", m[j].name, r[j].mrays);
            if (j <= M_FR4)
                printf("  %6.1f nodes/ray %6.1f tris/ray", r[j].nodes_per_ray,
                       r[j].tris_per_ray);
            printf("  (hits checksum %.0f)\n", r[j].hit_checksum);
            m[j].sum_log += log(r[j].mrays);
            m[j].sum_nodes += r[j].nodes_per_ray;
            char metric[64];
            snprintf(metric, sizeof metric, "cam%d_%s_mrays", k, g_metric[j]);
            bench_csv_row(csv, "frustum", sc, metric, r[j].mrays);
        }
        printf("  4-frustum / 1-frustum %.2fx, 4-frustum / embree1 %.2fx, / embree8 %.2fx\n",
               r[M_FR4].mrays / r[M_FR1].mrays, r[M_FR4].mrays / r[M_EMB1].mrays,
               r[M_FR4].mrays / r[M_EMB8].mrays);
        printf("  tile sweep (Mrays/s, 1-frustum / 4-frustum):");
        for (int ti = 0; ti < NSWEEP; ti++) {
            const uint32_t tile = 4u << ti;
            result a = run_frustum(&f, tile, KDR_FRUSTUM_SINGLE);
            result c = run_frustum(&f, tile, KDR_FRUSTUM_MULTI4);
            printf("  %u: %.1f/%.1f", tile, a.mrays, c.mrays);
            g_sweep[ti][0] += log(a.mrays);
            g_sweep[ti][1] += log(c.mrays);
        }
        printf("\n");
        ++g_ncams;
    }
    free(f.t);
    free(f.u);
    free(f.v);
    free(f.prim);
    free(f.dirs);
    oracle_free(emb);
    oracle_free(emb_fast);
    return 0;
}

int main(int argc, char **argv) {
    static const bench_section sections[] = {{"frustum", frustum_section}};
    const int rc = bench_main(argc, argv, sections, 1);
    const method *m = g_m;
    const int ncams = g_ncams;
    if (ncams == 0)
        return rc ? rc : 1;
    printf("\n== geometric means over %d cameras\n", ncams);
    for (int j = 0; j < M_COUNT; j++)
        printf("  %-26s %7.2f Mrays/s\n", m[j].name, exp(m[j].sum_log / ncams));
    printf("  4-frustum / 1-frustum: %.2fx (target >= 1.3)\n",
           exp((m[M_FR4].sum_log - m[M_FR1].sum_log) / ncams));
    printf("  4-frustum / embree rtcIntersect1: %.2fx (target >= 2)\n",
           exp((m[M_FR4].sum_log - m[M_EMB1].sum_log) / ncams));
    printf("  4-frustum / embree rtcIntersect8: %.2fx\n",
           exp((m[M_FR4].sum_log - m[M_EMB8].sum_log) / ncams));
    printf("  tile sweep, 4-frustum / 1-frustum at the same tile:");
    for (int ti = 0; ti < NSWEEP; ti++)
        printf("  %u: %.2fx", 4u << ti, exp((g_sweep[ti][1] - g_sweep[ti][0]) / ncams));
    printf("\n  same rays per traversal, 4-frustum tile T / 1-frustum tile 2T:");
    for (int ti = 0; ti + 1 < NSWEEP; ti++)
        printf("  %u: %.2fx", 4u << ti, exp((g_sweep[ti][1] - g_sweep[ti + 1][0]) / ncams));
    printf("\n");
    return rc;
}
