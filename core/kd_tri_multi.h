/*
 * kd_tri_multi.h — the watertight test of core/kd_tri.h for ONE ray against
 * four triangles at once (SSE2, the x86-64 baseline: no CPU dispatch), for
 * single-ray leaves holding many triangles.
 *
 * Each lane performs exactly the float operations of kd_tri_intersect in
 * the same order (the build has -ffp-contract=off and the lane layer has no
 * FMA), so a lane's t, V, W and det are bit-identical to the scalar test's;
 * the rare edge function that is exactly 0 is recomputed in double per lane,
 * as the scalar test does. The triangles are read from their 9-float rows
 * and transposed in registers, so the scene needs no second copy.
 *
 * The 8-wide form (kd_tri8_*) needs AVX2: call it only from KD_AVX2
 * functions after the CPU said yes (see core/simd.h).
 */
#ifndef KD_TRI_MULTI_H
#define KD_TRI_MULTI_H

#include "kd_tri.h"
#include "simd.h"

/* A ray's shear broadcast to four lanes (built once per ray). */
typedef struct kd_ray_pre4 {
    f4 ox, oy, oz, sx, sy, sz;
    int kx, ky, kz;
} kd_ray_pre4;

static inline void kd_ray_pre4_init(const kd_ray_pre *p, kd_ray_pre4 *q) {
    q->ox = f4_set1(p->org[p->kx]);
    q->oy = f4_set1(p->org[p->ky]);
    q->oz = f4_set1(p->org[p->kz]);
    q->sx = f4_set1(p->sx);
    q->sy = f4_set1(p->sy);
    q->sz = f4_set1(p->sz);
    q->kx = p->kx;
    q->ky = p->ky;
    q->kz = p->kz;
}

/* One vertex (x, y, z in rows r[0..3] at float offset off) of four
 * triangles, transposed into x, y and z vectors. */
static inline void kd_tri4_vertex(const float *const r[4], int off, int last,
                                  f4 xyz[3]) {
    /* The third vertex is loaded from offset 5 (B.z, C.x, C.y, C.z) so that
     * no load reads past a row's 9 floats. */
    f4 a = _mm_loadu_ps(r[0] + off), b = _mm_loadu_ps(r[1] + off),
       c = _mm_loadu_ps(r[2] + off), d = _mm_loadu_ps(r[3] + off);
    _MM_TRANSPOSE4_PS(a, b, c, d);
    if (last) {
        xyz[0] = b, xyz[1] = c, xyz[2] = d;
    } else {
        xyz[0] = a, xyz[1] = b, xyz[2] = c;
    }
}

/* The scalar double-precision recomputation for the lanes in `lanes`. */
static inline void kd_tri4_exact(int lanes, f4 ax, f4 ay, f4 bx, f4 by, f4 cx,
                                 f4 cy, f4 *U, f4 *V, f4 *W) {
    _Alignas(16) float s[9][4];
    const f4 in[9] = {ax, ay, bx, by, cx, cy, *U, *V, *W};
    for (int k = 0; k < 9; k++)
        f4_store(s[k], in[k]);
    for (int j = 0; j < 4; j++) {
        if (!((lanes >> j) & 1))
            continue;
        const double dax = s[0][j], day = s[1][j], dbx = s[2][j],
                     dby = s[3][j], dcx = s[4][j], dcy = s[5][j];
        s[6][j] = (float)(dcx * dby - dcy * dbx);
        s[7][j] = (float)(dax * dcy - day * dcx);
        s[8][j] = (float)(dbx * day - dby * dax);
    }
    *U = f4_load(s[6]);
    *V = f4_load(s[7]);
    *W = f4_load(s[8]);
}

/*
 * Tests the triangles whose rows are r[0..3] (rows may repeat); returns the
 * lane mask of hits with tmin <= t <= tmax and their t, scaled V, W and det
 * (u = V / det, v = W / det, as kd_tri_intersect computes them).
 */
static inline int kd_tri4_intersect(const kd_ray_pre4 *p, const float *const r[4],
                                    f4 tmin, f4 tmax, f4 *t_out, f4 *V_out,
                                    f4 *W_out, f4 *det_out) {
    f4 A[3], B[3], C[3];
    kd_tri4_vertex(r, 0, 0, A);
    kd_tri4_vertex(r, 3, 0, B);
    kd_tri4_vertex(r, 5, 1, C);
    /* vertices relative to the origin */
    const f4 Ax = f4_sub(A[p->kx], p->ox), Ay = f4_sub(A[p->ky], p->oy),
             Az0 = f4_sub(A[p->kz], p->oz);
    const f4 Bx = f4_sub(B[p->kx], p->ox), By = f4_sub(B[p->ky], p->oy),
             Bz0 = f4_sub(B[p->kz], p->oz);
    const f4 Cx = f4_sub(C[p->kx], p->ox), Cy = f4_sub(C[p->ky], p->oy),
             Cz0 = f4_sub(C[p->kz], p->oz);
    /* shear into ray space */
    const f4 ax = f4_sub(Ax, f4_mul(p->sx, Az0)), ay = f4_sub(Ay, f4_mul(p->sy, Az0));
    const f4 bx = f4_sub(Bx, f4_mul(p->sx, Bz0)), by = f4_sub(By, f4_mul(p->sy, Bz0));
    const f4 cx = f4_sub(Cx, f4_mul(p->sx, Cz0)), cy = f4_sub(Cy, f4_mul(p->sy, Cz0));
    /* scaled barycentrics */
    f4 U = f4_sub(f4_mul(cx, by), f4_mul(cy, bx));
    f4 V = f4_sub(f4_mul(ax, cy), f4_mul(ay, cx));
    f4 W = f4_sub(f4_mul(bx, ay), f4_mul(by, ax));
    const f4 zero = f4_set1(0.0f);
    const int zl =
        f4_bits(f4_or(f4_or(f4_eq(U, zero), f4_eq(V, zero)), f4_eq(W, zero)));
    if (zl)
        kd_tri4_exact(zl, ax, ay, bx, by, cx, cy, &U, &V, &W);
    const f4 neg = f4_or(f4_or(f4_lt(U, zero), f4_lt(V, zero)), f4_lt(W, zero));
    const f4 pos = f4_or(f4_or(f4_gt(U, zero), f4_gt(V, zero)), f4_gt(W, zero));
    const f4 det = f4_add(f4_add(U, V), W);
    const f4 ok = f4_andnot(f4_or(f4_and(neg, pos), f4_eq(det, zero)),
                            f4_seti(-1));
    if (!f4_bits(ok)) {
        *t_out = *V_out = *W_out = *det_out = zero;
        return 0;
    }
    const f4 az = f4_mul(p->sz, Az0), bz = f4_mul(p->sz, Bz0),
             cz = f4_mul(p->sz, Cz0);
    const f4 T = f4_add(f4_add(f4_mul(U, az), f4_mul(V, bz)), f4_mul(W, cz));
    const f4 t = f4_div(T, det);
    *t_out = t;
    *V_out = V;
    *W_out = W;
    *det_out = det;
    return f4_bits(f4_and(ok, f4_and(f4_le(tmin, t), f4_le(t, tmax))));
}

/* ---- eight triangles (AVX2) ------------------------------------------------ */

typedef struct kd_ray_pre8 {
    f8 ox, oy, oz, sx, sy, sz;
    int kx, ky, kz;
} kd_ray_pre8;

KD_AVX2 static inline void kd_ray_pre8_init(const kd_ray_pre *p, kd_ray_pre8 *q) {
    q->ox = f8_set1(p->org[p->kx]);
    q->oy = f8_set1(p->org[p->ky]);
    q->oz = f8_set1(p->org[p->kz]);
    q->sx = f8_set1(p->sx);
    q->sy = f8_set1(p->sy);
    q->sz = f8_set1(p->sz);
    q->kx = p->kx;
    q->ky = p->ky;
    q->kz = p->kz;
}

/* Floats 0..7 of rows r[0..7] transposed into c[0..7] (lane j of c[i] is
 * r[j][i]), and float 8 of every row into c[8]. */
KD_AVX2 static inline void kd_tri8_load(const float *const r[8], f8 c[9]) {
    f8 v[8], t[8], u[8];
    for (int j = 0; j < 8; j++)
        v[j] = _mm256_loadu_ps(r[j]);
    for (int j = 0; j < 8; j += 2) {
        t[j] = _mm256_unpacklo_ps(v[j], v[j + 1]);
        t[j + 1] = _mm256_unpackhi_ps(v[j], v[j + 1]);
    }
    for (int h = 0; h < 8; h += 4) { /* rows h..h+3 */
        u[h + 0] = _mm256_shuffle_ps(t[h], t[h + 2], 0x44);
        u[h + 1] = _mm256_shuffle_ps(t[h], t[h + 2], 0xEE);
        u[h + 2] = _mm256_shuffle_ps(t[h + 1], t[h + 3], 0x44);
        u[h + 3] = _mm256_shuffle_ps(t[h + 1], t[h + 3], 0xEE);
    }
    for (int i = 0; i < 4; i++) {
        c[i] = _mm256_permute2f128_ps(u[i], u[4 + i], 0x20);
        c[4 + i] = _mm256_permute2f128_ps(u[i], u[4 + i], 0x31);
    }
    c[8] = _mm256_setr_ps(r[0][8], r[1][8], r[2][8], r[3][8], r[4][8], r[5][8],
                          r[6][8], r[7][8]);
}

KD_AVX2 static inline void kd_tri8_exact(int lanes, f8 ax, f8 ay, f8 bx, f8 by,
                                         f8 cx, f8 cy, f8 *U, f8 *V, f8 *W) {
    _Alignas(32) float s[9][8];
    const f8 in[9] = {ax, ay, bx, by, cx, cy, *U, *V, *W};
    for (int k = 0; k < 9; k++)
        f8_store(s[k], in[k]);
    for (int j = 0; j < 8; j++) {
        if (!((lanes >> j) & 1))
            continue;
        const double dax = s[0][j], day = s[1][j], dbx = s[2][j],
                     dby = s[3][j], dcx = s[4][j], dcy = s[5][j];
        s[6][j] = (float)(dcx * dby - dcy * dbx);
        s[7][j] = (float)(dax * dcy - day * dcx);
        s[8][j] = (float)(dbx * day - dby * dax);
    }
    *U = f8_load(s[6]);
    *V = f8_load(s[7]);
    *W = f8_load(s[8]);
}

/* kd_tri4_intersect for eight rows (rows may repeat). */
KD_AVX2 static inline int kd_tri8_intersect(const kd_ray_pre8 *p,
                                            const float *const r[8], f8 tmin,
                                            f8 tmax, f8 *t_out, f8 *V_out,
                                            f8 *W_out, f8 *det_out) {
    f8 c[9];
    kd_tri8_load(r, c);
    const f8 *A = c, *B = c + 3, *C = c + 6;
    /* vertices relative to the origin */
    const f8 Ax = f8_sub(A[p->kx], p->ox), Ay = f8_sub(A[p->ky], p->oy),
             Az0 = f8_sub(A[p->kz], p->oz);
    const f8 Bx = f8_sub(B[p->kx], p->ox), By = f8_sub(B[p->ky], p->oy),
             Bz0 = f8_sub(B[p->kz], p->oz);
    const f8 Cx = f8_sub(C[p->kx], p->ox), Cy = f8_sub(C[p->ky], p->oy),
             Cz0 = f8_sub(C[p->kz], p->oz);
    /* shear into ray space */
    const f8 ax = f8_sub(Ax, f8_mul(p->sx, Az0)), ay = f8_sub(Ay, f8_mul(p->sy, Az0));
    const f8 bx = f8_sub(Bx, f8_mul(p->sx, Bz0)), by = f8_sub(By, f8_mul(p->sy, Bz0));
    const f8 cx = f8_sub(Cx, f8_mul(p->sx, Cz0)), cy = f8_sub(Cy, f8_mul(p->sy, Cz0));
    /* scaled barycentrics */
    f8 U = f8_sub(f8_mul(cx, by), f8_mul(cy, bx));
    f8 V = f8_sub(f8_mul(ax, cy), f8_mul(ay, cx));
    f8 W = f8_sub(f8_mul(bx, ay), f8_mul(by, ax));
    const f8 zero = f8_set1(0.0f);
    const int zl =
        f8_bits(f8_or(f8_or(f8_eq(U, zero), f8_eq(V, zero)), f8_eq(W, zero)));
    if (zl)
        kd_tri8_exact(zl, ax, ay, bx, by, cx, cy, &U, &V, &W);
    const f8 neg = f8_or(f8_or(f8_lt(U, zero), f8_lt(V, zero)), f8_lt(W, zero));
    const f8 pos = f8_or(f8_or(f8_gt(U, zero), f8_gt(V, zero)), f8_gt(W, zero));
    const f8 det = f8_add(f8_add(U, V), W);
    const f8 ok = f8_andnot(f8_or(f8_and(neg, pos), f8_eq(det, zero)),
                            f8_seti(-1));
    if (!f8_bits(ok)) {
        *t_out = *V_out = *W_out = *det_out = zero;
        return 0;
    }
    const f8 az = f8_mul(p->sz, Az0), bz = f8_mul(p->sz, Bz0),
             cz = f8_mul(p->sz, Cz0);
    const f8 T = f8_add(f8_add(f8_mul(U, az), f8_mul(V, bz)), f8_mul(W, cz));
    const f8 t = f8_div(T, det);
    *t_out = t;
    *V_out = V;
    *W_out = W;
    *det_out = det;
    return f8_bits(f8_and(ok, f8_and(f8_le(tmin, t), f8_le(t, tmax))));
}

#endif /* KD_TRI_MULTI_H */
