/*
 * kd_traverse_bundle8.c — the 8-wide (AVX2) instance of the omni-directional
 * bundle traversal in kd_traverse_bundle.h and kd_traverse_bundle_run.h.
 * Every function here carries the avx2 target attribute (the build has no
 * -mavx2); kd_batch.c calls kd_bundle8_trace only when the CPU supports
 * AVX2.
 */
#include "kd_traverse_bundle.h"

#define KD_W 8
#include "simd_width.h"
#include "kd_traverse_bundle.h"
#include "kd_traverse_bundle_run.h"

KD_AVX2 void kd_bundle8_trace(const kdr_scene *s, const kdr_ray_batch *b,
                              size_t first, size_t count, kdr_query q,
                              int flags, kdr_hits *out,
                              kdr_trav_stats *stats) {
    kb_run8(s, b, first, count, q, flags, out, stats);
}
