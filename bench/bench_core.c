/*
 * bench_core.c — the "core" section (kdray_bench): the kd-tree build
 * against Embree's BVH builds (HIGH quality, the one the rival traces, and
 * the default MEDIUM), memory per triangle, and kdray's single-ray walk
 * (kdr_intersect1 / kdr_occluded1) against every rival API on camera,
 * random, AO any-hit and shadow rays (16 per point toward a sphere light,
 * bench.h), and the batch API (kdr_trace_batch AUTO in
 * calls of BENCH_BATCH_RAYS rays with their own origins: bundles or the
 * interleaved walk, as the daemon traces a request) beside it. At the end,
 * one table of kd against the strongest Embree API per workload, read back
 * from the summary.
 */
#include <stdio.h>
#include <stdlib.h>

#include "bench.h"
#include "rival.h"

static const char *const core_workloads[] = {"camera", "random", "ao_any", "shadow"};
#define NWORK (sizeof core_workloads / sizeof *core_workloads)

/* Scenes in run order with the numbers only this section knows. */
#define MAX_SCENES 32
static struct {
    char name[64];
    size_t tris;
    double kd_bpt, emb_bpt;
} g_scenes[MAX_SCENES];
static int g_nscenes;

static int core_run(const bench_scene *s, const bench_opts *o) {
    rival *med =
        o->quick ? NULL : rival_create(s->tris, s->ntris, 0, RTC_BUILD_QUALITY_MEDIUM);
    if (med)
        bench_summary_add(s, "build", "embree_build_medium", 0, rival_build_ms(med), -1);
    rival_free(med);
    kdr_tree_stats st;
    kdr_scene_tree_stats(s->kd, &st);
    const double ntri = s->ntris ? (double)s->ntris : 1.0;
    if (g_nscenes < MAX_SCENES) {
        snprintf(g_scenes[g_nscenes].name, sizeof g_scenes[0].name, "%s", s->name);
        g_scenes[g_nscenes].tris = s->ntris;
        g_scenes[g_nscenes].kd_bpt = (double)st.bytes / ntri;
        g_scenes[g_nscenes++].emb_bpt = (double)rival_bytes(s->emb) / ntri;
    }
    printf("\n== %s: %zu triangles; build CPU ms: kd %.1f, Embree HIGH %.1f\n", s->name,
           s->ntris, s->kd_build_ms, rival_build_ms(s->emb));
    static const bench_kd single[] = {BENCH_KD_SINGLE, BENCH_KD_BATCH};
    for (size_t k = 0; k < NWORK; k++) {
        bench_workload w;
        if (bench_workload_make(&w, s->kd, core_workloads[k], o->rays) != 0)
            return -1;
        const int rc = bench_run_workload(s, &w, single, 2, o);
        bench_workload_free(&w);
        if (rc)
            return -1;
    }
    return 0;
}

/* "0.27 rtcIntersect16_coherent": kd speed (method kd_single or kd_batch)
 * / the strongest Embree API's. */
static void print_vs(const char *scene, const char *work, const char *method) {
    double best = 0.0;
    const char *api = bench_summary_rival(scene, work, &best);
    const double kd = bench_summary_ms(scene, work, method);
    if (!api || kd <= 0) {
        printf(" | %28s", "-");
        return;
    }
    printf(" | %5.2f %-22s", best / kd, api + 7 /* drop "embree_" */);
}

static void core_finish(const bench_opts *o) {
    (void)o;
    printf("\n== kd build, single rays and batches (kd_batch) against Embree's strongest "
           "API per workload (x = kd speed / Embree speed)\n");
    printf("%-10s %9s | %9s %9s %9s %6s | %6s %6s", "scene", "tris", "kd ms", "HIGH ms",
           "MED ms", "kd/HI", "B/tri", "Emb");
    for (size_t k = 0; k < NWORK; k++)
        printf(" | %-28s", core_workloads[k]);
    for (size_t k = 0; k < NWORK; k++)
        printf(" | batch %-22s", core_workloads[k]);
    printf("\n");
    for (int i = 0; i < g_nscenes; i++) {
        const char *n = g_scenes[i].name;
        const double kd = bench_summary_ms(n, "build", "kd_build");
        const double hi = bench_summary_ms(n, "build", "embree_build_high");
        const double med = bench_summary_ms(n, "build", "embree_build_medium");
        printf("%-10s %9zu | %9.1f %9.1f %9.1f %6.2f | %6.1f %6.1f", n, g_scenes[i].tris,
               kd, hi, med, hi > 0 ? kd / hi : 0.0, g_scenes[i].kd_bpt,
               g_scenes[i].emb_bpt);
        for (size_t k = 0; k < NWORK; k++)
            print_vs(n, core_workloads[k], "kd_single");
        for (size_t k = 0; k < NWORK; k++)
            print_vs(n, core_workloads[k], "kd_batch");
        printf("\n");
    }
}

const bench_section bench_core_section = {"core", core_run, core_finish};
