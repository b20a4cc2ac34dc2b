/*
 * bench_main.c — the one main of the benchmark programs. Each program is
 * this file built with BENCH_PROGRAM set to its index below; they differ
 * only in the sections and scenes they run by default (--section and
 * --only override both), so any program can run everything in one
 * process.
 */
#include <stddef.h>

#include "bench.h"

#ifndef BENCH_PROGRAM
#error "BENCH_PROGRAM must be set (bench/programs.cmake)"
#endif

static const struct program {
    const char *name;
    const char *sections[2];
    const char *scenes[4]; /* NULL-terminated; none: the whole ladder */
} programs[] = {
    {"kdray_bench", {"core", NULL}, {NULL}},
    {"kdray_bench_bundle", {"bundle", NULL}, {NULL}},
    {"kdray_bench_frustum", {"frustum", NULL}, {NULL}},
    /* engine9: 1.09M triangles, its large light the penumbra-heavy view of a
     * scene past a million triangles (issue 12) */
    {"kdray_bench_cone", {"cone", NULL}, {"default", "engine", "engine9", NULL}},
};

int main(int argc, char **argv) {
    const struct program *p = &programs[BENCH_PROGRAM];
    return bench_main(argc, argv, p->name, p->sections, p->scenes);
}
