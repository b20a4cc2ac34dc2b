/*
 * kd_traverse_bundle4.c — the 4-wide (SSE2, the paper's 2x2) instance of the
 * omni-directional bundle traversal in kd_traverse_bundle.h and
 * kd_traverse_bundle_run.h.
 */
#include "kd_traverse_bundle.h"

#define KD_W 4
#include "simd_width.h"
#include "kd_traverse_bundle.h"
#include "kd_traverse_bundle_run.h"

void kd_bundle4_trace(const kdr_scene *s, const kdr_ray_batch *b, size_t first,
                      size_t count, kdr_query q, int flags, kdr_hits *out,
                      kdr_trav_stats *stats) {
    kb_run4(s, b, first, count, q, flags, out, stats);
}
