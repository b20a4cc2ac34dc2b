/*
 * bench_cone.c — run time against error for soft shadows toward sphere
 * lights: (a) Embree rtcOccluded1 per sample ray, (b) kd-tree single rays
 * (KDR_SHADOW_RAYS), (c) cone traversal + sampling (KDR_SHADOW_CONE), for
 * 1..256 samples per point, RMSE against a 4096-sample Embree reference.
 *
 * Points are the primary hits of a camera looking at the scene; each scene
 * gets a small light (mostly fully lit or umbra points) and a large close one
 * (penumbra-heavy). All three methods trace the very same kdr_shadow_ray
 * rays, so at equal samples they have (almost exactly) the same RMSE and the
 * comparison at equal error is the time ratio. Single thread, all methods
 * measured in the same run. Writes a CSV, a gnuplot data file and (if
 * gnuplot is installed) a log-log PNG through bench/plot_cone.gp.
 *
 * usage: kdray_bench_cone [--res N] [--max-samples N] [--out PREFIX]
 *                         [--methods MASK] [--ref-samples N] [scene.glb ...]
 * --methods 4 --ref-samples 1 runs the cone alone (for a profiler).
 */
#define _POSIX_C_SOURCE 200809L
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include <embree3/rtcore.h>

#include "kd_cone.h"
#include "kdr_gltf.h"
#include "kdray.h"
#include "ladder.h"
#include "oracle.h"

#define BENCH_RES 64             /* camera is RES x RES points */
#define BENCH_MAX_SAMPLES 256
#define BENCH_REF_SAMPLES 4096
#define BENCH_MIN_SECONDS 0.15   /* all methods' passes at one sample count */
#define BENCH_MIN_ROUNDS 3
#define BENCH_EPSILON 1e-4f
#define BENCH_LADDER_SCENE "2CylinderEngine"
#define BENCH_FALLBACK_ENGINE \
    "/usr/share/assimp/models/glTF2/2CylinderEngine-glTF-Binary/2CylinderEngine.glb"

enum { M_EMBREE, M_KD_RAYS, M_KD_CONE, M_COUNT };
static const char *method_name[M_COUNT] = {"embree_rays", "kd_rays", "kd_cone"};
static int method_mask = (1 << M_COUNT) - 1;
static int ref_samples = BENCH_REF_SAMPLES;

static double now_s(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

/* ---- points: primary hits of a camera ------------------------------------ */

typedef struct point_set {
    float *p, *n;
    size_t count;
} point_set;

static void camera_points(const kdr_scene *s, int res, point_set *ps) {
    kdr_bounds b;
    kdr_scene_bounds(s, &b);
    const float diag = kdr_scene_diagonal(s);
    const float dir[3] = {0.55f, 0.45f, 0.70f};
    kdr_camera cam = {.up = {0, 1, 0}, .fov_y_deg = 50.0f,
                      .width = (uint32_t)res, .height = (uint32_t)res};
    for (int k = 0; k < 3; k++) {
        cam.target[k] = 0.5f * (b.min[k] + b.max[k]);
        cam.eye[k] = cam.target[k] + 0.9f * diag * dir[k];
    }
    ps->p = malloc((size_t)res * res * 3 * sizeof(float));
    ps->n = malloc((size_t)res * res * 3 * sizeof(float));
    ps->count = 0;
    for (int y = 0; y < res; y++) {
        for (int x = 0; x < res; x++) {
            kdr_ray r;
            kdr_hit h;
            kdr_camera_ray(&cam, (uint32_t)x, (uint32_t)y, &r);
            if (!kdr_intersect1(s, &r, &h, NULL))
                continue;
            const float *t = kdr_scene_triangle(s, (size_t)h.prim);
            float *p = ps->p + 3 * ps->count, *n = ps->n + 3 * ps->count;
            float e1[3], e2[3];
            for (int k = 0; k < 3; k++) {
                p[k] = r.org[k] + h.t * r.dir[k];
                e1[k] = t[3 + k] - t[k];
                e2[k] = t[6 + k] - t[k];
            }
            n[0] = e1[1] * e2[2] - e1[2] * e2[1];
            n[1] = e1[2] * e2[0] - e1[0] * e2[2];
            n[2] = e1[0] * e2[1] - e1[1] * e2[0];
            ps->count++;
        }
    }
}

/* ---- the three methods ---------------------------------------------------- */

/* Embree per sample: the same rays as the kd modes, built with the same
 * per-(point, light) frame so ray generation costs the same everywhere. */
static int embree_visibility(const kdr_scene *s, RTCScene es,
                             const kdr_shadow_query *q, float *vis) {
    struct RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    for (size_t i = 0; i < q->n; i++) {
        kd_shadow_frame f;
        if (kd_shadow_frame_init(s, q, i, 0, &f) != KDR_OK)
            return -1;
        uint32_t lit = 0;
        for (uint32_t k = 0; k < q->samples; k++) {
            kdr_ray r;
            struct RTCRay er;
            kd_shadow_frame_ray(&f, k, q->samples, &r);
            er.org_x = r.org[0];
            er.org_y = r.org[1];
            er.org_z = r.org[2];
            er.dir_x = r.dir[0];
            er.dir_y = r.dir[1];
            er.dir_z = r.dir[2];
            er.tnear = r.tmin;
            er.tfar = r.tmax;
            er.time = 0.0f;
            er.mask = 0xFFFFFFFFu;
            er.id = 0;
            er.flags = 0;
            rtcOccluded1(es, &ctx, &er);
            lit += er.tfar == -INFINITY ? 0u : 1u;
        }
        vis[i] = (float)lit / (float)q->samples;
    }
    return 0;
}

typedef struct run_result {
    double seconds; /* fastest full pass over the points */
    double rmse;
    uint64_t rays, decided;
} run_result;

static int run_once(int method, const kdr_scene *s, RTCScene es,
                    const kdr_shadow_query *q, float *vis, kdr_shadow_stats *st) {
    if (method == M_EMBREE)
        return embree_visibility(s, es, q, vis);
    return kdr_shadow_trace(s, q, 0, q->n,
                            method == M_KD_CONE ? KDR_SHADOW_CONE : KDR_SHADOW_RAYS,
                            vis, st);
}

/* Times one pass of a method (best so far kept in *out) and scores it. */
static int measure(int method, const kdr_scene *s, RTCScene es,
                   const kdr_shadow_query *q, const float *ref, float *vis,
                   run_result *out) {
    kdr_shadow_stats st = {0};
    const double ts = now_s();
    if (run_once(method, s, es, q, vis, &st) != 0)
        return -1;
    const double sec = now_s() - ts;
    if (sec >= out->seconds)
        return 0;
    double se = 0.0;
    for (size_t i = 0; i < q->n; i++)
        se += ((double)vis[i] - ref[i]) * ((double)vis[i] - ref[i]);
    out->seconds = sec;
    out->rmse = sqrt(se / (double)q->n);
    out->rays = method == M_EMBREE ? (uint64_t)q->n * q->samples : st.rays_traced;
    out->decided = st.cones_decided;
    return 0;
}

/* The methods take turns, pass after pass, until each has run
 * BENCH_MIN_ROUNDS passes and BENCH_MIN_SECONDS in all; each keeps its
 * fastest pass. Interleaving matters on a shared machine whose load drifts. */
static int measure_all(const kdr_scene *s, RTCScene es, const kdr_shadow_query *q,
                       const float *ref, float *vis, run_result *res) {
    const double t0 = now_s();
    for (int m = 0; m < M_COUNT; m++)
        res[m] = (run_result){INFINITY, 1.0, 0, 0};
    for (int round = 0; round < BENCH_MIN_ROUNDS || now_s() - t0 < BENCH_MIN_SECONDS;
         round++) {
        for (int m = 0; m < M_COUNT; m++) {
            if (((method_mask >> m) & 1) &&
                measure(m, s, es, q, ref, vis, &res[m]) != 0)
                return -1;
        }
    }
    for (int m = 0; m < M_COUNT; m++)
        if (!((method_mask >> m) & 1))
            res[m].seconds = 1.0;
    return 0;
}

/* ---- one scene, one light --------------------------------------------------- */

typedef struct bench_out {
    FILE *csv, *dat;
    int blocks;
    char titles[1024];
    double worst_ratio, best_ratio; /* embree time / cone time, n >= 4 */
} bench_out;

static void light_for(const kdr_scene *s, int large, kdr_sphere_light *li) {
    kdr_bounds b;
    kdr_scene_bounds(s, &b);
    const float diag = kdr_scene_diagonal(s);
    const float dir[3] = {-0.35f, 0.85f, 0.40f};
    const float dist = large ? 0.55f : 0.9f;
    for (int k = 0; k < 3; k++)
        li->center[k] = 0.5f * (b.min[k] + b.max[k]) + dist * diag * dir[k];
    li->radius = (large ? 0.25f : 0.03f) * diag;
}

/* Keeps only the points outside the light (the query rejects the others). */
static size_t points_outside(point_set *ps, const kdr_sphere_light *li) {
    size_t out = 0;
    for (size_t i = 0; i < ps->count; i++) {
        double d2 = 0;
        for (int k = 0; k < 3; k++) {
            const double d = ps->p[3 * i + k] - li->center[k];
            d2 += d * d;
        }
        if (d2 > 1.01 * li->radius * li->radius) {
            memmove(ps->p + 3 * out, ps->p + 3 * i, 3 * sizeof(float));
            memmove(ps->n + 3 * out, ps->n + 3 * i, 3 * sizeof(float));
            out++;
        }
    }
    return ps->count = out;
}

static int bench_config(const char *name, const kdr_scene *s, RTCScene es,
                        point_set *ps, int large, int max_samples, bench_out *bo) {
    kdr_sphere_light li;
    light_for(s, large, &li);
    points_outside(ps, &li);
    kdr_shadow_query q = {.n = ps->count, .points = ps->p, .normals = ps->n,
                          .lights = &li, .nlights = 1, .seed = 0x5eed,
                          .epsilon = BENCH_EPSILON};
    float *ref = malloc(q.n * sizeof *ref), *vis = malloc(q.n * sizeof *vis);
    q.samples = (uint32_t)ref_samples;
    q.seed = 0xfeedbeef; /* independent of the measured estimates */
    double t0 = now_s();
    if (embree_visibility(s, es, &q, ref) != 0)
        return -1;
    const double ref_s = now_s() - t0;
    size_t lit = 0, dark = 0;
    for (size_t i = 0; i < q.n; i++) {
        lit += ref[i] == 1.0f;
        dark += ref[i] == 0.0f;
    }
    const char *lname = large ? "large" : "small";
    printf("\n%s, %s light: %zu points, lit %.1f%%, umbra %.1f%%, penumbra "
           "%.1f%% (reference %d spp: %.2f s)\n",
           name, lname, q.n, 100.0 * lit / q.n, 100.0 * dark / q.n,
           100.0 * (q.n - lit - dark) / q.n, ref_samples, ref_s);
    printf("%8s %12s %10s %9s %12s %10s %9s %12s %10s %9s %9s %8s\n", "samples",
           "embree_s", "rmse", "Mray/s", "kd_rays_s", "rmse", "Mray/s",
           "kd_cone_s", "rmse", "decided", "cone/emb", "rays/emb");
    q.seed = 0x5eed;
    run_result res[M_COUNT][16];
    int nrows = 0;
    for (int n = 1; n <= max_samples; n *= 2, nrows++) {
        q.samples = (uint32_t)n;
        run_result row[M_COUNT];
        if (measure_all(s, es, &q, ref, vis, row) != 0)
            return -1;
        for (int m = 0; m < M_COUNT; m++) {
            res[m][nrows] = row[m];
            const run_result *r = &res[m][nrows];
            fprintf(bo->csv, "%s,%s,%s,%d,%.6g,%.6g,%llu,%llu,%zu\n", name, lname,
                    method_name[m], n, r->seconds, r->rmse,
                    (unsigned long long)r->rays, (unsigned long long)r->decided, q.n);
        }
        const run_result *e = &res[M_EMBREE][nrows], *k = &res[M_KD_RAYS][nrows],
                         *c = &res[M_KD_CONE][nrows];
        const double ratio = e->seconds / c->seconds;
        printf("%8d %12.5f %10.5f %9.2f %12.5f %10.5f %9.2f %12.5f %10.5f %8.1f%% "
               "%8.2fx %7.2fx\n",
               n, e->seconds, e->rmse, q.n * n / e->seconds * 1e-6, k->seconds,
               k->rmse, q.n * n / k->seconds * 1e-6, c->seconds, c->rmse,
               100.0 * c->decided / q.n, ratio, e->seconds / k->seconds);
        if (n >= 4) {
            bo->worst_ratio = fmin(bo->worst_ratio, ratio);
            bo->best_ratio = fmax(bo->best_ratio, ratio);
        }
    }
    for (int m = 0; m < M_COUNT; m++) {
        fprintf(bo->dat, "seconds %s\n", method_name[m]);
        for (int j = 0; j < nrows; j++)
            fprintf(bo->dat, "%.6g %.6g\n", res[m][j].seconds, res[m][j].rmse);
        fprintf(bo->dat, "\n\n");
    }
    bo->blocks++;
    size_t used = strlen(bo->titles);
    snprintf(bo->titles + used, sizeof bo->titles - used, "%s%s_%s_light",
             used ? " " : "", name, lname);
    free(ref);
    free(vis);
    return 0;
}

/* ---- scenes ----------------------------------------------------------------- */

static int bench_scene(const char *path, int res, int max_samples, bench_out *bo) {
    kdr_gltf_scene g;
    char err[256];
    if (kdr_gltf_load(path, &g, err, sizeof err) != 0) {
        fprintf(stderr, "bench_cone: %s\n", err);
        return -1;
    }
    kdr_build_opts opts;
    kdr_scene *s = NULL;
    kdr_build_opts_default(&opts);
    oracle *o = oracle_create(g.tris, g.ntris, NULL);
    if (!o || kdr_scene_build(g.tris, g.ntris, &opts, NULL, NULL, &s) != KDR_OK) {
        fprintf(stderr, "bench_cone: cannot build %s\n", path);
        return -1;
    }
    const char *base = strrchr(path, '/');
    char name[128];
    snprintf(name, sizeof name, "%s", base ? base + 1 : path);
    char *dot = strrchr(name, '.');
    if (dot)
        *dot = '\0';
    printf("\n== %s: %zu triangles\n", name, g.ntris);
    int rc = 0;
    for (int large = 0; large < 2 && rc == 0; large++) {
        point_set ps;
        camera_points(s, res, &ps);
        rc = bench_config(name, s, oracle_rtc_scene(o), &ps, large, max_samples, bo);
        free(ps.p);
        free(ps.n);
    }
    kdr_scene_free(s);
    oracle_free(o);
    kdr_gltf_free(&g);
    return rc;
}

/* The default scene and the ladder's 2CylinderEngine (or the assimp copy). */
static int default_scenes(const char **paths, char *engine, size_t len) {
    int n = 0;
#ifdef KDRAY_DEFAULT_SCENE
    FILE *f = fopen(KDRAY_DEFAULT_SCENE, "rb");
    if (f) {
        fclose(f);
        paths[n++] = KDRAY_DEFAULT_SCENE;
    }
#endif
    snprintf(engine, len, "%s", BENCH_FALLBACK_ENGINE);
    ladder_entry *lad = NULL;
    char err[256];
    const char *dir = ladder_default_dir();
    const int nl = dir ? ladder_read(dir, &lad, err, sizeof err) : -1;
    for (int j = 0; j < nl; j++) {
        if (strcmp(lad[j].name, BENCH_LADDER_SCENE) == 0)
            snprintf(engine, len, "%s", lad[j].path);
    }
    free(lad);
    paths[n++] = engine;
    return n;
}

static int write_plot(const char *prefix, const bench_out *bo) {
    char cmd[2048];
    snprintf(cmd, sizeof cmd,
             "gnuplot -e \"datafile='%s.dat'; outfile='%s.png'; nblocks=%d; "
             "titles='%s'\" %s",
             prefix, prefix, bo->blocks, bo->titles, KDRAY_CONE_PLOT);
    return system(cmd);
}

int main(int argc, char **argv) {
    int res = BENCH_RES, max_samples = BENCH_MAX_SAMPLES;
    const char *prefix = "bench_cone";
    const char *paths[16];
    char engine[1024];
    int np = 0;
    for (int a = 1; a < argc; a++) {
        if (!strcmp(argv[a], "--res") && a + 1 < argc)
            res = atoi(argv[++a]);
        else if (!strcmp(argv[a], "--max-samples") && a + 1 < argc)
            max_samples = atoi(argv[++a]);
        else if (!strcmp(argv[a], "--out") && a + 1 < argc)
            prefix = argv[++a];
        else if (!strcmp(argv[a], "--methods") && a + 1 < argc)
            method_mask = atoi(argv[++a]);
        else if (!strcmp(argv[a], "--ref-samples") && a + 1 < argc)
            ref_samples = atoi(argv[++a]);
        else if (np < 16)
            paths[np++] = argv[a];
    }
    if (res < 4 || max_samples < 1 || max_samples > 4096 || ref_samples < 1 ||
        ref_samples > 4096) {
        fprintf(stderr, "usage: %s [--res N] [--max-samples N] [--out PREFIX] "
                        "[scene.glb ...]\n", argv[0]);
        return 2;
    }
    if (np == 0)
        np = default_scenes(paths, engine, sizeof engine);
    char file[1100];
    bench_out bo = {.worst_ratio = INFINITY, .best_ratio = 0.0};
    snprintf(file, sizeof file, "%s.csv", prefix);
    bo.csv = fopen(file, "w");
    snprintf(file, sizeof file, "%s.dat", prefix);
    bo.dat = fopen(file, "w");
    if (!bo.csv || !bo.dat) {
        fprintf(stderr, "bench_cone: cannot write %s.*\n", prefix);
        return 1;
    }
    fprintf(bo.csv, "scene,light,method,samples,seconds,rmse,rays,cones_decided,points\n");
    const double t0 = now_s();
    int rc = 0;
    for (int j = 0; j < np && rc == 0; j++)
        rc = bench_scene(paths[j], res, max_samples, &bo);
    fclose(bo.csv);
    fclose(bo.dat);
    if (rc != 0)
        return 1;
    printf("\ncone vs Embree per-ray at equal samples (= equal rays, equal RMSE), "
           "4..%d spp: %.2fx .. %.2fx; total %.1f s\n",
           max_samples, bo.worst_ratio, bo.best_ratio, now_s() - t0);
    if (write_plot(prefix, &bo) == 0)
        printf("wrote %s.csv, %s.dat, %s.png\n", prefix, prefix, prefix);
    else
        printf("wrote %s.csv, %s.dat (gnuplot failed: no PNG)\n", prefix, prefix);
    return 0;
}
