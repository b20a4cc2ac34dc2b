/*
 * accuracy_internal.h — what the accuracy suite's files share: the
 * per-ray judge and the per-kind runners (not for tests to call).
 */
#ifndef KDRAY_TEST_ACCURACY_INTERNAL_H
#define KDRAY_TEST_ACCURACY_INTERNAL_H

#include "accuracy.h"
#include "kdray.h"
#include "oracle.h"
#include "stress.h"

/* Judges kd's closest hit and any-hit answer for one ray against Embree
 * and (bit for bit) against kdr_intersect1/kdr_occluded1. */
void acc_judge(const stress_scene *s, const kdr_scene *kd, const oracle *o,
               const kdr_ray *r, const kdr_hit *kd_closest, int kd_any,
               int check_single, acc_result *res);

int acc_run_frustum(const stress_scene *s, const kdr_scene *kd,
                    const oracle *o, kdr_frustum_mode mode, const acc_opts *opt,
                    acc_result *res);
int acc_run_cone(const stress_scene *s, const kdr_scene *kd, const oracle *o,
                 const acc_opts *opt, acc_result *res);

#endif
