/*
 * kd_cone_proof.c — proofs about one triangle and every sample segment of
 * a cone: "none of them hits it" (KD_TRI_MISSES) or "every one of them
 * hits it" (KD_TRI_COVERS), made against the float arithmetic of the one
 * triangle test (kd_tri.h), not against exact geometry. A sub-cone whose
 * candidates all miss is lit, one that a candidate covers is in umbra, and
 * both decide their samples exactly as KDR_SHADOW_RAYS would.
 *
 * Setting. Every sample ray of the cone starts at the apex o (the float
 * point moved along its normal; the proofs need that fixed origin, so they
 * are made only when the query has normals), has a float direction d
 * inside the cone (axis a, half-angle b, which already covers the rounding
 * of d) and ends at tmax >= tmax_lo. The test forms A_i = fl(P_i - o)
 * exactly as we do here, so the A_i are known floats; only the shear
 * (kx, ky, kz = the dominant axis of d, sx = d_kx/d_kz, sy, sz = 1/d_kz),
 * the edge functions U, V, W and T = U az + V bz + W cz carry rounding
 * (u = 2^-24 per operation, no FMA: -ffp-contract=off). The ray is accepted
 * when U, V, W share a sign s, det = U + V + W != 0 and t = T/det lies in
 * [0, tmax].
 *
 * Edge functions. The exact edge function of edge (j, k) for the exact
 * shear of the A's is U* = sz N_i . d'' with N_i = A_j x A_k (i the
 * opposite vertex) and d'' = (sx, sy, 1)/sz, a direction within ~4u of d.
 * The computed one differs by at most
 *     err_i = 4.02u w_j w_k + 2.01 (del_j w_k + del_k w_j),
 * w = max(|A_kx|, |A_ky|) + |A_kz| bounding the sheared coordinates
 * (|sx|, |sy| <= 1 since kz is dominant) and del = u (max(|A_kx|, |A_ky|) +
 * 2 |A_kz|) bounding their rounding; we take the largest over the three
 * choices of kz. As |sz| >= 1, the computed U has the sign of N_i . d
 * whenever |N_i . d| >= err_i + 4u |N_i|: a cone whose axis is at least
 * b + asin(err_i / |N_i| + 4u) away from the plane (o, edge) gives every
 * ray that sign ("robust" on that edge).
 *
 * The sign of t. With every U of sign s, s T = s det(K) + rounding, where
 * det(K) = sum U* z is the determinant of the computed sheared vertices K
 * and |T - sum U z| <= 3.01u sum |U z|. K is the exact shear of A + eps,
 * |eps_kx| <= u (|A_kx| + 3 |A_kz|), |eps_kz| <= u |A_kz|, so det(K) =
 * sz det(A + eps) and |det(A + eps) - det(A)| <= E1 = sum_i eps_i . |N_i|.
 * Hence when
 *     |det(A)| > 1.01 E1 + 10.3u sum_i w_j w_k |A_i,kz|       ("det_ok")
 * (largest over kz, plus a margin for our own double rounding), the sign
 * of the computed t equals the sign of the exact t* = det(A) / (n . d'')
 * (n = sum N_i, the plane's normal) for every ray whose edge functions
 * share a sign s that equals the sign of n . d'' — which holds when all
 * three edges are robust, or when |n . d| > sum err_i + 4u |n| (the ray is
 * not grazing the plane).
 *
 * Verdicts, for a cone:
 *  - robust on two edges with opposite signs: every ray has mixed signs,
 *    MISSES;
 *  - det_ok and the plane faces the cone away: every ray leaves the side of
 *    the plane the apex is on (n_o . d > 0, n_o from the plane to the apex,
 *    with the grazing margin), so t* < 0 and the computed t < 0: MISSES
 *    (this is what proves a point's own surface harmless);
 *  - det_ok and robust on all three edges with the sign of det(A): every
 *    ray passes through the triangle behind the apex (t* < 0): MISSES;
 *    with the other sign it passes through in front (t* > 0, so t > 0):
 *    COVERS if moreover t <= tmax for every ray. With weights of one sign,
 *    t = T/det is a convex combination of the z_i = fl(sz A_i,kz) up to
 *    rounding, so t <= (max_i (A_i,kz / d_kz) + 4u max_i |A_i,kz| / |d_kz|)
 *    (1 + 8u), bounded over the cone for every axis that can be dominant
 *    (|d_kz| >= 1/sqrt(3)) and compared with tmax_lo;
 *  - otherwise UNKNOWN (the samples are traced).
 * tests/test_cone_proofs.c (test_proofs) fires millions of float rays at
 * adversarial configurations and checks every verdict ray by ray.
 */
#include <math.h>

#include "kd_cone.h"
#include "kd_internal.h"

/* Plain-comparison min/max: fmin/fmax are libm calls without -ffast-math
 * (their NaN rules), and no operand here is NaN. */
static inline double dmax(double a, double b) { return a > b ? a : b; }
static inline double dmin(double a, double b) { return a < b ? a : b; }

#define UR 0x1p-24 /* unit roundoff of float */
/* Our own double arithmetic errs by ~1e-16 relative; margins this much
 * wider cover it many times over. */
#define OWN_REL 1e-12
#define INV_SQRT3 0.57735026918962576

static double dot3(const double *a, const double *b) {
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

static void cross3(const double *a, const double *b, double *c) {
    c[0] = a[1] * b[2] - a[2] * b[1];
    c[1] = a[2] * b[0] - a[0] * b[2];
    c[2] = a[0] * b[1] - a[1] * b[0];
}

static double len3(const double *a) { return sqrt(dot3(a, a)); }

/* sin and cos of a margin angle whose sine is s (s >= 1: unusable). */
static void margin(double s, double *sn, double *cs) {
    s += OWN_REL;
    *sn = s < 1.0 ? s : 1.0;
    *cs = s < 1.0 ? sqrt((1.0 - s) * (1.0 + s)) : 0.0;
}

/* The error bounds of the test for one choice of the dominant axis kz:
 * err[i] for the edge opposite vertex i, and det_ok's right-hand side. */
static double bounds_for_axis(const double A[3][3], const double N[3][3], int kz,
                              double err[3]) {
    const int kx = (kz + 1) % 3, ky = (kz + 2) % 3;
    double w[3], del[3], lat[3], az[3];
    for (int i = 0; i < 3; i++) {
        lat[i] = dmax(fabs(A[i][kx]), fabs(A[i][ky]));
        az[i] = fabs(A[i][kz]);
        w[i] = lat[i] + az[i];
        del[i] = UR * 1.001 * (lat[i] + 2.0 * az[i]);
    }
    double e1 = 0.0, tterm = 0.0;
    for (int i = 0; i < 3; i++) {
        const int j = (i + 1) % 3, k = (i + 2) % 3;
        err[i] = 4.02 * UR * w[j] * w[k] + 2.01 * (del[j] * w[k] + del[k] * w[j]);
        e1 += UR * (fabs(A[i][kx]) + 3.0 * az[i]) * fabs(N[i][kx]) +
              UR * (fabs(A[i][ky]) + 3.0 * az[i]) * fabs(N[i][ky]) +
              UR * az[i] * fabs(N[i][kz]);
        tterm += w[j] * w[k] * az[i];
    }
    return 1.01 * e1 + 10.3 * UR * tterm;
}

void kd_tri_view_init(kd_tri_view *v, const float *tri, uint32_t prim,
                      const float apex[3]) {
    double A[3][3], N[3][3], n[3], size = 1.0;
    v->prim = prim;
    for (int i = 0; i < 3; i++) {
        for (int k = 0; k < 3; k++) {
            /* the float subtraction the test makes, then exact in double */
            const float a = tri[3 * i + k] - apex[k];
            A[i][k] = a;
        }
        size *= fabs(A[i][0]) + fabs(A[i][1]) + fabs(A[i][2]);
    }
    for (int k = 0; k < 3; k++) {
        v->hi[k] = dmax(A[0][k], dmax(A[1][k], A[2][k]));
        v->lo[k] = dmin(A[0][k], dmin(A[1][k], A[2][k]));
    }
    for (int i = 0; i < 3; i++)
        cross3(A[(i + 1) % 3], A[(i + 2) % 3], N[i]);
    for (int k = 0; k < 3; k++)
        n[k] = N[0][k] + N[1][k] + N[2][k]; /* (A1 - A0) x (A2 - A0) */
    const double det = dot3(A[0], N[0]);
    double err[3] = {0, 0, 0}, rhs = 0.0;
    for (int kz = 0; kz < 3; kz++) {
        double e[3];
        rhs = dmax(rhs, bounds_for_axis(A, N, kz, e));
        for (int i = 0; i < 3; i++)
            err[i] = dmax(err[i], e[i]);
    }
    v->det_sign = det > 0.0 ? 1 : det < 0.0 ? -1 : 0;
    v->det_ok = fabs(det) > rhs + 6.0 * OWN_REL * size;
    double sum_err = 0.0;
    for (int i = 0; i < 3; i++) {
        const double l = len3(N[i]), inv = l > 0.0 ? 1.0 / l : 0.0;
        sum_err += err[i];
        for (int k = 0; k < 3; k++)
            v->edge[i][k] = N[i][k] * inv;
        margin(l > 0.0 ? err[i] * inv + 4.0 * UR : 1.0, &v->edge_sin[i], &v->edge_cos[i]);
    }
    const double nl = len3(n), ninv = nl > 0.0 ? -(double)v->det_sign / nl : 0.0;
    for (int k = 0; k < 3; k++) /* from the plane toward the apex */
        v->plane[k] = n[k] * ninv;
    margin(nl > 0.0 && v->det_sign ? sum_err / nl + 4.0 * UR : 1.0, &v->plane_sin,
           &v->plane_cos);
}

void kd_dir_cone_set(kd_dir_cone *c, const double axis[3], double cos_b, double sin_b,
                     double tmax_lo) {
    for (int k = 0; k < 3; k++) {
        /* d_k over the cone: cos(theta_k -/+ b), theta_k the angle between
         * the axis and e_k, clamped where the cone contains +-e_k */
        const double a = axis[k], s = sqrt(dmax(0.0, 1.0 - a * a));
        c->axis[k] = a;
        c->dmax[k] = a <= cos_b ? a * cos_b + s * sin_b + OWN_REL : 1.0;
        c->dmin[k] = a >= -cos_b ? a * cos_b - s * sin_b - OWN_REL : -1.0;
    }
    c->cos_b = cos_b;
    c->sin_b = sin_b;
    c->tmax_lo = tmax_lo;
}

/* 1 if every direction of the cone is at least the margin (sin m, cos m)
 * on the positive side of the plane through the apex with unit normal p
 * (p . d >= sin m for every d within b of the axis). */
static int side_robust(const kd_dir_cone *c, double x, double sin_m, double cos_m) {
    const double cos_bm = c->cos_b * cos_m - c->sin_b * sin_m; /* cos(b + m) */
    return cos_bm > 0.0 && x >= c->sin_b * cos_m + c->cos_b * sin_m;
}

/* The first verdict alone, with a cruder bound: w and del of every axis
 * are at most W = |A|_1 and 2.002u W, so err_i <= (4.02 + 8.05)u W_j W_k
 * whatever kz is; a larger margin only decides less. Costs a fraction of
 * kd_tri_view_init, and most triangles a cone's cull keeps beside it end
 * here (measured on the render: 3 in 4 of the views made were MISSES by
 * edges). */
int kd_tri_edges_miss(const float *tri, const float apex[3], const kd_dir_cone *c) {
    double A[3][3], W[3];
    for (int i = 0; i < 3; i++) {
        for (int k = 0; k < 3; k++)
            A[i][k] = (float)(tri[3 * i + k] - apex[k]); /* as the test does */
        W[i] = fabs(A[i][0]) + fabs(A[i][1]) + fabs(A[i][2]);
    }
    int pos = 0, neg = 0;
    for (int i = 0; i < 3; i++) {
        const int j = (i + 1) % 3, k = (i + 2) % 3;
        double N[3];
        cross3(A[j], A[k], N);
        const double l = len3(N);
        if (!(l > 0.0))
            continue;
        double sn, cs;
        margin(12.1 * UR * W[j] * W[k] / l + 4.0 * UR, &sn, &cs);
        const double x = dot3(N, c->axis) / l;
        pos += side_robust(c, x, sn, cs);
        neg += side_robust(c, -x, sn, cs);
    }
    return pos && neg;
}

/* t <= tmax for every ray of the cone, given weights of one sign. */
static int within_tmax(const kd_tri_view *v, const kd_dir_cone *c) {
    for (int k = 0; k < 3; k++) {
        const double top = dmax(fabs(c->dmin[k]), fabs(c->dmax[k]));
        if (top < INV_SQRT3 * (1.0 - 1e-6))
            continue; /* never the dominant axis of a ray in this cone */
        const double amax = dmax(fabs(v->lo[k]), fabs(v->hi[k]));
        double far, dz;
        if (c->dmin[k] > 0.0) { /* d_k > 0 over the cone */
            far = dmax(v->hi[k], 0.0);
            dz = dmax(c->dmin[k], INV_SQRT3 * (1.0 - 1e-6));
        } else if (c->dmax[k] < 0.0) {
            far = dmax(-v->lo[k], 0.0);
            dz = dmax(-c->dmax[k], INV_SQRT3 * (1.0 - 1e-6));
        } else { /* both signs: a very wide cone */
            far = amax;
            dz = INV_SQRT3 * (1.0 - 1e-6);
        }
        if ((far + 4.0 * UR * amax) / dz * (1.0 + 8.0 * UR) > c->tmax_lo)
            return 0;
    }
    return 1;
}

kd_verdict kd_tri_view_classify(const kd_tri_view *v, const kd_dir_cone *c) {
    int pos = 0, neg = 0;
    for (int i = 0; i < 3; i++) {
        const double x = dot3(v->edge[i], c->axis);
        pos += side_robust(c, x, v->edge_sin[i], v->edge_cos[i]);
        neg += side_robust(c, -x, v->edge_sin[i], v->edge_cos[i]);
    }
    if (pos && neg)
        return KD_TRI_MISSES;
    if (!v->det_ok)
        return KD_TRI_UNKNOWN;
    if (side_robust(c, dot3(v->plane, c->axis), v->plane_sin, v->plane_cos))
        return KD_TRI_MISSES;
    /* all three robust: N_i . d has the sign of det(A) for every edge when
     * the rays pass through the triangle in front of the apex */
    const int front = v->det_sign > 0 ? pos : neg, back = v->det_sign > 0 ? neg : pos;
    if (back == 3)
        return KD_TRI_MISSES;
    if (front == 3 && within_tmax(v, c))
        return KD_TRI_COVERS;
    return KD_TRI_UNKNOWN;
}
