/*
 * bench_bundle.c — kdray_bench_bundle: single-threaded throughput of
 * omni-directional bundles against single-ray kd traversal and Embree 3
 * (rtcIntersect1, and rtcIntersect4/8 packets with a coherent context), on
 * the same rays in the same run, for every scene of the ladder (the
 * oracle's harness, bench.h: --dir, --rays, --max-tris, --only, --repeat,
 * --csv). Ray sets:
 *   camera  primary rays of bench_camera_rays' camera (closest hit),
 *           pixels ordered in 4x2 tiles so that each group of 4 or 8 rays is
 *           a compact screen tile (the order a renderer would submit);
 *   ao      64 hemisphere rays per surface point from bench_ao_rays (one
 *           shared origin per 64 rays: the paper's mixed-sign case), any hit
 *           and closest hit;
 *   random  bench_random_rays (closest hit).
 * Prints Mrays/s, nodes visited per ray (kd), bundle fallbacks, and ratios
 * against single-ray kd and Embree rtcIntersect1. Timing is this thread's
 * CPU time (the machine is shared), engines interleaved, best of --repeat.
 * Embree: the same fast (non-robust), HIGH-quality, threads=1 set-up as
 * kdray_bench.
 */
#define _POSIX_C_SOURCE 200809L
#include <embree3/rtcore.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "bench.h"
#include "kd_traverse_bundle.h"
#include "kdray.h"
#include "oracle.h"

#define SEED 11u
#define AO_RAYS 64 /* rays per surface point */

/* ---- ray sets: rays in groups of `group` sharing one origin --------------- */

typedef struct rayset {
    const char *name;
    kdr_query query;
    size_t n, group;   /* group == 0: one origin for all; 1: one per ray */
    float *org;        /* 3 per group (3 in total when group == 0) */
    float *dir;        /* 3n */
    float tmin, tmax;  /* shared */
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

/* ---- ray sets ---------------------------------------------------------------- */

/* A rayset from kdray rays whose origins repeat in groups of `group` (0:
 * one origin for all) and whose interval is shared. */
static rayset from_rays(const char *name, kdr_query q, const kdr_ray *rays,
                        size_t n, size_t group) {
    const size_t norg = group == 0 ? 1 : (n + group - 1) / group;
    rayset rs = {name, q, n, group, malloc(norg * 12), malloc(n * 12),
                 rays[0].tmin, rays[0].tmax};
    for (size_t g = 0; g < norg; g++)
        memcpy(rs.org + 3 * g, rays[g * (group ? group : 1)].org, 12);
    for (size_t i = 0; i < n; i++)
        memcpy(rs.dir + 3 * i, rays[i].dir, 12);
    return rs;
}

/* The camera's pixels in 4x2 tiles (two 2x2 quads each), row-major tiles. */
static size_t camera_tiled(const kdr_camera *cam, kdr_ray *out) {
    size_t i = 0;
    for (uint32_t ty = 0; ty < cam->height; ty += 2)
        for (uint32_t tx = 0; tx < cam->width; tx += 4)
            for (uint32_t k = 0; k < 8; k++) {
                const uint32_t px = tx + (k & 1) + 2 * (k >> 2);
                const uint32_t py = ty + ((k >> 1) & 1);
                if (px < cam->width && py < cam->height)
                    kdr_camera_ray(cam, px, py, &out[i++]);
            }
    return i;
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
static double run_kd(const kdr_scene *kd, const rayset *r, int mode,
                     outbuf *o, kdr_trav_stats *st) {
    const size_t g = r->group <= 1 ? r->n : r->group;
    memset(st, 0, sizeof *st);
    double t0 = now_s();
    for (size_t first = 0; first < r->n; first += g) {
        kdr_ray_batch b = {g, r->group == 1 ? r->org : ray_org(r, first),
                           r->group == 1 ? 3 : 0, r->dir + 3 * first,
                           &r->tmin, 0, &r->tmax, 0};
        kdr_hits h = {o->t + first, o->prim + first, o->u + first,
                      o->v + first, o->hit + first};
        if (mode < 0)
            kd_bundle8_trace(kd, &b, 0, g, r->query, -mode - 8, &h, st);
        else
            kdr_trace_batch(kd, &b, 0, g, r->query, (kdr_trav_mode)mode, &h, st);
    }
    return now_s() - t0;
}

static double run_embree1(RTCScene sc, const rayset *r, outbuf *o) {
    struct RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    double t0 = now_s();
    for (size_t i = 0; i < r->n; i++) {
        struct RTCRayHit rh;
        const float *org = ray_org(r, i), *d = r->dir + 3 * i;
        rh.ray.org_x = org[0], rh.ray.org_y = org[1], rh.ray.org_z = org[2];
        rh.ray.dir_x = d[0], rh.ray.dir_y = d[1], rh.ray.dir_z = d[2];
        rh.ray.tnear = r->tmin, rh.ray.tfar = r->tmax, rh.ray.time = 0.0f;
        rh.ray.mask = 0xFFFFFFFFu, rh.ray.id = 0, rh.ray.flags = 0;
        rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
        if (r->query == KDR_ANY) {
            rtcOccluded1(sc, &ctx, &rh.ray);
            o->hit[i] = rh.ray.tfar < 0.0f;
        } else {
            rtcIntersect1(sc, &ctx, &rh);
            o->prim[i] = rh.hit.geomID == RTC_INVALID_GEOMETRY_ID ? -1 : (int32_t)rh.hit.primID;
        }
    }
    return now_s() - t0;
}

/* Packets of W (4 or 8) consecutive rays, coherent context. */
static double run_embree_packets(RTCScene sc, const rayset *r, int W,
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
            rh.ray.tnear[j] = r->tmin, rh.ray.tfar[j] = r->tmax, rh.ray.time[j] = 0.0f;
            rh.ray.mask[j] = 0xFFFFFFFFu, rh.ray.id[j] = 0, rh.ray.flags[j] = 0;
            rh.hit.geomID[j] = RTC_INVALID_GEOMETRY_ID;
        }
        /* RTCRayHit4's layout is RTCRayHit8's with 4-float arrays, so the
         * 4-wide call gets its own copy below */
        if (W == 8) {
            if (r->query == KDR_ANY)
                rtcOccluded8(valid, sc, &ctx, &rh.ray);
            else
                rtcIntersect8(valid, sc, &ctx, &rh);
        } else {
            _Alignas(16) struct RTCRayHit4 r4;
#define CP(f) memcpy(r4.f, rh.f, 16)
            CP(ray.org_x), CP(ray.org_y), CP(ray.org_z), CP(ray.dir_x), CP(ray.dir_y);
            CP(ray.dir_z), CP(ray.tnear), CP(ray.tfar), CP(ray.time), CP(ray.mask);
            CP(ray.id), CP(ray.flags), CP(hit.geomID);
#undef CP
            if (r->query == KDR_ANY)
                rtcOccluded4(valid, sc, &ctx, &r4.ray);
            else
                rtcIntersect4(valid, sc, &ctx, &r4);
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

/* ---- the table ---------------------------------------------------------------- */

enum { E_SINGLE, E_B4, E_B8, E_AUTO, E_SORT8, E_RAW8, E_EMB1, E_EMB4, E_EMB8, E_N };
static const char *const engine_names[E_N] = {
    "kd single", "kd bundle4", "kd bundle8", "kd auto",
    "kd sort8 (no fallback)", "kd raw8 (in order)",
    "embree rtcIntersect1", "embree rtcIntersect4 coh", "embree rtcIntersect8 coh"};
static const char *const engine_ids[E_N] = {
    "single", "bundle4", "bundle8", "auto", "sort8", "raw8",
    "embree1", "embree4", "embree8"};

static double run_engine(const bench_scene *s, RTCScene sc, const rayset *r,
                         int e, outbuf *o, kdr_trav_stats *st) {
    static const int modes[6] = {KDR_TRAV_SINGLE, KDR_TRAV_BUNDLE4,
                                 KDR_TRAV_BUNDLE8, KDR_TRAV_AUTO,
                                 -8 - KB_SORT, -8};
    memset(st, 0, sizeof *st);
    if (e <= E_RAW8)
        return run_kd(s->kd, r, modes[e], o, st);
    if (e == E_EMB1)
        return run_embree1(sc, r, o);
    return run_embree_packets(sc, r, e == E_EMB4 ? 4 : 8, o);
}

static int engine_wanted(int e) {
    return !((e == E_B8 || e == E_SORT8 || e == E_RAW8) && !kdr_cpu_has_avx2());
}

static void csv_metric(bench_csv *csv, const bench_scene *s, const rayset *r,
                       const char *what, double v) {
    char metric[96];
    snprintf(metric, sizeof metric, "%s_%s", r->name, what);
    bench_csv_row(csv, "bundle", s, metric, v);
}

/* Engines run interleaved, best of `repeat` each, so that load from other
 * processes hits them alike. */
static void bench_set(const bench_scene *s, RTCScene sc, const rayset *r,
                      int repeat, bench_csv *csv) {
    outbuf o = {malloc(r->n * 4), malloc(r->n * 4), malloc(r->n * 4),
                malloc(r->n * 4), malloc(r->n)};
    double best[E_N], mrays[E_N];
    size_t hits[E_N] = {0};
    kdr_trav_stats st[E_N];
    for (int e = 0; e < E_N; e++)
        best[e] = 1e30, mrays[e] = 0.0;
    for (int rep = 0; rep < repeat; rep++)
        for (int e = 0; e < E_N; e++)
            if (engine_wanted(e)) {
                double t = run_engine(s, sc, r, e, &o, &st[e]);
                best[e] = t < best[e] ? t : best[e];
                hits[e] = count_hits(r, &o);
            }
    printf("\n%s: %s, %zu rays (%s)\n", s->name, r->name, r->n,
           r->query == KDR_ANY ? "any hit" : "closest hit");
    for (int e = 0; e < E_N; e++) {
        if (!engine_wanted(e))
            continue;
        mrays[e] = (double)r->n / best[e] * 1e-6;
        printf("  %-26s %8.2f Mrays/s  hits %8zu", engine_names[e], mrays[e], hits[e]);
        char what[64];
        snprintf(what, sizeof what, "%s_mrays", engine_ids[e]);
        csv_metric(csv, s, r, what, mrays[e]);
        if (e <= E_RAW8) {
            const double npr = (double)st[e].nodes_visited / (double)r->n;
            printf("  nodes/ray %6.1f  fallbacks %llu", npr,
                   (unsigned long long)st[e].fallbacks);
            snprintf(what, sizeof what, "%s_nodes_per_ray", engine_ids[e]);
            csv_metric(csv, s, r, what, npr);
        }
        printf("\n");
    }
    printf("  ratios: bundle4/single %.2f  bundle8/single %.2f  auto/single %.2f"
           "  auto/embree1 %.2f  auto/embree8 %.2f\n",
           mrays[E_B4] / mrays[E_SINGLE], mrays[E_B8] / mrays[E_SINGLE],
           mrays[E_AUTO] / mrays[E_SINGLE], mrays[E_AUTO] / mrays[E_EMB1],
           mrays[E_AUTO] / mrays[E_EMB8]);
    csv_metric(csv, s, r, "auto_over_single", mrays[E_AUTO] / mrays[E_SINGLE]);
    csv_metric(csv, s, r, "auto_over_embree1", mrays[E_AUTO] / mrays[E_EMB1]);
    free(o.t), free(o.u), free(o.v), free(o.prim), free(o.hit);
}

static int bundle_section(const bench_scene *s, const bench_opts *opts,
                          bench_csv *csv) {
    oracle_opts oo;
    oracle_opts_default(&oo);
    oo.robust = 0;
    oo.device_config = BENCH_EMBREE_CONFIG;
    oracle *emb = oracle_create(s->tris, s->ntris, &oo);
    kdr_ray *rays = malloc(opts->rays * sizeof *rays);
    if (!emb || !rays || opts->rays < AO_RAYS) {
        free(rays);
        oracle_free(emb);
        return 1;
    }
    RTCScene sc = oracle_rtc_scene(emb);
    printf("\n== %s: %zu triangles, kd build %.0f ms, embree build %.0f ms\n",
           s->name, s->ntris, s->kd_build_ms, oracle_build_ms(emb));
    rayset sets[4];
    kdr_camera cam;
    bench_camera_rays(s->kd, opts->rays, &cam, rays);
    sets[0] = from_rays("camera", KDR_CLOSEST, rays, camera_tiled(&cam, rays), 0);
    const size_t nao = opts->rays / AO_RAYS * AO_RAYS;
    bench_ao_rays(s->kd, SEED, nao, AO_RAYS, rays);
    sets[1] = from_rays("ao_any", KDR_ANY, rays, nao, AO_RAYS);
    sets[2] = from_rays("ao_closest", KDR_CLOSEST, rays, nao, AO_RAYS);
    bench_random_rays(s->kd, SEED, opts->rays, rays);
    sets[3] = from_rays("random", KDR_CLOSEST, rays, opts->rays, 1);
    for (int k = 0; k < 4; k++) {
        bench_set(s, sc, &sets[k], opts->repeat, csv);
        free(sets[k].org), free(sets[k].dir);
    }
    free(rays);
    oracle_free(emb);
    return 0;
}

int main(int argc, char **argv) {
    static const bench_section sections[] = {{"bundle", bundle_section}};
    printf("kdray bundle benchmark, single thread; AVX2 %s\n",
           kdr_cpu_has_avx2() ? "yes" : "no");
    return bench_main(argc, argv, sections, 1);
}
