/*
 * kd_frustum_trav.c — interval frustum traversal (technique 3 of Tsakok,
 * Bishop and Kennings): up to four tiles of primary rays walk the kd-tree
 * together, one tile per SSE lane.
 *
 * A tile's rays share the eye, so the tile is bounded by the interval
 * [dmin, dmax] of its ray directions on each axis (min/max over ALL its
 * float rays, so rounding cannot put a ray outside). At a split plane at
 * distance dist = split - eye[axis], the rays that reach the plane do so at
 * t in dist / [dmin, dmax]; a ray moving away from the plane (or parallel
 * to it) never reaches it, which the paper's rule "negative distance means
 * +infinity" expresses. So per lane
 *   hi = latest crossing (+inf if some ray never crosses): the front child
 *        (the eye's side) is needed over [t_near, min(t_far, hi)];
 *   lo = earliest crossing (+inf if none): the back child is needed over
 *        [max(t_near, lo), t_far].
 * Every lane sees the same eye, so front and back are the same for all
 * lanes; an eye exactly on the plane visits both children whole. The t
 * bounds are padded by KF_REL_PAD so that they contain the exact real
 * interval of every ray: the frustum then reaches every leaf that holds a
 * ray's closest hit, whatever the rounding, and answers equal the single
 * ray traversal's.
 *
 * A lane stops when t_near exceeds the largest kd_term_bound(best_t) of its
 * still-searching rays (any-hit: when all have hit). At a leaf, the rays
 * of the lanes that reached it are tested in 2x2 groups: first against the
 * leaf's box (absolute padding KF_ABS_PAD), then against its triangles with
 * the SIMD watertight test of kd_tri_simd.h, bit-identical to kd_tri.h.
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "kd_frustum.h"
#include "kd_internal.h"
#include "simd.h"

#define KB_W 4
#define VF f4
#define V(op) f4_##op
#define KB(x) kf4_##x
#define KB_FN static inline
#include "kd_tri_simd.h"

/* Relative padding of split-plane distances: rounding in split - eye and
 * in the division is below 2^-22; this is far above and still negligible. */
#define KF_REL_PAD 0x1p-20f
/* Absolute padding of leaf and root boxes, relative to the magnitude of
 * the coordinates involved (eye and scene box). */
#define KF_ABS_PAD 0x1p-20f
/* Frusta per traversal in KDR_FRUSTUM_MULTI4 mode (the SSE width). */
#define KF_LANES 4
/* "No hit yet" prim: larger than any prim, so the tie rule needs no
 * unsigned compare. */
#define KF_NO_PRIM INT32_MAX

/* min/max without libm's NaN rules (no NaN reaches them). */
static inline float kf_minf(float a, float b) { return b < a ? b : a; }
static inline float kf_maxf(float a, float b) { return b > a ? b : a; }

/* Four rays of a 2x2 pixel block and their best hits. */
typedef struct kf_group {
    kf4_tri_pre pre;
    _Alignas(16) float inv[3][4]; /* 1 / dir, for box tests */
    _Alignas(16) float t[4], u[4], v[4];
    _Alignas(16) int32_t prim[4];
    int32_t pix[4];               /* output index; -1 for padding lanes */
    int live;                     /* lanes still searching (bit mask) */
    float term;                   /* max kd_term_bound(t) over live lanes */
} kf_group;

/* One tile: its groups and its bounding interval frustum. */
typedef struct kf_tile {
    size_t g0, ng;
    float dmin[3], dmax[3];
    float tn, tf; /* root interval; tn > tf when no ray meets the root */
    float term;
    uint32_t nrays;
} kf_tile;

typedef struct kf_ctx {
    const kdr_scene *s;
    const kdr_camera *cam;
    const kd_camera_basis *b;
    uint32_t tile;
    kdr_query q;
    float pad;          /* absolute box padding */
    kf_group *groups;   /* KF_LANES tiles' worth */
    size_t gpt;         /* groups per tile: lane l owns [l*gpt, (l+1)*gpt) */
    float *sx_tab, *sy_tab; /* kd_camera_sx per column, kd_camera_sy per row */
    uint32_t *sel;      /* groups selected at a leaf */
    int *selbits;
    kf_tile ft[KF_LANES];
    int nlanes;
    uint64_t tri_tests;
    uint64_t lane_steps[KF_LANES];
} kf_ctx;

/* Traversal stack entry: a node, the lanes' intervals and the node's box. */
typedef struct kf_entry {
    f4 tn, tf;
    float lo[3], hi[3];
    uint32_t node;
} kf_entry;

/* ---- tile set-up ---------------------------------------------------------- */

static size_t kf_groups_per_tile(uint32_t tile) {
    const size_t half = (tile + 1) / 2;
    return half * half;
}

/* The shear of kd_ray_precompute for four rays at once, when they share
 * the dominant axis and its sign (nearly always in a 2x2 block): the same
 * divisions, so the same bits. Returns 0 when the lanes disagree. */
static int kf_pre_uniform(const kf_ctx *c, kf_group *g, const f4 d[3]) {
    const f4 sign = f4_set1(-0.0f), zero = f4_set1(0.0f);
    const f4 ax = f4_andnot(sign, d[0]), ay = f4_andnot(sign, d[1]),
             az = f4_andnot(sign, d[2]);
    const f4 ge_xy = _mm_cmpge_ps(ax, ay);
    const int b0 = f4_bits(f4_and(ge_xy, _mm_cmpge_ps(ax, az)));
    const int b1 = f4_bits(f4_andnot(ge_xy, _mm_cmpge_ps(ay, az)));
    const int kz = b0 == 15 ? 0 : b1 == 15 ? 1 : (b0 | b1) == 0 ? 2 : -1;
    if (kz < 0)
        return 0;
    int kx = kz + 1 == 3 ? 0 : kz + 1, ky = kx + 1 == 3 ? 0 : kx + 1;
    const int neg = f4_bits(f4_lt(d[kz], zero));
    if (neg != 0 && neg != 15)
        return 0;
    if (neg) {
        const int tmp = kx;
        kx = ky;
        ky = tmp;
    }
    kf4_tri_pre *p = &g->pre;
    p->ox = f4_set1(c->b->eye[kx]);
    p->oy = f4_set1(c->b->eye[ky]);
    p->oz = f4_set1(c->b->eye[kz]);
    p->sx = f4_div(d[kx], d[kz]);
    p->sy = f4_div(d[ky], d[kz]);
    p->sz = f4_div(f4_set1(1.0f), d[kz]);
    p->kx0 = f4_seti(kx == 0 ? -1 : 0);
    p->kx1 = f4_seti(kx == 1 ? -1 : 0);
    p->ky0 = f4_seti(ky == 0 ? -1 : 0);
    p->ky1 = f4_seti(ky == 1 ? -1 : 0);
    p->kz0 = f4_seti(kz == 0 ? -1 : 0);
    p->kz1 = f4_seti(kz == 1 ? -1 : 0);
    p->uniform = 1;
    p->kx = kx;
    p->ky = ky;
    p->kz = kz;
    return 1;
}

/* Per-lane scalar precomputation, for blocks whose rays shear differently. */
static void kf_pre_mixed(const kf_ctx *c, kf_group *g, const f4 d[3]) {
    _Alignas(16) float dd[3][4];
    kd_ray_pre pre[4];
    for (int a = 0; a < 3; a++)
        f4_store(dd[a], d[a]);
    for (int j = 0; j < 4; j++) {
        const float dir[3] = {dd[0][j], dd[1][j], dd[2][j]};
        kd_ray_precompute(c->b->eye, dir, &pre[j]);
    }
    kf4_tri_pre_init(&g->pre, pre, 15, 0);
}

/* Fills group g with the 2x2 block at (x, y), clipped to [.., x1) x
 * [.., y1): clipped-off lanes repeat a pixel of the block (so the block
 * still shears uniformly) but are never live nor written. Widens the
 * tile's direction interval. */
static void kf_group_init(kf_ctx *c, kf_group *g, uint32_t x, uint32_t y,
                          uint32_t x1, uint32_t y1, f4 dmin[3], f4 dmax[3]) {
    const uint32_t xb = x + 1 < x1 ? x + 1 : x, yb = y + 1 < y1 ? y + 1 : y;
    const f4 sx = _mm_setr_ps(c->sx_tab[x], c->sx_tab[xb], c->sx_tab[x], c->sx_tab[xb]);
    const f4 sy = _mm_setr_ps(c->sy_tab[y], c->sy_tab[y], c->sy_tab[yb], c->sy_tab[yb]);
    const size_t W = c->cam->width;
    f4 d[3];
    for (int a = 0; a < 3; a++) {
        d[a] = f4_add(f4_add(f4_set1(c->b->f[a]), f4_mul(sx, f4_set1(c->b->r[a]))),
                      f4_mul(sy, f4_set1(c->b->u[a])));
        dmin[a] = f4_min(dmin[a], d[a]);
        dmax[a] = f4_max(dmax[a], d[a]);
        f4_store(g->inv[a], f4_div(f4_set1(1.0f), d[a]));
    }
    if (!kf_pre_uniform(c, g, d))
        kf_pre_mixed(c, g, d);
    g->pix[0] = (int32_t)((size_t)y * W + x);
    g->pix[1] = xb > x ? (int32_t)((size_t)y * W + xb) : -1;
    g->pix[2] = yb > y ? (int32_t)((size_t)yb * W + x) : -1;
    g->pix[3] = xb > x && yb > y ? (int32_t)((size_t)yb * W + xb) : -1;
    g->live = 1 | (g->pix[1] >= 0) << 1 | (g->pix[2] >= 0) << 2 | (g->pix[3] >= 0) << 3;
    f4_store(g->t, f4_set1(INFINITY));
    f4_store(g->u, f4_set1(0.0f));
    f4_store(g->v, f4_set1(0.0f));
    f4_store((float *)g->prim, f4_seti(KF_NO_PRIM));
    g->term = INFINITY;
}

/* Box [lo, hi] relative to the eye, padded outward and never 0 (a zero
 * times an infinite 1/dir would give NaN). */
static void kf_rel_box(const kf_ctx *c, const float lo[3], const float hi[3],
                       float rlo[3], float rhi[3]) {
    for (int a = 0; a < 3; a++) {
        rlo[a] = (lo[a] - c->b->eye[a]) - c->pad;
        rhi[a] = (hi[a] - c->b->eye[a]) + c->pad;
        if (rlo[a] == 0.0f)
            rlo[a] = -FLT_MIN;
        if (rhi[a] == 0.0f)
            rhi[a] = FLT_MIN;
    }
}

/* Slab test of a group's rays against a relative box, over t >= 0: the
 * lanes whose ray may meet it, with their entry and exit distances. */
static inline int kf_group_box(const kf_group *g, const float rlo[3],
                               const float rhi[3], f4 *tnear, f4 *tfar) {
    f4 tn = f4_set1(0.0f), tf = f4_set1(INFINITY);
    for (int a = 0; a < 3; a++) {
        const f4 inv = f4_load(g->inv[a]);
        const f4 t0 = f4_mul(f4_set1(rlo[a]), inv);
        const f4 t1 = f4_mul(f4_set1(rhi[a]), inv);
        tn = f4_max(tn, f4_min(t0, t1));
        tf = f4_min(tf, f4_max(t0, t1));
    }
    *tnear = tn;
    *tfar = tf;
    return f4_bits(f4_le(tn, tf));
}

/* kd_term_bound of four t values, same operations. */
static inline f4 kf_term4(f4 t) {
    const f4 abs_t = f4_andnot(f4_set1(-0.0f), t);
    return f4_add(f4_add(t, f4_mul(abs_t, f4_set1(0x1p-18f))), f4_set1(FLT_MIN));
}

static void kf_group_update_term(kf_ctx *c, kf_group *g) {
    _Alignas(16) float tb[4];
    float m = -INFINITY;
    if (c->q == KDR_ANY) {
        g->term = g->live ? INFINITY : -INFINITY;
        return;
    }
    f4_store(tb, kf_term4(f4_load(g->t)));
    for (int j = 0; j < 4; j++)
        if ((g->live >> j) & 1)
            m = kf_maxf(m, tb[j]);
    g->term = m;
}

static void kf_tile_update_term(kf_ctx *c, kf_tile *ft) {
    float m = -INFINITY;
    for (size_t k = 0; k < ft->ng; k++)
        m = kf_maxf(m, c->groups[ft->g0 + k].term);
    ft->term = m;
}

static float kf_hmin(f4 v) {
    _Alignas(16) float x[4];
    f4_store(x, v);
    return kf_minf(kf_minf(x[0], x[1]), kf_minf(x[2], x[3]));
}
static float kf_hmax(f4 v) {
    _Alignas(16) float x[4];
    f4_store(x, v);
    return kf_maxf(kf_maxf(x[0], x[1]), kf_maxf(x[2], x[3]));
}

/* Builds tile k's groups in lane l; clips its rays to the root box (rays
 * that miss it stop searching: every triangle lies inside). */
static void kf_tile_init(kf_ctx *c, int l, size_t k) {
    kf_tile *ft = &c->ft[l];
    const uint32_t T = c->tile, W = c->cam->width, H = c->cam->height;
    const size_t tiles_x = ((size_t)W + T - 1) / T;
    const uint32_t x0 = (uint32_t)(k % tiles_x) * T, y0 = (uint32_t)(k / tiles_x) * T;
    const uint32_t x1 = W - x0 < T ? W : x0 + T, y1 = H - y0 < T ? H : y0 + T;
    f4 dmin[3], dmax[3], tn = f4_set1(INFINITY), tf = f4_set1(-INFINITY);
    float rlo[3], rhi[3];
    for (int a = 0; a < 3; a++) {
        dmin[a] = f4_set1(INFINITY);
        dmax[a] = f4_set1(-INFINITY);
    }
    ft->g0 = (size_t)l * c->gpt;
    ft->ng = 0;
    ft->nrays = (x1 - x0) * (y1 - y0);
    kf_rel_box(c, c->s->root.min, c->s->root.max, rlo, rhi);
    for (uint32_t y = y0; y < y1; y += 2) {
        for (uint32_t x = x0; x < x1; x += 2) {
            kf_group *g = &c->groups[ft->g0 + ft->ng++];
            f4 vn, vf;
            kf_group_init(c, g, x, y, x1, y1, dmin, dmax);
            g->live &= kf_group_box(g, rlo, rhi, &vn, &vf);
            const f4 live = f4_bitmask(g->live);
            tn = f4_min(tn, f4_sel(live, vn, f4_set1(INFINITY)));
            tf = f4_max(tf, f4_sel(live, vf, f4_set1(-INFINITY)));
            if (!g->live)
                g->term = -INFINITY;
        }
    }
    for (int a = 0; a < 3; a++) {
        ft->dmin[a] = kf_hmin(dmin[a]);
        ft->dmax[a] = kf_hmax(dmax[a]);
    }
    ft->tn = kf_hmin(tn);
    ft->tf = kf_hmax(tf);
    kf_tile_update_term(c, ft);
}

/* ---- leaves ----------------------------------------------------------------- */

/* Tests triangle prim against the selected lanes of group g. */
static void kf_test_tri(kf_ctx *c, kf_group *g, int *bits, int32_t prim) {
    const float *tri = c->s->tris + 9 * (size_t)prim;
    f4 t, u, v;
    const f4 hit = kf4_tri_test(&g->pre, tri, f4_bitmask(*bits), f4_set1(0.0f),
                                f4_set1(INFINITY), &t, &u, &v);
    c->tri_tests += (uint64_t)((0x4332322132212110ull >> (4 * *bits)) & 15);
    if (!f4_bits(hit))
        return;
    const f4 pv = f4_seti(prim), best_p = f4_load((const float *)g->prim);
    const f4 best_t = f4_load(g->t);
    if (c->q == KDR_ANY) {
        const int h = f4_bits(hit);
        f4_store((float *)g->prim, f4_sel(hit, pv, best_p));
        g->live &= ~h;
        *bits &= ~h;
        return;
    }
    const f4 pless = _mm_castsi128_ps(
        _mm_cmplt_epi32(_mm_castps_si128(pv), _mm_castps_si128(best_p)));
    const f4 better = f4_and(hit, f4_or(f4_lt(t, best_t), f4_and(f4_eq(t, best_t), pless)));
    if (!f4_bits(better))
        return;
    f4_store(g->t, f4_sel(better, t, best_t));
    f4_store(g->u, f4_sel(better, u, f4_load(g->u)));
    f4_store(g->v, f4_sel(better, v, f4_load(g->v)));
    f4_store((float *)g->prim, f4_sel(better, pv, best_p));
}

/* Selects the groups of lane l whose rays may still meet box [rlo, rhi]
 * before their termination bound. */
static size_t kf_select(kf_ctx *c, const kf_tile *ft, float tn, const float rlo[3],
                        const float rhi[3], size_t nsel) {
    for (size_t k = 0; k < ft->ng; k++) {
        kf_group *g = &c->groups[ft->g0 + k];
        if (!g->live || g->term < tn)
            continue;
        f4 vn, vf;
        int bits = g->live & kf_group_box(g, rlo, rhi, &vn, &vf);
        if (c->q == KDR_CLOSEST)
            bits &= f4_bits(f4_le(vn, kf_term4(f4_load(g->t))));
        if (!bits)
            continue;
        c->sel[nsel] = (uint32_t)(ft->g0 + k);
        c->selbits[nsel++] = bits;
    }
    return nsel;
}

/* Intersects the rays of the lanes in `lanes` that may meet leaf n. */
static void kf_leaf(kf_ctx *c, const kd_node *n, int lanes, const float tn[4],
                    const float lo[3], const float hi[3]) {
    const uint32_t cnt = kd_count(n);
    float rlo[3], rhi[3];
    size_t nsel = 0;
    if (cnt == 0)
        return;
    kf_rel_box(c, lo, hi, rlo, rhi);
    for (int l = 0; l < c->nlanes; l++)
        if ((lanes >> l) & 1)
            nsel = kf_select(c, &c->ft[l], tn[l], rlo, rhi, nsel);
    if (nsel == 0)
        return;
    const uint32_t *refs = c->s->refs + n->u.first;
    for (uint32_t r = 0; r < cnt; r++)
        for (size_t k = 0; k < nsel; k++)
            if (c->selbits[k])
                kf_test_tri(c, &c->groups[c->sel[k]], &c->selbits[k], (int32_t)refs[r]);
    /* a lane's bound can only fall when a group holding it fell */
    int dirty = 0;
    for (size_t k = 0; k < nsel; k++) {
        kf_group *g = &c->groups[c->sel[k]];
        const int l = (int)(c->sel[k] / c->gpt);
        const float old = g->term;
        kf_group_update_term(c, g);
        if (old >= c->ft[l].term && g->term < old)
            dirty |= 1 << l;
    }
    for (int l = 0; l < c->nlanes; l++)
        if ((dirty >> l) & 1)
            kf_tile_update_term(c, &c->ft[l]);
}

/* ---- traversal -------------------------------------------------------------- */

/* Split-plane crossing interval of each lane: lo = earliest crossing, hi =
 * latest (+inf: none, resp. some ray never crosses), both padded. */
static inline void kf_cross(float dist, f4 r_near, f4 r_far, f4 *lo, f4 *hi) {
    const f4 inf = f4_set1(INFINITY), vd = f4_set1(dist);
    f4 a = f4_mul(vd, r_near), b = f4_mul(vd, r_far);
    a = f4_sel(f4_signmask(a), inf, a);
    b = f4_sel(f4_signmask(b), inf, b);
    *lo = f4_mul(a, f4_set1(1.0f - KF_REL_PAD));
    *hi = f4_mul(b, f4_set1(1.0f + KF_REL_PAD));
}

static inline f4 kf_active(f4 tn, f4 tf, f4 term) {
    return f4_and(f4_le(tn, tf), f4_le(tn, term));
}

static f4 kf_lane_terms(const kf_ctx *c) {
    _Alignas(16) float t[4] = {-INFINITY, -INFINITY, -INFINITY, -INFINITY};
    for (int l = 0; l < c->nlanes; l++)
        t[l] = c->ft[l].term;
    return f4_load(t);
}

/* Walks the tree with the lanes' frusta, front to back from the eye. */
static void kf_traverse(kf_ctx *c) {
    const kd_node *nodes = c->s->nodes;
    _Alignas(16) float tn0[4], tf0[4], rmin[3][4], rmax[3][4];
    kf_entry stack[KD_MAX_DEPTH + 2];
    int sp = 0;
    for (int l = 0; l < 4; l++) {
        const kf_tile *ft = &c->ft[l < c->nlanes ? l : 0];
        tn0[l] = l < c->nlanes ? ft->tn : INFINITY;
        tf0[l] = l < c->nlanes ? ft->tf : -INFINITY;
        for (int a = 0; a < 3; a++) {
            rmin[a][l] = 1.0f / ft->dmin[a];
            rmax[a][l] = 1.0f / ft->dmax[a];
        }
    }
    kf_entry cur = {.tn = f4_load(tn0), .tf = f4_load(tf0), .node = 0};
    memcpy(cur.lo, c->s->root.min, sizeof cur.lo);
    memcpy(cur.hi, c->s->root.max, sizeof cur.hi);
    f4 term = kf_lane_terms(c);
    __m128i steps = _mm_setzero_si128();
    for (;;) {
        const f4 act = kf_active(cur.tn, cur.tf, term);
        if (!f4_bits(act)) {
            if (sp == 0)
                break;
            cur = stack[--sp];
            continue;
        }
        steps = _mm_sub_epi32(steps, _mm_castps_si128(act));
        const kd_node *n = &nodes[cur.node];
        if (kd_is_leaf(n)) {
            _Alignas(16) float tn[4];
            f4_store(tn, cur.tn);
            kf_leaf(c, n, f4_bits(act), tn, cur.lo, cur.hi);
            term = kf_lane_terms(c);
            cur.tn = f4_set1(INFINITY); /* pop */
            continue;
        }
        const int axis = kd_axis(n);
        const float split = n->u.split, dist = split - c->b->eye[axis];
        const uint32_t below = cur.node + 1, above = kd_above(n);
        if (dist == 0.0f) { /* eye on the plane: both children, whole */
            stack[sp] = cur;
            stack[sp].node = above;
            stack[sp++].lo[axis] = split;
            cur.node = below;
            cur.hi[axis] = split;
            continue;
        }
        f4 lo, hi;
        if (dist > 0.0f)
            kf_cross(dist, f4_load(rmax[axis]), f4_load(rmin[axis]), &lo, &hi);
        else
            kf_cross(dist, f4_load(rmin[axis]), f4_load(rmax[axis]), &lo, &hi);
        const f4 fm = f4_and(act, f4_le(cur.tn, hi));
        const f4 bm = f4_and(act, f4_le(lo, cur.tf));
        kf_entry back = cur;
        back.node = dist > 0.0f ? above : below;
        back.tn = f4_sel(bm, f4_max(cur.tn, lo), f4_set1(INFINITY));
        if (dist > 0.0f)
            back.lo[axis] = split;
        else
            back.hi[axis] = split;
        if (!f4_bits(fm)) {
            cur = back;
            continue;
        }
        if (f4_bits(bm))
            stack[sp++] = back;
        cur.node = dist > 0.0f ? below : above;
        cur.tn = f4_sel(fm, cur.tn, f4_set1(INFINITY));
        cur.tf = f4_min(cur.tf, hi);
        if (dist > 0.0f)
            cur.hi[axis] = split;
        else
            cur.lo[axis] = split;
    }
    _Alignas(16) int32_t st[4];
    _mm_store_si128((__m128i *)st, steps);
    for (int l = 0; l < c->nlanes; l++)
        c->lane_steps[l] += (uint64_t)st[l] * c->ft[l].nrays;
}

/* ---- output ----------------------------------------------------------------- */

static void kf_write(const kf_ctx *c, kdr_hits *out) {
    for (int l = 0; l < c->nlanes; l++) {
        const kf_tile *ft = &c->ft[l];
        for (size_t k = 0; k < ft->ng; k++) {
            const kf_group *g = &c->groups[ft->g0 + k];
            for (int j = 0; j < 4; j++) {
                const int32_t i = g->pix[j];
                const int hit = g->prim[j] != KF_NO_PRIM;
                if (i < 0)
                    continue;
                if (c->q == KDR_ANY) {
                    out->hit[i] = (uint8_t)hit;
                    continue;
                }
                out->t[i] = hit ? g->t[j] : -1.0f;
                out->prim[i] = hit ? g->prim[j] : -1;
                out->u[i] = hit ? g->u[j] : 0.0f;
                out->v[i] = hit ? g->v[j] : 0.0f;
            }
        }
    }
}

/* Walks the tiles of [first, end) in 2x2 blocks of tiles, so that the
 * four frusta of one traversal form a square whenever the range allows. */
typedef struct kf_order {
    size_t first, end, tiles_x;
    size_t bx, by; /* current block */
    int j;         /* next tile within it */
} kf_order;

static int kf_next_tile(kf_order *o, size_t *k) {
    for (;;) {
        if (2 * o->by * o->tiles_x >= o->end)
            return 0;
        const size_t tx = 2 * o->bx + (size_t)(o->j & 1);
        const size_t ty = 2 * o->by + (size_t)(o->j >> 1);
        if (++o->j == 4) {
            o->j = 0;
            if (2 * ++o->bx >= o->tiles_x) {
                o->bx = 0;
                o->by++;
            }
        }
        const size_t idx = ty * o->tiles_x + tx;
        if (tx < o->tiles_x && idx >= o->first && idx < o->end) {
            *k = idx;
            return 1;
        }
    }
}

/* The box padding: a small fraction of the largest coordinate magnitude
 * among the eye and the root box, so it dwarfs rounding in (box - eye). */
static float kf_pad(const kdr_scene *s, const kd_camera_basis *b) {
    float m = 0.0f;
    for (int a = 0; a < 3; a++) {
        m = kf_maxf(m, fabsf(b->eye[a]));
        m = kf_maxf(m, fabsf(s->root.min[a]));
        m = kf_maxf(m, fabsf(s->root.max[a]));
    }
    return m * KF_ABS_PAD + FLT_MIN;
}

int kd_frustum_trace_tiles(const kdr_scene *s, const kdr_camera *cam,
                           const kd_camera_basis *b, uint32_t tile, size_t first,
                           size_t count, kdr_query q, int lanes, kdr_hits *out,
                           kdr_trav_stats *stats) {
    const size_t gpt = kf_groups_per_tile(tile);
    kf_ctx c = {.s = s, .cam = cam, .b = b, .tile = tile, .q = q, .gpt = gpt};
    c.groups = malloc((size_t)KF_LANES * gpt * sizeof *c.groups);
    c.sel = malloc((size_t)KF_LANES * gpt * sizeof *c.sel);
    c.selbits = malloc((size_t)KF_LANES * gpt * sizeof *c.selbits);
    c.sx_tab = malloc(((size_t)cam->width + cam->height) * sizeof *c.sx_tab);
    if (!c.groups || !c.sel || !c.selbits || !c.sx_tab) {
        free(c.sx_tab);
        free(c.groups);
        free(c.sel);
        free(c.selbits);
        return KDR_ENOMEM;
    }
    c.pad = kf_pad(s, b);
    c.sy_tab = c.sx_tab + cam->width;
    for (uint32_t x = 0; x < cam->width; x++)
        c.sx_tab[x] = kd_camera_sx(b, x);
    for (uint32_t y = 0; y < cam->height; y++)
        c.sy_tab[y] = kd_camera_sy(b, y);
    uint64_t rays = 0;
    kf_order o = {first, first + count, ((size_t)cam->width + tile - 1) / tile, 0, 0, 0};
    o.by = first / o.tiles_x / 2;
    for (;;) {
        size_t k;
        c.nlanes = 0;
        while (c.nlanes < lanes && kf_next_tile(&o, &k)) {
            kf_tile_init(&c, c.nlanes, k);
            rays += c.ft[c.nlanes++].nrays;
        }
        if (c.nlanes == 0)
            break;
        if (s->nodes && s->nnodes)
            kf_traverse(&c);
        kf_write(&c, out);
    }
    if (stats) {
        stats->rays += rays;
        stats->tri_tests += c.tri_tests;
        for (int l = 0; l < KF_LANES; l++)
            stats->nodes_visited += c.lane_steps[l];
    }
    free(c.groups);
    free(c.sel);
    free(c.selbits);
    free(c.sx_tab);
    return KDR_OK;
}
