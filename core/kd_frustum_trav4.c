/*
 * kd_frustum_trav4.c — the frustum traversal of kd_frustum_trav.h with
 * 4-wide (SSE2) ray groups (2x2 pixel blocks).
 */
#include "simd.h"

#define KB_W 4
#define VF f4
#define V(op) f4_##op
#define KB(x) kf4_##x
#define KB_FN static inline
#define KF_FN static
#define KF_FN_EXPORT 
#define KF_ENTRY kd_frustum_trace_tiles4
#include "kd_frustum_trav.h"
