/*
 * kd_traverse.h — small helpers every traversal shares: ray validation,
 * clipping a ray to the scene's padded root box, the interior-node step
 * convention, and the degenerate-triangle predicate the build uses (so that
 * brute-force oracles in tests can skip exactly the same triangles).
 *
 * Split-plane convention (single rays; bundles, cones and frusta mirror it):
 *   t_split = (split - org[axis]) * inv_dir[axis], inv_dir = 1.0f / dir,
 *   t_lo = t_split - dt[axis], t_hi = t_split + dt[axis] (kd_ray_slack_dt).
 * The child the ray is in for t < t_split is the "near" child: below when
 * inv_dir[axis] > 0 (including dir = +0.0), above when it is negative
 * (including dir = -0.0). The near child is visited over
 * [tnear, min(tfar, t_hi)], the far child over [max(tnear, t_lo), tfar],
 * each only when that interval is not empty (a single point counts). This
 * holds for every sign of t_split, so the origin may lie on either side or
 * on the plane. A NaN (origin on the plane and direction component 0: the
 * ray lies in the plane) visits both children with the full interval.
 *
 * Why the slack dt: kd_tri_intersect is watertight for the triangle as seen
 * after rounding the translation and shear, which can move it a few ulps of
 * |vertex - origin|. A ray aimed at a vertex lying in a split plane may
 * pass that vertex a hair on the wrong side and still "hit" the triangle, so
 * every leaf within `slack` (a small multiple of the scene's and origin's
 * magnitude) of the ray must be visited for answers to equal brute force.
 * Along an axis where the direction is 0 the test is exact in that
 * coordinate (no shear term), so dt is 0 there.
 */
#ifndef KD_TRAVERSE_H
#define KD_TRAVERSE_H

#include <math.h>

#include "kd_internal.h"

/* Positional slack of every traversal, relative to the largest coordinate
 * magnitude of the scene or the ray origin (2^-16: ~128 ulps). */
#define KD_SLACK_REL 0x1p-16f

/* Per-axis slack in t units for a ray (see the comment above). */
static inline void kd_ray_slack_dt(const struct kdr_scene *s, const float org[3],
                                   const float dir[3], const float inv_dir[3],
                                   float dt[3]) {
    /* plain compares: fmaxf is a library call without -ffast-math */
    float m = 0.0f;
    for (int k = 0; k < 3; k++) {
        const float a = -s->root.min[k], b = s->root.max[k];
        const float o = org[k] < 0.0f ? -org[k] : org[k];
        m = a > m ? a : m;
        m = b > m ? b : m;
        m = o > m ? o : m;
    }
    const float slack = m * KD_SLACK_REL;
    for (int k = 0; k < 3; k++) {
        const float ai = inv_dir[k] < 0.0f ? -inv_dir[k] : inv_dir[k];
        dt[k] = dir[k] == 0.0f ? 0.0f : slack * ai;
    }
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
 * Clips [tmin, tmax] to the scene's padded root box, widened by dt. An axis with a zero
 * direction component constrains nothing when the origin is inside the slab
 * and rejects the ray otherwise (no 0 * inf). Returns 0 when the ray misses.
 */
static inline int kd_clip_root_dt(const struct kdr_scene *s, const float org[3],
                                  const float dir[3], const float inv_dir[3],
                                  const float dt[3], float tmin, float tmax,
                                  float *tnear, float *tfar) {
    float tn = tmin, tf = tmax;
    for (int k = 0; k < 3; k++) {
        if (dir[k] == 0.0f) {
            if (org[k] < s->root.min[k] || org[k] > s->root.max[k])
                return 0;
            continue;
        }
        float t0 = (s->root.min[k] - org[k]) * inv_dir[k];
        float t1 = (s->root.max[k] - org[k]) * inv_dir[k];
        if (t0 > t1) {
            float tmp = t0;
            t0 = t1;
            t1 = tmp;
        }
        t0 -= dt[k];
        t1 += dt[k];
        tn = t0 > tn ? t0 : tn;
        tf = t1 < tf ? t1 : tf;
    }
    *tnear = tn;
    *tfar = tf;
    return tn <= tf;
}

/* The same, computing the ray's slack itself. */
static inline int kd_clip_root(const struct kdr_scene *s, const float org[3],
                               const float dir[3], const float inv_dir[3],
                               float tmin, float tmax, float *tnear,
                               float *tfar) {
    float dt[3];
    kd_ray_slack_dt(s, org, dir, inv_dir, dt);
    return kd_clip_root_dt(s, org, dir, inv_dir, dt, tmin, tmax, tnear, tfar);
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

#endif /* KD_TRAVERSE_H */
