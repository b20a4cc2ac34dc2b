/*
 * kd_walk.h — the pieces of the single-ray walk that every walk of ONE ray
 * per stack shares: the to-do entry, the per-ray result, the ray's set-up
 * (validity, 1/dir, signed slack, root clip) and the leaf test (one ray
 * against a leaf's references, 1, 4 or 8 triangles at a time, with the tie
 * rule). kd_traverse_single.c walks one ray with them (the reference,
 * kdr_intersect1 / kdr_occluded1); kd_traverse_stream.c walks many rays of
 * a batch interleaved with exactly the same set-up, node rule and leaf
 * test, so both return the same bits. Internal to core/.
 */
#ifndef KD_WALK_H
#define KD_WALK_H

#include <math.h>

#include "kd_internal.h"
#include "kd_traverse.h"
#include "kd_tri.h"
#include "kd_tri_ntri.h"

typedef struct kd_walk_out {
    float t, u, v;
    int32_t prim;
    uint64_t nodes, tests;
} kd_walk_out;

/* Keeps hit (t, prim) when it beats the best by the tie rule. */
static inline void kd_walk_keep(kd_walk_out *o, float t, int32_t prim, float u, float v) {
    if (kd_hit_better(t, prim, o->t, o->prim)) {
        o->t = t;
        o->u = u;
        o->v = v;
        o->prim = prim;
    }
}

/* Tests four references at once (the last group repeats its final
 * reference); returns 1 at a hit when any != 0. All four use the best t at
 * the start of the group as tmax: a hit the scalar loop would reject with a
 * tighter tmax loses the tie rule anyway, so the best hit is the same. */
static inline int kd_walk_group4(const kdr_scene *s, const uint32_t *ref, uint32_t left,
                                 const kd_ntri_pre4 *pre4, float tmin, const int any,
                                 kd_walk_out *o) {
    const float *rows[4];
    int32_t prims[4];
    kd_ntri_rows4(s->tris, ref, left, prims, rows);
    f4 t, V, W, det;
    const int hits =
        kd_ntri_test4(pre4, rows, f4_set1(tmin), f4_set1(o->t), &t, &V, &W, &det);
    if (!hits) return 0;
    if (any) return 1;
    _Alignas(16) float tv[4], vv[4], wv[4], dv[4];
    f4_store(tv, t);
    f4_store(vv, V);
    f4_store(wv, W);
    f4_store(dv, det);
    for (int j = 0; j < 4; j++)
        if ((hits >> j) & 1 && kd_hit_better(tv[j], prims[j], o->t, o->prim))
            kd_walk_keep(o, tv[j], prims[j], vv[j] / dv[j], wv[j] / dv[j]);
    return 0;
}

/* A leaf of at least 8 references, eight at a time; the last group is the
 * last eight references (re-testing a reference cannot change the best hit:
 * an equal (t, prim) is not better). Returns 1 at a hit when any != 0. Not
 * inlined: the caller is not compiled for AVX2. */
KD_AVX2 __attribute__((noinline)) static int
kd_walk_leaf8(const kdr_scene *s, const uint32_t *ref, uint32_t count,
              const kd_ray_pre *pre, float tmin, const int any, kd_walk_out *o) {
    kd_ntri_pre8 pre8;
    kd_ntri_pre_init8(pre, &pre8);
    const f8 tmin8 = f8_set1(tmin);
    for (uint32_t i = 0; i < count; i += 8) {
        const uint32_t base = i + 8 <= count ? i : count - 8;
        const float *rows[8];
        for (int j = 0; j < 8; j++)
            rows[j] = s->tris + 9 * (size_t)ref[base + j];
        f8 t, V, W, det;
        const int hits =
            kd_ntri_test8(&pre8, rows, tmin8, f8_set1(o->t), &t, &V, &W, &det);
        if (!hits) continue;
        if (any) return 1;
        _Alignas(32) float tv[8], vv[8], wv[8], dv[8];
        f8_store(tv, t);
        f8_store(vv, V);
        f8_store(wv, W);
        f8_store(dv, det);
        for (int j = 0; j < 8; j++) {
            const int32_t prim = (int32_t)ref[base + j];
            if ((hits >> j) & 1 && kd_hit_better(tv[j], prim, o->t, o->prim))
                kd_walk_keep(o, tv[j], prim, vv[j] / dv[j], wv[j] / dv[j]);
        }
    }
    return 0;
}

/* References ref[0..count) eight at a time with pre8, for callers compiled
 * for AVX2 (kd_walk_leaf_w8). As in kd_walk_leaf8 the last group is the
 * last eight references; a list of fewer than eight fills its one group
 * by repeating its last reference (re-testing a reference cannot change
 * the best hit: an equal (t, prim) is not better). Only the hit lanes are
 * visited, in lane order. Returns 1 at a hit when any != 0. */
KD_AVX2 static inline __attribute__((always_inline)) int
kd_walk_groups8(const kdr_scene *s, const uint32_t *ref, uint32_t count,
                const kd_ntri_pre8 *pre8, float tmin, const int any, kd_walk_out *o) {
    const f8 tmin8 = f8_set1(tmin);
    for (uint32_t i = 0; i < count; i += 8) {
        const uint32_t base = i + 8 <= count ? i : count >= 8 ? count - 8 : 0;
        const uint32_t last = count - 1 - base;
        int32_t prims[8];
        const float *rows[8];
        for (uint32_t j = 0; j < 8; j++) {
            prims[j] = (int32_t)ref[base + (j < last ? j : last)];
            rows[j] = s->tris + 9 * (size_t)prims[j];
        }
        f8 t, V, W, det;
        const int hits =
            kd_ntri_test8(pre8, rows, tmin8, f8_set1(o->t), &t, &V, &W, &det);
        if (!hits) continue;
        if (any) return 1;
        _Alignas(32) float tv[8], vv[8], wv[8], dv[8];
        f8_store(tv, t);
        f8_store(vv, V);
        f8_store(wv, W);
        f8_store(dv, det);
        for (unsigned m = (unsigned)hits; m; m &= m - 1) { /* the hit lanes, in order */
            const int j = __builtin_ctz(m);
            if (kd_hit_better(tv[j], prims[j], o->t, o->prim))
                kd_walk_keep(o, tv[j], prims[j], vv[j] / dv[j], wv[j] / dv[j]);
        }
    }
    return 0;
}

/* Tests every triangle of leaf n over [tmin, best t] and keeps the best by
 * the tie rule; returns 1 at the first hit when any != 0. Leaves of at least
 * KD_LEAF_SIMD_MIN references go four at a time. */
static inline int kd_walk_leaf(const kdr_scene *s, const kd_node *n,
                               const kd_ray_pre *pre, const kd_ntri_pre4 *pre4,
                               float tmin, const int any, const int avx2,
                               kd_walk_out *o) {
    /* a floor or wall behind the origin (kd_leaf_behind): nothing to find */
    if (tmin >= 0.0f && kd_leaf_behind(s, n, pre->kz, pre->org[pre->kz], pre->sz))
        return 0;
    const uint32_t *ref = s->refs + n->u.first;
    const uint32_t count = kd_count(n);
    o->tests += count;
    if (avx2 && count >= KD_LEAF_AVX2_MIN)
        return kd_walk_leaf8(s, ref, count, pre, tmin, any, o);
    if (count >= KD_LEAF_SIMD_MIN) {
        for (uint32_t i = 0; i < count; i += 4)
            if (kd_walk_group4(s, ref + i, count - i, pre4, tmin, any, o)) return 1;
        return 0;
    }
    for (uint32_t i = 0; i < count; i++) {
        float t, u, v;
        const int32_t prim = (int32_t)ref[i];
        if (!kd_tri_intersect(pre, s->tris + 9 * (size_t)prim, tmin, o->t, &t, &u, &v))
            continue;
        if (any) return 1;
        kd_walk_keep(o, t, prim, u, v);
    }
    return 0;
}

/* kd_walk_leaf for callers compiled for AVX2 (the interleaved walk's
 * closest-hit lanes; its any-hit lanes keep kd_walk_leaf, for which the
 * padded short lists cost more than the count's mispredicts, see
 * docs/TRAVERSAL.md): every leaf eight references at a time, however few
 * it holds, so the test takes one path whatever the count (kd_walk_leaf's
 * choice between one, four and eight at a time is a branch on the count,
 * which mispredicts for incoherent rays); a leaf of fewer than eight repeats its
 * last reference (kd_walk_groups8). Same answer as kd_walk_leaf. */
KD_AVX2 static inline __attribute__((always_inline)) int
kd_walk_leaf_w8(const kdr_scene *s, const kd_node *n, const kd_ntri_pre8 *pre8,
                float tmin, const int any, kd_walk_out *o) {
    if (tmin >= 0.0f &&
        kd_leaf_behind(s, n, pre8->kz, f8_first(pre8->oz), f8_first(pre8->sz)))
        return 0; /* as kd_walk_leaf */
    const uint32_t count = kd_count(n);
    o->tests += count;
    return kd_walk_groups8(s, s->refs + n->u.first, count, pre8, tmin, any, o);
}

/* The ray's set-up, three axes per SSE operation: validity (kd_ray_valid),
 * 1 / dir, the signed slack (kd_ray_slack, kd_signed_slack) and the root
 * clip (kd_clip_root_slack), every lane with the scalar operations, so the
 * interval is the scalar one bit for bit (max and min of the same non-NaN
 * values in another order). Lane 3 carries neutral values. Returns 0 when
 * the ray cannot be traced or misses the root box. */
static inline int kd_walk_setup(const kdr_scene *s, const kdr_ray *r, float inv[3],
                                float ss[3], unsigned neg[3], float *tn, float *tf) {
    /* org[0..2] and dir[0..2], each loaded with the next float of kdr_ray */
    const f4 org = f4_loadu(r->org), dir = f4_loadu(r->dir);
    const f4 zero = f4_set1(0.0f);
    const int finite = f4_bits(f4_eq(f4_sub(org, org), zero)) &
                       f4_bits(f4_eq(f4_sub(dir, dir), zero)) & 7;
    const int flat = f4_bits(f4_eq(dir, zero)) | 8;
    if (finite != 7 || flat == 15 || !(r->tmin <= r->tmax)) return 0;
    const f4 iv = f4_div(f4_set1(1.0f), f4_lane3(dir, 1.0f));
    const f4 sgn = f4_set1(-0.0f);
    const float slack =
        f4_hmax(f4_lane3(f4_max(f4_andnot(sgn, org), f4_set1(s->root_mag)), 0.0f)) *
        KD_SLACK_REL;
    const f4 sl = f4_set1(slack);
    _Alignas(16) float ivv[4], ssv[4];
    f4_store(ivv, iv);
    f4_store(ssv, f4_xor(sl, f4_and(iv, sgn)));
    const int sign = f4_bits(dir);
    for (int k = 0; k < 3; k++) {
        inv[k] = ivv[k];
        ss[k] = ssv[k];
        neg[k] = (unsigned)(sign >> k) & 1u;
    }
    /* the root clip; a flat axis (direction 0) only rejects an origin
     * outside the grown slab (kdr_bounds: max follows min in memory) */
    const f4 lo = f4_sub(f4_loadu(s->root.min), sl);
    const f4 hi = f4_add(f4_loadu(s->root.max), sl);
    const f4 fl = f4_bitmask(flat);
    if (f4_bits(f4_and(fl, f4_or(f4_lt(org, lo), f4_gt(org, hi)))) & 7) return 0;
    const f4 t0 = f4_mul(f4_sub(lo, org), iv), t1 = f4_mul(f4_sub(hi, org), iv);
    /* entry min(t1, t0) and exit max(t0, t1): the scalar swap's result,
     * NaN included; flat axes and lane 3 constrain nothing */
    const f4 ent = f4_sel(fl, f4_set1(-INFINITY), f4_min(t1, t0));
    const f4 ext = f4_sel(fl, f4_set1(INFINITY), f4_max(t0, t1));
    *tn = f4_hmax(f4_max(ent, f4_set1(r->tmin)));
    *tf = f4_hmin(f4_min(ext, f4_set1(r->tmax)));
    return *tn <= *tf;
}

/* kdr_occluded1's answer from a walk that visits the ray's cells back to
 * front: the cell of the interval's far end (tmax, or the root box's exit)
 * first, each interior node's far child before its near one, with the
 * same intervals, leaf test and pruning (kd_traverse_single.c). An
 * any-hit answer does not depend on the order in which cells are visited,
 * so the bits are kdr_occluded1's; only the steps differ. */
int kd_occluded1_far(const kdr_scene *scene, const kdr_ray *ray,
                     kdr_trav_stats *stats);

/* kdr_occluded1's answer from the front-to-back walk (the cells in the
 * ray's order from its start), whatever kdr_occluded1's own choice of
 * order: the walk whose steps kd_entry_occluded1 and the interleaved
 * walk's front-to-back forms take. */
int kd_occluded1_fwd(const kdr_scene *scene, const kdr_ray *ray,
                     kdr_trav_stats *stats);

#endif /* KD_WALK_H */
