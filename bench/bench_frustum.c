/*
 * bench_frustum.c — the "frustum" section (kdray_bench_frustum): one image
 * of primary rays per camera (three cameras per scene: front and diagonal
 * views from outside, a sideways view from inside; --frame N pixels a
 * side, default 1000), answered
 *   - by kdr_frustum_trace as the daemon calls it: four-frustum (MULTI4)
 *     and single-frustum traversal at tile 8, and its per-pixel reference
 *     walk (RAYS); all three generate the camera rays themselves;
 *   - by every rival API for camera rays, generating the very same rays
 *     inside the timed call too (rival_camera_job), so both sides time
 *     "camera in, t/prim/u/v image out".
 * A diagnostic row times the Embree side's ray generation and write-out
 * alone (raygen_only). Without --quick a tile sweep (4..64) of both
 * frustum modes follows. The finish prints geometric means over all
 * cameras, including 4-frustum / 1-frustum and against the strongest
 * Embree API per camera.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "bench.h"
#include "rival.h"

#define DEFAULT_TILE 8
#define NCAMS 3
#define QUICK_CAM 1 /* the diagonal view */
#define NSWEEP 5    /* tiles 4, 8, 16, 32, 64 */
#define HIT_TOLERANCE 0.001

/* Camera k: 0 = front view from outside, 1 = diagonal from outside, 2 =
 * inside the box near its centre, looking sideways. */
static void make_camera(const kdr_scene *s, int k, uint32_t size, kdr_camera *cam) {
    kdr_bounds b;
    kdr_scene_bounds(s, &b);
    const float diag = kdr_scene_diagonal(s);
    static const float off[NCAMS][3] = {{0.0f, 0.1f, 1.1f}, {0.8f, 0.6f, 0.7f},
                                        {0.05f, 0.02f, 0.1f}};
    memset(cam, 0, sizeof *cam);
    for (int a = 0; a < 3; a++) {
        const float c = 0.5f * (b.min[a] + b.max[a]);
        cam->eye[a] = c + off[k][a] * diag;
        cam->target[a] = c;
    }
    if (k == 2)
        cam->target[0] += diag;
    cam->up[1] = 1.0f;
    cam->fov_y_deg = k == 2 ? 70.0f : 45.0f;
    cam->width = cam->height = size;
}

typedef struct kd_frame {
    const kdr_scene *kd;
    const kdr_camera *cam;
    uint32_t tile;
    kdr_frustum_mode mode;
    kdr_hits out;
    kdr_trav_stats *stats;
} kd_frame;

static void kd_frame_run(void *ctx) {
    kd_frame *f = ctx;
    kdr_frustum_trace(f->kd, f->cam, f->tile, 0, kdr_frustum_tile_count(f->cam, f->tile),
                      KDR_CLOSEST, f->mode, &f->out, f->stats);
}

static int alloc_hits(kdr_hits *h, size_t n) {
    h->t = malloc(n * sizeof(float)), h->u = malloc(n * sizeof(float));
    h->v = malloc(n * sizeof(float)), h->prim = malloc(n * sizeof(int32_t));
    h->hit = NULL;
    return h->t && h->u && h->v && h->prim ? 0 : -1;
}

static void free_hits(kdr_hits *h) { free(h->t), free(h->u), free(h->v), free(h->prim); }

static size_t count_hits(const kdr_hits *h, size_t n) {
    size_t c = 0;
    for (size_t i = 0; i < n; i++)
        c += h->prim[i] >= 0;
    return c;
}

static const char *const kd_names[3] = {"kd_frustum4", "kd_frustum1", "kd_rays"};
static const kdr_frustum_mode kd_modes[3] = {KDR_FRUSTUM_MULTI4, KDR_FRUSTUM_SINGLE,
                                             KDR_FRUSTUM_RAYS};

/* Tile sweep: both frustum modes at each tile, interleaved. */
static void sweep(const bench_scene *s, kd_frame *f, const char *work, int repeat) {
    printf("  tile sweep (Mrays/s, 1-frustum / 4-frustum):");
    const size_t n = (size_t)f[0].cam->width * f[0].cam->height;
    for (int t = 0; t < NSWEEP; t++) {
        kd_frame fr[2] = {f[1], f[0]};
        fr[0].tile = fr[1].tile = 4u << t;
        bench_method m[2] = {{"kd_frustum1", 0, NULL, kd_frame_run, &fr[0], 0},
                             {"kd_frustum4", 0, NULL, kd_frame_run, &fr[1], 0}};
        bench_measure(m, 2, repeat, 0.0);
        char w[96];
        snprintf(w, sizeof w, "sweep_%s_tile%u", work + 8 /* "camK" */, 4u << t);
        for (int k = 0; k < 2; k++)
            bench_summary_add(s, w, m[k].name, n, m[k].best_ms, -1);
        printf("  %u: %.1f/%.1f", 4u << t, (double)n / (m[0].best_ms * 1e3),
               (double)n / (m[1].best_ms * 1e3));
    }
    printf("\n");
}

static int one_camera(const bench_scene *s, const kdr_camera *cam, int k,
                      const bench_opts *o) {
    const size_t n = (size_t)cam->width * cam->height;
    rival_api apis[RIVAL_MAX_APIS];
    const size_t napi = rival_apis(RIVAL_WORK_CAMERA, apis);
    kd_frame kf[3];
    rival_camera_job rj[RIVAL_MAX_APIS + 1];
    kdr_hits hits[3 + RIVAL_MAX_APIS + 1];
    bench_method m[3 + RIVAL_MAX_APIS + 1];
    size_t nm = 0;
    int rc = 0;
    for (int i = 0; i < 3; i++, nm++) {
        rc |= alloc_hits(&hits[nm], n);
        kf[i] = (kd_frame){s->kd, cam, DEFAULT_TILE, kd_modes[i], hits[nm], NULL};
        m[nm] = (bench_method){kd_names[i], 0, NULL, kd_frame_run, &kf[i], 0};
    }
    const size_t nr = napi + (o->quick ? 0 : 1);
    for (size_t i = 0; i < nr; i++, nm++) {
        rc |= alloc_hits(&hits[nm], n);
        rival_api a = i < napi ? apis[i] : apis[napi - 1];
        rc |= rival_camera_job_init(&rj[i], s->emb, a, cam, hits[nm]);
        m[nm] = rival_camera_job_method(&rj[i]);
        if (i == napi) { /* the same packets, generated and written out, not traced */
            rj[i].trace = 0;
            snprintf(rj[i].name, sizeof rj[i].name, "raygen_only_%s",
                     a.width == 1 ? "1" : "packets");
            m[nm].name = rj[i].name;
        }
    }
    if (rc == 0)
        bench_measure(m, nm, o->repeat, 0.0);
    char work[32];
    snprintf(work, sizeof work, "frustum_cam%d", k);
    printf("camera %d (eye %.3g %.3g %.3g), %ux%u:\n", k, cam->eye[0], cam->eye[1],
           cam->eye[2], cam->width, cam->height);
    const size_t ref = isnan(m[2].best_ms) ? 0 : count_hits(&hits[2], n); /* kd_rays */
    double best = INFINITY;
    for (size_t i = 3; i < 3 + napi; i++)
        best = fmin(best, m[i].best_ms);
    for (size_t i = 0; rc == 0 && i < nm; i++) {
        double npr = -1.0;
        if (isnan(m[i].best_ms))
            continue; /* left out by --method */
        if (i < 3 && !o->quick) {
            kdr_trav_stats st = {0};
            kf[i].stats = &st;
            kd_frame_run(&kf[i]);
            kf[i].stats = NULL;
            npr = (double)st.nodes_visited / (double)n;
        }
        const int traced = i < 3 + napi;
        const size_t h = traced ? count_hits(&hits[i], n) : 0;
        printf("  %-32s %8.2f Mrays/s %9.2f ms  x best Embree %5.2f", m[i].name,
               (double)n / (m[i].best_ms * 1e3), m[i].best_ms, best / m[i].best_ms);
        if (traced)
            printf("  hits %8zu", h);
        if (npr >= 0)
            printf("  %6.1f nodes/ray", npr);
        printf("\n");
        bench_summary_add(s, work, m[i].name, n, m[i].best_ms, npr);
        const size_t diff = h > ref ? h - ref : ref - h;
        if (ref && traced && (double)diff > HIT_TOLERANCE * (double)n)
            bench_fail("%s %s: %s hits %zu, kd_rays %zu", s->name, work, m[i].name, h,
                       ref);
    }
    if (rc == 0 && !o->quick && !bench_method_filtered())
        sweep(s, kf, work, o->repeat);
    for (size_t i = 0; i < nm; i++)
        free_hits(&hits[i]);
    for (size_t i = 0; i < nr; i++)
        rival_camera_job_free(&rj[i]);
    fflush(stdout);
    return rc ? -1 : 0;
}

static int frustum_run(const bench_scene *s, const bench_opts *o) {
    const uint32_t size = (o->quick && o->frame > 512 ? 512 : o->frame) & ~7u;
    printf("\n== %s: %zu triangles, frustum images %ux%u, tile %d\n", s->name, s->ntris,
           size, size, DEFAULT_TILE);
    for (int k = 0; k < NCAMS; k++) {
        if (o->quick && k != QUICK_CAM)
            continue;
        kdr_camera cam;
        make_camera(s->kd, k, size, &cam);
        if (one_camera(s, &cam, k, o))
            return -1;
    }
    return 0;
}

/* One geometric-mean line, or nothing when the method did not run. */
static void mean_line(const char *name) {
    const double g = bench_summary_geomean("frustum_cam", name, 1);
    if (g > 0)
        printf("  %-32s x best Embree %.2f\n", name, g);
}

static void frustum_finish(const bench_opts *o) {
    rival_api apis[RIVAL_MAX_APIS];
    const size_t napi = rival_apis(RIVAL_WORK_CAMERA, apis);
    printf("\n== frustum: geometric means over every camera of every scene\n");
    for (int i = 0; i < 3; i++)
        mean_line(kd_names[i]);
    for (size_t i = 0; i < napi; i++) {
        char name[64];
        rival_api_name(NULL, apis[i], KDR_CLOSEST, name, sizeof name);
        mean_line(name);
    }
    /* ratio of two methods' times over the same workloads: exp(mean log) */
    const double f4 = bench_summary_geomean("frustum_cam", "kd_frustum4", 0);
    const double f1 = bench_summary_geomean("frustum_cam", "kd_frustum1", 0);
    if (f4 > 0 && f1 > 0)
        printf("  4-frustum / 1-frustum at tile %d: %.2fx\n", DEFAULT_TILE, f1 / f4);
    if (o->quick || bench_method_filtered())
        return;
    printf("  tile sweep, 4-frustum / 1-frustum at the same tile:");
    for (int t = 0; t < NSWEEP; t++) {
        char w[48];
        double a = 0, b = 0;
        int cams = 0;
        /* geometric mean over cameras: sum logs of per-camera ratios */
        for (int k = 0; k < NCAMS; k++) {
            snprintf(w, sizeof w, "sweep_cam%d_tile%u", k, 4u << t);
            const double g1 = bench_summary_geomean(w, "kd_frustum1", 0);
            const double g4 = bench_summary_geomean(w, "kd_frustum4", 0);
            if (g1 > 0 && g4 > 0)
                a += log(g1), b += log(g4), cams++;
        }
        printf("  %u: %.2fx", 4u << t, cams ? exp((a - b) / cams) : 0.0);
    }
    printf("\n");
}

const bench_section bench_frustum_section = {"frustum", frustum_run, frustum_finish};
