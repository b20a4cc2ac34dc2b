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

#endif /* KD_CONE_H */
