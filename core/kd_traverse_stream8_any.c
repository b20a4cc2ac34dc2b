/*
 * kd_traverse_stream8_any.c — the interleaved walk of any-hit rays in
 * 8 AVX2 lanes (kd_stream_any8), instantiated from kd_traverse_stream_lanes.h
 * with the single walk's leaf test (kd_walk_leaf). A unit of its own so
 * that the closest-hit unit keeps the 8-wide test inlined. Runs only after
 * kdr_cpu_has_avx2() said yes.
 */
#include "kd_entry.h"
#include "kd_stream.h"
#include "kd_traverse_bundle.h"
#include "kd_walk.h"

#define KD_W 8
#define KS_ANY 1
#include "simd_width.h"
#include "kd_traverse_stream_lanes.h"
