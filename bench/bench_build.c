/*
 * bench_build.c — kdray_bench_build: the kd-tree build against Embree's,
 * and what the binned top costs the traversals. Not a test. Its own main
 * (builds are what it measures, so it does not use bench_main's
 * pre-built scenes); rays come from bench.h's workloads.
 *
 * Section "build", per ladder scene, best of --repeat:
 *   one thread, process CPU time: kdray's default build (binned above
 *   exact_max), kdray's exact sweep everywhere (exact_max = INT_MAX), and
 *   Embree's RTC_BUILD_QUALITY_HIGH and MEDIUM builds (device "threads=1",
 *   fast scenes; times of rtcCommitScene);
 *   --threads T (default: the number of online cores), wall time: kdray's
 *   default build with opts.threads = T, Embree HIGH and MEDIUM with
 *   "threads=T". Wall time is the only fair clock for a parallel build;
 *   the load average printed beside it says how busy the machine was, and
 *   "kd idle>=" bounds kdray's wall time on an idle machine from below (its
 *   CPU time outside the parallel phase plus that phase's busiest thread,
 *   from the build's log line).
 * Section "ab": the exact tree (A) against the default binned tree (B) on
 *   the same rays, same run, interleaved, this thread's CPU time: single
 *   rays (camera and random closest, ambient-occlusion any), bundles
 *   (kdr_trace_batch, camera closest and AO any, 64 rays per origin) and
 *   four-frustum traversal (tile 8). Prints Mrays/s of A and B, B/A, nodes
 *   and triangle tests per ray, and fails if any answer differs (both
 *   trees must give every ray the same hit, bit for bit).
 *
 * Flags: --dir DIR, --only NAME (repeatable), --max-tris N, --rays N
 * (default 262144), --repeat R (default 3), --csv PATH, --section build|ab
 * (repeatable; default both), --threads T, --exact-max N (tree B's
 * threshold; default the library's).
 */
#define _POSIX_C_SOURCE 200809L
#include <limits.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "bench.h"
#include "ladder.h"
#include "oracle.h"

#define FRUSTUM_TILE 8
#define MAX_ONLY 16

static int g_threads, g_exact_max = -1;

/* What the old harness handed every section: one scene, the run's flags,
 * and a long-format CSV (scene,triangles,section,metric,value). */
typedef struct scene_in {
    const char *name;
    const float *tris;
    size_t ntris;
} scene_in;

typedef struct run_opts {
    size_t rays;
    int repeat;
    FILE *csv;
} run_opts;

static void csv_row(const run_opts *o, const char *section, const scene_in *s,
                    const char *metric, double v) {
    if (o->csv)
        fprintf(o->csv, "%s,%zu,%s,%s,%.6g\n", s->name, s->ntris, section, metric, v);
}

static double clock_ms(clockid_t id) {
    struct timespec ts;
    clock_gettime(id, &ts);
    return (double)ts.tv_sec * 1e3 + (double)ts.tv_nsec * 1e-6;
}

static double load_avg(void) {
    double l = -1;
    FILE *f = fopen("/proc/loadavg", "r");
    if (f) {
        if (fscanf(f, "%lf", &l) != 1)
            l = -1;
        fclose(f);
    }
    return l;
}

/* ---- builds ------------------------------------------------------------------ */

typedef struct timing {
    double cpu, wall, idle; /* ms, best of the repetitions */
} timing;

static kdr_build_opts opts_for(int exact_max, int threads) {
    kdr_build_opts o;
    kdr_build_opts_default(&o);
    if (exact_max >= 0)
        o.exact_max = exact_max;
    o.threads = threads;
    return o;
}

/* The build's log line "... (CPU: busiest thread X ms, all Y ms)". */
static void log_cpu(void *user, const char *msg) {
    const char *p = strstr(msg, "busiest thread ");
    double *v = user;
    if (p && sscanf(p, "busiest thread %lf ms, all %lf", &v[0], &v[1]) != 2)
        v[0] = v[1] = 0;
}

/* Builds R times, keeps the fastest CPU and wall times and the last tree.
 * t->idle: a lower bound of the wall time on an idle machine, the CPU time
 * outside the parallel phase plus that phase's busiest thread. */
static kdr_scene *kd_timed(const scene_in *s, kdr_build_opts o, int repeat,
                           timing *t) {
    kdr_scene *kd = NULL;
    t->cpu = t->wall = t->idle = INFINITY;
    for (int r = 0; r < repeat; r++) {
        kdr_scene_free(kd);
        double busy[2] = {0, 0};
        const double w0 = clock_ms(CLOCK_MONOTONIC), c0 = clock_ms(CLOCK_PROCESS_CPUTIME_ID);
        if (kdr_scene_build(s->tris, s->ntris, &o, log_cpu, busy, &kd) != KDR_OK) {
            fprintf(stderr, "%s: kd build failed\n", s->name);
            return NULL;
        }
        const double c = clock_ms(CLOCK_PROCESS_CPUTIME_ID) - c0;
        t->cpu = fmin(t->cpu, c);
        t->wall = fmin(t->wall, clock_ms(CLOCK_MONOTONIC) - w0);
        t->idle = fmin(t->idle, busy[1] > 0 ? c - busy[1] + busy[0] : c);
    }
    return kd;
}

static int embree_timed(const scene_in *s, enum RTCBuildQuality q, int threads,
                        int repeat, timing *t) {
    char cfg[32];
    snprintf(cfg, sizeof cfg, "threads=%d", threads);
    oracle_opts o;
    oracle_opts_default(&o);
    o.robust = 0;
    o.quality = q;
    o.device_config = cfg;
    t->cpu = t->wall = INFINITY;
    for (int r = 0; r < repeat; r++) {
        oracle *e = oracle_create(s->tris, s->ntris, &o);
        if (!e)
            return -1;
        t->cpu = fmin(t->cpu, oracle_build_cpu_ms(e));
        t->wall = fmin(t->wall, oracle_build_ms(e));
        oracle_free(e);
    }
    return 0;
}

static int build_section(const scene_in *s, const run_opts *opts) {
    static int header;
    const int T = g_threads;
    if (!header++) {
        printf("build: one thread = process CPU ms; %d threads = wall ms (load = 1-min "
               "load average before the scene; kd idle>= = kd's CPU outside its parallel "
               "phase + that phase's busiest thread, a lower bound for an idle machine)\n",
               T);
        printf("%-10s %8s | %8s %8s %8s %8s %6s %6s | %8s %8s %8s %8s %6s %6s | %8s %8s | "
               "%5s\n",
               "scene", "tris", "kd", "kd exact", "emb HQ", "emb MED", "kd/HQ", "kd/MED",
               "kd", "kd idle>=", "emb HQ", "emb MED", "kd/HQ", "kd/MED", "SAH", "SAH ex",
               "load");
    }
    const double load = load_avg();
    timing kd1, kdx, kdt, hq1, med1, hqt, medt;
    kdr_scene *a = kd_timed(s, opts_for(g_exact_max, 1), opts->repeat, &kd1);
    kdr_scene *x = kd_timed(s, opts_for(INT_MAX, 1), opts->repeat, &kdx);
    kdr_scene *p = kd_timed(s, opts_for(g_exact_max, T), opts->repeat, &kdt);
    if (!a || !x || !p || embree_timed(s, RTC_BUILD_QUALITY_HIGH, 1, opts->repeat, &hq1) ||
        embree_timed(s, RTC_BUILD_QUALITY_MEDIUM, 1, opts->repeat, &med1) ||
        embree_timed(s, RTC_BUILD_QUALITY_HIGH, T, opts->repeat, &hqt) ||
        embree_timed(s, RTC_BUILD_QUALITY_MEDIUM, T, opts->repeat, &medt)) {
        kdr_scene_free(a);
        kdr_scene_free(x);
        kdr_scene_free(p);
        return -1;
    }
    kdr_tree_stats sa, sx;
    kdr_scene_tree_stats(a, &sa);
    kdr_scene_tree_stats(x, &sx);
    printf("%-10s %8zu | %8.1f %8.1f %8.1f %8.1f %6.2f %6.2f | %8.1f %8.1f %8.1f %8.1f "
           "%6.2f %6.2f | %8.1f %8.1f | %5.1f\n",
           s->name, s->ntris, kd1.cpu, kdx.cpu, hq1.cpu, med1.cpu, kd1.cpu / hq1.cpu,
           kd1.cpu / med1.cpu, kdt.wall, kdt.idle, hqt.wall, medt.wall, kdt.wall / hqt.wall,
           kdt.wall / medt.wall, sa.sah_cost, sx.sah_cost, load);
    fflush(stdout);
    csv_row(opts, "build", s, "kd_cpu_ms_1t", kd1.cpu);
    csv_row(opts, "build", s, "kd_exact_cpu_ms_1t", kdx.cpu);
    csv_row(opts, "build", s, "embree_hq_cpu_ms_1t", hq1.cpu);
    csv_row(opts, "build", s, "embree_med_cpu_ms_1t", med1.cpu);
    csv_row(opts, "build", s, "kd_wall_ms_nt", kdt.wall);
    csv_row(opts, "build", s, "kd_idle_bound_ms_nt", kdt.idle);
    csv_row(opts, "build", s, "embree_hq_wall_ms_nt", hqt.wall);
    csv_row(opts, "build", s, "embree_med_wall_ms_nt", medt.wall);
    csv_row(opts, "build", s, "threads", T);
    csv_row(opts, "build", s, "sah_default", sa.sah_cost);
    csv_row(opts, "build", s, "sah_exact", sx.sah_cost);
    csv_row(opts, "build", s, "load_avg", load);
    kdr_scene_free(a);
    kdr_scene_free(x);
    kdr_scene_free(p);
    return 0;
}

/* ---- A/B: exact tree against binned tree -------------------------------------------- */

typedef struct work {
    const char *name;
    int kind; /* 0 single, 1 batch, 2 frustum */
    kdr_query q;
    const kdr_ray *rays; /* single; batch: origins/intervals from these */
    float *dirs;         /* batch: 3n */
    size_t n, group;     /* batch: rays sharing an origin */
    const kdr_camera *cam;
} work;

typedef struct out {
    float *t, *u, *v;
    int32_t *prim;
    uint8_t *hit;
} out;

static double run(const kdr_scene *kd, const work *w, out *o, kdr_trav_stats *st) {
    memset(st, 0, sizeof *st);
    const double t0 = clock_ms(CLOCK_THREAD_CPUTIME_ID);
    if (w->kind == 0) {
        for (size_t i = 0; i < w->n; i++) {
            if (w->q == KDR_ANY) {
                o->hit[i] = (uint8_t)kdr_occluded1(kd, &w->rays[i], st);
            } else {
                kdr_hit h;
                kdr_intersect1(kd, &w->rays[i], &h, st);
                o->t[i] = h.t, o->u[i] = h.u, o->v[i] = h.v, o->prim[i] = h.prim;
            }
        }
    } else if (w->kind == 1) {
        for (size_t first = 0; first < w->n; first += w->group) {
            const size_t g = w->n - first < w->group ? w->n - first : w->group;
            const kdr_ray *r = &w->rays[first];
            kdr_ray_batch b = {g, r->org, 0, w->dirs + 3 * first, &r->tmin, 0, &r->tmax, 0};
            kdr_hits h = {o->t + first, o->prim + first, o->u + first, o->v + first,
                          o->hit + first};
            kdr_trace_batch(kd, &b, 0, g, w->q, KDR_TRAV_AUTO, &h, st);
        }
    } else {
        kdr_hits h = {o->t, o->prim, o->u, o->v, o->hit};
        kdr_frustum_trace(kd, w->cam, FRUSTUM_TILE, 0,
                          kdr_frustum_tile_count(w->cam, FRUSTUM_TILE), w->q,
                          KDR_FRUSTUM_MULTI4, &h, st);
    }
    return clock_ms(CLOCK_THREAD_CPUTIME_ID) - t0;
}

static size_t differences(const work *w, const out *a, const out *b) {
    size_t d = 0;
    for (size_t i = 0; i < w->n; i++) {
        if (w->q == KDR_ANY)
            d += a->hit[i] != b->hit[i];
        else
            d += a->prim[i] != b->prim[i] || memcmp(&a->t[i], &b->t[i], 4) ||
                 memcmp(&a->u[i], &b->u[i], 4) || memcmp(&a->v[i], &b->v[i], 4);
    }
    return d;
}

static int out_alloc(out *o, size_t n) {
    o->t = malloc(n * 4), o->u = malloc(n * 4), o->v = malloc(n * 4);
    o->prim = malloc(n * 4), o->hit = malloc(n);
    return o->t && o->u && o->v && o->prim && o->hit ? 0 : -1;
}

static void out_free(out *o) {
    free(o->t), free(o->u), free(o->v), free(o->prim), free(o->hit);
}

/* Runs w on both trees, interleaved, best CPU time of each; 0 if equal. */
static int ab_one(const scene_in *s, const kdr_scene *ta, const kdr_scene *tb,
                  const work *w, const run_opts *opts) {
    out oa, ob;
    int rc = out_alloc(&oa, w->n) | out_alloc(&ob, w->n);
    double best[2] = {INFINITY, INFINITY};
    kdr_trav_stats st[2];
    for (int r = 0; r < opts->repeat && rc == 0; r++) {
        best[0] = fmin(best[0], run(ta, w, &oa, &st[0]));
        best[1] = fmin(best[1], run(tb, w, &ob, &st[1]));
    }
    const size_t diff = rc ? 0 : differences(w, &oa, &ob);
    const double ma = (double)w->n / best[0] * 1e-3, mb = (double)w->n / best[1] * 1e-3;
    printf("  %-14s %8.2f %8.2f %6.3f | %7.1f %7.1f | %7.1f %7.1f%s\n", w->name, ma, mb,
           mb / ma, (double)st[0].nodes_visited / (double)w->n,
           (double)st[1].nodes_visited / (double)w->n,
           (double)st[0].tri_tests / (double)w->n, (double)st[1].tri_tests / (double)w->n,
           diff ? "  ANSWERS DIFFER" : "");
    if (diff)
        fprintf(stderr, "%s %s: %zu of %zu answers differ between the trees\n", s->name,
                w->name, diff, w->n);
    char m[64];
    snprintf(m, sizeof m, "%s_mrays_exact", w->name);
    csv_row(opts, "ab", s, m, ma);
    snprintf(m, sizeof m, "%s_mrays_binned", w->name);
    csv_row(opts, "ab", s, m, mb);
    out_free(&oa);
    out_free(&ob);
    return rc || diff ? -1 : 0;
}

/* The camera of the frustum workload: bench.h's camera-ray view. */
static kdr_camera view_of(const kdr_scene *kd, size_t n) {
    kdr_bounds b;
    kdr_scene_bounds(kd, &b);
    const float diag = kdr_scene_diagonal(kd);
    static const float view[3] = {0.55f, 0.35f, 0.75f};
    uint32_t side = (uint32_t)sqrt((double)n) & ~3u;
    kdr_camera c = {.up = {0, 1, 0}, .fov_y_deg = 45.0f};
    c.width = c.height = side < 4 ? 4 : side;
    for (int k = 0; k < 3; k++) {
        c.target[k] = 0.5f * (b.min[k] + b.max[k]);
        c.eye[k] = c.target[k] + 1.1f * diag * view[k];
    }
    return c;
}

static int ab_section(const scene_in *s, const run_opts *opts) {
    timing t;
    kdr_scene *ta = kd_timed(s, opts_for(INT_MAX, 1), 1, &t);
    kdr_scene *tb = kd_timed(s, opts_for(g_exact_max, 1), 1, &t);
    bench_workload cam, rnd, ao;
    memset(&cam, 0, sizeof cam), memset(&rnd, 0, sizeof rnd), memset(&ao, 0, sizeof ao);
    int fail = !ta || !tb || bench_workload_make(&cam, ta, "camera", opts->rays) ||
               bench_workload_make(&rnd, ta, "random", opts->rays) ||
               bench_workload_make(&ao, ta, "ao_any", opts->rays);
    if (!fail) {
        kdr_tree_stats sa, sb;
        kdr_scene_tree_stats(ta, &sa);
        kdr_scene_tree_stats(tb, &sb);
        printf("ab %s (%zu tris): A = exact, SAH %.1f, %llu nodes; B = exact_max %d, SAH "
               "%.1f, %llu nodes\n",
               s->name, s->ntris, sa.sah_cost, (unsigned long long)sa.nodes,
               g_exact_max >= 0 ? g_exact_max : opts_for(-1, 0).exact_max, sb.sah_cost,
               (unsigned long long)sb.nodes);
        printf("  %-14s %8s %8s %6s | %7s %7s | %7s %7s\n", "rays", "A Mray/s", "B Mray/s",
               "B/A", "nodes A", "nodes B", "tris A", "tris B");
        const kdr_camera c = view_of(ta, opts->rays);
        const work ws[] = {
            {"camera", 0, KDR_CLOSEST, cam.rays, NULL, cam.n, 1, NULL},
            {"random", 0, KDR_CLOSEST, rnd.rays, NULL, rnd.n, 1, NULL},
            {"ao_any", 0, KDR_ANY, ao.rays, NULL, ao.n, 1, NULL},
            {"bundle_camera", 1, KDR_CLOSEST, cam.rays, cam.dir, cam.n, cam.n, NULL},
            {"bundle_ao_any", 1, KDR_ANY, ao.rays, ao.dir, ao.n, BENCH_AO_PER_POINT, NULL},
            {"frustum4", 2, KDR_CLOSEST, NULL, NULL, (size_t)c.width * c.height, 0, &c},
        };
        for (size_t i = 0; i < sizeof ws / sizeof *ws; i++)
            fail |= ab_one(s, ta, tb, &ws[i], opts) != 0;
        fflush(stdout);
    }
    kdr_scene_free(ta);
    kdr_scene_free(tb);
    bench_workload_free(&cam), bench_workload_free(&rnd), bench_workload_free(&ao);
    return fail ? -1 : 0;
}

static int wanted(const char *const *list, int n, const char *name) {
    for (int i = 0; i < n; i++)
        if (!strcmp(list[i], name))
            return 1;
    return n == 0;
}

int main(int argc, char **argv) {
    long cores = sysconf(_SC_NPROCESSORS_ONLN);
    g_threads = cores > 0 ? (int)cores : 1;
    const char *dir = ladder_default_dir(), *csv_path = NULL;
    const char *only[MAX_ONLY], *sections[2];
    int nonly = 0, nsections = 0;
    size_t max_tris = (size_t)-1;
    run_opts o = {262144, 3, NULL};
    for (int i = 1; i < argc; i += 2) {
        const char *f = argv[i], *v = i + 1 < argc ? argv[i + 1] : NULL;
        if (!v)
            goto usage;
        if (!strcmp(f, "--dir"))
            dir = v;
        else if (!strcmp(f, "--only") && nonly < MAX_ONLY)
            only[nonly++] = v;
        else if (!strcmp(f, "--max-tris"))
            max_tris = strtoull(v, NULL, 10);
        else if (!strcmp(f, "--rays") && strtoull(v, NULL, 10) > 0)
            o.rays = strtoull(v, NULL, 10);
        else if (!strcmp(f, "--repeat") && atoi(v) > 0)
            o.repeat = atoi(v);
        else if (!strcmp(f, "--csv"))
            csv_path = v;
        else if (!strcmp(f, "--section") && nsections < 2 &&
                 (!strcmp(v, "build") || !strcmp(v, "ab")))
            sections[nsections++] = v;
        else if (!strcmp(f, "--threads") && atoi(v) >= 1)
            g_threads = atoi(v);
        else if (!strcmp(f, "--exact-max") && atoi(v) >= 0)
            g_exact_max = atoi(v);
        else
            goto usage;
    }
    ladder_entry *v;
    char err[512];
    const int n = ladder_read(dir, &v, err, sizeof err);
    if (n < 0) {
        fprintf(stderr, "%s\n", err);
        return 1;
    }
    if (csv_path && !(o.csv = fopen(csv_path, "w"))) {
        fprintf(stderr, "%s: cannot write\n", csv_path);
        free(v);
        return 1;
    }
    if (o.csv)
        fprintf(o.csv, "scene,triangles,section,metric,value\n");
    int fail = 0;
    for (int i = 0; i < n; i++) {
        if (v[i].triangles > max_tris || !wanted(only, nonly, v[i].name))
            continue;
        float *tris;
        size_t ntris;
        if (ladder_load(&v[i], &tris, &ntris, err, sizeof err) != 0) {
            fprintf(stderr, "%s\n", err);
            fail = 1;
            continue;
        }
        const scene_in s = {v[i].name, tris, ntris};
        if (wanted(sections, nsections, "build"))
            fail |= build_section(&s, &o) != 0;
        if (wanted(sections, nsections, "ab"))
            fail |= ab_section(&s, &o) != 0;
        free(tris);
    }
    if (o.csv)
        fclose(o.csv);
    free(v);
    return fail;
usage:
    fprintf(stderr,
            "usage: %s [--dir DIR] [--only NAME]... [--max-tris N] [--rays N] "
            "[--repeat R] [--csv PATH] [--section build|ab]... [--threads T] "
            "[--exact-max N]\n",
            argv[0]);
    return 2;
}
