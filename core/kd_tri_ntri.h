/*
 * kd_tri_ntri.h — the watertight test of core/kd_tri.h for ONE ray against
 * N triangles at once (N = 4 lanes, SSE2, the x86-64 baseline; N = 8 lanes,
 * AVX2), for single-ray leaves holding many triangles. Its twin for N rays
 * against one triangle is kd_tri_nray.h.
 *
 * Each lane performs exactly the float operations of kd_tri_intersect in
 * the same order (the build has -ffp-contract=off and the lane layer has no
 * FMA), so a lane's t, V, W and det are bit-identical to the scalar test's;
 * the rare edge function that is exactly 0 is recomputed in double per lane,
 * as the scalar test does. The triangles are read from their 9-float rows
 * and transposed in registers, so the scene needs no second copy.
 *
 * The arithmetic is written once in kd_tri_ntri_lanes.h and instantiated
 * here for 4 lanes (kd_ntri_pre4, kd_ntri_test4, ...) and 8 lanes
 * (kd_ntri_pre8, kd_ntri_test8, ...) with the convention of simd_width.h;
 * only the row transposes differ per width. The 8-wide form needs AVX2:
 * call it only from KD_AVX2 functions after the CPU said yes.
 */
#ifndef KD_TRI_NTRI_H
#define KD_TRI_NTRI_H

#include "kd_tri.h"
#include "simd.h"

/* The three vertices of the triangles in rows r[0..3], transposed (lane j
 * of A[i] is r[j][i], of B[i] r[j][3 + i], of C[i] r[j][6 + i]). The third
 * vertex is loaded from offset 5 (B.z, C.x, C.y, C.z) so that no load reads
 * past a row's 9 floats. */
static inline void kd_ntri_load4(const float *const r[4], f4 A[3], f4 B[3],
                                 f4 C[3]) {
    f4 c[4];
    f4_rows4(r, 0, c);
    A[0] = c[0], A[1] = c[1], A[2] = c[2];
    f4_rows4(r, 3, c);
    B[0] = c[0], B[1] = c[1], B[2] = c[2];
    f4_rows4(r, 5, c);
    C[0] = c[1], C[1] = c[2], C[2] = c[3];
}

/* The same for rows r[0..7]. */
KD_AVX2 static inline void kd_ntri_load8(const float *const r[8], f8 A[3],
                                         f8 B[3], f8 C[3]) {
    f8 c[9];
    f8_rows9(r, c);
    for (int i = 0; i < 3; i++)
        A[i] = c[i], B[i] = c[3 + i], C[i] = c[6 + i];
}

#define KD_W 4
#include "simd_width.h"
#include "kd_tri_ntri_lanes.h"
#undef KD_W
#define KD_W 8
#include "simd_width.h"
#include "kd_tri_ntri_lanes.h"
#undef KD_W

/* The rows of a group of four references from a leaf list with `left`
 * (>= 1) of them remaining: the last group repeats its final reference, so
 * a hit found twice is kept once. prims[j] is row j's triangle. */
static inline void kd_ntri_rows4(const float *tris, const uint32_t *ref, uint32_t left,
                                 int32_t prims[4], const float *rows[4]) {
    for (uint32_t j = 0; j < 4; j++) {
        prims[j] = (int32_t)ref[j < left ? j : left - 1];
        rows[j] = tris + 9 * (size_t)prims[j];
    }
}

#endif /* KD_TRI_NTRI_H */
