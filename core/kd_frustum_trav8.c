/*
 * kd_frustum_trav8.c — the frustum traversal of kd_frustum_trav.h with
 * 8-wide (AVX2) ray groups (4x2 pixel blocks); called only when kdr_cpu_has_avx2().
 */
#include "simd.h"

#define KB_W 8
#define VF f8
#define V(op) f8_##op
#define KB(x) kf8_##x
#define KB_FN KD_AVX2 static inline
#define KF_FN KD_AVX2 static
#define KF_FN_EXPORT KD_AVX2
#define KF_ENTRY kd_frustum_trace_tiles8
#include "kd_frustum_trav.h"
