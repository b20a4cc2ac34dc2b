/*
 * kd_closest.c — the closest point of the scene to a query point: a
 * nearest-triangle search through the kd-tree, and the exact point-triangle
 * distance it rests on.
 *
 * Search. Depth-first from the root with the cell box of each node derived
 * from the splits on the way down (the root cell is the padded root box);
 * at an interior node the child on the point's side of the split is entered
 * first and the other is pushed with its squared distance to the point. A
 * subtree is skipped when its cell is farther than the best distance so far
 * plus a positional slack (kd_traverse.h's KD_SLACK_REL of the largest
 * coordinate magnitude): the build places a triangle in the cells its
 * surface meets up to rounding, so the cell holding a triangle's closest
 * point may miss it by a few ulps, and the slack makes sure a neighbouring
 * cell that holds it is still searched.
 *
 * Distance. Each triangle's closest point is found in double precision by
 * the Voronoi-region walk over the vertices, edges and face (Ericson,
 * Real-Time Collision Detection, 5.1.5), from float inputs; the answer's
 * squared distance is the double distance to that point, so the kd search
 * and a brute-force loop over every triangle give the same number bit for
 * bit. Ties (equal squared distance) go to the smaller prim. Zero-area
 * triangles are never found (they are not in the tree). Before the exact
 * test a reference is culled by its triangle's bounding-box distance, in
 * float with a relative margin; on AVX2 CPUs eight boxes at a time.
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
    const kd_node *node;
    float lo[3], hi[3];
    double d2; /* box_d2 of the cell, taken when it was pushed */
} cp_todo;

typedef struct cp_best {
    double d2, q[3], u, v;
    int32_t prim;
    uint64_t nodes, tests;
} cp_best;

/* Squared distance from p to the box [lo, hi], in double. */
static double box_d2(const float p[3], const float lo[3], const float hi[3]) {
    double d2 = 0.0;
    for (int k = 0; k < 3; k++) {
        const double e = p[k] < lo[k]   ? (double)lo[k] - p[k]
                         : p[k] > hi[k] ? (double)p[k] - hi[k]
                                        : 0.0;
        d2 += e * e;
    }
    return d2;
}

/* A cell is searched while its distance is at most the best plus the slack. */
static int worth(double cell_d2, double best_d2, double slack) {
    if (cell_d2 <= best_d2) return 1;
    const double r = sqrt(best_d2) + slack;
    return cell_d2 <= r * r;
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

/* A leaf's references eight at a time (AVX2): the box distances of a
 * group by the same float operations as tri_box_d2 (min, max, subtract,
 * square, summed over x, y, z in that order), so they are bit for bit the
 * scalar ones; then the references in order, as the scalar loop takes
 * them. Not inlined: the caller is not compiled for AVX2. */
KD_AVX2 __attribute__((noinline)) static void
test_leaf8(const kdr_scene *s, const uint32_t *ref, uint32_t count, const float p[3],
           cp_best *b) {
    const f8 zero = f8_set1(0.0f);
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
        _Alignas(32) float box[8];
        f8_store(box, d2);
        for (uint32_t j = 0; j < m; j++)
            test_ref(s, (int32_t)ref[i + j], box[j], p, b);
    }
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

/* A child's cell is as far from p as its parent's when p is on its side
 * of the split (the cell loses only the part beyond the split, away from
 * p), so the near child needs no test of its own; the far child's
 * distance is taken when it is pushed and compared again with the best
 * when it is popped. */
static void search(const kdr_scene *s, const float p[3], double slack, cp_best *b) {
    const int avx2 = __builtin_cpu_supports("avx2") ? 1 : 0;
    cp_todo stack[KD_MAX_DEPTH + 1];
    int sp = 0;
    stack[sp].node = s->nodes;
    memcpy(stack[sp].lo, s->root.min, sizeof stack[sp].lo);
    memcpy(stack[sp].hi, s->root.max, sizeof stack[sp].hi);
    stack[sp].d2 = box_d2(p, stack[sp].lo, stack[sp].hi);
    sp++;
    while (sp > 0) {
        cp_todo t = stack[--sp];
        if (!worth(t.d2, b->d2, slack)) continue;
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
            if (!far_empty) {
                cp_todo *far = &stack[sp];
                *far = t;
                far->node = farc;
                if (p_above)
                    far->hi[axis] = split < far->hi[axis] ? split : far->hi[axis];
                else
                    far->lo[axis] = split > far->lo[axis] ? split : far->lo[axis];
                far->d2 = box_d2(p, far->lo, far->hi);
                sp += worth(far->d2, b->d2, slack);
            }
            if (near_empty) {
                n = NULL;
                break;
            }
            if (p_above)
                t.lo[axis] = split > t.lo[axis] ? split : t.lo[axis];
            else
                t.hi[axis] = split < t.hi[axis] ? split : t.hi[axis];
            n = nearc;
        }
        if (n) {
            b->nodes++;
            test_leaf(s, n, p, avx2, b);
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
