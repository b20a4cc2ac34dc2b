/*
 * kd_traverse_bundle16.c — the 16-wide (AVX-512) instance of the
 * omni-directional bundle traversal in kd_traverse_bundle.h and
 * kd_traverse_bundle_run.h: the width of Embree's strongest packets, for
 * coherent batches (a camera's tiles, many rays from one surface point).
 * The template's masks stay float vectors; simd.h's 16-lane helpers turn
 * AVX-512 compare masks into them. Every function here carries the
 * AVX-512 target attribute (the build has no -mavx512f); kd_batch.c calls
 * kd_bundle16_trace only when kd_cpu_has_avx512() said yes.
 */
#include "kd_traverse_bundle.h"

#define KD_W 16
#include "simd_width.h"
#include "kd_traverse_bundle.h"
#include "kd_traverse_bundle_run.h"

KD_AVX512 void kd_bundle16_trace(const kdr_scene *s, const kdr_ray_batch *b,
                                 size_t first, size_t count, kdr_query q,
                                 int flags, kdr_hits *out,
                                 kdr_trav_stats *stats) {
    kb_run16(s, b, first, count, q, flags, out, stats);
}
