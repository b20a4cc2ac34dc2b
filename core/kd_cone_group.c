/*
 * kd_cone_group.c — one kd-tree walk shared by a group of consecutive
 * points toward one light (kd_cone_query.c says when groups are formed).
 *
 * The group's cone holds every sample segment of every point of the group:
 * each segment runs from a point's apex into the light's ball, so it lies in
 * the convex hull of a ball around the apexes and the light's ball, and the
 * cone tangent to both balls (apex behind the points, on the line of the
 * two centres) holds that hull. The walk of that cone with its cull
 * (kd_cone_trav.c) lists every triangle any segment of the group can touch;
 * each point then judges that list with its own cull and proofs instead of
 * walking the tree (kd_cone_cells.c). An empty list decides the whole group
 * lit.
 *
 * Margins: a point's own walk and cull keep a triangle up to its margins
 * (positional band, relative slack, angular slack) outside the point's cone;
 * the balls are inflated so that the group's cone holds each point's cone
 * widened by those margins, and the group's band is the largest of the
 * points'. The list is therefore a superset of what each point's own walk
 * would keep, and every decision is still taken by the point's proofs.
 */
#include <math.h>

#include "kd_cone.h"
#include "kd_internal.h"
#include "kd_traverse.h"

/* Relative inflation of the balls, far above double rounding and above the
 * cull's CULL_REL_SLACK (1e-6) and angular slack (1e-5 rad). */
#define GROUP_REL_PAD 1e-4

static double dist3(const double *a, const double *b) {
    double d2 = 0.0;
    for (int k = 0; k < 3; k++)
        d2 += (a[k] - b[k]) * (a[k] - b[k]);
    return sqrt(d2);
}

/* Plain comparisons, not fmaxf (a libm call; no operand is NaN). */
static float fmax_plain(float a, float b) { return a > b ? a : b; }

double kd_frame_reach(const kd_shadow_frame *f) {
    /* the disc at t_far of the cone widened by 2e-5 rad (twice the cull's
     * CULL_ANGLE_SLACK): tan(asin(s) + 2e-5) by the tangent-sum formula (no
     * asin or tan per point; its last-bit differences from libm's are far
     * inside the callers' margins) */
    const double tan_slack = tan(2e-5); /* folds at compile time */
    const double tfar = f->dist * (1.0 + 0x1p-16);
    const double ta = f->sin_a / sqrt((1.0 - f->sin_a) * (1.0 + f->sin_a));
    const double den = 1.0 - ta * tan_slack;
    const double tan_p = den > 0.0 ? (ta + tan_slack) / den : INFINITY;
    const double x = tfar - f->dist, y = tfar * tan_p;
    return sqrt(x * x + y * y);
}

void kd_group_clear(const kd_shadow_frame *const *fs, size_t n, float band,
                    kd_tri_pre *pre, size_t npre) {
    if (n == 0) return;
    double lo[3], hi[3], cg[3], rg2 = 0.0, reach = 0.0, dmax = 0.0, a1 = 0.0;
    const double *lc = fs[0]->center;
    for (int k = 0; k < 3; k++)
        lo[k] = hi[k] = fs[0]->apex[k];
    for (size_t i = 0; i < n; i++) {
        const double r = kd_frame_reach(fs[i]);
        reach = r > reach ? r : reach;
        dmax = fs[i]->dist > dmax ? fs[i]->dist : dmax;
        double l1 = 0.0;
        for (int k = 0; k < 3; k++) {
            const double a = fs[i]->apex[k];
            lo[k] = a < lo[k] ? a : lo[k];
            hi[k] = a > hi[k] ? a : hi[k];
            l1 += fabs(a);
        }
        a1 = l1 > a1 ? l1 : a1;
    }
    for (int k = 0; k < 3; k++) {
        cg[k] = 0.5 * (lo[k] + hi[k]);
        rg2 += 0.25 * (hi[k] - lo[k]) * (hi[k] - lo[k]);
    }
    const double rg = sqrt(rg2), lc1 = fabs(lc[0]) + fabs(lc[1]) + fabs(lc[2]);
    /* every point's t_far (a float of dist (1 + 2^-16)) is below this */
    const double tfar = dmax * (1.0 + 1e-5);
    for (size_t j = 0; j < npre; j++) {
        kd_tri_pre *p = &pre[j];
        p->clear = 0;
        if (!p->flat) continue;
        double c1 = 0.0, wc[3];
        for (int k = 0; k < 3; k++) {
            c1 += fabs(p->c[k]);
            wc[k] = p->c[k] - cg[k];
        }
        /* kd_cone_pre_may_block's plane slack for any point of the group
         * (its |centre - apex| is at most |centre - cg| + rg), plus 1e-9
         * relative for this function's own rounding */
        const double w = sqrt(wc[0] * wc[0] + wc[1] * wc[1] + wc[2] * wc[2]) + rg;
        const double slack = band + 1e-6 * (w + p->r + tfar) +
                             1e-9 * (a1 + c1 + p->r) +
                             1e-9 * (a1 + lc1 + reach + tfar + fabs(p->n_off));
        /* the apexes' distances to the plane lie within those of their box */
        const double dc = p->n[0] * cg[0] + p->n[1] * cg[1] + p->n[2] * cg[2] - p->n_off;
        const double ext = 0.5 * (fabs(p->n[0]) * (hi[0] - lo[0]) +
                                  fabs(p->n[1]) * (hi[1] - lo[1]) +
                                  fabs(p->n[2]) * (hi[2] - lo[2]));
        const double smin = dc - ext, smax = dc + ext;
        const double dl = p->n[0] * lc[0] + p->n[1] * lc[1] + p->n[2] * lc[2] - p->n_off;
        p->clear = (smin > slack && dl - reach > slack) || (smax < -slack && dl + reach < -slack);
    }
}

int kd_group_cone(const kdr_scene *scene, const kd_shadow_frame *const *fs, size_t n,
                  double max_spread, kd_cone *c) {
    if (n == 0) return 0;
    /* the ball around the apexes: centre of their box, farthest apex */
    double lo[3], hi[3], cg[3], rg = 0.0, rl = 0.0;
    /* the largest coordinate magnitude a point's walk uses for its band:
     * the scene's, or an apex's */
    float mag = 0.0f;
    for (int k = 0; k < 3; k++) {
        lo[k] = hi[k] = fs[0]->apex[k];
        mag = fmax_plain(mag, fmax_plain(fabsf(scene->root.min[k]), fabsf(scene->root.max[k])));
    }
    for (size_t i = 0; i < n; i++) {
        if (fs[i]->along != 0.0f) /* no fixed apex: no group */
            return 0;
        for (int k = 0; k < 3; k++) {
            const double a = fs[i]->apex[k];
            lo[k] = a < lo[k] ? a : lo[k];
            hi[k] = a > hi[k] ? a : hi[k];
            mag = fmax_plain(mag, fabsf(fs[i]->apex[k]));
        }
    }
    for (int k = 0; k < 3; k++)
        cg[k] = 0.5 * (lo[k] + hi[k]);
    const double *lc = fs[0]->center;
    double dmax = 0.0;
    for (size_t i = 0; i < n; i++) {
        const double a[3] = {fs[i]->apex[0], fs[i]->apex[1], fs[i]->apex[2]};
        const double d = dist3(a, cg);
        rg = d > rg ? d : rg;
    }
    /* rl >= the light's radius: most groups that fail, fail here, before
     * any per-point trigonometry */
    if (!(rg <= max_spread * fs[0]->radius * (1.0 + 1e-3)))
        return 0;
    for (size_t i = 0; i < n; i++) {
        const double reach = kd_frame_reach(fs[i]);
        rl = rl > reach ? rl : reach;
        dmax = dmax > fs[i]->dist ? dmax : fs[i]->dist;
    }
    /* every point's margins: its band, and the cull's relative slack over
     * the distances involved */
    const double pad =
        (double)mag * KD_SLACK_REL + GROUP_REL_PAD * (rg + rl) + 1e-6 * (dmax + rg + rl);
    rg += pad;
    rl = rl * (1.0 + GROUP_REL_PAD) + pad;
    const double D = dist3(lc, cg);
    if (!(rl > rg) || !(rg <= max_spread * rl) || !(D > rg + rl) || !isfinite(D))
        return 0;
    /* the tangent cone's apex, behind the group: rg / dA = rl / (dA + D) */
    const double dA = rg * D / (rl - rg);
    float apex[3];
    double u[3];
    for (int k = 0; k < 3; k++) {
        u[k] = (lc[k] - cg[k]) / D;
        apex[k] = (float)(cg[k] - u[k] * dA);
    }
    if (!isfinite(apex[0]) || !isfinite(apex[1]) || !isfinite(apex[2])) return 0;
    /* from the rounded apex: the axis toward the light, the half-angle
     * holding both balls */
    const double a[3] = {apex[0], apex[1], apex[2]};
    const double dl = dist3(a, lc), dg = dist3(a, cg);
    if (!(dl > rl) || !(dg > rg)) return 0;
    double axis[3], cosg = 0.0;
    for (int k = 0; k < 3; k++) {
        axis[k] = (lc[k] - a[k]) / dl;
        cosg += axis[k] * (cg[k] - a[k]) / dg;
    }
    const double half = fmax(asin(rl / dl), acos(fmin(1.0, cosg)) + asin(rg / dg)) + 1e-9;
    if (!(half < 1.2)) /* a wide cone: the points walk on their own */
        return 0;
    kd_shadow_frame g = {.dist = dl + rl, .along = 0.0f};
    for (int k = 0; k < 3; k++)
        g.apex[k] = apex[k];
    kd_cone_init(c, scene, &g, axis, sin(half));
    /* the band of the farthest point, at least */
    c->band = fmaxf(c->band, mag * KD_SLACK_REL + FLT_MIN);
    /* segments start in the apexes' ball: nothing nearer to the apex */
    double proj = 0.0;
    for (int k = 0; k < 3; k++)
        proj += (cg[k] - a[k]) * axis[k];
    c->t_near = (float)fmax(0.0, (proj - rg) * (1.0 - 1e-6));
    return 1;
}
