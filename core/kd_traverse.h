/*
 * kd_traverse.h — small helpers every traversal shares: ray validation,
 * clipping a ray to the scene's padded root box, the interior-node step
 * convention, and the degenerate-triangle predicate the build uses (so that
 * brute-force oracles in tests can skip exactly the same triangles).
 *
 * Split-plane convention (single rays; bundles, cones and frusta must be at
 * least as conservative). With a = split - org[axis], inv = 1.0f / dir and
 * the ray's positional slack s (kd_ray_slack) signed like inv
 * (ss = kd_signed_slack):
 *   t_lo = (a - ss) * inv,  t_hi = (a + ss) * inv
 * are where the ray crosses the planes split -/+ s. The child the ray is in
 * for small t is the "near" child: below when inv > 0 (including
 * dir = +0.0), above when inv < 0 (including dir = -0.0). The near child is
 * visited over [tnear, min(tfar, t_hi)], the far child over
 * [max(tnear, t_lo), tfar], each only when that interval is not empty (a
 * single point counts). This holds for every sign of a, so the origin may
 * lie on either side or on the plane. Along an axis where the direction is
 * 0, t_lo and t_hi are infinities: the ray visits the origin's side, and
 * both sides (full interval) when the origin is within s of the plane. A NaN
 * (a = +-ss with dir 0) also visits both children with the full interval.
 *
 * Why the slack: kd_tri_intersect is watertight for the triangle as seen
 * after rounding the translation, shear and edge products, which can move
 * it a few ulps of |vertex - origin|, even along an axis where the ray does
 * not move. A ray aimed at a vertex lying in a split plane may pass it a
 * hair on the wrong side and still "hit" the triangle, so every leaf within
 * s (a small multiple of the scene's and origin's magnitude) of the ray must
 * be visited for answers to equal brute force.
 */
#ifndef KD_TRAVERSE_H
#define KD_TRAVERSE_H

#include <math.h>
#include <stdint.h>
#include <string.h>

#include "kd_internal.h"

/* Positional slack of every traversal, relative to the largest coordinate
 * magnitude of the scene or the ray origin (2^-16: ~128 ulps). */
#define KD_SLACK_REL 0x1p-16f

/* The ray's positional slack: KD_SLACK_REL times the largest magnitude of
 * the root box and the origin (plain compares: fmaxf is a library call
 * without -ffast-math). */
static inline float kd_ray_slack(const struct kdr_scene *s, const float org[3]) {
    float m = 0.0f;
    for (int k = 0; k < 3; k++) {
        const float a = -s->root.min[k], b = s->root.max[k];
        const float o = org[k] < 0.0f ? -org[k] : org[k];
        m = a > m ? a : m;
        m = b > m ? b : m;
        m = o > m ? o : m;
    }
    return m * KD_SLACK_REL;
}

/* The slack with the sign of inv_dir per axis (see the convention above). */
static inline void kd_signed_slack(float slack, const float inv_dir[3],
                                   float ss[3]) {
    for (int k = 0; k < 3; k++)
        ss[k] = signbit(inv_dir[k]) ? -slack : slack;
}

/* 1 if the ray can be traced: finite origin and direction, non-zero
 * direction, no NaN interval, tmin <= tmax. */
static inline int kd_ray_valid(const float org[3], const float dir[3],
                               float tmin, float tmax) {
    for (int k = 0; k < 3; k++)
        if (!isfinite(org[k]) || !isfinite(dir[k]))
            return 0;
    if (dir[0] == 0.0f && dir[1] == 0.0f && dir[2] == 0.0f)
        return 0;
    return tmin <= tmax; /* false for NaN */
}

/*
 * Clips [tmin, tmax] to the scene's padded root box grown by slack. This is
 * the scalar definition; the single walk (setup() in kd_traverse_single.c)
 * and the bundles (kb_clip) compute it three or more lanes at a time with
 * the same operations. An axis
 * with a zero direction component constrains nothing when the origin is
 * inside the (grown) slab and rejects the ray otherwise (no 0 * inf).
 * Returns 0 when the ray misses.
 */
static inline int kd_clip_root_slack(const struct kdr_scene *s,
                                     const float org[3], const float dir[3],
                                     const float inv_dir[3], float slack,
                                     float tmin, float tmax, float *tnear,
                                     float *tfar) {
    float tn = tmin, tf = tmax;
    for (int k = 0; k < 3; k++) {
        const float lo = s->root.min[k] - slack, hi = s->root.max[k] + slack;
        if (dir[k] == 0.0f) {
            if (org[k] < lo || org[k] > hi)
                return 0;
            continue;
        }
        float t0 = (lo - org[k]) * inv_dir[k];
        float t1 = (hi - org[k]) * inv_dir[k];
        if (t0 > t1) {
            float tmp = t0;
            t0 = t1;
            t1 = tmp;
        }
        tn = t0 > tn ? t0 : tn;
        tf = t1 < tf ? t1 : tf;
    }
    *tnear = tn;
    *tfar = tf;
    return tn <= tf;
}

/*
 * Zero-area test: the edge cross product in double precision is exactly
 * zero. Float differences and float-by-float products are exact in double
 * for all but extreme exponent spreads, so this is "exactly collinear".
 * Such triangles keep their number but are never put in the tree.
 */
static inline int kd_tri_degenerate(const float *tri) {
    double e1[3], e2[3];
    for (int k = 0; k < 3; k++) {
        e1[k] = (double)tri[3 + k] - (double)tri[k];
        e2[k] = (double)tri[6 + k] - (double)tri[k];
    }
    double cx = e1[1] * e2[2] - e1[2] * e2[1];
    double cy = e1[2] * e2[0] - e1[0] * e2[2];
    double cz = e1[0] * e2[1] - e1[1] * e2[0];
    return cx == 0.0 && cy == 0.0 && cz == 0.0;
}

/* A subtree still to visit over [tn, tf]: the walks' stack entry. */
typedef struct kd_todo {
    const kd_node *node;
    float tn, tf;
} kd_todo;

/* c ? a : b for c in {0, 1}, without a branch: the interleaved walks'
 * node steps (kd_step_nobranch), where the next address may wait for a
 * compare because other rays fill the wait. */
static inline uint32_t kd_sel_u32(uint32_t c, uint32_t a, uint32_t b) {
    const uint32_t m = 0u - c;
    return (a & m) | (b & ~m);
}
static inline float kd_sel_f32(uint32_t c, float a, float b) {
    uint32_t x, y;
    memcpy(&x, &a, 4);
    memcpy(&y, &b, 4);
    x = kd_sel_u32(c, x, y);
    memcpy(&a, &x, 4);
    return a;
}

/* The interleaved walks' node step (kd_traverse_stream.c, kd_all_stream.c):
 * the single walk's descent at interior node n, one node per turn, without
 * its branches (a mispredicted branch would stall every ray in flight).
 * With t_lo <= t_hi, or a NaN, its five cases are "near needed unless t_hi
 * < tn" and "far needed unless t_lo > tf", minus an empty child (bit 2 of
 * bits: below empty, bit 3: above; at most one child of a node is empty).
 * The far entry is always written to stack[*sp] (sp < KD_MAX_DEPTH at an
 * interior node: the build splits only above depth KD_MAX_DEPTH) and kept
 * only when both children are taken. When only the near child is taken
 * because t_lo > tf, min(t_hi, tf) is tf; when only the far one because
 * t_hi < tn, max(t_lo, tn) is tn: the intervals are the single walk's, its
 * float operations in its order. Returns the child to visit next with its
 * interval in *tn, *tf, or NULL when neither child is needed (pop). */
static inline const kd_node *kd_step_nobranch(const kd_node *nodes, const kd_node *n,
                                              const float org[3], const float inv[3],
                                              const float ss[3], const uint32_t neg[3],
                                              float *tn, float *tf, kd_todo *stack,
                                              int *sp) {
    const int axis = kd_axis(n);
    const float a = n->u.split - org[axis];
    const float t_lo = (a - ss[axis]) * inv[axis];
    const float t_hi = (a + ss[axis]) * inv[axis];
    const uint32_t bits = n->bits, ng = neg[axis];
    const uint32_t below = (uint32_t)(n - nodes) + 1, above = bits >> 4;
    const uint32_t nearc = kd_sel_u32(ng, above, below);
    const uint32_t farc = nearc ^ above ^ below;
    const uint32_t go_near = (uint32_t) !(t_hi < *tn) & ~(bits >> (2 + ng)) & 1u;
    const uint32_t go_far = (uint32_t) !(t_lo > *tf) & ~(bits >> (3 - ng)) & 1u;
    const float far_tn = t_lo > *tn ? t_lo : *tn;
    const float near_tf = t_hi < *tf ? t_hi : *tf;
    kd_todo *e = &stack[*sp];
    e->node = nodes + farc;
    e->tn = far_tn;
    e->tf = *tf;
    *sp += (int)(go_near & go_far);
    const kd_node *next = nodes + kd_sel_u32(go_near, nearc, farc);
    *tn = kd_sel_f32(go_near, *tn, far_tn);
    *tf = kd_sel_f32(go_near, near_tf, *tf);
    return (go_near | go_far) ? next : NULL;
}

#endif /* KD_TRAVERSE_H */
