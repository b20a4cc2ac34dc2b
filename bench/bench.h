/*
 * bench.h — the reusable benchmark harness (owner: oracle): a driver that
 * walks the scene ladder and calls per-section functions, a wall-clock
 * timer, ray generators (camera, random incoherent, ambient-occlusion
 * hemisphere), an Embree single-thread setup and a long-format CSV writer.
 *
 * A benchmark program is a table of sections and one call:
 *
 *     static const bench_section sections[] = {{"core", bench_core_section}};
 *     int main(int argc, char **argv) {
 *         return bench_main(argc, argv, sections, 1);
 *     }
 *
 * Flags understood by bench_main (all optional):
 *   --dir DIR        ladder directory (default: the build's scene-ladder)
 *   --rays N         rays per ray set (default 1000000)
 *   --max-tris N     skip ladder rungs above N triangles
 *   --only NAME      run only the ladder scene NAME (repeatable)
 *   --repeat R       time each measurement R times, keep the best (default 3)
 *   --csv PATH       write rows `section,scene,triangles,metric,value`
 *   --section NAME   run only that section (repeatable)
 * Embree runs single-threaded (rtcNewDevice "threads=1") like kdray's own
 * single-threaded calls, so ratios compare one core with one core.
 */
#ifndef KDRAY_BENCH_H
#define KDRAY_BENCH_H

#include <stddef.h>
#include <stdint.h>
#include <stdio.h>

#include <embree3/rtcore.h>

#include "kdray.h"

#define BENCH_DEFAULT_RAYS 1000000
#define BENCH_DEFAULT_REPEAT 3
#define BENCH_EMBREE_CONFIG "threads=1"

typedef struct bench_csv bench_csv;

typedef struct bench_opts {
    size_t rays;
    int repeat;
} bench_opts;

/* One ladder scene, loaded and built once for all sections. */
typedef struct bench_scene {
    const char *name;
    const float *tris;
    size_t ntris;
    const kdr_scene *kd;
    double kd_build_ms; /* CPU time of kdr_scene_build */
} bench_scene;

typedef int (*bench_section_fn)(const bench_scene *scene,
                                const bench_opts *opts, bench_csv *csv);
typedef struct bench_section {
    const char *name;
    bench_section_fn run;
} bench_section;

/* Parses the flags above, then for every selected ladder scene runs the
 * selected sections in order. Returns the process exit code. */
int bench_main(int argc, char **argv, const bench_section *sections,
               size_t nsections);

/* ---- timing ---------------------------------------------------------------- */

/* Wall-clock ms. */
double bench_now_ms(void);
/* CPU ms of the whole process (all threads). Speeds and build times use
 * this clock: on a machine shared with other jobs, wall time measures the
 * neighbours, while kdray and Embree (threads=1) both run on one thread. */
double bench_cpu_ms(void);

/* ---- rays -------------------------------------------------------------------- */

/* A camera outside the scene's bounds looking at their centre, with
 * width*height close to n (square image); the rays are kdr_camera_ray's in
 * row-major order. Returns the number of rays written (<= n). */
size_t bench_camera_rays(const kdr_scene *kd, size_t n, kdr_camera *cam,
                         kdr_ray *out);
/* Incoherent rays: origins uniform in the scene's bounds, directions
 * uniform on the sphere, [0, +inf). */
void bench_random_rays(const kdr_scene *kd, uint64_t seed, size_t n,
                       kdr_ray *out);
/* Ambient-occlusion rays: points on random triangles (area-unweighted),
 * `per_point` cosine-free hemisphere directions around the geometric
 * normal, tmin 1e-4 and tmax 0.1 of the scene diagonal (scene units). */
void bench_ao_rays(const kdr_scene *kd, uint64_t seed, size_t n,
                   size_t per_point, kdr_ray *out);

/* ---- Embree ------------------------------------------------------------------ */

/* Mrays/s of rtcIntersect1 (closest) or rtcOccluded1 (any) over the rays,
 * best of `repeat`. `hits` (may be NULL) receives the hit count. */
double bench_embree_mrays(RTCScene rtc_scene, const kdr_ray *rays, size_t n,
                          int any, int repeat, size_t *hits);
/* Mrays/s of kdr_intersect1 / kdr_occluded1, best of `repeat`. */
double bench_kd_mrays(const kdr_scene *kd, const kdr_ray *rays, size_t n,
                      int any, int repeat, size_t *hits);

/* ---- CSV -------------------------------------------------------------------- */

/* Appends one row (no-op when no --csv was given). */
void bench_csv_row(bench_csv *csv, const char *section,
                   const bench_scene *scene, const char *metric, double value);

#endif /* KDRAY_BENCH_H */
