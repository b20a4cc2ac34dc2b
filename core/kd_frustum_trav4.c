/*
 * kd_frustum_trav4.c — the frustum traversal of kd_frustum_trav.h with
 * 4-wide (SSE2) ray groups (2x2 pixel blocks): kd_frustum_trace_tiles4.
 */
#define KD_W 4
#include "simd_width.h"
#include "kd_frustum_trav.h"
