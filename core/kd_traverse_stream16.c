/*
 * kd_traverse_stream16.c — the interleaved walk in 16 AVX-512 lanes
 * (kd_stream_trace16), instantiated from kd_traverse_stream_lanes.h. Runs
 * only after kd_cpu_has_avx512() said yes.
 */
#include "kd_entry.h"
#include "kd_stream.h"
#include "kd_traverse_bundle.h"
#include "kd_walk.h"

#define KD_W 16
#include "simd_width.h"
#include "kd_traverse_stream_lanes.h"
