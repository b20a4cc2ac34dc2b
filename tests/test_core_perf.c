/*
 * test_core_perf.c — not a ctest test: the quick measurement the core
 * engineer quotes (build time and single-ray throughput against Embree 3 in
 * the same run, same rays, one thread, CPU time of this thread).
 *
 *   test_core_perf SCENE [RAYS [random|camera|ao|shadow]]
 *   SCENE: a .glb/.gltf file, or sphere:N (a 2*N*N-triangle lat-long sphere)
 *
 * Random rays start uniformly in the scene bounds with uniform directions;
 * camera rays form a 1000-wide image looking down -z at the scene; AO rays
 * leave random surface points (64 per point) into the normal's hemisphere
 * over [1e-5, 0.1] scene diagonals; shadow rays go from random surface
 * points to a point light above the scene. Also
 * prints how many closest-hit prims agree with Embree (Embree's hit t is
 * computed differently, so rare edge and tie cases may differ).
 */
#define _POSIX_C_SOURCE 200809L
#include <embree3/rtcore.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "kdr_gltf.h"
#include "kdray.h"

#define CAMERA_WIDTH 1000
#define AGREE_SAMPLE 20000

static double cpu_s(void) {
    struct timespec t;
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
    return (double)t.tv_sec + (double)t.tv_nsec * 1e-9;
}

static uint64_t g_rng = 88172645463325252ull;
static float rnd(void) {
    g_rng ^= g_rng << 13;
    g_rng ^= g_rng >> 7;
    g_rng ^= g_rng << 17;
    return (float)((g_rng >> 40) & 0xffffff) * 0x1p-24f;
}

static float *make_sphere(int n, size_t *ntris) {
    float *t = malloc((size_t)2 * n * n * 9 * sizeof(float));
    size_t k = 0;
    static const int quad[6] = {0, 1, 3, 0, 3, 2};
    for (int i = 0; i < n; i++)
        for (int j = 0; j < n; j++) {
            float p[4][3];
            for (int c = 0; c < 4; c++) {
                double th = 3.14159265358979 * (i + (c & 1)) / n;
                double ph = 2 * 3.14159265358979 * (j + (c >> 1)) / n;
                p[c][0] = (float)(sin(th) * cos(ph));
                p[c][1] = (float)(sin(th) * sin(ph));
                p[c][2] = (float)cos(th);
            }
            for (int q = 0; q < 6; q++)
                memcpy(t + 9 * (k + q / 3) + 3 * (q % 3), p[quad[q]], 12);
            k += 2;
        }
    *ntris = k;
    return t;
}

static RTCScene embree_scene(RTCDevice dev, const float *tris, size_t n) {
    RTCScene es = rtcNewScene(dev);
    rtcSetSceneFlags(es, RTC_SCENE_FLAG_ROBUST);
    rtcSetSceneBuildQuality(es, RTC_BUILD_QUALITY_HIGH);
    RTCGeometry g = rtcNewGeometry(dev, RTC_GEOMETRY_TYPE_TRIANGLE);
    float *vb = rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0,
                                        RTC_FORMAT_FLOAT3, 12, 3 * n);
    unsigned *ib = rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_INDEX, 0,
                                           RTC_FORMAT_UINT3, 12, n);
    memcpy(vb, tris, n * 36);
    for (size_t i = 0; i < 3 * n; i++)
        ib[i] = (unsigned)i;
    rtcCommitGeometry(g);
    rtcAttachGeometry(es, g);
    rtcReleaseGeometry(g);
    rtcCommitScene(es);
    return es;
}

static int embree_prim(RTCScene es, const kdr_ray *r) {
    struct RTCIntersectContext ctx;
    struct RTCRayHit rh;
    rtcInitIntersectContext(&ctx);
    rh.ray.org_x = r->org[0], rh.ray.org_y = r->org[1], rh.ray.org_z = r->org[2];
    rh.ray.dir_x = r->dir[0], rh.ray.dir_y = r->dir[1], rh.ray.dir_z = r->dir[2];
    rh.ray.tnear = r->tmin, rh.ray.tfar = r->tmax;
    rh.ray.mask = ~0u, rh.ray.flags = 0, rh.ray.time = 0;
    rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
    rtcIntersect1(es, &ctx, &rh);
    return rh.hit.geomID == RTC_INVALID_GEOMETRY_ID ? -1 : (int)rh.hit.primID;
}

#define AO_PER_POINT 64

/* A random point on a random triangle and its (unnormalised) normal. */
static void surface_point(const kdr_scene *s, float p[3], float nrm[3]) {
    const size_t n = kdr_scene_triangle_count(s);
    const float *t = kdr_scene_triangle(s, (size_t)(rnd() * (float)n) % n);
    float a = rnd(), b = rnd();
    if (a + b > 1.0f)
        a = 1.0f - a, b = 1.0f - b;
    float e1[3], e2[3];
    for (int k = 0; k < 3; k++) {
        p[k] = t[k] + a * (t[3 + k] - t[k]) + b * (t[6 + k] - t[k]);
        e1[k] = t[3 + k] - t[k];
        e2[k] = t[6 + k] - t[k];
    }
    nrm[0] = e1[1] * e2[2] - e1[2] * e2[1];
    nrm[1] = e1[2] * e2[0] - e1[0] * e2[2];
    nrm[2] = e1[0] * e2[1] - e1[1] * e2[0];
}

static int embree_occluded(RTCScene es, const kdr_ray *r) {
    struct RTCIntersectContext ctx;
    struct RTCRay ray;
    rtcInitIntersectContext(&ctx);
    ray.org_x = r->org[0], ray.org_y = r->org[1], ray.org_z = r->org[2];
    ray.dir_x = r->dir[0], ray.dir_y = r->dir[1], ray.dir_z = r->dir[2];
    ray.tnear = r->tmin, ray.tfar = r->tmax;
    ray.mask = ~0u, ray.flags = 0, ray.time = 0;
    rtcOccluded1(es, &ctx, &ray);
    return ray.tfar == -INFINITY;
}

static void make_surface_rays(const kdr_scene *s, int shadow, kdr_ray *rays,
                              int n) {
    kdr_bounds b;
    kdr_scene_bounds(s, &b);
    const float d = kdr_scene_diagonal(s);
    float p[3] = {0, 0, 0}, nrm[3] = {0, 1, 0};
    for (int i = 0; i < n; i++) {
        kdr_ray *r = &rays[i];
        if (shadow || i % AO_PER_POINT == 0)
            surface_point(s, p, nrm);
        float dir[3], len = 0.0f, dot = 0.0f;
        for (int k = 0; k < 3; k++) {
            const float light = k == 1 ? b.max[1] + 0.5f * d
                                       : 0.5f * (b.min[k] + b.max[k]);
            dir[k] = shadow ? light - p[k] : rnd() * 2 - 1;
            len += dir[k] * dir[k];
            dot += dir[k] * nrm[k];
        }
        len = sqrtf(len);
        for (int k = 0; k < 3; k++) {
            r->org[k] = p[k];
            r->dir[k] = (!shadow && dot < 0 ? -dir[k] : dir[k]) / len;
        }
        r->tmin = 1e-5f * d;
        r->tmax = shadow ? len : 0.1f * d;
    }
}

static void make_rays(const kdr_scene *s, int camera, kdr_ray *rays, int n) {
    kdr_bounds b;
    kdr_scene_bounds(s, &b);
    const float d = kdr_scene_diagonal(s);
    for (int i = 0; i < n; i++) {
        kdr_ray *r = &rays[i];
        for (int k = 0; k < 3; k++) {
            const float c = 0.5f * (b.min[k] + b.max[k]), e = b.max[k] - b.min[k];
            r->org[k] = camera ? c : b.min[k] + rnd() * e;
            r->dir[k] = rnd() * 2 - 1;
        }
        if (camera) {
            const int h = n / CAMERA_WIDTH, px = i % CAMERA_WIDTH, py = i / CAMERA_WIDTH;
            r->org[2] += 1.2f * d;
            r->dir[0] = (2 * (px + 0.5f) / CAMERA_WIDTH - 1) * 0.5f;
            r->dir[1] = (1 - 2 * (py + 0.5f) / (float)h) * 0.5f;
            r->dir[2] = -1;
        }
        r->tmin = 0;
        r->tmax = INFINITY;
    }
}

static const char *const kind_names[] = {"random", "camera", "ao", "shadow"};

static void measure(const kdr_scene *s, RTCScene es, int kind, kdr_ray *rays,
                    int n) {
    kdr_hit h;
    kdr_trav_stats st = {0}, sta = {0};
    long hits = 0, agree = 0;
    if (kind < 2)
        make_rays(s, kind, rays, n);
    else
        make_surface_rays(s, kind == 3, rays, n);
    double t0 = cpu_s();
    for (int i = 0; i < n; i++)
        hits += kdr_intersect1(s, &rays[i], &h, NULL);
    const double kd = cpu_s() - t0;
    t0 = cpu_s();
    for (int i = 0; i < n; i++)
        hits -= embree_prim(es, &rays[i]) >= 0;
    const double em = cpu_s() - t0;
    t0 = cpu_s();
    for (int i = 0; i < n; i++)
        kdr_occluded1(s, &rays[i], NULL);
    const double any = cpu_s() - t0;
    t0 = cpu_s();
    for (int i = 0; i < n; i++)
        embree_occluded(es, &rays[i]);
    const double eany = cpu_s() - t0;
    const int step = n > AGREE_SAMPLE ? n / AGREE_SAMPLE : 1;
    int sampled = 0;
    for (int i = 0; i < n; i += step, sampled++) {
        kdr_intersect1(s, &rays[i], &h, &st);
        agree += h.prim == embree_prim(es, &rays[i]);
        kdr_occluded1(s, &rays[i], &sta);
    }
    printf("%s rays: kd %.2f Mrays/s, embree %.2f, ratio %.2f; any-hit kd %.2f,"
           " embree %.2f, ratio %.2f;\n  closest nodes/ray %.1f tests/ray %.1f;"
           " any nodes/ray %.1f tests/ray %.1f; prims agree %ld/%d (hit count"
           " diff %ld)\n",
           kind_names[kind], n / kd * 1e-6, n / em * 1e-6, em / kd,
           n / any * 1e-6, n / eany * 1e-6, eany / any,
           (double)st.nodes_visited / (double)st.rays,
           (double)st.tri_tests / (double)st.rays,
           (double)sta.nodes_visited / (double)sta.rays,
           (double)sta.tri_tests / (double)sta.rays, agree, sampled, hits);
}

int main(int argc, char **argv) {
    if (argc < 2) {
        fprintf(stderr, "usage: %s SCENE.glb|sphere:N [RAYS]\n", argv[0]);
        return 2;
    }
    kdr_gltf_scene g = {0};
    float *tris;
    size_t n;
    if (strncmp(argv[1], "sphere:", 7) == 0) {
        tris = make_sphere(atoi(argv[1] + 7), &n);
    } else {
        char err[256];
        if (kdr_gltf_load(argv[1], &g, err, sizeof err) != 0) {
            fprintf(stderr, "%s\n", err);
            return 1;
        }
        tris = g.tris;
        n = g.ntris;
    }
    const int nrays = argc > 2 ? atoi(argv[2]) : 500000;
    kdr_scene *s;
    double t0 = cpu_s();
    kdr_build_opts opts;
    kdr_build_opts_default(&opts);
    if (getenv("KDR_PERF_MAX_DEPTH")) /* experiments with the depth limit */
        opts.max_depth = atoi(getenv("KDR_PERF_MAX_DEPTH"));
    if (getenv("KDR_PERF_LEAF"))
        opts.leaf_size = atoi(getenv("KDR_PERF_LEAF"));
    if (getenv("KDR_PERF_ISECT"))
        opts.isect_cost = (float)atof(getenv("KDR_PERF_ISECT"));
    if (kdr_scene_build(tris, n, &opts, NULL, NULL, &s) != KDR_OK)
        return 1;
    const double kb = cpu_s() - t0;
    RTCDevice dev = rtcNewDevice("threads=1");
    t0 = cpu_s();
    RTCScene es = embree_scene(dev, tris, n);
    const double eb = cpu_s() - t0;
    kdr_tree_stats st;
    kdr_scene_tree_stats(s, &st);
    printf("%zu triangles: kd build %.3f s, embree build %.3f s, ratio %.1f\n", n,
           kb, eb, kb / eb);
    printf("tree: %llu nodes, %llu leaves (%llu empty), depth %llu, %.2f refs/leaf,"
           " SAH %.0f, %.1f MB\n",
           (unsigned long long)st.nodes, (unsigned long long)st.leaves,
           (unsigned long long)st.empty_leaves, (unsigned long long)st.max_depth,
           st.refs_per_leaf, st.sah_cost, (double)st.bytes / 1e6);
    kdr_ray *rays = malloc(sizeof *rays * (size_t)nrays);
    const char *only = argc > 3 ? argv[3] : NULL;
    for (int kind = 0; kind < 4; kind++)
        if (!only || strcmp(only, kind_names[kind]) == 0)
            measure(s, es, kind, rays, nrays);
    free(rays);
    rtcReleaseScene(es);
    rtcReleaseDevice(dev);
    kdr_scene_free(s);
    if (g.tris)
        kdr_gltf_free(&g);
    else
        free(tris);
    return 0;
}
