/*
 * caps.h — upper bounds ("caps") on the explained disagreement classes of
 * compare.h (tie, edge, interval_end, parallel, ill_cond), per ctest test
 * and per tally.
 *
 * Those classes never fail a test by themselves: a ray there is a proven
 * boundary case. Without a bound, a regression that moves rays from agree
 * into one of them (a triangle test that lost precision near edges, a
 * judge whose tolerance grew) would pass. Every gate's rays are seeded or
 * come from the fixed ladder, so its class counts are the same on every
 * run of one build; caps.c records them as measured, with the number of
 * rays judged, and a test fails when a class exceeds its cap (the measured
 * count plus a small margin, caps_limit) or when it judged a different
 * number of rays than the counts were measured on (re-measure then).
 *
 * Tests take the name of their row set as `--caps NAME` (their ctest
 * name); run by hand without it, they check no caps and say so.
 */
#ifndef KDRAY_TEST_CAPS_H
#define KDRAY_TEST_CAPS_H

#include <stdint.h>
#include <stdio.h>

#include "compare.h"

/* Removes "--caps NAME" from argv (anywhere after argv[0]) and returns
 * NAME, or NULL if absent. *argc shrinks by 2 when found. */
const char *caps_arg(int *argc, char **argv);

/* The cap for a class measured at `measured` rays. */
uint64_t caps_limit(uint64_t measured);

/* Checks tally t (labelled `tally`, e.g. "TOTAL closest") of test `test`
 * against the recorded counts; prints one line per exceeded class, naming
 * the test, the tally, the class, the count and the cap. Returns the number
 * of problems (classes over their cap, a ray count that differs, or no
 * recorded row for a tally that judged rays); 0 when test is NULL (no
 * --caps given: prints that the caps were not checked). */
int caps_check(FILE *f, const char *test, const char *tally, const cmp_tally *t);

#endif /* KDRAY_TEST_CAPS_H */
