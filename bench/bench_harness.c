/*
 * bench_harness.c — the driver, the one timing loop and the summary of
 * bench.h. Scenes come from the ladder (tests/support/ladder.h), so the
 * benchmarks and the accuracy tests run on the same files; each scene's
 * kd-tree and the rival's BVH are built once and shared by all sections,
 * and both builds become the summary's "build" rows.
 */
#define _POSIX_C_SOURCE 200809L
#include "bench.h"

#include <math.h>
#include <stdarg.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "ladder.h"
#include "rival.h"

#define MAX_SELECT 16

double bench_cpu_ms(void) {
    struct timespec ts;
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
    return (double)ts.tv_sec * 1e3 + (double)ts.tv_nsec * 1e-6;
}

/* ---- the timing loop ----------------------------------------------------------- */

static double time_pass(bench_method *m) {
    if (m->prepare)
        m->prepare(m->ctx);
    rival_fp fp = {0};
    if (m->flags & BENCH_RIVAL)
        fp = rival_fp_enter();
    const double t0 = bench_cpu_ms();
    m->run(m->ctx);
    const double dt = bench_cpu_ms() - t0;
    if (m->flags & BENCH_RIVAL)
        rival_fp_leave(fp);
    return dt;
}

static struct {
    const char *prefix[MAX_SELECT];
    int n;
} g_methods;

int bench_method_wanted(const char *name) {
    for (int i = 0; i < g_methods.n; i++)
        if (!strncmp(name, g_methods.prefix[i], strlen(g_methods.prefix[i])))
            return 1;
    return g_methods.n == 0;
}

int bench_method_filtered(void) { return g_methods.n > 0; }

void bench_measure(bench_method *m, size_t n, int repeat, double min_ms) {
    int any = 0;
    for (size_t i = 0; i < n; i++) {
        const int wanted = bench_method_wanted(m[i].name);
        m[i].best_ms = wanted ? INFINITY : NAN;
        any |= wanted;
    }
    const double start = bench_cpu_ms();
    for (int round = 0; any && (round < (repeat > 0 ? repeat : 1) ||
                                bench_cpu_ms() - start < min_ms);
         round++)
        for (size_t i = 0; i < n; i++)
            if (!isnan(m[i].best_ms))
                m[i].best_ms = fmin(m[i].best_ms, time_pass(&m[i]));
}

/* ---- summary ------------------------------------------------------------------- */

typedef struct row {
    char scene[64], workload[64], method[64];
    size_t tris, rays;
    double ms, npr;
} row;

static struct {
    row *v;
    size_t n, cap;
    int failures;
} g_sum;

static row *find_row(const char *scene, const char *workload, const char *method) {
    for (size_t i = 0; i < g_sum.n; i++)
        if (!strcmp(g_sum.v[i].scene, scene) && !strcmp(g_sum.v[i].workload, workload) &&
            !strcmp(g_sum.v[i].method, method))
            return &g_sum.v[i];
    return NULL;
}

void bench_summary_add(const bench_scene *s, const char *workload,
                       const char *method, size_t rays, double ms,
                       double nodes_per_ray) {
    row *r = find_row(s->name, workload, method);
    if (r) {
        r->ms = fmin(r->ms, ms);
        return;
    }
    if (g_sum.n == g_sum.cap) {
        const size_t cap = g_sum.cap ? 2 * g_sum.cap : 256;
        row *v = realloc(g_sum.v, cap * sizeof *v);
        if (!v) {
            bench_fail("out of memory for the summary");
            return;
        }
        g_sum.v = v, g_sum.cap = cap;
    }
    r = &g_sum.v[g_sum.n++];
    memset(r, 0, sizeof *r);
    snprintf(r->scene, sizeof r->scene, "%s", s->name);
    snprintf(r->workload, sizeof r->workload, "%s", workload);
    snprintf(r->method, sizeof r->method, "%s", method);
    r->tris = s->ntris, r->rays = rays, r->ms = ms, r->npr = nodes_per_ray;
}

double bench_summary_ms(const char *scene, const char *workload, const char *method) {
    const row *r = find_row(scene, workload, method);
    return r ? r->ms : -1.0;
}

static int is_rival_row(const row *r) {
    return !strncmp(r->method, "embree_", 7) && strncmp(r->method, "embree_robust_", 14);
}

const char *bench_summary_rival(const char *scene, const char *workload,
                                double *ms) {
    const row *best = NULL;
    for (size_t i = 0; i < g_sum.n; i++) {
        const row *r = &g_sum.v[i];
        if (is_rival_row(r) && !strcmp(r->scene, scene) &&
            !strcmp(r->workload, workload) && (!best || r->ms < best->ms))
            best = r;
    }
    if (ms)
        *ms = best ? best->ms : 0.0;
    return best ? best->method : NULL;
}

double bench_summary_geomean(const char *prefix, const char *method, int rival) {
    double sum = 0.0;
    int n = 0;
    for (size_t i = 0; i < g_sum.n; i++) {
        const row *r = &g_sum.v[i];
        if (strncmp(r->workload, prefix, strlen(prefix)) || strcmp(r->method, method))
            continue;
        double best = 0.0;
        if (rival && !bench_summary_rival(r->scene, r->workload, &best))
            continue;
        sum += log(rival ? best / r->ms : r->ms);
        n++;
    }
    return n ? exp(sum / n) : 0.0;
}

void bench_summary_write(FILE *f) {
    fprintf(
        f,
        "scene,triangles,workload,method,rays,ms,mrays,nodes_per_ray,rival,vs_rival\n");
    for (size_t i = 0; i < g_sum.n; i++) {
        const row *r = &g_sum.v[i];
        double best = 0.0;
        const char *rv = bench_summary_rival(r->scene, r->workload, &best);
        fprintf(f, "%s,%zu,%s,%s,%zu,%.4f,", r->scene, r->tris, r->workload, r->method,
                r->rays, r->ms);
        if (r->rays)
            fprintf(f, "%.4f", (double)r->rays / (r->ms * 1e3));
        fprintf(f, ",");
        if (r->npr >= 0)
            fprintf(f, "%.2f", r->npr);
        fprintf(f, ",%s,", rv ? rv : "");
        if (rv)
            fprintf(f, "%.4f", best / r->ms);
        fprintf(f, "\n");
    }
    fflush(f);
}

void bench_fail(const char *fmt, ...) {
    va_list ap;
    va_start(ap, fmt);
    fprintf(stderr, "CHECK FAILED: ");
    vfprintf(stderr, fmt, ap);
    fprintf(stderr, "\n");
    va_end(ap);
    g_sum.failures++;
}

/* ---- flags --------------------------------------------------------------------- */

typedef struct driver {
    const char *dir, *csv_path;
    size_t max_tris;
    const char *only[MAX_SELECT], *sections[MAX_SELECT];
    int nonly, nsections;
    bench_opts opts;
} driver;

static int parse_samples(const char *v, bench_opts *o) {
    o->nsamples = 0;
    for (const char *p = v; *p && o->nsamples < BENCH_MAX_SAMPLES;) {
        char *end;
        const unsigned long s = strtoul(p, &end, 10);
        if (end == p || s < 1 || s > 4096)
            return -1;
        o->samples[o->nsamples++] = (uint32_t)s;
        p = *end == ',' ? end + 1 : end;
        if (*end && *end != ',')
            return -1;
    }
    return o->nsamples > 0 ? 0 : -1;
}

static int parse_flags(int argc, char **argv, driver *d) {
    bench_opts *o = &d->opts;
    d->dir = ladder_default_dir();
    d->max_tris = (size_t)-1;
    o->rays = BENCH_DEFAULT_RAYS;
    o->repeat = BENCH_DEFAULT_REPEAT;
    o->frame = 1000;
    o->ref_samples = -1; /* 4096, or none with --quick */
    o->res = 64;
    for (uint32_t s = 1; s <= 256; s *= 2)
        o->samples[o->nsamples++] = s;
    for (int i = 1; i < argc; i++) {
        const char *f = argv[i];
        if (!strcmp(f, "--quick")) {
            o->quick = 1;
            continue;
        }
        const char *v = i + 1 < argc ? argv[++i] : NULL;
        if (!v)
            return -1;
        if (!strcmp(f, "--dir"))
            d->dir = v;
        else if (!strcmp(f, "--csv"))
            d->csv_path = v;
        else if (!strcmp(f, "--rays"))
            o->rays = strtoul(v, NULL, 10);
        else if (!strcmp(f, "--repeat"))
            o->repeat = atoi(v);
        else if (!strcmp(f, "--max-tris"))
            d->max_tris = strtoul(v, NULL, 10);
        else if (!strcmp(f, "--frame"))
            o->frame = (uint32_t)strtoul(v, NULL, 10);
        else if (!strcmp(f, "--samples")) {
            if (parse_samples(v, o))
                return -1;
        } else if (!strcmp(f, "--ref-samples"))
            o->ref_samples = atoi(v);
        else if (!strcmp(f, "--res"))
            o->res = atoi(v);
        else if (!strcmp(f, "--out"))
            o->out_prefix = v;
        else if (!strcmp(f, "--only") && d->nonly < MAX_SELECT)
            d->only[d->nonly++] = v;
        else if (!strcmp(f, "--section") && d->nsections < MAX_SELECT)
            d->sections[d->nsections++] = v;
        else if (!strcmp(f, "--method") && g_methods.n < MAX_SELECT)
            g_methods.prefix[g_methods.n++] = v;
        else
            return -1;
    }
    if (o->ref_samples < 0)
        o->ref_samples = o->quick ? 0 : 4096;
    if (o->rays < 64 || o->repeat < 1 || o->frame < 8 || o->res < 4 ||
        o->ref_samples > 4096)
        return -1;
    return 0;
}

static void usage(const char *program) {
    fprintf(stderr,
            "usage: %s [--dir DIR] [--only SCENE]... [--max-tris N] [--section NAME]...\n"
            "       [--rays N] [--repeat R] [--quick] [--frame N] [--samples A,B,..]\n"
            "       [--ref-samples N] [--res N] [--out PREFIX] [--method PREFIX]...\n"
            "       [--csv PATH]\n"
            "sections: core, bundle, frustum, cone, cone_split, queries (see bench/bench.h)\n",
            program);
}

/* ---- driver -------------------------------------------------------------------- */

static const bench_section *const g_sections[] = {
    &bench_core_section, &bench_bundle_section, &bench_frustum_section,
    &bench_cone_section, &bench_cone_split_section, &bench_queries_section};
#define NSECTIONS (sizeof g_sections / sizeof *g_sections)

static int listed(const char *const *list, int n, const char *name) {
    for (int i = 0; i < n; i++)
        if (!strcmp(list[i], name))
            return 1;
    return 0;
}

static int run_scene(const driver *d, const ladder_entry *e,
                     const bench_section **run, size_t nrun) {
    char err[512];
    float *tris;
    size_t ntris;
    if (ladder_load(e, &tris, &ntris, err, sizeof err) != 0) {
        fprintf(stderr, "%s\n", err);
        return -1;
    }
    kdr_scene *kd = NULL;
    const double t0 = bench_cpu_ms();
    const int rc = kdr_scene_build(tris, ntris, NULL, NULL, NULL, &kd);
    const double kd_ms = bench_cpu_ms() - t0;
    rival *emb = rc == KDR_OK ? rival_create(tris, ntris, 0, RIVAL_QUALITY) : NULL;
    if (!emb) {
        fprintf(stderr, "%s: build failed: %s\n", e->name,
                rc != KDR_OK ? kdr_strerror(rc) : "Embree");
        kdr_scene_free(kd);
        free(tris);
        return -1;
    }
    const bench_scene s = {e->name, tris, ntris, kd, kd_ms, emb};
    bench_summary_add(&s, "build", "kd_build", 0, kd_ms, -1);
    bench_summary_add(&s, "build", "embree_build_high", 0, rival_build_ms(emb), -1);
    int fail = 0;
    for (size_t i = 0; i < nrun; i++)
        fail |= run[i]->run(&s, &d->opts) != 0;
    rival_free(emb);
    kdr_scene_free(kd);
    free(tris);
    return fail ? -1 : 0;
}

int bench_main(int argc, char **argv, const char *program,
               const char *const *default_sections,
               const char *const *default_scenes) {
    driver d;
    memset(&d, 0, sizeof d);
    if (parse_flags(argc, argv, &d) != 0) {
        usage(program);
        return 2;
    }
    for (; d.nsections == 0 && *default_sections; default_sections++)
        d.sections[d.nsections++] = *default_sections;
    if (d.nonly == 0)
        for (; *default_scenes && d.nonly < MAX_SELECT; default_scenes++)
            d.only[d.nonly++] = *default_scenes;
    const bench_section *run[NSECTIONS];
    size_t nrun = 0;
    for (int i = 0; i < d.nsections; i++) {
        size_t k = 0;
        while (k < NSECTIONS && strcmp(g_sections[k]->name, d.sections[i]))
            k++;
        if (k == NSECTIONS) {
            usage(program);
            return 2;
        }
        run[nrun++] = g_sections[k];
    }
    ladder_entry *v;
    char err[512];
    const int n = d.dir ? ladder_read(d.dir, &v, err, sizeof err) : -1;
    if (n < 0) {
        fprintf(stderr, "%s: %s\n", program, d.dir ? err : "no ladder (--dir DIR)");
        return 1;
    }
    printf("%s: sections", program);
    for (size_t i = 0; i < nrun; i++)
        printf(" %s", run[i]->name);
    printf("; one thread, process CPU time, best of %d%s\n", d.opts.repeat,
           d.opts.quick ? ", quick subset" : "");
    int fail = rival_print_setup(stdout) != 0;
    int scenes = 0;
    for (int i = 0; i < n; i++)
        if (v[i].triangles <= d.max_tris &&
            (d.nonly == 0 || listed(d.only, d.nonly, v[i].name))) {
            fail |= run_scene(&d, &v[i], run, nrun) != 0;
            scenes++;
        }
    free(v);
    if (scenes == 0) {
        fprintf(stderr, "%s: no ladder scene selected\n", program);
        return 1;
    }
    for (size_t i = 0; i < nrun; i++)
        if (run[i]->finish)
            run[i]->finish(&d.opts);
    printf("\n== summary (CSV; vs_rival = time of the fastest Embree API / this "
           "method's time)\n");
    bench_summary_write(stdout);
    if (d.csv_path) {
        FILE *f = fopen(d.csv_path, "w");
        if (!f) {
            fprintf(stderr, "%s: cannot write\n", d.csv_path);
            return 1;
        }
        bench_summary_write(f);
        fclose(f);
    }
    if (g_sum.failures)
        fprintf(stderr, "%s: %d check(s) failed\n", program, g_sum.failures);
    return fail || g_sum.failures ? 1 : 0;
}
