/*
 * compare.h — judging a kd-tree answer against Embree's, ray by ray, and a
 * brute-force reference (every triangle through core/kd_tri.h, the same
 * watertight test and tie rule as the kd-tree) for small scenes.
 *
 * Classes (a disagreement is "explained" only when it is proven to be a
 * boundary case within float rounding):
 *   AGREE      same prim (or both miss) and t within tolerance;
 *   TIE        different prims at the same t, and the hit point lies on both
 *              triangles (shared edge/vertex or coincident faces), kd's prim
 *              obeying the tie rule under kd's own test;
 *   BOUNDARY / INTERVAL_END / PARALLEL
 *              hit vs miss (or a different nearest prim) where the deciding
 *              hit is proven to lie within rounding of a triangle edge or
 *              vertex (a silhouette graze: BOUNDARY, printed "edge"), of an
 *              end of [tmin, tmax] (INTERVAL_END), or the ray lies in the
 *              triangle's plane or the triangle has zero area (PARALLEL);
 *              and the brute-force reference agrees with kd;
 *   ILL_COND   same triangle (or a tie-rule-consistent one), t off by more
 *              than the tolerance from Embree's, but kd's t is within the
 *              float-evaluation error bound of the exact (double) t: a ray
 *              grazing a sliver or nearly parallel to its plane;
 *   KD_MISS    Embree hits, kd misses (unexplained);
 *   KD_EXTRA   kd hits, Embree misses (unexplained);
 *   WRONG_PRIM different prim, not a tie, not explained;
 *   T_ERROR    same prim, |t_kd - t_embree| > 1e-5 * max(|t|, t_floor).
 * t_floor = 8 ulp(scale) / (1e-5 |dir|): below it the coordinates' own
 * rounding dominates (scale = the largest coordinate involved).
 */
#ifndef KDRAY_TEST_COMPARE_H
#define KDRAY_TEST_COMPARE_H

#include <stddef.h>
#include <stdint.h>
#include <stdio.h>

#include "kdray.h"

#define CMP_T_REL_TOL 1e-5

typedef enum cmp_class {
    CMP_AGREE = 0,
    CMP_TIE,
    CMP_BOUNDARY,
    CMP_INTERVAL_END,
    CMP_PARALLEL,
    CMP_ILL_COND,
    CMP_KD_MISS,
    CMP_KD_EXTRA,
    CMP_WRONG_PRIM,
    CMP_T_ERROR,
    CMP_NCLASSES
} cmp_class;

const char *cmp_class_name(cmp_class c);
int cmp_is_unexplained(cmp_class c);

/* Brute force over all triangles with kd_tri_intersect and the tie rule
 * (smaller t, then smaller prim); degenerate triangles (see
 * ref_tri_degenerate) are never hit. Same conventions as kdr_intersect1. */
int ref_intersect1(const float *tris, size_t ntris, const kdr_ray *ray,
                   kdr_hit *hit);
int ref_occluded1(const float *tris, size_t ntris, const kdr_ray *ray);
/* Zero-area triangle as the core defines it (never inserted, never hit). */
int ref_tri_degenerate(const float *tri);

/* Classifies kd's closest hit against Embree's on the same ray. tris is the
 * scene (needed to prove ties and boundary cases). *t_err gets the relative
 * t error when both hit the same prim (else 0). */
cmp_class cmp_closest(const float *tris, size_t ntris, const kdr_ray *ray,
                      const kdr_hit *kd, const kdr_hit *em, double *t_err);

/* Classifies an any-hit answer. On disagreement the closest hits of both
 * (kd_closest from kdr_intersect1, em_closest from oracle_intersect1) decide
 * whether it is a proven boundary case. */
cmp_class cmp_occluded(const float *tris, size_t ntris, const kdr_ray *ray,
                       int kd_hit, int em_hit, const kdr_hit *kd_closest,
                       const kdr_hit *em_closest);

/* Why a hit (or a miss) of triangle tri at distance t is decided by float
 * rounding: the ray lies in its plane or it has zero area (CMP_PARALLEL),
 * grazes an edge or vertex (CMP_BOUNDARY), or t is within rounding of an end
 * of [tmin, tmax] (CMP_INTERVAL_END); CMP_AGREE when none of these holds
 * (then two correct tests must agree on this triangle). Judges all-hits
 * lists prim by prim. */
cmp_class cmp_hit_reason(const kdr_ray *ray, const float *tri, double t);

typedef struct cmp_tally {
    uint64_t rays;
    uint64_t n[CMP_NCLASSES];
    uint64_t hits;        /* rays Embree reports a hit for */
    double max_t_err;     /* over AGREE rays */
    kdr_ray first_bad;    /* first unexplained ray, for reproduction */
    int has_bad;
} cmp_tally;

void cmp_tally_init(cmp_tally *t);
void cmp_tally_add(cmp_tally *t, const kdr_ray *ray, cmp_class c,
                   double t_err, int em_hit);
void cmp_tally_merge(cmp_tally *into, const cmp_tally *from);
uint64_t cmp_tally_unexplained(const cmp_tally *t);
/* One line: label, rays, hits, every class count, max t error. */
void cmp_tally_print(FILE *f, const char *label, const cmp_tally *t);
/* Prints the first unexplained ray with %a floats (if any). */
void cmp_tally_print_bad(FILE *f, const char *label, const cmp_tally *t);

#endif /* KDRAY_TEST_COMPARE_H */
