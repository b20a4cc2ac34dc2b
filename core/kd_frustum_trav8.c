/*
 * kd_frustum_trav8.c — the frustum traversal of kd_frustum_trav.h with
 * 8-wide (AVX2) ray groups (4x2 pixel blocks): kd_frustum_trace_tiles8,
 * called only when kdr_cpu_has_avx2().
 */
#define KD_W 8
#include "simd_width.h"
#include "kd_frustum_trav.h"
