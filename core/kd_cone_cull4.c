/*
 * kd_cone_cull4.c — the cone culls and the cheap edge test four triangles
 * at a time (AVX2 doubles):
 *  - the group list's per-point cull (kd_cone_pre_may_block4): each point
 *    of a group culls the group's whole list (kd_cone_cells.c,
 *    judge_group); the list is laid out by field once per group
 *    (kd_tri_soa_fill);
 *  - the walks' bounding-sphere test (kd_cone_tri_sphere4), the first test
 *    of kd_cone_tri_may_block, for a leaf's triangles (kd_cone_collect,
 *    walk_with_proofs);
 *  - the cheap edge test of kd_cone_proof.c (kd_tri_edges_miss4) for the
 *    survivors of either.
 * In the default picture those scalar loops, with a branch per test, were
 * a quarter of the instructions (26%). Each lane performs exactly the scalar
 * function's operations in its order (the build has -ffp-contract=off; the
 * vector min and max and the ordered compares give what the scalar
 * a < b ? a : b forms and comparisons give, NaN included), so every
 * triangle gets the scalar answer: tests/test_cone_cull4.c checks that
 * decision by decision.
 */
#include <immintrin.h>

#include "kd_cone.h"
#include "simd.h"

/* Field rows of kd_tri_soa.f (KD_SOA_FIELDS of them). */
enum {
    F_N = 0,     /* 3: the plane's unit normal */
    F_NOFF = 3,  /* its offset */
    F_C = 4,     /* 3: the bounding sphere's centre */
    F_R = 7,     /* its radius */
    F_E = 8,     /* 9: the prism sides' unit normals, side by side */
    F_EOFF = 17, /* 3: their offsets */
    F_FLAT = 20, /* 1.0 if plane and prism are usable */
    F_USED = 21, /* 1.0 for a real triangle, 0.0 for padding */
};

void kd_tri_soa_fill(kd_tri_soa *s, const kd_tri_pre *pre, size_t n) {
    const size_t cap = s->cap, padded = (n + 3) & ~(size_t)3;
    double *f = s->f;
    for (size_t j = 0; j < padded; j++) {
        const int real = j < n;
        const kd_tri_pre *p = &pre[real ? j : 0]; /* padding: any finite copy */
        for (int k = 0; k < 3; k++) {
            f[(F_N + k) * cap + j] = p->n[k];
            f[(F_C + k) * cap + j] = p->c[k];
            f[(F_EOFF + k) * cap + j] = p->e_off[k];
            for (int i = 0; i < 3; i++)
                f[(F_E + 3 * k + i) * cap + j] = p->e[k][i];
        }
        f[F_NOFF * cap + j] = p->n_off;
        f[F_R * cap + j] = p->r;
        f[F_FLAT * cap + j] = p->flat ? 1.0 : 0.0;
        f[F_USED * cap + j] = real ? 1.0 : 0.0;
        s->prim[j] = real ? p->prim : UINT32_MAX;
    }
    s->n = n;
}

#define LD(row) _mm256_loadu_pd(s->f + (size_t)(row) * s->cap + j)
#define SET(x) _mm256_set1_pd(x)
#define ADD _mm256_add_pd
#define SUB _mm256_sub_pd
#define MUL _mm256_mul_pd
#define GT(a, b) _mm256_cmp_pd(a, b, _CMP_GT_OQ)
#define LT(a, b) _mm256_cmp_pd(a, b, _CMP_LT_OQ)
#define LE(a, b) _mm256_cmp_pd(a, b, _CMP_LE_OQ)
#define OR _mm256_or_pd
#define AND _mm256_and_pd

/* pre_range of kd_cone_trav.c for four planes (m, off): lo and hi. */
KD_AVX2 static void range4(const kd_cone *cc, __m256d m0, __m256d m1, __m256d m2,
                           __m256d off, __m256d *lo, __m256d *hi) {
    const __m256d d_apex = SUB(
        ADD(ADD(MUL(m0, SET(cc->dapex[0])), MUL(m1, SET(cc->dapex[1]))),
            MUL(m2, SET(cc->dapex[2]))),
        off);
    const __m256d mv = ADD(ADD(MUL(m0, SET(cc->axis[0])), MUL(m1, SET(cc->axis[1]))),
                           MUL(m2, SET(cc->axis[2])));
    const __m256d tf = SET((double)cc->t_far);
    const __m256d d_disc = ADD(d_apex, MUL(tf, mv));
    const __m256d spread =
        MUL(MUL(tf, SET(cc->tan_p)),
            _mm256_sqrt_pd(_mm256_max_pd(SET(0.0), SUB(SET(1.0), MUL(mv, mv)))));
    *lo = _mm256_min_pd(d_apex, SUB(d_disc, spread));
    *hi = _mm256_max_pd(d_apex, ADD(d_disc, spread));
}

KD_AVX2 int kd_cone_pre_may_block4(const kd_cone *cc, const kd_tri_soa *s, size_t j) {
    const __m256d c0 = LD(F_C), c1 = LD(F_C + 1), c2 = LD(F_C + 2), r = LD(F_R);
    const __m256d w0 = SUB(c0, SET(cc->dapex[0])), w1 = SUB(c1, SET(cc->dapex[1])),
                  w2 = SUB(c2, SET(cc->dapex[2]));
    const __m256d wlen = _mm256_sqrt_pd(ADD(ADD(MUL(w0, w0), MUL(w1, w1)), MUL(w2, w2)));
    const __m256d sign = SET(-0.0);
    /* own: 1e-9 * (|a0| + |a1| + |a2| + |c0| + |c1| + |c2| + r), left to right */
    const double apex_abs =
        (fabs(cc->dapex[0]) + fabs(cc->dapex[1])) + fabs(cc->dapex[2]);
    const __m256d own = MUL(
        SET(1e-9),
        ADD(ADD(ADD(ADD(SET(apex_abs), _mm256_andnot_pd(sign, c0)), _mm256_andnot_pd(sign, c1)),
                _mm256_andnot_pd(sign, c2)),
            r));
    const __m256d band = SET((double)cc->band), tf = SET((double)cc->t_far);
    const __m256d rel = SET(KD_CULL_REL_SLACK);
    const __m256d slack = ADD(ADD(band, MUL(rel, ADD(ADD(wlen, r), tf))), own);
    const __m256d flat = GT(LD(F_FLAT), SET(0.0));
    __m256d lo, hi;
    range4(cc, LD(F_N), LD(F_N + 1), LD(F_N + 2), LD(F_NOFF), &lo, &hi);
    __m256d drop = AND(flat, OR(GT(lo, slack), LT(hi, SUB(SET(0.0), slack))));
    const __m256d a0 = SET(cc->axis[0]), a1 = SET(cc->axis[1]), a2 = SET(cc->axis[2]);
    const __m256d proj = ADD(ADD(MUL(w0, a0), MUL(w1, a1)), MUL(w2, a2));
    const __m256d cx = SUB(MUL(w1, a2), MUL(w2, a1));
    const __m256d cy = SUB(MUL(w2, a0), MUL(w0, a2));
    const __m256d cz = SUB(MUL(w0, a1), MUL(w1, a0));
    const __m256d perp = _mm256_sqrt_pd(ADD(ADD(MUL(cx, cx), MUL(cy, cy)), MUL(cz, cz)));
    const __m256d rad = ADD(ADD(ADD(r, band), MUL(rel, ADD(wlen, r))), own);
    drop = OR(drop, OR(GT(SUB(proj, rad), tf), LT(ADD(proj, rad), SET((double)cc->t_near))));
    const __m256d cp = SET(cc->cos_p), sp = SET(cc->sin_p);
    const __m256d apex_near = LE(ADD(MUL(proj, cp), MUL(perp, sp)), SET(0.0));
    drop = OR(drop, _mm256_blendv_pd(GT(SUB(MUL(perp, cp), MUL(proj, sp)), rad),
                                     GT(wlen, rad), apex_near));
    for (int i = 0; i < 3; i++) {
        range4(cc, LD(F_E + 3 * i), LD(F_E + 3 * i + 1), LD(F_E + 3 * i + 2),
               LD(F_EOFF + i), &lo, &hi);
        drop = OR(drop, AND(flat, GT(lo, slack)));
    }
    const __m256d keep = AND(_mm256_andnot_pd(drop, _mm256_castsi256_pd(_mm256_set1_epi64x(-1))),
                             GT(LD(F_USED), SET(0.0)));
    return _mm256_movemask_pd(keep);
}

/* ---- the walks' sphere test ------------------------------------------------------- */

/* Coordinate q (0..8) of the four triangles, widened exactly; lanes past n
 * repeat triangle 0. */
KD_AVX2 static __m256d coord4(const float *const *t, int n, int q) {
    return _mm256_set_pd((double)t[n > 3 ? 3 : 0][q], (double)t[n > 2 ? 2 : 0][q],
                         (double)t[n > 1 ? 1 : 0][q], (double)t[0][q]);
}

KD_AVX2 int kd_cone_tri_sphere4(const kd_cone *cc, const float *const *tris, int n) {
    __m256d v[9], m[3], w[3];
    for (int q = 0; q < 9; q++)
        v[q] = coord4(tris, n, q);
    for (int k = 0; k < 3; k++) {
        /* dmin(t0, dmin(t3, t6)): min_pd(a, b) is a < b ? a : b */
        const __m256d lo = _mm256_min_pd(v[k], _mm256_min_pd(v[3 + k], v[6 + k]));
        const __m256d hi = _mm256_max_pd(v[k], _mm256_max_pd(v[3 + k], v[6 + k]));
        m[k] = MUL(SET(0.5), ADD(lo, hi));
        w[k] = SUB(m[k], SET(cc->dapex[k]));
    }
    __m256d r2 = SET(0.0);
    for (int j = 0; j < 3; j++) {
        const __m256d d0 = SUB(v[3 * j], m[0]), d1 = SUB(v[3 * j + 1], m[1]),
                      d2 = SUB(v[3 * j + 2], m[2]);
        r2 = _mm256_max_pd(r2, ADD(ADD(MUL(d0, d0), MUL(d1, d1)), MUL(d2, d2)));
    }
    const __m256d a0 = SET(cc->axis[0]), a1 = SET(cc->axis[1]), a2 = SET(cc->axis[2]);
    const __m256d proj = ADD(ADD(MUL(w[0], a0), MUL(w[1], a1)), MUL(w[2], a2));
    const __m256d cx = SUB(MUL(w[1], a2), MUL(w[2], a1));
    const __m256d cy = SUB(MUL(w[2], a0), MUL(w[0], a2));
    const __m256d cz = SUB(MUL(w[0], a1), MUL(w[1], a0));
    const __m256d perp = _mm256_sqrt_pd(ADD(ADD(MUL(cx, cx), MUL(cy, cy)), MUL(cz, cz)));
    const __m256d wlen =
        _mm256_sqrt_pd(ADD(ADD(MUL(w[0], w[0]), MUL(w[1], w[1])), MUL(w[2], w[2])));
    const __m256d r = _mm256_sqrt_pd(r2);
    const __m256d rad = ADD(ADD(r, SET((double)cc->band)),
                            MUL(SET(KD_CULL_REL_SLACK), ADD(wlen, r)));
    __m256d drop = OR(GT(SUB(proj, rad), SET((double)cc->t_far)),
                      LT(ADD(proj, rad), SET((double)cc->t_near)));
    const __m256d cp = SET(cc->cos_p), sp = SET(cc->sin_p);
    const __m256d apex_near =
        LE(ADD(MUL(proj, cp), MUL(perp, sp)), SET(0.0));
    /* !(x <= rad): true for NaN too, as the scalar test's */
    drop = OR(drop, _mm256_blendv_pd(
                        _mm256_cmp_pd(SUB(MUL(perp, cp), MUL(proj, sp)), rad, _CMP_NLE_UQ),
                        _mm256_cmp_pd(wlen, rad, _CMP_NLE_UQ), apex_near));
    return ~_mm256_movemask_pd(drop) & ((1 << n) - 1);
}

/* ---- the cheap edge test ------------------------------------------------------------- */

/* Coordinate q of the four triangles less apex[q % 3], subtracted in float
 * as the triangle test does, then widened. */
KD_AVX2 static __m256d rel4(const float *const *t, int n, const float *apex, int q) {
    const __m128 v = _mm_set_ps(t[n > 3 ? 3 : 0][q], t[n > 2 ? 2 : 0][q],
                                t[n > 1 ? 1 : 0][q], t[0][q]);
    return _mm256_cvtps_pd(_mm_sub_ps(v, _mm_set1_ps(apex[q % 3])));
}

/* side_robust of kd_cone_proof.c for four planes. */
KD_AVX2 static __m256d robust4(const kd_dir_cone *c, __m256d x, __m256d sn, __m256d cs) {
    const __m256d cb = SET(c->cos_b), sb = SET(c->sin_b);
    const __m256d cos_bm = SUB(MUL(cb, cs), MUL(sb, sn));
    return AND(GT(cos_bm, SET(0.0)),
               _mm256_cmp_pd(x, ADD(MUL(sb, cs), MUL(cb, sn)), _CMP_GE_OQ));
}

KD_AVX2 int kd_tri_edges_miss4(const float *const *tris, int n, const float apex[3],
                               const kd_dir_cone *c) {
    const double ur = 0x1p-24; /* kd_cone_proof.c's UR and OWN_REL */
    const __m256d sign = SET(-0.0);
    __m256d A[3][3], W[3];
    for (int i = 0; i < 3; i++) {
        for (int k = 0; k < 3; k++)
            A[i][k] = rel4(tris, n, apex, 3 * i + k);
        W[i] = ADD(ADD(_mm256_andnot_pd(sign, A[i][0]), _mm256_andnot_pd(sign, A[i][1])),
                   _mm256_andnot_pd(sign, A[i][2]));
    }
    __m256d pos = SET(0.0), neg = SET(0.0);
    for (int i = 0; i < 3; i++) {
        const int j = (i + 1) % 3, k = (i + 2) % 3;
        const __m256d n0 = SUB(MUL(A[j][1], A[k][2]), MUL(A[j][2], A[k][1]));
        const __m256d n1 = SUB(MUL(A[j][2], A[k][0]), MUL(A[j][0], A[k][2]));
        const __m256d n2 = SUB(MUL(A[j][0], A[k][1]), MUL(A[j][1], A[k][0]));
        const __m256d l = _mm256_sqrt_pd(ADD(ADD(MUL(n0, n0), MUL(n1, n1)), MUL(n2, n2)));
        const __m256d ok = GT(l, SET(0.0));
        /* margin(12.1 UR W_j W_k / l + 4 UR): s + OWN_REL, its sine and cosine */
        const __m256d s = ADD(
            ADD(_mm256_div_pd(MUL(MUL(SET(12.1 * ur), W[j]), W[k]), l), SET(4.0 * ur)),
            SET(1e-12));
        const __m256d below = LT(s, SET(1.0));
        const __m256d sn = _mm256_blendv_pd(SET(1.0), s, below);
        const __m256d cs = _mm256_blendv_pd(
            SET(0.0), _mm256_sqrt_pd(MUL(SUB(SET(1.0), s), ADD(SET(1.0), s))), below);
        const __m256d x = _mm256_div_pd(
            ADD(ADD(MUL(n0, SET(c->axis[0])), MUL(n1, SET(c->axis[1]))),
                MUL(n2, SET(c->axis[2]))),
            l);
        pos = OR(pos, AND(ok, robust4(c, x, sn, cs)));
        neg = OR(neg, AND(ok, robust4(c, _mm256_xor_pd(x, sign), sn, cs)));
    }
    return _mm256_movemask_pd(AND(pos, neg)) & ((1 << n) - 1);
}
