/*
 * test_batch_route.c — where kdr_trace_batch sends a 256-ray chunk
 * (kd_batch_scattered in core/kd_batch.c): bundles, or the interleaved walk
 * of kd_stream.h. The answers are the same either way (test_bundle checks
 * them), so only the route shows the rule; it is read twice: from
 * kd_batch_scattered itself and from kdr_trav_stats.fallbacks of a
 * kdr_trace_batch call (one per bundle-sized group the walk traced).
 *
 * The rule under test (docs/TRAVERSAL.md, "Where kdr_trace_batch uses
 * it"): incoherent rays whose origins change at least every
 * KD_STREAM_MAX_RUN rays go to the walk on any scene; runs of a shared
 * origin (AO rays of many points) go there only on scenes of
 * KD_STREAM_RUNS_MIN_BYTES and more; a chunk with ONE origin (stride 0, or
 * stride 3 with every origin equal: a cone's samples of one point) stays
 * with bundles even on such a scene, because there the walk lost.
 * Also kd_batch_runs_fit, which lets the bundle driver skip ordering a
 * chunk whose bundles already hold whole runs of one origin, and
 * kd_batch_far_first, which offers any-hit chunks whose ends cluster
 * (shadow rays of many points toward one light) the far end first order,
 * and kd_far_pick, which takes it where the call's probe measured it
 * cheaper; chunks whose ends spread (AO) walk far end first in the
 * interleaved walk, where kd_batch_scattered_any sends their runs of
 * shared origins from KD_FAR_RUNS_MIN_BYTES on.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "kd_internal.h"
#include "kd_traverse_bundle.h"
#include "kd_tune.h"
#include "kdray.h"
#include "check.h"

#define PI 3.14159265358979323846

static uint64_t g_rng = 0x2545F4914F6CDD1Dull;

static float rnd01(void) {
    g_rng ^= g_rng << 13, g_rng ^= g_rng >> 7, g_rng ^= g_rng << 17;
    return (float)(g_rng >> 40) * 0x1p-24f;
}

/* A soup of n small triangles in [-1, 1]^3 (sizes 0.01-0.03). */
static float *make_soup(size_t n) {
    float *t = malloc(n * 9 * sizeof(float));
    for (size_t i = 0; i < n; i++) {
        float c[3];
        for (int k = 0; k < 3; k++)
            c[k] = 2.0f * rnd01() - 1.0f;
        const float size = 0.01f + 0.02f * rnd01();
        for (int j = 0; j < 3; j++)
            for (int k = 0; k < 3; k++)
                t[9 * i + 3 * j + k] = c[k] + size * (2.0f * rnd01() - 1.0f);
    }
    return t;
}

/* A chunk of KB_CHUNK rays with directions spread over the sphere in the
 * caller's order (a mean spread per 8 rays far above KB_SORT_SPREAD). The
 * origins: one point for all (run = KB_CHUNK), runs of run rays sharing a
 * point, or (run = 1) a point per ray. */
typedef struct chunk {
    float org[3 * KB_CHUNK], dir[3 * KB_CHUNK], tmin[KB_CHUNK], tmax[KB_CHUNK];
    kdr_ray_batch b;
} chunk;

static void make_chunk(chunk *c, int run) {
    float p[3] = {0};
    for (int i = 0; i < KB_CHUNK; i++) {
        if (i % run == 0)
            for (int k = 0; k < 3; k++)
                p[k] = 1.6f * rnd01() - 0.8f;
        memcpy(c->org + 3 * i, p, sizeof p);
        const float z = 2.0f * rnd01() - 1.0f, ph = (float)(2.0 * PI) * rnd01();
        const float r = sqrtf(1.0f - z * z);
        c->dir[3 * i] = r * cosf(ph);
        c->dir[3 * i + 1] = r * sinf(ph);
        c->dir[3 * i + 2] = z;
        c->tmin[i] = 0.0f;
        c->tmax[i] = INFINITY;
    }
    c->b = (kdr_ray_batch){KB_CHUNK, c->org, 3, c->dir, c->tmin, 1, c->tmax, 1};
}

/* Checks one chunk's route: want_walk 1 = the interleaved walk, 0 =
 * bundles. Stride 3 unless shared (stride 0, only for run = KB_CHUNK). */
static void check_route(const char *scene, const kdr_scene *s, const char *what, int run,
                        int shared, int want_walk) {
    chunk *c = malloc(sizeof *c);
    make_chunk(c, run);
    if (shared) c->b.org_stride = 0;
    const int scattered = kd_batch_scattered(s, &c->b, 0, KB_CHUNK);
    float t[KB_CHUNK], u[KB_CHUNK], v[KB_CHUNK];
    int32_t prim[KB_CHUNK];
    uint8_t hit[KB_CHUNK];
    kdr_hits h = {t, prim, u, v, hit};
    kdr_trav_stats st = {0};
    const int rc =
        kdr_trace_batch(s, &c->b, 0, KB_CHUNK, KDR_CLOSEST, KDR_TRAV_AUTO, &h, &st);
    /* the walk's groups are AUTO's bundle width's (16 with AVX-512, 8 with
     * AVX2, else 4) */
    const uint64_t width = kd_cpu_has_avx512() ? 16 : kdr_cpu_has_avx2() ? 8 : 4;
    /* the walk route traces every group there; bundles trace KB_PROBE
     * bundles at least before a failed probe may send the rest there */
    const uint64_t all = KB_CHUNK / width;
    const int fb_ok = want_walk ? st.fallbacks == all : st.fallbacks <= all - KB_PROBE;
    size_t hits = 0;
    for (int i = 0; i < KB_CHUNK; i++)
        hits += prim[i] >= 0;
    const int ok = rc == KDR_OK && scattered == want_walk && fb_ok && st.rays == KB_CHUNK;
    printf("%-5s %-30s scattered %d, fallbacks %llu of %llu groups, %zu hits: %s\n",
           scene, what, scattered, (unsigned long long)st.fallbacks,
           (unsigned long long)all, hits, ok ? "ok" : "FAIL");
    if (!ok) {
        fprintf(stderr, "FAIL %s/%s: route %s, want %s (rc %d, rays %llu)\n", scene, what,
                scattered ? "walk" : "bundles", want_walk ? "walk" : "bundles", rc,
                (unsigned long long)st.rays);
        failures++;
    }
    free(c);
}

/* The any-hit route of AO-like chunks (ends spread around the origins,
 * tmax `reach`; kd_batch_scattered_any): want_walk 1 = the interleaved
 * walk (where they walk far end first), 0 = bundles; read from
 * kd_batch_scattered_any and from an any-hit kdr_trace_batch call's
 * fallbacks. want_closest: kd_batch_scattered's (closest-hit) verdict,
 * which must not move. */
static void check_route_any(const char *scene, const kdr_scene *s, const char *what,
                            int run, float reach, int want_walk, int want_closest) {
    chunk *c = malloc(sizeof *c);
    make_chunk(c, run);
    for (int i = 0; i < KB_CHUNK; i++)
        c->tmax[i] = reach;
    const int walk = kd_batch_scattered_any(s, &c->b, 0, KB_CHUNK);
    const int closest = kd_batch_scattered(s, &c->b, 0, KB_CHUNK);
    uint8_t hit[KB_CHUNK];
    kdr_hits h = {NULL, NULL, NULL, NULL, hit};
    kdr_trav_stats st = {0};
    const int rc = kdr_trace_batch(s, &c->b, 0, KB_CHUNK, KDR_ANY, KDR_TRAV_AUTO, &h, &st);
    const uint64_t width = kd_cpu_has_avx512() ? 16 : kdr_cpu_has_avx2() ? 8 : 4;
    const uint64_t all = KB_CHUNK / width;
    const int fb_ok = want_walk ? st.fallbacks == all : st.fallbacks <= all - KB_PROBE;
    const int ok = rc == KDR_OK && walk == want_walk && closest == want_closest && fb_ok &&
                   st.rays == KB_CHUNK;
    printf("%-5s any hit, %-27s walk %d (closest hit %d), fallbacks %llu of %llu groups: "
           "%s\n",
           scene, what, walk, closest, (unsigned long long)st.fallbacks,
           (unsigned long long)all, ok ? "ok" : "FAIL");
    if (!ok) {
        fprintf(stderr, "FAIL any %s/%s: walk %d closest %d, want %d %d (rc %d)\n", scene,
                what, walk, closest, want_walk, want_closest, rc);
        failures++;
    }
    free(c);
}

/* kd_batch_runs_fit (the bundle driver skips kd_batch_order where it says
 * 1): its answer for a chunk of runs of `run` rays seen from ray `skip` on
 * at bundle width w, and, where it says 1, the property the skip relies
 * on: kd_batch_order keeps every group of w consecutive rays (a bundle)
 * the same set of rays, only permuted. */
static void check_runs_fit(int run, int shared, size_t skip, size_t w, int want) {
    chunk *c = malloc(sizeof *c);
    make_chunk(c, run);
    if (shared) c->b.org_stride = 0;
    const size_t n = KB_CHUNK - skip;
    size_t ids[KB_CHUNK], sorted[KB_CHUNK];
    for (size_t i = 0; i < n; i++)
        ids[i] = sorted[i] = skip + i;
    const int fit = kd_batch_runs_fit(&c->b, ids, n, w);
    kd_batch_order(&c->b, n, 1, sorted);
    int moved = 0, permuted = 0; /* rays that left their group / changed place */
    for (size_t i = 0; i < n; i++) {
        moved += (sorted[i] - skip) / w != i / w;
        permuted += sorted[i] != ids[i];
    }
    const int ok = fit == want && (!fit || moved == 0);
    printf("runs of %3d%s from ray %zu, width %2zu: fit %d (want %d), order moves %d rays"
           " across bundles, %d in all: %s\n",
           run, shared ? " (stride 0)" : "", skip, w, fit, want, moved, permuted,
           ok ? "ok" : "FAIL");
    if (!ok) {
        fprintf(stderr, "FAIL runs_fit: runs of %d from %zu, width %zu\n", run, skip, w);
        failures++;
    }
    free(c);
}

/* kd_batch_far_first's verdict (any-hit chunks walked far end first) for
 * a chunk of make_chunk's origins whose rays run either toward a small
 * ball (a light at y = 3, radius 0.05: ends that cluster) or along
 * make_chunk's directions for `reach` (AO-like: ends spread as the
 * origins do); then one ray's tmax made +inf (no finite end), or the
 * tmax array dropped (every tmax +inf). */
enum { END_LIGHT, END_REACH, END_BIG_LIGHT };
static void check_far_first(const kdr_scene *s, const char *what, int run, int shared,
                            int ends, float reach, int inf_at, int no_tmax, int want) {
    chunk *c = malloc(sizeof *c);
    make_chunk(c, run);
    if (shared) c->b.org_stride = 0;
    for (int i = 0; i < KB_CHUNK; i++) {
        const float *o = c->org + (shared ? 0 : 3 * i);
        float *d = c->dir + 3 * i;
        if (ends != END_REACH) {
            const float light[3] = {0.0f, 3.0f, 0.0f};
            const float radius = ends == END_LIGHT ? 0.05f : 1.5f;
            for (int k = 0; k < 3; k++)
                d[k] = light[k] + radius * d[k] - o[k];
            c->tmin[i] = 1e-4f, c->tmax[i] = 1.0f;
        } else {
            c->tmin[i] = 0.0f, c->tmax[i] = reach;
        }
    }
    if (inf_at >= 0) c->tmax[inf_at] = INFINITY;
    if (no_tmax) c->b.tmax = NULL;
    const int got = kd_batch_far_first(s, &c->b, NULL, 0, KB_CHUNK);
    size_t ids[KB_CHUNK];
    for (int i = 0; i < KB_CHUNK; i++) /* rotated by 8: the same rays sampled */
        ids[i] = (size_t)((i + 8) % KB_CHUNK);
    const int got_ids = kd_batch_far_first(s, &c->b, ids, 0, KB_CHUNK);
    const int ok = got == want && got_ids == want;
    printf("far end first: %-44s %d (want %d): %s\n", what, got, want, ok ? "ok" : "FAIL");
    if (!ok) {
        fprintf(stderr, "FAIL far_first %s: %d / %d with ids, want %d\n", what, got, got_ids,
                want);
        failures++;
    }
    free(c);
}

/* kd_far_pick, the probe's choice: while an order is short of
 * KD_FAR_PROBE_RAYS the one with fewer rays (far on a tie), then far end
 * first only while its work per ray is under KD_FAR_GAIN of the other's. */
static void check_far_pick(void) {
    struct {
        double work0, rays0, work1, rays1;
        int want;
        const char *what;
    } c[] = {
        {0, 0, 0, 0, 1, "nothing measured: far first"},
        {0, 0, 900, KD_FAR_PROBE_RAYS, 0, "far measured, front to back not"},
        {800, KD_FAR_PROBE_RAYS - 1, 100, KD_FAR_PROBE_RAYS, 0, "front to back one ray short"},
        {3200, KD_FAR_PROBE_RAYS, 1600, KD_FAR_PROBE_RAYS, 1, "far half the work"},
        {3200, KD_FAR_PROBE_RAYS, 3100, KD_FAR_PROBE_RAYS, 0, "far 3 % cheaper: not enough"},
        {1000, 10 * KD_FAR_PROBE_RAYS, 5000, 100 * KD_FAR_PROBE_RAYS, 1,
         "per ray, not in all: far 0.5 of front to back"},
    };
    for (size_t i = 0; i < sizeof c / sizeof c[0]; i++) {
        const kd_far_probe p = {{c[i].work0, c[i].work1}, {c[i].rays0, c[i].rays1}};
        const int got = kd_far_pick(&p);
        printf("far pick: %-46s %d (want %d): %s\n", c[i].what, got, c[i].want,
               got == c[i].want ? "ok" : "FAIL");
        if (got != c[i].want) {
            fprintf(stderr, "FAIL far_pick %s\n", c[i].what);
            failures++;
        }
    }
}

/* The driver's wiring of the order: shadow rays from points among small
 * triangles toward a light above a roof (two large triangles at y = 1.5
 * over the soup): far end first meets the roof at once, front to back
 * walks the soup first. kdr_trace_batch (KB_FAR_AUTO) must then do less
 * work (node steps + triangle tests) than the same driver without it, with
 * the same answers. AO-like rays (ends spread as their origins) with an
 * origin per ray go to the interleaved walk and must walk far end first
 * there: exactly the work of the driver with KB_FAR, not the front-to-back
 * work; in runs of 16 on this small scene (under KD_FAR_RUNS_MIN_BYTES)
 * they stay in bundles front to back: exactly the work without the flag.
 * Longer AO-like rays (KB_ENDS_LONG: 3 units, half the diagonal) with an
 * origin per ray walk far end first there too. */
static void check_far_work(void) {
    const size_t nsoup = 20000, n = 4096;
    float *tris = malloc((nsoup + 2) * 9 * sizeof(float));
    float *soup = make_soup(nsoup);
    memcpy(tris, soup, nsoup * 9 * sizeof(float));
    free(soup);
    const float roof[18] = {-2, 1.5f, -2, 2, 1.5f, -2, 2, 1.5f, 2,
                            -2, 1.5f, -2, 2, 1.5f, 2, -2, 1.5f, 2};
    memcpy(tris + 9 * nsoup, roof, sizeof roof);
    kdr_scene *s = NULL;
    if (kdr_scene_build(tris, nsoup + 2, NULL, NULL, NULL, &s) != KDR_OK) {
        fprintf(stderr, "FAIL far_work: build\n");
        failures++;
        free(tris);
        return;
    }
    float *org = malloc(3 * n * sizeof(float)), *dir = malloc(3 * n * sizeof(float));
    float *tmin = malloc(n * sizeof(float)), *tmax = malloc(n * sizeof(float));
    uint8_t *hit[3] = {malloc(n), malloc(n), malloc(n)};
    typedef void (*bundle_fn)(const kdr_scene *, const kdr_ray_batch *, size_t, size_t,
                              kdr_query, int, kdr_hits *, kdr_trav_stats *);
    const bundle_fn fn = kd_cpu_has_avx512() ? kd_bundle16_trace
                         : kdr_cpu_has_avx2() ? kd_bundle8_trace
                                              : kd_bundle4_trace;
    static const char *const what[4] = {"shadow rays", "AO-like rays, an origin per ray",
                                        "AO-like rays, runs of 16",
                                        "long AO-like rays (KB_ENDS_LONG), an origin per ray"};
    for (int ao = 0; ao < 4; ao++) {
        for (size_t i = 0; i < n; i++) {
            if (ao != 2 || i % 16 == 0)
                for (int k = 0; k < 3; k++)
                    org[3 * i + k] = 1.6f * rnd01() - 0.8f;
            else
                memcpy(org + 3 * i, org + 3 * (i - 1), 3 * sizeof(float));
            const float light[3] = {0.2f * rnd01(), 3.0f, 0.2f * rnd01()};
            for (int k = 0; k < 3; k++)
                dir[3 * i + k] = ao ? 2.0f * rnd01() - 1.0f : light[k] - org[3 * i + k];
            /* AO-like: from the soup's upper part (y 0.2-1), upper
             * hemisphere, 1.4 long (under KD_FAR_SPREAD_MAX_LEN of the
             * diagonal, 6.2), so most reach the roof (ends spread over a
             * box wider than the origins'), are blocked by it and the two
             * orders' work differs */
            if (ao) {
                org[3 * i + 1] = 0.2f + 0.8f * rnd01();
                if (ao == 2 && i % 16) org[3 * i + 1] = org[3 * (i - 1) + 1];
                dir[3 * i + 1] = fabsf(dir[3 * i + 1]) + 0.5f;
                float len = 0.0f;
                for (int k = 0; k < 3; k++)
                    len += dir[3 * i + k] * dir[3 * i + k];
                for (int k = 0; k < 3; k++)
                    dir[3 * i + k] /= sqrtf(len);
            }
            tmin[i] = 1e-4f;
            tmax[i] = ao == 3 ? 3.0f : ao ? 1.4f : 1.0f;
        }
        const kdr_ray_batch b = {n, org, 3, dir, tmin, 1, tmax, 1};
        /* without the far order, KB_FAR_AUTO, KB_FAR */
        kdr_trav_stats st[3] = {{0, 0, 0, 0}, {0, 0, 0, 0}, {0, 0, 0, 0}};
        static const int far_flag[3] = {0, KB_FAR_AUTO, KB_FAR};
        for (int w = 0; w < 3; w++) {
            kdr_hits h = {NULL, NULL, NULL, NULL, hit[w]};
            for (size_t f = 0; f < n; f += 1024) /* the daemon's calls, smaller */
                fn(s, &b, f, 1024, KDR_ANY,
                   KB_FALLBACK | KB_SORT | KB_LIVE | far_flag[w], &h, &st[w]);
        }
        uint64_t wk[3];
        for (int w = 0; w < 3; w++)
            wk[w] = st[w].nodes_visited + st[w].tri_tests;
        const int same = memcmp(hit[0], hit[1], n) == 0 && memcmp(hit[0], hit[2], n) == 0;
        const int ok = same && (ao == 0   ? wk[1] < wk[0]
                                : ao == 2 ? wk[1] == wk[0] && wk[2] != wk[0]
                                          : wk[1] == wk[2] && wk[1] < wk[0]);
        printf("far work: %s, work per ray %.1f without the far order, %.1f with "
               "KB_FAR_AUTO, %.1f with KB_FAR, answers %s: %s\n",
               what[ao], (double)wk[0] / n, (double)wk[1] / n, (double)wk[2] / n,
               same ? "equal" : "DIFFER", ok ? "ok" : "FAIL");
        if (!ok) {
            fprintf(stderr, "FAIL far_work %s\n", what[ao]);
            failures++;
        }
    }
    free(org), free(dir), free(tmin), free(tmax), free(hit[0]), free(hit[1]), free(hit[2]);
    kdr_scene_free(s);
    free(tris);
}

static kdr_scene *build(size_t ntris) {
    float *tris = make_soup(ntris);
    kdr_scene *s = NULL;
    if (kdr_scene_build(tris, ntris, NULL, NULL, NULL, &s) != KDR_OK) {
        fprintf(stderr, "FAIL: building a soup of %zu triangles\n", ntris);
        failures++;
    }
    free(tris);
    return s;
}

int main(void) {
    /* the large scene must reach the threshold, the small one stay below */
    kdr_scene *big = build(200000), *small = build(20000), *mid = build(110000);
    if (!big || !small || !mid) return 1;
    printf("scenes: big %llu bytes, small %llu bytes, threshold %zu\n",
           (unsigned long long)big->stats.bytes, (unsigned long long)small->stats.bytes,
           KD_STREAM_RUNS_MIN_BYTES);
    if (big->stats.bytes < KD_STREAM_RUNS_MIN_BYTES ||
        small->stats.bytes >= KD_STREAM_RUNS_MIN_BYTES) {
        fprintf(stderr, "FAIL: scene sizes do not bracket KD_STREAM_RUNS_MIN_BYTES\n");
        failures++;
    }
    check_route("big", big, "one origin, stride 3", KB_CHUNK, 0, 0);
    check_route("big", big, "one origin, stride 0", KB_CHUNK, 1, 0);
    check_route("big", big, "runs of 16 (AO of 16 points)", 16, 0, 1);
    check_route("big", big, "an origin per ray", 1, 0, 1);
    check_route("small", small, "one origin, stride 3", KB_CHUNK, 0, 0);
    check_route("small", small, "runs of 16 (AO of 16 points)", 16, 0, 0);
    check_route("small", small, "an origin per ray", 1, 0, 1);
    /* any hit, AO-like ends: runs go to the walk (far end first) from
     * KD_FAR_RUNS_MIN_BYTES, closest-hit chunks from
     * KD_STREAM_RUNS_MIN_BYTES */
    printf("scene: mid %llu bytes, threshold %zu\n", (unsigned long long)mid->stats.bytes,
           KD_FAR_RUNS_MIN_BYTES);
    if (mid->stats.bytes < KD_FAR_RUNS_MIN_BYTES ||
        mid->stats.bytes >= KD_STREAM_RUNS_MIN_BYTES ||
        small->stats.bytes >= KD_FAR_RUNS_MIN_BYTES) {
        fprintf(stderr, "FAIL: scene sizes do not bracket KD_FAR_RUNS_MIN_BYTES\n");
        failures++;
    }
    check_route_any("mid", mid, "runs of 16, reach 0.2", 16, 0.2f, 1, 0);
    check_route_any("mid", mid, "runs of 16, reach +inf", 16, INFINITY, 0, 0);
    check_route_any("mid", mid, "one origin, stride 3", KB_CHUNK, 0.2f, 0, 0);
    check_route_any("small", small, "runs of 16, reach 0.2", 16, 0.2f, 0, 0);
    check_route_any("big", big, "runs of 16, reach 0.2", 16, 0.2f, 1, 1);
    /* the order must really permute these chunks (spread directions), or
     * the "no ray leaves its bundle" half would hold trivially */
    check_runs_fit(16, 0, 0, 16, 1);  /* 16 rays per point, 16 lanes */
    check_runs_fit(16, 0, 0, 8, 0);   /* a run across every second boundary */
    check_runs_fit(8, 0, 0, 16, 1);   /* two whole runs per bundle */
    check_runs_fit(1, 0, 0, 16, 1);   /* an origin per ray: the order is the identity */
    check_runs_fit(64, 0, 0, 16, 0);  /* 64 AO rays per point: 4 bundles a run */
    check_runs_fit(16, 0, 3, 16, 0);  /* runs off the bundles' grid */
    check_runs_fit(KB_CHUNK, 1, 0, 16, 0); /* one origin, stride 0 */
    check_far_pick();
    check_far_work();
    check_far_first(mid, "shadow rays, an origin per ray", 1, 0, END_LIGHT, 0, -1, 0,
                    KB_ENDS_CLUSTER);
    check_far_first(mid, "shadow rays, runs of 16 (16 points)", 16, 0, END_LIGHT, 0, -1, 0,
                    KB_ENDS_CLUSTER);
    /* one of the rays the rule samples (every eighth of 256); an unsampled
     * one is walked far end first from the root box's exit, which
     * test_bundle's ends-on-splits set checks */
    check_far_first(mid, "shadow rays, one ray with tmax +inf", 16, 0, END_LIGHT, 0, 64, 0, 0);
    check_far_first(mid, "shadow rays, no tmax array (all +inf)", 16, 0, END_LIGHT, 0, -1, 1, 0);
    check_far_first(mid, "shadow rays of one origin, stride 3", KB_CHUNK, 0, END_LIGHT, 0, -1, 0,
                    0);
    check_far_first(mid, "shadow rays of one origin, stride 0", KB_CHUNK, 1, END_LIGHT, 0, -1, 0,
                    0);
    check_far_first(mid, "AO rays, runs of 16, reach 0.2", 16, 0, END_REACH, 0.2f, -1, 0,
                    KB_ENDS_SPREAD);
    check_far_first(mid, "AO rays, an origin per ray, reach 0.05", 1, 0, END_REACH, 0.05f, -1, 0,
                    KB_ENDS_SPREAD);
    check_far_first(mid, "AO rays, one ray with tmax +inf", 16, 0, END_REACH, 0.2f, 64, 0, 0);
    check_far_first(mid, "AO rays of one origin, stride 3", KB_CHUNK, 0, END_REACH, 0.2f, -1, 0,
                    0);
    /* spread ends of long rays (the soup's diagonal is 2 sqrt 3):
     * KB_ENDS_LONG (KD_FAR_SPREAD_MAX_LEN) */
    check_far_first(mid, "long rays, runs of 16, reach 1.5", 16, 0, END_REACH, 1.5f, -1, 0,
                    KB_ENDS_LONG);
    check_far_first(mid, "AO rays, reach 0.8 (0.23 diagonal)", 16, 0, END_REACH, 0.8f, -1, 0,
                    KB_ENDS_SPREAD);
    check_far_first(mid, "shadow rays toward a large light", 1, 0, END_BIG_LIGHT, 0, -1, 0,
                    KB_ENDS_LONG);
    kdr_scene_free(big);
    kdr_scene_free(small);
    kdr_scene_free(mid);
    printf("%s: %d failures\n", failures ? "FAILED" : "passed", failures);
    return failures ? 1 : 0;
}
