/*
 * ab_sets.c — kdray_ab's ray-set generators (ab_sets.h): cameras, random
 * and hemisphere rays, lights, shadow and cone queries, closest-point
 * workloads, all from seeded tests/support/stress generators so that both
 * cores and Embree trace the same rays in every run.
 */
#define _POSIX_C_SOURCE 200809L
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "ab_sets.h"
#include "stress.h"

const char *const set_names[NSETS] = {"camera",  "random",  "ao",     "ao64",   "b8ao",
                                      "b8cam",   "frustum", "cone16", "cone64", "shadow",
                                      "camshadow",
                                      "brandom", "bao",     "baoc",   "bshadow", "bshadow16",
                                      "b16cam",  "conecam", "b8ao8",   "bao64",  "bao1",   "bcamlarge",
                                      "all16",   "all",     "count",  "closest", "ball16",
                                      "ball",    "bcount"};
const unsigned char set_embree[NSETS] = {1, 1, 1, 1, 0, 0, 0, 0, 0, 1, 1,
                                         1, 1, 1, 1, 1, 0, 0, 0, 1, 1, 1, 0, 0,
                                         0, 0, 0, 0, 0};

void scene_bounds(scene_in *s) {
    for (int k = 0; k < 3; k++)
        s->lo[k] = INFINITY, s->hi[k] = -INFINITY;
    for (size_t i = 0; i < 3 * s->ntris; i++) {
        const float *p = s->tris + 3 * i;
        for (int k = 0; k < 3; k++) {
            s->lo[k] = p[k] < s->lo[k] ? p[k] : s->lo[k];
            s->hi[k] = p[k] > s->hi[k] ? p[k] : s->hi[k];
        }
    }
    double d = 0;
    for (int k = 0; k < 3; k++)
        d += (double)(s->hi[k] - s->lo[k]) * (s->hi[k] - s->lo[k]);
    s->diag = (float)sqrt(d);
}

void camera_of(const scene_in *s, size_t n, kdr_camera *cam) {
    static const float view[3] = {0.55f, 0.35f, 0.75f};
    uint32_t side = (uint32_t)sqrt((double)n);
    memset(cam, 0, sizeof *cam);
    cam->up[1] = 1.0f;
    cam->fov_y_deg = 45.0f;
    cam->width = cam->height = side ? side : 1;
    for (int k = 0; k < 3; k++) {
        cam->target[k] = 0.5f * (s->lo[k] + s->hi[k]);
        cam->eye[k] = cam->target[k] + 1.1f * s->diag * view[k];
    }
}

size_t camera_rays(const kdr_camera *cam, int tiled, kdr_ray *out) {
    size_t i = 0;
    if (!tiled) {
        for (uint32_t y = 0; y < cam->height; y++)
            for (uint32_t x = 0; x < cam->width; x++)
                kdr_camera_ray(cam, x, y, &out[i++]);
        return i;
    }
    const uint32_t th = tiled == 2 ? 4 : 2; /* block height */
    for (uint32_t ty = 0; ty < cam->height; ty += th)
        for (uint32_t tx = 0; tx < cam->width; tx += 4)
            for (uint32_t k = 0; k < 4 * th; k++) {
                /* 4x2: two 2x2 quads side by side; 4x4: rows of 4 */
                const uint32_t px = th == 4 ? tx + (k & 3) : tx + (k & 1) + 2 * (k >> 2);
                const uint32_t py = th == 4 ? ty + (k >> 2) : ty + ((k >> 1) & 1);
                if (px < cam->width && py < cam->height)
                    kdr_camera_ray(cam, px, py, &out[i++]);
            }
    return i;
}

void random_rays(const scene_in *s, size_t n, kdr_ray *out) {
    stress_rng r;
    stress_rng_seed(&r, 7);
    for (size_t i = 0; i < n; i++) {
        for (int k = 0; k < 3; k++)
            out[i].org[k] = s->lo[k] + (s->hi[k] - s->lo[k]) * stress_rng_float(&r);
        stress_rng_dir(&r, out[i].dir);
        out[i].tmin = 0.0f;
        out[i].tmax = INFINITY;
    }
}

void ao_rays(const scene_in *s, size_t n, size_t per_point, kdr_ray *out) {
    const float reach = 0.1f * s->diag;
    stress_rng r;
    stress_rng_seed(&r, 7);
    float p[3] = {0, 0, 0}, nrm[3] = {0, 1, 0};
    for (size_t i = 0; i < n; i++) {
        if (i % per_point == 0)
            stress_tri_point(&r, s->tris + 9 * (stress_rng_next(&r) % s->ntris), p, nrm);
        float d[3];
        stress_rng_dir(&r, d);
        const float dot = d[0] * nrm[0] + d[1] * nrm[1] + d[2] * nrm[2];
        for (int k = 0; k < 3; k++) {
            out[i].org[k] = p[k];
            out[i].dir[k] = dot < 0 ? -d[k] : d[k];
        }
        out[i].tmin = 1e-4f * reach;
        out[i].tmax = reach;
    }
}

void light_of(const scene_in *s, int large, kdr_sphere_light *li) {
    static const float dir[3] = {-0.35f, 0.85f, 0.40f};
    const float dist = large ? 0.55f : 0.9f;
    for (int k = 0; k < 3; k++)
        li->center[k] = 0.5f * (s->lo[k] + s->hi[k]) + dist * s->diag * dir[k];
    li->radius = (large ? 0.25f : 0.03f) * s->diag;
}

void shadow_rays(const scene_in *s, size_t n, size_t per_point,
                 const kdr_sphere_light *li, kdr_ray *out) {
    ao_rays(s, n, per_point, out);
    stress_rng r;
    stress_rng_seed(&r, 11);
    for (size_t i = 0; i < n; i++) {
        float d[3];
        stress_rng_dir(&r, d);
        const float u = stress_rng_float(&r);
        for (int k = 0; k < 3; k++)
            out[i].dir[k] = li->center[k] + u * li->radius * d[k] - out[i].org[k];
        out[i].tmin = 1e-4f;
        out[i].tmax = 1.0f;
    }
}

void cone_query(const scene_in *s, size_t npts, int large, uint32_t spp,
                       kdr_ray *scratch, float *pts, kdr_sphere_light *li,
                       kdr_shadow_query *q) {
    light_of(s, large, li);
    float *nrm = pts + 3 * npts;
    ao_rays(s, npts, 1, scratch);
    size_t m = 0;
    for (size_t i = 0; i < npts; i++) {
        double d2 = 0;
        for (int k = 0; k < 3; k++) {
            const double d = scratch[i].org[k] - li->center[k];
            d2 += d * d;
        }
        if (d2 <= 1.01 * li->radius * li->radius)
            continue;
        for (int k = 0; k < 3; k++) {
            pts[3 * m + k] = scratch[i].org[k];
            nrm[3 * m + k] = scratch[i].dir[k]; /* the hemisphere side */
        }
        m++;
    }
    memmove(pts + 3 * m, nrm, 3 * m * sizeof(float));
    *q = (kdr_shadow_query){.n = m, .points = pts, .normals = pts + 3 * m,
                            .lights = li, .nlights = 1, .samples = spp,
                            .seed = 7, .offset = KDR_OFFSET_DIAGONAL,
                            .epsilon = 1e-4f};
}

/* The camera's hit at pixel (x, y): the point in p, the geometric normal
 * (unnormalised) turned toward the viewer in n; 0 where the ray misses. */
static int camera_hit(const scene_in *s, ab_intersect1_fn intersect1, const kdr_scene *kd,
                      const kdr_camera *cam, uint32_t x, uint32_t y, float p[3],
                      float n[3]) {
    kdr_ray r;
    kdr_hit h;
    kdr_camera_ray(cam, x, y, &r);
    if (!intersect1(kd, &r, &h, NULL))
        return 0;
    const float *t = s->tris + 9 * (size_t)h.prim;
    float e1[3], e2[3], dot = 0.0f;
    for (int k = 0; k < 3; k++) {
        p[k] = r.org[k] + h.t * r.dir[k];
        e1[k] = t[3 + k] - t[k], e2[k] = t[6 + k] - t[k];
    }
    n[0] = e1[1] * e2[2] - e1[2] * e2[1];
    n[1] = e1[2] * e2[0] - e1[0] * e2[2];
    n[2] = e1[0] * e2[1] - e1[1] * e2[0];
    for (int k = 0; k < 3; k++)
        dot += n[k] * r.dir[k];
    if (dot > 0.0f)
        for (int k = 0; k < 3; k++)
            n[k] = -n[k];
    return 1;
}

void conecam_query(const scene_in *s, ab_intersect1_fn intersect1, const kdr_scene *kd,
                   size_t max, float *pts, kdr_sphere_light *li, kdr_shadow_query *q) {
    kdr_camera cam;
    camera_of(s, max, &cam);
    light_of(s, 0, li);
    float *nrm = pts + 3 * max;
    size_t m = 0;
    for (uint32_t y = 0; y < cam.height; y++)
        for (uint32_t x = 0; x < cam.width; x++)
            if (camera_hit(s, intersect1, kd, &cam, x, y, pts + 3 * m, nrm + 3 * m))
                m++;
    memmove(pts + 3 * m, nrm, 3 * m * sizeof(float));
    *q = (kdr_shadow_query){.n = m, .points = pts, .normals = pts + 3 * m,
                            .lights = li, .nlights = 1, .samples = 64,
                            .seed = 7, .offset = KDR_OFFSET_DIAGONAL,
                            .epsilon = 1e-4f};
}

size_t camshadow_rays(const scene_in *s, ab_intersect1_fn intersect1, const kdr_scene *kd,
                      size_t max, const kdr_sphere_light *li, kdr_ray *out) {
    kdr_camera cam;
    camera_of(s, max, &cam);
    stress_rng r;
    stress_rng_seed(&r, 13);
    size_t m = 0;
    for (uint32_t y = 0; y < cam.height; y++)
        for (uint32_t x = 0; x < cam.width; x++) {
            float p[3], n[3], d[3], len = 0.0f;
            if (!camera_hit(s, intersect1, kd, &cam, x, y, p, n))
                continue;
            for (int k = 0; k < 3; k++)
                len += n[k] * n[k];
            const float off = 1e-4f * s->diag / sqrtf(len);
            stress_rng_dir(&r, d);
            const float u = stress_rng_float(&r);
            for (int k = 0; k < 3; k++) {
                out[m].org[k] = p[k] + off * n[k];
                out[m].dir[k] = li->center[k] + u * li->radius * d[k] - out[m].org[k];
            }
            out[m].tmin = 1e-4f;
            out[m].tmax = 1.0f;
            m++;
        }
    return m;
}

void closest_points(const scene_in *s, size_t n, float *pts) {
    stress_rng r;
    stress_rng_seed(&r, 7);
    for (size_t i = 0; i < n; i++) {
        float *p = pts + 3 * i;
        if (i % 2) {
            for (int k = 0; k < 3; k++)
                p[k] = s->lo[k] + (s->hi[k] - s->lo[k]) * stress_rng_float(&r);
            continue;
        }
        const float *t = s->tris + 9 * (stress_rng_next(&r) % s->ntris);
        float a = stress_rng_float(&r), b = stress_rng_float(&r);
        if (a + b > 1.0f)
            a = 1.0f - a, b = 1.0f - b;
        for (int k = 0; k < 3; k++)
            p[k] = (1 - a - b) * t[k] + a * t[3 + k] + b * t[6 + k] +
                   1e-3f * s->diag * (stress_rng_float(&r) - 0.5f);
    }
}
