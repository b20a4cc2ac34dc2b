/*
 * tree_digest.c — kdray-tree-digest: not a test, the tool that proves a
 * build change did (or did not) change the trees. For every ladder scene it
 * builds the kd-tree and prints its statistics, the build's wall and CPU
 * time, and 64-bit FNV-1a digests of the node array and of the leaf
 * reference array, so two commits (or two option sets) can be compared line
 * by line: equal digests mean byte-identical trees.
 *
 *   kdray-tree-digest [--dir DIR] [--max-tris N] [--only NAME]...
 *                     [--threads N] [--exact-max N] [--repeat R]
 *
 * --threads and --exact-max set kdr_build_opts (defaults: the library's);
 * with --repeat R the build runs R times and the fastest is printed.
 *
 * "idle>=" is a lower bound of the wall time on an idle machine: the
 * build's CPU time outside its parallel phase plus the CPU time of that
 * phase's busiest thread (from the build's log line; with one thread, the
 * CPU time). All times are the best of --repeat.
 * It reads the built scene's internals (kd_internal.h), which only core
 * tools and tests may do.
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

typedef struct args {
    const char *dir;
    size_t max_tris;
    const char *only[MAX_ONLY];
    int nonly;
    int threads, exact_max, repeat; /* exact_max < 0: the default */
} args;

static int parse(int argc, char **argv, args *a) {
    a->dir = ladder_default_dir();
    a->max_tris = (size_t)-1;
    a->exact_max = -1;
    a->repeat = 1;
    for (int i = 1; i < argc; i += 2) {
        const char *f = argv[i], *v = i + 1 < argc ? argv[i + 1] : NULL;
        if (!v)
            return -1;
        if (!strcmp(f, "--dir"))
            a->dir = v;
        else if (!strcmp(f, "--max-tris"))
            a->max_tris = strtoull(v, NULL, 10);
        else if (!strcmp(f, "--only") && a->nonly < MAX_ONLY)
            a->only[a->nonly++] = v;
        else if (!strcmp(f, "--threads"))
            a->threads = atoi(v);
        else if (!strcmp(f, "--exact-max"))
            a->exact_max = atoi(v);
        else if (!strcmp(f, "--repeat") && atoi(v) > 0)
            a->repeat = atoi(v);
        else
            return -1;
    }
    return 0;
}

static int wanted(const args *a, const ladder_entry *e) {
    if (e->triangles > a->max_tris)
        return 0;
    for (int i = 0; i < a->nonly; i++)
        if (!strcmp(a->only[i], e->name))
            return 1;
    return a->nonly == 0;
}

/* The build's log line "... (CPU: busiest thread X ms, all Y ms)". */
static void log_busiest(void *user, const char *msg) {
    const char *p = strstr(msg, "busiest thread ");
    double *v = user;
    if (p && sscanf(p, "busiest thread %lf ms, all %lf", &v[0], &v[1]) != 2)
        v[0] = v[1] = 0;
}

static int run(const args *a, const ladder_entry *e) {
    char err[512];
    float *tris;
    size_t ntris;
    if (ladder_load(e, &tris, &ntris, err, sizeof err) != 0) {
        fprintf(stderr, "%s\n", err);
        return -1;
    }
    kdr_build_opts o;
    kdr_build_opts_default(&o);
    o.threads = a->threads;
    if (a->exact_max >= 0)
        o.exact_max = a->exact_max;
    kdr_scene *s = NULL;
    double wall = 0, cpu = 0, bound = 0;
    for (int r = 0; r < a->repeat; r++) {
        kdr_scene_free(s);
        double busy[2] = {0, 0};
        const double w0 = th_clock_ms(CLOCK_MONOTONIC);
        const double c0 = th_clock_ms(CLOCK_PROCESS_CPUTIME_ID);
        const int rc = kdr_scene_build(tris, ntris, &o, log_busiest, busy, &s);
        const double w = th_clock_ms(CLOCK_MONOTONIC) - w0;
        const double c = th_clock_ms(CLOCK_PROCESS_CPUTIME_ID) - c0;
        if (rc != KDR_OK) {
            fprintf(stderr, "%s: %s\n", e->name, kdr_strerror(rc));
            free(tris);
            return -1;
        }
        if (r == 0 || w < wall)
            wall = w;
        if (r == 0 || c < cpu)
            cpu = c;
        /* serial CPU before and after the parallel phase, plus its
         * busiest thread: what an idle machine needs at least */
        const double b = busy[1] > 0 ? c - busy[1] + busy[0] : c;
        if (r == 0 || b < bound)
            bound = b;
    }
    free(tris);
    uint64_t dig[2];
    th_tree_digest(s, dig);
    printf("%-10s %8zu %8zu %8zu %5llu %9.2f %8.1f %8.1f %8.1f  %016llx %016llx\n",
           e->name, ntris, s->nnodes, s->nrefs,
           (unsigned long long)s->stats.max_depth, s->stats.sah_cost, wall, cpu, bound,
           (unsigned long long)dig[0], (unsigned long long)dig[1]);
    fflush(stdout);
    kdr_scene_free(s);
    return 0;
}

int main(int argc, char **argv) {
    args a;
    memset(&a, 0, sizeof a);
    if (parse(argc, argv, &a) != 0) {
        fprintf(stderr,
                "usage: %s [--dir DIR] [--max-tris N] [--only NAME]... "
                "[--threads N] [--exact-max N] [--repeat R]\n",
                argv[0]);
        return 2;
    }
    ladder_entry *v;
    char err[512];
    const int n = ladder_read(a.dir, &v, err, sizeof err);
    if (n < 0) {
        fprintf(stderr, "%s\n", err);
        return 1;
    }
    printf("%-10s %8s %8s %8s %5s %9s %8s %8s %8s  %-16s %-16s\n", "scene", "tris",
           "nodes", "refs", "depth", "SAH", "wall ms", "cpu ms", "idle>=",
           "nodes digest", "refs digest");
    int fail = 0;
    for (int i = 0; i < n; i++)
        if (wanted(&a, &v[i]))
            fail |= run(&a, &v[i]) != 0;
    free(v);
    return fail;
}
