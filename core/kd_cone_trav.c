/*
 * kd_cone_trav.c — the cone traversal of technique 2 of Tsakok et al.: a
 * cone from a shading point toward a sphere light (or toward one group of
 * its samples) walks the kd-tree and returns the triangles that any sample
 * segment inside it could touch.
 *
 * Conservative by construction (a leaf or triangle is dropped only when no
 * sample segment can reach it):
 *  - every sample segment starts on the ray from the apex (up to rounding,
 *    covered by `band`), runs in a direction inside the cone (up to
 *    rounding, covered by CONE_SLOPE_SLACK), and ends on the sphere's near
 *    side, within the tangent length sqrt(D^2 - r^2) < D of the apex; its
 *    axial distance therefore stays in [0, t_far];
 *  - at axial distance t the cone is a disc; along world axis k the disc
 *    spans apex_k + t * [v_k - tan(a) s_k, v_k + tan(a) s_k] with
 *    s_k = sqrt(1 - v_k^2) (the paper's two denominators), so a child cell is
 *    reachable only for the t where that span reaches its side of the split;
 *  - `band` is the same positional slack (KD_SLACK_REL of the scene's and
 *    the apex's magnitude) that single-ray traversal uses, because the
 *    watertight test can accept a triangle a few ulps off its true place.
 */
#include <stdlib.h>
#include <string.h>

#include "kd_cone.h"
#include "kd_internal.h"
#include "kd_traverse.h"

/* Angular slack (radians, on the slopes) that keeps float sample directions
 * inside the traversal cone; far above their ~1e-7 rounding. */
#define CONE_SLOPE_SLACK 1e-5f
/* Relative padding of plane distances (float division rounding). */
#define CONE_REL_PAD 0x1p-20f
/* The cull's half-angle slack and relative distance slack (the latter is
 * KD_CULL_REL_SLACK of kd_cone.h: kd_cone_cull4.c uses it too). */
#define CULL_ANGLE_SLACK 1e-5
#define CULL_REL_SLACK KD_CULL_REL_SLACK
/* Beyond this half-angle the cull's cone formulas are not trusted. */
#define CULL_MAX_ANGLE 1.5707

/* ---- the cone ------------------------------------------------------------ */

/* (Plain comparisons, not fmaxf: a libm call without -ffast-math, one per
 * point and axis; no operand is NaN.) */
static float fmax_plain(float a, float b) { return a > b ? a : b; }

static float magnitude(const kdr_scene *scene, const float apex[3], float along) {
    float m = 0.0f;
    for (int k = 0; k < 3; k++) {
        m = fmax_plain(m, fmax_plain(fabsf(scene->root.min[k]), fabsf(scene->root.max[k])));
        m = fmax_plain(m, fabsf(apex[k]) + along);
    }
    return m;
}

void kd_cone_init(kd_cone *c, const kdr_scene *scene, const kd_shadow_frame *f,
                  const double *axis, double sin_a) {
    if (!axis) {
        axis = f->axis;
        sin_a = f->sin_a;
    }
    const double cos_a = sqrt((1.0 - sin_a) * (1.0 + sin_a));
    const double tan_a = sin_a / cos_a;
    for (int k = 0; k < 3; k++) {
        const double s2 = 1.0 - axis[k] * axis[k], s = sqrt(s2 > 0.0 ? s2 : 0.0);
        const float spread = (float)(tan_a * s) + CONE_SLOPE_SLACK;
        c->apex[k] = f->apex[k];
        c->dapex[k] = f->apex[k];
        c->axis[k] = axis[k];
        c->lo[k] = (float)axis[k] - spread;
        c->hi[k] = (float)axis[k] + spread;
        c->inv_lo[k] = 1.0f / c->lo[k];    /* the paper's precomputed */
        c->inv_nhi[k] = -1.0f / c->hi[k];  /* denominators, inverted */
    }
    c->band = magnitude(scene, f->apex, f->along) * KD_SLACK_REL + FLT_MIN;
    c->t_far = (float)f->dist * (1.0f + 0x1p-16f) + f->along;
    c->t_near = 0.0f;
    /* the half-angle widened by CULL_ANGLE_SLACK, by the angle-sum formulas
     * (cos and sin of the slack fold at compile time) rather than asin, cos
     * and sin per cone: the results differ from libm's in the last bits,
     * far inside the slack itself */
    const double cs = cos(CULL_ANGLE_SLACK), sn = sin(CULL_ANGLE_SLACK);
    if (sin_a < sin(CULL_MAX_ANGLE - CULL_ANGLE_SLACK)) {
        c->cos_p = cos_a * cs - sin_a * sn;
        c->sin_p = sin_a * cs + cos_a * sn;
        c->tan_p = c->sin_p / c->cos_p;
    } else { /* within 1e-4 rad of a hemisphere: cull disabled */
        c->cos_p = 0.0;
        c->sin_p = 1.0;
        c->tan_p = INFINITY;
    }
}

/* The t >= 0 with t*m <= e (inv_m = 1/m), as [*lo, *hi] padded outward
 * (CONE_REL_PAD covers the rounding of the reciprocal and the product); 0
 * (and *lo, *hi untouched) if none. A zero slope never reaches a product. This
 * one case analysis covers the hard cases: an axis parallel to the plane
 * (both slopes non-zero thanks to the slack), wide cones whose slopes have
 * opposite signs (one side is reached from the apex on, the other never ends),
 * and an apex on the plane (e = band >= 0 on both sides). */
static int halfline(float m, float inv_m, float e, float *lo, float *hi) {
    if (e >= 0.0f) {
        *lo = 0.0f;
        *hi = m > 0.0f ? (e * inv_m) * (1.0f + CONE_REL_PAD) : INFINITY;
        return 1;
    }
    if (m >= 0.0f)
        return 0;
    *lo = (e * inv_m) * (1.0f - CONE_REL_PAD);
    *hi = INFINITY;
    return 1;
}

/* Interval of t where the cone reaches the side x_k <= split (below != 0)
 * or x_k >= split, clipped to [tn, tf]; 0 if empty. (Plain comparisons, not
 * fminf/fmaxf: no operand is NaN and the libm calls showed in profiles.) */
static int cone_side(const kd_cone *c, int k, float split, int below, float tn,
                     float tf, float *t0, float *t1) {
    const float delta = split - c->apex[k];
    const float band = c->band + fabsf(split) * CONE_REL_PAD;
    float lo = INFINITY, hi = 0.0f; /* empty unless halfline says otherwise */
    if (below)
        halfline(c->lo[k], c->inv_lo[k], delta + band, &lo, &hi);
    else
        halfline(-c->hi[k], c->inv_nhi[k], band - delta, &lo, &hi);
    *t0 = lo > tn ? lo : tn;
    *t1 = hi < tf ? hi : tf;
    return *t0 <= *t1;
}

/* Clips [0, t_far] to the scene's padded root box. */
static int cone_clip_root(const kdr_scene *scene, const kd_cone *c, float *tn,
                          float *tf) {
    *tn = c->t_near;
    *tf = c->t_far;
    for (int k = 0; k < 3; k++) {
        if (!cone_side(c, k, scene->root.min[k], 0, *tn, *tf, tn, tf))
            return 0;
        if (!cone_side(c, k, scene->root.max[k], 1, *tn, *tf, tn, tf))
            return 0;
    }
    return 1;
}

/* ---- candidate culling ---------------------------------------------------- */

/* Plain-comparison min/max: fmin/fmax are libm calls here (they must treat
 * NaN specially) and took ~9% of cone time at 4 spp; no operand of the cull
 * is NaN (scene coordinates are finite, nn > 0 is checked). */
static inline double dmin(double a, double b) { return a < b ? a : b; }
static inline double dmax(double a, double b) { return a > b ? a : b; }

/* The signed distance range of the truncated cone over the plane through
 * p with unit normal m: [*lo, *hi]. */
static void cone_range(const kd_cone *cc, const double m[3], const float *p, double *lo,
                       double *hi, double *wlen) {
    double w[3];
    for (int k = 0; k < 3; k++)
        w[k] = cc->dapex[k] - p[k];
    const double d_apex = m[0] * w[0] + m[1] * w[1] + m[2] * w[2];
    const double mv = m[0] * cc->axis[0] + m[1] * cc->axis[1] + m[2] * cc->axis[2];
    const double d_disc = d_apex + (double)cc->t_far * mv;
    const double spread = (double)cc->t_far * cc->tan_p * sqrt(dmax(0.0, 1.0 - mv * mv));
    *lo = dmin(d_apex, d_disc - spread);
    *hi = dmax(d_apex, d_disc + spread);
    *wlen = sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2]);
}

/* 1 if the truncated cone lies wholly outside one side of the triangle's
 * prism (the plane through an edge, perpendicular to the triangle, facing
 * away from the third vertex): no point of the triangle is in the cone.
 * Catches the large triangles beside a cone that the bounding-sphere test
 * keeps (walls, floors), each of which would otherwise get a proof. */
static int prism_misses(const kd_cone *cc, const float *tri, const double n[3]) {
    for (int i = 0; i < 3; i++) {
        const float *a = tri + 3 * i, *b = tri + 3 * ((i + 1) % 3), *o = tri + 3 * ((i + 2) % 3);
        double e[3], m[3], lo, hi, wlen;
        for (int k = 0; k < 3; k++)
            e[k] = (double)b[k] - a[k];
        m[0] = e[1] * n[2] - e[2] * n[1];
        m[1] = e[2] * n[0] - e[0] * n[2];
        m[2] = e[0] * n[1] - e[1] * n[0];
        const double ml = sqrt(m[0] * m[0] + m[1] * m[1] + m[2] * m[2]);
        if (!(ml > 0.0))
            continue;
        double side = 0.0;
        for (int k = 0; k < 3; k++) {
            m[k] /= ml;
            side += m[k] * ((double)o[k] - a[k]);
        }
        if (side > 0.0) /* face away from the third vertex */
            for (int k = 0; k < 3; k++)
                m[k] = -m[k];
        cone_range(cc, m, a, &lo, &hi, &wlen);
        if (lo > cc->band + CULL_REL_SLACK * (wlen + (double)cc->t_far))
            return 1;
    }
    return 0;
}

/* 1 if the triangle's plane has the whole truncated cone strictly on one
 * side. The truncated cone is the convex hull of the apex and its disc at
 * axial distance reach, so the plane's signed distance over it ranges over
 * the apex's value and the disc's centre value +- the disc's extent.
 * Otherwise sets un to the plane's unit normal (0 for a degenerate one). */
static int plane_misses(const kd_cone *cc, const float *tri, double un[3]) {
    double e1[3], e2[3], w[3];
    for (int k = 0; k < 3; k++) {
        e1[k] = (double)tri[3 + k] - tri[k];
        e2[k] = (double)tri[6 + k] - tri[k];
        w[k] = cc->dapex[k] - tri[k];
    }
    double n[3] = {e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2],
                   e1[0] * e2[1] - e1[1] * e2[0]};
    const double nn = sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    if (!(nn > 0.0))
        return 0;
    const double d_apex = (n[0] * w[0] + n[1] * w[1] + n[2] * w[2]) / nn;
    const double nv = (n[0] * cc->axis[0] + n[1] * cc->axis[1] + n[2] * cc->axis[2]) / nn;
    const double d_disc = d_apex + (double)cc->t_far * nv;
    const double spread = (double)cc->t_far * cc->tan_p * sqrt(dmax(0.0, 1.0 - nv * nv));
    const double wlen = sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2]);
    const double slack = cc->band + CULL_REL_SLACK * (wlen + (double)cc->t_far);
    const double lo = dmin(d_apex, d_disc - spread);
    const double hi = dmax(d_apex, d_disc + spread);
    if (lo > slack || hi < -slack)
        return 1;
    for (int k = 0; k < 3; k++)
        un[k] = n[k] / nn;
    return 0;
}

/* 0 only if the triangle provably misses every sample segment: its
 * bounding sphere lies beyond the segments' axial reach or farther from
 * the cone than its radius, or its plane leaves the truncated cone on one
 * side, or (with prism) the cone lies outside one side of its prism. The
 * sphere goes first: most triangles a walk meets lie beside the cone, and
 * it drops them before the plane is formed (the same triangles are kept
 * in either order; callgrind of the default picture -2.5%). The sphere
 * test is kd_cone_tri_sphere_may (kd_cone_tri_sphere4 makes it for four
 * triangles at once in the walks' leaves), the rest tri_rest_may. */
int kd_cone_tri_sphere_may(const kd_cone *cc, const float *tri) {
    double m[3], w[3], r2 = 0.0;
    for (int k = 0; k < 3; k++) {
        const double lo = dmin(tri[k], dmin(tri[3 + k], tri[6 + k]));
        const double hi = dmax(tri[k], dmax(tri[3 + k], tri[6 + k]));
        m[k] = 0.5 * (lo + hi);
        w[k] = m[k] - cc->dapex[k];
    }
    for (int j = 0; j < 3; j++) {
        double d2 = 0.0;
        for (int k = 0; k < 3; k++)
            d2 += (tri[3 * j + k] - m[k]) * (tri[3 * j + k] - m[k]);
        r2 = dmax(r2, d2);
    }
    const double proj = w[0] * cc->axis[0] + w[1] * cc->axis[1] + w[2] * cc->axis[2];
    const double cx = w[1] * cc->axis[2] - w[2] * cc->axis[1];
    const double cy = w[2] * cc->axis[0] - w[0] * cc->axis[2];
    const double cz = w[0] * cc->axis[1] - w[1] * cc->axis[0];
    const double perp = sqrt(cx * cx + cy * cy + cz * cz);
    const double wlen = sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2]);
    const double r = sqrt(r2);
    const double rad = r + cc->band + CULL_REL_SLACK * (wlen + r);
    if (proj - rad > (double)cc->t_far || proj + rad < (double)cc->t_near)
        return 0;
    if (proj * cc->cos_p + perp * cc->sin_p <= 0.0) { /* nearest: the apex */
        if (!(wlen <= rad))
            return 0;
    } else if (!(perp * cc->cos_p - proj * cc->sin_p <= rad)) {
        return 0;
    }
    return 1;
}

/* tri_may_block after the sphere: the plane, then (prism) the sides. */
static int tri_rest_may(const kd_cone *cc, const float *tri, int prism) {
    double un[3] = {0, 0, 0};
    if (plane_misses(cc, tri, un))
        return 0;
    return !(prism && prism_misses(cc, tri, un));
}

static int tri_may_block(const kd_cone *cc, const float *tri, int prism) {
    if (cc->cos_p == 0.0) /* near-hemisphere cone: keep everything */
        return 1;
    return kd_cone_tri_sphere_may(cc, tri) && tri_rest_may(cc, tri, prism);
}

int kd_cone_tri_may_block(const kd_cone *c, const float *tri) {
    return tri_may_block(c, tri, 1);
}

int kd_cone_tri_rest_may(const kd_cone *c, const float *tri) {
    return tri_rest_may(c, tri, 1);
}

void kd_tri_pre_init(kd_tri_pre *p, const float *tri, uint32_t prim) {
    kd_tri_pre_plane(p, tri, prim);
    kd_tri_pre_sides(p, tri);
}

void kd_tri_pre_plane(kd_tri_pre *p, const float *tri, uint32_t prim) {
    double e1[3], e2[3], r2 = 0.0;
    p->prim = prim;
    for (int k = 0; k < 3; k++) {
        const double lo = dmin(tri[k], dmin(tri[3 + k], tri[6 + k]));
        const double hi = dmax(tri[k], dmax(tri[3 + k], tri[6 + k]));
        p->c[k] = 0.5 * (lo + hi);
        e1[k] = (double)tri[3 + k] - tri[k];
        e2[k] = (double)tri[6 + k] - tri[k];
    }
    for (int j = 0; j < 3; j++) {
        double d2 = 0.0;
        for (int k = 0; k < 3; k++)
            d2 += (tri[3 * j + k] - p->c[k]) * (tri[3 * j + k] - p->c[k]);
        r2 = dmax(r2, d2);
    }
    p->r = sqrt(r2);
    double n[3] = {e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2],
                   e1[0] * e2[1] - e1[1] * e2[0]};
    const double nn = sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    p->flat = nn > 0.0;
    p->clear = 0;
    for (int k = 0; k < 3; k++)
        p->n[k] = p->flat ? n[k] / nn : 0.0;
    p->n_off = p->n[0] * tri[0] + p->n[1] * tri[1] + p->n[2] * tri[2];
}

void kd_tri_pre_sides(kd_tri_pre *p, const float *tri) {
    for (int i = 0; i < 3; i++) {
        const float *a = tri + 3 * i, *b = tri + 3 * ((i + 1) % 3), *o = tri + 3 * ((i + 2) % 3);
        double e[3], m[3], side = 0.0;
        for (int k = 0; k < 3; k++)
            e[k] = (double)b[k] - a[k];
        m[0] = e[1] * p->n[2] - e[2] * p->n[1];
        m[1] = e[2] * p->n[0] - e[0] * p->n[2];
        m[2] = e[0] * p->n[1] - e[1] * p->n[0];
        const double ml = sqrt(m[0] * m[0] + m[1] * m[1] + m[2] * m[2]);
        for (int k = 0; k < 3; k++) {
            m[k] = ml > 0.0 ? m[k] / ml : 0.0;
            side += m[k] * ((double)o[k] - a[k]);
        }
        const double s = side > 0.0 ? -1.0 : 1.0; /* away from the third vertex */
        for (int k = 0; k < 3; k++)
            p->e[i][k] = s * m[k];
        p->e_off[i] = p->e[i][0] * a[0] + p->e[i][1] * a[1] + p->e[i][2] * a[2];
    }
}

/* The signed distance range [*lo, *hi] of the truncated cone over the
 * plane {x : m . x = off} (m unit). */
static void pre_range(const kd_cone *cc, const double m[3], double off, double *lo,
                      double *hi) {
    const double d_apex = m[0] * cc->dapex[0] + m[1] * cc->dapex[1] + m[2] * cc->dapex[2] - off;
    const double mv = m[0] * cc->axis[0] + m[1] * cc->axis[1] + m[2] * cc->axis[2];
    const double d_disc = d_apex + (double)cc->t_far * mv;
    const double spread = (double)cc->t_far * cc->tan_p * sqrt(dmax(0.0, 1.0 - mv * mv));
    *lo = dmin(d_apex, d_disc - spread);
    *hi = dmax(d_apex, d_disc + spread);
}

/* tri_may_block's three tests (plane first: here it is precomputed and
 * cheap; the order changes no answer). Its slacks use distances
 * from the apex to a vertex or the sphere's centre; here all are bounded by
 * |apex - c| + r, so the margins are at least as wide, plus 1e-9 relative
 * for the offsets' own rounding (|off| up to the scene's magnitude). */
int kd_cone_pre_may_block(const kd_cone *cc, const kd_tri_pre *p) {
    if (cc->cos_p == 0.0)
        return 1;
    double w[3];
    for (int k = 0; k < 3; k++)
        w[k] = p->c[k] - cc->dapex[k];
    const double wlen = sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2]);
    const double own = 1e-9 * (fabs(cc->dapex[0]) + fabs(cc->dapex[1]) + fabs(cc->dapex[2]) +
                               fabs(p->c[0]) + fabs(p->c[1]) + fabs(p->c[2]) + p->r);
    const double slack = cc->band + CULL_REL_SLACK * (wlen + p->r + (double)cc->t_far) + own;
    double lo, hi;
    if (p->flat) {
        pre_range(cc, p->n, p->n_off, &lo, &hi);
        if (lo > slack || hi < -slack)
            return 0;
    }
    const double proj = w[0] * cc->axis[0] + w[1] * cc->axis[1] + w[2] * cc->axis[2];
    const double cx = w[1] * cc->axis[2] - w[2] * cc->axis[1];
    const double cy = w[2] * cc->axis[0] - w[0] * cc->axis[2];
    const double cz = w[0] * cc->axis[1] - w[1] * cc->axis[0];
    const double perp = sqrt(cx * cx + cy * cy + cz * cz);
    const double rad = p->r + cc->band + CULL_REL_SLACK * (wlen + p->r) + own;
    if (proj - rad > (double)cc->t_far || proj + rad < (double)cc->t_near)
        return 0;
    if (proj * cc->cos_p + perp * cc->sin_p <= 0.0) {
        if (wlen > rad)
            return 0;
    } else if (perp * cc->cos_p - proj * cc->sin_p > rad) {
        return 0;
    }
    if (p->flat)
        for (int i = 0; i < 3; i++) {
            pre_range(cc, p->e[i], p->e_off[i], &lo, &hi);
            if (lo > slack)
                return 0;
        }
    return 1;
}

static int cmp_u32(const void *a, const void *b) {
    const uint32_t x = *(const uint32_t *)a, y = *(const uint32_t *)b;
    return (x > y) - (x < y);
}

/* ---- the walk ------------------------------------------------------------------ */

/* Walks from it down to a leaf, stacking the far child wherever the cone
 * reaches both sides (the apex's side is near: front to back, so that a
 * packet of samples meets its nearest blockers first); NULL if the cone
 * leaves the subtree. */
static const kd_node *cone_descend(kd_cone_walk *w, kd_cone_item it) {
    const kd_node *nodes = w->scene->nodes, *node = &nodes[it.node];
    const kd_cone *c = w->cone;
    for (;;) {
        w->visited++;
        if (kd_is_leaf(node))
            return node;
        const int k = kd_axis(node);
        const float split = node->u.split;
        kd_cone_item b = {(uint32_t)(node - nodes) + 1, 0, 0};
        kd_cone_item a = {kd_above(node), 0, 0};
        /* an empty child (kd_layout's flags) holds nothing to reach */
        const int below = !kd_below_empty(node) &&
                          cone_side(c, k, split, 1, it.tn, it.tf, &b.tn, &b.tf);
        const int above = !kd_above_empty(node) &&
                          cone_side(c, k, split, 0, it.tn, it.tf, &a.tn, &a.tf);
        const int below_first = c->apex[k] <= split;
        if (below && above) {
            w->stack[w->top++] = below_first ? a : b;
            it = below_first ? b : a;
        } else if (below || above) {
            it = below ? b : a;
        } else {
            return NULL;
        }
        node = &nodes[it.node];
    }
}

void kd_cone_walk_init(kd_cone_walk *w, const kdr_scene *scene,
                       const kd_cone *c) {
    float tn, tf;
    w->scene = scene;
    w->cone = c;
    w->top = 0;
    w->visited = 0;
    if (scene->nodes && cone_clip_root(scene, c, &tn, &tf))
        w->stack[w->top++] = (kd_cone_item){0, tn, tf};
}

/*
 * The paper's cone traversal with a stack: at each split, each child is
 * entered over the part of [tn, tf] where the cone reaches its side of the
 * plane (cone_side); see the file comment for why no reachable leaf is
 * skipped. Returns the next leaf, or NULL when the walk is over.
 */
const kd_node *kd_cone_walk_next(kd_cone_walk *w) {
    while (w->top > 0) {
        const kd_node *leaf = cone_descend(w, w->stack[--w->top]);
        if (leaf)
            return leaf;
    }
    return NULL;
}

/* Triangles a walk has judged, so that one straddling several leaves is
 * culled once (open addressing; stops remembering when half full). */
#define SEEN_SLOTS 256u
typedef struct seen_set {
    uint32_t prim[SEEN_SLOTS];
    uint32_t n;
} seen_set;

/* 1 if prim was judged before in this walk; else remembers it. */
static int seen_before(seen_set *st, uint32_t prim) {
    for (uint32_t h = (prim * 2654435761u) >> 24;; h = (h + 1) & (SEEN_SLOTS - 1)) {
        if (st->prim[h] == UINT32_MAX) {
            if (st->n < SEEN_SLOTS / 2) {
                st->prim[h] = prim;
                st->n++;
            }
            return 0;
        }
        if (st->prim[h] == prim)
            return 1;
    }
}

/* Appends the leaf's triangles that may touch a segment; 0 once the list
 * is over max (or memory runs out: *rc = KDR_ENOMEM). */
static int take_leaf(const kdr_scene *scene, const kd_cone *c, const kd_node *leaf,
                     kd_cand_list *cl, size_t max, int prism, seen_set *seen, int wide4,
                     int *rc) {
    const uint32_t *refs = scene->refs + leaf->u.first;
    const uint32_t count = kd_count(leaf);
    if (cl->n + count > cl->cap) {
        size_t cap = cl->cap ? cl->cap : 256;
        while (cap < cl->n + count)
            cap *= 2;
        uint32_t *v = realloc(cl->v, cap * sizeof *v);
        if (!v) {
            *rc = KDR_ENOMEM;
            return 0;
        }
        cl->v = v;
        cl->cap = cap;
    }
    if (wide4 && c->cos_p != 0.0) {
        /* the sphere tests four at a time (kd_cone_cull4.c: the same
         * answers), the rest one by one, in the leaf's order */
        const float *tris[4];
        uint32_t prims[4];
        int nb = 0;
        for (uint32_t j = 0; j <= count; j++) {
            if (j < count && !seen_before(seen, refs[j])) {
                prims[nb] = refs[j];
                tris[nb++] = scene->tris + 9 * (size_t)refs[j];
            }
            if (nb == 4 || (j == count && nb > 0)) {
                const int near = kd_cone_tri_sphere4(c, tris, nb);
                for (int i = 0; i < nb; i++)
                    if ((near >> i) & 1 && tri_rest_may(c, tris[i], prism))
                        cl->v[cl->n++] = prims[i];
                nb = 0;
            }
        }
    } else {
        for (uint32_t j = 0; j < count; j++) {
            if (!seen_before(seen, refs[j]) &&
                tri_may_block(c, scene->tris + 9 * (size_t)refs[j], prism))
                cl->v[cl->n++] = refs[j];
        }
    }
    if (cl->n > max) {
        *rc = KD_CONE_OVER;
        return 0;
    }
    return 1;
}

/* Sorts and drops duplicates (a triangle straddling splits sits in several
 * leaves; only needed when the walk's seen set was full). */
static void cand_unique(kd_cand_list *cl) {
    if (cl->n < 2) /* also: qsort must not see the NULL of an empty list */
        return;
    qsort(cl->v, cl->n, sizeof *cl->v, cmp_u32);
    size_t out = 0;
    for (size_t j = 0; j < cl->n; j++) {
        if (out == 0 || cl->v[j] != cl->v[out - 1])
            cl->v[out++] = cl->v[j];
    }
    cl->n = out;
}

int kd_cone_collect(const kdr_scene *scene, const kd_cone *c, kd_cand_list *cl,
                    size_t max_cands, uint64_t max_nodes, int prism, uint64_t *nodes) {
    kd_cone_walk w;
    const kd_node *leaf;
    int rc = KDR_OK;
    seen_set seen;
    memset(seen.prim, 0xff, sizeof seen.prim);
    seen.n = 0;
    cl->n = 0;
    const int wide4 = kdr_cpu_has_avx2();
    kd_cone_walk_init(&w, scene, c);
    while (rc == KDR_OK && (leaf = kd_cone_walk_next(&w)) != NULL) {
        if (!take_leaf(scene, c, leaf, cl, max_cands, prism, &seen, wide4, &rc))
            break;
        if (w.visited > max_nodes)
            rc = KD_CONE_OVER;
    }
    *nodes += w.visited;
    if (rc == KDR_OK && seen.n >= SEEN_SLOTS / 2)
        cand_unique(cl); /* the seen set filled up: duplicates are possible */
    return rc;
}
