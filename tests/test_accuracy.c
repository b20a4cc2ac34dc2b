/*
 * test_accuracy.c — the accuracy gate (ctest): every query kind given on
 * the command line (default: all) on the stress corpus, with zero tolerated
 * unexplained disagreements with Embree, zero answers differing from the
 * single-ray ones, zero watertightness failures, zero API errors, and cone
 * visibilities equal to the fraction of unblocked samples. A kind whose
 * function is missing or returns an error fails; with --caps, so does an
 * explained class over its cap (tests/support/caps.h).
 *
 *   test_accuracy [--caps NAME] [--rays N] [KIND...]
 *                             KIND: single bundle4 bundle8 frustum_multi4
 *                             frustum_single cone_shadow (default: all);
 *                             N rays per stress scene and ray kind; NAME
 *                             the row set of caps.c (the ctest name)
 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "accuracy.h"
#include "caps.h"

/* argv[first..argc) are kind names; none means all. */
static int wanted(int argc, char **argv, int first, acc_kind k) {
    if (argc <= first)
        return 1;
    for (int i = first; i < argc; i++)
        if (strcmp(argv[i], acc_kind_name(k)) == 0)
            return 1;
    return 0;
}

int main(int argc, char **argv) {
    acc_opts opt;
    acc_opts_default(&opt);
    const char *caps = caps_arg(&argc, argv);
    int first = 1;
    if (argc >= 3 && strcmp(argv[1], "--rays") == 0) {
        opt.rays = strtoul(argv[2], NULL, 10);
        first = 3;
    }
    int fail = 0, ran = 0;
    acc_result res[ACC_NKINDS];
    memset(res, 0, sizeof res);
    for (int k = 0; k < ACC_NKINDS; k++) {
        if (!wanted(argc, argv, first, (acc_kind)k))
            continue;
        ran++;
        if (acc_run((acc_kind)k, &opt, &res[k]) != 0) {
            printf("%s: a stress scene could not be built\n",
                   acc_kind_name((acc_kind)k));
            fail = 1;
        }
        fail |= acc_failures(&res[k]) != 0;
    }
    acc_print_header(stdout);
    for (int k = 0; k < ACC_NKINDS; k++)
        if (wanted(argc, argv, first, (acc_kind)k))
            acc_print_row(stdout, (acc_kind)k, &res[k]);
    for (int k = 0; k < ACC_NKINDS; k++) {
        if (!wanted(argc, argv, first, (acc_kind)k))
            continue;
        acc_print_details(stdout, (acc_kind)k, &res[k]);
        char label[64];
        snprintf(label, sizeof label, "%s closest", acc_kind_name((acc_kind)k));
        fail |= caps_check(stdout, caps, label, &res[k].closest) != 0;
        snprintf(label, sizeof label, "%s any", acc_kind_name((acc_kind)k));
        fail |= caps_check(stdout, caps, label, &res[k].any) != 0;
    }
    if (ran == 0) {
        printf("no such query kind\n");
        return 2;
    }
    return fail;
}
