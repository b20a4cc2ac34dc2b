/*
 * kd_traverse_stream16.c — the interleaved walk of closest-hit rays in
 * 16 AVX-512 lanes (kd_stream_hit16), instantiated from kd_traverse_stream_lanes.h;
 * any-hit rays have their own unit (kd_traverse_stream16_any.c). Runs only
 * after kd_cpu_has_avx512() said yes.
 */
#include "kd_entry.h"
#include "kd_stream.h"
#include "kd_traverse_bundle.h"
#include "kd_walk.h"

#define KD_W 16
#define KS_ANY 0
#include "simd_width.h"
#include "kd_traverse_stream_lanes.h"
