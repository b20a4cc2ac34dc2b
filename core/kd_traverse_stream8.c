/*
 * kd_traverse_stream8.c — the interleaved walk of closest-hit rays in
 * 8 AVX2 lanes (kd_stream_hit8), instantiated from kd_traverse_stream_lanes.h;
 * any-hit rays have their own unit (kd_traverse_stream8_any.c). Runs only
 * after kdr_cpu_has_avx2() said yes.
 */
#include "kd_entry.h"
#include "kd_stream.h"
#include "kd_traverse_bundle.h"
#include "kd_walk.h"

#define KD_W 8
#define KS_ANY 0
#include "simd_width.h"
#include "kd_traverse_stream_lanes.h"
