/*
 * kd_traverse_stream8.c — the interleaved walk in 8 AVX2 lanes
 * (kd_stream_trace8), instantiated from kd_traverse_stream_lanes.h. Runs
 * only after kdr_cpu_has_avx2() said yes.
 */
#include "kd_entry.h"
#include "kd_stream.h"
#include "kd_traverse_bundle.h"
#include "kd_walk.h"

#define KD_W 8
#include "simd_width.h"
#include "kd_traverse_stream_lanes.h"
