/*
 * kd_frustum.c — the camera (kdr_camera_validate, kdr_camera_ray) and the
 * frustum query entry point kdr_frustum_trace: the image is cut into
 * tile x tile tiles in row-major tile order, and each tile's primary rays
 * are answered with results equal to tracing every pixel's ray alone.
 */
#include <math.h>
#include <stddef.h>

#include "kd_frustum.h"
#include "kd_internal.h"

#define KD_TILE_MIN 4u
#define KD_TILE_MAX 64u
/* Images are at most this many pixels (KDR_ERANGE beyond): the traversal
 * keeps pixel indices in int32 lanes. */
#define KD_MAX_PIXELS 0x7fffffffull
/* pi / 360: turns fov_y in degrees into the half angle in radians */
#define KD_HALF_DEG_TO_RAD 0.008726646259971647884618453842443

static int finite3(const float v[3]) {
    return isfinite(v[0]) && isfinite(v[1]) && isfinite(v[2]);
}

static void cross3(const float a[3], const float b[3], float out[3]) {
    out[0] = a[1] * b[2] - a[2] * b[1];
    out[1] = a[2] * b[0] - a[0] * b[2];
    out[2] = a[0] * b[1] - a[1] * b[0];
}

static float len3(const float v[3]) {
    return sqrtf((v[0] * v[0] + v[1] * v[1]) + v[2] * v[2]);
}

/* Divides by the length; returns 0 (v untouched) when it is not positive
 * and finite, which is how validation detects degenerate bases. */
static int normalize3(float v[3]) {
    const float len = len3(v);
    if (!(len > 0.0f) || !isfinite(len))
        return 0;
    v[0] = v[0] / len;
    v[1] = v[1] / len;
    v[2] = v[2] / len;
    return 1;
}

/* Builds f and r; 0 if eye == target or up is parallel to the view. */
static int camera_frame(const kdr_camera *cam, float f[3], float r[3]) {
    for (int i = 0; i < 3; i++)
        f[i] = cam->target[i] - cam->eye[i];
    if (!normalize3(f))
        return 0;
    cross3(f, cam->up, r);
    return normalize3(r);
}

int kdr_camera_validate(const kdr_camera *cam) {
    float f[3], r[3];
    if (!cam || !finite3(cam->eye) || !finite3(cam->target) || !finite3(cam->up))
        return KDR_EINVAL;
    if (!(cam->fov_y_deg > 0.0f && cam->fov_y_deg < 180.0f))
        return KDR_EINVAL;
    if (cam->width < 1 || cam->height < 1)
        return KDR_EINVAL;
    if (!camera_frame(cam, f, r))
        return KDR_EINVAL;
    return KDR_OK;
}

void kd_camera_basis_init(const kdr_camera *cam, kd_camera_basis *b) {
    camera_frame(cam, b->f, b->r);
    cross3(b->r, b->f, b->u);
    for (int i = 0; i < 3; i++)
        b->eye[i] = cam->eye[i];
    b->h = (float)tan((double)cam->fov_y_deg * KD_HALF_DEG_TO_RAD);
    b->w = (float)cam->width;
    b->hgt = (float)cam->height;
    b->a = b->w / b->hgt;
}

void kdr_camera_ray(const kdr_camera *cam, uint32_t px, uint32_t py,
                    kdr_ray *out) {
    kd_camera_basis b;
    kd_camera_basis_init(cam, &b);
    for (int i = 0; i < 3; i++)
        out->org[i] = b.eye[i];
    kd_camera_dir(&b, px, py, out->dir);
    out->tmin = 0.0f;
    out->tmax = INFINITY;
}

void kdr_camera_row_dirs(const kdr_camera *cam, uint32_t py, uint32_t x0,
                         uint32_t n, float *dirs) {
    kd_camera_basis b;
    kd_camera_basis_init(cam, &b);
    for (uint32_t i = 0; i < n; i++)
        kd_camera_dir(&b, x0 + i, py, dirs + 3 * (size_t)i);
}

size_t kdr_frustum_tile_count(const kdr_camera *cam, uint32_t tile) {
    if (!cam || tile == 0)
        return 0;
    const size_t tx = ((size_t)cam->width + tile - 1) / tile;
    const size_t ty = ((size_t)cam->height + tile - 1) / tile;
    return tx * ty;
}

/* Reference mode: each pixel of tile k through the single-ray traversal. */
static void trace_tile_rays(const kdr_scene *scene, const kdr_camera *cam,
                            const kd_camera_basis *b, uint32_t tile, size_t k,
                            kdr_query query, kdr_hits *out,
                            kdr_trav_stats *stats) {
    const size_t tiles_x = ((size_t)cam->width + tile - 1) / tile;
    const uint32_t x0 = (uint32_t)(k % tiles_x) * tile;
    const uint32_t y0 = (uint32_t)(k / tiles_x) * tile;
    const uint32_t x1 = x0 + tile < cam->width ? x0 + tile : cam->width;
    const uint32_t y1 = y0 + tile < cam->height ? y0 + tile : cam->height;
    kdr_ray ray = {.org = {b->eye[0], b->eye[1], b->eye[2]},
                   .tmin = 0.0f, .tmax = INFINITY};
    for (uint32_t py = y0; py < y1; py++) {
        for (uint32_t px = x0; px < x1; px++) {
            const size_t i = (size_t)py * cam->width + px;
            kd_camera_dir(b, px, py, ray.dir);
            if (query == KDR_ANY) {
                out->hit[i] = (uint8_t)kdr_occluded1(scene, &ray, stats);
            } else {
                kdr_hit h;
                kdr_intersect1(scene, &ray, &h, stats);
                out->t[i] = h.t;
                out->prim[i] = h.prim;
                out->u[i] = h.u;
                out->v[i] = h.v;
            }
        }
    }
}

static int check_args(const kdr_scene *scene, const kdr_camera *cam,
                      uint32_t tile, size_t first_tile, size_t count,
                      kdr_query query, kdr_frustum_mode mode,
                      const kdr_hits *out) {
    if (!scene || !out || kdr_camera_validate(cam) != KDR_OK)
        return KDR_EINVAL;
    if (tile < KD_TILE_MIN || tile > KD_TILE_MAX)
        return KDR_EINVAL;
    if (query != KDR_CLOSEST && query != KDR_ANY)
        return KDR_EINVAL;
    if (mode != KDR_FRUSTUM_MULTI4 && mode != KDR_FRUSTUM_SINGLE &&
        mode != KDR_FRUSTUM_RAYS)
        return KDR_EINVAL;
    if ((unsigned long long)cam->width * cam->height > KD_MAX_PIXELS)
        return KDR_ERANGE;
    const size_t ntiles = kdr_frustum_tile_count(cam, tile);
    if (first_tile > ntiles || count > ntiles - first_tile)
        return KDR_EINVAL;
    if (query == KDR_ANY ? !out->hit
                         : (!out->t || !out->prim || !out->u || !out->v))
        return KDR_EINVAL;
    return KDR_OK;
}

int kdr_frustum_trace(const kdr_scene *scene, const kdr_camera *cam,
                      uint32_t tile, size_t first_tile, size_t count,
                      kdr_query query, kdr_frustum_mode mode, kdr_hits *out,
                      kdr_trav_stats *stats) {
    const int rc = check_args(scene, cam, tile, first_tile, count, query, mode, out);
    if (rc != KDR_OK)
        return rc;
    kd_camera_basis b;
    kd_camera_basis_init(cam, &b);
    if (mode != KDR_FRUSTUM_RAYS) {
        const int lanes = mode == KDR_FRUSTUM_MULTI4 ? 4 : 1;
        return (kdr_cpu_has_avx2() ? kd_frustum_trace_tiles8 : kd_frustum_trace_tiles4)(
            scene, cam, &b, tile, first_tile, count, query, lanes, out, stats);
    }
    for (size_t k = first_tile; k < first_tile + count; k++)
        trace_tile_rays(scene, cam, &b, tile, k, query, out, stats);
    return KDR_OK;
}
