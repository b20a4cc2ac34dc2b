/*
 * test_all_stream.c — the interleaved walk of all hits and counts
 * (core/kd_all_stream.c) against the one-ray walk (kdr_intersect_all1,
 * kdr_count1), ray by ray, bit for bit.
 *
 * Scenes and rays are test_bundle's (test_bundle_sets.h): a random soup, a
 * lattice of axis-aligned quads (triangles straddling many leaves, shared
 * edges, rays through split planes at integer coordinates), a closed
 * tessellated sphere (shared edges and vertices), and every set built to
 * break a walk: shared and distinct origins, zero direction components,
 * origins on split planes, rays in the slack planes (NaN crossings), rays
 * aimed at edges and vertices, odd intervals (NaN, inf, tmin > tmax).
 * Each set goes through kd_all_stream with leaves staged and not, with the
 * per-ray mailbox forced on and not (KD_ALL_MBOX: tests of a triangle the
 * ray tested in an earlier leaf are dropped), capped at 1, 3, 16 and 1024
 * hits and as counts; every ray's list (t, prim, u, v) and count must equal
 * the one-ray answer, and the work sums (rays, nodes entered, triangle
 * tests) the one-ray walk's: a walk that visits other leaves, drops a
 * pending subtree or keeps a duplicate differs there. With the mailbox
 * forced the walk may make fewer triangle tests, never more, and over all
 * sets it must make fewer (a mailbox that drops nothing fails; one that
 * drops a test it never made loses hits).
 * Each set also goes through the public kdr_all_batch / kdr_count_batch,
 * which on these small scenes take the interleaved walk for chunks
 * kd_batch_scattered calls scattered (own origins, spread directions; at
 * least three sets must be) and one ray at a time for the rest.
 * Then a soup of KD_ALL_STREAM_MIN_BYTES and more through the public
 * kdr_all_batch / kdr_count_batch (which take the interleaved walk there),
 * with a cap whose scratch lists do not fit on the stack.
 * Exit 1 on any difference.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "kd_all_stream.h"
#include "kd_traverse_bundle.h"
#include "kdray.h"
#include "test_bundle_sets.h"

static int failures;
/* sets whose first chunk kd_batch_scattered calls scattered: the public
 * batch calls take the interleaved walk for them on small scenes too */
static int scattered_sets;

typedef struct answers {
    uint32_t *nh, *cnt;
    float *t, *u, *v;
    int32_t *prim;
} answers;

static int answers_alloc(answers *a, size_t n, uint32_t cap) {
    const size_t slots = n * cap;
    *a = (answers){malloc(n * sizeof(uint32_t)), malloc(n * sizeof(uint32_t)),
                   malloc(slots * sizeof(float)),  malloc(slots * sizeof(float)),
                   malloc(slots * sizeof(float)),  malloc(slots * sizeof(int32_t))};
    return a->nh && a->cnt && a->t && a->u && a->v && a->prim ? 0 : -1;
}

static void answers_free(answers *a) {
    free(a->nh), free(a->cnt), free(a->t), free(a->u), free(a->v), free(a->prim);
}

static void ray_of(const rayset *rs, size_t i, kdr_ray *r) {
    const float *o = rs->org + (rs->shared_org ? 0 : 3 * i);
    for (int k = 0; k < 3; k++) {
        r->org[k] = o[k];
        r->dir[k] = rs->dir[3 * i + k];
    }
    r->tmin = rs->tmin[i];
    r->tmax = rs->tmax[i];
}

/* Triangle tests the forced mailbox (KD_ALL_MBOX) saved over the one-ray
 * walk, summed over every set: 0 means the mailbox dropped nothing. */
static unsigned long long mbox_saved;

/* a: the walk under test, b: the one-ray walk. With the mailbox forced
 * (mbox), a may make fewer triangle tests than b, never more. */
static int same_stats(const kdr_trav_stats *a, const kdr_trav_stats *b, int mbox) {
    if (a->rays != b->rays || a->nodes_visited != b->nodes_visited) return 0;
    if (!mbox) return a->tri_tests == b->tri_tests;
    if (a->tri_tests > b->tri_tests) return 0;
    mbox_saved += b->tri_tests - a->tri_tests;
    return 1;
}

/* The batch's answers (lists capped at cap, counts) against the one-ray
 * calls; `what` names the way for the messages. */
static void compare(const char *scene, const rayset *rs, const kdr_scene *s, uint32_t cap,
                    const answers *a, const kdr_trav_stats *st_list,
                    const kdr_trav_stats *st_count, const char *what, int mbox) {
    kdr_hit *h = malloc(cap * sizeof *h);
    kdr_trav_stats r1 = {0}, r2 = {0};
    int bad = 0;
    for (size_t i = 0; i < rs->n; i++) {
        kdr_ray r;
        ray_of(rs, i, &r);
        uint32_t m = 0, c = 0;
        kdr_intersect_all1(s, &r, cap, h, &m, &r1);
        kdr_count1(s, &r, &c, &r2);
        int ok = a->nh[i] == m && a->cnt[i] == c;
        for (uint32_t k = 0; ok && k < m; k++) {
            const size_t j = i * cap + k;
            ok = memcmp(&a->t[j], &h[k].t, 4) == 0 && a->prim[j] == h[k].prim &&
                 memcmp(&a->u[j], &h[k].u, 4) == 0 && memcmp(&a->v[j], &h[k].v, 4) == 0;
        }
        if (!ok && bad++ < 3)
            fprintf(stderr,
                    "FAIL %s/%s %s cap %u ray %zu: %u hits, count %u (one ray: %u, %u)\n",
                    scene, rs->name, what, cap, i, a->nh[i], a->cnt[i], m, c);
    }
    if (!same_stats(st_list, &r1, mbox) || !same_stats(st_count, &r2, mbox)) {
        fprintf(stderr,
                "FAIL %s/%s %s cap %u: work sums (rays, nodes, tests) list %llu %llu %llu, "
                "count %llu %llu %llu; one ray: %llu %llu %llu, %llu %llu %llu\n",
                scene, rs->name, what, cap, (unsigned long long)st_list->rays,
                (unsigned long long)st_list->nodes_visited,
                (unsigned long long)st_list->tri_tests, (unsigned long long)st_count->rays,
                (unsigned long long)st_count->nodes_visited,
                (unsigned long long)st_count->tri_tests, (unsigned long long)r1.rays,
                (unsigned long long)r1.nodes_visited, (unsigned long long)r1.tri_tests,
                (unsigned long long)r2.rays, (unsigned long long)r2.nodes_visited,
                (unsigned long long)r2.tri_tests);
        bad++;
    }
    failures += bad;
    free(h);
}

static void check_set(const char *scene, const kdr_scene *s, rayset *rs) {
    static const uint32_t caps[] = {1, 3, 16, KDR_MAX_HITS_LIMIT};
    const kdr_ray_batch b = {rs->n, rs->org, rs->shared_org ? 0 : 3, rs->dir,
                             rs->tmin, 1, rs->tmax, 1};
    for (size_t c = 0; c < sizeof caps / sizeof caps[0]; c++) {
        answers a;
        kdr_hit *buf = malloc((size_t)KD_ALL_RAYS * caps[c] * sizeof *buf);
        if (answers_alloc(&a, rs->n, caps[c]) != 0 || !buf) {
            fprintf(stderr, "FAIL: out of memory\n");
            failures++;
            answers_free(&a);
            free(buf);
            return;
        }
        /* both forms (the lanes on AVX-512 CPUs, and the scalar one),
         * staged and not, with the mailbox forced and not */
        for (int flags = 0; flags <= (KD_ALL_STAGE | KD_ALL_SCALAR | KD_ALL_MBOX); flags++) {
            kdr_all_hits out = {a.nh, a.t, a.u, a.v, a.prim};
            kdr_trav_stats sl = {0}, sc = {0};
            /* a first ray other than 0: answers land at their own index */
            const size_t first = rs->n > 5 ? 5 : 0;
            for (size_t i = 0; i < first; i++)
                a.nh[i] = a.cnt[i] = 0;
            int rc = kd_all_stream(s, &b, 0, first, caps[c], buf, &out, NULL, flags, &sl);
            rc |= kd_all_stream(s, &b, first, rs->n - first, caps[c], buf, &out, NULL, flags,
                                &sl);
            rc |= kd_all_stream(s, &b, 0, rs->n, 0, NULL, NULL, a.cnt, flags, &sc);
            if (rc != KDR_OK) {
                fprintf(stderr, "FAIL %s/%s: kd_all_stream returned %d\n", scene, rs->name,
                        rc);
                failures++;
            }
            static const char *const form[] = {
                "stream",      "stream-staged",      "stream-scalar",
                "stream-scalar-staged",      "stream-mbox", "stream-staged-mbox",
                "stream-scalar-mbox", "stream-scalar-staged-mbox"};
            compare(scene, rs, s, caps[c], &a, &sl, &sc, form[flags], flags & KD_ALL_MBOX);
        }
        /* the public calls: on these small scenes they take the interleaved
         * walk for the chunks kd_batch_scattered calls scattered */
        kdr_all_hits out = {a.nh, a.t, a.u, a.v, a.prim};
        kdr_trav_stats sl = {0}, sc = {0};
        if (kdr_all_batch(s, &b, 0, rs->n, caps[c], &out, &sl) != KDR_OK ||
            kdr_count_batch(s, &b, 0, rs->n, a.cnt, &sc) != KDR_OK) {
            fprintf(stderr, "FAIL %s/%s: batch call\n", scene, rs->name);
            failures++;
        }
        compare(scene, rs, s, caps[c], &a, &sl, &sc, "kdr_all_batch", 0);
        answers_free(&a);
        free(buf);
    }
    if (b.org_stride && rs->n > 8 && kd_batch_scattered(s, &b, 0, rs->n < KB_CHUNK ? rs->n : KB_CHUNK))
        scattered_sets++;
}

static void check_scene(const scene_src *src, int integer) {
    failures += rays_check_every_set(src, integer, check_set);
}

/* A soup of n small triangles in [-1, 1]^3 (edges up to 0.06): about 50
 * bytes of tree per triangle (test_bundle_sets' soup has long triangles
 * whose trees grow far larger). */
static scene_src small_soup(size_t n) {
    uint64_t x = 0x9E3779B97F4A7C15ull;
    float *t = malloc(n * 9 * sizeof(float));
    for (size_t i = 0; t && i < n; i++) {
        float r[13];
        for (int k = 0; k < 13; k++) {
            x ^= x << 13, x ^= x >> 7, x ^= x << 17;
            r[k] = (float)(x >> 40) * 0x1p-24f;
        }
        const float size = 0.01f + 0.02f * r[12];
        for (int j = 0; j < 3; j++)
            for (int k = 0; k < 3; k++)
                t[9 * i + 3 * j + k] = 2.0f * r[k] - 1.0f + size * (2.0f * r[3 + 3 * j + k] - 1.0f);
    }
    return (scene_src){"small-soup", t, t ? n : 0};
}

/* The public entry points on a scene large enough for the interleaved
 * walk: cap 1024 (KD_ALL_RAYS * 1024 scratch hits: the heap) and 16 (the
 * stack). */
static void check_large(void) {
    const scene_src src = small_soup(360000);
    kdr_scene *s = NULL;
    if (kdr_scene_build(src.tris, src.ntris, NULL, NULL, NULL, &s) != KDR_OK) {
        fprintf(stderr, "FAIL: building the large soup\n");
        failures++;
        free(src.tris);
        return;
    }
    kdr_tree_stats ts;
    kdr_scene_tree_stats(s, &ts);
    if (ts.bytes < KD_ALL_STREAM_MIN_BYTES) {
        fprintf(stderr, "FAIL: the large soup takes %zu bytes, under %zu\n",
                (size_t)ts.bytes, (size_t)KD_ALL_STREAM_MIN_BYTES);
        failures++;
    }
    kdr_bounds bb;
    kdr_scene_bounds(s, &bb);
    rayset sets[] = {rays_omni(&bb), rays_camera(&bb)};
    for (size_t k = 0; k < 2; k++) {
        const rayset *rs = &sets[k];
        const kdr_ray_batch b = {rs->n, rs->org, rs->shared_org ? 0 : 3, rs->dir,
                                 rs->tmin, 1, rs->tmax, 1};
        static const uint32_t caps[] = {16, KDR_MAX_HITS_LIMIT};
        for (int c = 0; c < 2; c++) {
            answers a;
            if (answers_alloc(&a, rs->n, caps[c]) != 0) {
                failures++;
                answers_free(&a);
                continue;
            }
            kdr_all_hits out = {a.nh, a.t, a.u, a.v, a.prim};
            kdr_trav_stats sl = {0}, sc = {0};
            if (kdr_all_batch(s, &b, 0, rs->n, caps[c], &out, &sl) != KDR_OK ||
                kdr_count_batch(s, &b, 0, rs->n, a.cnt, &sc) != KDR_OK) {
                fprintf(stderr, "FAIL: batch call on the large soup\n");
                failures++;
            }
            compare("large-soup", rs, s, caps[c], &a, &sl, &sc, "kdr_all_batch", 0);
            answers_free(&a);
        }
        rays_free(&sets[k]);
    }
    kdr_scene_free(s);
    free(src.tris);
}

int main(int argc, char **argv) {
    (void)argv;
    scene_src scenes[] = {make_soup(3000), make_lattice(6, 0.3f), make_sphere(24, 48)};
    for (size_t k = 0; k < sizeof scenes / sizeof scenes[0]; k++)
        check_scene(&scenes[k], k == 1);
    for (size_t k = 0; k < sizeof scenes / sizeof scenes[0]; k++)
        free(scenes[k].tris);
    if (scattered_sets < 3) {
        fprintf(stderr, "FAIL: only %d ray sets are scattered: the public calls' "
                        "interleaved route on small scenes went untested\n",
                scattered_sets);
        failures++;
    }
    if (mbox_saved == 0) {
        fprintf(stderr, "FAIL: the forced mailbox (KD_ALL_MBOX) saved no triangle test: "
                        "the lattice's triangles straddle many leaves\n");
        failures++;
    }
    if (argc < 2) check_large();
    printf("%s: %d mismatches (%d scattered sets, %llu tests saved by the mailbox)\n",
           failures ? "FAILED" : "passed", failures, scattered_sets, mbox_saved);
    return failures ? 1 : 0;
}
