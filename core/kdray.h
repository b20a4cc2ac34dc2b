/*
 * kdray.h — the public API of the kdray core: SAH kd-trees over triangle
 * soups and the four ways of walking them (single rays, omni-directional ray
 * bundles, cone-shadow queries, interval frusta).
 *
 * The core is pure computation: no I/O, no globals, no locks. A built
 * kdr_scene is read-only; every query function may be called on the same
 * scene from any number of threads at once. All arrays are owned by the
 * caller unless a function says otherwise.
 *
 * Conventions (the HTTP contract in shared/API.md uses the same ones):
 *  - a triangle is 9 floats, vertices p0, p1, p2 in file order; triangles
 *    keep the caller's numbering ("prim"); zero-area triangles keep their
 *    number but are never hit;
 *  - a ray is origin o, direction d (any non-zero length; t is measured in
 *    units of |d|, as in Embree) and a closed interval [tmin, tmax];
 *  - a hit has t, prim, and barycentrics u, v with
 *    hit point = (1-u-v)*p0 + u*p1 + v*p2;
 *  - a miss has prim = -1, t = -1, u = v = 0;
 *  - among hits at exactly equal t the smallest prim wins, so every
 *    traversal kind returns the same answer bit for bit.
 */
#ifndef KDRAY_H
#define KDRAY_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/* ---- errors ------------------------------------------------------------ */

typedef enum kdr_status {
    KDR_OK = 0,
    KDR_ENOMEM = -1,   /* allocation failed */
    KDR_EINVAL = -2,   /* invalid argument (NULL, bad count, non-finite) */
    KDR_ERANGE = -3,   /* a size over a hard limit (e.g. > 2^30 triangles) */
    KDR_EIMAGE = -4,   /* a tree image that is truncated, corrupt or stale */
} kdr_status;

const char *kdr_strerror(int status);

/* ---- scenes ------------------------------------------------------------ */

typedef struct kdr_scene kdr_scene; /* opaque, read-only once built */

typedef struct kdr_bounds {
    float min[3], max[3];
} kdr_bounds;

/* SAH build parameters; kdr_build_opts_default() gives the tuned values. */
typedef struct kdr_build_opts {
    float isect_cost;   /* cost of one ray-triangle test */
    float trav_cost;    /* cost of one interior-node step */
    float empty_bonus;  /* in [0,1): SAH discount for cutting off empty space */
    int max_depth;      /* <= 0: 6 + 1.3 log2(N) (pbrt: 8 + ...) */
    int leaf_size;      /* never split a node with at most this many refs */
    int exact_max;      /* >= 0: nodes with more triangles than this choose
                           their plane from min-max bins, smaller ones by the
                           exact SAH sweep (default 65536; INT_MAX: exact
                           everywhere, 0: binned everywhere) */
    int threads;        /* build threads: 0 or 1 = the calling thread only
                           (the default: the caller decides); N > 1 = the
                           caller and up to N-1 threads it starts and joins
                           (fewer on small scenes: about one per 4096
                           triangles; at most 1024 in all). The tree is the
                           same for every value. */
} kdr_build_opts;

void kdr_build_opts_default(kdr_build_opts *opts);

typedef struct kdr_tree_stats {
    uint64_t nodes;        /* interior + leaf */
    uint64_t leaves;
    uint64_t empty_leaves;
    uint64_t max_depth;
    uint64_t refs;         /* triangle references in leaves */
    double refs_per_leaf;  /* refs / non-empty leaves */
    double sah_cost;       /* expected cost of a random ray, SAH units */
    double build_ms;
    uint64_t bytes;        /* nodes + leaf lists + triangle copy */
} kdr_tree_stats;

/* Progress callback for large builds (may be NULL). Called from the
 * building thread only. */
typedef void (*kdr_log_fn)(void *user, const char *msg);

/* Builds a scene from ntris triangles (9*ntris floats, copied). Non-finite
 * coordinates are KDR_EINVAL. ntris may be 0 (every ray misses). With
 * opts->threads > 1 the build starts threads of its own (POSIX threads) and
 * joins them before returning; kdr_scene_build itself may be called from
 * several threads at once. */
int kdr_scene_build(const float *tris, size_t ntris, const kdr_build_opts *opts,
                    kdr_log_fn log, void *log_user, kdr_scene **out);
void kdr_scene_free(kdr_scene *scene);

size_t kdr_scene_triangle_count(const kdr_scene *scene);
void kdr_scene_bounds(const kdr_scene *scene, kdr_bounds *out);
void kdr_scene_tree_stats(const kdr_scene *scene, kdr_tree_stats *out);
/* Length of the bounding-box diagonal (0 for an empty scene). */
float kdr_scene_diagonal(const kdr_scene *scene);
/* The 9 floats of triangle prim (NULL if out of range). */
const float *kdr_scene_triangle(const kdr_scene *scene, size_t prim);

/* ---- traversal statistics (all optional: pass NULL) --------------------- */

typedef struct kdr_trav_stats {
    uint64_t rays;           /* rays answered */
    uint64_t nodes_visited;  /* interior + leaf nodes entered (per ray, summed
                                over rays; a bundle/frustum step counts once per
                                active ray) */
    uint64_t tri_tests;      /* ray-triangle tests */
    uint64_t fallbacks;      /* frusta that fell back to single rays; bundle-sized
                              * groups of a batch traced without bundles (the
                              * interleaved walk of incoherent rays) */
} kdr_trav_stats;

/* ---- single rays --------------------------------------------------------- */

typedef struct kdr_ray {
    float org[3];
    float dir[3];
    float tmin, tmax;
} kdr_ray;

typedef struct kdr_hit {
    float t, u, v;
    int32_t prim; /* -1: miss */
} kdr_hit;

typedef enum kdr_query {
    KDR_CLOSEST = 0, /* nearest hit */
    KDR_ANY = 1,     /* occlusion: any hit in [tmin, tmax] */
    KDR_ALL = 2,     /* every hit, capped (kdr_all_batch only) */
    KDR_COUNT = 3,   /* number of hits (kdr_count_batch only) */
} kdr_query;

/* Closest hit; returns 1 on hit, 0 on miss (hit filled either way). A ray
 * with tmax < tmin, or a NaN anywhere, misses. */
int kdr_intersect1(const kdr_scene *scene, const kdr_ray *ray, kdr_hit *hit,
                   kdr_trav_stats *stats);
/* Any hit; returns 1 if some triangle is hit in [tmin, tmax]. (A ray with
 * a finite tmax is walked from its far end: only stats show it.) */
int kdr_occluded1(const kdr_scene *scene, const kdr_ray *ray,
                  kdr_trav_stats *stats);

/* ---- batches of rays (bundle query) --------------------------------------
 * Inputs are AoS float triples, outputs SoA. A stride of 0 means "one value
 * shared by every ray" (org: 3 floats; tmin/tmax: 1 float). Rays i in
 * [first, first+count) are answered; outputs are indexed by i as well, so
 * several threads can fill disjoint ranges of one output. */
typedef struct kdr_ray_batch {
    size_t n;
    const float *org;  size_t org_stride;  /* 0 or 3 */
    const float *dir;                      /* 3*n, stride 3 */
    const float *tmin; size_t tmin_stride; /* 0 or 1 */
    const float *tmax; size_t tmax_stride; /* 0 or 1 */
} kdr_ray_batch;

typedef struct kdr_hits {
    float *t;       /* closest: n floats */
    int32_t *prim;  /* closest: n ints */
    float *u, *v;   /* closest: n floats each */
    uint8_t *hit;   /* any: n bytes, 0 or 1 */
} kdr_hits;

typedef enum kdr_trav_mode {
    KDR_TRAV_AUTO = 0,   /* best available: bundles of 16 (AVX-512), 8 (AVX2) or 4 */
    KDR_TRAV_SINGLE = 1, /* one ray at a time */
    KDR_TRAV_BUNDLE4 = 2,
    KDR_TRAV_BUNDLE8 = 3, /* falls back to 4 without AVX2 */
} kdr_trav_mode;
/* In the bundle modes (and AUTO) incoherent rays do not go into bundles:
 * chunks of rays with their own origins and scattered directions, and
 * chunks whose first bundles hold few active lanes, are walked one ray per
 * stack but many rays interleaved in one thread (16 in AVX-512 lanes, else
 * KD_STREAM_RAYS in scalar code; core/kd_stream.h). KDR_TRAV_SINGLE is the
 * plain single-ray walk. */

/* Traces rays [first, first+count) of the batch. Results are identical to
 * kdr_intersect1 / kdr_occluded1 ray by ray, whatever the mode. */
int kdr_trace_batch(const kdr_scene *scene, const kdr_ray_batch *batch,
                    size_t first, size_t count, kdr_query query,
                    kdr_trav_mode mode, kdr_hits *out, kdr_trav_stats *stats);

/* 1 if the CPU runs the 8-wide (AVX2) bundle code. */
int kdr_cpu_has_avx2(void);

/* ---- all hits and hit counts (core/kd_all.c) -------------------------------
 * A hit is a triangle that the watertight test (core/kd_tri.h) accepts with
 * tmin <= t <= tmax. Nothing is merged: a ray through an edge shared by two
 * triangles hits both (two hits at the same t), through a vertex shared by
 * k triangles up to k; each triangle counts once however many leaves hold
 * it. The first of the all-hits list is kdr_intersect1's hit. */
#define KDR_MAX_HITS_LIMIT 1024u

/* The first min(max_hits, all) hits of the ray in increasing t, ties by
 * smaller prim, into hits[0..*nhits). max_hits in 1..KDR_MAX_HITS_LIMIT,
 * else KDR_EINVAL. An invalid ray (as for kdr_intersect1) has no hit. */
int kdr_intersect_all1(const kdr_scene *scene, const kdr_ray *ray, uint32_t max_hits,
                       kdr_hit *hits, uint32_t *nhits, kdr_trav_stats *stats);
/* The number of hits, no cap. KDR_ENOMEM when its scratch list (one entry
 * per triangle test that hits) cannot grow. */
int kdr_count1(const kdr_scene *scene, const kdr_ray *ray, uint32_t *count,
               kdr_trav_stats *stats);

/* All hits of rays [first, first+count) of a batch: ray i's hits go to
 * slots [i*max_hits, i*max_hits + nhits[i]) of t, prim, u, v (each
 * n*max_hits long; slots past nhits[i] are not written). */
typedef struct kdr_all_hits {
    uint32_t *nhits; /* n */
    float *t, *u, *v;
    int32_t *prim;
} kdr_all_hits;

int kdr_all_batch(const kdr_scene *scene, const kdr_ray_batch *batch, size_t first,
                  size_t count, uint32_t max_hits, kdr_all_hits *out,
                  kdr_trav_stats *stats);
/* counts[i] = kdr_count1 of ray i. KDR_ENOMEM when a ray's scratch list
 * cannot grow: ray by ray (scenes under 16 MiB) the rays after it are not
 * answered; interleaved (larger scenes, core/kd_all_stream.c) every other
 * ray is, and that ray's count is 0. */
int kdr_count_batch(const kdr_scene *scene, const kdr_ray_batch *batch, size_t first,
                    size_t count, uint32_t *counts, kdr_trav_stats *stats);

/* ---- closest points (core/kd_closest.c) ------------------------------------
 * The point of the scene nearest to a query point: its triangle (prim),
 * barycentrics (point = (1-u-v)*p0 + u*p1 + v*p2) and distance, found by a
 * nearest-triangle search of the kd-tree. Distances are computed in double
 * precision (kdr_point_triangle); among triangles at exactly the same
 * distance the smallest prim wins. Zero-area triangles are never found. */
typedef struct kdr_closest {
    float point[3];
    float distance; /* -1: nothing within max_distance */
    float u, v;
    int32_t prim;   /* -1: nothing within max_distance */
} kdr_closest;

/* The closest point within max_distance (>= 0; +inf: no limit; a triangle
 * at exactly max_distance counts). KDR_EINVAL for a non-finite point or a
 * negative / NaN max_distance. stats count points as rays. */
int kdr_closest_point1(const kdr_scene *scene, const float point[3], float max_distance,
                       kdr_closest *out, kdr_trav_stats *stats);
/* Points [first, first+count) of points (3 floats each) into out[i]. */
int kdr_closest_point_batch(const kdr_scene *scene, const float *points, size_t first,
                            size_t count, float max_distance, kdr_closest *out,
                            kdr_trav_stats *stats);
/* The exact closest point q of triangle tri (9 floats) to p, in double:
 * q = (1-u-v)*p0 + u*p1 + v*p2 and d2 = |p - q|^2. The one distance every
 * search (and the Embree point-query callback of the benchmark) uses. */
void kdr_point_triangle(const float p[3], const float *tri, double q[3], double *u,
                        double *v, double *d2);

/* ---- occupancy (core/kd_occupancy.c) ------------------------------------------
 * Inside (1) or outside (0) the scene's closed meshes: each of
 * KDR_OCCUPANCY_RAYS rays from the point in fixed, well-spread directions
 * counts its hits (kdr_count1) and votes "inside" when the count is odd;
 * the majority decides. A point inside two overlapping closed meshes is
 * outside (parity). Meaningless for open meshes. */
#define KDR_OCCUPANCY_RAYS 9

/* votes (may be NULL): how many rays voted inside. KDR_EINVAL for a
 * non-finite point; KDR_ENOMEM as kdr_count1. */
int kdr_occupancy1(const kdr_scene *scene, const float point[3], uint8_t *inside,
                   uint8_t *votes, kdr_trav_stats *stats);
/* Points [first, first+count) of points (3 floats each) into inside[i]. */
int kdr_occupancy_batch(const kdr_scene *scene, const float *points, size_t first,
                        size_t count, uint8_t *inside, kdr_trav_stats *stats);
/* Direction r (0..KDR_OCCUPANCY_RAYS-1) of the vote (unit length). */
void kdr_occupancy_direction(int r, float dir[3]);

/* ---- cone-shadow queries -------------------------------------------------- */

typedef struct kdr_sphere_light {
    float center[3];
    float radius; /* > 0 */
} kdr_sphere_light;

/* How far each shadow ray's start moves off the surface (shared/API.md
 * v1.1, "epsilon"). */
typedef enum kdr_shadow_offset {
    /* KDR_OFFSET_AUTO_ULPS units in the last place of the point's largest
     * |coordinate| (of FLT_MIN for a point nearer 0): a bound on the float
     * error of the point itself, as renderers offset spawned rays; the
     * same start relative to the point wherever it lies in the scene. */
    KDR_OFFSET_AUTO = 0,
    /* epsilon * the scene's bounding-box diagonal (API v1's only meaning). */
    KDR_OFFSET_DIAGONAL = 1,
} kdr_shadow_offset;

#define KDR_OFFSET_AUTO_ULPS 16

typedef struct kdr_shadow_query {
    size_t n;                 /* points */
    const float *points;      /* 3*n */
    const float *normals;     /* 3*n or NULL */
    const kdr_sphere_light *lights;
    size_t nlights;
    uint32_t samples;         /* 1..4096 */
    uint64_t seed;
    kdr_shadow_offset offset; /* 0 (a zeroed query): KDR_OFFSET_AUTO */
    float epsilon;            /* KDR_OFFSET_DIAGONAL: finite, >= 0 */
} kdr_shadow_query;

typedef struct kdr_shadow_stats {
    uint64_t cones_decided;   /* (point, light) pairs answered without rays */
    uint64_t rays_traced;     /* samples tested against triangles (by a
                                 candidate list, a packet or the tree); samples
                                 of a decided cone are not counted */
    uint64_t nodes_visited;   /* cone traversal nodes + ray traversal nodes */
} kdr_shadow_stats;
/* The stats are a deterministic function of the scene, the query and the
 * range [first, first + count) of one call: within a call each light's last
 * blocker and walk back-off carry from point to point, so splitting the
 * same points into other ranges changes the stats (never the visibilities). */

typedef enum kdr_shadow_mode {
    KDR_SHADOW_CONE = 0,      /* cone traversal, then samples vs candidates */
    KDR_SHADOW_RAYS = 1,      /* every sample traced through the kd-tree */
} kdr_shadow_mode;

/* The exact shadow ray of sample s of point i toward light l (origin already
 * offset, direction toward the sampled point of the sphere, tmin = 0,
 * tmax = the distance to the sphere's near surface in units of dir).
 * Every mode, and the Embree reference in tests, uses these rays. Returns
 * KDR_EINVAL if the point is inside the light. */
/* Details (core/kd_cone_sample.c): dir is unit length, so tmax is a
 * distance. Directions are uniform in solid angle over the cap of half-angle
 * asin(r/D): cos(theta) stratified into `samples` strata with a hashed
 * jitter, the azimuth on a golden-ratio lattice rotated per (point, light);
 * all of it a counter-based hash of (seed, i, l, s): no state, thread-safe.
 * Offset (q->offset): with a normal, the start moves that distance along
 * the normal AS GIVEN (API v1.1: the caller says which side of the surface
 * the point is on; a normal facing away from the light puts the surface
 * between them), each coordinate rounded away from the point so that the
 * move is never shortened by rounding; the offset point is the cone's apex
 * and must itself lie outside the light. Without normals (or with a zero
 * normal) each ray's origin moves that distance along the ray itself.
 * Non-finite inputs, radius <= 0, an unknown offset mode and, with
 * KDR_OFFSET_DIAGONAL, epsilon < 0 or a non-finite epsilon * diagonal are
 * KDR_EINVAL. */
int kdr_shadow_ray(const kdr_scene *scene, const kdr_shadow_query *q, size_t i,
                   size_t l, uint32_t s, kdr_ray *out);

/* Visibility of lights for points [first, first+count): writes
 * visibility[i*nlights + l] in [0,1]. */
int kdr_shadow_trace(const kdr_scene *scene, const kdr_shadow_query *q,
                     size_t first, size_t count, kdr_shadow_mode mode,
                     float *visibility, kdr_shadow_stats *stats);
/* The same answers for the points order[0..count) (indices into q->points,
 * each < q->n), traced in that order: point order[j] keeps its own samples
 * (its index seeds them) and writes only visibility[order[j]*nlights + l].
 * The order changes nothing but the cost: consecutive points that lie
 * close together share cone walks (render/ passes a picture's pixels tile
 * by tile rather than row by row). KDR_EINVAL for an index out of range. */
int kdr_shadow_trace_order(const kdr_scene *scene, const kdr_shadow_query *q,
                           const size_t *order, size_t count, kdr_shadow_mode mode,
                           float *visibility, kdr_shadow_stats *stats);

/* ---- frustum queries ------------------------------------------------------ */

typedef struct kdr_camera {
    float eye[3], target[3], up[3];
    float fov_y_deg;
    uint32_t width, height;
} kdr_camera;

/* Checks the camera (finite, eye != target, up not parallel to the view,
 * 0 < fov < 180, sizes >= 1). */
int kdr_camera_validate(const kdr_camera *cam);
/* The primary ray of pixel (px, py) exactly as shared/API.md defines it
 * (unnormalised direction, tmin 0, tmax +inf). */
void kdr_camera_ray(const kdr_camera *cam, uint32_t px, uint32_t py,
                    kdr_ray *out);
/* The directions of pixels (x0 .. x0+n-1, py), 3 floats each into dirs:
 * exactly kdr_camera_ray's, with the camera's basis computed once (for
 * callers that need many pixels' rays, such as render/). */
void kdr_camera_row_dirs(const kdr_camera *cam, uint32_t py, uint32_t x0,
                         uint32_t n, float *dirs);

typedef enum kdr_frustum_mode {
    KDR_FRUSTUM_MULTI4 = 0, /* four tiles per traversal, SIMD lanes */
    KDR_FRUSTUM_SINGLE = 1, /* one tile per traversal */
    KDR_FRUSTUM_RAYS = 2,   /* reference: each pixel's ray alone */
} kdr_frustum_mode;

/* Number of tile x tile tiles covering the image (row-major tile order). */
size_t kdr_frustum_tile_count(const kdr_camera *cam, uint32_t tile);

/* Traces tiles [first_tile, first_tile+count) of the image; output arrays
 * have width*height entries in row-major pixel order. Results equal
 * kdr_intersect1/kdr_occluded1 of kdr_camera_ray() pixel by pixel. */
int kdr_frustum_trace(const kdr_scene *scene, const kdr_camera *cam,
                      uint32_t tile, size_t first_tile, size_t count,
                      kdr_query query, kdr_frustum_mode mode, kdr_hits *out,
                      kdr_trav_stats *stats);

/* ---- tree images (core/kd_image.c) ---------------------------------------
 * A built scene as one flat, position-independent buffer: the triangles,
 * nodes, leaf lists, bounds and statistics, with a header naming the format
 * and layout versions, the build options and a checksum. The core does no
 * I/O: callers store the buffer (e.g. a tree cache file) and later hand it
 * back, e.g. memory-mapped, to kdr_scene_image_open, which validates every
 * byte a traversal could read before trusting any of it. */

/* Bytes kdr_scene_image_write needs for scene (0 if scene is NULL). */
size_t kdr_scene_image_size(const kdr_scene *scene);

/* Writes the image of scene, built with opts (NULL: defaults), into buf
 * (len >= kdr_scene_image_size(scene); bytes past the image are left as
 * they are). */
int kdr_scene_image_write(const kdr_scene *scene, const kdr_build_opts *opts,
                          void *buf, size_t len);

/* Builds a scene that reads its arrays from buf in place (buf must be
 * 64-byte aligned, e.g. from mmap, and outlive the scene; kdr_scene_free
 * then frees only the scene's own record). The image must have exactly len
 * bytes and have been written with build options equal to opts (NULL:
 * defaults) by this version of the core. Anything else (wrong magic,
 * version, options, size or checksum, an index out of range, a tree deeper
 * than the walks' stacks, a non-finite coordinate) is KDR_EIMAGE, with a
 * static one-line reason in *why (why may be NULL). */
int kdr_scene_image_open(const void *buf, size_t len, const kdr_build_opts *opts,
                         kdr_scene **out, const char **why);

/* The 64-bit checksum the images use (not cryptographic: it catches torn
 * writes and flipped bits, not an adversary); seed chains calls. Exposed so
 * that callers can key caches by file contents with the same function. */
uint64_t kdr_hash64(const void *data, size_t len, uint64_t seed);

#ifdef __cplusplus
}
#endif
#endif /* KDRAY_H */
