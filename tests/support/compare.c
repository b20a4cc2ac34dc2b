/*
 * compare.c — the brute-force reference and the classification of kd vs
 * Embree disagreements. Boundary cases are proven in double precision: the
 * triangle's three edge functions in the ray's sheared frame (the frame of
 * core/kd_tri.h) are compared with the rounding error their float
 * evaluation can carry, so "on the edge" means "within rounding of it", not
 * "close enough by eye".
 */
#include "compare.h"

#include <float.h>
#include <math.h>
#include <string.h>

#include "kd_internal.h"
#include "kd_traverse.h"
#include "kd_tri.h"

/* How many FLT_EPSILONs of the edge functions' magnitude (m below) count as
 * "on the edge". kd_tri.h's float edge function is within 5 FLT_EPSILON of
 * its own term magnitude of the exact one (first order: 2 FLT_EPSILON per
 * sheared coordinate, products and difference), and m sums all three
 * edges' magnitudes; Embree's Pluecker test rounds a similar number of
 * times in another frame and widens edges by one ulp of the determinant.
 * 16 covers both evaluations with room to spare. Measured on every gate
 * (docs/ACCURACY.md, "Caps"): no disagreement needs more than 1; 64 (the
 * old value) only moved rays from parallel (|det| <= 3 tol) into edge. */
#define EDGE_ULPS 16.0
/* t agrees when within CMP_T_REL_TOL relative, or within this many ulps of
 * the largest coordinate involved (the inputs' own rounding). */
#define T_FLOOR_ULPS 8.0
/* Roundings allowed in the float t of kd_tri.h (a first-order bound of its
 * operation count) before an off t counts as an error. */
#define T_COND_ULPS 16.0

static const char *const class_names[CMP_NCLASSES] = {
    "agree", "tie", "edge", "interval_end", "parallel", "ill_cond", "kd_miss", "kd_extra", "wrong_prim", "t_error",
};

const char *cmp_class_name(cmp_class c) {
    return (c >= 0 && c < CMP_NCLASSES) ? class_names[c] : "?";
}

int cmp_is_unexplained(cmp_class c) {
    return c != CMP_AGREE && c != CMP_TIE && c != CMP_BOUNDARY &&
           c != CMP_INTERVAL_END && c != CMP_PARALLEL && c != CMP_ILL_COND;
}

/* ---- brute-force reference ------------------------------------------------ */

int ref_tri_degenerate(const float *tri) { return kd_tri_degenerate(tri); }

static int ray_usable(const kdr_ray *r) {
    return kd_ray_valid(r->org, r->dir, r->tmin, r->tmax);
}

static void set_miss(kdr_hit *h) {
    h->t = -1.0f;
    h->u = h->v = 0.0f;
    h->prim = -1;
}

int ref_intersect1(const float *tris, size_t ntris, const kdr_ray *ray,
                   kdr_hit *hit) {
    set_miss(hit);
    if (!ray_usable(ray))
        return 0;
    kd_ray_pre pre;
    kd_ray_precompute(ray->org, ray->dir, &pre);
    float best = INFINITY;
    int32_t best_prim = -1;
    for (size_t i = 0; i < ntris; i++) {
        const float *tri = tris + 9 * i;
        float t, u, v;
        if (ref_tri_degenerate(tri) ||
            !kd_tri_intersect(&pre, tri, ray->tmin, ray->tmax, &t, &u, &v))
            continue;
        if (best_prim < 0 || kd_hit_better(t, (int32_t)i, best, best_prim)) {
            best = t;
            best_prim = (int32_t)i;
            hit->t = t;
            hit->u = u;
            hit->v = v;
            hit->prim = (int32_t)i;
        }
    }
    return best_prim >= 0;
}

int ref_occluded1(const float *tris, size_t ntris, const kdr_ray *ray) {
    if (!ray_usable(ray))
        return 0;
    kd_ray_pre pre;
    kd_ray_precompute(ray->org, ray->dir, &pre);
    for (size_t i = 0; i < ntris; i++) {
        float t, u, v;
        if (!ref_tri_degenerate(tris + 9 * i) &&
            kd_tri_intersect(&pre, tris + 9 * i, ray->tmin, ray->tmax, &t, &u, &v))
            return 1;
    }
    return 0;
}

/* ---- proofs of boundary cases --------------------------------------------- */

/* The triangle seen from the ray, in double precision. margin is the
 * smallest edge function (inside positive) over the rounding scale of the
 * edge functions; parallel means the projected area is itself within
 * rounding of zero (the ray lies in the triangle's plane). */
typedef struct tri_view {
    double margin; /* smallest edge function, inside positive */
    double tol;    /* rounding (and underflow) bound of an edge function */
    int parallel;
    double t;       /* exact (double) hit distance on the triangle's plane */
    double t_bound; /* error bound of kd_tri.h's float t */
} tri_view;

static void view_triangle(const kdr_ray *r, const float *tri, tri_view *out) {
    kd_ray_pre p;
    kd_ray_precompute(r->org, r->dir, &p);
    const double sx = (double)r->dir[p.kx] / r->dir[p.kz];
    const double sy = (double)r->dir[p.ky] / r->dir[p.kz];
    double x[3], y[3], z[3], mx[3], my[3];
    for (int i = 0; i < 3; i++) {
        const double ax = (double)tri[3 * i + p.kx] - r->org[p.kx];
        const double ay = (double)tri[3 * i + p.ky] - r->org[p.ky];
        const double az = (double)tri[3 * i + p.kz] - r->org[p.kz];
        x[i] = ax - sx * az;
        y[i] = ay - sy * az;
        z[i] = az / r->dir[p.kz];
        mx[i] = fabs(ax) + fabs(sx * az);
        my[i] = fabs(ay) + fabs(sy * az);
    }
    /* edge function opposite vertex i uses the other two vertices */
    /* m: rounding scale of the edge functions; under: what underflow of
     * the sheared coordinates (denormal direction components) adds */
    double e[3], me[3], m = 0.0, under = 0.0, T = 0.0, mT = 0.0, mz = 0.0;
    for (int i = 0; i < 3; i++) {
        const int b = (i + 1) % 3, c = (i + 2) % 3;
        e[i] = x[c] * y[b] - y[c] * x[b];
        me[i] = mx[c] * my[b] + my[c] * mx[b];
        m += me[i];
        under += 2.0 * FLT_TRUE_MIN * (mx[i] + my[i]);
        T += e[i] * z[i];
        mT += (me[i] + fabs(e[i])) * fabs(z[i]);
        mz += fabs(z[i]);
    }
    const double det = e[0] + e[1] + e[2];
    out->t = det != 0.0 ? T / det : INFINITY;
    out->t_bound = det != 0.0 ? T_COND_ULPS *
                                    (FLT_EPSILON * (mT + fabs(out->t) * m) +
                                     under * (mz + fabs(out->t))) /
                                    fabs(det)
                              : INFINITY;
    out->tol = EDGE_ULPS * (FLT_EPSILON * m + under);
    out->parallel = fabs(det) <= 3.0 * out->tol;
    const double s = det < 0 ? -1.0 : 1.0;
    double lo = INFINITY;
    for (int i = 0; i < 3; i++)
        lo = fmin(lo, s * e[i]);
    out->margin = lo;
}

/* Why a hit on tri is decided by rounding, as a class: the ray lies in the
 * triangle's plane (CMP_PARALLEL), grazes an edge or vertex
 * (CMP_BOUNDARY), or the exact t sits within rounding of an end of
 * [tmin, tmax] (CMP_INTERVAL_END); CMP_NCLASSES if none of these. */
static cmp_class boundary_reason(const kdr_ray *r, const float *tri) {
    tri_view v;
    view_triangle(r, tri, &v);
    if (v.parallel)
        return CMP_PARALLEL;
    if (fabs(v.margin) <= v.tol)
        return CMP_BOUNDARY;
    if (fabs(v.t - r->tmin) <= v.t_bound ||
        (isfinite(r->tmax) && fabs(v.t - r->tmax) <= v.t_bound))
        return CMP_INTERVAL_END;
    return CMP_NCLASSES;
}

static int on_boundary(const kdr_ray *r, const float *tri) {
    return boundary_reason(r, tri) != CMP_NCLASSES;
}

static double scale_of(const kdr_ray *r, const float *a, const float *b) {
    double s = 0.0;
    for (int k = 0; k < 3; k++)
        s = fmax(s, fabs(r->org[k]));
    for (int k = 0; k < 9; k++) {
        if (a)
            s = fmax(s, fabs(a[k]));
        if (b)
            s = fmax(s, fabs(b[k]));
    }
    return s;
}

static double t_floor(const kdr_ray *r, double scale) {
    const double len = sqrt((double)r->dir[0] * r->dir[0] +
                            (double)r->dir[1] * r->dir[1] +
                            (double)r->dir[2] * r->dir[2]);
    return T_FLOOR_ULPS * FLT_EPSILON * scale / (CMP_T_REL_TOL * len);
}

/* Relative t difference on the scale CMP_T_REL_TOL is compared with. */
static double t_diff(double a, double b, double floor) {
    const double den = fmax(fmax(fabs(a), fabs(b)), floor);
    return den > 0 ? fabs(a - b) / den : 0.0;
}

static const float *tri_at(const float *tris, size_t ntris, int32_t prim) {
    return (prim >= 0 && (size_t)prim < ntris) ? tris + 9 * (size_t)prim : NULL;
}

/* Our own test on one triangle, over [lo, hi]. */
static int our_test(const kdr_ray *r, const float *tri, float lo, float hi,
                    float *t) {
    kd_ray_pre p;
    float u, v;
    kd_ray_precompute(r->org, r->dir, &p);
    return kd_tri_intersect(&p, tri, lo, hi, t, &u, &v);
}

/* A hit at t that is within tolerance of the ray's interval ends. */
static int near_interval_end(const kdr_ray *r, double t, double floor) {
    return t_diff(t, r->tmin, floor) <= CMP_T_REL_TOL ||
           (isfinite(r->tmax) && t_diff(t, r->tmax, floor) <= CMP_T_REL_TOL);
}

/* Why the float t of a hit is legitimately on either side of an interval
 * end, or CMP_NCLASSES. */
static cmp_class reason_at(const kdr_ray *r, const float *tri, double t) {
    const cmp_class c = ref_tri_degenerate(tri) ? CMP_PARALLEL
                                                : boundary_reason(r, tri);
    if (c != CMP_NCLASSES)
        return c;
    return near_interval_end(r, t, t_floor(r, scale_of(r, tri, NULL)))
               ? CMP_INTERVAL_END
               : CMP_NCLASSES;
}

cmp_class cmp_hit_reason(const kdr_ray *ray, const float *tri, double t) {
    const cmp_class c = reason_at(ray, tri, t);
    return c == CMP_NCLASSES ? CMP_AGREE : c;
}

/* Embree hits tri, kd (and, to be sure, brute force) does not: the reason
 * class, or CMP_NCLASSES when unexplained. */
static cmp_class explain_embree_only(const float *tris, size_t ntris,
                                     const kdr_ray *r, const kdr_hit *em,
                                     const kdr_hit *kd) {
    const float *p = tri_at(tris, ntris, em->prim);
    if (!p)
        return CMP_NCLASSES;
    float t;
    if (!ref_tri_degenerate(p) && our_test(r, p, r->tmin, r->tmax, &t) &&
        (kd->prim < 0 || kd_hit_better(t, em->prim, kd->t, kd->prim)))
        return CMP_NCLASSES; /* kd's own test would have found a better hit */
    const cmp_class c = reason_at(r, p, em->t);
    if (c == CMP_NCLASSES)
        return c;
    kdr_hit ref;
    ref_intersect1(tris, ntris, r, &ref);
    if (ref.prim == kd->prim)
        return c;
    /* Brute force found a hit kd did not: acceptable only for a miss, and
     * only when that hit is itself decided by rounding (e.g. a sliver whose
     * float t rounds to tmin while its exact t lies before it). */
    const float *b = tri_at(tris, ntris, ref.prim);
    return kd->prim < 0 && b && reason_at(r, b, ref.t) != CMP_NCLASSES
               ? c
               : CMP_NCLASSES;
}

/* kd hits tri, Embree does not see it (or sees something farther). */
static cmp_class explain_kd_only(const float *tris, size_t ntris,
                                 const kdr_ray *r, const kdr_hit *kd) {
    const float *q = tri_at(tris, ntris, kd->prim);
    float t;
    if (!q || !our_test(r, q, r->tmin, r->tmax, &t) || t != kd->t)
        return CMP_NCLASSES; /* a hit kd's own triangle test does not give */
    return reason_at(r, q, kd->t);
}

/* The explanation, or the unexplained class `otherwise`. */
static cmp_class or_else(cmp_class why, cmp_class otherwise) {
    return why != CMP_NCLASSES ? why : otherwise;
}

/* Same triangle, t compared with Embree's (d) and, when that is off, with
 * the exact t: the worse of the two float evaluations may be Embree's. */
static cmp_class classify_same_prim(const kdr_ray *r, const float *tri,
                                    float t_kd, double d, double fl,
                                    double *t_err) {
    if (d <= CMP_T_REL_TOL) {
        *t_err = d;
        return CMP_AGREE;
    }
    tri_view v;
    view_triangle(r, tri, &v);
    const double dx = t_diff(t_kd, v.t, fl);
    if (dx <= CMP_T_REL_TOL) {
        *t_err = dx;
        return CMP_AGREE;
    }
    return fabs(t_kd - v.t) <= v.t_bound ? CMP_ILL_COND : CMP_T_ERROR;
}

/* t_ours and t_other are two float evaluations of a hit on tri that both
 * lie within rounding of the exact t (up to twice the error bound). */
static int ill_conditioned(const kdr_ray *r, const float *tri, double t_ours,
                           double t_other) {
    tri_view v;
    view_triangle(r, tri, &v);
    return fabs(t_ours - v.t) <= v.t_bound &&
           fabs(t_other - v.t) <= 2.0 * v.t_bound;
}

/* Different prims at (about) the same t. */
static cmp_class classify_tie(const float *tris, size_t ntris,
                              const kdr_ray *r, const kdr_hit *kd,
                              const kdr_hit *em) {
    const float *p = tri_at(tris, ntris, em->prim);
    const float *q = tri_at(tris, ntris, kd->prim);
    float t;
    if (!p || !q || !our_test(r, q, r->tmin, r->tmax, &t) || t != kd->t)
        return CMP_WRONG_PRIM; /* kd's own hit must be real */
    if (!ref_tri_degenerate(p) && our_test(r, p, r->tmin, r->tmax, &t))
        return kd_hit_better(t, em->prim, kd->t, kd->prim) ? CMP_WRONG_PRIM
                                                          : CMP_TIE;
    return on_boundary(r, p) ? CMP_TIE : CMP_WRONG_PRIM;
}

cmp_class cmp_closest(const float *tris, size_t ntris, const kdr_ray *ray,
                      const kdr_hit *kd, const kdr_hit *em, double *t_err) {
    *t_err = 0.0;
    if (kd->prim < 0 && em->prim < 0)
        return CMP_AGREE;
    if (kd->prim < 0)
        return or_else(explain_embree_only(tris, ntris, ray, em, kd),
                       CMP_KD_MISS);
    if (em->prim < 0)
        return or_else(explain_kd_only(tris, ntris, ray, kd), CMP_KD_EXTRA);
    const float *a = tri_at(tris, ntris, kd->prim);
    const float *b = tri_at(tris, ntris, em->prim);
    const double fl = t_floor(ray, scale_of(ray, a, b));
    const double d = t_diff(kd->t, em->t, fl);
    if (kd->prim == em->prim)
        return classify_same_prim(ray, a, kd->t, d, fl, t_err);
    if (d <= CMP_T_REL_TOL) {
        cmp_class c = classify_tie(tris, ntris, ray, kd, em);
        if (c == CMP_TIE)
            *t_err = d;
        return c;
    }
    if (kd->t < em->t) {
        const cmp_class why = explain_kd_only(tris, ntris, ray, kd);
        if (why != CMP_NCLASSES)
            return why;
        /* Embree ordered kd's triangle after its own: both t's of it are
         * within twice its error bound of each other */
        return ill_conditioned(ray, a, kd->t, em->t) ? CMP_ILL_COND
                                                     : CMP_WRONG_PRIM;
    }
    const cmp_class why = explain_embree_only(tris, ntris, ray, em, kd);
    if (why != CMP_NCLASSES)
        return why;
    float tp;
    if (!ref_tri_degenerate(b) && our_test(ray, b, ray->tmin, ray->tmax, &tp) &&
        !kd_hit_better(tp, em->prim, kd->t, kd->prim) &&
        ill_conditioned(ray, b, tp, em->t))
        return CMP_ILL_COND;
    return CMP_WRONG_PRIM;
}

cmp_class cmp_occluded(const float *tris, size_t ntris, const kdr_ray *ray,
                       int kd_hit, int em_hit, const kdr_hit *kd_closest,
                       const kdr_hit *em_closest) {
    if (!kd_hit != !em_hit) {
        double e;
        /* kd's two answers must be consistent before anything is explained */
        if (!kd_hit != (kd_closest->prim < 0))
            return kd_hit ? CMP_KD_EXTRA : CMP_KD_MISS;
        cmp_class c = cmp_closest(tris, ntris, ray, kd_closest, em_closest, &e);
        if (c == CMP_BOUNDARY || c == CMP_INTERVAL_END || c == CMP_PARALLEL)
            return c;
        return kd_hit ? CMP_KD_EXTRA : CMP_KD_MISS;
    }
    return CMP_AGREE;
}

/* ---- tallies ------------------------------------------------------------- */

void cmp_tally_init(cmp_tally *t) { memset(t, 0, sizeof *t); }

void cmp_tally_add(cmp_tally *t, const kdr_ray *ray, cmp_class c,
                   double t_err, int em_hit) {
    t->rays++;
    t->n[c]++;
    t->hits += em_hit != 0;
    if ((c == CMP_AGREE || c == CMP_TIE) && t_err > t->max_t_err)
        t->max_t_err = t_err;
    if (cmp_is_unexplained(c) && !t->has_bad) {
        t->first_bad = *ray;
        t->has_bad = 1;
    }
}

void cmp_tally_merge(cmp_tally *into, const cmp_tally *from) {
    into->rays += from->rays;
    into->hits += from->hits;
    for (int c = 0; c < CMP_NCLASSES; c++)
        into->n[c] += from->n[c];
    if (from->max_t_err > into->max_t_err)
        into->max_t_err = from->max_t_err;
    if (from->has_bad && !into->has_bad) {
        into->first_bad = from->first_bad;
        into->has_bad = 1;
    }
}

uint64_t cmp_tally_unexplained(const cmp_tally *t) {
    uint64_t n = 0;
    for (int c = 0; c < CMP_NCLASSES; c++)
        if (cmp_is_unexplained((cmp_class)c))
            n += t->n[c];
    return n;
}

void cmp_tally_print(FILE *f, const char *label, const cmp_tally *t) {
    fprintf(f, "%-34s rays %8llu hits %8llu", label,
            (unsigned long long)t->rays, (unsigned long long)t->hits);
    for (int c = 1; c < CMP_NCLASSES; c++)
        fprintf(f, " %s %llu", class_names[c], (unsigned long long)t->n[c]);
    fprintf(f, " max_t_err %.2e\n", t->max_t_err);
}

void cmp_tally_print_bad(FILE *f, const char *label, const cmp_tally *t) {
    if (!t->has_bad)
        return;
    const kdr_ray *r = &t->first_bad;
    fprintf(f, "  %s first unexplained ray: org %a %a %a dir %a %a %a "
               "tmin %a tmax %a\n",
            label, r->org[0], r->org[1], r->org[2], r->dir[0], r->dir[1],
            r->dir[2], r->tmin, r->tmax);
}
