/*
 * rival.h — Intel Embree 3 as every benchmark's rival, set up the way a user
 * who wants speed sets it up. This is the only place the benchmarks talk to
 * Embree: device and scene, the ISA report, the floating-point mode, the
 * conversion of kdray's rays into Embree's structs and every timed Embree
 * call.
 *
 * The set-up, and why:
 *  - device "threads=1": kdray's calls are single-threaded, so one core is
 *    compared with one core (the build runs on that thread too);
 *  - scene flags NONE (Embree's fast intersector). RTC_SCENE_FLAG_ROBUST
 *    is only for accuracy references (rival_create(..., robust = 1)); its
 *    rows are never the headline;
 *  - RTC_BUILD_QUALITY_HIGH (spatial splits): what a user who traces many
 *    rays against a static scene picks; the medium build is timed too;
 *  - FTZ/DAZ on while Embree runs (build and trace), as Embree's manual asks
 *    of every application thread; kdray runs with the process default
 *    (off), as the daemon does. rival_fp_enter/leave switch around each
 *    Embree call (bench_measure does it for BENCH_RIVAL methods);
 *  - rays are converted into Embree's structs before the timed call (the
 *    prepare step), except where kdray's own timed work generates its rays
 *    (the frustum's camera rays, the cone's shadow samples): there Embree's
 *    timed call generates them too, with the same generator, straight into
 *    its structs (rival_camera_*, rival_shadow_*);
 *  - for each kind of work, every API a user would reasonably pick is
 *    measured (rival_apis) and the fastest is the headline.
 */
#ifndef KDRAY_BENCH_RIVAL_H
#define KDRAY_BENCH_RIVAL_H

#include <stddef.h>
#include <stdint.h>
#include <stdio.h>

#include <embree3/rtcore.h>

#include "bench.h"
#include "kdray.h"

#define RIVAL_DEVICE_CONFIG "threads=1"
#define RIVAL_QUALITY RTC_BUILD_QUALITY_HIGH

/* ---- device, scene, report ------------------------------------------------ */

typedef struct rival rival;

/* Builds Embree's BVH over ntris triangles (9 floats each, copied; primID
 * == kdray's prim) with FTZ/DAZ on. NULL on failure (message on stderr). */
rival *rival_create(const float *tris, size_t ntris, int robust,
                    enum RTCBuildQuality quality);
void rival_free(rival *r);
double rival_build_ms(const rival *r); /* process CPU ms of rtcCommitScene */
int64_t rival_bytes(const rival *r);   /* Embree's allocations for the scene */
int rival_robust(const rival *r);
RTCScene rival_rtc_scene(const rival *r);
/* The same fast scene (flags NONE plus RTC_SCENE_FLAG_CONTEXT_FILTER_FUNCTION,
 * the flag a context filter needs), for collecting every hit with a filter
 * (bench_queries.c). */
rival *rival_create_filter(const float *tris, size_t ntris, enum RTCBuildQuality quality);
/* The oracle under a rival (oracle_all_filter / oracle_all_requery). */
const struct oracle *rival_oracle(const rival *r);

/* Prints Embree's version, the device set-up, the kernels (and so the ISA)
 * Embree selected for each API, read from its own verbose report of a probe
 * scene, and which packet widths are native. Call once, first. Returns 0,
 * or -1 if Embree's report could not be read (the reason is printed). */
int rival_print_setup(FILE *out);

/* ---- floating-point mode ---------------------------------------------------- */

typedef struct rival_fp {
    unsigned csr;
} rival_fp;
rival_fp rival_fp_enter(void); /* FTZ and DAZ on; returns the old state */
void rival_fp_leave(rival_fp saved);

/* ---- APIs -------------------------------------------------------------------- */

#define RIVAL_STREAM 0 /* width of rtcIntersect1M / rtcOccluded1M */

typedef struct rival_api {
    int width;    /* 1, 4, 8, 16, or RIVAL_STREAM */
    int coherent; /* RTC_INTERSECT_CONTEXT_FLAG_COHERENT */
} rival_api;

typedef enum rival_work {
    RIVAL_WORK_CAMERA,     /* primary rays, pixels in 4x4 tiles */
    RIVAL_WORK_INCOHERENT, /* random origins and directions */
    RIVAL_WORK_HEMISPHERE, /* many directions from one surface point (AO) */
    RIVAL_WORK_SHADOW,     /* a point's samples toward a sphere light */
} rival_work;

#define RIVAL_MAX_APIS 8

/* The APIs a user would try for this kind of work (16-wide only where the
 * device reports native 16-wide packets). Returns how many. */
size_t rival_apis(rival_work work, rival_api *out);

/* "embree_rtcIntersect16_coherent", "embree_rtcOccluded1", ...; robust
 * scenes get "embree_robust_..." (never a headline: see bench_summary). */
void rival_api_name(const rival *r, rival_api api, kdr_query q, char *buf,
                    size_t len);

/* ---- tracing a ray set --------------------------------------------------------- */

/* One API over n kdray rays. The job owns Embree's structs for all n rays:
 * prepare converts the rays into them (untimed), run traces them (timed);
 * afterwards rival_job_answers reads the last pass's answers. */
typedef struct rival_job {
    const rival *r;
    rival_api api;
    kdr_query query;
    const kdr_ray *rays;
    size_t n;
    void *buf;          /* RTCRayHit[n] or RTCRayHitK[ceil(n/K)], aligned */
    int *valid_last;    /* the lane mask of the last (partial) packet */
    char name[64];
} rival_job;

int rival_job_init(rival_job *j, const rival *r, rival_api api, kdr_query q,
                   const kdr_ray *rays, size_t n);
void rival_job_free(rival_job *j);
/* The job as a bench_method (prepare = convert, run = trace, BENCH_RIVAL). */
bench_method rival_job_method(rival_job *j);
/* Per ray: hit[i] = 1 if hit/occluded; prim[i] (may be NULL) = primID or -1. */
void rival_job_answers(const rival_job *j, uint8_t *hit, int32_t *prim);

/* ---- a camera's image (the frustum workload) ----------------------------------- */

/* Every pixel's primary ray (exactly kdr_camera_ray's) is generated inside
 * the timed call, 4x4 pixel tiles at a time, packed for the API, traced,
 * and t/prim/u/v written to row-major arrays: the work kdr_frustum_trace
 * does for one image. The camera's width and height must be multiples of 4. */
typedef struct rival_camera_job {
    const rival *r;
    rival_api api;
    const kdr_camera *cam;
    kdr_hits out;       /* width*height each: t, prim, u, v */
    void *buf;          /* one frame of RTCRayHit (stream) or one packet */
    float *sx, *sy;     /* per-column and per-row camera terms */
    int trace;          /* 0: generate and write out only (the generation's cost) */
    char name[64];
} rival_camera_job;

int rival_camera_job_init(rival_camera_job *j, const rival *r, rival_api api,
                          const kdr_camera *cam, kdr_hits out);
void rival_camera_job_free(rival_camera_job *j);
bench_method rival_camera_job_method(rival_camera_job *j);

/* ---- cone-shadow visibility ---------------------------------------------------- */

/* Visibility of every (point, light) pair of q, as kdr_shadow_trace
 * computes it, with Embree's any-hit API: each sample ray is generated by
 * the project's sampler (kdr_shadow_ray's, via kd_shadow_frame) inside the
 * timed call, straight into the API's struct. Consecutive samples in
 * (point, light, sample) order fill a packet (a point's samples share
 * packets; below the width, neighbouring points' samples fill them) or a
 * stream chunk of 1024 rays; rtcOccluded1 takes them one by one. */
typedef struct rival_shadow_job {
    const rival *r;
    rival_api api;
    const kdr_scene *kd;
    const kdr_shadow_query *q;
    float *vis;         /* n * nlights */
    void *buf;          /* one packet or stream chunk */
    size_t *owner;      /* the (point, light) pair of each slot */
    int trace;          /* 0: generate only (the generation's cost) */
    int failed;         /* a point was rejected by the sampler */
    char name[64];
} rival_shadow_job;

int rival_shadow_job_init(rival_shadow_job *j, const rival *r, rival_api api,
                          const kdr_scene *kd, const kdr_shadow_query *q,
                          float *vis);
void rival_shadow_job_free(rival_shadow_job *j);
bench_method rival_shadow_job_method(rival_shadow_job *j);
/* Runs the job once, untimed (references); -1 if the sampler refused. */
int rival_shadow_job_once(rival_shadow_job *j);

#endif /* KDRAY_BENCH_RIVAL_H */
