/*
 * kd_traverse_stream16_any.c — the interleaved walk of any-hit rays in
 * 16 AVX-512 lanes (kd_stream_any16), instantiated from kd_traverse_stream_lanes.h
 * with the single walk's leaf test (kd_walk_leaf). A unit of its own so
 * that the closest-hit unit keeps the 8-wide test inlined. Runs only after
 * kd_cpu_has_avx512() said yes.
 */
#include "kd_entry.h"
#include "kd_stream.h"
#include "kd_traverse_bundle.h"
#include "kd_walk.h"

#define KD_W 16
#define KS_ANY 1
#include "simd_width.h"
#include "kd_traverse_stream_lanes.h"
