/*
 * bench_rays.c — the ray workloads of bench.h (camera, random, AO) and
 * bench_run_workload: kdray's single rays and bundles against every rival
 * API on one workload, in one bench_measure call, with the answer check.
 * The core and bundle sections are both made of these calls.
 */
#define _POSIX_C_SOURCE 200809L
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "bench.h"
#include "kd_traverse_bundle.h"
#include "rival.h"
#include "stress.h"

#define SEED 7u
/* The largest share of rays on which a method's hit count may differ from
 * kd_single's: Embree's fast (non-watertight) mode lets a few rays slip
 * through shared edges; more than this means a method traced other rays. */
#define HIT_TOLERANCE 0.001

/* ---- workloads ----------------------------------------------------------------- */

/* Z-order inside 4x4 tiles (same as rival_trace.c's tile_pixel). */
static void tile_pixel(int k, uint32_t *dx, uint32_t *dy) {
    *dx = (uint32_t)((k & 1) | ((k >> 1) & 2));
    *dy = (uint32_t)(((k >> 1) & 1) | ((k >> 2) & 2));
}

static size_t camera_rays(const kdr_scene *kd, size_t n, kdr_ray *out,
                          kdr_camera *cam_out) {
    kdr_bounds b;
    kdr_scene_bounds(kd, &b);
    const float diag = kdr_scene_diagonal(kd);
    static const float view[3] = {0.55f, 0.35f, 0.75f}; /* |view| ~ 1 */
    uint32_t side = (uint32_t)sqrt((double)n) & ~3u;
    kdr_camera cam = {.up = {0, 1, 0}, .fov_y_deg = 45.0f};
    cam.width = cam.height = side = side < 4 ? 4 : side;
    for (int k = 0; k < 3; k++) {
        cam.target[k] = 0.5f * (b.min[k] + b.max[k]);
        cam.eye[k] = cam.target[k] + 1.1f * diag * view[k];
    }
    size_t i = 0;
    for (uint32_t y0 = 0; y0 < side; y0 += 4)
        for (uint32_t x0 = 0; x0 < side; x0 += 4)
            for (int k = 0; k < 16; k++) {
                uint32_t dx, dy;
                tile_pixel(k, &dx, &dy);
                kdr_camera_ray(&cam, x0 + dx, y0 + dy, &out[i++]);
            }
    *cam_out = cam;
    return i;
}

static void random_rays(const kdr_scene *kd, size_t n, kdr_ray *out) {
    kdr_bounds b;
    kdr_scene_bounds(kd, &b);
    stress_rng r;
    stress_rng_seed(&r, SEED);
    for (size_t i = 0; i < n; i++) {
        for (int k = 0; k < 3; k++)
            out[i].org[k] = b.min[k] + (b.max[k] - b.min[k]) * stress_rng_float(&r);
        stress_rng_dir(&r, out[i].dir);
        out[i].tmin = 0.0f;
        out[i].tmax = INFINITY;
    }
}

/* A point on triangle tri with its unit geometric normal. */
static void surface_point(const float *tri, stress_rng *r, float p[3], float nrm[3]) {
    stress_tri_point(r, tri, p, nrm);
    const float len = sqrtf(nrm[0] * nrm[0] + nrm[1] * nrm[1] + nrm[2] * nrm[2]);
    for (int k = 0; k < 3; k++)
        nrm[k] = len > 0 ? nrm[k] / len : (k == 1);
}

static void ao_rays(const kdr_scene *kd, size_t n, kdr_ray *out) {
    const size_t ntris = kdr_scene_triangle_count(kd);
    const float reach = 0.1f * kdr_scene_diagonal(kd);
    stress_rng r;
    stress_rng_seed(&r, SEED);
    float p[3] = {0, 0, 0}, nrm[3] = {0, 1, 0};
    for (size_t i = 0; i < n; i++) {
        if (i % BENCH_AO_PER_POINT == 0 && ntris)
            surface_point(kdr_scene_triangle(kd, stress_rng_next(&r) % ntris), &r, p,
                          nrm);
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

/* Shadow rays: 16 samples per surface point (a random point on a random
 * triangle) toward uniform points of a sphere light above the scene (centre
 * half a diagonal above the box's top, radius 5% of the diagonal). The
 * direction is the unnormalised segment to the light sample and [tmin,
 * tmax] = [1e-4, 1 - 1e-4] of it, so every ray shares tmin and tmax; any
 * hit. */
static void shadow_rays(const kdr_scene *kd, size_t n, kdr_ray *out) {
    const size_t ntris = kdr_scene_triangle_count(kd);
    const float diag = kdr_scene_diagonal(kd);
    kdr_bounds b;
    kdr_scene_bounds(kd, &b);
    const float light[3] = {0.5f * (b.min[0] + b.max[0]), b.max[1] + 0.5f * diag,
                            0.5f * (b.min[2] + b.max[2])};
    stress_rng r;
    stress_rng_seed(&r, SEED + 1);
    float p[3] = {0, 0, 0}, nrm[3];
    for (size_t i = 0; i < n; i++) {
        if (i % BENCH_SHADOW_PER_POINT == 0 && ntris)
            surface_point(kdr_scene_triangle(kd, stress_rng_next(&r) % ntris), &r, p,
                          nrm);
        float d[3];
        stress_rng_dir(&r, d);
        for (int k = 0; k < 3; k++) {
            out[i].org[k] = p[k];
            out[i].dir[k] = light[k] + 0.05f * diag * d[k] - p[k];
        }
        out[i].tmin = 1e-4f;
        out[i].tmax = 1.0f - 1e-4f;
    }
}

int bench_workload_make(bench_workload *w, const kdr_scene *kd, const char *name,
                        size_t n) {
    memset(w, 0, sizeof *w);
    w->rays = malloc((n ? n : 1) * sizeof *w->rays);
    if (!w->rays)
        return -1;
    w->name = name;
    if (!strcmp(name, "camera")) {
        w->n = camera_rays(kd, n, w->rays, &w->cam);
        w->query = KDR_CLOSEST, w->work = RIVAL_WORK_CAMERA, w->group = 0;
    } else if (!strcmp(name, "random")) {
        random_rays(kd, w->n = n, w->rays);
        w->query = KDR_CLOSEST, w->work = RIVAL_WORK_INCOHERENT, w->group = 1;
    } else if (!strcmp(name, "ao_any") || !strcmp(name, "ao_closest")) {
        ao_rays(kd, w->n = n / BENCH_AO_PER_POINT * BENCH_AO_PER_POINT, w->rays);
        w->query = name[3] == 'a' ? KDR_ANY : KDR_CLOSEST;
        w->work = RIVAL_WORK_HEMISPHERE, w->group = BENCH_AO_PER_POINT;
    } else if (!strcmp(name, "shadow")) {
        shadow_rays(kd, w->n = n / BENCH_SHADOW_PER_POINT * BENCH_SHADOW_PER_POINT,
                    w->rays);
        w->query = KDR_ANY, w->work = RIVAL_WORK_SHADOW;
        w->group = BENCH_SHADOW_PER_POINT;
    } else {
        bench_workload_free(w);
        return -1;
    }
    const size_t norg = w->group == 0 ? 1 : (w->n + w->group - 1) / w->group;
    w->org = malloc(norg * 3 * sizeof(float));
    w->dir = malloc((w->n ? w->n : 1) * 3 * sizeof(float));
    if (!w->org || !w->dir || w->n == 0) {
        bench_workload_free(w);
        return -1;
    }
    for (size_t g = 0; g < norg; g++)
        memcpy(w->org + 3 * g, w->rays[g * (w->group ? w->group : 1)].org, 12);
    for (size_t i = 0; i < w->n; i++)
        memcpy(w->dir + 3 * i, w->rays[i].dir, 12);
    w->tmin = w->rays[0].tmin, w->tmax = w->rays[0].tmax;
    return 0;
}

void bench_workload_free(bench_workload *w) {
    free(w->rays), free(w->org), free(w->dir);
    memset(w, 0, sizeof *w);
}

/* ---- kdray's methods ----------------------------------------------------------- */

static const char *const kd_names[] = {"kd_single", "kd_bundle4", "kd_bundle8",
                                       "kd_sort8_nofallback", "kd_raw8_nofallback",
                                       "kd_batch", "kd_bundle16"};

typedef struct kd_job {
    const kdr_scene *kd;
    const bench_workload *w;
    bench_kd mode;
    kdr_hits out;
    kdr_trav_stats *stats; /* NULL in timed passes, as the daemon calls */
    float *org3;           /* BENCH_KD_BATCH: every ray's origin */
} kd_job;

static void kd_single(const kd_job *j) {
    const bench_workload *w = j->w;
    for (size_t i = 0; i < w->n; i++) {
        if (w->query == KDR_ANY) {
            j->out.hit[i] = (uint8_t)kdr_occluded1(j->kd, &w->rays[i], j->stats);
            continue;
        }
        kdr_hit h;
        kdr_intersect1(j->kd, &w->rays[i], &h, j->stats);
        j->out.t[i] = h.t, j->out.prim[i] = h.prim, j->out.u[i] = h.u, j->out.v[i] = h.v;
    }
}

static void kd_run(void *ctx) {
    kd_job *j = ctx;
    const bench_workload *w = j->w;
    if (j->mode == BENCH_KD_SINGLE) {
        kd_single(j);
        return;
    }
    if (j->mode == BENCH_KD_BATCH) {
        for (size_t first = 0; first < w->n; first += BENCH_BATCH_RAYS) {
            const size_t cnt =
                w->n - first < BENCH_BATCH_RAYS ? w->n - first : BENCH_BATCH_RAYS;
            const kdr_ray_batch b = {cnt,       j->org3 + 3 * first, 3, w->dir + 3 * first,
                                     &w->tmin, 0,                    &w->tmax, 0};
            kdr_hits h = j->out;
            if (w->query == KDR_ANY)
                h.hit += first;
            else
                h.t += first, h.prim += first, h.u += first, h.v += first;
            kdr_trace_batch(j->kd, &b, 0, cnt, w->query, KDR_TRAV_AUTO, &h, j->stats);
        }
        return;
    }
    /* one batch per shared origin (all rays when each has its own) */
    const size_t g = w->group <= 1 ? w->n : w->group;
    for (size_t first = 0; first < w->n; first += g) {
        const size_t cnt = w->n - first < g ? w->n - first : g;
        const float *org =
            w->group == 1 ? w->org : w->org + (w->group ? 3 * (first / g) : 0);
        const kdr_ray_batch b = {cnt, org, w->group == 1 ? 3 : 0, w->dir + 3 * first,
                                 &w->tmin, 0, &w->tmax, 0};
        kdr_hits h = j->out;
        if (w->query == KDR_ANY)
            h.hit += first;
        else
            h.t += first, h.prim += first, h.u += first, h.v += first;
        switch (j->mode) {
        case BENCH_KD_BUNDLE4:
            kdr_trace_batch(j->kd, &b, 0, cnt, w->query, KDR_TRAV_BUNDLE4, &h, j->stats);
            break;
        case BENCH_KD_BUNDLE8:
            kdr_trace_batch(j->kd, &b, 0, cnt, w->query, KDR_TRAV_BUNDLE8, &h, j->stats);
            break;
        case BENCH_KD_BUNDLE16:
            kd_bundle16_trace(j->kd, &b, 0, cnt, w->query, KB_FALLBACK | KB_SORT | KB_LIVE,
                              &h, j->stats);
            break;
        default:
            kd_bundle8_trace(j->kd, &b, 0, cnt, w->query,
                             j->mode == BENCH_KD_SORT8 ? KB_SORT : 0, &h, j->stats);
        }
    }
}

static int kd_job_init(kd_job *j, const bench_scene *s, const bench_workload *w,
                       bench_kd mode) {
    memset(j, 0, sizeof *j);
    j->kd = s->kd, j->w = w, j->mode = mode;
    const size_t n = w->n;
    j->out.t = malloc(n * sizeof(float)), j->out.u = malloc(n * sizeof(float));
    j->out.v = malloc(n * sizeof(float)), j->out.prim = malloc(n * sizeof(int32_t));
    j->out.hit = malloc(n);
    if (mode == BENCH_KD_BATCH) {
        j->org3 = malloc(3 * n * sizeof(float));
        if (!j->org3)
            return -1;
        for (size_t i = 0; i < n; i++)
            memcpy(j->org3 + 3 * i, w->rays[i].org, 12);
    }
    return j->out.t && j->out.u && j->out.v && j->out.prim && j->out.hit ? 0 : -1;
}

static void kd_job_free(kd_job *j) {
    free(j->out.t), free(j->out.u), free(j->out.v), free(j->out.prim), free(j->out.hit);
    free(j->org3);
}

static size_t kd_job_hits(const kd_job *j) {
    size_t h = 0;
    for (size_t i = 0; i < j->w->n; i++)
        h += j->w->query == KDR_ANY ? j->out.hit[i] != 0 : j->out.prim[i] >= 0;
    return h;
}

/* ---- one workload, every method ------------------------------------------------ */

#define MAX_METHODS (8 + RIVAL_MAX_APIS)

int bench_run_workload(const bench_scene *s, const bench_workload *w,
                       const bench_kd *modes, size_t nmodes, const bench_opts *o) {
    kd_job kj[8];
    rival_job rj[RIVAL_MAX_APIS];
    rival_api apis[RIVAL_MAX_APIS];
    bench_method m[MAX_METHODS];
    size_t nk = 0, nr = 0, nm = 0;
    int rc = 0;
    const size_t napi = rival_apis((rival_work)w->work, apis);
    for (size_t i = 0; i < nmodes && nk < 8 && rc == 0; i++) {
        if (modes[i] >= BENCH_KD_BUNDLE8 && modes[i] <= BENCH_KD_RAW8 && !kdr_cpu_has_avx2())
            continue; /* 8-wide needs AVX2: AUTO is 4-wide on this CPU */
        if (modes[i] == BENCH_KD_BUNDLE16 && !kd_cpu_has_avx512())
            continue;
        rc = kd_job_init(&kj[nk], s, w, modes[i]);
        m[nm++] = (bench_method){kd_names[modes[i]], 0, NULL, kd_run, &kj[nk++], 0.0};
    }
    for (size_t i = 0; i < napi && rc == 0; i++) {
        rc = rival_job_init(&rj[nr], s->emb, apis[i], w->query, w->rays, w->n);
        m[nm++] = rival_job_method(&rj[nr++]);
    }
    if (rc == 0)
        bench_measure(m, nm, o->repeat, 0.0);

    uint8_t *hit = malloc(w->n);
    /* kd_single's hit count is the reference, when it ran */
    const size_t ref = nk && kj[0].mode == BENCH_KD_SINGLE && !isnan(m[0].best_ms)
                           ? kd_job_hits(&kj[0]) : 0;
    double best_ms = NAN;
    const char *best = NULL;
    for (size_t i = nk; i < nm; i++)
        if (!isnan(m[i].best_ms) && (!best || m[i].best_ms < best_ms))
            best = m[i].name, best_ms = m[i].best_ms;
    char origins[32];
    snprintf(origins, sizeof origins, "%zu per origin", w->group);
    printf("\n%s: %s, %zu rays (%s, %s)\n", s->name, w->name, w->n,
           w->query == KDR_ANY ? "any hit" : "closest hit",
           w->group == 0 ? "one origin" : w->group == 1 ? "own origins" : origins);
    printf("  %-32s %9s %9s %8s %9s %9s\n", "method", "Mrays/s", "ms", "x best",
           "hits", "nodes/ray");
    for (size_t i = 0; rc == 0 && hit && i < nm; i++) {
        size_t hits;
        double npr = -1.0;
        if (isnan(m[i].best_ms))
            continue; /* left out by --method */
        if (i < nk) {
            hits = kd_job_hits(&kj[i]);
            if (!o->quick) { /* one untimed pass for the node count */
                kdr_trav_stats st = {0};
                kj[i].stats = &st;
                kd_run(&kj[i]);
                kj[i].stats = NULL;
                npr = (double)st.nodes_visited / (double)w->n;
            }
        } else {
            rival_job_answers(&rj[i - nk], hit, NULL);
            hits = 0;
            for (size_t k = 0; k < w->n; k++)
                hits += hit[k];
        }
        printf("  %-32s %9.2f %9.2f %8.2f %9zu", m[i].name,
               (double)w->n / (m[i].best_ms * 1e3), m[i].best_ms, best_ms / m[i].best_ms,
               hits);
        if (npr >= 0)
            printf(" %9.1f", npr);
        printf("%s\n", m[i].name == best ? "  <- best Embree" : "");
        bench_summary_add(s, w->name, m[i].name, w->n, m[i].best_ms, npr);
        if (i < nk && kj[i].mode == BENCH_KD_BATCH && ref) {
            /* the batch path must give kd_single's answers bit for bit */
            size_t bad = 0;
            for (size_t k = 0; k < w->n; k++)
                bad += w->query == KDR_ANY
                           ? kj[i].out.hit[k] != kj[0].out.hit[k]
                           : memcmp(&kj[i].out.t[k], &kj[0].out.t[k], 4) ||
                                 kj[i].out.prim[k] != kj[0].out.prim[k];
            if (bad)
                bench_fail("%s %s: kd_batch differs from kd_single on %zu rays", s->name,
                           w->name, bad);
        }
        const size_t diff = hits > ref ? hits - ref : ref - hits;
        if (ref && (double)diff > HIT_TOLERANCE * (double)w->n)
            bench_fail("%s %s: %s found %zu hits, kd_single %zu", s->name, w->name,
                       m[i].name, hits, ref);
    }
    fflush(stdout);
    free(hit);
    for (size_t i = 0; i < nk; i++)
        kd_job_free(&kj[i]);
    for (size_t i = 0; i < nr; i++)
        rival_job_free(&rj[i]);
    return rc || !hit ? -1 : 0;
}
