/*
 * bench.h — the benchmark harness every program shares: the driver that
 * walks the scene ladder and runs sections, one timing loop (bench_measure),
 * the ray workloads, and the summary every program ends with.
 *
 * A program is a list of sections (bench_core.c, bench_bundle.c,
 * bench_frustum.c, bench_cone.c, bench_queries.c); bench_main.c is the one main, built once
 * per program with its default sections and scenes. Any program runs any
 * section (--section), so one process can load each scene once for all.
 *
 * Rules every program follows (docs/BENCHMARKS.md):
 *  - kdray and Embree are measured in the same process and run, on one
 *    thread; timings are process CPU time (the machine is shared: wall
 *    time would measure the neighbours);
 *  - methods are interleaved (m0 m1 m2 m0 m1 m2 ...) and each keeps its
 *    best pass, so a load spike hits all of them alike;
 *  - Embree is the rival of rival.h: fast mode, FTZ/DAZ, rays converted
 *    before timing, every plausible API measured, the fastest the headline.
 *
 * Flags (all optional):
 *   --dir DIR          ladder directory (default: the build's scene-ladder)
 *   --only NAME        ladder scene NAME (repeatable; default: the program's)
 *   --max-tris N       skip ladder scenes above N triangles
 *   --section NAME     run that section (repeatable; default: the program's)
 *   --rays N           rays per workload (default 1048576)
 *   --repeat R         passes per method, best kept (default 3)
 *   --quick            the short subset bench/compare runs (fewer methods,
 *                      one frustum camera, cone at --samples without the
 *                      RMSE reference)
 *   --frame N          frustum image N x N pixels (default 1000)
 *   --samples A,B,...  cone samples per point (default 1,2,4,...,256)
 *   --ref-samples N    cone RMSE reference samples (default 4096; 0: none)
 *   --res N            cone points: an N x N camera's hits (default 64)
 *   --out PREFIX       cone CSV/plot data files PREFIX.csv/.dat/.png
 *   --method PREFIX    time only the methods whose name starts with PREFIX
 *                      (repeatable), e.g. under a profiler: kdray_bench_cone
 *                      --method kd_cone --ref-samples 0; checks that need a
 *                      method left out are skipped
 *   --csv PATH         also write the summary CSV to PATH
 */
#ifndef KDRAY_BENCH_H
#define KDRAY_BENCH_H

#include <stddef.h>
#include <stdint.h>
#include <stdio.h>

#include "kdray.h"

#define BENCH_DEFAULT_RAYS 1048576
#define BENCH_DEFAULT_REPEAT 3
#define BENCH_MAX_SAMPLES 16 /* entries of --samples */

typedef struct rival rival;

typedef struct bench_opts {
    size_t rays;
    int repeat;
    int quick;
    uint32_t frame;
    uint32_t samples[BENCH_MAX_SAMPLES];
    int nsamples;
    int ref_samples;
    int res;
    const char *out_prefix;
} bench_opts;

/* One ladder scene, loaded and built once for all sections: the kd-tree
 * and the rival's fast high-quality BVH, both build times in CPU ms. */
typedef struct bench_scene {
    const char *name;
    const float *tris;
    size_t ntris;
    const kdr_scene *kd;
    double kd_build_ms;
    rival *emb;
} bench_scene;

typedef struct bench_section {
    const char *name;
    int (*run)(const bench_scene *scene, const bench_opts *opts);
    void (*finish)(const bench_opts *opts); /* after the last scene; may be NULL */
} bench_section;

extern const bench_section bench_core_section, bench_bundle_section,
    bench_frustum_section, bench_cone_section, bench_cone_split_section,
    bench_queries_section;

/* Parses the flags above; runs the selected sections on every selected
 * scene; prints the summary CSV. Returns the process exit code (nonzero if
 * a section failed or a check did). */
int bench_main(int argc, char **argv, const char *program,
               const char *const *default_sections,
               const char *const *default_scenes);

/* ---- timing ---------------------------------------------------------------- */

/* Process CPU time in ms. Embree runs threads=1, so this is one core's
 * work on both sides, whatever else the machine runs. */
double bench_cpu_ms(void);

#define BENCH_RIVAL 1u /* an Embree call: FTZ/DAZ on while it runs */

/* One thing to time. prepare (untimed, may be NULL) runs before every pass,
 * run is the timed pass. */
typedef struct bench_method {
    const char *name;
    unsigned flags;
    void (*prepare)(void *ctx);
    void (*run)(void *ctx);
    void *ctx;
    double best_ms; /* out: fastest pass */
} bench_method;

/* The one timing loop: rounds of every method in turn until each has run
 * `repeat` passes and the rounds took min_ms of CPU time in all; each
 * method keeps its fastest pass. A method --method left out is not run
 * and gets best_ms = NAN. */
void bench_measure(bench_method *m, size_t n, int repeat, double min_ms);
/* 1 unless --method was given and no prefix matches the name. */
int bench_method_wanted(const char *name);
/* 1 if --method was given (sections then skip their extra measurements). */
int bench_method_filtered(void);

/* ---- summary ------------------------------------------------------------------ */

/* One row per scene x workload x method. `rays` is the work (rays, pixels
 * or shadow samples; the same for every method of a workload, 0 for
 * builds); nodes_per_ray < 0 when not measured. A second row with the same
 * key keeps the faster time. */
void bench_summary_add(const bench_scene *s, const char *workload,
                       const char *method, size_t rays, double ms,
                       double nodes_per_ray);
/* The time of one row; -1 if there is none. */
double bench_summary_ms(const char *scene, const char *workload, const char *method);
/* The strongest Embree row (least ms; robust rows excluded) of the
 * workload; NULL if there is none. */
const char *bench_summary_rival(const char *scene, const char *workload,
                                double *ms);
/* Geometric mean over the rows of workloads starting with `prefix` of
 * (best Embree ms / method ms) (rival = 1) or of method ms itself (rival =
 * 0); 0 if no row. */
double bench_summary_geomean(const char *prefix, const char *method, int rival);
/* scene,triangles,workload,method,rays,ms,mrays,nodes_per_ray,rival,vs_rival */
void bench_summary_write(FILE *f);

/* Marks the run as failed (a check did not hold); printed at the end. */
void bench_fail(const char *fmt, ...);

/* ---- ray workloads ------------------------------------------------------------- */

/* A set of rays in two forms: kdr_ray structs (single rays, and what the
 * rival converts), and a kdr_trace_batch batch (bundles) in which rays
 * [g*group, (g+1)*group) share one origin (group 0: all share; 1: none). */
typedef struct bench_workload {
    const char *name;   /* camera, random, ao_any, ao_closest, shadow */
    kdr_query query;
    int work;           /* rival_work */
    size_t n, group;
    kdr_ray *rays;
    float *org, *dir;
    float tmin, tmax;   /* shared by all rays */
    kdr_camera cam;     /* camera: the camera whose pixels the rays are */
} bench_workload;

#define BENCH_AO_PER_POINT 64
#define BENCH_SHADOW_PER_POINT 16

/*
 * camera:     primary rays of a camera outside the scene looking at its
 *             centre, square image of about n pixels (side a multiple of
 *             4), pixels in 4x4 tiles, Z-order inside a tile, so any 4, 8
 *             or 16 consecutive rays are a 2x2, 4x2 or 4x4 screen block
 *             (the order a renderer submits packets in); closest hit;
 * random:     origins uniform in the scene's box, directions uniform on
 *             the sphere, [0, inf); closest hit;
 * ao_any,
 * ao_closest: 64 hemisphere directions around the geometric normal of a
 *             random point on a random triangle, tmin 1e-4 and tmax 0.1 of
 *             the scene diagonal; any hit / closest hit;
 * shadow:     16 rays per random surface point toward random points of a
 *             sphere light above the scene (unnormalised directions,
 *             [1e-4, 1 - 1e-4] of the segment); any hit.
 * Returns 0, or -1 (out of memory / unknown name).
 */
int bench_workload_make(bench_workload *w, const kdr_scene *kd,
                        const char *name, size_t n);
void bench_workload_free(bench_workload *w);

/* kdray's ways of answering a workload, as the daemon calls them. */
typedef enum bench_kd {
    BENCH_KD_SINGLE,  /* kdr_intersect1 / kdr_occluded1, ray by ray */
    BENCH_KD_BUNDLE4, /* kdr_trace_batch KDR_TRAV_BUNDLE4 */
    BENCH_KD_BUNDLE8, /* kdr_trace_batch KDR_TRAV_BUNDLE8 (= AUTO with AVX2) */
    BENCH_KD_SORT8,   /* diagnostics: 8-wide, regrouped, no fallback */
    BENCH_KD_RAW8,    /* diagnostics: 8-wide, caller's order, no fallback */
    BENCH_KD_BATCH,   /* kdr_trace_batch KDR_TRAV_AUTO in calls of
                       * BENCH_BATCH_RAYS, every ray with its own origin
                       * (stride 3), as a client's large request arrives */
    BENCH_KD_BUNDLE16, /* the 16-wide (AVX-512) driver, kdr_trace_batch's flags */
} bench_kd;

#define BENCH_BATCH_RAYS 4096

/* Measures the kd modes and every rival API for the workload's kind,
 * interleaved; prints a block, adds summary rows (with nodes per ray
 * from one untimed pass unless quick) and checks that each method's hit
 * count is within 0.1% of kd_single's (bench_fail otherwise). */
int bench_run_workload(const bench_scene *s, const bench_workload *w,
                       const bench_kd *modes, size_t nmodes,
                       const bench_opts *opts);

#endif /* KDRAY_BENCH_H */
