/*
 * ab_core.c — kdray_ab: two builds of the kdray core in ONE process, so a
 * change to the core is judged against its parent on the same machine
 * state (bench/ab builds it; read that script first). Revision A's and B's
 * libkdray_core.a are linked side by side with every global symbol renamed
 * to A_... and B_... (objcopy --redefine-syms), and Embree (fast mode,
 * HIGH quality, threads=1, FTZ/DAZ on around its calls only) runs beside
 * them on the same rays.
 *
 * For each ladder scene it builds A's and B's kd-trees and prints their
 * shape (nodes, depth, refs per leaf, SAH cost, bytes per triangle), then
 * for each ray set traces A, B and (single rays only) Embree in rounds,
 * rotating their order every round, and prints the best Mrays/s of each,
 * the median over rounds of the per-round ratio B/A (with its range), kd /
 * Embree, nodes and triangle tests per ray, and how many answers differ
 * between A and B (they must not: every change keeps answers bit for bit).
 *
 * The ray sets and their generators are ab_sets.c's (listed in ab_sets.h);
 * this file holds the two cores' tables, the timing rounds and the driver.
 *
 *   kdray_ab [--dir DIR] [--only NAME]... [--rays N] [--rounds R]
 *            [--set NAME]...
 */
#define _POSIX_C_SOURCE 200809L
#include <embree3/rtcore.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <xmmintrin.h>

#include "ab_sets.h"
#include "kdray.h"
#include "ladder.h"
#include "oracle.h"

/* ---- the two cores ----------------------------------------------------------- */

#define AB_DECLARE(P)                                                           \
    int P##kdr_scene_build(const float *, size_t, const kdr_build_opts *,       \
                           kdr_log_fn, void *, kdr_scene **);                   \
    void P##kdr_scene_free(kdr_scene *);                                        \
    void P##kdr_scene_tree_stats(const kdr_scene *, kdr_tree_stats *);          \
    int P##kdr_intersect1(const kdr_scene *, const kdr_ray *, kdr_hit *,        \
                          kdr_trav_stats *);                                    \
    int P##kdr_occluded1(const kdr_scene *, const kdr_ray *, kdr_trav_stats *); \
    int P##kdr_trace_batch(const kdr_scene *, const kdr_ray_batch *, size_t,    \
                           size_t, kdr_query, kdr_trav_mode, kdr_hits *,        \
                           kdr_trav_stats *);                                   \
    int P##kdr_frustum_trace(const kdr_scene *, const kdr_camera *, uint32_t,   \
                             size_t, size_t, kdr_query, kdr_frustum_mode,       \
                             kdr_hits *, kdr_trav_stats *);                     \
    size_t P##kdr_frustum_tile_count(const kdr_camera *, uint32_t);             \
    int P##kdr_shadow_trace(const kdr_scene *, const kdr_shadow_query *, size_t, \
                            size_t, kdr_shadow_mode, float *, kdr_shadow_stats *); \
    int P##kdr_intersect_all1(const kdr_scene *, const kdr_ray *, uint32_t,     \
                              kdr_hit *, uint32_t *, kdr_trav_stats *);         \
    int P##kdr_count1(const kdr_scene *, const kdr_ray *, uint32_t *,           \
                      kdr_trav_stats *);                                        \
    int P##kdr_closest_point1(const kdr_scene *, const float *, float,          \
                              kdr_closest *, kdr_trav_stats *);                  \
    int P##kdr_all_batch(const kdr_scene *, const kdr_ray_batch *, size_t,      \
                         size_t, uint32_t, kdr_all_hits *, kdr_trav_stats *);   \
    int P##kdr_count_batch(const kdr_scene *, const kdr_ray_batch *, size_t,    \
                           size_t, uint32_t *, kdr_trav_stats *);
AB_DECLARE(A_)
AB_DECLARE(B_)

typedef struct core_api {
    int (*build)(const float *, size_t, const kdr_build_opts *, kdr_log_fn,
                 void *, kdr_scene **);
    void (*release)(kdr_scene *);
    void (*tree_stats)(const kdr_scene *, kdr_tree_stats *);
    int (*intersect1)(const kdr_scene *, const kdr_ray *, kdr_hit *,
                      kdr_trav_stats *);
    int (*occluded1)(const kdr_scene *, const kdr_ray *, kdr_trav_stats *);
    int (*trace_batch)(const kdr_scene *, const kdr_ray_batch *, size_t, size_t,
                       kdr_query, kdr_trav_mode, kdr_hits *, kdr_trav_stats *);
    int (*frustum)(const kdr_scene *, const kdr_camera *, uint32_t, size_t,
                   size_t, kdr_query, kdr_frustum_mode, kdr_hits *,
                   kdr_trav_stats *);
    size_t (*tiles)(const kdr_camera *, uint32_t);
    int (*shadow)(const kdr_scene *, const kdr_shadow_query *, size_t, size_t,
                  kdr_shadow_mode, float *, kdr_shadow_stats *);
    int (*all1)(const kdr_scene *, const kdr_ray *, uint32_t, kdr_hit *, uint32_t *,
                kdr_trav_stats *);
    int (*count1)(const kdr_scene *, const kdr_ray *, uint32_t *, kdr_trav_stats *);
    int (*closest1)(const kdr_scene *, const float *, float, kdr_closest *,
                    kdr_trav_stats *);
    int (*all_batch)(const kdr_scene *, const kdr_ray_batch *, size_t, size_t,
                     uint32_t, kdr_all_hits *, kdr_trav_stats *);
    int (*count_batch)(const kdr_scene *, const kdr_ray_batch *, size_t, size_t,
                       uint32_t *, kdr_trav_stats *);
} core_api;

#define AB_API(P)                                                               \
    {P##kdr_scene_build,  P##kdr_scene_free,    P##kdr_scene_tree_stats,        \
     P##kdr_intersect1,   P##kdr_occluded1,     P##kdr_trace_batch,             \
     P##kdr_frustum_trace, P##kdr_frustum_tile_count, P##kdr_shadow_trace,     \
     P##kdr_intersect_all1, P##kdr_count1, P##kdr_closest_point1,               \
     P##kdr_all_batch, P##kdr_count_batch}
static const core_api cores[2] = {AB_API(A_), AB_API(B_)};

/* ---- clocks ------------------------------------------------------------------ */

static double cpu_s(void) {
    struct timespec ts;
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

/* ---- one ray set, traced by A, B and Embree -------------------------------- */

typedef struct job {
    int set;
    kdr_query q;
    const kdr_ray *rays;
    size_t n, group; /* batches: rays per kdr_trace_batch call (shared origin) */
    const kdr_camera *cam;
    float *bdir; /* batch directions, 3n */
    float *borg, *btmin, *btmax; /* b* sets: origins (3n), tmin, tmax (n) */
    const kdr_shadow_query *sq; /* cone sets: n = points * samples */
} job;

typedef struct result {
    float *t;
    int32_t *prim;
    float *u, *v;
    uint8_t *hit;
} result;

/* FNV-1a over the bits of n hits (the query sets' answer digest). */
static uint32_t hits_hash(const kdr_hit *h, uint32_t n) {
    uint32_t x = 2166136261u;
    const unsigned char *b = (const unsigned char *)h;
    for (size_t i = 0; i < n * sizeof *h; i++)
        x = (x ^ b[i]) * 16777619u;
    return x;
}

/* Rays per kdr_all_batch / kdr_count_batch call in the ball16, ball and
 * bcount sets: the daemon's calls for these queries (exec/ chunks of 256). */
#define AB_QUERY_BATCH 256

/* The batch forms of issue 15's sets: the same columns as trace_query
 * (prim = number of hits, t = a hash of the hits), the hash taken over
 * the batch's t, prim, u, v arrays of each ray. */
static void trace_query_batch(const core_api *c, const kdr_scene *s, const job *j,
                              result *o, kdr_trav_stats *st) {
    const uint32_t cap = j->set == SET_BALL16 ? 16 : KDR_MAX_HITS_LIMIT;
    static uint32_t nh[AB_QUERY_BATCH];
    static float t[AB_QUERY_BATCH * KDR_MAX_HITS_LIMIT];
    static float u[AB_QUERY_BATCH * KDR_MAX_HITS_LIMIT];
    static float v[AB_QUERY_BATCH * KDR_MAX_HITS_LIMIT];
    static int32_t prim[AB_QUERY_BATCH * KDR_MAX_HITS_LIMIT];
    for (size_t first = 0; first < j->n; first += AB_QUERY_BATCH) {
        const size_t g = j->n - first < AB_QUERY_BATCH ? j->n - first : AB_QUERY_BATCH;
        /* a batch of this call's rays alone: answers go to slot i of ray
         * first + i, so the buffers hold one call */
        kdr_ray_batch b = {g,           j->borg + 3 * first, 3, j->bdir + 3 * first,
                           j->btmin + first, 1, j->btmax + first, 1};
        if (j->set == SET_BCOUNT) {
            c->count_batch(s, &b, 0, g, nh, st);
        } else {
            kdr_all_hits h = {nh, t, u, v, prim};
            c->all_batch(s, &b, 0, g, cap, &h, st);
        }
        for (size_t i = 0; i < g; i++) {
            uint32_t x = 2166136261u;
            if (j->set != SET_BCOUNT) {
                const float *cols[3] = {t + i * cap, u + i * cap, v + i * cap};
                for (int k = 0; k < 4; k++) {
                    const unsigned char *p =
                        k < 3 ? (const unsigned char *)cols[k]
                              : (const unsigned char *)(prim + i * cap);
                    for (size_t q = 0; q < 4 * (size_t)nh[i]; q++)
                        x = (x ^ p[q]) * 16777619u;
                }
            }
            o->prim[first + i] = (int32_t)nh[i];
            memcpy(&o->t[first + i], &x, 4);
        }
    }
}

/* Issue 15's sets: per query, prim = number of hits (closest: the prim) and
 * t = the hash of the hits (closest: the distance). */
static void trace_query(const core_api *c, const kdr_scene *s, const job *j,
                        result *o, kdr_trav_stats *st) {
    static kdr_hit buf[KDR_MAX_HITS_LIMIT];
    if (j->set >= SET_BALL16) {
        trace_query_batch(c, s, j, o, st);
        return;
    }
    for (size_t i = 0; i < j->n; i++) {
        uint32_t n = 0, h = 0;
        if (j->set == SET_CLOSEST) {
            kdr_closest r;
            c->closest1(s, j->borg + 3 * i, INFINITY, &r, st);
            o->prim[i] = r.prim;
            o->t[i] = r.distance;
            continue;
        }
        if (j->set == SET_COUNT) {
            c->count1(s, &j->rays[i], &n, st);
        } else {
            c->all1(s, &j->rays[i], j->set == SET_ALL16 ? 16 : KDR_MAX_HITS_LIMIT, buf,
                    &n, st);
            h = hits_hash(buf, n);
        }
        o->prim[i] = (int32_t)n;
        memcpy(&o->t[i], &h, 4);
    }
}

static void trace_kd(const core_api *c, const kdr_scene *s, const job *j,
                     result *o, kdr_trav_stats *st) {
    if (j->set >= SET_ALL16) {
        trace_query(c, s, j, o, st);
        return;
    }
    if (j->sq) { /* visibility per point, as the t column */
        kdr_shadow_stats ss = {0, 0, 0};
        c->shadow(s, j->sq, 0, j->sq->n, KDR_SHADOW_CONE, o->t, &ss);
        st->rays += j->n;
        st->nodes_visited += ss.nodes_visited;
        st->tri_tests += ss.rays_traced;
        return;
    }
    if (j->set == SET_FRUSTUM) {
        kdr_hits h = {o->t, o->prim, o->u, o->v, o->hit};
        c->frustum(s, j->cam, 8, 0, c->tiles(j->cam, 8), j->q, KDR_FRUSTUM_MULTI4,
                   &h, st);
        return;
    }
    if (j->set == SET_B8AO || j->set == SET_B8AO8 || j->set == SET_B8CAM ||
        j->set == SET_B16CAM) {
        const kdr_trav_mode mode = j->set == SET_B8AO8 ? KDR_TRAV_BUNDLE8 : KDR_TRAV_AUTO;
        for (size_t first = 0; first < j->n; first += j->group) {
            const size_t g = j->n - first < j->group ? j->n - first : j->group;
            const kdr_ray *r0 = &j->rays[first];
            kdr_ray_batch b = {g, r0->org, 0, j->bdir + 3 * first,
                               &r0->tmin, 0, &r0->tmax, 0};
            kdr_hits h = {o->t + first, o->prim + first, o->u + first,
                          o->v + first, o->hit + first};
            c->trace_batch(s, &b, 0, g, j->q, mode, &h, st);
        }
        return;
    }
    if (j->set >= SET_BRANDOM) {
        for (size_t first = 0; first < j->n; first += AB_BATCH) {
            const size_t g = j->n - first < AB_BATCH ? j->n - first : AB_BATCH;
            kdr_ray_batch b = {j->n, j->borg, 3, j->bdir, j->btmin, 1, j->btmax, 1};
            kdr_hits h = {o->t, o->prim, o->u, o->v, o->hit};
            c->trace_batch(s, &b, first, g, j->q, KDR_TRAV_AUTO, &h, st);
        }
        return;
    }
    for (size_t i = 0; i < j->n; i++) {
        if (j->q == KDR_ANY) {
            o->hit[i] = (uint8_t)c->occluded1(s, &j->rays[i], st);
        } else {
            kdr_hit h;
            c->intersect1(s, &j->rays[i], &h, st);
            o->t[i] = h.t, o->prim[i] = h.prim;
        }
    }
}

static void trace_embree(RTCScene sc, const job *j) {
    const unsigned csr = _mm_getcsr();
    _mm_setcsr(csr | 0x8040); /* FTZ | DAZ: Embree's recommended mode */
    struct RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    for (size_t i = 0; i < j->n; i++) {
        const kdr_ray *r = &j->rays[i];
        struct RTCRayHit rh;
        rh.ray.org_x = r->org[0], rh.ray.org_y = r->org[1], rh.ray.org_z = r->org[2];
        rh.ray.dir_x = r->dir[0], rh.ray.dir_y = r->dir[1], rh.ray.dir_z = r->dir[2];
        rh.ray.tnear = r->tmin, rh.ray.tfar = r->tmax, rh.ray.time = 0.0f;
        rh.ray.mask = 0xFFFFFFFFu, rh.ray.id = 0, rh.ray.flags = 0;
        if (j->q == KDR_ANY) {
            rtcOccluded1(sc, &ctx, &rh.ray);
        } else {
            rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
            rtcIntersect1(sc, &ctx, &rh);
        }
    }
    _mm_setcsr(csr);
}

static int cmp_double(const void *a, const void *b) {
    const double x = *(const double *)a, y = *(const double *)b;
    return x < y ? -1 : x > y;
}

static size_t result_diffs(const job *j, const result *a, const result *b) {
    size_t d = 0;
    if (j->sq) {
        for (size_t i = 0; i < j->sq->n; i++)
            d += memcmp(&a->t[i], &b->t[i], 4) != 0;
        return d;
    }
    for (size_t i = 0; i < j->n; i++) {
        if (j->q == KDR_ANY)
            d += a->hit[i] != b->hit[i];
        else
            d += a->prim[i] != b->prim[i] || memcmp(&a->t[i], &b->t[i], 4) != 0;
    }
    return d;
}

static void result_copy(const job *j, const result *from, result *to) {
    memcpy(to->t, from->t, j->n * 4);
    memcpy(to->prim, from->prim, j->n * 4);
    memcpy(to->hit, from->hit, j->n);
}

/* Both cores write into the same buffers (out[2]), so that neither gains
 * from where its outputs happen to live; the first round's answers are
 * copied to out[0] and out[1] for the comparison. */
static void run_job(const job *j, kdr_scene *const kd[2], RTCScene sc, int rounds,
                    result out[3]) {
    const int emb = set_embree[j->set];
    double best[3] = {INFINITY, INFINITY, INFINITY};
    double ratio_ba[64], ratio_ae[64], ratio_be[64];
    kdr_trav_stats st[2];
    if (rounds > 64)
        rounds = 64;
    for (int r = 0; r < rounds; r++) {
        double sec[3] = {0, 0, 0};
        for (int k = 0; k < 3; k++) {
            const int who = (r + k) % 3;
            if (who == 2 && !emb)
                continue;
            const double t0 = cpu_s();
            if (who == 2) {
                trace_embree(sc, j);
            } else {
                memset(&st[who], 0, sizeof st[who]);
                trace_kd(&cores[who], kd[who], j, &out[2], &st[who]);
            }
            sec[who] = cpu_s() - t0;
            if (r == 0 && who < 2)
                result_copy(j, &out[2], &out[who]);
            best[who] = sec[who] < best[who] ? sec[who] : best[who];
        }
        ratio_ba[r] = sec[0] / sec[1];
        ratio_ae[r] = emb ? sec[2] / sec[0] : 0;
        ratio_be[r] = emb ? sec[2] / sec[1] : 0;
    }
    qsort(ratio_ba, (size_t)rounds, sizeof(double), cmp_double);
    qsort(ratio_ae, (size_t)rounds, sizeof(double), cmp_double);
    qsort(ratio_be, (size_t)rounds, sizeof(double), cmp_double);
    const double mr = (double)j->n * 1e-6;
    printf("  %-8s %8.2f %8.2f %8.2f | %5.3f (%5.3f-%5.3f)", set_names[j->set],
           mr / best[0], mr / best[1], emb ? mr / best[2] : 0.0,
           ratio_ba[rounds / 2], ratio_ba[0], ratio_ba[rounds - 1]);
    if (emb)
        printf(" | %5.3f %5.3f", ratio_ae[rounds / 2], ratio_be[rounds / 2]);
    else
        printf(" | %5s %5s", "-", "-");
    const double ra = st[0].rays ? (double)st[0].rays : 1.0;
    const double rb = st[1].rays ? (double)st[1].rays : 1.0;
    printf(" | %6.1f %6.1f %6.1f %6.1f | %zu\n", (double)st[0].nodes_visited / ra,
           (double)st[1].nodes_visited / rb, (double)st[0].tri_tests / ra,
           (double)st[1].tri_tests / rb, result_diffs(j, &out[0], &out[1]));
    fflush(stdout);
}

/* ---- driver ----------------------------------------------------------------------- */

typedef struct opts {
    const char *dir;
    const char *only[16];
    int nonly;
    int sets; /* bit mask */
    size_t rays;
    int rounds;
} opts;

static void print_tree(const char *who, const kdr_tree_stats *t, double ms,
                       size_t ntris) {
    printf("  %s: build %.0f ms, %llu nodes, %llu leaves (%llu empty), depth %llu,"
           " %.2f refs/leaf, %.2f refs/tri, SAH %.1f, %.1f B/tri\n",
           who, ms, (unsigned long long)t->nodes, (unsigned long long)t->leaves,
           (unsigned long long)t->empty_leaves, (unsigned long long)t->max_depth,
           t->refs_per_leaf, (double)t->refs / (double)(ntris ? ntris : 1),
           t->sah_cost, (double)t->bytes / (double)(ntris ? ntris : 1));
}

static int run_scene(const opts *o, const ladder_entry *e) {
    char err[512];
    float *tris;
    size_t ntris;
    if (ladder_load(e, &tris, &ntris, err, sizeof err) != 0) {
        fprintf(stderr, "%s\n", err);
        return -1;
    }
    scene_in si = {tris, ntris, {0}, {0}, 0};
    scene_bounds(&si);
    printf("%s (%zu triangles)\n", e->name, ntris);
    kdr_scene *kd[2] = {NULL, NULL};
    for (int c = 0; c < 2; c++) {
        const double t0 = cpu_s();
        if (cores[c].build(tris, ntris, NULL, NULL, NULL, &kd[c]) != KDR_OK) {
            fprintf(stderr, "%s: build failed\n", e->name);
            return -1;
        }
        kdr_tree_stats ts;
        cores[c].tree_stats(kd[c], &ts);
        print_tree(c ? "B" : "A", &ts, (cpu_s() - t0) * 1e3, ntris);
    }
    oracle_opts oo;
    oracle_opts_default(&oo);
    oo.robust = 0;
    oo.quality = RTC_BUILD_QUALITY_HIGH;
    oo.device_config = "threads=1";
    oracle *orc = oracle_create(tris, ntris, &oo);
    const size_t n = o->rays;
    kdr_ray *rays = malloc(n * sizeof *rays);
    float *bdir = malloc(3 * n * sizeof *bdir);
    float *borg = malloc(3 * n * sizeof *borg);
    float *btmin = malloc(n * sizeof *btmin), *btmax = malloc(n * sizeof *btmax);
    result out[3];
    for (int c = 0; c < 3; c++) {
        out[c].t = malloc(n * 4), out[c].prim = malloc(n * 4);
        out[c].u = malloc(n * 4), out[c].v = malloc(n * 4);
        out[c].hit = malloc(n);
    }
    printf("  %-8s %8s %8s %8s | %-19s | %5s %5s | %6s %6s %6s %6s | %s\n", "set",
           "A Mr/s", "B Mr/s", "emb", "B/A med (range)", "A/emb", "B/emb",
           "nodeA", "nodeB", "testA", "testB", "diff");
    kdr_camera cam;
    camera_of(&si, n, &cam);
    for (int set = 0; set < NSETS; set++) {
        if (!((o->sets >> set) & 1))
            continue;
        job j = {set, KDR_CLOSEST, rays, n, n, &cam, bdir, borg, btmin, btmax, NULL};
        kdr_sphere_light li;
        switch (set) {
        case SET_CAMERA:
        case SET_FRUSTUM:
            j.n = camera_rays(&cam, 0, rays);
            break;
        case SET_B8CAM:
            j.n = camera_rays(&cam, 1, rays);
            break;
        case SET_B16CAM:
            j.n = camera_rays(&cam, 2, rays);
            break;
        case SET_RANDOM:
        case SET_BRANDOM:
        case SET_ALL:
        case SET_COUNT:
        case SET_BALL:
        case SET_BCOUNT:
            random_rays(&si, n, rays);
            break;
        case SET_ALL16:
        case SET_BALL16:
            j.n = camera_rays(&cam, 0, rays);
            break;
        case SET_CLOSEST:
            break; /* points: below */
        case SET_AO:
        case SET_BAO:
            ao_rays(&si, n, 16, rays), j.q = KDR_ANY;
            break;
        case SET_BAOC:
            ao_rays(&si, n, 16, rays);
            break;
        case SET_CAMSHADOW:
            light_of(&si, 0, &li);
            j.n = camshadow_rays(&si, cores[0].intersect1, kd[0], n, &li, rays);
            j.q = KDR_ANY;
            break;
        case SET_BAO1:
            ao_rays(&si, n, 1, rays), j.q = KDR_ANY;
            break;
        case SET_BCAMLARGE:
            light_of(&si, 1, &li);
            j.n = camshadow_rays(&si, cores[0].intersect1, kd[0], n, &li, rays);
            j.q = KDR_ANY;
            break;
        case SET_SHADOW:
        case SET_BSHADOW:
            light_of(&si, 0, &li);
            shadow_rays(&si, n, 1, &li, rays), j.q = KDR_ANY;
            break;
        case SET_BSHADOW16:
            light_of(&si, 0, &li);
            shadow_rays(&si, n, 16, &li, rays), j.q = KDR_ANY;
            break;
        default: /* ao64, b8ao, b8ao8, bao64 */
            ao_rays(&si, n, 64, rays), j.q = KDR_ANY, j.group = 64;
            break;
        }
        kdr_shadow_query sq;
        if (set == SET_CONE16 || set == SET_CONE64) {
            const int large = set == SET_CONE64;
            const uint32_t spp = large ? 64 : 16;
            cone_query(&si, n / spp, large, spp, rays, bdir, &li, &sq);
            j.sq = &sq;
            j.n = sq.n * spp;
        } else if (set == SET_CONECAM) {
            conecam_query(&si, cores[0].intersect1, kd[0], n / 64, bdir, &li, &sq);
            j.sq = &sq;
            j.n = sq.n * 64;
        } else if (set == SET_CLOSEST) {
            closest_points(&si, n, borg);
        } else {
            for (size_t i = 0; i < j.n; i++) {
                memcpy(bdir + 3 * i, rays[i].dir, 12);
                memcpy(borg + 3 * i, rays[i].org, 12);
                btmin[i] = rays[i].tmin, btmax[i] = rays[i].tmax;
            }
        }
        run_job(&j, kd, oracle_rtc_scene(orc), o->rounds, out);
    }
    for (int c = 0; c < 2; c++)
        cores[c].release(kd[c]);
    for (int c = 0; c < 3; c++) {
        free(out[c].t), free(out[c].prim), free(out[c].u), free(out[c].v);
        free(out[c].hit);
    }
    oracle_free(orc);
    free(rays);
    free(bdir);
    free(borg), free(btmin), free(btmax);
    free(tris);
    return 0;
}

static int parse(int argc, char **argv, opts *o) {
    o->dir = ladder_default_dir();
    o->rays = 262144;
    o->rounds = 5;
    o->sets = 0;
    for (int i = 1; i + 1 < argc; i += 2) {
        const char *f = argv[i], *v = argv[i + 1];
        if (strcmp(f, "--dir") == 0)
            o->dir = v;
        else if (strcmp(f, "--only") == 0 && o->nonly < 16)
            o->only[o->nonly++] = v;
        else if (strcmp(f, "--rays") == 0)
            o->rays = strtoul(v, NULL, 10);
        else if (strcmp(f, "--rounds") == 0)
            o->rounds = atoi(v);
        else if (strcmp(f, "--set") == 0) {
            int k = 0;
            while (k < NSETS && strcmp(set_names[k], v) != 0)
                k++;
            if (k == NSETS)
                return -1;
            o->sets |= 1 << k;
        } else
            return -1;
    }
    if (argc % 2 == 0 || o->rays == 0 || o->rounds < 1 || !o->dir)
        return -1;
    if (!o->sets)
        o->sets = DEFAULT_SETS;
    return 0;
}

int main(int argc, char **argv) {
    opts o;
    memset(&o, 0, sizeof o);
    if (parse(argc, argv, &o) != 0) {
        fprintf(stderr, "usage: %s [--dir DIR] [--only NAME]... [--rays N] "
                        "[--rounds R] [--set camera|random|ao|ao64|b8ao|b8cam|"
                        "frustum|cone16|cone64|shadow|camshadow|brandom|bao|baoc|bshadow|conecam|b8ao8|bao64|bao1|all16|all|"
                        "count|closest|ball16|ball|bcount]...\n", argv[0]);
        return 2;
    }
    ladder_entry *v;
    char err[512];
    const int n = ladder_read(o.dir, &v, err, sizeof err);
    if (n < 0) {
        fprintf(stderr, "%s\n", err);
        return 1;
    }
    int fail = 0;
    for (int i = 0; i < n; i++) {
        int sel = o.nonly == 0;
        for (int k = 0; k < o.nonly; k++)
            sel |= strcmp(o.only[k], v[i].name) == 0;
        if (sel)
            fail |= run_scene(&o, &v[i]) != 0;
    }
    free(v);
    return fail;
}
