/*
 * kd_closest.c — the closest point of the scene to a query point: a
 * nearest-triangle search through the kd-tree, and the exact point-triangle
 * distance it rests on.
 *
 * Search. From the root with the cell box of each node derived from the
 * splits on the way down (the root cell is the padded root box); pending
 * cells are taken nearest first (search()), and from a taken cell the walk
 * descends on the point's side of each split, pushing the other child with
 * its squared distance to the point (in float, a lower bound: cell_d2). A
 * cell is skipped when it is farther than the best distance so far plus a
 * positional slack (kd_traverse.h's KD_SLACK_REL of the largest coordinate
 * magnitude): the build places a triangle in the cells its surface meets
 * up to rounding, so the cell holding a triangle's closest point may miss
 * it by a few ulps, and the slack makes sure a neighbouring cell that
 * holds it is still searched.
 *
 * Distance. Each triangle's closest point is found in double precision by
 * the Voronoi-region walk over the vertices, edges and face (Ericson,
 * Real-Time Collision Detection, 5.1.5), from float inputs; the answer's
 * squared distance is the double distance to that point, so the kd search
 * and a brute-force loop over every triangle give the same number bit for
 * bit. Ties (equal squared distance) go to the smaller prim. Zero-area
 * triangles are never found (they are not in the tree). Before the exact
 * test a reference is culled by its triangle's bounding-box distance, in
 * float with a relative margin. On AVX2 CPUs a leaf's boxes are measured
 * eight at a time and the exact tests run four at a time in double lanes
 * that repeat the scalar operations (point_triangle4), so the answer is
 * the same bit for bit.
 */
#include <math.h>
#include <string.h>

#include "kd_internal.h"
#include "kd_traverse.h"
#include "kd_tri_ntri.h"

void kdr_point_triangle(const float p[3], const float *tri, double out_q[3],
                        double *out_u, double *out_v, double *out_d2) {
    double a[3], b[3], c[3], ab[3], ac[3], ap[3];
    for (int k = 0; k < 3; k++) {
        a[k] = tri[k];
        b[k] = tri[3 + k];
        c[k] = tri[6 + k];
        ab[k] = b[k] - a[k];
        ac[k] = c[k] - a[k];
        ap[k] = (double)p[k] - a[k];
    }
#define DOT(x, y) ((x)[0] * (y)[0] + (x)[1] * (y)[1] + (x)[2] * (y)[2])
    double u, v; /* weights of b and c */
    const double d1 = DOT(ab, ap), d2 = DOT(ac, ap);
    double bp[3], cp[3];
    for (int k = 0; k < 3; k++) {
        bp[k] = (double)p[k] - b[k];
        cp[k] = (double)p[k] - c[k];
    }
    const double d3 = DOT(ab, bp), d4 = DOT(ac, bp);
    const double d5 = DOT(ab, cp), d6 = DOT(ac, cp);
    const double vc = d1 * d4 - d3 * d2, vb = d5 * d2 - d1 * d6, va = d3 * d6 - d5 * d4;
    if (d1 <= 0.0 && d2 <= 0.0) { /* vertex a */
        u = 0.0;
        v = 0.0;
    } else if (d3 >= 0.0 && d4 <= d3) { /* vertex b */
        u = 1.0;
        v = 0.0;
    } else if (vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0) { /* edge ab */
        u = d1 / (d1 - d3);
        v = 0.0;
    } else if (d6 >= 0.0 && d5 <= d6) { /* vertex c */
        u = 0.0;
        v = 1.0;
    } else if (vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0) { /* edge ac */
        u = 0.0;
        v = d2 / (d2 - d6);
    } else if (va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0) { /* edge bc */
        v = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        u = 1.0 - v;
    } else { /* the face */
        const double den = 1.0 / (va + vb + vc);
        u = vb * den;
        v = vc * den;
    }
#undef DOT
    double d2sum = 0.0;
    for (int k = 0; k < 3; k++) {
        const double q = a[k] + u * ab[k] + v * ac[k];
        const double e = (double)p[k] - q;
        out_q[k] = q;
        d2sum += e * e;
    }
    *out_u = u;
    *out_v = v;
    *out_d2 = d2sum;
}

typedef struct cp_todo {
    f4 lo, hi; /* the cell: x, y, z and a zero lane */
    const kd_node *node;
    float d2; /* cell_d2 of the cell, taken when it was pushed */
} cp_todo;

typedef struct cp_best {
    double d2, q[3], u, v;
    int32_t prim;
    uint64_t nodes, tests;
} cp_best;

/* Squared distance from p (x, y, z, 0) to the cell [lo, hi], in float:
 * per axis max(lo - p, p - hi, 0), squared and summed (+inf on overflow
 * becomes 0: such a cell is never skipped). Each operation rounds by at
 * most 2^-24 relative, so the float sum is within 2^-21 of the exact
 * distance (plus a few 2^-149 where squares fall below the normal range):
 * worth() scales it down by more than that, so a cell is skipped only when
 * the exact distance would skip it too. */
static inline float cell_d2(f4 p, f4 lo, f4 hi) {
    const f4 e = f4_max(f4_max(f4_sub(lo, p), f4_sub(p, hi)), f4_set1(0.0f));
    const f4 sq = f4_mul(e, e);
    /* (x + y) + z in registers (a store and three loads made the push
     * wait for store forwarding) */
    const float d2 = f4_sum3(sq);
    return d2 < INFINITY ? d2 : 0.0f;
}

/* All ones in lane axis, zeros elsewhere. */
static inline f4 axis_mask(int axis) {
    static const _Alignas(16) int32_t m[3][4] = {{-1, 0, 0, 0}, {0, -1, 0, 0}, {0, 0, -1, 0}};
    return f4_load_words(m[axis]);
}

/* A cell is searched while its distance (a lower bound of it) is at most
 * the best plus the slack: limit() turns the best into the bound a cell's
 * scaled distance is compared with (recomputed only when the best changes,
 * so a cell's test is one multiply and one compare). */
static double limit(double best_d2, double slack) {
    const double r = sqrt(best_d2) + slack;
    return r * r > best_d2 ? r * r : best_d2;
}

static inline int worth(float cell, double lim) {
    return (double)cell * (1.0 - 0x1p-20) - 0x1p-126 <= lim;
}

/* Squared distance from p to the bounding box of tri, in float, without
 * branches (ternaries of floats become min/max instructions): at most the
 * distance to any point of tri up to float rounding, so a triangle whose
 * box is farther than the best by a relative margin far above that
 * rounding (2^-16) cannot win or tie and is skipped without the exact test. */
static inline float tri_box_d2(const float p[3], const float *tri) {
    float d2 = 0.0f;
    for (int k = 0; k < 3; k++) {
        const float a = tri[k], b = tri[3 + k], c = tri[6 + k];
        const float ab_lo = a < b ? a : b, ab_hi = a > b ? a : b;
        const float lo = ab_lo < c ? ab_lo : c, hi = ab_hi > c ? ab_hi : c;
        const float below = lo - p[k], above = p[k] - hi;
        float e = below > above ? below : above;
        e = e > 0.0f ? e : 0.0f;
        d2 += e * e;
    }
    return d2;
}

/* The exact test of one reference whose box distance (tri_box_d2) is box:
 * skipped when the box is farther than the best by the margin above. */
static inline void test_ref(const kdr_scene *s, int32_t prim, float box, const float p[3],
                            cp_best *b) {
    if (box < INFINITY && (double)box > b->d2 * (1.0 + 0x1p-16)) return;
    b->tests++;
    double q[3], u, v, d2;
    kdr_point_triangle(p, s->tris + 9 * (size_t)prim, q, &u, &v, &d2);
    if (d2 < b->d2 || (d2 == b->d2 && (uint32_t)prim < (uint32_t)b->prim)) {
        b->d2 = d2;
        b->prim = prim;
        b->u = u;
        b->v = v;
        memcpy(b->q, q, sizeof q);
    }
}

/* ---- AVX2: four exact tests at once, in double ------------------------------
 * kdr_point_triangle for the rows r[0..3], one per lane, by the same double
 * operations in the same order (the build has -ffp-contract=off: no FMA),
 * so each lane's distance, weights and point are bit for bit the scalar
 * ones. The scalar test branches over the Voronoi regions; here every
 * region's weights are computed in every lane and the first region whose
 * condition holds (in the scalar order) is selected: a lane's divisions by
 * zero in a region it does not select are discarded. */

KD_AVX2 static inline d4 d4_dot(const d4 x[3], const d4 y[3]) {
    return d4_add(d4_add(d4_mul(x[0], y[0]), d4_mul(x[1], y[1])), d4_mul(x[2], y[2]));
}

typedef struct cp_lanes {
    _Alignas(32) double d2[4], u[4], v[4], q[3][4];
} cp_lanes;

KD_AVX2 static void point_triangle4(const float p[3], const float *const r[4],
                                    cp_lanes *out) {
    f4 A4[3], B4[3], C4[3];
    kd_ntri_load4(r, A4, B4, C4);
    d4 a[3], ab[3], ac[3], ap[3], bp[3], cp[3], pk[3];
    for (int k = 0; k < 3; k++) {
        pk[k] = d4_set1((double)p[k]);
        a[k] = d4_from_f4(A4[k]);
        const d4 b = d4_from_f4(B4[k]), c = d4_from_f4(C4[k]);
        ab[k] = d4_sub(b, a[k]);
        ac[k] = d4_sub(c, a[k]);
        ap[k] = d4_sub(pk[k], a[k]);
        bp[k] = d4_sub(pk[k], b);
        cp[k] = d4_sub(pk[k], c);
    }
    const d4 d1 = d4_dot(ab, ap), d2 = d4_dot(ac, ap);
    const d4 d3 = d4_dot(ab, bp), d4v = d4_dot(ac, bp);
    const d4 d5 = d4_dot(ab, cp), d6 = d4_dot(ac, cp);
    const d4 vc = d4_sub(d4_mul(d1, d4v), d4_mul(d3, d2));
    const d4 vb = d4_sub(d4_mul(d5, d2), d4_mul(d1, d6));
    const d4 va = d4_sub(d4_mul(d3, d6), d4_mul(d5, d4v));
    const d4 zero = d4_zero(), one = d4_set1(1.0);
    /* the face, then each region of higher priority over it */
    const d4 den = d4_div(one, d4_add(d4_add(va, vb), vc));
    d4 u = d4_mul(vb, den), v = d4_mul(vc, den);
    const d4 e43 = d4_sub(d4v, d3), e56 = d4_sub(d5, d6);
    const d4 m_bc = d4_and(d4_le(va, zero), d4_and(d4_ge(e43, zero), d4_ge(e56, zero)));
    const d4 v_bc = d4_div(e43, d4_add(e43, e56));
    u = d4_sel(m_bc, d4_sub(one, v_bc), u);
    v = d4_sel(m_bc, v_bc, v);
    const d4 m_ac = d4_and(d4_le(vb, zero), d4_and(d4_ge(d2, zero), d4_le(d6, zero)));
    u = d4_sel(m_ac, zero, u);
    v = d4_sel(m_ac, d4_div(d2, d4_sub(d2, d6)), v);
    const d4 m_c = d4_and(d4_ge(d6, zero), d4_le(d5, d6));
    u = d4_sel(m_c, zero, u);
    v = d4_sel(m_c, one, v);
    const d4 m_ab = d4_and(d4_le(vc, zero), d4_and(d4_ge(d1, zero), d4_le(d3, zero)));
    u = d4_sel(m_ab, d4_div(d1, d4_sub(d1, d3)), u);
    v = d4_sel(m_ab, zero, v);
    const d4 m_b = d4_and(d4_ge(d3, zero), d4_le(d4v, d3));
    u = d4_sel(m_b, one, u);
    v = d4_sel(m_b, zero, v);
    const d4 m_a = d4_and(d4_le(d1, zero), d4_le(d2, zero));
    u = d4_sel(m_a, zero, u);
    v = d4_sel(m_a, zero, v);
    d4 sum = zero;
    for (int k = 0; k < 3; k++) {
        const d4 q = d4_add(d4_add(a[k], d4_mul(u, ab[k])), d4_mul(v, ac[k]));
        const d4 e = d4_sub(pk[k], q);
        d4_store(out->q[k], q);
        sum = d4_add(sum, d4_mul(e, e));
    }
    d4_store(out->d2, sum);
    d4_store(out->u, u);
    d4_store(out->v, v);
}

/* The exact tests of n (1..4) references, four lanes at once (the last
 * lanes repeat the last reference: a triangle measured twice changes
 * nothing), taken into the best in reference order. */
KD_AVX2 static void test_refs4(const kdr_scene *s, const int32_t *prim, int n,
                               const float p[3], cp_best *b) {
    const float *rows[4];
    for (int j = 0; j < 4; j++)
        rows[j] = s->tris + 9 * (size_t)prim[j < n ? j : n - 1];
    cp_lanes l;
    point_triangle4(p, rows, &l);
    b->tests += (uint64_t)n;
    for (int j = 0; j < n; j++) {
        const double d2 = l.d2[j];
        if (d2 < b->d2 || (d2 == b->d2 && (uint32_t)prim[j] < (uint32_t)b->prim)) {
            b->d2 = d2;
            b->prim = prim[j];
            b->u = l.u[j];
            b->v = l.v[j];
            for (int k = 0; k < 3; k++)
                b->q[k] = l.q[k][j];
        }
    }
}

/* The float bound a box distance must exceed to be culled: at least the
 * scalar test's b->d2 (1 + 2^-16), rounded up to a float, so a box culled
 * here would be culled there too. */
static inline float cull_bound(double d2) {
    const double t = d2 * (1.0 + 0x1p-16);
    float f = (float)t;
    if ((double)f < t) { /* the next float up: t is positive and finite here */
        uint32_t w;
        memcpy(&w, &f, 4);
        w++;
        memcpy(&f, &w, 4);
    }
    return f;
}

/* A leaf's references eight at a time (AVX2): the box distances of a
 * group by the same float operations as tri_box_d2 (min, max, subtract,
 * square, summed over x, y, z in that order); the references whose box is
 * not farther than the bound go to the exact test four at a time. The
 * answer is the least (distance, prim) over the tested references, so the
 * order of the tests does not change it. Not inlined: the caller is not
 * compiled for AVX2. */
KD_AVX2 __attribute__((noinline)) static void
test_leaf8(const kdr_scene *s, const uint32_t *ref, uint32_t count, const float p[3],
           cp_best *b) {
    const f8 zero = f8_set1(0.0f), inf = f8_set1(INFINITY);
    int32_t pend[12];
    int np = 0;
    double bound_of = b->d2;
    f8 bound = f8_set1(cull_bound(bound_of));
    for (uint32_t i = 0; i < count; i += 8) {
        const uint32_t m = count - i < 8 ? count - i : 8;
        const float *rows[8];
        for (uint32_t j = 0; j < 8; j++)
            rows[j] = s->tris + 9 * (size_t)ref[i + (j < m ? j : m - 1)];
        f8 A[3], B[3], C[3];
        kd_ntri_load8(rows, A, B, C);
        f8 d2 = zero;
        for (int k = 0; k < 3; k++) {
            const f8 pk = f8_set1(p[k]);
            const f8 lo = f8_min(f8_min(A[k], B[k]), C[k]);
            const f8 hi = f8_max(f8_max(A[k], B[k]), C[k]);
            const f8 e = f8_max(f8_max(f8_sub(lo, pk), f8_sub(pk, hi)), zero);
            d2 = f8_add(d2, f8_mul(e, e));
        }
        /* culled: farther than the bound and finite (+inf on overflow); the
         * bound follows the best as the exact tests lower it */
        if (b->d2 != bound_of) bound = f8_set1(cull_bound(bound_of = b->d2));
        unsigned keep = ~(unsigned)f8_bits(f8_and(f8_gt(d2, bound), f8_lt(d2, inf))) &
                        ((1u << m) - 1);
        while (keep) {
            const int j = __builtin_ctz(keep);
            keep &= keep - 1;
            pend[np++] = (int32_t)ref[i + (uint32_t)j];
            if (np == 4) {
                test_refs4(s, pend, 4, p, b);
                np = 0;
            }
        }
    }
    if (np) test_refs4(s, pend, np, p, b);
}

static void test_leaf(const kdr_scene *s, const kd_node *n, const float p[3], int avx2,
                      cp_best *b) {
    const uint32_t *ref = s->refs + n->u.first;
    const uint32_t count = kd_count(n);
    if (avx2 && count >= 4) {
        test_leaf8(s, ref, count, p, b);
        return;
    }
    for (uint32_t i = 0; i < count; i++) {
        const int32_t prim = (int32_t)ref[i];
        /* +inf on overflow: never culls */
        test_ref(s, prim, tri_box_d2(p, s->tris + 9 * (size_t)prim), p, b);
    }
}

/* Pending cells taken nearest first while fewer than this many wait; past
 * it, last in first out (depth first) for the rest of the query, which
 * adds at most one pending cell per level of the tree, so the stack below
 * has room for all. */
#define CP_NEAREST_MAX 64

/* Cells are taken nearest first: of the pending cells the one whose box is
 * nearest to p (the last pushed of equals), so the best distance shrinks
 * as early as it can and the search stops at the first pending cell that
 * is farther than it (all others are at least as far). From a taken cell
 * the walk descends to the leaf on p's side: a child's cell is as far from
 * p as its parent's when p is on its side of the split (the cell loses
 * only the part beyond the split, away from p), so the near child needs no
 * test of its own; each far child's distance is taken when it is pushed.
 * The answer is the least (distance, prim) over the tested triangles and
 * every cell that could hold a better one is searched, so the order
 * changes the work, not the answer. */
static void search(const kdr_scene *s, const float p[3], double slack, cp_best *b) {
    const int avx2 = __builtin_cpu_supports("avx2") ? 1 : 0;
    cp_todo stack[CP_NEAREST_MAX + 2 * (KD_MAX_DEPTH + 1)];
    int sp = 0, nearest = 1;
    const f4 p4 = f4_xyz0(p[0], p[1], p[2]);
    stack[sp].node = s->nodes;
    stack[sp].lo = f4_xyz0(s->root.min[0], s->root.min[1], s->root.min[2]);
    stack[sp].hi = f4_xyz0(s->root.max[0], s->root.max[1], s->root.max[2]);
    stack[sp].d2 = cell_d2(p4, stack[sp].lo, stack[sp].hi);
    sp++;
    double lim = limit(b->d2, slack);
    while (sp > 0) {
        int sel = sp - 1;
        if (nearest && sp >= CP_NEAREST_MAX) nearest = 0;
        if (nearest)
            for (int i = sp - 2; i >= 0; i--)
                sel = stack[i].d2 < stack[sel].d2 ? i : sel;
        cp_todo t = stack[sel];
        stack[sel] = stack[--sp];
        if (!worth(t.d2, lim)) {
            if (nearest) break;
            continue;
        }
        const kd_node *n = t.node;
        while (!kd_is_leaf(n)) {
            b->nodes++;
            const int axis = kd_axis(n);
            const float split = n->u.split;
            const kd_node *below = n + 1, *above = s->nodes + kd_above(n);
            const int p_above = p[axis] > split;
            const kd_node *nearc = p_above ? above : below,
                          *farc = p_above ? below : above;
            const int near_empty = p_above ? kd_above_empty(n) : kd_below_empty(n);
            const int far_empty = p_above ? kd_below_empty(n) : kd_above_empty(n);
            /* the split as a cell bound on this axis only */
            const f4 m = axis_mask(axis), sp4 = f4_set1(split);
            const f4 hi_b = f4_sel(m, sp4, f4_set1(INFINITY));
            const f4 lo_b = f4_sel(m, sp4, f4_set1(-INFINITY));
            if (!far_empty) {
                cp_todo *far = &stack[sp];
                far->node = farc;
                far->lo = p_above ? t.lo : f4_max(t.lo, lo_b);
                far->hi = p_above ? f4_min(t.hi, hi_b) : t.hi;
                far->d2 = cell_d2(p4, far->lo, far->hi);
                sp += worth(far->d2, lim);
            }
            if (near_empty) {
                n = NULL;
                break;
            }
            if (p_above)
                t.lo = f4_max(t.lo, lo_b);
            else
                t.hi = f4_min(t.hi, hi_b);
            n = nearc;
        }
        if (n) {
            b->nodes++;
            const double before = b->d2;
            test_leaf(s, n, p, avx2, b);
            if (b->d2 != before) lim = limit(b->d2, slack);
        }
    }
}

int kdr_closest_point1(const kdr_scene *scene, const float point[3], float max_distance,
                       kdr_closest *out, kdr_trav_stats *stats) {
    if (!scene || !point || !out) return KDR_EINVAL;
    out->prim = -1;
    out->distance = -1.0f;
    out->u = out->v = 0.0f;
    out->point[0] = out->point[1] = out->point[2] = 0.0f;
    if (!isfinite(point[0]) || !isfinite(point[1]) || !isfinite(point[2]) ||
        !(max_distance >= 0.0f))
        return KDR_EINVAL;
    cp_best b = {(double)max_distance * max_distance, {0, 0, 0}, 0, 0, -1, 0, 0};
    if (scene->nodes) search(scene, point, kd_ray_slack(scene, point), &b);
    if (stats) {
        stats->rays++;
        stats->nodes_visited += b.nodes;
        stats->tri_tests += b.tests;
    }
    if (b.prim < 0) return KDR_OK;
    out->prim = b.prim;
    out->distance = (float)sqrt(b.d2);
    out->u = (float)b.u;
    out->v = (float)b.v;
    for (int k = 0; k < 3; k++)
        out->point[k] = (float)b.q[k];
    return KDR_OK;
}

int kdr_closest_point_batch(const kdr_scene *scene, const float *points, size_t first,
                            size_t count, float max_distance, kdr_closest *out,
                            kdr_trav_stats *stats) {
    if (!scene || !points || !out) return KDR_EINVAL;
    for (size_t i = first; i < first + count; i++) {
        const int rc =
            kdr_closest_point1(scene, points + 3 * i, max_distance, &out[i], stats);
        if (rc != KDR_OK) return rc;
    }
    return KDR_OK;
}
