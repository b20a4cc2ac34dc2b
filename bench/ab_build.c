/*
 * ab_build.c — kdray_ab_build: the kd-tree build of two revisions of the
 * core in ONE process (bench/ab_build links it, as bench/ab does for
 * traversal: A's and B's libkdray_core.a with their global symbols renamed
 * A_... and B_...). Not a test: a build change is judged by it.
 *
 * For each ladder scene and each thread count of --threads (repeatable;
 * default 1 and 2) it builds A's and B's trees in --rounds rounds,
 * alternating which goes first, and prints per side the best and median
 * CPU time of the process (all threads) and wall time, then the median of
 * the per-round ratios B/A. It also prints both trees' node and reference
 * digests (FNV-1a over the arrays, as kdray-tree-digest does) and says
 * whether they are byte-identical; with --same it exits 1 when they are
 * not (for changes that must not change the tree). The digests read the
 * scene's internals through this tree's kd_internal.h, so both revisions
 * must share its layout (bench/ab_build is for build changes).
 *
 *   kdray_ab_build [--dir DIR] [--only NAME]... [--rounds R] [--threads T]...
 *                  [--same] [--side A|B]
 *
 * --side A (or B) builds only that side, R times, and prints one line per
 * scene and thread count: "side SCENE TRIS T" and then process CPU, wall
 * and idle>= ms of the first build and the best of the R, and the digests.
 * idle>= is the build's CPU outside its parallel phase plus that phase's
 * busiest thread (from the build's log line), a lower bound of the wall
 * time on an idle machine. bench/ab_build --separate N runs N such
 * processes per side, alternated, so that neither revision's build reuses
 * the pages the other one faulted in and freed.
 */
#define _POSIX_C_SOURCE 200809L
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "kd_internal.h"
#include "ladder.h"
#include "tree_hash.h"

#define MAX_ONLY 16
#define MAX_THREADS_SET 8
#define MAX_ROUNDS 64

int A_kdr_scene_build(const float *, size_t, const kdr_build_opts *, kdr_log_fn,
                      void *, kdr_scene **);
void A_kdr_scene_free(kdr_scene *);
void A_kdr_build_opts_default(kdr_build_opts *);
int B_kdr_scene_build(const float *, size_t, const kdr_build_opts *, kdr_log_fn,
                      void *, kdr_scene **);
void B_kdr_scene_free(kdr_scene *);
void B_kdr_build_opts_default(kdr_build_opts *);

typedef struct core_api {
    int (*build)(const float *, size_t, const kdr_build_opts *, kdr_log_fn,
                 void *, kdr_scene **);
    void (*release)(kdr_scene *);
    void (*defaults)(kdr_build_opts *);
} core_api;

static const core_api cores[2] = {
    {A_kdr_scene_build, A_kdr_scene_free, A_kdr_build_opts_default},
    {B_kdr_scene_build, B_kdr_scene_free, B_kdr_build_opts_default}};

static int cmp_double(const void *a, const void *b) {
    const double x = *(const double *)a, y = *(const double *)b;
    return x < y ? -1 : x > y;
}

static double median(const double *v, int n) {
    double s[MAX_ROUNDS];
    memcpy(s, v, (size_t)n * sizeof *s);
    qsort(s, (size_t)n, sizeof *s, cmp_double);
    return n % 2 ? s[n / 2] : 0.5 * (s[n / 2 - 1] + s[n / 2]);
}

static double best(const double *v, int n) {
    double m = v[0];
    for (int i = 1; i < n; i++)
        m = v[i] < m ? v[i] : m;
    return m;
}

typedef struct args {
    const char *dir;
    const char *only[MAX_ONLY];
    int nonly, rounds, same;
    int side; /* -1: both, alternating; 0 or 1: --side A or B alone */
    int threads[MAX_THREADS_SET], nthreads;
} args;

/* The build's log line "... (CPU: busiest thread X ms, all Y ms)". */
static void log_cpu(void *user, const char *msg) {
    const char *p = strstr(msg, "busiest thread ");
    double *v = user;
    if (p && sscanf(p, "busiest thread %lf ms, all %lf", &v[0], &v[1]) != 2)
        v[0] = v[1] = 0;
}

/* One build of side c: its CPU and wall ms, its idle>= bound (NULL: not
 * wanted) and the tree's digests. */
static int build_one(int c, const float *tris, size_t ntris, int threads,
                     double *cpu, double *wall, double *idle, uint64_t dig[2]) {
    kdr_build_opts o;
    cores[c].defaults(&o);
    o.threads = threads;
    kdr_scene *s = NULL;
    double busy[2] = {0, 0};
    const double c0 = th_clock_ms(CLOCK_PROCESS_CPUTIME_ID), w0 = th_clock_ms(CLOCK_MONOTONIC);
    const int err = cores[c].build(tris, ntris, &o, idle ? log_cpu : NULL, busy, &s);
    *wall = th_clock_ms(CLOCK_MONOTONIC) - w0;
    *cpu = th_clock_ms(CLOCK_PROCESS_CPUTIME_ID) - c0;
    if (idle)
        *idle = busy[1] > 0 ? *cpu - busy[1] + busy[0] : *cpu;
    if (err != KDR_OK)
        return err;
    th_tree_digest(s, dig);
    cores[c].release(s);
    return KDR_OK;
}

/* --side: a->rounds builds of one side; the first and the best. */
static int run_side(const args *a, const ladder_entry *e, const float *tris,
                    size_t ntris) {
    for (int ti = 0; ti < a->nthreads; ti++) {
        double cpu[MAX_ROUNDS] = {0}, wall[MAX_ROUNDS] = {0}, idle[MAX_ROUNDS] = {0};
        uint64_t dig[2] = {0, 0};
        for (int r = 0; r < a->rounds; r++) {
            if (build_one(a->side, tris, ntris, a->threads[ti], &cpu[r], &wall[r],
                          &idle[r], dig) != KDR_OK) {
                fprintf(stderr, "%s: build %c failed\n", e->name, 'A' + a->side);
                return 1;
            }
        }
        printf("side %c %s %zu %d first %.3f %.3f %.3f best %.3f %.3f %.3f %016llx "
               "%016llx\n",
               'A' + a->side, e->name, ntris, a->threads[ti], cpu[0], wall[0], idle[0],
               best(cpu, a->rounds), best(wall, a->rounds), best(idle, a->rounds),
               (unsigned long long)dig[0], (unsigned long long)dig[1]);
        fflush(stdout);
    }
    return 0;
}

static int run_scene(const args *a, const ladder_entry *e) {
    float *tris;
    size_t ntris;
    char err[256];
    if (ladder_load(e, &tris, &ntris, err, sizeof err) != 0) {
        fprintf(stderr, "%s: %s\n", e->name, err);
        return 1;
    }
    if (a->side >= 0) {
        const int bad = run_side(a, e, tris, ntris);
        free(tris);
        return bad;
    }
    int bad = 0;
    for (int ti = 0; ti < a->nthreads; ti++) {
        double cpu[2][MAX_ROUNDS], wall[2][MAX_ROUNDS], rc[MAX_ROUNDS], rw[MAX_ROUNDS];
        uint64_t dig[2][2] = {{0, 0}, {0, 0}};
        for (int r = 0; r < a->rounds; r++) {
            for (int i = 0; i < 2; i++) {
                const int c = (r + i) % 2; /* A first on even rounds */
                if (build_one(c, tris, ntris, a->threads[ti], &cpu[c][r], &wall[c][r],
                              NULL, dig[c]) != KDR_OK) {
                    fprintf(stderr, "%s: build %c failed\n", e->name, 'A' + c);
                    free(tris);
                    return 1;
                }
            }
            rc[r] = cpu[1][r] / cpu[0][r];
            rw[r] = wall[1][r] / wall[0][r];
        }
        const int same = dig[0][0] == dig[1][0] && dig[0][1] == dig[1][1];
        double rmin = rc[0], rmax = rc[0];
        for (int r = 1; r < a->rounds; r++) {
            rmin = rc[r] < rmin ? rc[r] : rmin;
            rmax = rc[r] > rmax ? rc[r] : rmax;
        }
        printf("%-10s %8zu %2d | %8.1f %8.1f %8.1f %8.1f | %8.1f %8.1f %8.1f %8.1f | "
               "%6.3f (%5.3f-%5.3f) %6.3f | %016llx %016llx %s\n",
               e->name, ntris, a->threads[ti], best(cpu[0], a->rounds),
               median(cpu[0], a->rounds), best(wall[0], a->rounds),
               median(wall[0], a->rounds), best(cpu[1], a->rounds),
               median(cpu[1], a->rounds), best(wall[1], a->rounds),
               median(wall[1], a->rounds), median(rc, a->rounds), rmin, rmax,
               median(rw, a->rounds), (unsigned long long)dig[1][0],
               (unsigned long long)dig[1][1], same ? "same" : "DIFFERENT");
        fflush(stdout);
        bad |= a->same && !same;
    }
    free(tris);
    return bad;
}

static int parse(int argc, char **argv, args *a) {
    memset(a, 0, sizeof *a);
    a->dir = ladder_default_dir();
    a->rounds = 5;
    a->side = -1;
    for (int i = 1; i < argc; i++) {
        const char *f = argv[i];
        if (strcmp(f, "--same") == 0) {
            a->same = 1;
            continue;
        }
        if (i + 1 >= argc)
            return -1;
        const char *v = argv[++i];
        if (strcmp(f, "--dir") == 0)
            a->dir = v;
        else if (strcmp(f, "--only") == 0 && a->nonly < MAX_ONLY)
            a->only[a->nonly++] = v;
        else if (strcmp(f, "--rounds") == 0)
            a->rounds = atoi(v);
        else if (strcmp(f, "--threads") == 0 && a->nthreads < MAX_THREADS_SET)
            a->threads[a->nthreads++] = atoi(v);
        else if (strcmp(f, "--side") == 0 && (strcmp(v, "A") == 0 || strcmp(v, "B") == 0))
            a->side = v[0] - 'A';
        else
            return -1;
    }
    if (a->rounds < 1 || a->rounds > MAX_ROUNDS)
        return -1;
    if (a->nthreads == 0) {
        a->threads[0] = 1;
        a->threads[1] = 2;
        a->nthreads = 2;
    }
    return 0;
}

int main(int argc, char **argv) {
    args a;
    if (parse(argc, argv, &a) != 0) {
        fprintf(stderr,
                "usage: %s [--dir DIR] [--only NAME]... [--rounds R (1-%d, default 5)] "
                "[--threads T]... [--same] [--side A|B]\n",
                argv[0], MAX_ROUNDS);
        return 2;
    }
    ladder_entry *v;
    char err[256];
    const int n = ladder_read(a.dir, &v, err, sizeof err);
    if (n < 0) {
        fprintf(stderr, "%s\n", err);
        return 1;
    }
    if (a.side < 0) {
        printf("build A vs B, %d rounds (order alternating); ms: best and median of "
               "process CPU, best and median wall; B/A: median of per-round CPU "
               "ratios (range), median wall ratio; B's digests\n",
               a.rounds);
        printf("%-10s %8s %2s | %8s %8s %8s %8s | %8s %8s %8s %8s | %s\n", "scene",
               "tris", "T", "A cpu", "A cpu~", "A wall", "A wall~", "B cpu", "B cpu~",
               "B wall", "B wall~", "B/A cpu (range) wall | nodes, refs digest");
    }
    int bad = 0;
    for (int i = 0; i < n; i++) {
        int want = a.nonly == 0;
        for (int j = 0; j < a.nonly; j++)
            want |= strcmp(a.only[j], v[i].name) == 0;
        if (want)
            bad |= run_scene(&a, &v[i]);
    }
    free(v);
    return bad;
}
