/*
 * bench_core.c — kdray_bench: the core benchmark (issue 2). For every
 * ladder scene, in the same run and on one core: the kd-tree build against
 * Embree's BVH builds (RTC_BUILD_QUALITY_HIGH and the default MEDIUM), and
 * single-ray tracing of the same rays with kdr_intersect1 / kdr_occluded1
 * against rtcIntersect1 / rtcOccluded1 (on the HIGH-quality BVH, default
 * scene flags: Embree's fast path, not the robust mode the tests use).
 * Ray sets: camera rays, random incoherent rays, AO hemisphere rays (any).
 *
 * Times are process CPU time (bench_cpu_ms): both sides run on one thread,
 * and on a shared machine wall time would mostly measure the neighbours.
 * Prints one table row per scene and, with --csv, long-format rows. Other
 * sections can be added to the table in main() or, better, live in their
 * own program built on bench.h.
 */
#include <stdio.h>
#include <stdlib.h>

#include "bench.h"
#include "oracle.h"

#define SEED 7u
#define AO_PER_POINT 16

static void print_header(void) {
    printf("%-10s %9s | %9s %9s %9s %6s | %6s %6s | %21s | %21s | %21s\n",
           "scene", "tris", "build kd", "emb HQ", "emb MED", "kd/HQ", "B/tri",
           "embB/t", "camera Mray/s kd emb x", "random Mray/s kd emb x",
           "AO any Mray/s kd emb x");
    printf("%-10s %9s | %9s %9s %9s %6s | %6s %6s | %21s | %21s | %21s\n", "",
           "", "ms", "ms", "ms", "", "kd", "HQ", "", "", "");
}

static oracle *embree_build(const bench_scene *s, enum RTCBuildQuality q) {
    oracle_opts o;
    oracle_opts_default(&o);
    o.robust = 0;
    o.quality = q;
    o.device_config = BENCH_EMBREE_CONFIG;
    return oracle_create(s->tris, s->ntris, &o);
}

typedef struct speed {
    double kd, emb;
    size_t hit_diff;
} speed;

static speed trace_both(const bench_scene *s, RTCScene sc, const kdr_ray *rays,
                        size_t n, int any, int repeat) {
    size_t hk, he;
    speed v;
    v.kd = bench_kd_mrays(s->kd, rays, n, any, repeat, &hk);
    v.emb = bench_embree_mrays(sc, rays, n, any, repeat, &he);
    /* Embree's fast (non-robust) mode leaks a few rays through shared
     * edges; more than 0.1% would make the speeds incomparable */
    v.hit_diff = hk > he ? hk - he : he - hk;
    if (v.hit_diff * 1000 > n)
        fprintf(stderr, "%s: hit counts differ: kd %zu embree %zu of %zu\n",
                s->name, hk, he, n);
    return v;
}

static void csv_speed(bench_csv *csv, const bench_scene *s, const char *set,
                      speed v) {
    char m[64];
    snprintf(m, sizeof m, "%s_mrays_kd", set);
    bench_csv_row(csv, "core", s, m, v.kd);
    snprintf(m, sizeof m, "%s_mrays_embree", set);
    bench_csv_row(csv, "core", s, m, v.emb);
    snprintf(m, sizeof m, "%s_ratio", set);
    bench_csv_row(csv, "core", s, m, v.emb > 0 ? v.kd / v.emb : 0);
}

static int core_section(const bench_scene *s, const bench_opts *opts,
                        bench_csv *csv) {
    static int header;
    if (!header++)
        print_header();
    oracle *hq = embree_build(s, RTC_BUILD_QUALITY_HIGH);
    oracle *med = embree_build(s, RTC_BUILD_QUALITY_MEDIUM);
    kdr_ray *rays = malloc(opts->rays * sizeof *rays);
    if (!hq || !med || !rays) {
        oracle_free(hq);
        oracle_free(med);
        free(rays);
        return -1;
    }
    kdr_tree_stats st;
    kdr_scene_tree_stats(s->kd, &st);
    const double ntri = s->ntris ? (double)s->ntris : 1.0;
    const double kd_bpt = (double)st.bytes / ntri;
    const double emb_bpt = (double)oracle_bytes(hq) / ntri;
    const double hq_ms = oracle_build_cpu_ms(hq);
    const double med_ms = oracle_build_cpu_ms(med);
    oracle_free(med);

    kdr_camera cam;
    RTCScene sc = oracle_rtc_scene(hq);
    const size_t ncam = bench_camera_rays(s->kd, opts->rays, &cam, rays);
    const speed cs = trace_both(s, sc, rays, ncam, 0, opts->repeat);
    bench_random_rays(s->kd, SEED, opts->rays, rays);
    const speed rs = trace_both(s, sc, rays, opts->rays, 0, opts->repeat);
    bench_ao_rays(s->kd, SEED, opts->rays, AO_PER_POINT, rays);
    const speed as = trace_both(s, sc, rays, opts->rays, 1, opts->repeat);
    oracle_free(hq);
    free(rays);

    printf("%-10s %9zu | %9.1f %9.1f %9.1f %6.2f | %6.1f %6.1f | %6.2f %6.2f %6.2f "
           "| %6.2f %6.2f %6.2f | %6.2f %6.2f %6.2f\n",
           s->name, s->ntris, s->kd_build_ms, hq_ms, med_ms,
           hq_ms > 0 ? s->kd_build_ms / hq_ms : 0, kd_bpt, emb_bpt, cs.kd,
           cs.emb, cs.kd / cs.emb, rs.kd, rs.emb, rs.kd / rs.emb, as.kd,
           as.emb, as.kd / as.emb);
    fflush(stdout);
    bench_csv_row(csv, "core", s, "build_ms_kd", s->kd_build_ms);
    bench_csv_row(csv, "core", s, "build_ms_embree_hq", hq_ms);
    bench_csv_row(csv, "core", s, "build_ms_embree_medium", med_ms);
    bench_csv_row(csv, "core", s, "build_ratio_kd_hq", s->kd_build_ms / hq_ms);
    bench_csv_row(csv, "core", s, "bytes_per_tri_kd", kd_bpt);
    bench_csv_row(csv, "core", s, "bytes_per_tri_embree_hq", emb_bpt);
    csv_speed(csv, s, "camera", cs);
    csv_speed(csv, s, "random", rs);
    csv_speed(csv, s, "ao_any", as);
    return 0;
}

int main(int argc, char **argv) {
    static const bench_section sections[] = {{"core", core_section}};
    return bench_main(argc, argv, sections, sizeof sections / sizeof *sections);
}
