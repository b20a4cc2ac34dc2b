/*
 * kd_cone.c — the cone-shadow query (kdr_shadow_trace): visibility of
 * spherical lights from points, as the fraction of kdr_shadow_ray samples
 * that reach the light.
 *
 * KDR_SHADOW_CONE walks the kd-tree once per (point, light) with the cone
 * from the point around the light (technique 2 of Tsakok et al.), collects
 * the triangles of every leaf the cone reaches, drops those whose bounding
 * sphere misses the cone, and then tests the samples against that short
 * list only. A cone that reaches no triangle is decided (visibility 1, no
 * rays). Because the list is a superset of every triangle any sample segment
 * can touch, and the samples use the same triangle test as kdr_occluded1,
 * both modes give the same answer bit for bit. KDR_SHADOW_RAYS traces every
 * sample through the kd-tree (the reference).
 */
#include <stdlib.h>

#include "kd_cone.h"
#include "kd_internal.h"
#include "kd_tri.h"

#define SHADOW_MAX_SAMPLES 4096u
/* Angular slack (radians, on the slopes) that keeps float sample directions
 * inside the traversal cone; far above their ~1e-7 rounding. */
#define CONE_SLOPE_SLACK 1e-5f
/* Relative padding of plane distances and of the origin band. */
#define CONE_REL_PAD 0x1p-20f
/* Beyond this many candidates per sample a kd-tree ray is cheaper than the
 * linear list (measured with bench/bench_cone.c). */
#define CONE_MAX_LINEAR 48u

/* ---- the cone as the traversal sees it ---------------------------------- */

/*
 * The cone is the union over t >= 0 (t = distance along the axis) of discs
 * centred at apex + t*v of radius t*tan(alpha). Along world axis k such a
 * disc spans apex_k + t*[v_k - tan(alpha)*s_k, v_k + tan(alpha)*s_k] with
 * s_k = sqrt(1 - v_k^2): the paper's two denominators n.v -/+ tan(alpha)
 * sqrt(1 - (n.v)^2). lo[k] and hi[k] are those slopes widened by
 * CONE_SLOPE_SLACK.
 */
typedef struct cone {
    float apex[3];
    float lo[3], hi[3];
    float band;   /* absolute error of sample origins around the apex */
    float t_far;  /* axial extent: every sample segment ends before it */
} cone;

static void cone_setup(const kd_shadow_frame *f, cone *c) {
    const double cos_a = 1.0 - f->one_minus_cos;
    const double tan_a = f->sin_a / cos_a;
    float mag = f->along;
    for (int k = 0; k < 3; k++) {
        const double v = f->axis[k];
        const double s = sqrt(fmax(0.0, 1.0 - v * v));
        const float spread = (float)(tan_a * s) + CONE_SLOPE_SLACK;
        c->apex[k] = f->apex[k];
        c->lo[k] = (float)v - spread;
        c->hi[k] = (float)v + spread;
        mag += fabsf(f->apex[k]);
    }
    c->band = mag * CONE_REL_PAD + FLT_MIN;
    /* samples end on the sphere's near side, within the tangent length
     * sqrt(D^2 - r^2) < D of the apex */
    c->t_far = (float)f->dist * (1.0f + 0x1p-16f) + f->along;
}

/* The t >= 0 with t*m <= e, as [*lo, *hi] padded outward; 0 (and *lo, *hi
 * untouched) if none. This
 * one case analysis covers the hard cases: an axis parallel to the plane
 * (both slopes non-zero thanks to the slack), wide cones whose slopes have
 * opposite signs (one side is reached from the apex on, the other never ends),
 * and an apex on the plane (e = band >= 0 on both sides). */
static int halfline(float m, float e, float *lo, float *hi) {
    if (e >= 0.0f) {
        *lo = 0.0f;
        *hi = m > 0.0f ? (e / m) * (1.0f + CONE_REL_PAD) : INFINITY;
        return 1;
    }
    if (m >= 0.0f)
        return 0;
    *lo = (e / m) * (1.0f - CONE_REL_PAD);
    *hi = INFINITY;
    return 1;
}

/* Interval of t where the cone reaches the side x_k <= split (below != 0)
 * or x_k >= split, clipped to [tn, tf]; 0 if empty. */
static int cone_side(const cone *c, int k, float split, int below, float tn,
                     float tf, float *t0, float *t1) {
    const float delta = split - c->apex[k];
    const float band = c->band + fabsf(split) * CONE_REL_PAD;
    float lo = INFINITY, hi = 0.0f; /* empty unless halfline says otherwise */
    if (below)
        halfline(c->lo[k], delta + band, &lo, &hi);
    else
        halfline(-c->hi[k], band - delta, &lo, &hi);
    *t0 = fmaxf(lo, tn);
    *t1 = fminf(hi, tf);
    return *t0 <= *t1;
}

/* Clips [0, t_far] to the scene's padded root box. */
static int cone_clip_root(const kdr_scene *scene, const cone *c, float *tn,
                          float *tf) {
    *tn = 0.0f;
    *tf = c->t_far;
    for (int k = 0; k < 3; k++) {
        if (!cone_side(c, k, scene->root.min[k], 0, *tn, *tf, tn, tf))
            return 0;
        if (!cone_side(c, k, scene->root.max[k], 1, *tn, *tf, tn, tf))
            return 0;
    }
    return 1;
}

/* ---- candidate list -------------------------------------------------------- */

typedef struct cand_list {
    uint32_t *v;
    size_t n, cap;
} cand_list;

static int cand_append(cand_list *cl, const uint32_t *refs, size_t count) {
    if (cl->n + count > cl->cap) {
        size_t cap = cl->cap ? cl->cap : 256;
        while (cap < cl->n + count)
            cap *= 2;
        uint32_t *v = realloc(cl->v, cap * sizeof *v);
        if (!v)
            return KDR_ENOMEM;
        cl->v = v;
        cl->cap = cap;
    }
    for (size_t j = 0; j < count; j++)
        cl->v[cl->n + j] = refs[j];
    cl->n += count;
    return KDR_OK;
}

typedef struct cone_item {
    uint32_t node;
    float tn, tf;
} cone_item;

/* Walks from it.node down to a leaf, pushing the far child wherever the
 * cone reaches both sides; NULL if the cone leaves the subtree. */
static const kd_node *cone_descend(const kdr_scene *scene, const cone *c,
                                   cone_item it, cone_item *stack, int *top,
                                   uint64_t *nodes_visited) {
    const kd_node *node = &scene->nodes[it.node];
    for (;;) {
        ++*nodes_visited;
        if (kd_is_leaf(node))
            return node;
        const int k = kd_axis(node);
        const float split = node->u.split;
        float b0, b1, a0, a1;
        const int below = cone_side(c, k, split, 1, it.tn, it.tf, &b0, &b1);
        const int above = cone_side(c, k, split, 0, it.tn, it.tf, &a0, &a1);
        if (below && above)
            stack[(*top)++] = (cone_item){kd_above(node), a0, a1};
        if (below) {
            node = node + 1;
            it.tn = b0;
            it.tf = b1;
        } else if (above) {
            node = &scene->nodes[kd_above(node)];
            it.tn = a0;
            it.tf = a1;
        } else {
            return NULL;
        }
    }
}

/*
 * The paper's cone traversal with a stack: at each split, each child is
 * entered over the part of [tn, tf] where the cone reaches its side of the
 * plane (cone_side). No leaf that a sample segment can enter is skipped:
 * every segment lies inside the (slack-widened) cone between axial
 * distances 0 and t_far, and at axial distance t the cone lies within its
 * slope bounds on every axis, so a segment point in a child's cell has an
 * axial distance inside that child's interval.
 */
static int cone_collect(const kdr_scene *scene, const cone *c, cand_list *cl,
                        uint64_t *nodes_visited) {
    cone_item stack[KD_MAX_DEPTH + 2]; /* one push per level at most */
    int top = 0;
    float tn, tf;
    if (!scene->nodes || !cone_clip_root(scene, c, &tn, &tf))
        return KDR_OK;
    stack[top++] = (cone_item){0, tn, tf};
    while (top > 0) {
        const kd_node *leaf =
            cone_descend(scene, c, stack[--top], stack, &top, nodes_visited);
        if (leaf && cand_append(cl, scene->refs + leaf->u.first,
                                kd_count(leaf)) != KDR_OK)
            return KDR_ENOMEM;
    }
    return KDR_OK;
}

/* ---- candidate culling ------------------------------------------------------- */

/* The cone again, in double, for the per-triangle bounding-sphere test. */
typedef struct cull_cone {
    double apex[3], axis[3];
    double cos_p, sin_p, tan_p; /* half-angle widened by CULL_ANGLE_SLACK */
    double reach;        /* axial extent of the sample segments */
    double band;         /* sample origins' distance from the apex line */
} cull_cone;

#define CULL_ANGLE_SLACK 1e-5
#define CULL_REL_SLACK 1e-6

static void cull_setup(const kd_shadow_frame *f, const cone *c, cull_cone *cc) {
    const double a = asin(f->sin_a) + CULL_ANGLE_SLACK;
    for (int k = 0; k < 3; k++) {
        cc->apex[k] = f->apex[k];
        cc->axis[k] = f->axis[k];
    }
    cc->cos_p = cos(a);
    cc->sin_p = sin(a);
    cc->tan_p = cc->sin_p / cc->cos_p;
    cc->reach = c->t_far;
    cc->band = c->band;
}

/* 1 if the triangle's plane has the whole truncated cone strictly on one
 * side. The truncated cone is the convex hull of the apex and its disc at
 * axial distance reach, so the plane's signed distance over it ranges over
 * the apex's value and the disc's centre value +- the disc's extent. */
static int plane_misses(const cull_cone *cc, const float *tri) {
    double e1[3], e2[3], w[3];
    for (int k = 0; k < 3; k++) {
        e1[k] = (double)tri[3 + k] - tri[k];
        e2[k] = (double)tri[6 + k] - tri[k];
        w[k] = cc->apex[k] - tri[k];
    }
    double n[3] = {e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2],
                   e1[0] * e2[1] - e1[1] * e2[0]};
    const double nn = sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    if (!(nn > 0.0))
        return 0;
    const double d_apex = (n[0] * w[0] + n[1] * w[1] + n[2] * w[2]) / nn;
    const double nv = (n[0] * cc->axis[0] + n[1] * cc->axis[1] + n[2] * cc->axis[2]) / nn;
    const double d_disc = d_apex + cc->reach * nv;
    const double spread = cc->reach * cc->tan_p * sqrt(fmax(0.0, 1.0 - nv * nv));
    const double wlen = sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2]);
    const double slack = cc->band + CULL_REL_SLACK * (wlen + cc->reach);
    const double lo = fmin(d_apex, d_disc - spread);
    const double hi = fmax(d_apex, d_disc + spread);
    return lo > slack || hi < -slack;
}

/* 0 only if the triangle provably misses every sample segment: its plane
 * leaves the truncated cone on one side, or its bounding sphere lies beyond
 * the segments' axial reach or farther from the cone than its radius. */
static int tri_may_block(const cull_cone *cc, const float *tri) {
    if (plane_misses(cc, tri))
        return 0;
    double m[3], w[3], r2 = 0.0;
    for (int k = 0; k < 3; k++) {
        const double lo = fmin(tri[k], fmin(tri[3 + k], tri[6 + k]));
        const double hi = fmax(tri[k], fmax(tri[3 + k], tri[6 + k]));
        m[k] = 0.5 * (lo + hi);
        w[k] = m[k] - cc->apex[k];
    }
    for (int j = 0; j < 3; j++) {
        double d2 = 0.0;
        for (int k = 0; k < 3; k++)
            d2 += (tri[3 * j + k] - m[k]) * (tri[3 * j + k] - m[k]);
        r2 = fmax(r2, d2);
    }
    const double proj = w[0] * cc->axis[0] + w[1] * cc->axis[1] + w[2] * cc->axis[2];
    const double cx = w[1] * cc->axis[2] - w[2] * cc->axis[1];
    const double cy = w[2] * cc->axis[0] - w[0] * cc->axis[2];
    const double cz = w[0] * cc->axis[1] - w[1] * cc->axis[0];
    const double perp = sqrt(cx * cx + cy * cy + cz * cz);
    const double wlen = sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2]);
    const double r = sqrt(r2);
    const double rad = r + cc->band + CULL_REL_SLACK * (wlen + r);
    if (proj - rad > cc->reach)
        return 0;
    if (proj * cc->cos_p + perp * cc->sin_p <= 0.0) /* nearest: the apex */
        return wlen <= rad;
    return perp * cc->cos_p - proj * cc->sin_p <= rad;
}

static int cmp_u32(const void *a, const void *b) {
    const uint32_t x = *(const uint32_t *)a, y = *(const uint32_t *)b;
    return (x > y) - (x < y);
}

/* Sorts, removes duplicates (a triangle straddling splits sits in several
 * leaves) and drops triangles that cannot block. */
static void cand_filter(const kdr_scene *scene, const cull_cone *cc,
                        cand_list *cl) {
    qsort(cl->v, cl->n, sizeof *cl->v, cmp_u32);
    size_t out = 0;
    for (size_t j = 0; j < cl->n; j++) {
        if (j > 0 && cl->v[j] == cl->v[j - 1])
            continue;
        if (tri_may_block(cc, scene->tris + 9 * (size_t)cl->v[j]))
            cl->v[out++] = cl->v[j];
    }
    cl->n = out;
}

/* ---- sample tracing ------------------------------------------------------ */

/* Fraction of the frame's samples that reach the light, each sample traced
 * through the whole kd-tree. */
static float visibility_by_rays(const kdr_scene *scene,
                                const kd_shadow_frame *f, uint32_t nsamples,
                                kdr_shadow_stats *stats) {
    kdr_trav_stats ts = {0};
    uint32_t lit = 0;
    for (uint32_t s = 0; s < nsamples; s++) {
        kdr_ray r;
        kd_shadow_frame_ray(f, s, nsamples, &r);
        lit += kdr_occluded1(scene, &r, &ts) ? 0u : 1u;
    }
    if (stats) {
        stats->rays_traced += nsamples;
        stats->nodes_visited += ts.nodes_visited;
    }
    return (float)lit / (float)nsamples;
}

/* 1 if the ray hits one of the candidates; *last is the index of the latest
 * blocker, tried first because neighbouring samples share occluders. */
static int blocked_by(const kdr_scene *scene, const kdr_ray *r,
                      const cand_list *cl, size_t *last) {
    kd_ray_pre pre;
    float t, u, v;
    kd_ray_precompute(r->org, r->dir, &pre);
    const float *tris = scene->tris;
    if (*last < cl->n &&
        kd_tri_intersect(&pre, tris + 9 * (size_t)cl->v[*last], r->tmin,
                         r->tmax, &t, &u, &v))
        return 1;
    for (size_t j = 0; j < cl->n; j++) {
        if (kd_tri_intersect(&pre, tris + 9 * (size_t)cl->v[j], r->tmin,
                             r->tmax, &t, &u, &v)) {
            *last = j;
            return 1;
        }
    }
    return 0;
}

static float visibility_by_list(const kdr_scene *scene,
                                const kd_shadow_frame *f, uint32_t nsamples,
                                const cand_list *cl, kdr_shadow_stats *stats) {
    uint32_t lit = 0;
    size_t last = 0;
    for (uint32_t s = 0; s < nsamples; s++) {
        kdr_ray r;
        kd_shadow_frame_ray(f, s, nsamples, &r);
        lit += blocked_by(scene, &r, cl, &last) ? 0u : 1u;
    }
    if (stats)
        stats->rays_traced += nsamples;
    return (float)lit / (float)nsamples;
}

/* ---- the query ----------------------------------------------------------- */

static float visibility_by_cone(const kdr_scene *scene,
                                const kd_shadow_frame *f, uint32_t nsamples,
                                cand_list *cl, kdr_shadow_stats *stats,
                                int *rc) {
    cone c;
    cull_cone cc;
    uint64_t visited = 0;
    cone_setup(f, &c);
    cl->n = 0;
    *rc = cone_collect(scene, &c, cl, &visited);
    if (stats)
        stats->nodes_visited += visited;
    if (*rc != KDR_OK)
        return 0.0f;
    cull_setup(f, &c, &cc);
    cand_filter(scene, &cc, cl);
    if (cl->n == 0) {
        if (stats)
            stats->cones_decided++;
        return 1.0f;
    }
    if (cl->n > CONE_MAX_LINEAR)
        return visibility_by_rays(scene, f, nsamples, stats);
    return visibility_by_list(scene, f, nsamples, cl, stats);
}

static int query_valid(const kdr_scene *scene, const kdr_shadow_query *q,
                       size_t first, size_t count, const float *visibility) {
    if (!scene || !q || !visibility || !q->points || !q->lights)
        return 0;
    if (q->nlights < 1 || q->samples < 1 || q->samples > SHADOW_MAX_SAMPLES)
        return 0;
    return first <= q->n && count <= q->n - first;
}

int kdr_shadow_trace(const kdr_scene *scene, const kdr_shadow_query *q,
                     size_t first, size_t count, kdr_shadow_mode mode,
                     float *visibility, kdr_shadow_stats *stats) {
    if (!query_valid(scene, q, first, count, visibility))
        return KDR_EINVAL;
    if (mode != KDR_SHADOW_CONE && mode != KDR_SHADOW_RAYS)
        return KDR_EINVAL;
    cand_list cl = {0};
    int rc = KDR_OK;
    for (size_t i = first; i < first + count && rc == KDR_OK; i++) {
        for (size_t l = 0; l < q->nlights && rc == KDR_OK; l++) {
            kd_shadow_frame f;
            rc = kd_shadow_frame_init(scene, q, i, l, &f);
            if (rc != KDR_OK)
                break;
            visibility[i * q->nlights + l] =
                mode == KDR_SHADOW_RAYS
                    ? visibility_by_rays(scene, &f, q->samples, stats)
                    : visibility_by_cone(scene, &f, q->samples, &cl, stats, &rc);
        }
    }
    free(cl.v);
    return rc;
}
