/*
 * bench_bundle.c — single-threaded throughput of omni-directional bundles
 * against single-ray kd traversal and Embree 3 (rtcIntersect1, and
 * rtcIntersect4/8 packets with a coherent context), all measured in the same
 * run on the same rays:
 *   camera  primary rays from one eye (closest hit), pixels ordered in 4x2
 *           tiles so that each 4- or 8-ray group is a compact screen tile;
 *   ao      64 cosine-weighted hemisphere rays from each of many surface
 *           points (one shared origin per 64 rays: the paper's case of mixed
 *           direction signs), any-hit within a radius, and closest hit;
 *   random  random origins in the scene box, random directions (closest).
 * Prints Mrays/s, nodes visited per ray (kd), bundle fallbacks, and ratios
 * against single-ray kd and Embree rtcIntersect1. Embree uses the same
 * RTC_SCENE_FLAG_ROBUST scene as the oracle; FTZ/DAZ off for both.
 *
 * Usage: kdray_bench_bundle [-s SET] [-e ENGINE] [scene.glb ...]   (default: 2CylinderEngine from
 * assimp-testmodels when present, and a generated room of spheres)
 */
#define _POSIX_C_SOURCE 200809L
#include <embree3/rtcore.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "kd_traverse_bundle.h"
#include "kdray.h"
#ifdef KDRAY_HAVE_GLTF
#include "kdr_gltf.h"
#endif

/* Tuning of the workload, in one place. */
#define CAM_W 640
#define CAM_H 480
#define AO_POINTS 3072
#define AO_RAYS 64
#define AO_RADIUS 0.1f  /* of the scene diagonal */
#define AO_OFFSET 1e-4f /* origin offset along the normal, of the diagonal */
#define RANDOM_RAYS 131072
#define REPEATS 5       /* best of, interleaved */

static const char *const ENGINE_GLB =
    "/usr/share/assimp/models/glTF2/2CylinderEngine-glTF-Binary/2CylinderEngine.glb";

/* ---- ray sets: rays in groups of `group` sharing one origin --------------- */

typedef struct rayset {
    const char *name;
    kdr_query query;
    size_t n, group;   /* group == 0: one origin for all; 1: one per ray */
    float *org;        /* 3 per group (3 in total when group == 0) */
    float *dir;        /* 3n */
    float tmax;        /* shared */
} rayset;

static const float *ray_org(const rayset *r, size_t i) {
    return r->org + (r->group == 0 ? 0 : 3 * (i / r->group));
}

/* Thread CPU time: the machine is shared, so wall time would measure the
 * neighbours; every engine runs on this one thread. */
static double now_s(void) {
    struct timespec ts;
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

static uint64_t g_rng = 0x243F6A8885A308D3ull;
static float rnd01(void) {
    g_rng ^= g_rng >> 12, g_rng ^= g_rng << 25, g_rng ^= g_rng >> 27;
    return (float)((g_rng * 0x2545F4914F6CDD1Dull) >> 40) * 0x1p-24f;
}

/* ---- scenes ---------------------------------------------------------------- */

typedef struct bscene {
    char name[64];
    float *tris;
    size_t ntris;
    kdr_scene *kd;
    RTCScene emb;
} bscene;

static void push_tri(float **t, size_t *n, size_t *cap, const float *a,
                     const float *b, const float *c) {
    if (*n == *cap) {
        *cap = *cap ? 2 * *cap : 1024;
        *t = realloc(*t, *cap * 9 * sizeof(float));
    }
    memcpy(*t + 9 * *n, a, 12), memcpy(*t + 9 * *n + 3, b, 12);
    memcpy(*t + 9 * *n + 6, c, 12);
    ++*n;
}

/* A 6x6 grid of spheres (2304 triangles each) on the floor of a box room. */
static void make_room(bscene *s) {
    size_t cap = 0;
    const float L = 12.0f, H = 6.0f;
    const float box[8][3] = {{0, 0, 0}, {L, 0, 0}, {L, 0, L}, {0, 0, L},
                             {0, H, 0}, {L, H, 0}, {L, H, L}, {0, H, L}};
    const int quads[6][4] = {{0, 1, 2, 3}, {4, 7, 6, 5}, {0, 4, 5, 1},
                             {1, 5, 6, 2}, {2, 6, 7, 3}, {3, 7, 4, 0}};
    for (int q = 0; q < 6; q++) {
        const int *v = quads[q];
        push_tri(&s->tris, &s->ntris, &cap, box[v[0]], box[v[1]], box[v[2]]);
        push_tri(&s->tris, &s->ntris, &cap, box[v[0]], box[v[2]], box[v[3]]);
    }
    const int rings = 24, segs = 48;
    for (int gx = 0; gx < 6; gx++)
        for (int gz = 0; gz < 6; gz++) {
            const float cx = 1.0f + 2.0f * gx, cz = 1.0f + 2.0f * gz;
            const float rad = 0.45f + 0.08f * (float)((gx * 7 + gz * 3) % 5);
            for (int r = 0; r < rings; r++)
                for (int g = 0; g < segs; g++) {
                    float p[4][3];
                    for (int k = 0; k < 4; k++) {
                        int rr = r + (k >= 2), gg = (g + (k == 1 || k == 2)) % segs;
                        double th = 3.14159265358979 * rr / rings;
                        double ph = 6.28318530717959 * gg / segs;
                        p[k][0] = cx + rad * (float)(sin(th) * cos(ph));
                        p[k][1] = rad + rad * (float)cos(th);
                        p[k][2] = cz + rad * (float)(sin(th) * sin(ph));
                    }
                    push_tri(&s->tris, &s->ntris, &cap, p[0], p[1], p[2]);
                    push_tri(&s->tris, &s->ntris, &cap, p[0], p[2], p[3]);
                }
        }
    snprintf(s->name, sizeof s->name, "room-of-spheres");
}

static int load_scene(const char *path, bscene *s) {
#ifdef KDRAY_HAVE_GLTF
    kdr_gltf_scene g;
    char err[256];
    if (kdr_gltf_load(path, &g, err, sizeof err) != 0) {
        fprintf(stderr, "bench_bundle: %s\n", err);
        return -1;
    }
    s->ntris = g.ntris;
    s->tris = malloc(g.ntris * 9 * sizeof(float));
    memcpy(s->tris, g.tris, g.ntris * 9 * sizeof(float));
    kdr_gltf_free(&g);
    const char *base = strrchr(path, '/');
    snprintf(s->name, sizeof s->name, "%s", base ? base + 1 : path);
    return 0;
#else
    fprintf(stderr, "bench_bundle: built without the glTF loader: %s\n", path);
    return -1;
#endif
}

static RTCScene embree_scene(RTCDevice dev, const float *tris, size_t n) {
    RTCScene sc = rtcNewScene(dev);
    rtcSetSceneFlags(sc, RTC_SCENE_FLAG_ROBUST);
    RTCGeometry g = rtcNewGeometry(dev, RTC_GEOMETRY_TYPE_TRIANGLE);
    float *vb = rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0,
                                        RTC_FORMAT_FLOAT3, 12, 3 * n);
    unsigned *ib = rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_INDEX, 0,
                                           RTC_FORMAT_UINT3, 12, n);
    memcpy(vb, tris, n * 9 * sizeof(float));
    for (size_t i = 0; i < 3 * n; i++)
        ib[i] = (unsigned)i;
    rtcCommitGeometry(g);
    rtcAttachGeometry(sc, g);
    rtcReleaseGeometry(g);
    rtcCommitScene(sc);
    return sc;
}

/* ---- ray sets -------------------------------------------------------------- */

static void scene_box(const bscene *s, float lo[3], float hi[3], float *diag) {
    kdr_bounds b;
    kdr_scene_bounds(s->kd, &b);
    memcpy(lo, b.min, 12), memcpy(hi, b.max, 12);
    *diag = kdr_scene_diagonal(s->kd);
}

static void cross3(const float a[3], const float b[3], float c[3]) {
    c[0] = a[1] * b[2] - a[2] * b[1];
    c[1] = a[2] * b[0] - a[0] * b[2];
    c[2] = a[0] * b[1] - a[1] * b[0];
}
static void norm3(float a[3]) {
    float l = sqrtf(a[0] * a[0] + a[1] * a[1] + a[2] * a[2]);
    for (int k = 0; k < 3; k++)
        a[k] /= l;
}

/* Primary rays, pixels in 4x2 tiles (each tile = two 2x2 quads). */
static rayset make_camera(const bscene *s, float eye_scale) {
    float lo[3], hi[3], diag, c[3], f[3], r[3], u[3];
    scene_box(s, lo, hi, &diag);
    rayset rs = {"camera", KDR_CLOSEST, (size_t)CAM_W * CAM_H, 0,
                 malloc(12), malloc((size_t)CAM_W * CAM_H * 12), INFINITY};
    const float off[3] = {1.0f, 0.45f, 1.2f}, up[3] = {0, 1, 0};
    for (int k = 0; k < 3; k++) {
        c[k] = 0.5f * (lo[k] + hi[k]);
        rs.org[k] = c[k] + eye_scale * off[k] * 0.5f * (hi[k] - lo[k]);
        f[k] = c[k] - rs.org[k];
    }
    norm3(f), cross3(f, up, r), norm3(r), cross3(r, f, u);
    const float h = tanf(0.5f * 60.0f * 3.14159265f / 180.0f), a = (float)CAM_W / CAM_H;
    size_t i = 0;
    for (int ty = 0; ty < CAM_H; ty += 2)
        for (int tx = 0; tx < CAM_W; tx += 4)
            for (int k = 0; k < 8; k++, i++) {
                int px = tx + (k & 1) + 2 * (k >> 2), py = ty + ((k >> 1) & 1);
                float sx = (2.0f * (px + 0.5f) / CAM_W - 1.0f) * h * a;
                float sy = (1.0f - 2.0f * (py + 0.5f) / CAM_H) * h;
                for (int j = 0; j < 3; j++)
                    rs.dir[3 * i + j] = f[j] + sx * r[j] + sy * u[j];
            }
    return rs;
}

/* Hemisphere rays from surface points the camera sees. */
static rayset make_ao(const bscene *s, const rayset *cam, kdr_query q) {
    float lo[3], hi[3], diag;
    scene_box(s, lo, hi, &diag);
    rayset rs = {q == KDR_ANY ? "ao-any" : "ao-closest", q,
                 (size_t)AO_POINTS * AO_RAYS, AO_RAYS, malloc(AO_POINTS * 12),
                 malloc((size_t)AO_POINTS * AO_RAYS * 12), AO_RADIUS * diag};
    size_t p = 0;
    g_rng = 0x243F6A8885A308D3ull;
    for (size_t i = 0; p < AO_POINTS; i = (i + 7919) % cam->n) {
        kdr_ray ray = {{0}, {0}, 0.0f, INFINITY};
        memcpy(ray.org, cam->org, 12), memcpy(ray.dir, cam->dir + 3 * i, 12);
        kdr_hit h;
        if (!kdr_intersect1(s->kd, &ray, &h, NULL))
            continue;
        const float *t = kdr_scene_triangle(s->kd, (size_t)h.prim);
        float e1[3], e2[3], n[3], tb[3], bb[3];
        for (int k = 0; k < 3; k++)
            e1[k] = t[3 + k] - t[k], e2[k] = t[6 + k] - t[k];
        cross3(e1, e2, n), norm3(n);
        if (n[0] * ray.dir[0] + n[1] * ray.dir[1] + n[2] * ray.dir[2] > 0)
            for (int k = 0; k < 3; k++)
                n[k] = -n[k];
        for (int k = 0; k < 3; k++)
            rs.org[3 * p + k] = ray.org[k] + h.t * ray.dir[k] + AO_OFFSET * diag * n[k];
        const float any[3] = {fabsf(n[0]) < 0.6f ? 1.0f : 0.0f, fabsf(n[0]) < 0.6f ? 0.0f : 1.0f, 0};
        cross3(n, any, tb), norm3(tb), cross3(n, tb, bb);
        for (int j = 0; j < AO_RAYS; j++) {
            float u1 = rnd01(), ph = 6.2831853f * rnd01(), rr = sqrtf(u1);
            float *d = rs.dir + 3 * (p * AO_RAYS + (size_t)j);
            for (int k = 0; k < 3; k++)
                d[k] = rr * cosf(ph) * tb[k] + rr * sinf(ph) * bb[k] + sqrtf(1.0f - u1) * n[k];
        }
        p++;
    }
    return rs;
}

static rayset make_random(const bscene *s) {
    float lo[3], hi[3], diag;
    scene_box(s, lo, hi, &diag);
    rayset rs = {"random", KDR_CLOSEST, RANDOM_RAYS, 1, malloc(RANDOM_RAYS * 12),
                 malloc(RANDOM_RAYS * 12), INFINITY};
    g_rng = 0x13198A2E03707344ull;
    for (size_t i = 0; i < rs.n; i++) {
        float d[3], l;
        for (int k = 0; k < 3; k++)
            rs.org[3 * i + k] = lo[k] + (hi[k] - lo[k]) * rnd01();
        do {
            for (int k = 0; k < 3; k++)
                d[k] = 2.0f * rnd01() - 1.0f;
            l = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
        } while (l > 1.0f || l < 1e-3f);
        memcpy(rs.dir + 3 * i, d, 12);
    }
    return rs;
}

/* ---- runners: each returns seconds and counts hits ------------------------ */

typedef struct outbuf {
    float *t, *u, *v;
    int32_t *prim;
    uint8_t *hit;
} outbuf;

static size_t count_hits(const rayset *r, const outbuf *o) {
    size_t h = 0;
    for (size_t i = 0; i < r->n; i++)
        h += r->query == KDR_ANY ? o->hit[i] : o->prim[i] >= 0;
    return h;
}

/* mode < 0: the internal 8-wide driver with flags -mode - 8 (0: in order,
 * no fallback; KB_SORT: regrouped, no fallback). */
static double run_kd(const bscene *s, const rayset *r, int mode, outbuf *o,
                     kdr_trav_stats *st) {
    const float tmin = 0.0f;
    const size_t g = r->group <= 1 ? r->n : r->group;
    memset(st, 0, sizeof *st);
    double t0 = now_s();
    for (size_t first = 0; first < r->n; first += g) {
        kdr_ray_batch b = {g, r->group == 1 ? r->org : ray_org(r, first),
                           r->group == 1 ? 3 : 0, r->dir + 3 * first,
                           &tmin, 0, &r->tmax, 0};
        kdr_hits h = {o->t + first, o->prim + first, o->u + first,
                      o->v + first, o->hit + first};
        if (mode < 0)
            kd_bundle8_trace(s->kd, &b, 0, g, r->query, -mode - 8, &h, st);
        else
            kdr_trace_batch(s->kd, &b, 0, g, r->query, (kdr_trav_mode)mode, &h, st);
    }
    return now_s() - t0;
}

static double run_embree1(const bscene *s, const rayset *r, outbuf *o) {
    struct RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    double t0 = now_s();
    for (size_t i = 0; i < r->n; i++) {
        struct RTCRayHit rh;
        const float *org = ray_org(r, i), *d = r->dir + 3 * i;
        rh.ray.org_x = org[0], rh.ray.org_y = org[1], rh.ray.org_z = org[2];
        rh.ray.dir_x = d[0], rh.ray.dir_y = d[1], rh.ray.dir_z = d[2];
        rh.ray.tnear = 0.0f, rh.ray.tfar = r->tmax, rh.ray.time = 0.0f;
        rh.ray.mask = 0xFFFFFFFFu, rh.ray.id = 0, rh.ray.flags = 0;
        rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
        if (r->query == KDR_ANY) {
            rtcOccluded1(s->emb, &ctx, &rh.ray);
            o->hit[i] = rh.ray.tfar < 0.0f;
        } else {
            rtcIntersect1(s->emb, &ctx, &rh);
            o->prim[i] = rh.hit.geomID == RTC_INVALID_GEOMETRY_ID ? -1 : (int32_t)rh.hit.primID;
        }
    }
    return now_s() - t0;
}

/* Packets of W (4 or 8) consecutive rays, coherent context. */
static double run_embree_packets(const bscene *s, const rayset *r, int W,
                                 outbuf *o) {
    struct RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    ctx.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
    _Alignas(32) struct RTCRayHit8 rh;
    _Alignas(32) int valid[8];
    double t0 = now_s();
    for (size_t base = 0; base < r->n; base += (size_t)W) {
        for (int j = 0; j < W; j++) {
            const size_t i = base + (size_t)j < r->n ? base + (size_t)j : r->n - 1;
            const float *org = ray_org(r, i), *d = r->dir + 3 * i;
            valid[j] = base + (size_t)j < r->n ? -1 : 0;
            rh.ray.org_x[j] = org[0], rh.ray.org_y[j] = org[1], rh.ray.org_z[j] = org[2];
            rh.ray.dir_x[j] = d[0], rh.ray.dir_y[j] = d[1], rh.ray.dir_z[j] = d[2];
            rh.ray.tnear[j] = 0.0f, rh.ray.tfar[j] = r->tmax, rh.ray.time[j] = 0.0f;
            rh.ray.mask[j] = 0xFFFFFFFFu, rh.ray.id[j] = 0, rh.ray.flags[j] = 0;
            rh.hit.geomID[j] = RTC_INVALID_GEOMETRY_ID;
        }
        /* RTCRayHit4's layout is RTCRayHit8's with 4-float arrays, so the
         * 4-wide call gets its own copy below */
        if (W == 8) {
            if (r->query == KDR_ANY)
                rtcOccluded8(valid, s->emb, &ctx, &rh.ray);
            else
                rtcIntersect8(valid, s->emb, &ctx, &rh);
        } else {
            _Alignas(16) struct RTCRayHit4 r4;
#define CP(f) memcpy(r4.f, rh.f, 16)
            CP(ray.org_x), CP(ray.org_y), CP(ray.org_z), CP(ray.dir_x), CP(ray.dir_y);
            CP(ray.dir_z), CP(ray.tnear), CP(ray.tfar), CP(ray.time), CP(ray.mask);
            CP(ray.id), CP(ray.flags), CP(hit.geomID);
#undef CP
            if (r->query == KDR_ANY)
                rtcOccluded4(valid, s->emb, &ctx, &r4.ray);
            else
                rtcIntersect4(valid, s->emb, &ctx, &r4);
            memcpy(rh.ray.tfar, r4.ray.tfar, 16), memcpy(rh.hit.geomID, r4.hit.geomID, 16);
            memcpy(rh.hit.primID, r4.hit.primID, 16);
        }
        for (int j = 0; j < W && base + (size_t)j < r->n; j++) {
            if (r->query == KDR_ANY)
                o->hit[base + j] = rh.ray.tfar[j] < 0.0f;
            else
                o->prim[base + j] = rh.hit.geomID[j] == RTC_INVALID_GEOMETRY_ID
                                        ? -1 : (int32_t)rh.hit.primID[j];
        }
    }
    return now_s() - t0;
}

/* ---- the table ------------------------------------------------------------- */

enum { E_SINGLE, E_B4, E_B8, E_AUTO, E_RAW4, E_RAW8, E_EMB1, E_EMB4, E_EMB8, E_N };
static const char *const engine_names[E_N] = {
    "kd single", "kd bundle4", "kd bundle8", "kd auto",
    "kd sort8 (no fallback)", "kd raw8 (no fallback)",
    "embree rtcIntersect1", "embree rtcIntersect4 coh", "embree rtcIntersect8 coh"};

/* Command-line filters (-s SET, -e ENGINE: substrings), for profiling. */
static const char *g_only_set, *g_only_engine;

static double run_engine(const bscene *s, const rayset *r, int e, outbuf *o,
                         kdr_trav_stats *st) {
    static const int modes[6] = {KDR_TRAV_SINGLE, KDR_TRAV_BUNDLE4,
                                 KDR_TRAV_BUNDLE8, KDR_TRAV_AUTO,
                                 -8 - KB_SORT, -8};
    memset(st, 0, sizeof *st);
    if (e <= E_RAW8)
        return run_kd(s, r, modes[e], o, st);
    if (e == E_EMB1)
        return run_embree1(s, r, o);
    return run_embree_packets(s, r, e == E_EMB4 ? 4 : 8, o);
}

static int engine_wanted(int e) {
    if ((e == E_B8 || e == E_RAW4 || e == E_RAW8) && !kdr_cpu_has_avx2())
        return 0;
    return !g_only_engine || strstr(engine_names[e], g_only_engine) != NULL;
}

/* Engines run interleaved, best of REPEATS each, so that load from other
 * processes hits them alike. */
static void bench_set(const bscene *s, const rayset *r) {
    outbuf o = {malloc(r->n * 4), malloc(r->n * 4), malloc(r->n * 4),
                malloc(r->n * 4), malloc(r->n)};
    double best[E_N], mrays[E_N];
    size_t hits[E_N];
    kdr_trav_stats st[E_N];
    for (int e = 0; e < E_N; e++)
        best[e] = 1e30, mrays[e] = 0.0;
    for (int rep = 0; rep < REPEATS; rep++)
        for (int e = 0; e < E_N; e++) {
            if (!engine_wanted(e))
                continue;
            double t = run_engine(s, r, e, &o, &st[e]);
            best[e] = t < best[e] ? t : best[e];
            hits[e] = count_hits(r, &o);
        }
    printf("\n%s: %s, %zu rays (%s)\n", s->name, r->name, r->n,
           r->query == KDR_ANY ? "any hit" : "closest hit");
    for (int e = 0; e < E_N; e++) {
        if (!engine_wanted(e))
            continue;
        mrays[e] = (double)r->n / best[e] * 1e-6;
        printf("  %-26s %8.2f Mrays/s  hits %7zu", engine_names[e], mrays[e], hits[e]);
        if (e <= E_RAW8)
            printf("  nodes/ray %6.1f  fallbacks %llu",
                   (double)st[e].nodes_visited / (double)r->n,
                   (unsigned long long)st[e].fallbacks);
        printf("\n");
    }
    printf("  ratios: bundle4/single %.2f  bundle8/single %.2f  auto/single %.2f"
           "  auto/embree1 %.2f  auto/embree8 %.2f\n",
           mrays[E_B4] / mrays[E_SINGLE], mrays[E_B8] / mrays[E_SINGLE],
           mrays[E_AUTO] / mrays[E_SINGLE], mrays[E_AUTO] / mrays[E_EMB1],
           mrays[E_AUTO] / mrays[E_EMB8]);
    free(o.t), free(o.u), free(o.v), free(o.prim), free(o.hit);
}

static void bench_scene(RTCDevice dev, bscene *s, float eye_scale) {
    double t0 = now_s();
    if (kdr_scene_build(s->tris, s->ntris, NULL, NULL, NULL, &s->kd) != KDR_OK) {
        fprintf(stderr, "bench_bundle: kd build failed for %s\n", s->name);
        return;
    }
    double kd_ms = 1e3 * (now_s() - t0);
    t0 = now_s();
    s->emb = embree_scene(dev, s->tris, s->ntris);
    printf("\n== %s: %zu triangles, kd build %.0f ms, embree build %.0f ms\n",
           s->name, s->ntris, kd_ms, 1e3 * (now_s() - t0));
    rayset sets[4];
    sets[0] = make_camera(s, eye_scale);
    sets[1] = make_ao(s, &sets[0], KDR_ANY);
    sets[2] = make_ao(s, &sets[0], KDR_CLOSEST);
    sets[3] = make_random(s);
    for (int k = 0; k < 4; k++) {
        if (!g_only_set || strstr(sets[k].name, g_only_set))
            bench_set(s, &sets[k]);
        free(sets[k].org), free(sets[k].dir);
    }
    rtcReleaseScene(s->emb);
    kdr_scene_free(s->kd);
    free(s->tris);
}

int main(int argc, char **argv) {
    RTCDevice dev = rtcNewDevice(NULL);
    printf("kdray bundle benchmark, single thread; AVX2 %s\n",
           kdr_cpu_has_avx2() ? "yes" : "no");
    int nscenes = 0, first = 1;
    for (; first + 1 < argc && argv[first][0] == '-'; first += 2) {
        if (!strcmp(argv[first], "-s"))
            g_only_set = argv[first + 1];
        else if (!strcmp(argv[first], "-e"))
            g_only_engine = argv[first + 1];
    }
    for (int a = first; a < argc; a++) {
        bscene s = {{0}, NULL, 0, NULL, NULL};
        if (load_scene(argv[a], &s) == 0)
            bench_scene(dev, &s, 1.6f), nscenes++;
    }
    if (first == argc) {
        bscene room = {{0}, NULL, 0, NULL, NULL};
        make_room(&room);
        bench_scene(dev, &room, 0.8f);
        FILE *f = fopen(ENGINE_GLB, "rb");
        bscene eng = {{0}, NULL, 0, NULL, NULL};
        if (f && (fclose(f), load_scene(ENGINE_GLB, &eng) == 0))
            bench_scene(dev, &eng, 1.6f);
    }
    rtcReleaseDevice(dev);
    return first < argc && nscenes == 0 ? 1 : 0;
}
