/*
 * bench_queries.c — the "queries" section (issue 15): every hit along a ray
 * and hit counts, kdray against the two ways Embree users collect hits, in
 * the same process and run, one thread, CPU time (bench.h's rules):
 *  - capped lists (16 hits per ray): kdr_intersect_all1 against the
 *    re-query loop on the rival's fast scene (closest hit, then again from
 *    the next float past it; oracle_all_requery, which loses hits that
 *    share a t, so it does less work than kdray's exact list);
 *  - every hit (uncapped) and counts: kdr_intersect_all1 with cap 1024 and
 *    kdr_count1 against a context filter that records every hit and
 *    rejects it (oracle_all_filter_into: into one buffer reused for every
 *    ray, sorted for the lists, unsorted for the counts) on the same fast
 *    HIGH-quality BVH with the context-filter flag it needs.
 *  - closest points: kdr_closest_point1 against rtcPointQuery with a
 *    closest-triangle callback (oracle_closest_point: the core's double
 *    distance, the query radius shrunk to each better distance) on the
 *    rival's fast scene; points half on/near the surfaces (offset up to
 *    1e-3 of the diagonal), half uniform in the box. Check: the same
 *    distance for every point, bit for bit.
 *  - occupancy: kdr_occupancy1 against the same 9-ray vote with the
 *    collecting filter (points uniform in the box; answers compared and
 *    the number differing printed: the two triangle tests may disagree on
 *    rays through shared edges, which the vote is there to outvote).
 *    Correctness against the winding number is tests/test_occupancy.c's.
 *  - each list and count kdray's two ways: one ray at a time (kd_all16,
 *    kd_all, kd_count: kdr_intersect_all1, kdr_count1) and through the
 *    batch calls kdrayd makes (the _batch methods: kdr_all_batch,
 *    kdr_count_batch in calls of Q_CHUNK rays with per-ray origins, which
 *    take the interleaved walk on large scenes); the closing table rates
 *    the batch calls.
 * Workloads: "camera" (primary rays from outside through the scene: many
 * surfaces per ray) and "random" (origins in the box). Checks: kdray's hit
 * total equals the filter's within 0.1% (they differ only on rounding
 * cases), and the re-query loop's is no larger than kdray's capped one.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "bench.h"
#include "oracle.h"
#include "rival.h"

#define CAPPED 16u

/* The workload as a batch with per-ray origins and intervals (what a
 * client's request becomes), answered in calls of Q_CHUNK rays into
 * outputs reused for every call. */
#define Q_CHUNK 256

typedef struct q_batch {
    float *org, *dir, *tmin, *tmax;
    uint32_t *nhits;
    float *t, *u, *v;
    int32_t *prim;
} q_batch;

typedef struct q_ctx {
    const bench_scene *s;
    const bench_workload *w;
    const oracle *fast, *filter;
    kdr_hit *buf;
    const q_batch *qb;
    uint64_t hits; /* the last pass's total */
} q_ctx;

/* Whether every method m[idx[0..k-1]] was timed: --method leaves the others
 * out (best_ms NAN), and a check comparing their answers is then skipped,
 * as bench.h promises, instead of failing on answers never computed. */
static int q_ran(const bench_method *m, const int *idx, int k) {
    for (int i = 0; i < k; i++)
        if (isnan(m[idx[i]].best_ms))
            return 0;
    return 1;
}

static void q_batch_free(q_batch *b) {
    free(b->org), free(b->dir), free(b->tmin), free(b->tmax), free(b->nhits);
    free(b->t), free(b->u), free(b->v), free(b->prim);
}

static int q_batch_make(q_batch *b, const bench_workload *w) {
    const size_t n = w->n, slots = (size_t)Q_CHUNK * KDR_MAX_HITS_LIMIT;
    *b = (q_batch){malloc(3 * n * sizeof(float)), malloc(3 * n * sizeof(float)),
                   malloc(n * sizeof(float)), malloc(n * sizeof(float)),
                   malloc(Q_CHUNK * sizeof(uint32_t)), malloc(slots * sizeof(float)),
                   malloc(slots * sizeof(float)), malloc(slots * sizeof(float)),
                   malloc(slots * sizeof(int32_t))};
    if (!b->org || !b->dir || !b->tmin || !b->tmax || !b->nhits || !b->t || !b->u ||
        !b->v || !b->prim) {
        q_batch_free(b);
        return -1;
    }
    for (size_t i = 0; i < n; i++) {
        memcpy(b->org + 3 * i, w->rays[i].org, sizeof w->rays[i].org);
        memcpy(b->dir + 3 * i, w->rays[i].dir, sizeof w->rays[i].dir);
        b->tmin[i] = w->rays[i].tmin;
        b->tmax[i] = w->rays[i].tmax;
    }
    return 0;
}

/* kdr_all_batch (cap > 0) or kdr_count_batch (cap 0) over the workload;
 * returns the hit total. */
static uint64_t kd_batch_pass(const q_ctx *c, uint32_t cap) {
    const q_batch *qb = c->qb;
    uint64_t h = 0;
    for (size_t first = 0; first < c->w->n; first += Q_CHUNK) {
        const size_t m = c->w->n - first < Q_CHUNK ? c->w->n - first : Q_CHUNK;
        const kdr_ray_batch b = {m, qb->org + 3 * first, 3, qb->dir + 3 * first,
                                 qb->tmin + first, 1, qb->tmax + first, 1};
        kdr_all_hits out = {qb->nhits, qb->t, qb->u, qb->v, qb->prim};
        if (cap)
            kdr_all_batch(c->s->kd, &b, 0, m, cap, &out, NULL);
        else
            kdr_count_batch(c->s->kd, &b, 0, m, qb->nhits, NULL);
        for (size_t i = 0; i < m; i++)
            h += qb->nhits[i];
    }
    return h;
}

static void kd_capped_batch(void *p) {
    q_ctx *c = p;
    c->hits = kd_batch_pass(c, CAPPED);
}

static void kd_every_batch(void *p) {
    q_ctx *c = p;
    c->hits = kd_batch_pass(c, KDR_MAX_HITS_LIMIT);
}

static void kd_count_batch(void *p) {
    q_ctx *c = p;
    c->hits = kd_batch_pass(c, 0);
}

static void kd_capped(void *p) {
    q_ctx *c = p;
    uint64_t h = 0;
    for (size_t i = 0; i < c->w->n; i++) {
        uint32_t n = 0;
        kdr_intersect_all1(c->s->kd, &c->w->rays[i], CAPPED, c->buf, &n, NULL);
        h += n;
    }
    c->hits = h;
}

static void kd_every(void *p) {
    q_ctx *c = p;
    uint64_t h = 0;
    for (size_t i = 0; i < c->w->n; i++) {
        uint32_t n = 0;
        kdr_intersect_all1(c->s->kd, &c->w->rays[i], KDR_MAX_HITS_LIMIT, c->buf, &n,
                           NULL);
        h += n;
    }
    c->hits = h;
}

static void kd_count(void *p) {
    q_ctx *c = p;
    uint64_t h = 0;
    for (size_t i = 0; i < c->w->n; i++) {
        uint32_t n = 0;
        kdr_count1(c->s->kd, &c->w->rays[i], &n, NULL);
        h += n;
    }
    c->hits = h;
}

static void emb_requery(void *p) {
    q_ctx *c = p;
    uint64_t h = 0;
    for (size_t i = 0; i < c->w->n; i++)
        h += oracle_all_requery(c->fast, &c->w->rays[i], c->buf, CAPPED);
    c->hits = h;
}

static void emb_filter(void *p) {
    q_ctx *c = p;
    uint64_t h = 0;
    for (size_t i = 0; i < c->w->n; i++)
        h += oracle_all_filter_into(c->filter, &c->w->rays[i], c->buf,
                                    KDR_MAX_HITS_LIMIT, 1);
    c->hits = h;
}

/* The rival of kd_count: the same filter, no sort. */
static void emb_filter_count(void *p) {
    q_ctx *c = p;
    uint64_t h = 0;
    for (size_t i = 0; i < c->w->n; i++)
        h += oracle_all_filter_into(c->filter, &c->w->rays[i], c->buf,
                                    KDR_MAX_HITS_LIMIT, 0);
    c->hits = h;
}

typedef struct cp_ctx {
    const bench_scene *s;
    const oracle *fast;
    const float *pts;
    size_t n;
    float *dist; /* per point, the last pass */
} cp_ctx;

static void kd_closest(void *p) {
    cp_ctx *c = p;
    for (size_t i = 0; i < c->n; i++) {
        kdr_closest r;
        kdr_closest_point1(c->s->kd, c->pts + 3 * i, INFINITY, &r, NULL);
        c->dist[i] = r.distance;
    }
}

static void emb_closest(void *p) {
    cp_ctx *c = p;
    for (size_t i = 0; i < c->n; i++) {
        kdr_closest r;
        oracle_closest_point(c->fast, c->s->tris, c->pts + 3 * i, INFINITY, &r);
        c->dist[i] = r.distance;
    }
}

static int closest_run(const bench_scene *s, const bench_opts *o) {
    const size_t n = o->rays / 4 ? o->rays / 4 : 1;
    float *pts = malloc(3 * n * sizeof *pts), *d0 = malloc(n * sizeof *d0),
          *d1 = malloc(n * sizeof *d1);
    if (!pts || !d0 || !d1) {
        free(pts), free(d0), free(d1);
        return -1;
    }
    kdr_bounds bb;
    kdr_scene_bounds(s->kd, &bb);
    const float diag = kdr_scene_diagonal(s->kd);
    uint64_t x = 0x9e3779b97f4a7c15ull;
    for (size_t i = 0; i < n; i++) {
        float r[6];
        for (int k = 0; k < 6; k++) {
            x ^= x << 13, x ^= x >> 7, x ^= x << 17;
            r[k] = (float)(x >> 40) / 16777216.0f;
        }
        float *p = pts + 3 * i;
        if (i % 2) {
            for (int k = 0; k < 3; k++)
                p[k] = bb.min[k] + (bb.max[k] - bb.min[k]) * r[k];
            continue;
        }
        const float *t = s->tris + 9 * (size_t)(x % s->ntris);
        float a = r[0], b = r[1];
        if (a + b > 1) a = 1 - a, b = 1 - b;
        for (int k = 0; k < 3; k++)
            p[k] = (1 - a - b) * t[k] + a * t[3 + k] + b * t[6 + k] +
                   1e-3f * diag * (r[3 + k] - 0.5f);
    }
    cp_ctx c0 = {s, rival_oracle(s->emb), pts, n, d0}, c1 = c0;
    c1.dist = d1;
    bench_method m[2] = {{"kd_closest", 0, NULL, kd_closest, &c0, 0},
                         {"embree_point_query", BENCH_RIVAL, NULL, emb_closest, &c1, 0}};
    bench_measure(m, 2, o->repeat, 200.0);
    bench_summary_add(s, "closest_point", m[0].name, n, m[0].best_ms, -1.0);
    bench_summary_add(s, "closest_point", m[1].name, n, m[1].best_ms, -1.0);
    size_t differ = 0;
    for (size_t i = 0; i < n; i++)
        differ += d0[i] != d1[i];
    printf("closest  %zu points: kd %.1f ms, rtcPointQuery %.1f ms (kd %.2fx), distances "
           "differing: %zu\n",
           n, m[0].best_ms, m[1].best_ms, m[1].best_ms / m[0].best_ms, differ);
    if (differ && q_ran(m, (const int[]){0, 1}, 2))
        bench_fail("%s: %zu closest-point distances differ from rtcPointQuery's", s->name,
                   differ);
    free(pts), free(d0), free(d1);
    return 0;
}

/* ---- occupancy: kdr_occupancy1 against the same vote with Embree's
 * collecting filter (9 rays, parity of each ray's hit count, majority) ---- */

typedef struct occ_ctx {
    const bench_scene *s;
    const oracle *filter;
    const float *pts;
    size_t n;
    uint8_t *inside;
    kdr_hit *buf;
} occ_ctx;

static void kd_occ(void *p) {
    occ_ctx *c = p;
    for (size_t i = 0; i < c->n; i++)
        kdr_occupancy1(c->s->kd, c->pts + 3 * i, &c->inside[i], NULL, NULL);
}

static void emb_occ(void *p) {
    occ_ctx *c = p;
    for (size_t i = 0; i < c->n; i++) {
        int odd = 0;
        for (int r = 0; r < KDR_OCCUPANCY_RAYS; r++) {
            kdr_ray ray = {{c->pts[3 * i], c->pts[3 * i + 1], c->pts[3 * i + 2]},
                           {0, 0, 0},
                           0.0f,
                           INFINITY};
            kdr_occupancy_direction(r, ray.dir);
            odd +=
                (int)(oracle_all_filter_into(c->filter, &ray, c->buf, KDR_MAX_HITS_LIMIT, 0) &
                      1);
        }
        c->inside[i] = 2 * odd > KDR_OCCUPANCY_RAYS;
    }
}

static int occupancy_run(const bench_scene *s, const bench_opts *o, const oracle *filter,
                         kdr_hit *buf) {
    const size_t n = o->rays / 16 ? o->rays / 16 : 1;
    float *pts = malloc(3 * n * sizeof *pts);
    uint8_t *a = malloc(n), *b = malloc(n);
    if (!pts || !a || !b) {
        free(pts), free(a), free(b);
        return -1;
    }
    kdr_bounds bb;
    kdr_scene_bounds(s->kd, &bb);
    uint64_t x = 0x2545f4914f6cdd1dull;
    for (size_t i = 0; i < 3 * n; i++) {
        x ^= x << 13, x ^= x >> 7, x ^= x << 17;
        const int k = (int)(i % 3);
        pts[i] = bb.min[k] + (bb.max[k] - bb.min[k]) * ((float)(x >> 40) / 16777216.0f);
    }
    occ_ctx c0 = {s, filter, pts, n, a, buf}, c1 = c0;
    c1.inside = b;
    bench_method m[2] = {{"kd_occupancy", 0, NULL, kd_occ, &c0, 0},
                         {"embree_filter_occupancy", BENCH_RIVAL, NULL, emb_occ, &c1, 0}};
    bench_measure(m, 2, o->repeat, 200.0);
    bench_summary_add(s, "occupancy", m[0].name, n, m[0].best_ms, -1.0);
    bench_summary_add(s, "occupancy", m[1].name, n, m[1].best_ms, -1.0);
    size_t differ = 0, inside = 0;
    for (size_t i = 0; i < n; i++) {
        differ += a[i] != b[i];
        inside += a[i];
    }
    printf(
        "occupancy %zu points (%zu inside): kd %.1f ms, Embree filter vote %.1f ms (kd "
        "%.2fx), answers differing: %zu\n",
        n, inside, m[0].best_ms, m[1].best_ms, m[1].best_ms / m[0].best_ms, differ);
    free(pts), free(a), free(b);
    return 0;
}

static const char *const q_workloads[] = {"camera", "random"};
#define NWORK (sizeof q_workloads / sizeof *q_workloads)
#define MAX_SCENES 32
static char g_scene[MAX_SCENES][64];
static int g_nscenes;

static int queries_run(const bench_scene *s, const bench_opts *o) {
    rival *filt = rival_create_filter(s->tris, s->ntris, RIVAL_QUALITY);
    kdr_hit *buf = malloc(KDR_MAX_HITS_LIMIT * sizeof *buf);
    if (!filt || !buf) {
        rival_free(filt);
        free(buf);
        return -1;
    }
    if (g_nscenes < MAX_SCENES)
        snprintf(g_scene[g_nscenes++], sizeof g_scene[0], "%s", s->name);
    printf("\n== %s: %zu triangles, all hits and counts (CPU ms, best of %d)\n", s->name,
           s->ntris, o->repeat);
    int rc = 0;
    for (size_t k = 0; k < NWORK && rc == 0; k++) {
        bench_workload w;
        if (bench_workload_make(&w, s->kd, q_workloads[k], o->rays) != 0) {
            rc = -1;
            break;
        }
        q_batch qb;
        if (q_batch_make(&qb, &w) != 0) {
            bench_workload_free(&w);
            rc = -1;
            break;
        }
        enum { NM = 9 };
        q_ctx ctx[NM];
        for (int m = 0; m < NM; m++)
            ctx[m] = (q_ctx){s, &w, rival_oracle(s->emb), rival_oracle(filt), buf, &qb, 0};
        bench_method m[NM] = {
            {"kd_all16", 0, NULL, kd_capped, &ctx[0], 0},
            {"embree_requery16", BENCH_RIVAL, NULL, emb_requery, &ctx[1], 0},
            {"kd_all", 0, NULL, kd_every, &ctx[2], 0},
            {"kd_count", 0, NULL, kd_count, &ctx[3], 0},
            {"embree_filter_all", BENCH_RIVAL, NULL, emb_filter, &ctx[4], 0},
            {"embree_filter_count", BENCH_RIVAL, NULL, emb_filter_count, &ctx[5], 0},
            {"kd_all16_batch", 0, NULL, kd_capped_batch, &ctx[6], 0},
            {"kd_all_batch", 0, NULL, kd_every_batch, &ctx[7], 0},
            {"kd_count_batch", 0, NULL, kd_count_batch, &ctx[8], 0},
        };
        bench_measure(m, NM, o->repeat, 200.0);
        char wk[64];
        /* lists capped at 16, every hit, counts: each against its own rival */
        static const char *const kinds[NM] = {"all16", "all16", "all", "count", "all",
                                              "count", "all16", "all", "count"};
        for (int i = 0; i < NM; i++) {
            snprintf(wk, sizeof wk, "%s_%s", kinds[i], q_workloads[k]);
            bench_summary_add(s, wk, m[i].name, w.n, m[i].best_ms, -1.0);
        }
        printf("%-8s hits: kd_all16 %llu, requery16 %llu, kd_all %llu, kd_count %llu, "
               "filter %llu, filter count %llu\n",
               q_workloads[k], (unsigned long long)ctx[0].hits,
               (unsigned long long)ctx[1].hits, (unsigned long long)ctx[2].hits,
               (unsigned long long)ctx[3].hits, (unsigned long long)ctx[4].hits,
               (unsigned long long)ctx[5].hits);
        printf("%-8s ms:   kd_all16 %.1f, requery16 %.1f (kd %.2fx) | kd_all %.1f, "
               "kd_count %.1f, filter %.1f, filter count %.1f (kd_all %.2fx, kd_count %.2fx)\n",
               q_workloads[k], m[0].best_ms, m[1].best_ms, m[1].best_ms / m[0].best_ms,
               m[2].best_ms, m[3].best_ms, m[4].best_ms, m[5].best_ms,
               m[4].best_ms / m[2].best_ms, m[5].best_ms / m[3].best_ms);
        printf("%-8s batch ms: kd_all16 %.1f (%.2fx requery16, %.2fx one ray at a time) | "
               "kd_all %.1f (%.2fx filter, %.2fx) | kd_count %.1f (%.2fx filter count, "
               "%.2fx)\n",
               q_workloads[k], m[6].best_ms, m[1].best_ms / m[6].best_ms,
               m[0].best_ms / m[6].best_ms, m[7].best_ms, m[4].best_ms / m[7].best_ms,
               m[2].best_ms / m[7].best_ms, m[8].best_ms, m[5].best_ms / m[8].best_ms,
               m[3].best_ms / m[8].best_ms);
        /* each check only where every method it compares ran (--method) */
        const double d = fabs((double)ctx[2].hits - (double)ctx[4].hits);
        if (q_ran(m, (const int[]){2, 3, 4, 5}, 4) &&
            (ctx[2].hits != ctx[3].hits || d > 0.001 * (double)ctx[4].hits + 2 ||
             ctx[5].hits != ctx[4].hits))
            bench_fail("%s %s: kd_all %llu / kd_count %llu hits vs the filter's %llu",
                       s->name, q_workloads[k], (unsigned long long)ctx[2].hits,
                       (unsigned long long)ctx[3].hits, (unsigned long long)ctx[4].hits);
        if (q_ran(m, (const int[]){0, 2, 3, 6, 7, 8}, 6) &&
            (ctx[6].hits != ctx[0].hits || ctx[7].hits != ctx[2].hits ||
             ctx[8].hits != ctx[3].hits))
            bench_fail("%s %s: batch hit totals %llu / %llu / %llu differ from one ray at "
                       "a time's %llu / %llu / %llu",
                       s->name, q_workloads[k], (unsigned long long)ctx[6].hits,
                       (unsigned long long)ctx[7].hits, (unsigned long long)ctx[8].hits,
                       (unsigned long long)ctx[0].hits, (unsigned long long)ctx[2].hits,
                       (unsigned long long)ctx[3].hits);
        if (q_ran(m, (const int[]){0, 1}, 2) && ctx[1].hits > ctx[0].hits)
            bench_fail(
                "%s %s: the re-query loop found more hits (%llu) than kd_all16 (%llu)",
                s->name, q_workloads[k], (unsigned long long)ctx[1].hits,
                (unsigned long long)ctx[0].hits);
        q_batch_free(&qb);
        bench_workload_free(&w);
    }
    if (rc == 0) rc = occupancy_run(s, o, rival_oracle(filt), buf);
    rival_free(filt);
    free(buf);
    if (rc == 0) rc = closest_run(s, o);
    return rc;
}

static void queries_finish(const bench_opts *o) {
    (void)o;
    printf("\n== all hits: Embree ms / kdray ms (> 1: kdray faster); kdray through "
           "kdr_all_batch / kdr_count_batch\n");
    static const char *const head[8] = {
        "all16 camera (requery)", "all16 random (requery)", "all camera (filter)",
        "all random (filter)",    "count camera (filter)",  "count random (filter)",
        "closest (point query)",  "occupancy (filter)"};
    printf("%-10s", "scene");
    for (int r = 0; r < 8; r++)
        printf(" | %-22s", head[r]);
    printf("\n");
    for (int i = 0; i < g_nscenes; i++) {
        printf("%-10s", g_scene[i]);
        static const char *const rows[8][3] = {
            {"all16_camera", "kd_all16_batch", "embree_requery16"},
            {"all16_random", "kd_all16_batch", "embree_requery16"},
            {"all_camera", "kd_all_batch", "embree_filter_all"},
            {"all_random", "kd_all_batch", "embree_filter_all"},
            {"count_camera", "kd_count_batch", "embree_filter_count"},
            {"count_random", "kd_count_batch", "embree_filter_count"},
            {"closest_point", "kd_closest", "embree_point_query"},
            {"occupancy", "kd_occupancy", "embree_filter_occupancy"}};
        for (int r = 0; r < 8; r++) {
            const double kd = bench_summary_ms(g_scene[i], rows[r][0], rows[r][1]);
            const double em = bench_summary_ms(g_scene[i], rows[r][0], rows[r][2]);
            if (kd > 0 && em > 0)
                printf(" | %22.2f", em / kd);
            else
                printf(" | %22s", "-");
        }
        printf("\n");
    }
}

const bench_section bench_queries_section = {"queries", queries_run, queries_finish};
