/*
 * caps.c — the recorded class counts of every Embree-judged ctest gate and
 * the check against them (caps.h). To re-measure after a change that moves
 * rays between classes on purpose: run the test with --caps NAME; for each
 * tally that differs it prints the row as measured, ready to paste below
 * (and say why in the commit and in docs/ACCURACY.md).
 */
#include "caps.h"

#include <stdlib.h>
#include <string.h>
#if defined(__x86_64__) || defined(__i386__)
#include <cpuid.h>
#endif

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
    const char *vendor; /* CPU vendor the counts were measured on; NULL: any */
    const char *test, *tally;
    uint64_t rays;       /* rays the counts were measured on */
    uint64_t n[NCAPPED]; /* tie, edge, interval_end, parallel, ill_cond */
} cap_row;

/* Measured with ctest's arguments (the tests/ cmake fragments; each
 * program's stress seeds; the ladder of scenes/fetch), EDGE_ULPS 16,
 * Embree 3.13.5 at max_isa=avx2, on the core of b60fc84 (AMD EPYC, Zen 5).
 *
 * Embree's answers, and so the counts, depend on the CPU's vendor even at
 * one ISA, most likely through the approximate reciprocal its fast
 * intersectors start from (rcpps and a Newton step), whose low bits differ
 * between AMD's and Intel's implementations: a ray at an edge or a tie may
 * land on the other triangle. On an Intel Xeon (family 6 model 167,
 * AVX-512) the same build moved 1-3% of the rays between tie and edge
 * (embree_ref: tie 21355 -> 21295, edge 4288 -> 4370), the brute-force and
 * kdray answers unchanged. Rows that differ are therefore recorded per
 * vendor: the AMD rows are those of b60fc84, the Intel rows were measured
 * at stop 26 on a core whose answers are 17ed08b's. A CPU of another vendor
 * is held to the larger count of the recorded vendors (the check says so).
 */
static const cap_row rows[] = {
    /* vendor          test                       tally                     rays
     *                               tie   edge  int.end  parallel ill_cond */
    {"AuthenticAMD",
     "accuracy_single",
     "single closest",
     56000,
     {10479, 2219, 33, 818, 119}},
    {"GenuineIntel",
     "accuracy_single",
     "single closest",
     56000,
     {10434, 2273, 29, 826, 119}},
    {"AuthenticAMD", "accuracy_single", "single any", 56000, {0, 1435, 10, 627, 0}},
    {"GenuineIntel", "accuracy_single", "single any", 56000, {0, 1490, 11, 638, 0}},
    {"AuthenticAMD",
     "accuracy_bundle4",
     "bundle4 closest",
     56000,
     {10479, 2219, 33, 818, 119}},
    {"GenuineIntel",
     "accuracy_bundle4",
     "bundle4 closest",
     56000,
     {10434, 2273, 29, 826, 119}},
    {"AuthenticAMD", "accuracy_bundle4", "bundle4 any", 56000, {0, 1435, 10, 627, 0}},
    {"GenuineIntel", "accuracy_bundle4", "bundle4 any", 56000, {0, 1490, 11, 638, 0}},
    {"AuthenticAMD",
     "accuracy_bundle8",
     "bundle8 closest",
     56000,
     {10479, 2219, 33, 818, 119}},
    {"GenuineIntel",
     "accuracy_bundle8",
     "bundle8 closest",
     56000,
     {10434, 2273, 29, 826, 119}},
    {"AuthenticAMD", "accuracy_bundle8", "bundle8 any", 56000, {0, 1435, 10, 627, 0}},
    {"GenuineIntel", "accuracy_bundle8", "bundle8 any", 56000, {0, 1490, 11, 638, 0}},
    {NULL,
     "accuracy_frustum_multi4",
     "frustum_multi4 closest",
     54747,
     {5396, 149, 0, 0, 0}},
    {NULL, "accuracy_frustum_multi4", "frustum_multi4 any", 54747, {0, 25, 0, 0, 0}},
    {NULL,
     "accuracy_frustum_single",
     "frustum_single closest",
     54747,
     {5396, 149, 0, 0, 0}},
    {NULL, "accuracy_frustum_single", "frustum_single any", 54747, {0, 25, 0, 0, 0}},
    {NULL, "accuracy_cone_shadow", "cone_shadow any", 23296, {0, 2, 0, 0, 0}},
    {"AuthenticAMD",
     "embree_stress",
     "TOTAL closest",
     168000,
     {32038, 6699, 114, 2354, 313}},
    {"GenuineIntel",
     "embree_stress",
     "TOTAL closest",
     168000,
     {31992, 6830, 95, 2357, 314}},
    {"AuthenticAMD", "embree_stress", "TOTAL any", 168000, {0, 4345, 46, 1760, 0}},
    {"GenuineIntel", "embree_stress", "TOTAL any", 168000, {0, 4476, 45, 1790, 0}},
    {"AuthenticAMD",
     "embree_ladder",
     "TOTAL closest",
     192000,
     {29666, 5207, 192, 364, 13}},
    {"GenuineIntel",
     "embree_ladder",
     "TOTAL closest",
     192000,
     {29487, 5333, 182, 370, 13}},
    {"AuthenticAMD", "embree_ladder", "TOTAL any", 192000, {0, 3363, 46, 169, 0}},
    {"GenuineIntel", "embree_ladder", "TOTAL any", 192000, {0, 3457, 49, 174, 0}},
    /* 880000: the ladder's 11th rung, distinct (1M triangles), adds 80000
     * rays; the other ten rungs' counts are unchanged (binned top at 65536,
     * corebuild branch) */
    {"AuthenticAMD",
     "embree_ladder_all",
     "TOTAL closest",
     880000,
     {128479, 21389, 615, 2778, 64}},
    {"GenuineIntel",
     "embree_ladder_all",
     "TOTAL closest",
     880000,
     {127805, 21896, 611, 2862, 64}},
    {"AuthenticAMD", "embree_ladder_all", "TOTAL any", 880000, {0, 12985, 156, 1363, 0}},
    {"GenuineIntel", "embree_ladder_all", "TOTAL any", 880000, {0, 13419, 153, 1396, 0}},
    {"AuthenticAMD",
     "embree_ref",
     "TOTAL brute force vs Embree",
     112000,
     {21355, 4288, 74, 1635, 210}},
    {"GenuineIntel",
     "embree_ref",
     "TOTAL brute force vs Embree",
     112000,
     {21295, 4370, 63, 1648, 209}},
    {NULL, "cone", "cone samples vs embree", 720, {0, 0, 0, 0, 0}},
    {NULL, "frustum", "frustum vs embree", 4058, {0, 0, 0, 0, 0}},
    {NULL, NULL, NULL, 0, {0}},
};

const char *caps_arg(int *argc, char **argv) {
    for (int i = 1; i + 1 < *argc; i++) {
        if (strcmp(argv[i], "--caps") != 0) continue;
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

/* The CPU's vendor string from cpuid leaf 0 ("AuthenticAMD",
 * "GenuineIntel", ...), "" where there is none; KDRAY_CAPS_VENDOR in the
 * environment stands in for it (ctest accuracy_caps_other_vendor holds a
 * vendor with no row of its own to the larger counts). */
static const char *cpu_vendor(void) {
    static char v[13];
    const char *env = getenv("KDRAY_CAPS_VENDOR");
    if (env && *env) return env;
#if defined(__x86_64__) || defined(__i386__)
    unsigned a, b, c, d;
    if (!v[0] && __get_cpuid(0, &a, &b, &c, &d)) {
        memcpy(v, &b, 4);
        memcpy(v + 4, &d, 4);
        memcpy(v + 8, &c, 4);
    }
#endif
    return v;
}

/* The counts for (test, tally) on this CPU: its vendor's row, else the row
 * for any vendor, else (a vendor with no row of its own) the largest count
 * of each class over the vendors' rows, in *merged; *how says which. */
static const cap_row *find_row(const char *test, const char *tally, cap_row *merged,
                               const char **how) {
    const char *vendor = cpu_vendor();
    const cap_row *any = NULL;
    int nvendor = 0;
    for (size_t i = 0; rows[i].test; i++) {
        const cap_row *r = &rows[i];
        if (strcmp(r->test, test) != 0 || strcmp(r->tally, tally) != 0) continue;
        if (!r->vendor) {
            any = r;
            continue;
        }
        if (strcmp(r->vendor, vendor) == 0) {
            *how = r->vendor;
            return r;
        }
        if (nvendor++ == 0) {
            *merged = *r;
        } else {
            if (r->rays != merged->rays)
                merged->rays = 0; /* vendors' rows disagree: re-measure */
            for (int c = 0; c < NCAPPED; c++)
                merged->n[c] = r->n[c] > merged->n[c] ? r->n[c] : merged->n[c];
        }
    }
    if (any) {
        *how = "any CPU";
        return any;
    }
    if (nvendor) {
        *how =
            "the largest of the recorded vendors' counts (no row for this CPU's vendor)";
        merged->vendor = NULL;
        return merged;
    }
    return NULL;
}

/* The tally as a row of the table above. */
static void print_row(FILE *f, const char *test, const char *tally, const cmp_tally *t) {
    fprintf(f, "  measured row: {\"%s\", \"%s\", %llu, {", test, tally,
            (unsigned long long)t->rays);
    for (int c = 0; c < NCAPPED; c++)
        fprintf(f, "%s%llu", c ? ", " : "", (unsigned long long)t->n[FIRST_CAPPED + c]);
    fprintf(f, "}},\n");
}

int caps_check(FILE *f, const char *test, const char *tally, const cmp_tally *t) {
    if (!test) {
        fprintf(f, "caps: not checked for %s (no --caps)\n", tally);
        return 0;
    }
    cap_row merged;
    const char *how = "";
    const cap_row *r = find_row(test, tally, &merged, &how);
    if (!r) {
        if (t->rays == 0) return 0; /* nothing judged, nothing to bound */
        fprintf(f, "CAPS: no recorded counts for %s %s\n", test, tally);
        print_row(f, test, tally, t);
        return 1;
    }
    int bad = 0;
    if (t->rays != r->rays) {
        fprintf(f,
                "CAPS: %s %s judged %llu rays, the caps were measured on "
                "%llu: re-measure\n",
                test, tally, (unsigned long long)t->rays, (unsigned long long)r->rays);
        bad++;
    }
    for (int c = 0; c < NCAPPED; c++) {
        const uint64_t got = t->n[FIRST_CAPPED + c];
        const uint64_t cap = caps_limit(r->n[c]);
        if (got > cap) {
            fprintf(f,
                    "CAP EXCEEDED: %s %s: class %s has %llu rays, cap %llu "
                    "(measured %llu)\n",
                    test, tally, cmp_class_name((cmp_class)(FIRST_CAPPED + c)),
                    (unsigned long long)got, (unsigned long long)cap,
                    (unsigned long long)r->n[c]);
            bad++;
        }
    }
    int same = t->rays == r->rays;
    for (int c = 0; c < NCAPPED; c++)
        same &= t->n[FIRST_CAPPED + c] == r->n[c];
    if (!same) print_row(f, test, tally, t);
    if (bad && !kdr_cpu_has_avx2())
        fprintf(f, "  (this CPU has no AVX2: Embree runs a narrower ISA than the "
                   "counts were measured with, ORACLE_JUDGE_CONFIG)\n");
    fprintf(f, "caps: %s %s: %s (counts of %s; CPU vendor '%s')\n", test, tally,
            bad ? "FAILED" : "within caps", how, cpu_vendor());
    return bad;
}
