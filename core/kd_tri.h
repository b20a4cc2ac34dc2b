/*
 * kd_tri.h — the one ray-triangle test every traversal uses: the watertight
 * test of Woop, Benthin and Wald (JCGT 2013).
 *
 * The ray is sheared so that it becomes the +z axis; the triangle's 2D edge
 * functions U, V, W at the origin then decide inclusion with no epsilon, and
 * an edge shared by two triangles gives the same value (opposite sign) in
 * both, so no ray slips between them. A zero edge function is recomputed in
 * double precision (the paper's fallback). Edges count as inside.
 *
 * SIMD versions (bundles, frusta) must perform exactly these float
 * operations in exactly this order, so that every traversal returns
 * bit-identical t, u, v. The build compiles with -ffp-contract=off so that
 * no compiler fuses a multiply-add in one version and not the other.
 */
#ifndef KD_TRI_H
#define KD_TRI_H

#include <float.h>
#include <stdint.h>

/* Per-ray precomputation of the shear. */
typedef struct kd_ray_pre {
    float org[3];
    int kx, ky, kz;
    float sx, sy, sz;
} kd_ray_pre;

static inline void kd_ray_precompute(const float org[3], const float dir[3],
                                     kd_ray_pre *p) {
    float ax = dir[0] < 0 ? -dir[0] : dir[0];
    float ay = dir[1] < 0 ? -dir[1] : dir[1];
    float az = dir[2] < 0 ? -dir[2] : dir[2];
    /* the dominant axis, first one on ties */
    int kz = (ax >= ay) ? (ax >= az ? 0 : 2) : (ay >= az ? 1 : 2);
    int kx = kz + 1 == 3 ? 0 : kz + 1;
    int ky = kx + 1 == 3 ? 0 : kx + 1;
    if (dir[kz] < 0.0f) { /* keep the winding so U, V, W signs agree */
        int tmp = kx;
        kx = ky;
        ky = tmp;
    }
    p->org[0] = org[0];
    p->org[1] = org[1];
    p->org[2] = org[2];
    p->kx = kx;
    p->ky = ky;
    p->kz = kz;
    p->sx = dir[kx] / dir[kz];
    p->sy = dir[ky] / dir[kz];
    p->sz = 1.0f / dir[kz];
}

/* The edge functions in double precision: exact products, one rounding.
 * The fallback of every version of the test when an edge function is 0. */
static inline void kd_tri_edges_exact(float ax, float ay, float bx, float by,
                                      float cx, float cy, float *U, float *V,
                                      float *W) {
    *U = (float)((double)cx * (double)by - (double)cy * (double)bx);
    *V = (float)((double)ax * (double)cy - (double)ay * (double)cx);
    *W = (float)((double)bx * (double)ay - (double)by * (double)ax);
}

/*
 * Underflow of t (docs/ACCURACY.md). With az = sz * Az0 (z over the
 * direction's length), a product U * az of T below FLT_MIN loses up to
 * 2^-150 absolutely; divided by a small det (a ray nearly parallel to the
 * triangle, or tiny sheared coordinates) that moves t far from where the
 * triangle lies along the ray: a triangle the ray passes at t ~ 2^-119
 * (direction 2^116 long, origin coordinates ~2^-100) came out at t = 0,
 * before the walk's termination bound, so no walk could follow brute force.
 * Such a t is recomputed. |T| >= KD_TRI_T_EXACT_BELOW bounds that loss by
 * 2^-48 of T, far below T's own rounding, so only a smaller |T| is looked
 * at (the cheap test every version makes per lane); rays starting on a
 * triangle (T ~ 0 by cancellation, no product small) keep their float t.
 */
#define KD_TRI_T_EXACT_BELOW 0x1p-100f

/* t for |T| < KD_TRI_T_EXACT_BELOW: the float t unless a product of T (or
 * a scaled z) fell below FLT_MIN from non-zero factors; then T from the
 * unscaled z differences in double (exact products of floats, no
 * underflow), times sz, over det, rounded once. A zero result keeps the
 * float t. Every SIMD version calls this per lane under the same test. */
static inline float kd_tri_t_exact(float U, float V, float W, float Az0, float Bz0,
                                   float Cz0, float sz, float det, float t) {
    const float e[3] = {U, V, W}, z[3] = {Az0, Bz0, Cz0};
    int lost = 0;
    for (int i = 0; i < 3; i++) {
        const float zs = sz * z[i], p = e[i] * zs;
        lost |= (zs < FLT_MIN && zs > -FLT_MIN && z[i] != 0.0f) ||
                (p < FLT_MIN && p > -FLT_MIN && e[i] != 0.0f && zs != 0.0f);
    }
    if (!lost)
        return t;
    const double T =
        ((double)U * (double)Az0 + (double)V * (double)Bz0 + (double)W * (double)Cz0) *
        (double)sz;
    const float te = (float)(T / (double)det);
    return te != 0.0f ? te : t;
}

/*
 * Tests triangle tri (9 floats) against the ray; on a hit with
 * tmin <= t <= tmax stores t, u, v and returns 1.
 */
static inline int kd_tri_intersect(const kd_ray_pre *p, const float *tri,
                                   float tmin, float tmax, float *t_out,
                                   float *u_out, float *v_out) {
    const int kx = p->kx, ky = p->ky, kz = p->kz;
    /* vertices relative to the origin */
    const float Ax = tri[0 + kx] - p->org[kx], Ay = tri[0 + ky] - p->org[ky],
                Az0 = tri[0 + kz] - p->org[kz];
    const float Bx = tri[3 + kx] - p->org[kx], By = tri[3 + ky] - p->org[ky],
                Bz0 = tri[3 + kz] - p->org[kz];
    const float Cx = tri[6 + kx] - p->org[kx], Cy = tri[6 + ky] - p->org[ky],
                Cz0 = tri[6 + kz] - p->org[kz];
    /* shear into ray space */
    const float ax = Ax - p->sx * Az0, ay = Ay - p->sy * Az0;
    const float bx = Bx - p->sx * Bz0, by = By - p->sy * Bz0;
    const float cx = Cx - p->sx * Cz0, cy = Cy - p->sy * Cz0;
    /* scaled barycentrics: U weighs p0, V p1, W p2 */
    float U = cx * by - cy * bx;
    float V = ax * cy - ay * cx;
    float W = bx * ay - by * ax;
    if (U == 0.0f || V == 0.0f || W == 0.0f)
        kd_tri_edges_exact(ax, ay, bx, by, cx, cy, &U, &V, &W);
    if ((U < 0.0f || V < 0.0f || W < 0.0f) && (U > 0.0f || V > 0.0f || W > 0.0f))
        return 0;
    const float det = U + V + W;
    if (det == 0.0f)
        return 0;
    const float az = p->sz * Az0, bz = p->sz * Bz0, cz = p->sz * Cz0;
    const float T = U * az + V * bz + W * cz;
    float t = T / det;
    if (T < KD_TRI_T_EXACT_BELOW && T > -KD_TRI_T_EXACT_BELOW)
        t = kd_tri_t_exact(U, V, W, Az0, Bz0, Cz0, p->sz, det, t);
    if (!(t >= tmin && t <= tmax)) /* also rejects NaN */
        return 0;
    *t_out = t;
    *u_out = V / det;
    *v_out = W / det;
    return 1;
}

#endif /* KD_TRI_H */
