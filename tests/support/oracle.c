/*
 * oracle.c — builds one Embree device + scene per oracle and converts rays
 * and hits between kdray's structs and Embree's. The vertex and index
 * buffers come from rtcSetNewGeometryBuffer, which over-allocates so that
 * Embree's 16-byte vector loads past the last vertex stay inside the buffer
 * (the padding DEPS-NOTES asks for with shared buffers).
 */
#define _POSIX_C_SOURCE 200809L
#include "oracle.h"
#include "kd_traverse.h"

#include <math.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

struct oracle {
    RTCDevice device;
    RTCScene scene;
    double build_ms, build_cpu_ms;
    _Atomic int64_t bytes; /* updated by Embree's memory monitor */
};

void oracle_opts_default(oracle_opts *opts) {
    opts->robust = 1;
    opts->quality = RTC_BUILD_QUALITY_HIGH;
    opts->device_config = NULL;
    opts->context_filter = 0;
}

void oracle_opts_judge(oracle_opts *opts) {
    oracle_opts_default(opts);
    opts->device_config = ORACLE_JUDGE_CONFIG;
}

static double clock_ms(clockid_t id) {
    struct timespec ts;
    clock_gettime(id, &ts);
    return (double)ts.tv_sec * 1e3 + (double)ts.tv_nsec * 1e-6;
}

static void on_error(void *user, enum RTCError code, const char *msg) {
    (void)user;
    fprintf(stderr, "embree error %d: %s\n", (int)code, msg ? msg : "");
}

static bool on_memory(void *user, ssize_t bytes, bool post) {
    oracle *o = user;
    (void)post;
    atomic_fetch_add(&o->bytes, (int64_t)bytes);
    return true;
}

/* One triangle geometry with its own 3 vertices per triangle, so that
 * primID i is exactly triangle i of the caller's array. */
static int attach_triangles(oracle *o, const float *tris, size_t ntris,
                            enum RTCBuildQuality quality) {
    RTCGeometry g = rtcNewGeometry(o->device, RTC_GEOMETRY_TYPE_TRIANGLE);
    if (!g)
        return -1;
    rtcSetGeometryBuildQuality(g, quality);
    float *v = rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0,
                                       RTC_FORMAT_FLOAT3, 3 * sizeof(float),
                                       3 * ntris);
    unsigned *idx = rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_INDEX, 0,
                                            RTC_FORMAT_UINT3,
                                            3 * sizeof(unsigned), ntris);
    if (!v || !idx) {
        rtcReleaseGeometry(g);
        return -1;
    }
    if (ntris)
        memcpy(v, tris, 9 * ntris * sizeof(float));
    for (size_t i = 0; i < 3 * ntris; i++)
        idx[i] = (unsigned)i;
    rtcCommitGeometry(g);
    rtcAttachGeometryByID(o->scene, g, 0);
    rtcReleaseGeometry(g);
    return 0;
}

oracle *oracle_create(const float *tris, size_t ntris, const oracle_opts *opts) {
    oracle_opts def;
    if (!opts) {
        oracle_opts_default(&def);
        opts = &def;
    }
    oracle *o = calloc(1, sizeof *o);
    if (!o)
        return NULL;
    atomic_init(&o->bytes, 0);
    o->device = rtcNewDevice(opts->device_config);
    if (!o->device) {
        fprintf(stderr, "oracle: rtcNewDevice failed\n");
        free(o);
        return NULL;
    }
    rtcSetDeviceErrorFunction(o->device, on_error, NULL);
    rtcSetDeviceMemoryMonitorFunction(o->device, on_memory, o);
    o->scene = rtcNewScene(o->device);
    rtcSetSceneFlags(o->scene,
                     (opts->robust ? RTC_SCENE_FLAG_ROBUST : RTC_SCENE_FLAG_NONE) |
                         (opts->context_filter ? RTC_SCENE_FLAG_CONTEXT_FILTER_FUNCTION
                                               : RTC_SCENE_FLAG_NONE));
    rtcSetSceneBuildQuality(o->scene, opts->quality);
    if (ntris > 0 && attach_triangles(o, tris, ntris, opts->quality) != 0) {
        oracle_free(o);
        return NULL;
    }
    const double t0 = clock_ms(CLOCK_MONOTONIC);
    const double c0 = clock_ms(CLOCK_PROCESS_CPUTIME_ID);
    rtcCommitScene(o->scene);
    o->build_cpu_ms = clock_ms(CLOCK_PROCESS_CPUTIME_ID) - c0;
    o->build_ms = clock_ms(CLOCK_MONOTONIC) - t0;
    if (rtcGetDeviceError(o->device) != RTC_ERROR_NONE) {
        oracle_free(o);
        return NULL;
    }
    return o;
}

void oracle_free(oracle *o) {
    if (!o)
        return;
    if (o->scene)
        rtcReleaseScene(o->scene);
    if (o->device)
        rtcReleaseDevice(o->device);
    free(o);
}

double oracle_build_ms(const oracle *o) { return o->build_ms; }
double oracle_build_cpu_ms(const oracle *o) { return o->build_cpu_ms; }
int64_t oracle_bytes(const oracle *o) {
    return atomic_load(&((oracle *)o)->bytes);
}
RTCScene oracle_rtc_scene(const oracle *o) { return o->scene; }

/* Rays Embree must not see: its behaviour on NaN, a zero direction or an
 * empty interval is unspecified, while kdray defines all three as misses. */
static int ray_is_valid(const kdr_ray *r) {
    for (int k = 0; k < 3; k++)
        if (isnan(r->org[k]) || isnan(r->dir[k]))
            return 0;
    if (isnan(r->tmin) || isnan(r->tmax) || r->tmax < r->tmin)
        return 0;
    return r->dir[0] != 0.0f || r->dir[1] != 0.0f || r->dir[2] != 0.0f;
}

static void to_rtc_ray(const kdr_ray *r, struct RTCRay *out) {
    out->org_x = r->org[0];
    out->org_y = r->org[1];
    out->org_z = r->org[2];
    out->dir_x = r->dir[0];
    out->dir_y = r->dir[1];
    out->dir_z = r->dir[2];
    out->tnear = r->tmin;
    out->tfar = r->tmax;
    out->time = 0.0f;
    out->mask = 0xFFFFFFFFu;
    out->id = 0;
    out->flags = 0;
}

int oracle_intersect1(const oracle *o, const kdr_ray *ray, kdr_hit *hit) {
    hit->t = -1.0f;
    hit->u = hit->v = 0.0f;
    hit->prim = -1;
    if (!ray_is_valid(ray))
        return 0;
    struct RTCRayHit rh;
    to_rtc_ray(ray, &rh.ray);
    rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
    rh.hit.primID = RTC_INVALID_GEOMETRY_ID;
    rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
    struct RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    rtcIntersect1(o->scene, &ctx, &rh);
    if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID)
        return 0;
    hit->t = rh.ray.tfar;
    hit->u = rh.hit.u;
    hit->v = rh.hit.v;
    hit->prim = (int32_t)rh.hit.primID;
    return 1;
}

int oracle_occluded1(const oracle *o, const kdr_ray *ray) {
    if (!ray_is_valid(ray))
        return 0;
    struct RTCRay r;
    to_rtc_ray(ray, &r);
    struct RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    rtcOccluded1(o->scene, &ctx, &r);
    /* Embree marks an occluded ray by setting tfar to -inf */
    return r.tfar == -INFINITY;
}

/* ---- every hit along a ray ------------------------------------------------ */

typedef struct all_ctx {
    struct RTCIntersectContext ctx; /* first: Embree hands this pointer back */
    kdr_hit *hits;
    size_t n, cap;
    int oom;
    int fixed;    /* hits is the caller's buffer: never grown */
    size_t extra; /* fixed: hits past cap, counted, not stored or deduplicated */
} all_ctx;

/* rtcIntersect1 calls filters with N == 1: ray and hit are then an RTCRay
 * and an RTCHit (the RTCRayN/RTCHitN accessors are C++ only). */
static void record_hit(const struct RTCFilterFunctionNArguments *args) {
    all_ctx *c = (all_ctx *)args->context;
    if (args->N != 1 || !args->valid[0])
        return;
    args->valid[0] = 0; /* reject: traversal goes on */
    const struct RTCHit *hit = (const struct RTCHit *)args->hit;
    const struct RTCRay *ray = (const struct RTCRay *)args->ray;
    for (size_t i = 0; i < c->n; i++)
        if (c->hits[i].prim == (int32_t)hit->primID)
            return;
    if (c->n == c->cap && c->fixed) {
        c->extra++;
        return;
    }
    if (c->n == c->cap) {
        const size_t cap = c->cap ? 2 * c->cap : 64;
        kdr_hit *h = realloc(c->hits, cap * sizeof *h);
        if (!h) {
            c->oom = 1;
            return;
        }
        c->hits = h;
        c->cap = cap;
    }
    c->hits[c->n++] = (kdr_hit){ray->tfar, hit->u, hit->v, (int32_t)hit->primID};
}

static int hit_order(const void *a, const void *b) {
    const kdr_hit *x = a, *y = b;
    if (x->t != y->t)
        return x->t < y->t ? -1 : 1;
    return (x->prim > y->prim) - (x->prim < y->prim);
}

/* One rtcIntersect1 with record_hit as the context filter: c collects. */
static void collect(const oracle *o, const kdr_ray *ray, all_ctx *c) {
    rtcInitIntersectContext(&c->ctx);
    c->ctx.filter = record_hit;
    struct RTCRayHit rh;
    to_rtc_ray(ray, &rh.ray);
    rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
    rh.hit.primID = RTC_INVALID_GEOMETRY_ID;
    rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
    rtcIntersect1(o->scene, &c->ctx, &rh);
}

size_t oracle_all_filter(const oracle *o, const kdr_ray *ray, kdr_hit *out, size_t cap) {
    if (!ray_is_valid(ray))
        return 0;
    all_ctx c = {.hits = NULL};
    collect(o, ray, &c);
    if (c.n > 1)
        qsort(c.hits, c.n, sizeof *c.hits, hit_order);
    for (size_t i = 0; i < c.n && i < cap; i++)
        out[i] = c.hits[i];
    free(c.hits);
    return c.oom ? 0 : c.n;
}

size_t oracle_all_filter_into(const oracle *o, const kdr_ray *ray, kdr_hit *buf,
                              size_t cap, int sort) {
    if (!ray_is_valid(ray))
        return 0;
    all_ctx c = {.hits = buf, .cap = cap, .fixed = 1};
    collect(o, ray, &c);
    if (sort && c.n > 1)
        qsort(c.hits, c.n, sizeof *c.hits, hit_order);
    return c.n + c.extra;
}

size_t oracle_all_requery(const oracle *o, const kdr_ray *ray, kdr_hit *out, size_t cap) {
    size_t n = 0;
    kdr_ray r = *ray;
    while (n < cap && oracle_intersect1(o, &r, &out[n])) {
        r.tmin = nextafterf(out[n].t, INFINITY);
        n++;
        if (!(r.tmin <= r.tmax))
            break;
    }
    return n;
}

/* ---- closest point: rtcPointQuery with a closest-triangle callback ------- */

typedef struct cp_user {
    const float *tris;
    const float *p;
    double d2;
    kdr_closest best;
} cp_user;

static bool closest_triangle(struct RTCPointQueryFunctionArguments *args) {
    cp_user *u = args->userPtr;
    const unsigned prim = args->primID;
    const float *tri = u->tris + 9 * (size_t)prim;
    if (kd_tri_degenerate(tri))
        return false;
    double q[3], bu, bv, d2;
    kdr_point_triangle(u->p, tri, q, &bu, &bv, &d2);
    if (!(d2 < u->d2 || (d2 == u->d2 && (int32_t)prim < u->best.prim)))
        return false;
    u->d2 = d2;
    u->best.prim = (int32_t)prim;
    u->best.u = (float)bu;
    u->best.v = (float)bv;
    for (int k = 0; k < 3; k++)
        u->best.point[k] = (float)q[k];
    const float r = (float)sqrt(d2);
    /* the query sphere shrinks to the best distance (rounded up: a tie at
     * exactly that distance must still be reported) */
    args->query->radius = nextafterf(r, INFINITY);
    return true;
}

int oracle_closest_point(const oracle *o, const float *tris, const float p[3],
                         float max_distance, kdr_closest *out) {
    cp_user u = {tris, p, (double)max_distance * max_distance, {{0, 0, 0}, -1, 0, 0, -1}};
    if (u.d2 > 0 && isinf(max_distance))
        u.d2 = INFINITY;
    struct RTCPointQuery q = {p[0], p[1], p[2], 0.0f, max_distance};
    struct RTCPointQueryContext ctx;
    rtcInitPointQueryContext(&ctx);
    rtcPointQuery(o->scene, &q, &ctx, closest_triangle, &u);
    *out = u.best;
    if (u.best.prim >= 0)
        out->distance = (float)sqrt(u.d2);
    return u.best.prim >= 0;
}
