/*
 * kd_all.h — what the two walks of all hits and counts share: the one-ray
 * walk (kd_all.c, kdr_intersect_all1 / kdr_count1, the reference) and the
 * interleaved walk of a batch (kd_all_stream.c, kdr_all_batch /
 * kdr_count_batch): the to-do entry, where accepted hits go (the sink: a
 * sorted, prim-unique list for "all", a growing list of prims for "count"),
 * a leaf's test (1, 4 or 8 references at a time; on scenes of many
 * references per triangle first filtered by the ray's mailbox of prims it
 * tested already) and the ray's set-up. Both
 * walks call exactly these, so their answers are the same bits. Internal
 * to core/.
 */
#ifndef KD_ALL_H
#define KD_ALL_H

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "kd_internal.h"
#include "kd_all_stream.h"
#include "kd_tune.h"
#include "kd_traverse.h"
#include "kd_tri.h"
#include "kd_tri_ntri.h"

#define KD_COUNT_STACK 256
/* Leaves of at least this many references are tested eight at a time on
 * AVX2 CPUs (one call where two groups of four cost more). */
#define KD_ALL_LEAF8_MIN 5
/* The per-ray mailbox of tested prims (direct-mapped by prim's low bits;
 * a power of two), and the longest leaf it filters (longer ones are tested
 * whole: the filtered list lives on the stack). */
#define KD_ALL_MBOX_SLOTS 64
#define KD_ALL_MBOX_LEAF 64
/* Counts use the mailbox on scenes of at least KD_ALL_MBOX_REFS_NUM /
 * KD_ALL_MBOX_REFS_DEN references per triangle (lists on every scene:
 * all_use_mbox), where repeated tests are
 * common enough to pay for it (docs/TRAVERSAL.md, round 6: haus 3.28 and
 * engine9 2.93 gained, 2CylinderEngine 2.39 even, duck 2.16 lost). */
#define KD_ALL_MBOX_REFS_NUM 5
#define KD_ALL_MBOX_REFS_DEN 2

/* Where accepted hits go: a sorted, prim-unique list of at most cap hits
 * (all), or a growing list of prims (count). */
typedef struct all_sink {
    kdr_hit *hits; /* all: sorted by (t, prim) */
    uint32_t cap, n;
    uint32_t *prims; /* count */
    size_t np, pcap;
    int heap, oom;
    float bound; /* triangle tests use [tmin, bound] */
    uint64_t nodes, tests;
    /* the ray's mailbox, KD_ALL_MBOX_SLOTS entries (all_mbox_start), or
     * NULL: none. Entry prim % KD_ALL_MBOX_SLOTS holds prim + 1 of the last
     * prim tested there (0: none). */
    uint32_t *mbox;
} all_sink;

/* Gives the sink the mailbox mb, emptied (the walk's own storage, once
 * per ray, on scenes where all_use_mbox or KD_ALL_MBOX says so). */
static inline void all_mbox_start(all_sink *s, uint32_t *mb) {
    memset(mb, 0, KD_ALL_MBOX_SLOTS * sizeof *mb);
    s->mbox = mb;
}

/* all: inserts (t, prim) unless it is already held or cannot be among the
 * first cap hits. The walk goes front to back, so a new hit mostly
 * belongs at or near the end: its place is found from the end. */
static void keep_all(all_sink *s, float t, int32_t prim, float u, float v) {
    if (s->n == s->cap &&
        !kd_hit_better(t, prim, s->hits[s->n - 1].t, s->hits[s->n - 1].prim))
        return;
    /* first position whose (t, prim) is not better than the new one */
    uint32_t lo = s->n;
    while (lo > 0 && !kd_hit_better(s->hits[lo - 1].t, s->hits[lo - 1].prim, t, prim))
        lo--;
    if (lo < s->n && s->hits[lo].prim == prim)
        return; /* the same triangle, found again in another leaf */
    const uint32_t keep = s->n < s->cap ? s->n : s->cap - 1;
    for (uint32_t i = keep; i > lo; i--)
        s->hits[i] = s->hits[i - 1];
    s->hits[lo] = (kdr_hit){t, u, v, prim};
    s->n = keep + 1;
    if (s->n == s->cap) s->bound = s->hits[s->n - 1].t;
}

/* count: appends prim, growing the buffer (first move: off the stack). */
static void keep_prim(all_sink *s, int32_t prim) {
    if (s->np == s->pcap) {
        const size_t cap = 2 * s->pcap;
        uint32_t *p =
            s->heap ? realloc(s->prims, cap * sizeof *p) : malloc(cap * sizeof *p);
        if (!p) {
            s->oom = 1;
            return;
        }
        if (!s->heap) memcpy(p, s->prims, s->np * sizeof *p);
        s->prims = p;
        s->pcap = cap;
        s->heap = 1;
    }
    s->prims[s->np++] = (uint32_t)prim;
}

/* One accepted hit into the sink. */
static inline void keep(all_sink *s, float t, int32_t prim, float u, float v) {
    if (s->hits)
        keep_all(s, t, prim, u, v);
    else
        keep_prim(s, prim);
}

/* The hit lanes (bit j of hits) of a group of w tests, stored lane by
 * lane: each one at or before the bound is kept with its u, v divided out
 * (the division only for hits, as the scalar test does it). */
static inline void keep_lanes(all_sink *s, int hits, int w, const float *tv,
                              const float *vv, const float *wv, const float *dv,
                              const int32_t *prims) {
    for (int j = 0; j < w; j++)
        if ((hits >> j) & 1 && tv[j] <= s->bound)
            keep(s, tv[j], prims[j], vv[j] / dv[j], wv[j] / dv[j]);
}

/* Four references at once (the last group repeats its final reference: a
 * hit found twice is kept once); the same float operations as
 * kd_tri_intersect, so t, u, v are bit for bit the scalar ones. */
static void test_group4(const kdr_scene *sc, const uint32_t *ref, uint32_t left,
                        const kd_ntri_pre4 *pre4, float tmin, all_sink *s) {
    const float *rows[4];
    int32_t prims[4];
    kd_ntri_rows4(sc->tris, ref, left, prims, rows);
    f4 t, V, W, det;
    const int hits =
        kd_ntri_test4(pre4, rows, f4_set1(tmin), f4_set1(s->bound), &t, &V, &W, &det);
    if (!hits) return;
    _Alignas(16) float tv[4], vv[4], wv[4], dv[4];
    f4_store(tv, t);
    f4_store(vv, V);
    f4_store(wv, W);
    f4_store(dv, det);
    keep_lanes(s, hits, 4, tv, vv, wv, dv, prims);
}

/* Eight at a time (AVX2), a tail of four or fewer four at a time (the
 * last four references), a longer tail as the last eight references; a
 * hit found twice is kept once. Not inlined: the caller is not compiled
 * for AVX2. */
KD_AVX2 __attribute__((noinline)) static void
test_leaf8(const kdr_scene *sc, const uint32_t *ref, uint32_t count,
           const kd_ray_pre *pre, const kd_ntri_pre4 *pre4, float tmin, all_sink *s) {
    kd_ntri_pre8 pre8;
    kd_ntri_pre_init8(pre, &pre8);
    const f8 tmin8 = f8_set1(tmin);
    for (uint32_t i = 0; i < count && !s->oom; i += 8) {
        if (i > 0 && count - i <= 4) {
            test_group4(sc, ref + count - 4, 4, pre4, tmin, s);
            return;
        }
        /* a leaf of fewer than eight repeats its last reference */
        const uint32_t base = i + 8 <= count ? i : count >= 8 ? count - 8 : 0;
        const float *rows[8];
        int32_t prims[8];
        for (uint32_t j = 0; j < 8; j++) {
            prims[j] = (int32_t)ref[base + j < count ? base + j : count - 1];
            rows[j] = sc->tris + 9 * (size_t)prims[j];
        }
        f8 t, V, W, det;
        const int hits =
            kd_ntri_test8(&pre8, rows, tmin8, f8_set1(s->bound), &t, &V, &W, &det);
        if (!hits) continue;
        _Alignas(32) float tv[8], vv[8], wv[8], dv[8];
        f8_store(tv, t);
        f8_store(vv, V);
        f8_store(wv, W);
        f8_store(dv, det);
        keep_lanes(s, hits, 8, tv, vv, wv, dv, prims);
    }
}

/* Every reference of leaf n over [tmin, bound]: leaves of at least
 * KD_ALL_LEAF8_MIN references eight at a time (test_leaf8), of at least
 * KD_LEAF_SIMD_MIN four at a time, smaller ones one by one. prefetch:
 * request the leaf's triangles first (sc->prefetch_leaves; 0 where a
 * staged walk requested them already). With a mailbox (s->mbox) the
 * references whose prim it holds are dropped first; s->tests counts the
 * tests made. */
static void test_leaf(const kdr_scene *sc, const kd_node *n, const kd_ray_pre *pre,
                      const kd_ntri_pre4 *pre4, int avx2, float tmin, all_sink *s,
                      int prefetch) {
    const uint32_t *ref = sc->refs + n->u.first;
    uint32_t count = kd_count(n);
    if (prefetch) kd_prefetch_tris(sc, ref, count);
    /* Each triangle once per ray: references whose prim the mailbox says
     * this ray tested already (in an earlier leaf: a triangle straddling
     * several) are dropped. Exact: the test depends only on the ray, the
     * triangle, tmin and the bound, and the bound only shrinks, so the
     * dropped test would be rejected or found again in the sink as the
     * same hit (keep_all's duplicate, a count's repeated prim). */
    uint32_t fresh[KD_ALL_MBOX_LEAF];
    if (s->mbox && count <= KD_ALL_MBOX_LEAF) {
        uint32_t m = 0;
        for (uint32_t i = 0; i < count; i++) {
            const uint32_t p = ref[i];
            uint32_t *slot = &s->mbox[p & (KD_ALL_MBOX_SLOTS - 1)];
            fresh[m] = p;
            m += *slot != p + 1;
            *slot = p + 1;
        }
        ref = fresh;
        count = m;
    }
    s->tests += count;
    if (avx2 && count >= KD_ALL_LEAF8_MIN) {
        test_leaf8(sc, ref, count, pre, pre4, tmin, s);
        return;
    }
    if (count >= KD_LEAF_SIMD_MIN) {
        for (uint32_t i = 0; i < count && !s->oom; i += 4)
            test_group4(sc, ref + i, count - i, pre4, tmin, s);
        return;
    }
    for (uint32_t i = 0; i < count && !s->oom; i++) {
        float t, u, v;
        const int32_t prim = (int32_t)ref[i];
        if (kd_tri_intersect(pre, sc->tris + 9 * (size_t)prim, tmin, s->bound, &t, &u,
                             &v))
            keep(s, t, prim, u, v);
    }
}

/* Whether walks on sc use the sink's mailbox (test_leaf's mbox): lists
 * (list: max_hits > 0) on every scene, counts on scenes of many references
 * per triangle. Lists with it against without (bench/ab c2c189b . --rays
 * 32768 --rounds 3, load 3.1-3.5, docs/TRAVERSAL.md round 8): duck all16 /
 * all / ball16 / ball 1.073 / 1.038 / 1.049 / 1.068, 2CylinderEngine
 * 1.102 / 1.094 / 1.121 / 1.074; counts with it lost on duck (count 0.945,
 * bcount 0.958, load 2.2-2.7). */
static inline int all_use_mbox(const kdr_scene *sc, int list) {
    return list || KD_ALL_MBOX_REFS_DEN * sc->nrefs >= KD_ALL_MBOX_REFS_NUM * sc->ntris;
}

/* The ray's set-up as kd_all.c's walk() writes it out (the single-ray
 * walk's scalar forms: kd_ray_valid,
 * 1 / dir, kd_ray_slack, kd_signed_slack, kd_clip_root_slack): inv, ss,
 * the root interval [tn, tf] and the triangle-test set-up. Returns 0 when
 * the ray cannot be traced or misses the root box. */
static inline int all_setup(const kdr_scene *sc, const kdr_ray *r, float inv[3],
                            float ss[3], float *tn, float *tf, kd_ray_pre *pre,
                            kd_ntri_pre4 *pre4) {
    if (!sc || !sc->nodes || !kd_ray_valid(r->org, r->dir, r->tmin, r->tmax)) return 0;
    for (int k = 0; k < 3; k++)
        inv[k] = 1.0f / r->dir[k];
    const float slack = kd_ray_slack(sc, r->org);
    kd_signed_slack(slack, inv, ss);
    if (!kd_clip_root_slack(sc, r->org, r->dir, inv, slack, r->tmin, r->tmax, tn, tf))
        return 0;
    kd_ray_precompute(r->org, r->dir, pre);
    kd_ntri_pre_init4(pre, pre4);
    return 1;
}

static int cmp_u32(const void *a, const void *b) {
    const uint32_t x = *(const uint32_t *)a, y = *(const uint32_t *)b;
    return (x > y) - (x < y);
}

/* Sorts the prims of a ray: by insertion when there are few (the common
 * case, where qsort's calls through a comparison pointer cost more than
 * the walk's hit collection), else qsort. */
static void sort_prims(uint32_t *p, size_t n) {
    if (n > 32) {
        qsort(p, n, sizeof *p, cmp_u32);
        return;
    }
    for (size_t i = 1; i < n; i++) {
        const uint32_t x = p[i];
        size_t j = i;
        for (; j > 0 && p[j - 1] > x; j--)
            p[j] = p[j - 1];
        p[j] = x;
    }
}

/* count: the number of distinct prims the sink holds (sorting them);
 * frees a heap buffer. */
static uint32_t all_distinct(all_sink *s) {
    if (!s->oom) sort_prims(s->prims, s->np);
    uint32_t distinct = 0;
    for (size_t i = 0; i < s->np; i++)
        distinct += i == 0 || s->prims[i] != s->prims[i - 1];
    if (s->heap) free(s->prims);
    return distinct;
}

static void add_stats(kdr_trav_stats *st, const all_sink *s) {
    if (!st) return;
    st->rays++;
    st->nodes_visited += s->nodes;
    st->tri_tests += s->tests;
}

/* Ray i's list of nh hits into out (slots i * max_hits on). */
static inline void all_put_list(kdr_all_hits *out, size_t i, uint32_t max_hits,
                                const kdr_hit *h, uint32_t nh) {
    out->nhits[i] = nh;
    const size_t base = i * (size_t)max_hits;
    for (uint32_t k = 0; k < nh; k++) {
        out->t[base + k] = h[k].t;
        out->prim[base + k] = h[k].prim;
        out->u[base + k] = h[k].u;
        out->v[base + k] = h[k].v;
    }
}

/* A batch walk's answer for ray i from its sink: the list into out, or
 * (max_hits 0) the count into counts (0, and KDR_ENOMEM into *rc, when the
 * sink ran out of memory); adds the sink's work to stats. */
static inline void all_answer(all_sink *s, size_t i, uint32_t max_hits, kdr_all_hits *out,
                              uint32_t *counts, kdr_trav_stats *stats, int *rc) {
    add_stats(stats, s);
    if (!max_hits) {
        const uint32_t d = all_distinct(s);
        if (s->oom) *rc = KDR_ENOMEM;
        counts[i] = s->oom ? 0 : d;
        return;
    }
    all_put_list(out, i, max_hits, s->hits, s->n);
}

/* The ray i of a batch (kd_batch.c reads batches the same way). */
static void all_batch_ray(const kdr_ray_batch *b, size_t i, kdr_ray *r) {
    const float *o = b->org + (b->org_stride ? 3 * i : 0);
    for (int k = 0; k < 3; k++) {
        r->org[k] = o[k];
        r->dir[k] = b->dir[3 * i + k];
    }
    r->tmin = b->tmin ? b->tmin[b->tmin_stride ? i : 0] : 0.0f;
    r->tmax = b->tmax ? b->tmax[b->tmax_stride ? i : 0] : INFINITY;
}

#endif /* KD_ALL_H */
