/*
 * bench_bundle.c — the "bundle" section (kdray_bench_bundle): kdray's
 * omni-directional bundles (4, 8 and 16 lanes; the daemon's AUTO is 16 on
 * an AVX-512 CPU, else 8 with AVX2) against its single rays and every rival API,
 * on camera rays (4x4 pixel tiles, one origin), AO rays (64 hemisphere
 * rays per surface point, one batch per point: the paper's mixed-sign
 * case; any hit and closest hit), random rays (own origins) and shadow
 * rays (16 per surface point toward a sphere light, one batch per point).
 * The 8-wide driver without fallback (in order / regrouped) is printed for
 * diagnosis. --quick measures kd_single and AUTO's width only.
 */
#include <stdio.h>
#include <string.h>

#include "bench.h"
#include "kd_stream.h" /* kd_cpu_has_avx512 */
#include "rival.h"

static const char *const bundle_workloads[] = {"camera", "ao_any", "ao_closest",
                                               "random", "shadow"};
#define NWORK (sizeof bundle_workloads / sizeof *bundle_workloads)

#define MAX_SCENES 32
static char g_scene[MAX_SCENES][64];
static int g_nscenes;

static int bundle_run(const bench_scene *s, const bench_opts *o) {
    static const bench_kd all[] = {BENCH_KD_SINGLE, BENCH_KD_BUNDLE4, BENCH_KD_BUNDLE8,
                                   BENCH_KD_SORT8, BENCH_KD_RAW8, BENCH_KD_BUNDLE16};
    const bench_kd quick[] = {BENCH_KD_SINGLE, kd_cpu_has_avx512() ? BENCH_KD_BUNDLE16
                                                                   : BENCH_KD_BUNDLE8};
    if (g_nscenes < MAX_SCENES)
        snprintf(g_scene[g_nscenes++], sizeof g_scene[0], "%s", s->name);
    printf("\n== %s: %zu triangles, bundles (AUTO = %s)\n", s->name, s->ntris,
           kd_cpu_has_avx512() ? "bundle16, AVX-512"
           : kdr_cpu_has_avx2() ? "bundle8, AVX2" : "bundle4");
    for (size_t k = 0; k < NWORK; k++) {
        bench_workload w;
        if (bench_workload_make(&w, s->kd, bundle_workloads[k], o->rays) != 0)
            return -1;
        const int rc = o->quick ? bench_run_workload(s, &w, quick, 2, o)
                                : bench_run_workload(s, &w, all, 6, o);
        bench_workload_free(&w);
        if (rc)
            return -1;
    }
    return 0;
}

static void bundle_finish(const bench_opts *o) {
    (void)o;
    const char *auto_name = kd_cpu_has_avx512() ? "kd_bundle16"
                            : kdr_cpu_has_avx2() ? "kd_bundle8" : "kd_bundle4";
    printf("\n== %s (the daemon's AUTO) per workload: speed over kd_single, speed "
           "over the strongest Embree API (named)\n", auto_name);
    printf("%-10s", "scene");
    for (size_t k = 0; k < NWORK; k++)
        printf(" | %-40s", bundle_workloads[k]);
    printf("\n");
    for (int i = 0; i < g_nscenes; i++) {
        printf("%-10s", g_scene[i]);
        for (size_t k = 0; k < NWORK; k++) {
            const char *wk = bundle_workloads[k];
            double best = 0.0;
            const char *api = bench_summary_rival(g_scene[i], wk, &best);
            const double b = bench_summary_ms(g_scene[i], wk, auto_name);
            const double one = bench_summary_ms(g_scene[i], wk, "kd_single");
            if (!api || b <= 0 || one <= 0) {
                printf(" | %-40s", "-");
                continue;
            }
            printf(" | %5.2fx %5.2fx %-26s", one / b, best / b, api + 7);
        }
        printf("\n");
    }
}

const bench_section bench_bundle_section = {"bundle", bundle_run, bundle_finish};
