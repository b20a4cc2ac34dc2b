/*
 * kd_frustum_trav.h — interval frustum traversal (technique 3 of Tsakok,
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
 * of the lanes that reached it are tested in groups of KD_W (2x2 pixel
 * blocks with SSE, 4x2 with AVX2): first against the leaf's box (absolute
 * padding KF_ABS_PAD), then against its triangles with the SIMD watertight
 * test of kd_tri_nray.h, bit-identical to kd_tri.h.
 *
 * This is a template, instantiated once per group width by
 * kd_frustum_trav4.c (SSE2) and kd_frustum_trav8.c (AVX2) with the
 * convention of simd_width.h; the entry point is kd_frustum_trace_tiles4 /
 * kd_frustum_trace_tiles8 (kd_frustum.h).
 * The four frusta themselves always ride in SSE lanes (f4). The ray
 * groups' set-up and output live in kd_frustum_rays.h, included below.
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "kd_frustum.h"
#include "kd_internal.h"
#include "kd_tri_nray.h"

/* all lanes of a group */
#define KF_FULL ((1 << KD_W) - 1)
/* a group is a KF_BW x 2 pixel block */
#define KF_BW (KD_W / 2)

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

/* The rays of a KF_BW x 2 pixel block and their best hits. */
typedef struct kf_group {
    KD_WN(kd_nray_pre) pre;
    _Alignas(32) float inv[3][KD_W]; /* 1 / dir, for box tests */
    _Alignas(32) float t[KD_W], u[KD_W], v[KD_W];
    _Alignas(32) int32_t prim[KD_W];
    int32_t pix[KD_W];            /* output index; -1 for padding lanes */
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

#include "kd_frustum_rays.h"

/* ---- leaves ----------------------------------------------------------------- */

/* A triangle's vertices relative to the eye, broadcast once per leaf for
 * all groups: r[vertex][axis]. The scalar tri[3v+a] - eye[a] is the very
 * float kd_tri_intersect computes as tri[..] - org[..]. */
typedef struct kf_tri_rel {
    VF r[3][3];
} kf_tri_rel;

KD_TARGET static void kf_tri_rel_init(const kf_ctx *c, const float *tri, kf_tri_rel *tr) {
    for (int k = 0; k < 3; k++)
        for (int a = 0; a < 3; a++)
            tr->r[k][a] = V(set1)(tri[3 * k + a] - c->b->eye[a]);
}

/* kd_nray_test for a uniformly shearing group of rays from the eye, over
 * [0, +inf]: the same operations from the shear on. */
KD_TARGET static VF kf_tri_test_eye(const KD_WN(kd_nray_pre) *p, const kf_tri_rel *tr,
                                    VF act, VF *t_out, VF *u_out, VF *v_out) {
    const VF Ax = tr->r[0][p->kx], Ay = tr->r[0][p->ky], Az0 = tr->r[0][p->kz];
    const VF Bx = tr->r[1][p->kx], By = tr->r[1][p->ky], Bz0 = tr->r[1][p->kz];
    const VF Cx = tr->r[2][p->kx], Cy = tr->r[2][p->ky], Cz0 = tr->r[2][p->kz];
    const VF ax = V(sub)(Ax, V(mul)(p->sx, Az0)), ay = V(sub)(Ay, V(mul)(p->sy, Az0));
    const VF bx = V(sub)(Bx, V(mul)(p->sx, Bz0)), by = V(sub)(By, V(mul)(p->sy, Bz0));
    const VF cx = V(sub)(Cx, V(mul)(p->sx, Cz0)), cy = V(sub)(Cy, V(mul)(p->sy, Cz0));
    VF U = V(sub)(V(mul)(cx, by), V(mul)(cy, bx));
    VF Vv = V(sub)(V(mul)(ax, cy), V(mul)(ay, cx));
    VF W = V(sub)(V(mul)(bx, ay), V(mul)(by, ax));
    const VF zero = V(set1)(0.0f);
    const VF z = V(or)(V(or)(V(eq)(U, zero), V(eq)(Vv, zero)), V(eq)(W, zero));
    const int zl = V(bits)(V(and)(z, act));
    if (zl)
        KD_WN(kd_nray_exact)(zl, ax, ay, bx, by, cx, cy, &U, &Vv, &W);
    const VF neg = V(or)(V(or)(V(lt)(U, zero), V(lt)(Vv, zero)), V(lt)(W, zero));
    const VF pos = V(or)(V(or)(V(gt)(U, zero), V(gt)(Vv, zero)), V(gt)(W, zero));
    const VF det = V(add)(V(add)(U, Vv), W);
    VF ok = V(andnot)(V(eq)(det, zero), V(andnot)(V(and)(neg, pos), act));
    if (!V(bits)(ok))
        return ok;
    const VF az = V(mul)(p->sz, Az0), bz = V(mul)(p->sz, Bz0), cz = V(mul)(p->sz, Cz0);
    const VF T = V(add)(V(add)(V(mul)(U, az), V(mul)(Vv, bz)), V(mul)(W, cz));
    const VF t = KD_WN(kd_lanes_t)(ok, T, det, U, Vv, W, Az0, Bz0, Cz0, p->sz);
    ok = V(and)(ok, V(and)(V(le)(zero, t), V(le)(t, V(set1)(INFINITY))));
    *t_out = t;
    *u_out = V(div)(Vv, det);
    *v_out = V(div)(W, det);
    return ok;
}

/* Tests triangle prim against the selected lanes of group g. */
KD_TARGET static void kf_test_tri(kf_ctx *c, kf_group *g, int *bits, int32_t prim,
                       const kf_tri_rel *tr) {
    const float *tri = c->s->tris + 9 * (size_t)prim;
    VF t = V(set1)(0.0f), u = t, v = t; /* set by the test on a hit */
    const VF hit =
        g->pre.uniform
            ? kf_tri_test_eye(&g->pre, tr, V(bitmask)(*bits), &t, &u, &v)
            : KD_WN(kd_nray_test)(&g->pre, tri, V(bitmask)(*bits), V(set1)(0.0f),
                                  V(set1)(INFINITY), &t, &u, &v);
    c->tri_tests += (uint64_t)kf_popcount(*bits);
    if (!V(bits)(hit))
        return;
    const VF pv = V(seti)(prim), best_p = V(load)((const float *)g->prim);
    const VF best_t = V(load)(g->t);
    if (c->q == KDR_ANY) {
        const int h = V(bits)(hit);
        V(store)((float *)g->prim, V(sel)(hit, pv, best_p));
        g->live &= ~h;
        *bits &= ~h;
        return;
    }
    const VF better = V(and)(hit, V(or)(V(lt)(t, best_t),
                                        V(and)(V(eq)(t, best_t), V(ilt)(pv, best_p))));
    if (!V(bits)(better))
        return;
    V(store)(g->t, V(sel)(better, t, best_t));
    V(store)(g->u, V(sel)(better, u, V(load)(g->u)));
    V(store)(g->v, V(sel)(better, v, V(load)(g->v)));
    V(store)((float *)g->prim, V(sel)(better, pv, best_p));
}

/* Selects the groups of lane l whose rays may still meet box [rlo, rhi]
 * before their termination bound. */
KD_TARGET static size_t kf_select(kf_ctx *c, const kf_tile *ft, float tn,
                                  const float rlo[3], const float rhi[3], size_t nsel) {
    for (size_t k = 0; k < ft->ng; k++) {
        kf_group *g = &c->groups[ft->g0 + k];
        if (!g->live || g->term < tn)
            continue;
        VF vn, vf;
        int bits = g->live & kf_group_box(g, rlo, rhi, &vn, &vf);
        if (c->q == KDR_CLOSEST)
            bits &= V(bits)(V(le)(vn, kf_termv(V(load)(g->t))));
        if (!bits)
            continue;
        c->sel[nsel] = (uint32_t)(ft->g0 + k);
        c->selbits[nsel++] = bits;
    }
    return nsel;
}

/* Intersects the rays of the lanes in `lanes` that may meet leaf n. */
KD_TARGET static void kf_leaf(kf_ctx *c, const kd_node *n, int lanes, const float tn[4],
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
    if (c->s->prefetch_leaves) /* every row in flight at once (kd_tune.h) */
        kd_prefetch_tris(c->s, refs, cnt);
    for (uint32_t r = 0; r < cnt; r++) {
        kf_tri_rel tr;
        kf_tri_rel_init(c, c->s->tris + 9 * (size_t)refs[r], &tr);
        for (size_t k = 0; k < nsel; k++)
            if (c->selbits[k])
                kf_test_tri(c, &c->groups[c->sel[k]], &c->selbits[k], (int32_t)refs[r],
                            &tr);
    }
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
KD_TARGET static void kf_traverse(kf_ctx *c) {
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
    f4 steps = f4_seti(0); /* node steps per lane (f4_count) */
    for (;;) {
        const f4 act = kf_active(cur.tn, cur.tf, term);
        if (!f4_bits(act)) {
            if (sp == 0)
                break;
            cur = stack[--sp];
            continue;
        }
        steps = f4_count(steps, act);
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
        const int below_empty = kd_below_empty(n), above_empty = kd_above_empty(n);
        if (dist == 0.0f) { /* eye on the plane: both children, whole */
            if (!above_empty) {
                stack[sp] = cur;
                stack[sp].node = above;
                stack[sp++].lo[axis] = split;
            }
            cur.node = below;
            cur.hi[axis] = split;
            if (below_empty)
                cur.tn = f4_set1(INFINITY); /* pop */
            continue;
        }
        f4 lo, hi;
        if (dist > 0.0f)
            kf_cross(dist, f4_load(rmax[axis]), f4_load(rmin[axis]), &lo, &hi);
        else
            kf_cross(dist, f4_load(rmin[axis]), f4_load(rmax[axis]), &lo, &hi);
        /* an empty child (kd_layout's flags) needs no visit */
        const int front_empty = dist > 0.0f ? below_empty : above_empty;
        const int back_empty = dist > 0.0f ? above_empty : below_empty;
        const f4 fm = front_empty ? f4_seti(0) : f4_and(act, f4_le(cur.tn, hi));
        const f4 bm = back_empty ? f4_seti(0) : f4_and(act, f4_le(lo, cur.tf));
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
    f4_store((float *)st, steps);
    for (int l = 0; l < c->nlanes; l++)
        c->lane_steps[l] += (uint64_t)st[l] * c->ft[l].nrays;
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

KD_TARGET int KD_WN(kd_frustum_trace_tiles)(const kdr_scene *s, const kdr_camera *cam,
                          const kd_camera_basis *b, uint32_t tile, size_t first,
                          size_t count, kdr_query q, int lanes, kdr_hits *out,
                          kdr_trav_stats *stats) {
    const size_t gpt = kf_groups_per_tile(tile);
    kf_ctx c = {.s = s, .cam = cam, .b = b, .tile = tile, .q = q, .gpt = gpt};
    c.groups = aligned_alloc(32, (size_t)KF_LANES * gpt * sizeof *c.groups);
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
