/*
 * kd_frustum.h — the camera basis shared by kdr_camera_ray and the frustum
 * traversal (core/kd_frustum*.c). Not part of the public API.
 *
 * The basis is computed once per camera; kd_camera_dir then evaluates one
 * pixel's direction. kdr_camera_ray is defined as exactly these two steps,
 * so the frustum code, the tests and the Embree reference all trace the
 * same float rays.
 */
#ifndef KD_FRUSTUM_H
#define KD_FRUSTUM_H

#include <stddef.h>
#include <stdint.h>

#include "kdray.h"

typedef struct kd_camera_basis {
    float eye[3];
    float f[3], r[3], u[3]; /* forward, right, up: unit (up: nearly) */
    float h, a;             /* tan(fov_y/2), width/height */
    float w, hgt;           /* width, height as floats */
} kd_camera_basis;

/* Fills the basis of a camera that passed kdr_camera_validate. */
void kd_camera_basis_init(const kdr_camera *cam, kd_camera_basis *b);

/*
 * Direction of pixel (px, py); the operation order is the definition:
 *   sx = ((2 * (px + 0.5)) / w - 1) * h * a   (left to right)
 *   sy = (1 - (2 * (py + 0.5)) / hgt) * h
 *   d[i] = (f[i] + sx * r[i]) + sy * u[i]
 * sx depends on the column only and sy on the row only, so tile code may
 * tabulate them (kd_camera_sx, kd_camera_sy) and combine them later.
 */
static inline float kd_camera_sx(const kd_camera_basis *b, uint32_t px) {
    return ((2.0f * ((float)px + 0.5f)) / b->w - 1.0f) * b->h * b->a;
}
static inline float kd_camera_sy(const kd_camera_basis *b, uint32_t py) {
    return (1.0f - (2.0f * ((float)py + 0.5f)) / b->hgt) * b->h;
}
static inline void kd_camera_dir(const kd_camera_basis *b, uint32_t px,
                                 uint32_t py, float d[3]) {
    const float sx = kd_camera_sx(b, px), sy = kd_camera_sy(b, py);
    for (int i = 0; i < 3; i++)
        d[i] = (b->f[i] + sx * b->r[i]) + sy * b->u[i];
}

/*
 * Traces tiles [first, first+count) with interval frusta, `lanes` tiles
 * per traversal (1 or 4), rays in groups of 4 (SSE2) or 8 (AVX2: call
 * only when kdr_cpu_has_avx2()) (kd_frustum_trav.h). Arguments are checked
 * by the caller; returns KDR_OK or KDR_ENOMEM.
 */
int kd_frustum_trace_tiles4(const kdr_scene *s, const kdr_camera *cam,
                            const kd_camera_basis *b, uint32_t tile, size_t first,
                            size_t count, kdr_query q, int lanes, kdr_hits *out,
                            kdr_trav_stats *stats);
int kd_frustum_trace_tiles8(const kdr_scene *s, const kdr_camera *cam,
                            const kd_camera_basis *b, uint32_t tile, size_t first,
                            size_t count, kdr_query q, int lanes, kdr_hits *out,
                            kdr_trav_stats *stats);

#endif /* KD_FRUSTUM_H */
