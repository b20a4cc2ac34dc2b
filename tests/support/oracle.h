/*
 * oracle.h — Intel Embree 3 as the reference answer for kdray's tests and
 * benchmarks. An oracle is one Embree device and scene built from the same
 * flat triangle array the kd-tree gets (geomID 0, primID == our prim), and
 * answers single rays with kdray's conventions: a miss is prim -1, t -1,
 * u = v = 0; the interval [tmin, tmax] is closed (Embree's Pluecker test
 * accepts tnear <= t <= tfar, the same closed interval).
 *
 * Tests use the default options: RTC_SCENE_FLAG_ROBUST (watertight-ish edge
 * tests; without it about 1 ray in 100K slips through a closed sphere) and
 * RTC_BUILD_QUALITY_HIGH. FTZ/DAZ is left off, as for kdray. Embree is never
 * linked into the daemon; this file is tests/ and bench/ only.
 */
#ifndef KDRAY_TEST_ORACLE_H
#define KDRAY_TEST_ORACLE_H

#include <stddef.h>
#include <stdint.h>

#include <embree3/rtcore.h>

#include "kdray.h"

typedef struct oracle_opts {
    int robust;               /* RTC_SCENE_FLAG_ROBUST */
    enum RTCBuildQuality quality;
    const char *device_config; /* rtcNewDevice config, e.g. "threads=1" */
    int context_filter;       /* RTC_SCENE_FLAG_CONTEXT_FILTER_FUNCTION: needed
                                 by oracle_all_filter (oracle_all.c) */
} oracle_opts;

/* robust = 1, quality = HIGH, device_config = NULL (Embree's default),
 * context_filter = 0. */
void oracle_opts_default(oracle_opts *opts);

/* What the accuracy gates judge with: the defaults plus device_config
 * ORACLE_JUDGE_CONFIG. Embree's robust kernels decide some boundary rays
 * differently per ISA (between AVX-512, AVX2 and SSE4.2 a class moves by
 * up to 15%, frustum ties by 44%: docs/ACCURACY.md, "Caps"), so the
 * gates cap Embree at AVX2, which every AVX2 machine runs the same: their
 * class counts, and the caps on them (caps.h), are then machine-independent.
 * Benchmarks never use this. */
#define ORACLE_JUDGE_CONFIG "max_isa=avx2"
void oracle_opts_judge(oracle_opts *opts);

typedef struct oracle oracle;

/* Builds Embree's BVH over ntris triangles (9*ntris floats; copied). NULL on
 * failure (a message goes to stderr). opts may be NULL for the defaults. */
oracle *oracle_create(const float *tris, size_t ntris, const oracle_opts *opts);
void oracle_free(oracle *o);

/* Wall-clock milliseconds of rtcCommitScene (the BVH build alone). */
double oracle_build_ms(const oracle *o);
/* Process CPU milliseconds of the same call (robust on a busy machine when
 * the device runs one thread). */
double oracle_build_cpu_ms(const oracle *o);
/* Bytes Embree allocated for the scene (buffers + BVH), from its device
 * memory monitor; includes the copy of the triangles. */
int64_t oracle_bytes(const oracle *o);

RTCScene oracle_rtc_scene(const oracle *o);

/* Closest hit with kdray's conventions; returns 1 on hit. A ray with a NaN,
 * a zero direction or tmax < tmin misses without asking Embree. */
int oracle_intersect1(const oracle *o, const kdr_ray *ray, kdr_hit *hit);
/* Any hit in [tmin, tmax]. */
int oracle_occluded1(const oracle *o, const kdr_ray *ray);

/* ---- every hit along a ray, the two ways Embree users collect them
 * (oracle_all.c) ---- */

/* A context filter function that records each (t, primID, u, v) Embree
 * reports and rejects it, so the traversal goes on to the end; hits of the
 * same prim reported twice (a triangle in several BVH leaves, spatial
 * splits) are kept once. Needs an oracle made with context_filter = 1.
 * Writes the hits sorted by (t, prim) into out[0..cap) and returns how many
 * there are in all (may exceed cap: only the first cap are written). */
size_t oracle_all_filter(const oracle *o, const kdr_ray *ray, kdr_hit *out, size_t cap);
/* The same filter as a benchmark rival would write it: hits go straight into
 * the caller's buf[0..cap) (no allocation per ray), deduplicated there;
 * hits past cap are only counted (not deduplicated, so a prim reported twice
 * past cap counts twice); sorted by (t, prim) only when sort != 0 (a count
 * or a parity needs no order). Returns the hits found. */
size_t oracle_all_filter_into(const oracle *o, const kdr_ray *ray, kdr_hit *buf,
                              size_t cap, int sort);
/* The re-query loop: closest hit, then again from just past it (tnear =
 * the next float after t) until a miss or cap hits. Hits sharing a t with
 * an earlier one (shared edges) are lost, as they are for users of this
 * way. Returns the number written (<= cap). Any oracle. */
size_t oracle_all_requery(const oracle *o, const kdr_ray *ray, kdr_hit *out, size_t cap);

/* The closest point of the scene to p within max_distance, the way an
 * Embree user gets it: rtcPointQuery with a callback that computes each
 * candidate's distance (kdr_point_triangle, the core's double-precision
 * distance, so answers compare bit for bit) and shrinks the query radius.
 * tris: the triangles the oracle was built from. Returns 1 if found. */
int oracle_closest_point(const oracle *o, const float *tris, const float p[3],
                         float max_distance, kdr_closest *out);

#endif /* KDRAY_TEST_ORACLE_H */
