/*
 * kd_cone.h — internal interface between the shadow-ray sampler
 * (kd_cone_sample.c, which defines kdr_shadow_ray) and the cone-shadow query
 * (kd_cone.c). A "frame" is everything about one (point, light) pair that
 * all of its samples share: the cone apex, the axis and its basis, the
 * half-angle and the hash key; building it once per pair keeps the per-sample
 * cost to a few multiplications and makes every mode use identical rays.
 */
#ifndef KD_CONE_H
#define KD_CONE_H

#include <stdint.h>

#include "kd_internal.h"
#include "kdray.h"

typedef struct kd_shadow_frame {
    float apex[3];      /* the point, moved along the normal when given */
    double axis[3];     /* unit vector from apex toward the light centre */
    double b1[3], b2[3];/* completes axis to an orthonormal basis */
    double center[3];
    double radius;
    double dist;        /* apex to light centre, > radius */
    double sin_a;       /* sin of the half-angle: radius / dist */
    double one_minus_cos; /* 1 - cos(half-angle), without cancellation */
    float along;        /* > 0: each ray's origin moves this far along it */
    uint64_t key;       /* hash of (seed, point, light) */
    double phi_shift;   /* per-pair rotation of the azimuth lattice */
} kd_shadow_frame;

/* Sets up the frame of point i and light l; KDR_EINVAL if an input is not
 * finite, the radius is not positive or the apex is inside the light. */
int kd_shadow_frame_init(const kdr_scene *scene, const kdr_shadow_query *q,
                         size_t i, size_t l, kd_shadow_frame *f);

/* Sample s of nsamples of the frame (direction unit length, tmin 0). */
void kd_shadow_frame_ray(const kd_shadow_frame *f, uint32_t s,
                         uint32_t nsamples, kdr_ray *out);

/* ---- cone traversal (kd_cone_trav.c) ------------------------------------ */

/*
 * A traversal cone: apex, unit axis and half-angle, containing every sample
 * segment it stands for (the whole light, or one group of samples). The
 * float part drives the kd-tree walk, the double part the per-triangle cull.
 */
typedef struct kd_cone {
    float apex[3];
    float lo[3], hi[3]; /* slopes of the cone's extent along each world axis */
    float inv_lo[3], inv_nhi[3]; /* 1 / lo, -1 / hi */
    float band;         /* positional slack (apex rounding, triangle test) */
    float t_far;        /* axial reach: every segment ends before it */
    double dapex[3], axis[3];
    double cos_p, sin_p, tan_p; /* half-angle widened for the cull */
} kd_cone;

/* The cone of the frame's whole light (axis NULL) or the cone around axis
 * with half-angle asin(sin_a) from the frame's apex. */
void kd_cone_init(kd_cone *c, const kdr_scene *scene, const kd_shadow_frame *f,
                  const double *axis, double sin_a);

/* Leaf by leaf, front to back (kd_cone_walk_next returns NULL at the end). */
typedef struct kd_cone_item {
    uint32_t node;
    float tn, tf;
} kd_cone_item;

typedef struct kd_cone_walk {
    const kdr_scene *scene;
    const kd_cone *cone;
    kd_cone_item stack[KD_MAX_DEPTH + 2]; /* one push per level at most */
    int top;
    uint64_t visited; /* nodes entered so far */
} kd_cone_walk;

void kd_cone_walk_init(kd_cone_walk *w, const kdr_scene *scene, const kd_cone *c);
const struct kd_node *kd_cone_walk_next(kd_cone_walk *w);

typedef struct kd_cand_list {
    uint32_t *v;
    size_t n, cap;
} kd_cand_list;

#define KD_CONE_OVER 1 /* kd_cone_collect gave up: over its budget */

/* The sorted, distinct triangles of the leaves the cone reaches that may
 * touch a segment inside it. Returns KDR_OK, KDR_ENOMEM, or KD_CONE_OVER
 * once more than max_cands candidates or max_nodes nodes are reached (the
 * list is then incomplete). Adds the nodes visited to *nodes. */
int kd_cone_collect(const kdr_scene *scene, const kd_cone *c, kd_cand_list *cl,
                    size_t max_cands, uint64_t max_nodes, uint64_t *nodes);

/* ---- packets (kd_cone_packet.c) ------------------------------------------ */

/* Tests the n <= 8 rays lanes[0..n) against the candidates (any hit in each
 * ray's [tmin, tmax]); returns the mask of blocked lanes and sets *blocker
 * to the last triangle that blocked one. wide: use AVX2 (only when
 * kdr_cpu_has_avx2()). */
int kd_cone_packet_blocked(const kdr_scene *scene, const kdr_ray *const *lanes,
                           int n, const uint32_t *cands, size_t ncand,
                           uint32_t *blocker, int wide);

/* The n rays (n <= 8 with wide, <= 4 without) walk cone c together, testing
 * each leaf's triangles on the way; returns the mask of blocked lanes. When
 * more than max_nodes nodes would be needed the lanes still undecided are
 * returned in *open (they must be traced otherwise). */
int kd_cone_packet_walk(const kdr_scene *scene, const kd_cone *c,
                        const kdr_ray *const *lanes, int n, uint64_t max_nodes,
                        uint32_t *blocker, uint64_t *visited, int *open,
                        int wide);

#endif /* KD_CONE_H */
