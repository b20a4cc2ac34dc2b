/*
 * test_bundle.c — omni-directional bundles must answer exactly like single
 * rays: for every ray, t, u, v (bit patterns), prim and the any-hit flag of
 * kdr_trace_batch in every mode equal kdr_intersect1 / kdr_occluded1.
 *
 * Scenes: a random soup, an integer lattice of axis-aligned quads (triangles
 * in split planes, shared edges, equal-t ties), a closed tessellated sphere,
 * and, when scenes/fetch prepared them, the real-scene ladder. Ray sets:
 * camera and hemisphere rays from one shared origin (mixed direction signs
 * in every bundle), distinct random origins, +0/-0 direction components,
 * origins placed exactly on split planes read from the tree (some rays
 * lying in the plane), odd intervals (tmax < tmin, tmin == tmax, finite
 * tmax, negative tmin, NaN/inf inputs), rays aimed at vertices and edge
 * midpoints (test_bundle_sets.c), each cut into calls of 1, 3, 5, 7, 9,
 * 13 and 64 rays. The 4-, 8- and 16-wide drivers are also called directly
 * with the incoherence fallback off, so the SIMD path sees every
 * adversarial ray; the 16-wide one also with the fallback, sorting and
 * early answers on (the flags kdr_trace_batch passes).
 * So does the interleaved walk of incoherent rays (kd_stream.h): its scalar
 * and AVX-512 forms are called directly on every set, each also with its
 * leaves staged (the large-scene path), and through its dispatch with the
 * rays in reverse order (the id list the bundle fallback passes); as it
 * takes the single walk's steps, its work sums (rays, nodes entered,
 * triangle tests) must also equal the single walk's. That is what catches
 * a wrong NaN rule in its node step (slack-planes): the far child a NaN
 * crossing pushes lies exactly the slack beyond the ray, holds nothing the
 * ray hits, so dropping it changes no answer, only the work.
 * Any hit walked far end first (kd_occluded1_far's order): the bundle
 * drivers and the interleaved walk's lane forms with KB_FAR /
 * KD_STREAM_FAR on every set, answers against kdr_occluded1, and the lane
 * forms' work against kd_occluded1_far's (a cell the far walk drops or
 * adds changes the work even where it changes no answer); the sets
 * include rays whose end lies on a split plane and shadow rays toward a
 * small light (which kdr_trace_batch itself walks far end first).
 * kdr_occluded1 itself walks far end first exactly where tmax is finite
 * (KD_FAR1_FINITE): its work on each ray must be kd_occluded1_far's there
 * and the forward walk's (kd_occluded1_fwd, the reference of the work
 * sums above) elsewhere, on rays where the two orders differ.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "kd_internal.h"
#include "kd_stream.h"
#include "kd_traverse.h"
#include "kd_traverse_bundle.h"
#include "kd_tune.h"
#include "kd_walk.h"
#include "kdray.h"
#include "ladder.h"
#include "check.h"
#include "test_bundle_sets.h"

/* ---- comparison ------------------------------------------------------------ */

typedef struct results {
    float *t, *u, *v;
    int32_t *prim;
    uint8_t *hit;
    kdr_trav_stats st[2]; /* per query (closest, any): the walk's work */
    kdr_trav_stats far;   /* any hit walked far end first (kd_occluded1_far) */
} results;

static results res_alloc(size_t n) {
    results r = {malloc(n * 4), malloc(n * 4), malloc(n * 4), malloc(n * 4),
                 malloc(n), {{0}}, {0}};
    memset(r.t, 0xA5, n * 4); /* sentinels: unwritten entries fail the test */
    memset(r.u, 0xA5, n * 4);
    memset(r.v, 0xA5, n * 4);
    memset(r.prim, 0xA5, n * 4);
    memset(r.hit, 0xA5, n);
    return r;
}

static void res_free(results *r) {
    free(r->t), free(r->u), free(r->v), free(r->prim), free(r->hit);
}

static kdr_ray batch_ray_at(const kdr_ray_batch *b, size_t i) {
    kdr_ray r;
    memcpy(r.org, b->org + b->org_stride * i, sizeof r.org);
    memcpy(r.dir, b->dir + 3 * i, sizeof r.dir);
    r.tmin = b->tmin[b->tmin_stride * i];
    r.tmax = b->tmax[b->tmax_stride * i];
    return r;
}

/* Rays whose two orders take different work, by the order kdr_occluded1
 * must take (KD_FAR1_FINITE: far end first exactly when tmax is finite):
 * main requires some of each, so that the order check below can fail. */
static size_t order_decisive[2];

/* kdr_occluded1's work on r must be the far walk's where tmax is finite and
 * the forward walk's elsewhere (a ray whose orders take the same work
 * cannot tell them apart and is not counted). */
static void check_order(const kdr_scene *s, const kdr_ray *r, size_t i,
                        const kdr_trav_stats *fwd, const kdr_trav_stats *far) {
    kdr_trav_stats got = {0};
    kdr_occluded1(s, r, &got);
    const int want_far = KD_FAR1_FINITE && r->tmax < INFINITY;
    const kdr_trav_stats *w = want_far ? far : fwd;
    if (got.nodes_visited != w->nodes_visited || got.tri_tests != w->tri_tests) {
        fprintf(stderr,
                "FAIL ray %zu (tmax %a): kdr_occluded1 took %llu nodes / %llu tests, "
                "the %s walk %llu / %llu\n",
                i, r->tmax, (unsigned long long)got.nodes_visited,
                (unsigned long long)got.tri_tests, want_far ? "far" : "forward",
                (unsigned long long)w->nodes_visited, (unsigned long long)w->tri_tests);
        failures++;
    }
    order_decisive[want_far] += fwd->nodes_visited != far->nodes_visited ||
                                fwd->tri_tests != far->tri_tests;
}

static results reference(const kdr_scene *s, const kdr_ray_batch *b) {
    results ref = res_alloc(b->n);
    for (size_t i = 0; i < b->n; i++) {
        kdr_ray r = batch_ray_at(b, i);
        kdr_hit h;
        kdr_intersect1(s, &r, &h, &ref.st[KDR_CLOSEST]);
        ref.t[i] = h.t, ref.u[i] = h.u, ref.v[i] = h.v, ref.prim[i] = h.prim;
        kdr_trav_stats fwd = {0}, far = {0};
        ref.hit[i] = (uint8_t)kd_occluded1_fwd(s, &r, &fwd);
        if (kdr_occluded1(s, &r, NULL) != ref.hit[i]) {
            fprintf(stderr, "FAIL ray %zu: kdr_occluded1 differs from the forward walk\n", i);
            failures++;
        }
        if (kd_occluded1_far(s, &r, &far) != ref.hit[i]) {
            fprintf(stderr, "FAIL ray %zu: kd_occluded1_far differs from the forward walk\n", i);
            failures++;
        }
        check_order(s, &r, i, &fwd, &far);
        ref.st[KDR_ANY].rays += fwd.rays, ref.far.rays += far.rays;
        ref.st[KDR_ANY].nodes_visited += fwd.nodes_visited;
        ref.st[KDR_ANY].tri_tests += fwd.tri_tests;
        ref.far.nodes_visited += far.nodes_visited;
        ref.far.tri_tests += far.tri_tests;
    }
    return ref;
}

static int differ(const results *a, const results *b, size_t i, kdr_query q) {
    if (q == KDR_ANY)
        return a->hit[i] != b->hit[i];
    return memcmp(&a->t[i], &b->t[i], 4) || memcmp(&a->u[i], &b->u[i], 4) ||
           memcmp(&a->v[i], &b->v[i], 4) || a->prim[i] != b->prim[i];
}

/* The traversal under test: 0..3 = the public modes, 4/5 = the 4/8-wide
 * drivers without the incoherence fallback, 6..9 = the interleaved walk's
 * scalar and AVX-512 forms, plain and with staged leaves, 10 = its
 * dispatch with an id list (the rays in reverse order), 11/12 = its AVX2
 * 8-lane form, plain and staged, 13/14 = the 16-wide (AVX-512) bundle
 * driver without the fallback and with kdr_trace_batch's flags; far end
 * first for any hit (KB_FAR, KD_STREAM_FAR; closest hit ignores it):
 * 15..17 = the 4/8/16-wide drivers without the fallback, 18..20 = the
 * interleaved walk's 8 and 16-lane forms (16 also staged), 21 = the
 * 16-wide driver with kdr_trace_batch's flags. */
#define NWAYS 22
#define WAY_FAR_STREAM_FIRST 18
#define WAY_FAR_STREAM_LAST 20
static const char *const way_names[NWAYS] = {
    "auto",   "single",        "bundle4",  "bundle8",          "raw4",      "raw8",
    "stream", "stream-staged", "stream16", "stream16-staged", "stream-ids",
    "stream8", "stream8-staged", "raw16", "bundle16",
    "raw4-far", "raw8-far", "raw16-far", "stream8-far", "stream16-far",
    "stream16-far-staged", "bundle16-far"};

/* 0 when the CPU cannot run that way (8 lanes without AVX2, 16 without
 * AVX-512). */
static int way_runs(int way) {
    if (way == 3 || way == 5 || way == 11 || way == 12 || way == 16 || way == 18)
        return kdr_cpu_has_avx2(); /* bundle8 would run 4-wide: raw8 must not run */
    if (way == 8 || way == 9 || way == 13 || way == 14 || way == 17 || way == 19 ||
        way == 20 || way == 21)
        return kd_cpu_has_avx512();
    return 1;
}

static void run_way(const kdr_scene *s, const kdr_ray_batch *b, size_t first,
                    size_t count, kdr_query q, int way, results *out) {
    kdr_hits h = {out->t, out->prim, out->u, out->v, out->hit};
    kdr_trav_stats *st = &out->st[q];
    if (way == 15) {
        kd_bundle4_trace(s, b, first, count, q, KB_FAR, &h, NULL);
    } else if (way == 16) {
        kd_bundle8_trace(s, b, first, count, q, KB_FAR, &h, NULL);
    } else if (way == 17 || way == 21) {
        kd_bundle16_trace(s, b, first, count, q,
                          way == 21 ? KB_FALLBACK | KB_SORT | KB_LIVE | KB_FAR : KB_FAR,
                          &h, NULL);
    } else if (way == 18) {
        if (s->nodes)
            kd_stream_trace8(s, b, NULL, first, count, q, KD_STREAM_FAR, &h, st);
    } else if (way == 19 || way == 20) {
        if (s->nodes)
            kd_stream_trace16(s, b, NULL, first, count, q,
                              KD_STREAM_FAR | (way == 20 ? KD_STREAM_STAGE : 0), &h, st);
    } else if (way == 4) {
        kd_bundle4_trace(s, b, first, count, q, 0, &h, NULL);
    } else if (way == 5) {
        kd_bundle8_trace(s, b, first, count, q, 0, &h, NULL);
    } else if (way == 13 || way == 14) {
        kd_bundle16_trace(s, b, first, count, q,
                          way == 14 ? KB_FALLBACK | KB_SORT | KB_LIVE : 0, &h, NULL);
    } else if (way == 6 || way == 7) {
        if (s->nodes)
            kd_stream_scalar_trace(s, b, NULL, first, count, q,
                                   way == 7 ? KD_STREAM_STAGE : 0, &h, st);
    } else if (way == 8 || way == 9) {
        if (s->nodes)
            kd_stream_trace16(s, b, NULL, first, count, q,
                              way == 9 ? KD_STREAM_STAGE : 0, &h, st);
    } else if (way == 11 || way == 12) {
        if (s->nodes)
            kd_stream_trace8(s, b, NULL, first, count, q,
                             way == 12 ? KD_STREAM_STAGE : 0, &h, st);
    } else if (way == 10) {
        size_t *ids = malloc(count * sizeof *ids);
        for (size_t i = 0; i < count; i++)
            ids[i] = first + count - 1 - i;
        if (s->nodes)
            kd_stream_trace(s, b, ids, 0, count, q, &h, st);
        free(ids);
    } else if (kdr_trace_batch(s, b, first, count, q, (kdr_trav_mode)way, &h, NULL)) {
        failures++;
    }
}

static void check_cut(const char *scene, const rayset *rs, const kdr_scene *s,
                      const kdr_ray_batch *b, const results *ref, kdr_query q,
                      int way, const size_t *sizes);

/* Traces the whole set in calls of 1, 3, 5, 7, 9, 13, 64 rays (cycling),
 * then in one call, and compares each ray with the single-ray reference. */
static void check_way(const char *scene, const rayset *rs, const kdr_scene *s,
                      const kdr_ray_batch *b, const results *ref, kdr_query q,
                      int way) {
    static const size_t sizes[] = {1, 3, 5, 7, 9, 13, 64};
    for (int whole = 0; whole < 2; whole++)
        check_cut(scene, rs, s, b, ref, q, way, whole ? NULL : sizes);
}

/* One pass: calls of sizes[] rays (cycling), or one call for all rays
 * (several chunks: regrouping and the fallback carry across them). */
static void check_cut(const char *scene, const rayset *rs, const kdr_scene *s,
                      const kdr_ray_batch *b, const results *ref, kdr_query q,
                      int way, const size_t *sizes) {
    results got = res_alloc(b->n);
    size_t first = 0;
    for (int c = 0; first < b->n; c = (c + 1) % 7) {
        size_t cnt = !sizes ? b->n : sizes[c] < b->n - first ? sizes[c] : b->n - first;
        run_way(s, b, first, cnt, q, way, &got);
        first += cnt;
    }
    int bad = 0;
    for (size_t i = 0; i < b->n; i++) {
        if (!differ(&got, ref, i, q))
            continue;
        if (bad++ < 3) {
            kdr_ray r = batch_ray_at(b, i);
            fprintf(stderr,
                    "FAIL %s/%s %s %s ray %zu o=(%a %a %a) d=(%a %a %a) "
                    "[%a %a]: got t=%a p=%d u=%a v=%a hit=%d, single t=%a "
                    "p=%d u=%a v=%a hit=%d\n",
                    scene, rs->name, way_names[way],
                    q == KDR_ANY ? "any" : "closest", i, r.org[0], r.org[1],
                    r.org[2], r.dir[0], r.dir[1], r.dir[2], r.tmin, r.tmax,
                    got.t[i], got.prim[i], got.u[i], got.v[i], got.hit[i],
                    ref->t[i], ref->prim[i], ref->u[i], ref->v[i], ref->hit[i]);
        }
    }
    if (bad)
        fprintf(stderr, "FAIL %s/%s %s%s: %d of %zu rays differ\n", scene,
                rs->name, way_names[way], sizes ? "" : " (one call)", bad, b->n);
    failures += bad;
    /* The interleaved walk takes the single walk's steps ray by ray, so it
     * enters the same nodes and tests the same triangles: equal work sums
     * catch a step that differs without changing an answer (a far child
     * dropped or entered that holds nothing the ray hits, e.g. a NaN
     * crossing's far entry, see rays_slack_planes). */
    /* the far end first forms against kd_occluded1_far's work (closest
     * hit ignores the flag: against the single walk's) */
    const int far_stream = way >= WAY_FAR_STREAM_FIRST && way <= WAY_FAR_STREAM_LAST;
    const kdr_trav_stats *gs = &got.st[q],
                         *rs_ = far_stream && q == KDR_ANY ? &ref->far : &ref->st[q];
    if (((way >= 6 && way <= 12) || far_stream) && s->nodes &&
        (gs->rays != rs_->rays || gs->nodes_visited != rs_->nodes_visited ||
         gs->tri_tests != rs_->tri_tests)) {
        fprintf(stderr,
                "FAIL %s/%s %s %s%s: work differs from the single walk: rays %llu "
                "/ %llu, nodes %llu / %llu, triangle tests %llu / %llu\n",
                scene, rs->name, way_names[way], q == KDR_ANY ? "any" : "closest",
                sizes ? "" : " (one call)", (unsigned long long)gs->rays,
                (unsigned long long)rs_->rays, (unsigned long long)gs->nodes_visited,
                (unsigned long long)rs_->nodes_visited,
                (unsigned long long)gs->tri_tests, (unsigned long long)rs_->tri_tests);
        failures++;
    }
    res_free(&got);
}

/* Bundles whose lanes share an origin replay the top of their walk along
 * the origin's path (kb_replay) once a second bundle in a row has that
 * origin. The replay must reach the loop's state exactly: the same answers
 * (bits) and the same work (lane node steps, triangle tests) as the same
 * driver with every walk from the root (KB_ROOT), at each width, in one
 * call (runs of bundles) and in calls of 1..64 rays. A sibling the replay
 * failed to push, or pushed with another interval, changes the work even
 * where no answer changes. */
static void check_entry_work(const char *scene, const rayset *rs, const kdr_scene *s,
                             const kdr_ray_batch *b) {
    typedef void (*bundle_fn)(const kdr_scene *, const kdr_ray_batch *, size_t, size_t,
                              kdr_query, int, kdr_hits *, kdr_trav_stats *);
    static const bundle_fn fns[3] = {kd_bundle4_trace, kd_bundle8_trace, kd_bundle16_trace};
    static const char *const names[3] = {"raw4", "raw8", "raw16"};
    static const size_t sizes[] = {1, 3, 5, 7, 9, 13, 64};
    for (int w = 0; w < 3; w++) {
        if ((w == 1 && !kdr_cpu_has_avx2()) || (w == 2 && !kd_cpu_has_avx512()))
            continue;
        for (int q = KDR_CLOSEST; q <= KDR_ANY; q++)
            for (int whole = 0; whole < 2; whole++) {
                results got[2] = {res_alloc(b->n), res_alloc(b->n)};
                for (int root = 0; root < 2; root++) {
                    kdr_hits h = {got[root].t, got[root].prim, got[root].u, got[root].v,
                                  got[root].hit};
                    size_t first = 0;
                    for (int c = 0; first < b->n; c = (c + 1) % 7) {
                        const size_t cnt = whole ? b->n
                                           : sizes[c] < b->n - first ? sizes[c]
                                                                     : b->n - first;
                        fns[w](s, b, first, cnt, (kdr_query)q, root ? KB_ROOT : 0, &h,
                               &got[root].st[q]);
                        first += cnt;
                    }
                }
                int bad = 0;
                for (size_t i = 0; i < b->n; i++)
                    bad += differ(&got[0], &got[1], i, (kdr_query)q);
                const kdr_trav_stats *e = &got[0].st[q], *r = &got[1].st[q];
                if (bad || e->rays != r->rays || e->nodes_visited != r->nodes_visited ||
                    e->tri_tests != r->tri_tests) {
                    fprintf(stderr,
                            "FAIL %s/%s %s %s%s: with entries / from the root: %d answers "
                            "differ, rays %llu / %llu, nodes %llu / %llu, triangle tests "
                            "%llu / %llu\n",
                            scene, rs->name, names[w], q == KDR_ANY ? "any" : "closest",
                            whole ? " (one call)" : "", bad, (unsigned long long)e->rays,
                            (unsigned long long)r->rays,
                            (unsigned long long)e->nodes_visited,
                            (unsigned long long)r->nodes_visited,
                            (unsigned long long)e->tri_tests,
                            (unsigned long long)r->tri_tests);
                    failures++;
                }
                res_free(&got[0]);
                res_free(&got[1]);
            }
    }
}

static void check_set(const char *scene, const kdr_scene *s, rayset *rs) {
    kdr_ray_batch b = {rs->n, rs->org, rs->shared_org ? 0 : 3, rs->dir,
                       rs->tmin, 1, rs->tmax, 1};
    results ref = reference(s, &b);
    size_t hits = 0;
    for (size_t i = 0; i < b.n; i++)
        hits += ref.prim[i] >= 0;
    printf("%-8s %-13s %zu rays, %zu hits\n", scene, rs->name, b.n, hits);
    for (int q = KDR_CLOSEST; q <= KDR_ANY; q++)
        for (int way = 0; way < NWAYS; way++)
            if (way_runs(way))
                check_way(scene, rs, s, &b, &ref, (kdr_query)q, way);
    if (s->nodes)
        check_entry_work(scene, rs, s, &b);
    res_free(&ref);
}

static void check_scene(const scene_src *src, int integer) {
    failures += rays_check_every_set(src, integer, check_set);
}

/* Stride-0 tmin/tmax: one interval shared by every ray. */
static void check_shared_interval(const scene_src *src) {
    kdr_scene *s = NULL;
    if (kdr_scene_build(src->tris, src->ntris, NULL, NULL, NULL, &s) != KDR_OK) {
        failures++;
        return;
    }
    kdr_bounds bb;
    kdr_scene_bounds(s, &bb);
    rayset rs = rays_omni(&bb);
    rs.name = "omni-shared-interval";
    rs.tmin[0] = 0.05f;
    rs.tmax[0] = 0.5f * (bb.max[0] - bb.min[0]);
    kdr_ray_batch b = {rs.n, rs.org, 0, rs.dir, rs.tmin, 0, rs.tmax, 0};
    results ref = reference(s, &b);
    for (int q = KDR_CLOSEST; q <= KDR_ANY; q++)
        for (int way = 0; way < NWAYS; way++)
            if (way_runs(way))
                check_way(src->name, &rs, s, &b, &ref, (kdr_query)q, way);
    res_free(&ref);
    rays_free(&rs);
    kdr_scene_free(s);
}

/* Absent tmin / tmax (NULL: 0 and +inf for every ray) must answer as
 * arrays holding 0 and +inf do; the 16-lane driver reads 16 consecutive
 * rays a vector at a time, with its own handling of each field's
 * absence or stride (kb_gather_run). Shared and per-ray origins, closest
 * and any hit, AUTO and the raw 16-lane driver; compared bit for bit. */
static void check_absent_interval(const scene_src *src) {
    kdr_scene *s = NULL;
    if (kdr_scene_build(src->tris, src->ntris, NULL, NULL, NULL, &s) != KDR_OK) {
        failures++;
        return;
    }
    kdr_bounds bb;
    kdr_scene_bounds(s, &bb);
    rayset sets[2] = {rays_omni(&bb), rays_distinct(&bb)};
    for (int k = 0; k < 2; k++) {
        rayset *rs = &sets[k];
        for (size_t i = 0; i < rs->n; i++)
            rs->tmin[i] = 0.0f, rs->tmax[i] = INFINITY;
        const size_t os = rs->shared_org ? 0 : 3;
        const kdr_ray_batch full = {rs->n, rs->org, os, rs->dir, rs->tmin, 1, rs->tmax, 1};
        const kdr_ray_batch bare = {rs->n, rs->org, os, rs->dir, NULL, 0, NULL, 0};
        for (int q = KDR_CLOSEST; q <= KDR_ANY; q++)
            for (int raw = 0; raw < 2; raw++) {
                if (raw && !kd_cpu_has_avx512())
                    continue;
                results r[2] = {res_alloc(rs->n), res_alloc(rs->n)};
                for (int w = 0; w < 2; w++) {
                    kdr_hits h = {r[w].t, r[w].prim, r[w].u, r[w].v, r[w].hit};
                    const kdr_ray_batch *b = w ? &bare : &full;
                    if (raw)
                        kd_bundle16_trace(s, b, 0, rs->n, (kdr_query)q, 0, &h, NULL);
                    else
                        kdr_trace_batch(s, b, 0, rs->n, (kdr_query)q, KDR_TRAV_AUTO, &h,
                                        NULL);
                }
                int bad = 0;
                for (size_t i = 0; i < rs->n; i++)
                    bad += q == KDR_ANY ? r[0].hit[i] != r[1].hit[i]
                                        : memcmp(&r[0].t[i], &r[1].t[i], 4) != 0 ||
                                              r[0].prim[i] != r[1].prim[i] ||
                                              memcmp(&r[0].u[i], &r[1].u[i], 4) != 0 ||
                                              memcmp(&r[0].v[i], &r[1].v[i], 4) != 0;
                if (bad)
                    fprintf(stderr, "FAIL %s/%s %s %s: %d of %zu rays differ without "
                                    "tmin/tmax arrays\n",
                            src->name, rs->name, raw ? "raw16" : "auto",
                            q == KDR_ANY ? "any" : "closest", bad, rs->n);
                failures += bad;
                res_free(&r[0]);
                res_free(&r[1]);
            }
        rays_free(rs);
    }
    kdr_scene_free(s);
}

/* Argument checks and the empty scene. */
static void check_api(void) {
    kdr_scene *s = NULL;
    if (kdr_scene_build(NULL, 0, NULL, NULL, NULL, &s) != KDR_OK) {
        fprintf(stderr, "FAIL: empty scene build\n");
        failures++;
        return;
    }
    float org[3] = {0, 0, 0}, dir[6] = {1, 0, 0, 0, -1, 0}, tmin = 0, tmax = 1;
    float t[2], u[2], v[2];
    int32_t prim[2];
    uint8_t hit[2];
    kdr_hits h = {t, prim, u, v, hit};
    kdr_ray_batch b = {2, org, 0, dir, &tmin, 0, &tmax, 0};
    int bad = 0;
    bad += kdr_trace_batch(s, &b, 0, 2, KDR_CLOSEST, KDR_TRAV_AUTO, &h, NULL) != KDR_OK;
    bad += prim[0] != -1 || prim[1] != -1 || t[0] != -1.0f || u[1] != 0.0f;
    bad += kdr_trace_batch(s, &b, 1, 2, KDR_CLOSEST, KDR_TRAV_AUTO, &h, NULL) != KDR_EINVAL;
    b.org_stride = 2;
    bad += kdr_trace_batch(s, &b, 0, 2, KDR_ANY, KDR_TRAV_AUTO, &h, NULL) != KDR_EINVAL;
    b.org_stride = 0;
    bad += kdr_trace_batch(s, &b, 0, 2, KDR_ANY, (kdr_trav_mode)7, &h, NULL) != KDR_EINVAL;
    bad += kdr_trace_batch(NULL, &b, 0, 2, KDR_ANY, KDR_TRAV_AUTO, &h, NULL) != KDR_EINVAL;
    if (bad)
        fprintf(stderr, "FAIL: %d API checks\n", bad);
    failures += bad;
    kdr_scene_free(s);
}

/* The real-scene ladder of scenes/fetch: every ray set on every scene. */
static int check_ladder(const char *dir) {
    ladder_entry *e = NULL;
    char err[256];
    int n = ladder_read(dir, &e, err, sizeof err);
    if (n < 0) {
        printf("no ladder: %s\n", err);
        return 77;
    }
    for (int i = 0; i < n; i++) {
        scene_src src = {e[i].name, NULL, 0};
        if (ladder_load(&e[i], &src.tris, &src.ntris, err, sizeof err) != 0) {
            fprintf(stderr, "FAIL: %s\n", err);
            failures++;
            continue;
        }
        if (src.ntris > 0)
            check_scene(&src, 0);
        free(src.tris);
    }
    free(e);
    printf("%s: %d mismatches\n", failures ? "FAILED" : "passed", failures);
    return failures ? 1 : 0;
}

/* No argument: generated scenes. One argument: the ladder directory. */
int main(int argc, char **argv) {
    printf("AVX2: %s\n", kdr_cpu_has_avx2() ? "yes (4- and 8-wide tested)"
                                            : "no (8-wide skipped)");
    printf("AVX-512: %s\n", kd_cpu_has_avx512() ? "yes (16-lane bundles and interleaved walk tested)"
                                               : "no (16-lane bundles and interleaved walk skipped)");
    if (argc > 1)
        return check_ladder(argv[1]);
    check_api();
    scene_src scenes[] = {make_soup(3000), make_lattice(6, 0.3f),
                          make_sphere(24, 48)};
    for (size_t k = 0; k < sizeof scenes / sizeof scenes[0]; k++) {
        check_scene(&scenes[k], k == 1);
        if (k == 0) {
            check_shared_interval(&scenes[k]);
            check_absent_interval(&scenes[k]);
        }
    }
    for (size_t k = 0; k < sizeof scenes / sizeof scenes[0]; k++)
        free(scenes[k].tris);
    /* kdr_occluded1's order was checked on rays where it shows */
    printf("kdr_occluded1's order: %zu rays with tmax finite (far end first), %zu "
           "without (front to back) where the two orders differ\n",
           order_decisive[1], order_decisive[0]);
    if (!order_decisive[0] || !order_decisive[1]) {
        fprintf(stderr, "FAIL: no ray shows kdr_occluded1's order\n");
        failures++;
    }
    printf("%s: %d mismatches\n", failures ? "FAILED" : "passed", failures);
    return failures ? 1 : 0;
}
