/*
 * caps.c — the recorded class counts of every Embree-judged ctest gate and
 * the check against them (caps.h). To re-measure after a change that moves
 * rays between classes on purpose: run the test with --caps NAME; for each
 * tally that differs it prints the row as measured, ready to paste below
 * (and say why in the commit and in docs/ACCURACY.md).
 */
#include "caps.h"

#include <string.h>

#include "kdray.h"

/* Margin of a cap over its measured count: 1% plus 4 rays. The counts are
 * exact for one build of the core (the judge's Embree is pinned to AVX2,
 * oracle.h ORACLE_JUDGE_CONFIG, so the CPU does not move them); the margin
 * absorbs the few rays a core change that is not about accuracy may move
 * (between d3ec2c8 and b60fc84: 1 to 2 rays per class on the full ladder),
 * and nothing like a regression that moves a class by tens of rays. */
#define CAP_REL_DIV 100
#define CAP_ABS 4

#define FIRST_CAPPED CMP_TIE
#define NCAPPED (CMP_ILL_COND - CMP_TIE + 1)

typedef struct cap_row {
    const char *test, *tally;
    uint64_t rays;         /* rays the counts were measured on */
    uint64_t n[NCAPPED];   /* tie, edge, interval_end, parallel, ill_cond */
} cap_row;

/* Measured with ctest's arguments (the tests/ cmake fragments; each
 * program's stress seeds; the ladder of scenes/fetch), EDGE_ULPS 16,
 * Embree 3.13.5 at max_isa=avx2, on the core of b60fc84. */
static const cap_row rows[] = {
    /* test                       tally                     rays
     *                               tie   edge  int.end  parallel ill_cond */
    {"accuracy_single", "single closest", 56000, {10479, 2219, 33, 818, 119}},
    {"accuracy_single", "single any", 56000, {0, 1435, 10, 627, 0}},
    {"accuracy_bundle4", "bundle4 closest", 56000, {10479, 2219, 33, 818, 119}},
    {"accuracy_bundle4", "bundle4 any", 56000, {0, 1435, 10, 627, 0}},
    {"accuracy_bundle8", "bundle8 closest", 56000, {10479, 2219, 33, 818, 119}},
    {"accuracy_bundle8", "bundle8 any", 56000, {0, 1435, 10, 627, 0}},
    {"accuracy_frustum_multi4", "frustum_multi4 closest", 54747, {5396, 149, 0, 0, 0}},
    {"accuracy_frustum_multi4", "frustum_multi4 any", 54747, {0, 25, 0, 0, 0}},
    {"accuracy_frustum_single", "frustum_single closest", 54747, {5396, 149, 0, 0, 0}},
    {"accuracy_frustum_single", "frustum_single any", 54747, {0, 25, 0, 0, 0}},
    {"accuracy_cone_shadow", "cone_shadow any", 23296, {0, 2, 0, 0, 0}},
    {"embree_stress", "TOTAL closest", 168000, {32038, 6699, 114, 2354, 313}},
    {"embree_stress", "TOTAL any", 168000, {0, 4345, 46, 1760, 0}},
    {"embree_ladder", "TOTAL closest", 192000, {29666, 5207, 192, 364, 13}},
    {"embree_ladder", "TOTAL any", 192000, {0, 3363, 46, 169, 0}},
    /* 880000: the ladder's 11th rung, distinct (1M triangles), adds 80000
     * rays; the other ten rungs' counts are unchanged (binned top at 65536,
     * corebuild branch) */
    {"embree_ladder_all", "TOTAL closest", 880000, {128479, 21389, 615, 2778, 64}},
    {"embree_ladder_all", "TOTAL any", 880000, {0, 12985, 156, 1363, 0}},
    {"embree_ref", "TOTAL brute force vs Embree", 112000, {21355, 4288, 74, 1635, 210}},
    {"cone", "cone samples vs embree", 720, {0, 0, 0, 0, 0}},
    {"frustum", "frustum vs embree", 4058, {0, 0, 0, 0, 0}},
    {NULL, NULL, 0, {0}},
};

const char *caps_arg(int *argc, char **argv) {
    for (int i = 1; i + 1 < *argc; i++) {
        if (strcmp(argv[i], "--caps") != 0)
            continue;
        const char *name = argv[i + 1];
        for (int j = i; j + 2 <= *argc; j++)
            argv[j] = argv[j + 2];
        *argc -= 2;
        return name;
    }
    return NULL;
}

uint64_t caps_limit(uint64_t measured) {
    return measured + measured / CAP_REL_DIV + CAP_ABS;
}

static const cap_row *find_row(const char *test, const char *tally) {
    for (size_t i = 0; rows[i].test; i++)
        if (strcmp(rows[i].test, test) == 0 && strcmp(rows[i].tally, tally) == 0)
            return &rows[i];
    return NULL;
}

/* The tally as a row of the table above. */
static void print_row(FILE *f, const char *test, const char *tally,
                      const cmp_tally *t) {
    fprintf(f, "  measured row: {\"%s\", \"%s\", %llu, {", test, tally,
            (unsigned long long)t->rays);
    for (int c = 0; c < NCAPPED; c++)
        fprintf(f, "%s%llu", c ? ", " : "",
                (unsigned long long)t->n[FIRST_CAPPED + c]);
    fprintf(f, "}},\n");
}

int caps_check(FILE *f, const char *test, const char *tally, const cmp_tally *t) {
    if (!test) {
        fprintf(f, "caps: not checked for %s (no --caps)\n", tally);
        return 0;
    }
    const cap_row *r = find_row(test, tally);
    if (!r) {
        if (t->rays == 0)
            return 0; /* nothing judged, nothing to bound */
        fprintf(f, "CAPS: no recorded counts for %s %s\n", test, tally);
        print_row(f, test, tally, t);
        return 1;
    }
    int bad = 0;
    if (t->rays != r->rays) {
        fprintf(f, "CAPS: %s %s judged %llu rays, the caps were measured on "
                   "%llu: re-measure\n", test, tally,
                (unsigned long long)t->rays, (unsigned long long)r->rays);
        bad++;
    }
    for (int c = 0; c < NCAPPED; c++) {
        const uint64_t got = t->n[FIRST_CAPPED + c];
        const uint64_t cap = caps_limit(r->n[c]);
        if (got > cap) {
            fprintf(f, "CAP EXCEEDED: %s %s: class %s has %llu rays, cap %llu "
                       "(measured %llu)\n", test, tally,
                    cmp_class_name((cmp_class)(FIRST_CAPPED + c)),
                    (unsigned long long)got, (unsigned long long)cap,
                    (unsigned long long)r->n[c]);
            bad++;
        }
    }
    int same = t->rays == r->rays;
    for (int c = 0; c < NCAPPED; c++)
        same &= t->n[FIRST_CAPPED + c] == r->n[c];
    if (!same)
        print_row(f, test, tally, t);
    if (bad && !kdr_cpu_has_avx2())
        fprintf(f, "  (this CPU has no AVX2: Embree runs a narrower ISA than the "
                   "counts were measured with, ORACLE_JUDGE_CONFIG)\n");
    fprintf(f, "caps: %s %s: %s\n", test, tally, bad ? "FAILED" : "within caps");
    return bad;
}
