/*
 * ab_sets.h — the ray sets kdray_ab (ab_core.c) traces, and the generators
 * that make them from a scene's triangles. The generators only use the
 * public API of the core this tree builds (kdr_camera_ray and the structs
 * of kdray.h), never core A's or B's, so every revision is measured on the
 * same rays; conecam, which needs hit points, is handed core A's
 * intersect1.
 *
 * Ray sets (issue 11's benchmark, same generators as kdray_bench):
 *   camera   closest, a square image of bench_camera_rays' view, per ray
 *   random   closest, origins in the bounds, uniform directions, per ray
 *   ao       any hit, 16 hemisphere rays per surface point, per ray
 *   ao64     any hit, 64 rays per point, per ray (the bundles' baseline)
 *   b8ao     ao64 through kdr_trace_batch(AUTO): bundles per point (16
 *            lanes on an AVX-512 CPU, else 8)
 *   b8ao8    the same through KDR_TRAV_BUNDLE8: 8 lanes on any AVX2 CPU
 *            (kdray_bench's kd_bundle8 AO row, issue 11's bundle target)
 *   b8cam    camera rays in 4x2 pixel blocks through kdr_trace_batch(AUTO)
 *   b16cam   camera rays in 4x4 pixel blocks (a 16-wide bundle's tile)
 *            through kdr_trace_batch(AUTO)
 *   frustum  the camera through kdr_frustum_trace(MULTI4, tile 8)
 *   cone16   kdr_shadow_trace(CONE), 16 samples per point toward a small
 *            light (bench_cone's, r = 0.03 diagonal), points and normals
 *            of ao's surface points (rays / 16 points)
 *   cone64   the same with bench_cone's large light (r = 0.25) at 64 spp
 *   conecam  the small light at 64 spp from the camera's hit points in scan
 *            order, normals toward the eye, 1e-4 x diagonal offsets (what
 *            a render asks: coherent runs of points; rays / 64 pixels)
 *   shadow   any hit, one ray per surface point (ao's points) toward a
 *            random point of bench_cone's small light, tmax 1, per ray
 *   camshadow
 *            any hit, one ray per hit point of the camera (offset 1e-4
 *            diagonal toward the eye) to a random point of the small
 *            light, tmax 1, single rays (what a renderer's shadow pass asks)
 *   brandom, bao, baoc, bshadow
 *            random (closest), ao (any hit), ao with closest hit and shadow
 *            rays through kdr_trace_batch(AUTO) in calls of 4096 rays
 *            (KDR_CHUNK_RAYS, the daemon's chunk) with per-ray origins and
 *            intervals, in the order the single sets trace them; Embree
 *            traces them with rtcIntersect1 / rtcOccluded1 as in the single
 *            sets
 *   bao64    ao64 as bao: calls of 4096 rays with per-ray origins, runs
 *            of 64 sharing one (kdray_bench --section core's ao_any
 *            kd_batch row, the one issue 11's AO target is read from; on
 *            large scenes kd_batch_scattered sends its chunks to the
 *            interleaved walk, where b8ao's one-origin calls stay bundles)
 *   bao1     AO any hit with one ray per surface point (ao_rays with a
 *            run of 1: a renderer's one AO sample per pixel), as bao
 *   bshadow16
 *            any hit, 16 rays per surface point (ao_rays' points) toward
 *            the small light, as bshadow (kdray_bench's shadow workload:
 *            runs of 16 rays sharing an origin in calls of 4096)
 * Issue 15's queries (only when named with --set; no Embree here, its
 * rivals are in kdray_bench --section queries):
 *   all16    camera rays, kdr_intersect_all1 capped at 16 hits
 *   all      random rays, kdr_intersect_all1 capped at 1024 (every hit)
 *   count    random rays, kdr_count1
 *   closest  kdr_closest_point1 without a distance limit; bench_queries'
 *            points (alternately near a random triangle, offset up to
 *            1e-3 of the diagonal, and uniform in the box)
 *   ball16, ball, bcount
 *            all16, all and count through kdr_all_batch / kdr_count_batch
 *            in calls of AB_QUERY_BATCH rays (the daemon's calls), so the
 *            batch walk (kd_all_stream.c on large scenes) is A/B'd too
 *   For these, "diff" counts queries whose answer differs between A and B:
 */
#ifndef KDRAY_BENCH_AB_SETS_H
#define KDRAY_BENCH_AB_SETS_H

#include <stddef.h>
#include <stdint.h>

#include "kdray.h"

enum {
    SET_CAMERA, SET_RANDOM, SET_AO, SET_AO64, SET_B8AO, SET_B8CAM, SET_FRUSTUM,
    SET_CONE16, SET_CONE64, SET_SHADOW,
    SET_CAMSHADOW, /* shadow rays from the camera's hit points, one each, single rays */
    SET_BRANDOM, SET_BAO, SET_BAOC,
    SET_BSHADOW, SET_BSHADOW16, SET_B16CAM, SET_CONECAM,
    SET_B8AO8, /* b8ao through the 8-wide driver (KDR_TRAV_BUNDLE8), issue 11 */
    SET_BAO64, /* ao64 as bao: calls of AB_BATCH with per-ray origins */
    SET_BAO1,  /* AO any hit, one ray per point, as bao */
    SET_BCAMLARGE, /* camshadow's points toward the large light, in calls of AB_BATCH */
    SET_ALL16, SET_ALL, SET_COUNT, SET_CLOSEST,
    SET_BALL16, SET_BALL, SET_BCOUNT, NSETS
};
/* The sets run when no --set is given (issue 15's only on request). */
#define DEFAULT_SETS ((1 << SET_ALL16) - 1)
extern const char *const set_names[NSETS];
/* Sets Embree traces too (per ray, rtcIntersect1 / rtcOccluded1). */
extern const unsigned char set_embree[NSETS];
/* Rays per kdr_trace_batch call of the b* sets (the daemon's chunk). */
#define AB_BATCH 4096

/* A scene's triangles (9 floats each) and their bounds. */
typedef struct scene_in {
    const float *tris;
    size_t ntris;
    float lo[3], hi[3], diag;
} scene_in;

/* Fills lo, hi and diag from the triangles. */
void scene_bounds(scene_in *s);

/* bench_camera_rays' camera: outside the box, looking at its centre; a
 * square image of at most n pixels. */
void camera_of(const scene_in *s, size_t n, kdr_camera *cam);

/* Camera rays, row-major (tiled 1: in 4x2 pixel blocks, 2: in 4x4);
 * returns how many were written. */
size_t camera_rays(const kdr_camera *cam, int tiled, kdr_ray *out);

/* Origins in the bounds, uniform directions, t in [0, inf). */
void random_rays(const scene_in *s, size_t n, kdr_ray *out);

/* bench_ao_rays: per_point hemisphere rays around a random triangle's
 * geometric normal, [1e-4, 1] * 0.1 diagonal. */
void ao_rays(const scene_in *s, size_t n, size_t per_point, kdr_ray *out);

/* bench_cone's lights: small (r = 0.03 diagonal) or large (0.25). */
void light_of(const scene_in *s, int large, kdr_sphere_light *li);

/* per_point shadow rays per surface point (ao_rays' points) toward random
 * points of the sphere light li: dir = target - point, t in [1e-4, 1]. */
void shadow_rays(const scene_in *s, size_t n, size_t per_point,
                 const kdr_sphere_light *li, kdr_ray *out);

/* cone16 / cone64's query: up to npts surface points (ao_rays' points)
 * outside the light, spp samples each; scratch holds npts rays, pts 6 *
 * npts floats (points, then normals). */
void cone_query(const scene_in *s, size_t npts, int large, uint32_t spp, kdr_ray *scratch,
                float *pts, kdr_sphere_light *li, kdr_shadow_query *q);

/* A core's kdr_intersect1. */
typedef int (*ab_intersect1_fn)(const kdr_scene *, const kdr_ray *, kdr_hit *,
                                kdr_trav_stats *);

/* conecam's query: the hit points of a side x side camera (side^2 <= max
 * pixels, traced by intersect1 on kd), row by row, normals toward the eye;
 * pts holds 6 * max floats. */
void conecam_query(const scene_in *s, ab_intersect1_fn intersect1, const kdr_scene *kd,
                   size_t max, float *pts, kdr_sphere_light *li, kdr_shadow_query *q);

/* camshadow's rays: one shadow ray per hit point of a side x side camera
 * (side^2 <= max pixels, traced by intersect1 on kd), from the point
 * offset 1e-4 diagonal off its triangle toward the eye's side, to a random
 * point of the light, [1e-4, 1]; returns how many. */
size_t camshadow_rays(const scene_in *s, ab_intersect1_fn intersect1, const kdr_scene *kd,
                      size_t max, const kdr_sphere_light *li, kdr_ray *out);

/* bench_queries' closest-point workload (3 floats per point). */
void closest_points(const scene_in *s, size_t n, float *pts);

#endif
