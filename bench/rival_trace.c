/*
 * rival_trace.c — every timed Embree call of the benchmarks (rival.h):
 * ray sets (converted before timing), a camera's image and cone-shadow
 * visibility (rays generated inside the timed call, as kdray's own timed
 * work generates them).
 *
 * Ray conversion is written once. Embree's packet structs RTCRayHit4/8/16
 * are the same 20 four-byte fields, each an array of K lanes, and RTCRayK
 * is their first 12 (the static asserts below hold that), so one function
 * fills lane j of a packet of any width; single rays and streams use
 * struct RTCRayHit. Any-hit work gets the ray alone (RTCRay, RTCRayK:
 * 48 bytes a ray instead of 80), as a user tracing shadow rays would.
 */
#define _POSIX_C_SOURCE 200809L
#include "rival.h"

#include <math.h>
#include <stddef.h>
#include <stdlib.h>
#include <string.h>

#include "kd_cone.h"
#include "kd_frustum.h"

/* ---- Embree's structs ---------------------------------------------------------- */

enum { F_ORG = 0, F_TNEAR = 3, F_DIR = 4, F_TIME = 7, F_TFAR = 8, F_MASK = 9,
       F_ID = 10, F_FLAGS = 11, F_RAY = 12, F_U = 15, F_V = 16, F_PRIM = 17,
       F_GEOM = 18, F_INST = 19, F_COUNT = 20 };

#define PACKET_LAYOUT(K)                                                              \
    _Static_assert(sizeof(struct RTCRayHit##K) == F_COUNT * 4 * K, "RTCRayHit" #K);   \
    _Static_assert(offsetof(struct RTCRayHit##K, ray.tfar) == F_TFAR * 4 * K, "tfar"); \
    _Static_assert(offsetof(struct RTCRayHit##K, hit.u) == F_U * 4 * K, "u");         \
    _Static_assert(offsetof(struct RTCRayHit##K, hit.primID) == F_PRIM * 4 * K, "p"); \
    _Static_assert(offsetof(struct RTCRayHit##K, hit.instID) == F_INST * 4 * K, "i"); \
    _Static_assert(sizeof(struct RTCRay##K) == F_RAY * 4 * K, "RTCRay" #K)
PACKET_LAYOUT(4);
PACKET_LAYOUT(8);
PACKET_LAYOUT(16);

static uint32_t fbits(float f) {
    uint32_t u;
    memcpy(&u, &f, 4);
    return u;
}

static float bitsf(uint32_t u) {
    float f;
    memcpy(&f, &u, 4);
    return f;
}

/* Four-byte words per lane: the ray alone for any hit, ray and hit else. */
static size_t lane_words(kdr_query q) { return q == KDR_ANY ? F_RAY : F_COUNT; }

/* Lane j of a K-wide packet (p: lane_words(q) * K words). */
static void packet_put(uint32_t *p, int K, int j, kdr_query q, const kdr_ray *r) {
    for (int k = 0; k < 3; k++) {
        p[(F_ORG + k) * K + j] = fbits(r->org[k]);
        p[(F_DIR + k) * K + j] = fbits(r->dir[k]);
    }
    p[F_TNEAR * K + j] = fbits(r->tmin);
    p[F_TFAR * K + j] = fbits(r->tmax);
    p[F_TIME * K + j] = fbits(0.0f);
    p[F_MASK * K + j] = 0xFFFFFFFFu;
    p[F_ID * K + j] = (uint32_t)j;
    p[F_FLAGS * K + j] = 0;
    if (q == KDR_ANY)
        return;
    p[F_GEOM * K + j] = RTC_INVALID_GEOMETRY_ID;
    p[F_INST * K + j] = RTC_INVALID_GEOMETRY_ID;
}

/* Single rays and streams: arrays of struct RTCRay (any) or RTCRayHit. */
static size_t single_bytes(kdr_query q) {
    return q == KDR_ANY ? sizeof(struct RTCRay) : sizeof(struct RTCRayHit);
}

static struct RTCRay *single_at(void *base, size_t i, kdr_query q) {
    return (struct RTCRay *)((char *)base + i * single_bytes(q));
}

static void single_put(void *base, size_t i, kdr_query q, const kdr_ray *r) {
    struct RTCRay *ray = single_at(base, i, q);
    ray->org_x = r->org[0], ray->org_y = r->org[1], ray->org_z = r->org[2];
    ray->dir_x = r->dir[0], ray->dir_y = r->dir[1], ray->dir_z = r->dir[2];
    ray->tnear = r->tmin, ray->tfar = r->tmax, ray->time = 0.0f;
    ray->mask = 0xFFFFFFFFu, ray->id = 0, ray->flags = 0;
    if (q == KDR_ANY)
        return;
    struct RTCRayHit *h = (struct RTCRayHit *)ray;
    h->hit.geomID = RTC_INVALID_GEOMETRY_ID;
    h->hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
}

/* Answer of lane j: 1 if hit (closest) or occluded (any). */
static int packet_hit(const uint32_t *p, int K, int j, kdr_query q) {
    if (q == KDR_ANY)
        return bitsf(p[F_TFAR * K + j]) == -INFINITY;
    return p[F_GEOM * K + j] != RTC_INVALID_GEOMETRY_ID;
}

static int single_hit(void *base, size_t i, kdr_query q) {
    const struct RTCRay *ray = single_at(base, i, q);
    return q == KDR_ANY ? ray->tfar == -INFINITY
                        : ((const struct RTCRayHit *)ray)->hit.geomID !=
                              RTC_INVALID_GEOMETRY_ID;
}

/* Every lane valid; Embree wants the mask as aligned as the packet. */
static _Alignas(64) const int g_all_valid[16] = {-1, -1, -1, -1, -1, -1, -1, -1,
                                                 -1, -1, -1, -1, -1, -1, -1, -1};

static void init_context(struct RTCIntersectContext *ctx, rival_api api) {
    rtcInitIntersectContext(ctx);
    ctx->flags = api.coherent ? RTC_INTERSECT_CONTEXT_FLAG_COHERENT
                              : RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT;
}

/* One packet call of width K. */
static void packet_call(RTCScene sc, struct RTCIntersectContext *ctx, int K,
                        kdr_query q, const int *valid, uint32_t *p) {
    switch (K) {
    case 4:
        if (q == KDR_ANY)
            rtcOccluded4(valid, sc, ctx, (struct RTCRay4 *)p);
        else
            rtcIntersect4(valid, sc, ctx, (struct RTCRayHit4 *)p);
        break;
    case 8:
        if (q == KDR_ANY)
            rtcOccluded8(valid, sc, ctx, (struct RTCRay8 *)p);
        else
            rtcIntersect8(valid, sc, ctx, (struct RTCRayHit8 *)p);
        break;
    default:
        if (q == KDR_ANY)
            rtcOccluded16(valid, sc, ctx, (struct RTCRay16 *)p);
        else
            rtcIntersect16(valid, sc, ctx, (struct RTCRayHit16 *)p);
    }
}

static void single_call(RTCScene sc, struct RTCIntersectContext *ctx, kdr_query q,
                        void *base, size_t i) {
    if (q == KDR_ANY)
        rtcOccluded1(sc, ctx, single_at(base, i, q));
    else
        rtcIntersect1(sc, ctx, (struct RTCRayHit *)single_at(base, i, q));
}

static void stream_call(RTCScene sc, struct RTCIntersectContext *ctx, kdr_query q,
                        void *base, size_t n) {
    if (q == KDR_ANY)
        rtcOccluded1M(sc, ctx, base, (unsigned)n, single_bytes(q));
    else
        rtcIntersect1M(sc, ctx, base, (unsigned)n, single_bytes(q));
}

static size_t api_bytes(rival_api api, kdr_query q, size_t n) {
    if (api.width <= 1)
        return n * single_bytes(q);
    const size_t K = (size_t)api.width;
    return (n + K - 1) / K * lane_words(q) * 4 * K;
}

static void *alloc_aligned(size_t bytes) {
    return aligned_alloc(64, (bytes + 63) / 64 * 64);
}

/* ---- ray sets ------------------------------------------------------------------ */

int rival_job_init(rival_job *j, const rival *r, rival_api api, kdr_query q,
                   const kdr_ray *rays, size_t n) {
    memset(j, 0, sizeof *j);
    j->r = r, j->api = api, j->query = q, j->rays = rays, j->n = n;
    rival_api_name(r, api, q, j->name, sizeof j->name);
    j->buf = alloc_aligned(api_bytes(api, q, n ? n : 1));
    j->valid_last = alloc_aligned(16 * sizeof(int));
    if (!j->buf || !j->valid_last) {
        rival_job_free(j);
        return -1;
    }
    const int K = api.width > 1 ? api.width : 1;
    const size_t tail = n % (size_t)K ? n % (size_t)K : (size_t)K;
    for (int l = 0; l < 16; l++)
        j->valid_last[l] = (size_t)l < tail ? -1 : 0;
    return 0;
}

void rival_job_free(rival_job *j) {
    free(j->buf);
    free(j->valid_last);
    j->buf = NULL, j->valid_last = NULL;
}

static void job_convert(void *ctx) {
    rival_job *j = ctx;
    if (j->api.width <= 1) {
        for (size_t i = 0; i < j->n; i++)
            single_put(j->buf, i, j->query, &j->rays[i]);
        return;
    }
    const size_t K = (size_t)j->api.width, words = lane_words(j->query) * K;
    uint32_t *p = j->buf;
    const size_t np = (j->n + K - 1) / K;
    for (size_t i = 0; i < np * K; i++) /* idle lanes repeat the last ray */
        packet_put(p + i / K * words, (int)K, (int)(i % K), j->query,
                   &j->rays[i < j->n ? i : j->n - 1]);
}

static void job_trace(void *ctx) {
    rival_job *j = ctx;
    RTCScene sc = rival_rtc_scene(j->r);
    struct RTCIntersectContext c;
    init_context(&c, j->api);
    if (j->api.width == RIVAL_STREAM) {
        stream_call(sc, &c, j->query, j->buf, j->n);
    } else if (j->api.width == 1) {
        for (size_t i = 0; i < j->n; i++)
            single_call(sc, &c, j->query, j->buf, i);
    } else {
        const size_t K = (size_t)j->api.width, np = (j->n + K - 1) / K;
        const size_t words = lane_words(j->query) * K;
        uint32_t *p = j->buf;
        for (size_t k = 0; k < np; k++)
            packet_call(sc, &c, (int)K, j->query,
                        k + 1 < np ? g_all_valid : j->valid_last, p + k * words);
    }
}

bench_method rival_job_method(rival_job *j) {
    return (bench_method){j->name, BENCH_RIVAL, job_convert, job_trace, j, 0.0};
}

void rival_job_answers(const rival_job *j, uint8_t *hit, int32_t *prim) {
    for (size_t i = 0; i < j->n; i++) {
        int h;
        uint32_t p;
        if (j->api.width <= 1) {
            h = single_hit(j->buf, i, j->query);
            p = h && j->query == KDR_CLOSEST
                    ? ((const struct RTCRayHit *)j->buf)[i].hit.primID : 0;
        } else {
            const size_t K = (size_t)j->api.width;
            const uint32_t *pk = (const uint32_t *)j->buf + i / K * lane_words(j->query) * K;
            h = packet_hit(pk, (int)K, (int)(i % K), j->query);
            p = j->query == KDR_CLOSEST ? pk[F_PRIM * K + i % K] : 0;
        }
        hit[i] = (uint8_t)h;
        if (prim)
            prim[i] = h && j->query == KDR_CLOSEST ? (int32_t)p : -1;
    }
}

/* ---- a camera's image ---------------------------------------------------------- */

int rival_camera_job_init(rival_camera_job *j, const rival *r, rival_api api,
                          const kdr_camera *cam, kdr_hits out) {
    memset(j, 0, sizeof *j);
    j->r = r, j->api = api, j->cam = cam, j->out = out, j->trace = 1;
    rival_api_name(r, api, KDR_CLOSEST, j->name, sizeof j->name);
    const size_t pixels = (size_t)cam->width * cam->height;
    j->buf = alloc_aligned(
        api_bytes(api, KDR_CLOSEST, api.width == RIVAL_STREAM ? pixels : 16));
    j->sx = malloc(cam->width * sizeof *j->sx);
    j->sy = malloc(cam->height * sizeof *j->sy);
    if (!j->buf || !j->sx || !j->sy || cam->width % 4 || cam->height % 4) {
        rival_camera_job_free(j);
        return -1;
    }
    return 0;
}

void rival_camera_job_free(rival_camera_job *j) {
    free(j->buf), free(j->sx), free(j->sy);
    j->buf = j->sx = j->sy = NULL;
}

/* Pixel k (0..15) of a 4x4 tile in Z-order: 2x2 quads, left to right,
 * top to bottom, so lanes 0-3 / 0-7 / 0-15 are a 2x2 / 4x2 / 4x4 block. */
static void tile_pixel(int k, uint32_t *dx, uint32_t *dy) {
    *dx = (uint32_t)((k & 1) | ((k >> 1) & 2));
    *dy = (uint32_t)(((k >> 1) & 1) | ((k >> 2) & 2));
}

static void camera_put(const rival_camera_job *j, const kd_camera_basis *b,
                       uint32_t px, uint32_t py, kdr_ray *ray) {
    const float sx = j->sx[px], sy = j->sy[py];
    for (int i = 0; i < 3; i++) /* kd_camera_dir's operations, in its order */
        ray->dir[i] = (b->f[i] + sx * b->r[i]) + sy * b->u[i];
}

static void camera_out(const rival_camera_job *j, size_t pix, int hit, float t,
                       uint32_t prim, float u, float v) {
    j->out.t[pix] = hit ? t : -1.0f;
    j->out.prim[pix] = hit ? (int32_t)prim : -1;
    j->out.u[pix] = hit ? u : 0.0f;
    j->out.v[pix] = hit ? v : 0.0f;
}

/* Generates (and traces) one 4x4 tile with packets of K (4, 8, 16) or
 * single rays (K = 1). */
static void camera_tile(rival_camera_job *j, const kd_camera_basis *b,
                        struct RTCIntersectContext *c, uint32_t x0, uint32_t y0,
                        kdr_ray *ray) {
    RTCScene sc = rival_rtc_scene(j->r);
    const uint32_t w = j->cam->width;
    const int K = j->api.width;
    for (int k0 = 0; k0 < 16; k0 += K) {
        uint32_t *p = j->buf;
        struct RTCRayHit *h = j->buf;
        for (int k = k0; k < k0 + K; k++) {
            uint32_t dx, dy;
            tile_pixel(k, &dx, &dy);
            camera_put(j, b, x0 + dx, y0 + dy, ray);
            if (K == 1)
                single_put(h, 0, KDR_CLOSEST, ray);
            else
                packet_put(p, K, k - k0, KDR_CLOSEST, ray);
        }
        if (!j->trace)
            continue;
        if (K == 1)
            single_call(sc, c, KDR_CLOSEST, h, 0);
        else
            packet_call(sc, c, K, KDR_CLOSEST, g_all_valid, p);
        for (int k = k0; k < k0 + K; k++) {
            uint32_t dx, dy;
            tile_pixel(k, &dx, &dy);
            const size_t pix = (size_t)(y0 + dy) * w + x0 + dx;
            if (K == 1) {
                camera_out(j, pix, single_hit(h, 0, KDR_CLOSEST), h->ray.tfar,
                           h->hit.primID, h->hit.u, h->hit.v);
            } else {
                const int l = k - k0;
                camera_out(j, pix, packet_hit(p, K, l, KDR_CLOSEST),
                           bitsf(p[F_TFAR * K + l]), p[F_PRIM * K + l],
                           bitsf(p[F_U * K + l]), bitsf(p[F_V * K + l]));
            }
        }
    }
}

/* The whole image as one stream, in tile order. */
static void camera_stream(rival_camera_job *j, const kd_camera_basis *b,
                          struct RTCIntersectContext *c, kdr_ray *ray) {
    struct RTCRayHit *h = j->buf;
    const uint32_t w = j->cam->width, hgt = j->cam->height;
    size_t i = 0;
    for (uint32_t y0 = 0; y0 < hgt; y0 += 4)
        for (uint32_t x0 = 0; x0 < w; x0 += 4)
            for (int k = 0; k < 16; k++, i++) {
                uint32_t dx, dy;
                tile_pixel(k, &dx, &dy);
                camera_put(j, b, x0 + dx, y0 + dy, ray);
                single_put(h, i, KDR_CLOSEST, ray);
            }
    if (j->trace)
        stream_call(rival_rtc_scene(j->r), c, KDR_CLOSEST, h, i);
    i = 0;
    for (uint32_t y0 = 0; y0 < hgt; y0 += 4)
        for (uint32_t x0 = 0; x0 < w; x0 += 4)
            for (int k = 0; k < 16; k++, i++) {
                uint32_t dx, dy;
                tile_pixel(k, &dx, &dy);
                camera_out(j, (size_t)(y0 + dy) * w + x0 + dx,
                           single_hit(h, i, KDR_CLOSEST), h[i].ray.tfar,
                           h[i].hit.primID, h[i].hit.u, h[i].hit.v);
            }
}

static void camera_run(void *ctx) {
    rival_camera_job *j = ctx;
    kd_camera_basis b;
    kd_camera_basis_init(j->cam, &b);
    for (uint32_t x = 0; x < j->cam->width; x++)
        j->sx[x] = kd_camera_sx(&b, x);
    for (uint32_t y = 0; y < j->cam->height; y++)
        j->sy[y] = kd_camera_sy(&b, y);
    struct RTCIntersectContext c;
    init_context(&c, j->api);
    kdr_ray ray = {{b.eye[0], b.eye[1], b.eye[2]}, {0, 0, 0}, 0.0f, INFINITY};
    if (j->api.width == RIVAL_STREAM) {
        camera_stream(j, &b, &c, &ray);
        return;
    }
    for (uint32_t y0 = 0; y0 < j->cam->height; y0 += 4)
        for (uint32_t x0 = 0; x0 < j->cam->width; x0 += 4)
            camera_tile(j, &b, &c, x0, y0, &ray);
}

bench_method rival_camera_job_method(rival_camera_job *j) {
    return (bench_method){j->name, BENCH_RIVAL, NULL, camera_run, j, 0.0};
}

/* ---- cone-shadow visibility ---------------------------------------------------- */

/* Rays per rtcOccluded1M call: a chunk of consecutive samples, small
 * enough to stay in cache while Embree walks it. */
#define SHADOW_STREAM_CHUNK 1024

static size_t shadow_capacity(rival_api api) {
    return api.width == RIVAL_STREAM ? SHADOW_STREAM_CHUNK : (size_t)api.width;
}

int rival_shadow_job_init(rival_shadow_job *j, const rival *r, rival_api api,
                          const kdr_scene *kd, const kdr_shadow_query *q,
                          float *vis) {
    memset(j, 0, sizeof *j);
    j->r = r, j->api = api, j->kd = kd, j->q = q, j->vis = vis, j->trace = 1;
    rival_api_name(r, api, KDR_ANY, j->name, sizeof j->name);
    j->buf = alloc_aligned(api_bytes(api, KDR_ANY, shadow_capacity(api)));
    j->owner = malloc(shadow_capacity(api) * sizeof *j->owner);
    if (!j->buf || !j->owner) {
        rival_shadow_job_free(j);
        return -1;
    }
    return 0;
}

void rival_shadow_job_free(rival_shadow_job *j) {
    free(j->buf);
    free(j->owner);
    j->buf = NULL, j->owner = NULL;
}

/* Traces the batch's first `used` slots; slot k belongs to pair owner[k],
 * and vis[pair] counts the lit samples until shadow_run scales it. */
static void shadow_flush(rival_shadow_job *j, struct RTCIntersectContext *c,
                         size_t used) {
    RTCScene sc = rival_rtc_scene(j->r);
    const int K = j->api.width;
    if (!j->trace)
        return;
    if (K <= 1) {
        if (K == 1)
            single_call(sc, c, KDR_ANY, j->buf, 0);
        else
            stream_call(sc, c, KDR_ANY, j->buf, used);
        for (size_t k = 0; k < used; k++)
            j->vis[j->owner[k]] += single_hit(j->buf, k, KDR_ANY) ? 0.0f : 1.0f;
        return;
    }
    _Alignas(64) int valid[16];
    for (int l = 0; l < K; l++)
        valid[l] = (size_t)l < used ? -1 : 0;
    uint32_t *p = j->buf;
    packet_call(sc, c, K, KDR_ANY, (size_t)K == used ? g_all_valid : valid, p);
    for (size_t l = 0; l < used; l++)
        j->vis[j->owner[l]] += packet_hit(p, K, (int)l, KDR_ANY) ? 0.0f : 1.0f;
}

static void shadow_run(void *ctx) {
    rival_shadow_job *j = ctx;
    const kdr_shadow_query *q = j->q;
    const size_t pairs = q->n * q->nlights, cap = shadow_capacity(j->api);
    struct RTCIntersectContext c;
    init_context(&c, j->api);
    size_t used = 0;
    for (size_t o = 0; o < pairs; o++)
        j->vis[o] = 0.0f;
    for (size_t i = 0; i < q->n; i++) {
        for (size_t l = 0; l < q->nlights; l++) {
            const size_t o = i * q->nlights + l;
            kd_shadow_frame f;
            if (kd_shadow_frame_init(j->kd, q, i, l, &f) != KDR_OK) {
                j->failed = 1;
                continue;
            }
            kdr_ray rays[64];
            for (uint32_t s = 0; s < q->samples; s++) {
                /* the sampler's batch form, as kdray's own paths use it
                 * (bench/compare builds this file against older cores
                 * too: those, without KD_SHADOW_MAX_SAMPLES, have only
                 * the one-sample form) */
#ifdef KD_SHADOW_MAX_SAMPLES
                if (s % 64 == 0)
                    kd_shadow_frame_rays(&f, NULL, s, q->samples - s < 64 ? q->samples - s : 64,
                                         q->samples, rays);
#else
                kd_shadow_frame_ray(&f, s, q->samples, &rays[s % 64]);
#endif
                const kdr_ray *ray = &rays[s % 64];
                if (j->api.width <= 1)
                    single_put(j->buf, used, KDR_ANY, ray);
                else
                    packet_put(j->buf, j->api.width, (int)used, KDR_ANY, ray);
                j->owner[used++] = o;
                if (used == cap) {
                    shadow_flush(j, &c, used);
                    used = 0;
                }
            }
        }
    }
    if (used)
        shadow_flush(j, &c, used);
    const float scale = 1.0f / (float)q->samples;
    for (size_t o = 0; o < pairs; o++)
        j->vis[o] *= scale;
}

bench_method rival_shadow_job_method(rival_shadow_job *j) {
    return (bench_method){j->name, BENCH_RIVAL, NULL, shadow_run, j, 0.0};
}

int rival_shadow_job_once(rival_shadow_job *j) {
    const rival_fp fp = rival_fp_enter();
    shadow_run(j);
    rival_fp_leave(fp);
    return j->failed ? -1 : 0;
}
