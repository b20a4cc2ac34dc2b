/*
 * test_core_util.h — shared pieces of the core tests: a deterministic RNG,
 * the brute-force oracle (every triangle, kd_tri_intersect, the tie rule)
 * and a failure counter. Header-only so each test_core*.c stays standalone.
 */
#ifndef TEST_CORE_UTIL_H
#define TEST_CORE_UTIL_H

#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "kd_internal.h"
#include "kd_traverse.h"
#include "kd_tri.h"
#include "kd_walk.h"
#include "kdray.h"
#define CHECK_PRINT_MAX 20
#include "check.h"

static uint64_t g_rng = 0x9e3779b97f4a7c15ull;

static inline uint32_t rng_u32(void) {
    g_rng ^= g_rng << 13;
    g_rng ^= g_rng >> 7;
    g_rng ^= g_rng << 17;
    return (uint32_t)(g_rng >> 16);
}

static inline float rng_f(float lo, float hi) {
    return lo + (hi - lo) * (float)(rng_u32() >> 8) * 0x1p-24f;
}

/* Brute force: the reference answer of kdr_intersect1. */
static inline int brute_intersect(const float *tris, size_t ntris,
                                  const kdr_ray *r, kdr_hit *hit) {
    hit->t = -1.0f;
    hit->u = hit->v = 0.0f;
    hit->prim = -1;
    if (!kd_ray_valid(r->org, r->dir, r->tmin, r->tmax))
        return 0;
    kd_ray_pre pre;
    kd_ray_precompute(r->org, r->dir, &pre);
    float best_t = r->tmax, bu = 0, bv = 0;
    int32_t best = -1;
    for (size_t i = 0; i < ntris; i++) {
        float t, u, v;
        if (kd_tri_degenerate(tris + 9 * i))
            continue;
        if (kd_tri_intersect(&pre, tris + 9 * i, r->tmin, best_t, &t, &u, &v) &&
            kd_hit_better(t, (int32_t)i, best_t, best)) {
            best_t = t;
            bu = u;
            bv = v;
            best = (int32_t)i;
        }
    }
    if (best < 0)
        return 0;
    hit->t = best_t;
    hit->u = bu;
    hit->v = bv;
    hit->prim = best;
    return 1;
}

static inline int same_hit(const kdr_hit *a, const kdr_hit *b) {
    return a->prim == b->prim && memcmp(&a->t, &b->t, sizeof a->t) == 0 &&
           memcmp(&a->u, &b->u, sizeof a->u) == 0 &&
           memcmp(&a->v, &b->v, sizeof a->v) == 0;
}

/* Compares kd against brute force for one ray (closest hit, any hit, and
 * any hit walked from the far end); returns 1 when equal. */
static inline int compare_ray(const kdr_scene *s, const kdr_ray *r) {
    kdr_hit kh, bh;
    int kf = kdr_intersect1(s, r, &kh, NULL);
    int bf = brute_intersect(s->tris, s->ntris, r, &bh);
    int ka = kdr_occluded1(s, r, NULL);
    int kr = kd_occluded1_far(s, r, NULL);
    int kw = kd_occluded1_fwd(s, r, NULL);
    int ok = kf == bf && ka == bf && kr == bf && kw == bf && same_hit(&kh, &bh);
    if (!ok && failures < CHECK_PRINT_MAX)
        fprintf(stderr,
                "mismatch: org %a %a %a dir %a %a %a [%a, %a]\n"
                "  kd    %d prim %d t %a u %a v %a (any %d, far end first %d, front to back %d)\n"
                "  brute %d prim %d t %a u %a v %a\n",
                r->org[0], r->org[1], r->org[2], r->dir[0], r->dir[1],
                r->dir[2], r->tmin, r->tmax, kf, kh.prim, kh.t, kh.u, kh.v, ka, kr, kw,
                bf, bh.prim, bh.t, bh.u, bh.v);
    return ok;
}

#endif /* TEST_CORE_UTIL_H */
