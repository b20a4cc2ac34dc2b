/*
 * kd_all_stream.h — the entry point of the interleaved walk of all hits and
 * counts (kd_all_stream.c) and its tuning, apart from kd_all.h's walk
 * pieces so that tests can call it directly. Internal to core/.
 */
#ifndef KD_ALL_STREAM_H
#define KD_ALL_STREAM_H

#include <stddef.h>
#include <stdint.h>

#include "kd_tune.h"
#include "kdray.h"

/* Rays in flight in the interleaved walk. 16 against 8 (bench/ab, B/A
 * median, --rays 32768 --rounds 5; 0 answers differ): batches of random
 * rays 1.12-1.16 on 2CylinderEngine, 1.13-1.18 on engine3, 1.23-1.24 on
 * engine9, 1.01-1.08 on duck and haus (bcount; ball 0.97-1.01); camera
 * batches 1.08 on engine3, 1.12 on engine9. Each slot holds about 2 KiB
 * (its stack and a count's first prims), on the caller's stack. */
#define KD_ALL_RAYS 16
/* kdr_all_batch and kdr_count_batch take the interleaved walk on scenes
 * of at least this many bytes (kdr_tree_stats.bytes), the closest-hit
 * walk's staging threshold; on smaller ones, for the chunks that
 * kd_batch_scattered calls scattered. */
#define KD_ALL_STREAM_MIN_BYTES KD_STREAM_STAGE_MIN_BYTES
/* Leaves staged (references, then triangles requested a turn ahead of the
 * test) on every scene, not only on those of KD_STREAM_STAGE_MIN_BYTES and
 * more (tests put small scenes through that path with it). */
#define KD_ALL_STAGE 1
/* kd_all_stream takes its scalar form even on AVX-512 CPUs (tests compare
 * both forms with the one-ray walk). */
#define KD_ALL_SCALAR 2
/* The walk drops tests the ray's mailbox says it made already (kd_all.h,
 * test_leaf's mbox) whatever the scene's references per triangle
 * (all_use_mbox decides otherwise; tests put every scene through it). */
#define KD_ALL_MBOX 4
/* kdr_all_batch and kdr_count_batch stage leaves (KD_ALL_STAGE) on scenes
 * of at least this many bytes: staged against not, scattered chunks
 * (bench/ab, sets ball and bcount, --rays 32768 --rounds 5, B/A median):
 * 2CylinderEngine (6 MiB) 1.29 / 1.12, haus (2 MiB) 0.89 / 0.87; the
 * threshold lies between them, no scene in between was measured. */
#define KD_ALL_STAGE_MIN_BYTES ((size_t)4 << 20)
/* On AVX-512 CPUs (kd_all_lanes16) kdr_all_batch and kdr_count_batch take
 * the interleaved walk for every chunk from this many bytes, a camera's
 * chunks included. */
#define KD_ALL_LANES_MIN_BYTES ((size_t)4 << 20)

/* The interleaved walk of rays [first, first + count) of a batch
 * (arguments checked by the caller): with max_hits > 0 each ray's hits, as
 * kdr_intersect_all1 finds them, into out (buf: KD_ALL_RAYS * max_hits
 * entries of scratch); else each ray's count, as kdr_count1 finds it, into
 * counts[i]. Stats as the one-ray calls sum them (with KD_ALL_MBOX on a
 * scene where all_use_mbox says no, fewer triangle tests). flags: any of
 * KD_ALL_STAGE, KD_ALL_SCALAR, KD_ALL_MBOX, or 0. On AVX-512 CPUs, unless flags has KD_ALL_SCALAR,
 * the node steps run in the lanes of kd_all_lanes16 (kd_all_lanes.c), else
 * one ray at a time in turn (kd_all_stream.c). Returns KDR_OK, or
 * KDR_ENOMEM when a count's list could not grow (that ray's count is 0;
 * the other rays are answered). */
int kd_all_stream(const kdr_scene *sc, const kdr_ray_batch *b, size_t first,
                  size_t count, uint32_t max_hits, kdr_hit *buf, kdr_all_hits *out,
                  uint32_t *counts, int flags, kdr_trav_stats *stats);
/* The lanes form, same contract (flags: KD_ALL_STAGE, KD_ALL_MBOX); only after
 * kd_cpu_has_avx512() said yes. */
int kd_all_lanes16(const kdr_scene *sc, const kdr_ray_batch *b, size_t first,
                   size_t count, uint32_t max_hits, kdr_hit *buf, kdr_all_hits *out,
                   uint32_t *counts, int flags, kdr_trav_stats *stats);

#endif /* KD_ALL_STREAM_H */
