/*
 * kd_stream.h — the interleaved walk of a batch's incoherent rays
 * (core/kd_traverse_stream.c): many rays of one batch in flight in one
 * thread, each with its own stack and interval, advanced in turn one node
 * step or one leaf at a time after its next node was requested from
 * memory. Per ray it is exactly the single-ray walk (kd_traverse_single.c:
 * same set-up, node rule, leaves and tie rule), so every answer equals
 * kdr_intersect1 / kdr_occluded1 bit for bit. Internal to core/.
 */
#ifndef KD_STREAM_H
#define KD_STREAM_H

#include <stddef.h>

#include "kdray.h"

/* Traces rays ids[0..m) of the batch (ids NULL: rays [first, first + m);
 * arguments checked by the caller, scene with a tree) and writes each
 * result at its own index; stats as kdr_trace_batch. Picks
 * kd_stream_trace16 on AVX-512 CPUs, else kd_stream_trace8 on AVX2 CPUs,
 * else kd_stream_scalar_trace. */
void kd_stream_trace(const kdr_scene *s, const kdr_ray_batch *b, const size_t *ids,
                     size_t first, size_t m, kdr_query q, kdr_hits *out,
                     kdr_trav_stats *stats);
/* The same with any-hit rays walked far end first (KD_STREAM_FAR in the
 * lane forms; the scalar form walks them front to back: same answers);
 * flags: 0 or KD_STREAM_STAGE (leaves staged whatever the scene's size). */
void kd_stream_trace_far(const kdr_scene *s, const kdr_ray_batch *b, const size_t *ids,
                         size_t first, size_t m, kdr_query q, int flags, kdr_hits *out,
                         kdr_trav_stats *stats);

/* The forms, same contract (tests call each): KD_STREAM_RAYS rays
 * interleaved in scalar code (kd_traverse_stream.c), and 8 or 16 rays in
 * the lanes of AVX2 or AVX-512 registers (kd_traverse_stream_lanes.h; only
 * after kdr_cpu_has_avx2() / kd_cpu_has_avx512() said yes). flags:
 * KD_STREAM_STAGE, KD_STREAM_FAR (lane forms only), or 0. */
void kd_stream_scalar_trace(const kdr_scene *s, const kdr_ray_batch *b, const size_t *ids,
                            size_t first, size_t m, kdr_query q, int flags, kdr_hits *out,
                            kdr_trav_stats *stats);
void kd_stream_trace8(const kdr_scene *s, const kdr_ray_batch *b, const size_t *ids,
                      size_t first, size_t m, kdr_query q, int flags, kdr_hits *out,
                      kdr_trav_stats *stats);
void kd_stream_trace16(const kdr_scene *s, const kdr_ray_batch *b, const size_t *ids,
                       size_t first, size_t m, kdr_query q, int flags, kdr_hits *out,
                       kdr_trav_stats *stats);

/* The lane forms' instantiations, one per query kind (the leaf test is
 * chosen at compile time, kd_traverse_stream_lanes.h): kd_stream_trace8 /
 * 16 call kd_stream_any* for KDR_ANY, kd_stream_hit* otherwise. */
void kd_stream_hit8(const kdr_scene *s, const kdr_ray_batch *b, const size_t *ids,
                    size_t first, size_t m, int flags, kdr_hits *out, kdr_trav_stats *stats);
void kd_stream_any8(const kdr_scene *s, const kdr_ray_batch *b, const size_t *ids,
                    size_t first, size_t m, int flags, kdr_hits *out, kdr_trav_stats *stats);
void kd_stream_hit16(const kdr_scene *s, const kdr_ray_batch *b, const size_t *ids,
                     size_t first, size_t m, int flags, kdr_hits *out, kdr_trav_stats *stats);
void kd_stream_any16(const kdr_scene *s, const kdr_ray_batch *b, const size_t *ids,
                     size_t first, size_t m, int flags, kdr_hits *out, kdr_trav_stats *stats);

/* Leaves staged (a leaf's triangles requested one turn before their test)
 * and next nodes requested on every scene, not only on scenes of
 * KD_STREAM_STAGE_MIN_BYTES and more (tests put small scenes through that
 * path with it). */
#define KD_STREAM_STAGE 1
/* Any-hit rays visit their cells back to front (kd_occluded1_far's order:
 * the far child first, the same intervals, from the root), for rays whose
 * blockers lie nearer their end (kd_batch_far_first); closest-hit walks
 * ignore it. */
#define KD_STREAM_FAR 2

/* The interleaved walks' pop for lane j (walk()'s pop): the depth below
 * sp of the deepest stacked entry whose start stk_tn[depth * width + j] is
 * at or before bound, or -1 when there is none (the ray is done). The
 * stacks are [depth][width] arrays in lane columns. */
static inline int kd_lane_pop_depth(const float *stk_tn, int width, int j, int sp,
                                    float bound) {
    do {
        if (sp == 0) return -1;
        --sp;
    } while (!(stk_tn[sp * width + j] <= bound));
    return sp;
}

/* 1 if the CPU (and OS) run AVX-512 F, DQ, BW and VL code. */
int kd_cpu_has_avx512(void);

#endif /* KD_STREAM_H */
