/*
 * test_all.c — all hits (kdr_intersect_all1, kdr_all_batch) and hit counts
 * (kdr_count1, kdr_count_batch) against brute force and against Embree, on
 * the stress corpus (tests/support/stress.h: mixed adversarial rays plus
 * rays from inside the closed meshes) and on the bundled default scene.
 *
 * Per ray:
 *  - brute force: every non-degenerate triangle through kd_tri_intersect
 *    over [tmin, tmax], sorted by (t, prim). The kd list (cap 1024) must be
 *    sorted, prim-unique, and every entry must equal brute force's entry of
 *    that prim bit for bit; a brute-force hit the kd walk does not find is
 *    allowed only where cmp_hit_reason proves it a rounding case (the single
 *    walk's known cases, docs/ACCURACY.md), and is counted;
 *  - capped lists (1, 2, 3, 16) are the uncapped list's prefix, bit for bit;
 *    cap 1 is kdr_intersect1's hit; kdr_count1 is the uncapped length;
 *  - Embree (robust, a context filter that collects every hit): every prim
 *    on one list and not the other must be a proven rounding case;
 *  - 300 stacked squares across one ray (many_hits): 300 hits in t order
 *    uncapped and counted, the first 16 when capped.
 * The stress scenes have under 2.5 references per triangle, so their counts
 * run without the per-ray mailbox (kd_all.h, all_use_mbox; lists use it on
 * every scene); "blades" (long
 * thin triangles in random directions, asserted >= 2.5 references per
 * triangle) puts every check above through it, and mbox_between_rays
 * checks that a ray's mailbox does not outlive it (the same ray twice in a
 * row; 64 copies of it through the interleaved walk's slots).
 * Exit 1 on any unexplained difference.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "compare.h"
#include "kd_all_stream.h"
#include "kd_traverse.h"
#include "kd_tri.h"
#include "kdray.h"
#include "oracle.h"
#include "stress.h"
#ifdef KDRAY_HAVE_GLTF
#include "kdr_gltf.h"
#endif

#define SEED 20261201u
#define CAP KDR_MAX_HITS_LIMIT

typedef struct tally {
    unsigned long rays, hits, brute_only_explained, embree_explained, bad;
} tally;

static int g_printed;

static void bad(tally *t, const char *what, const kdr_ray *r) {
    t->bad++;
    if (g_printed++ < 10)
        fprintf(stderr, "  UNEXPLAINED %s: org %a %a %a dir %a %a %a [%a, %a]\n", what,
                r->org[0], r->org[1], r->org[2], r->dir[0], r->dir[1], r->dir[2], r->tmin,
                r->tmax);
}

static int by_t_prim(const void *a, const void *b) {
    const kdr_hit *x = a, *y = b;
    if (x->t != y->t) return x->t < y->t ? -1 : 1;
    return (x->prim > y->prim) - (x->prim < y->prim);
}

/* Every hit by brute force, sorted; returns the count (<= cap written). */
static size_t brute_all(const float *tris, size_t ntris, const kdr_ray *r, kdr_hit *out,
                        size_t cap) {
    if (!kd_ray_valid(r->org, r->dir, r->tmin, r->tmax)) return 0;
    kd_ray_pre pre;
    kd_ray_precompute(r->org, r->dir, &pre);
    size_t n = 0;
    for (size_t p = 0; p < ntris; p++) {
        const float *tri = tris + 9 * p;
        float t, u, v;
        if (kd_tri_degenerate(tri) ||
            !kd_tri_intersect(&pre, tri, r->tmin, r->tmax, &t, &u, &v))
            continue;
        if (n < cap) out[n] = (kdr_hit){t, u, v, (int32_t)p};
        n++;
    }
    qsort(out, n < cap ? n : cap, sizeof *out, by_t_prim);
    return n;
}

static int same_hit(const kdr_hit *a, const kdr_hit *b) {
    return memcmp(a, b, sizeof *a) == 0;
}

static const kdr_hit *find_prim(const kdr_hit *h, size_t n, int32_t prim) {
    for (size_t i = 0; i < n; i++)
        if (h[i].prim == prim) return &h[i];
    return NULL;
}

static void check_ray(const kdr_scene *sc, const oracle *o, const float *tris,
                      size_t ntris, const kdr_ray *r, tally *t) {
    static kdr_hit kd[CAP], br[CAP], em[CAP], capped[16];
    t->rays++;
    uint32_t nk = 0;
    if (kdr_intersect_all1(sc, r, CAP, kd, &nk, NULL) != KDR_OK) {
        bad(t, "kdr_intersect_all1 failed", r);
        return;
    }
    t->hits += nk;
    for (uint32_t i = 1; i < nk; i++)
        if (!(kd[i - 1].t < kd[i].t ||
              (kd[i - 1].t == kd[i].t && kd[i - 1].prim < kd[i].prim)))
            bad(t, "list not in (t, prim) order or a prim twice", r);
    const size_t nb = brute_all(tris, ntris, r, br, CAP);
    if (nb > CAP || nk == CAP) {
        fprintf(stderr, "  a ray with >= %u hits: raise CAP\n", CAP);
        t->bad++;
        return;
    }
    for (uint32_t i = 0; i < nk; i++) {
        const kdr_hit *b = find_prim(br, nb, kd[i].prim);
        if (!b || !same_hit(b, &kd[i]))
            bad(t, "kd hit that brute force does not give bit for bit", r);
    }
    for (size_t i = 0; i < nb; i++)
        if (!find_prim(kd, nk, br[i].prim)) {
            if (cmp_hit_reason(r, tris + 9 * (size_t)br[i].prim, br[i].t) == CMP_AGREE)
                bad(t, "brute-force hit the kd walk misses", r);
            else
                t->brute_only_explained++;
        }
    /* capped lists: the prefix, bit for bit */
    static const uint32_t caps[] = {1, 2, 3, 16};
    for (size_t c = 0; c < sizeof caps / sizeof caps[0]; c++) {
        uint32_t nc = 0;
        kdr_intersect_all1(sc, r, caps[c], capped, &nc, NULL);
        if (nc != (nk < caps[c] ? nk : caps[c]) ||
            memcmp(capped, kd, nc * sizeof *kd) != 0)
            bad(t, "capped list is not the prefix", r);
    }
    kdr_hit first;
    kdr_intersect1(sc, r, &first, NULL);
    if (nk ? !same_hit(&first, &kd[0]) : first.prim >= 0)
        bad(t, "first of all hits is not kdr_intersect1's hit", r);
    uint32_t cnt = 0;
    if (kdr_count1(sc, r, &cnt, NULL) != KDR_OK || cnt != nk)
        bad(t, "kdr_count1 differs from the list's length", r);
    /* Embree: the prims on one list only must be rounding cases */
    const size_t ne = oracle_all_filter(o, r, em, CAP);
    for (size_t i = 0; i < ne && i < CAP; i++)
        if (!find_prim(kd, nk, em[i].prim)) {
            if (cmp_hit_reason(r, tris + 9 * (size_t)em[i].prim, em[i].t) == CMP_AGREE)
                bad(t, "Embree hit that kd does not report", r);
            else
                t->embree_explained++;
        }
    for (uint32_t i = 0; i < nk; i++)
        if (!find_prim(em, ne < CAP ? ne : CAP, kd[i].prim)) {
            if (cmp_hit_reason(r, tris + 9 * (size_t)kd[i].prim, kd[i].t) == CMP_AGREE)
                bad(t, "kd hit that Embree does not report", r);
            else
                t->embree_explained++;
        }
}

/* The batch entry points equal the single-ray ones ray by ray, with the
 * origin shared (stride 0) and per ray. */
static void check_batch(const kdr_scene *sc, const kdr_ray *rays, size_t n, tally *t) {
    const uint32_t K = 4;
    float *org = malloc(3 * n * sizeof *org), *dir = malloc(3 * n * sizeof *dir);
    float *tmin = malloc(n * sizeof *tmin), *tmax = malloc(n * sizeof *tmax);
    uint32_t *nh = malloc(n * sizeof *nh), *cnt = malloc(n * sizeof *cnt);
    float *ht = malloc(n * K * sizeof *ht), *hu = malloc(n * K * sizeof *hu),
          *hv = malloc(n * K * sizeof *hv);
    int32_t *hp = malloc(n * K * sizeof *hp);
    for (size_t i = 0; i < n; i++) {
        memcpy(org + 3 * i, rays[i].org, sizeof rays[i].org);
        memcpy(dir + 3 * i, rays[i].dir, sizeof rays[i].dir);
        tmin[i] = rays[i].tmin;
        tmax[i] = rays[i].tmax;
    }
    for (int shared = 0; shared < 2; shared++) {
        kdr_ray_batch b = {n, org, shared ? 0 : 3, dir, tmin, 1, tmax, 1};
        kdr_all_hits out = {nh, ht, hu, hv, hp};
        if (kdr_all_batch(sc, &b, 0, n, K, &out, NULL) != KDR_OK ||
            kdr_count_batch(sc, &b, 0, n, cnt, NULL) != KDR_OK) {
            bad(t, "batch call failed", &rays[0]);
            break;
        }
        for (size_t i = 0; i < n; i++) {
            kdr_ray r = rays[i];
            if (shared) memcpy(r.org, org, sizeof r.org);
            kdr_hit h[4];
            uint32_t m = 0, c = 0;
            kdr_intersect_all1(sc, &r, K, h, &m, NULL);
            kdr_count1(sc, &r, &c, NULL);
            int ok = nh[i] == m && cnt[i] == c;
            for (uint32_t k = 0; ok && k < m; k++)
                ok = ht[i * K + k] == h[k].t && hp[i * K + k] == h[k].prim &&
                     hu[i * K + k] == h[k].u && hv[i * K + k] == h[k].v;
            if (!ok) bad(t, "batch answer differs from the single-ray one", &r);
        }
    }
    free(org), free(dir), free(tmin), free(tmax), free(nh), free(cnt);
    free(ht), free(hu), free(hv), free(hp);
}

static void print_tally(const char *label, const tally *t) {
    printf("%-16s rays %6lu hits %7lu brute-only(rounding) %lu embree-diff(rounding) "
           "%lu unexplained %lu\n",
           label, t->rays, t->hits, t->brute_only_explained, t->embree_explained, t->bad);
}

static int run_scene(const char *label, const float *tris, size_t ntris,
                     const kdr_ray *rays, size_t n, tally *total) {
    kdr_scene *sc = NULL;
    if (kdr_scene_build(tris, ntris, NULL, NULL, NULL, &sc) != KDR_OK) {
        fprintf(stderr, "%s: build failed\n", label);
        return 1;
    }
    oracle_opts oo;
    oracle_opts_judge(&oo);
    oo.context_filter = 1;
    oracle *o = oracle_create(tris, ntris, &oo);
    if (!o) {
        kdr_scene_free(sc);
        return 1;
    }
    tally t = {0};
    for (size_t i = 0; i < n; i++)
        check_ray(sc, o, tris, ntris, &rays[i], &t);
    check_batch(sc, rays, n < 500 ? n : 500, &t);
    print_tally(label, &t);
    total->rays += t.rays;
    total->hits += t.hits;
    total->brute_only_explained += t.brute_only_explained;
    total->embree_explained += t.embree_explained;
    total->bad += t.bad;
    oracle_free(o);
    kdr_scene_free(sc);
    return 0;
}

static int api_errors(void) {
    const float tri[9] = {0, 0, 0, 1, 0, 0, 0, 1, 0};
    kdr_scene *sc = NULL;
    if (kdr_scene_build(tri, 1, NULL, NULL, NULL, &sc) != KDR_OK) return 1;
    kdr_ray r = {{0.25f, 0.25f, 1}, {0, 0, -1}, 0, INFINITY};
    kdr_hit h[2];
    uint32_t n = 7, c = 0;
    int fails = 0;
    fails += kdr_intersect_all1(sc, &r, 0, h, &n, NULL) != KDR_EINVAL || n != 0;
    fails +=
        kdr_intersect_all1(sc, &r, KDR_MAX_HITS_LIMIT + 1, h, &n, NULL) != KDR_EINVAL;
    fails += kdr_intersect_all1(NULL, &r, 1, h, &n, NULL) != KDR_EINVAL;
    fails += kdr_count1(sc, NULL, &c, NULL) != KDR_EINVAL;
    fails += kdr_intersect_all1(sc, &r, 2, h, &n, NULL) != KDR_OK || n != 1 ||
             h[0].prim != 0 || h[0].t != 1.0f;
    fails += kdr_count1(sc, &r, &c, NULL) != KDR_OK || c != 1;
    /* a ray outside its interval, and an invalid one: no hits */
    r.tmax = 0.5f;
    fails += kdr_count1(sc, &r, &c, NULL) != KDR_OK || c != 0;
    r.tmax = INFINITY;
    r.dir[2] = 0.0f;
    fails += kdr_intersect_all1(sc, &r, 2, h, &n, NULL) != KDR_OK || n != 0;
    kdr_scene_free(sc);
    if (fails) fprintf(stderr, "api_errors: %d checks failed\n", fails);
    return fails;
}

/* Two triangles sharing an edge, a ray through that edge: two hits at the
 * same t (the documented definition), ordered by prim. */
static int shared_edge(void) {
    const float tris[18] = {0, 0, 0, 1, 0, 0, 0, 1, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0};
    kdr_scene *sc = NULL;
    if (kdr_scene_build(tris, 2, NULL, NULL, NULL, &sc) != KDR_OK) return 1;
    kdr_ray r = {{0.5f, 0.5f, 1}, {0, 0, -1}, 0, INFINITY};
    kdr_hit h[4];
    uint32_t n = 0, c = 0;
    kdr_intersect_all1(sc, &r, 4, h, &n, NULL);
    kdr_count1(sc, &r, &c, NULL);
    kdr_scene_free(sc);
    const int ok = n == 2 && c == 2 && h[0].prim == 0 && h[1].prim == 1 &&
                   h[0].t == 1.0f && h[1].t == 1.0f;
    if (!ok) fprintf(stderr, "shared_edge: n %u count %u\n", n, c);
    return !ok;
}

/* 300 stacked squares (two triangles each) across one ray: 300 hits, more
 * than count's insertion sort takes (32, then qsort), arriving within a
 * leaf in reference order rather than t order (the hit list's insertion
 * from its end must place them), uncapped and capped at 16. */
static int many_hits(void) {
    enum { N = 300 };
    float *tris = malloc(2 * N * 9 * sizeof *tris);
    /* squares in a shuffled order, so prim order is not t order */
    for (int i = 0; i < N; i++) {
        const float z = (float)((i * 7) % N);
        const float t[18] = {-1, -1, z, 1, -1, z, 1, 1, z, -1, -1, z, 1, 1, z, -1, 1, z};
        memcpy(tris + 18 * i, t, sizeof t);
    }
    kdr_scene *sc = NULL;
    if (kdr_scene_build(tris, 2 * N, NULL, NULL, NULL, &sc) != KDR_OK) {
        free(tris);
        return 1;
    }
    kdr_ray r = {{0.3f, 0.2f, -1}, {0, 0, 1}, 0, INFINITY}; /* below each diagonal */
    kdr_hit *h = malloc(KDR_MAX_HITS_LIMIT * sizeof *h);
    uint32_t n = 0, c = 0, n16 = 0;
    kdr_intersect_all1(sc, &r, KDR_MAX_HITS_LIMIT, h, &n, NULL);
    kdr_count1(sc, &r, &c, NULL);
    int bad = n != N || c != N;
    /* the k-th hit is on the square at z = k (t = k + 1 up to the
     * watertight test's rounding), its first triangle (an even prim) */
    for (uint32_t k = 0; !bad && k < n; k++)
        bad = fabsf(h[k].t - ((float)k + 1.0f)) > 1e-4f * ((float)k + 1.0f) ||
              (k > 0 && !(h[k].t > h[k - 1].t)) || (h[k].prim & 1) ||
              tris[9 * (size_t)h[k].prim + 2] != (float)k;
    kdr_hit h16[16];
    kdr_intersect_all1(sc, &r, 16, h16, &n16, NULL);
    bad |= n16 != 16 || (n == N && memcmp(h16, h, sizeof h16) != 0);
    if (bad) fprintf(stderr, "many_hits: n %u count %u capped %u\n", n, c, n16);
    free(h);
    free(tris);
    kdr_scene_free(sc);
    return bad;
}

/* Long thin blades in random directions across a box (seeded): the tree
 * clips each into many leaves, so the scene has >= 2.5 references per
 * triangle and every walk of all hits filters its leaves through the
 * per-ray mailbox (kd_all.h, all_use_mbox). Returns NULL on failure; the
 * caller checks the ratio. */
static float *blades_make(uint64_t seed, size_t n) {
    float *tris = malloc(9 * n * sizeof *tris);
    if (!tris) return NULL;
    stress_rng rng;
    stress_rng_seed(&rng, seed);
    for (size_t i = 0; i < n; i++) {
        float c[3], d[3], e[3], x[3];
        for (int k = 0; k < 3; k++)
            c[k] = 10.0f * stress_rng_float(&rng);
        stress_rng_dir(&rng, d);
        stress_rng_dir(&rng, x);
        /* e: x's part across d, a width of 0.4 */
        const float dx = d[0] * x[0] + d[1] * x[1] + d[2] * x[2];
        float len = 0.0f;
        for (int k = 0; k < 3; k++) {
            e[k] = x[k] - dx * d[k];
            len += e[k] * e[k];
        }
        len = sqrtf(len) > 1e-3f ? 0.4f / sqrtf(len) : 0.0f;
        float *t = tris + 9 * i;
        for (int k = 0; k < 3; k++) {
            t[k] = c[k] - 4.0f * d[k];
            t[3 + k] = c[k] + 4.0f * d[k];
            t[6 + k] = c[k] + len * e[k];
        }
    }
    return tris;
}

/* Rays through the blades' box: the stress corpus's mixed kinds (aimed at
 * vertices and edges, axis-aligned, odd intervals) built from the
 * triangles alone. */
static void blades_rays(float *tris, size_t ntris, size_t n, kdr_ray *rays) {
    stress_scene s = {STRESS_SOUP, tris, ntris, NULL, 0};
    stress_rays(&s, STRESS_RAYS_MIXED, SEED + 77, n, rays);
}

/* References per triangle of sc's tree. */
static double refs_per_tri(const kdr_scene *sc, size_t ntris) {
    kdr_tree_stats st;
    kdr_scene_tree_stats(sc, &st);
    return ntris ? (double)st.refs / (double)ntris : 0.0;
}

/* The mailbox is per ray: the same ray walked again right after itself
 * (the one-ray walk; its mailbox would still name every triangle it
 * tested) and 64 copies of it in one batch through the interleaved walk's
 * both forms (a slot's mailbox would outlive its ray) must give the first
 * walk's list and count. A mailbox kept across rays drops every repeated
 * test and answers fewer hits. Returns the number of failed checks. */
static int mbox_between_rays(const float *tris, size_t ntris, const kdr_ray *rays,
                             size_t nrays) {
    kdr_scene *sc = NULL;
    if (kdr_scene_build(tris, ntris, NULL, NULL, NULL, &sc) != KDR_OK) return 1;
    enum { COPIES = 64, K = 64 };
    static kdr_hit first[K], again[K];
    static float org[3 * COPIES], dir[3 * COPIES], ht[COPIES * K], hu[COPIES * K],
        hv[COPIES * K];
    static int32_t hp[COPIES * K];
    static uint32_t nh[COPIES], cnt[COPIES];
    kdr_hit buf[KD_ALL_RAYS * K];
    int fails = 0, tried = 0;
    for (size_t i = 0; i < nrays && tried < 40; i++) {
        kdr_ray r = rays[i];
        r.tmin = 0.0f;
        r.tmax = INFINITY;
        uint32_t n1 = 0, n2 = 0, c1 = 0, c2 = 0;
        kdr_intersect_all1(sc, &r, K, first, &n1, NULL);
        if (n1 < 2) continue; /* rays that hit something, through several leaves */
        tried++;
        kdr_intersect_all1(sc, &r, K, again, &n2, NULL);
        kdr_count1(sc, &r, &c1, NULL);
        kdr_count1(sc, &r, &c2, NULL);
        if (n2 != n1 || memcmp(first, again, n1 * sizeof *first) != 0 || c1 != c2 ||
            c1 < n1) {
            fprintf(stderr, "mbox_between_rays: ray %zu walked again: %u then %u hits, "
                            "counts %u then %u\n", i, n1, n2, c1, c2);
            fails++;
        }
        for (int k = 0; k < COPIES; k++) {
            memcpy(org + 3 * k, r.org, sizeof r.org);
            memcpy(dir + 3 * k, r.dir, sizeof r.dir);
        }
        const kdr_ray_batch b = {COPIES, org, 3, dir, NULL, 0, NULL, 0};
        kdr_all_hits out = {nh, ht, hu, hv, hp};
        static const int forms[] = {KD_ALL_SCALAR | KD_ALL_MBOX, KD_ALL_MBOX};
        for (int f = 0; f < 2; f++) {
            memset(nh, 0, sizeof nh);
            memset(cnt, 0, sizeof cnt);
            kd_all_stream(sc, &b, 0, COPIES, K, buf, &out, NULL, forms[f], NULL);
            kd_all_stream(sc, &b, 0, COPIES, 0, NULL, NULL, cnt, forms[f], NULL);
            int bad_copies = 0;
            for (int k = 0; k < COPIES; k++) {
                int ok = nh[k] == n1 && cnt[k] == c1;
                for (uint32_t j = 0; ok && j < n1; j++)
                    ok = ht[k * K + j] == first[j].t && hp[k * K + j] == first[j].prim &&
                         hu[k * K + j] == first[j].u && hv[k * K + j] == first[j].v;
                bad_copies += !ok;
            }
            if (bad_copies) {
                fprintf(stderr, "mbox_between_rays: ray %zu, %d of %d copies differ "
                                "(interleaved walk, flags %d)\n",
                        i, bad_copies, COPIES, forms[f]);
                fails++;
            }
        }
    }
    kdr_scene_free(sc);
    if (tried < 40) {
        fprintf(stderr, "mbox_between_rays: only %d rays with 2+ hits\n", tried);
        fails++;
    }
    return fails;
}

int main(int argc, char **argv) {
    const size_t nrays = argc > 1 ? (size_t)atol(argv[1]) : 1500;
    int fails = api_errors() + shared_edge() + many_hits();
    tally total = {0};
    kdr_ray *rays = malloc((nrays + 400) * sizeof *rays);
    for (int k = 0; k < STRESS_NSCENES; k++) {
        stress_scene s;
        if (stress_scene_make((stress_scene_kind)k, SEED, &s) != 0) return 1;
        stress_rays(&s, STRESS_RAYS_MIXED, SEED + (uint64_t)k, nrays, rays);
        const size_t ni = stress_inside_rays(&s, SEED, 400, rays + nrays);
        fails += run_scene(stress_scene_name((stress_scene_kind)k), s.tris, s.ntris, rays,
                           nrays + ni, &total);
        stress_scene_free(&s);
    }
    { /* blades: >= 2.5 references per triangle, every walk with the mailbox */
        enum { NB = 600 };
        float *bt = blades_make(SEED + 5, NB);
        kdr_scene *bs = NULL;
        if (!bt || kdr_scene_build(bt, NB, NULL, NULL, NULL, &bs) != KDR_OK) return 1;
        const double ratio = refs_per_tri(bs, NB);
        kdr_scene_free(bs);
        printf("blades: %.2f references per triangle\n", ratio);
        if (!(ratio >= 2.5)) {
            fprintf(stderr, "blades: %.2f references per triangle, under the mailbox's "
                            "2.5: the scene no longer covers it\n", ratio);
            fails++;
        }
        blades_rays(bt, NB, nrays, rays);
        fails += run_scene("blades", bt, NB, rays, nrays, &total);
        fails += mbox_between_rays(bt, NB, rays, nrays);
        free(bt);
    }
#ifdef KDRAY_HAVE_GLTF
    if (argc > 2) { /* a real scene: random rays through its box */
        kdr_gltf_scene gs, *g = &gs;
        char err[256];
        if (kdr_gltf_load(argv[2], g, err, sizeof err) != 0) {
            fprintf(stderr, "%s\n", err);
            return 1;
        }
        stress_rng rng;
        stress_rng_seed(&rng, SEED);
        kdr_bounds bb = {{INFINITY, INFINITY, INFINITY},
                         {-INFINITY, -INFINITY, -INFINITY}};
        for (size_t i = 0; i < 3 * g->ntris; i++)
            for (int k = 0; k < 3; k++) {
                const float x = g->tris[3 * i + k];
                bb.min[k] = x < bb.min[k] ? x : bb.min[k];
                bb.max[k] = x > bb.max[k] ? x : bb.max[k];
            }
        for (size_t i = 0; i < nrays; i++) {
            for (int k = 0; k < 3; k++)
                rays[i].org[k] =
                    bb.min[k] + (bb.max[k] - bb.min[k]) * stress_rng_float(&rng);
            stress_rng_dir(&rng, rays[i].dir);
            rays[i].tmin = 0.0f;
            rays[i].tmax = INFINITY;
        }
        fails += run_scene("gltf", g->tris, g->ntris, rays, nrays, &total);
        kdr_gltf_free(g);
    }
#endif
    free(rays);
    print_tally("total", &total);
    if (total.bad || fails) {
        printf("FAIL: %lu unexplained, %d other failures\n", total.bad, fails);
        return 1;
    }
    printf("ok\n");
    return 0;
}
