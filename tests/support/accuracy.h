/*
 * accuracy.h — the accuracy suite behind test_accuracy (ctest) and
 * kdray_accuracy_report: every query kind of the public API run on the
 * stress corpus and judged against Embree (compare.h classes), against
 * kdr_intersect1/kdr_occluded1 bit for bit (the "identical across traversal
 * kinds" guarantee), and for watertightness (rays, bundles, frusta and
 * shadow cones starting inside closed meshes must always be blocked).
 */
#ifndef KDRAY_TEST_ACCURACY_H
#define KDRAY_TEST_ACCURACY_H

#include <stdint.h>
#include <stdio.h>

#include "compare.h"
#include "kdray.h"

typedef enum acc_kind {
    ACC_SINGLE = 0,     /* kdr_intersect1 / kdr_occluded1 */
    ACC_BUNDLE4,        /* kdr_trace_batch, KDR_TRAV_BUNDLE4 */
    ACC_BUNDLE8,        /* kdr_trace_batch, KDR_TRAV_BUNDLE8 */
    ACC_FRUSTUM_MULTI4, /* kdr_frustum_trace, KDR_FRUSTUM_MULTI4 */
    ACC_FRUSTUM_SINGLE, /* kdr_frustum_trace, KDR_FRUSTUM_SINGLE */
    ACC_CONE,           /* kdr_shadow_trace, KDR_SHADOW_CONE */
    ACC_NKINDS
} acc_kind;

typedef struct acc_result {
    cmp_tally closest;     /* vs Embree (rays, bundles, frusta) */
    cmp_tally any;         /* vs Embree; for cones: every shadow sample */
    uint64_t not_single;   /* answers not bit-identical to kdr_intersect1 /
                              kdr_occluded1 on the same ray */
    kdr_ray first_not_single; /* valid when not_single > 0 */
    const char *first_not_single_scene;
    uint64_t own_unexplained; /* unexplained vs Embree and not inherited
                                 from the single-ray answer (bundles and
                                 frusta equal to single rays inherit its
                                 disagreements: accuracy_single owns them);
                                 for cones every unexplained shadow sample */
    uint64_t inside, inside_miss; /* watertightness probes and failures */
    uint64_t errors;       /* API calls that returned an error */
    /* cones: (point, light) pairs, pairs whose visibility differs from the
     * fraction of samples kdr_occluded1 leaves unblocked (must be 0), pairs
     * whose Embree fraction differs (each sample judged in `any`) */
    uint64_t pairs, vis_mismatch, frac_differs;
} acc_result;

typedef struct acc_opts {
    uint64_t seed;
    size_t rays;    /* per stress scene and ray kind (rays, bundles) */
    int cameras;    /* frustum: scale of the image sizes (1 = small) */
    uint32_t points; /* cone: points per scene */
    uint32_t samples;
} acc_opts;

void acc_opts_default(acc_opts *o);
const char *acc_kind_name(acc_kind k);

/* Runs one query kind over every stress scene, adding into *res. Returns
 * -1 if a scene could not be built (not a disagreement). */
int acc_run(acc_kind k, const acc_opts *o, acc_result *res);

/* Everything that must be zero for this kind: its own unexplained
 * disagreements, answers differing from single rays, watertightness
 * failures, API errors, cone visibility mismatches. */
uint64_t acc_failures(const acc_result *r);

void acc_print_header(FILE *f);
void acc_print_row(FILE *f, acc_kind k, const acc_result *r);
/* Prints the first unexplained ray of each tally, if any. */
void acc_print_details(FILE *f, acc_kind k, const acc_result *r);

#endif /* KDRAY_TEST_ACCURACY_H */
