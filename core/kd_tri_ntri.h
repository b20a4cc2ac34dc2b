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
 * The arithmetic is written once in kd_tri_lanes.h and instantiated here
 * for 4 lanes (kd_ray_pre4, kd_tri4_*) and 8 lanes (kd_ray_pre8,
 * kd_tri8_*); only the row transposes differ per width. The 8-wide form
 * needs AVX2: call it only from KD_AVX2 functions after the CPU said yes
 * (see core/simd.h).
 */
#ifndef KD_TRI_MULTI_H
#define KD_TRI_MULTI_H

#include "kd_tri.h"
#include "simd.h"

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

/* The three vertices of the triangles in rows r[0..3], transposed. */
static inline void kd_tri4_load(const float *const r[4], f4 A[3], f4 B[3],
                                f4 C[3]) {
    kd_tri4_vertex(r, 0, 0, A);
    kd_tri4_vertex(r, 3, 0, B);
    kd_tri4_vertex(r, 5, 1, C);
}

/* Floats 0..7 of rows r[0..7] transposed into c[0..7] (lane j of c[i] is
 * r[j][i]), and float 8 of every row into c[8]. */
KD_AVX2 static inline void kd_tri8_rows(const float *const r[8], f8 c[9]) {
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

/* The three vertices of the triangles in rows r[0..7], transposed. */
KD_AVX2 static inline void kd_tri8_load(const float *const r[8], f8 A[3],
                                        f8 B[3], f8 C[3]) {
    f8 c[9];
    kd_tri8_rows(r, c);
    for (int i = 0; i < 3; i++)
        A[i] = c[i], B[i] = c[3 + i], C[i] = c[6 + i];
}

/* ---- four triangles (SSE2) ------------------------------------------------- */
#define KT_W 4
#define VF f4
#define V(op) f4_##op
#define KT(x) kd_tri4_##x
#define KT_PRE(x) kd_ray_pre4##x
#define KT_FN static inline
#include "kd_tri_lanes.h"
#undef KT_W
#undef VF
#undef V
#undef KT
#undef KT_PRE
#undef KT_FN

/* ---- eight triangles (AVX2) ------------------------------------------------ */
#define KT_W 8
#define VF f8
#define V(op) f8_##op
#define KT(x) kd_tri8_##x
#define KT_PRE(x) kd_ray_pre8##x
#define KT_FN KD_AVX2 static inline
#include "kd_tri_lanes.h"
#undef KT_W
#undef VF
#undef V
#undef KT
#undef KT_PRE
#undef KT_FN

#endif /* KD_TRI_MULTI_H */
