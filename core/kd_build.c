/*
 * kd_build.c — SAH kd-tree construction in O(N log N), after Wald and
 * Havran, "On building fast kd-trees for ray tracing, and on doing that in
 * O(N log N)" (2006).
 *
 * Every node has three sorted event lists, one per axis. An event is one
 * 64-bit key: the order-preserving bits of its position (high 32), its type
 * (end < planar < start, bits 30-31) and its triangle (low 30 bits), so that
 * sorting keys sorts events by (position, type, triangle). The lists are
 * sorted once at the root (radix sort); a split then partitions each list
 * in order, and only the triangles that straddle the plane get new events:
 * they are clipped to the node's box and then to each side of the plane
 * ("perfect splits"), and their few new events are sorted and merged in.
 * The children's lists live in a scratch buffer per depth: the build is
 * depth-first, so a subtree only ever writes the buffers below it.
 *
 * Clipping runs in double and rounds the bounds of computed points outward,
 * so a triangle is never left out of a box it touches. A triangle lying in
 * the split plane goes to the cheaper side; a triangle touching the plane
 * from one side goes to that side only.
 */
#include <assert.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "kd_internal.h"
#include "kd_traverse.h"

#define KD_MAX_TRIS ((size_t)1 << 30)  /* triangle ids fit 30 bits */
#define KD_MAX_NODES ((size_t)1 << 30) /* above-child index fits 30 bits */
#define KD_LOG_PHASES 1000000          /* log each phase above this size */
#define KD_ROOT_PAD 0x1p-20f           /* root padding, relative (~8 ulps) */

enum { EV_END = 0, EV_PLANAR = 1, EV_START = 2 };
enum { SIDE_BOTH = 0, SIDE_LEFT = 1, SIDE_RIGHT = 2 };

typedef uint64_t kd_event;

typedef struct ev_list {
    kd_event *e[3];
    size_t n[3];
    size_t ntri;
} ev_list;

typedef struct kd_split {
    int axis;
    float pos;
    int planar_left;
    float cost;
} kd_split;

typedef struct builder {
    const float *tris;
    kdr_build_opts o;
    int max_depth;
    uint8_t *side; /* per triangle, valid for the node being split */
    kd_event *lvl[KD_MAX_DEPTH + 1]; /* children of a node at depth d */
    size_t lvl_cap[KD_MAX_DEPTH + 1];
    uint32_t *both; /* straddlers of the node being split */
    size_t both_cap;
    kd_event *add; /* their new events */
    size_t add_cap;
    kd_node *nodes;
    size_t nnodes, cap_nodes;
    uint32_t *refs;
    size_t nrefs, cap_refs;
    uint64_t leaves, empty_leaves, depth_seen;
    double sah, inv_root_area;
    int err;
} builder;

/* ---- event keys ---------------------------------------------------------- */

static inline uint32_t float_key(float f) {
    uint32_t u;
    memcpy(&u, &f, sizeof u);
    return (u & 0x80000000u) ? ~u : (u | 0x80000000u);
}

static inline float key_float(uint32_t k) {
    uint32_t u = (k & 0x80000000u) ? (k & 0x7fffffffu) : ~k;
    float f;
    memcpy(&f, &u, sizeof f);
    return f;
}

/* pos + 0.0f turns -0.0 into +0.0 so equal positions share one key. */
static inline kd_event ev_make(float pos, unsigned type, uint32_t tri) {
    return ((uint64_t)float_key(pos + 0.0f) << 32) | ((uint64_t)type << 30) | tri;
}
static inline uint32_t ev_tri(kd_event e) { return (uint32_t)e & 0x3fffffffu; }
static inline unsigned ev_type(kd_event e) { return (unsigned)(e >> 30) & 3u; }
static inline uint32_t ev_key(kd_event e) { return (uint32_t)(e >> 32); }

/* Inputs are finite, so plain compares do; fminf/fmaxf are library calls
 * without -ffast-math. */
static inline float min3(float a, float b, float c) {
    float m = a < b ? a : b;
    return m < c ? m : c;
}
static inline float max3(float a, float b, float c) {
    float m = a > b ? a : b;
    return m > c ? m : c;
}

static void ev_free(ev_list *l) {
    for (int k = 0; k < 3; k++) {
        free(l->e[k]);
        l->e[k] = NULL;
    }
}

/* Appends the events of a triangle with bounds bb to dst[k] + n[k]. */
static void ev_add(kd_event *dst[3], size_t n[3], const kdr_bounds *bb,
                   uint32_t tri) {
    for (int k = 0; k < 3; k++) {
        if (bb->min[k] == bb->max[k]) {
            dst[k][n[k]++] = ev_make(bb->min[k], EV_PLANAR, tri);
        } else {
            dst[k][n[k]++] = ev_make(bb->min[k], EV_START, tri);
            dst[k][n[k]++] = ev_make(bb->max[k], EV_END, tri);
        }
    }
}

/* LSD radix sort on bits 30..63 (position and type); stable, so events
 * generated in triangle order end up in full key order. */
static void radix_sort(kd_event *a, kd_event *tmp, size_t n) {
    static const int shift[3] = {30, 41, 52};
    static const int bits[3] = {11, 11, 12};
    size_t count[1u << 12];
    for (int pass = 0; pass < 3; pass++) {
        const size_t nb = (size_t)1 << bits[pass];
        const uint64_t mask = nb - 1;
        memset(count, 0, nb * sizeof *count);
        for (size_t i = 0; i < n; i++)
            count[(a[i] >> shift[pass]) & mask]++;
        size_t sum = 0;
        for (size_t b = 0; b < nb; b++) {
            size_t c = count[b];
            count[b] = sum;
            sum += c;
        }
        for (size_t i = 0; i < n; i++)
            tmp[count[(a[i] >> shift[pass]) & mask]++] = a[i];
        memcpy(a, tmp, n * sizeof *a);
    }
}

/* ---- boxes and clipping ---------------------------------------------------- */

static double box_area(const kdr_bounds *b) {
    double dx = (double)b->max[0] - b->min[0];
    double dy = (double)b->max[1] - b->min[1];
    double dz = (double)b->max[2] - b->min[2];
    return 2.0 * (dx * dy + dy * dz + dz * dx);
}

typedef struct cvert {
    double p[3];
    unsigned exact; /* bit k: p[k] is exactly a float of the input */
} cvert;

/* Sutherland-Hodgman step: keeps the part where sign * (p[k] - c) >= 0. */
static int clip_plane(const cvert *in, int n, cvert *out, int k, float c,
                      double sign) {
    int m = 0;
    for (int i = 0; i < n; i++) {
        const cvert *a = &in[i], *b = &in[(i + 1) % n];
        double da = sign * (a->p[k] - c), db = sign * (b->p[k] - c);
        if (da >= 0.0)
            out[m++] = *a;
        if ((da > 0.0 && db < 0.0) || (da < 0.0 && db > 0.0)) {
            cvert *v = &out[m++];
            double t = da / (da - db);
            v->exact = 1u << k;
            for (int j = 0; j < 3; j++) {
                v->p[j] = a->p[j] + t * (b->p[j] - a->p[j]);
                if (j != k && a->p[j] == b->p[j])
                    v->exact |= a->exact & b->exact & (1u << j);
            }
            v->p[k] = c;
        }
    }
    return m;
}

/* The next float toward -infinity (finite input). */
static inline float step_down(float f) {
    uint32_t u;
    if (f == 0.0f)
        return -FLT_TRUE_MIN;
    memcpy(&u, &f, sizeof u);
    u = f > 0.0f ? u - 1 : u + 1;
    memcpy(&f, &u, sizeof f);
    return f;
}

/* Clips tri to box (only against the planes its bounds cross) into out[];
 * returns the vertex count, 0 when nothing is left. */
static int clip_to_box(const float *tri, const kdr_bounds *box, cvert out[16]) {
    cvert tmp[16];
    cvert *buf[2] = {out, tmp};
    int n = 3, cur = 0;
    for (int i = 0; i < 3; i++) {
        for (int k = 0; k < 3; k++)
            out[i].p[k] = tri[3 * i + k];
        out[i].exact = 7u;
    }
    for (int k = 0; k < 3 && n > 0; k++) {
        if (min3(tri[k], tri[3 + k], tri[6 + k]) < box->min[k]) {
            n = clip_plane(buf[cur], n, buf[cur ^ 1], k, box->min[k], 1.0);
            cur ^= 1;
        }
        if (n > 0 && max3(tri[k], tri[3 + k], tri[6 + k]) > box->max[k]) {
            n = clip_plane(buf[cur], n, buf[cur ^ 1], k, box->max[k], -1.0);
            cur ^= 1;
        }
    }
    if (cur)
        memcpy(out, tmp, (size_t)n * sizeof *out);
    return n;
}

/* Bounds of a clipped polygon, computed coordinates rounded outward, cut
 * to box; 0 when empty. */
static int poly_bounds(const cvert *v, int n, const kdr_bounds *box,
                       kdr_bounds *out) {
    if (n == 0)
        return 0;
    for (int k = 0; k < 3; k++) {
        float lo = INFINITY, hi = -INFINITY;
        for (int i = 0; i < n; i++) {
            const float f = (float)v[i].p[k];
            const int ex = (v[i].exact >> k) & 1u;
            const float flo = ex ? f : step_down(f);
            const float fhi = ex ? f : -step_down(-f);
            lo = flo < lo ? flo : lo;
            hi = fhi > hi ? fhi : hi;
        }
        out->min[k] = lo > box->min[k] ? lo : box->min[k];
        out->max[k] = hi < box->max[k] ? hi : box->max[k];
        if (out->min[k] > out->max[k])
            return 0;
    }
    return 1;
}

/* Fallback when double clipping loses a sliver: the triangle's bounds cut
 * to the box (still conservative). */
static int tri_bounds_in_box(const float *tri, const kdr_bounds *box,
                             kdr_bounds *out) {
    for (int k = 0; k < 3; k++) {
        float lo = min3(tri[k], tri[3 + k], tri[6 + k]);
        float hi = max3(tri[k], tri[3 + k], tri[6 + k]);
        out->min[k] = lo > box->min[k] ? lo : box->min[k];
        out->max[k] = hi < box->max[k] ? hi : box->max[k];
        if (out->min[k] > out->max[k])
            return 0;
    }
    return 1;
}

/* ---- split search: one sweep per axis -------------------------------------- */

typedef struct sah_ctx {
    float min, max;      /* node extent on the axis */
    float cap, perim;    /* child area = 2 (cap + len * perim) */
    float inv_area;      /* 1 / node area */
    float isect, trav, bonus;
} sah_ctx;

static float sah_cost(const sah_ctx *c, float p, size_t nl, size_t nr) {
    float pl = 2.0f * (c->cap + (p - c->min) * c->perim) * c->inv_area;
    float pr = 2.0f * (c->cap + (c->max - p) * c->perim) * c->inv_area;
    float eb = (nl == 0 || nr == 0) ? 1.0f - c->bonus : 1.0f;
    return c->trav + c->isect * eb * (pl * (float)nl + pr * (float)nr);
}

/* Evaluates plane p with nl left, np planar, nr right; planar triangles go
 * to the cheaper side (left on ties). */
static void sah_try(const sah_ctx *c, int k, float p, size_t nl, size_t np,
                    size_t nr, kd_split *best) {
    float cl = sah_cost(c, p, nl + np, nr);
    float cr = sah_cost(c, p, nl, nr + np);
    float cost = cl <= cr ? cl : cr;
    if (cost < best->cost) {
        best->cost = cost;
        best->axis = k;
        best->pos = p;
        best->planar_left = cl <= cr;
    }
}

static void sweep_axis(const builder *b, const kdr_bounds *box,
                       const ev_list *ev, int k, kd_split *best) {
    const int a1 = (k + 1) % 3, a2 = (k + 2) % 3;
    const float d1 = box->max[a1] - box->min[a1], d2 = box->max[a2] - box->min[a2];
    sah_ctx c = {box->min[k], box->max[k], d1 * d2, d1 + d2, 0.0f,
                 b->o.isect_cost, b->o.trav_cost, b->o.empty_bonus};
    float area = 2.0f * (c.cap + (c.max - c.min) * c.perim);
    if (!(area > 0.0f) || !(c.max > c.min))
        return;
    c.inv_area = 1.0f / area;
    const kd_event *e = ev->e[k];
    const size_t n = ev->n[k];
    size_t nl = 0, nr = ev->ntri;
    for (size_t i = 0; i < n;) {
        const uint32_t key = ev_key(e[i]);
        size_t pe = 0, pp = 0, ps = 0;
        do { /* one group: the events at this position */
            const unsigned type = ev_type(e[i]);
            pe += type == EV_END;
            pp += type == EV_PLANAR;
            ps += type == EV_START;
        } while (++i < n && ev_key(e[i]) == key);
        const float p = key_float(key);
        nr -= pp + pe;
        if (p > c.min && p < c.max)
            sah_try(&c, k, p, nl, pp, nr, best);
        nl += ps + pp;
    }
}

static int find_split(const builder *b, const kdr_bounds *box,
                      const ev_list *ev, kd_split *best) {
    best->axis = -1;
    best->pos = 0.0f;
    best->planar_left = 1;
    best->cost = INFINITY;
    for (int k = 0; k < 3; k++)
        sweep_axis(b, box, ev, k, best);
    return best->axis >= 0;
}

/* ---- splitting the event lists ------------------------------------------------ */

/* Makes *p hold at least need elements; the old contents are dead. */
static int grow(void **p, size_t *cap, size_t need, size_t elem) {
    if (need <= *cap)
        return KDR_OK;
    size_t c = *cap ? *cap : 4096;
    while (c < need)
        c *= 2;
    free(*p);
    *p = malloc(c * elem);
    *cap = *p ? c : 0;
    return *p ? KDR_OK : KDR_ENOMEM;
}

/* Marks each triangle of the node LEFT, RIGHT or BOTH and gathers the BOTH
 * ones in b->both; returns their count, or (size_t)-1 without memory.
 * One pass over the split axis suffices: a triangle's start event comes
 * before its end event. */
static size_t classify(builder *b, const ev_list *ev, const kd_split *s) {
    if (grow((void **)&b->both, &b->both_cap, ev->ntri + 1, sizeof *b->both))
        return (size_t)-1;
    const kd_event *e = ev->e[s->axis];
    const uint32_t split_key = float_key(s->pos + 0.0f);
    uint8_t *side = b->side;
    size_t nboth = 0;
    for (size_t i = 0; i < ev->n[s->axis]; i++) {
        const uint32_t key = ev_key(e[i]), tri = ev_tri(e[i]);
        switch (ev_type(e[i])) {
        case EV_START:
            side[tri] = key >= split_key ? SIDE_RIGHT : SIDE_BOTH;
            break;
        case EV_END:
            if (key <= split_key)
                side[tri] = SIDE_LEFT;
            else if (side[tri] == SIDE_BOTH)
                b->both[nboth++] = tri;
            break;
        default: /* planar */
            side[tri] = (key < split_key || (key == split_key && s->planar_left))
                            ? SIDE_LEFT
                            : SIDE_RIGHT;
        }
    }
    return nboth;
}

/* Merges sorted add[0..nadd) into dst, whose old sorted events sit at
 * dst[nadd .. nadd+nold); the write index never passes the read index. */
static void merge_tail(kd_event *dst, size_t nadd, size_t nold,
                       const kd_event *add) {
    size_t i = nadd, j = 0, w = 0;
    const size_t end = nadd + nold;
    while (j < nadd) {
        if (i < end && dst[i] <= add[j])
            dst[w++] = dst[i++];
        else
            dst[w++] = add[j++];
    }
}

/* Sorts the few new events of straddling triangles (keys are unique). */
static void sort_events(kd_event *a, size_t n) {
    while (n > 16) {
        kd_event x = a[0], y = a[n / 2], z = a[n - 1];
        kd_event p = x < y ? (y < z ? y : (x < z ? z : x)) : (x < z ? x : (y < z ? z : y));
        size_t i = 0, j = n - 1;
        for (;;) {
            while (a[i] < p)
                i++;
            while (a[j] > p)
                j--;
            if (i >= j)
                break;
            kd_event t = a[i];
            a[i++] = a[j];
            a[j--] = t;
        }
        sort_events(a, j + 1);
        a += j + 1;
        n -= j + 1;
    }
    for (size_t i = 1; i < n; i++) {
        kd_event v = a[i];
        size_t j = i;
        for (; j > 0 && a[j - 1] > v; j--)
            a[j] = a[j - 1];
        a[j] = v;
    }
}

/* Clips the straddlers to both child boxes; their new events go to
 * add[0..2] (left) and add[3..5] (right), sorted. Each triangle is clipped
 * to the node's box once, then that polygon to either side of the plane. */
static void clip_both(builder *b, size_t nboth, const kdr_bounds *box,
                      const kd_split *s, const kdr_bounds cbox[2],
                      kd_event *add[6], size_t nadd[6], size_t ntri[2]) {
    for (size_t i = 0; i < nboth; i++) {
        const float *tri = b->tris + 9 * (size_t)b->both[i];
        cvert poly[16], half[16];
        const int n = clip_to_box(tri, box, poly);
        for (int side = 0; side < 2; side++) {
            kdr_bounds bb;
            const int m = n ? clip_plane(poly, n, half, s->axis, s->pos,
                                         side ? 1.0 : -1.0)
                            : 0;
            if (poly_bounds(half, m, &cbox[side], &bb) ||
                tri_bounds_in_box(tri, &cbox[side], &bb)) {
                ev_add(add + 3 * side, nadd + 3 * side, &bb, b->both[i]);
                ntri[side]++;
            }
        }
    }
    for (int k = 0; k < 6; k++)
        sort_events(add[k], nadd[k]);
}

/* Partitions the node's events into the two children (kept in order,
 * branch-free) and merges in the straddlers' new events. The children live
 * in this depth's scratch buffer: a subtree only writes deeper buffers. */
static int split_events(builder *b, const ev_list *ev, const kd_split *s,
                        const kdr_bounds *box, const kdr_bounds cbox[2],
                        int depth, ev_list ch[2]) {
    const size_t nboth = classify(b, ev, s);
    if (nboth == (size_t)-1)
        return KDR_ENOMEM;
    const size_t stride = 2 * nboth + 1;
    if (grow((void **)&b->add, &b->add_cap, 6 * stride, sizeof *b->add))
        return KDR_ENOMEM;
    kd_event *add[6];
    size_t nadd[6] = {0, 0, 0, 0, 0, 0}, ntri[2] = {0, 0};
    for (int k = 0; k < 6; k++)
        add[k] = b->add + (size_t)k * stride;
    clip_both(b, nboth, box, s, cbox, add, nadd, ntri);
    size_t need = 0;
    for (int k = 0; k < 3; k++)
        need += 2 * ev->n[k] + nadd[k] + nadd[3 + k];
    if (grow((void **)&b->lvl[depth], &b->lvl_cap[depth], need, sizeof(kd_event)))
        return KDR_ENOMEM;
    kd_event *base = b->lvl[depth];
    for (int k = 0; k < 3; k++) {
        kd_event *w[2];
        for (int side = 0; side < 2; side++) {
            ch[side].e[k] = base;
            w[side] = base + nadd[3 * side + k];
            base += ev->n[k] + nadd[3 * side + k];
        }
        for (size_t i = 0; i < ev->n[k]; i++) {
            const kd_event e = ev->e[k][i];
            const uint8_t sd = b->side[ev_tri(e)];
            *w[0] = e;
            *w[1] = e;
            w[0] += sd == SIDE_LEFT;
            w[1] += sd == SIDE_RIGHT;
            if (k == 0 && ev_type(e) != EV_END) {
                ntri[0] += sd == SIDE_LEFT;
                ntri[1] += sd == SIDE_RIGHT;
            }
        }
        for (int side = 0; side < 2; side++) {
            const size_t na = nadd[3 * side + k];
            const size_t nold = (size_t)(w[side] - ch[side].e[k]) - na;
            merge_tail(ch[side].e[k], na, nold, add[3 * side + k]);
            ch[side].n[k] = na + nold;
        }
    }
    ch[0].ntri = ntri[0];
    ch[1].ntri = ntri[1];
    return KDR_OK;
}

/* ---- the recursion ------------------------------------------------------------- */

static int push_node(builder *b, size_t *idx) {
    if (b->nnodes >= KD_MAX_NODES)
        return KDR_ERANGE;
    if (b->nnodes == b->cap_nodes) {
        size_t cap = b->cap_nodes ? 2 * b->cap_nodes : 1024;
        kd_node *n = realloc(b->nodes, cap * sizeof *n);
        if (!n)
            return KDR_ENOMEM;
        b->nodes = n;
        b->cap_nodes = cap;
    }
    *idx = b->nnodes++;
    return KDR_OK;
}

static int reserve_refs(builder *b, size_t more) {
    if (b->nrefs + more > UINT32_MAX)
        return KDR_ERANGE;
    if (b->nrefs + more <= b->cap_refs)
        return KDR_OK;
    size_t cap = b->cap_refs ? b->cap_refs : 1024;
    while (cap < b->nrefs + more)
        cap *= 2;
    uint32_t *r = realloc(b->refs, cap * sizeof *r);
    if (!r)
        return KDR_ENOMEM;
    b->refs = r;
    b->cap_refs = cap;
    return KDR_OK;
}

static void make_leaf(builder *b, const ev_list *ev, const kdr_bounds *box,
                      int depth) {
    size_t idx;
    const size_t count = ev->ntri;
    int err = count >= KD_MAX_TRIS ? KDR_ERANGE : reserve_refs(b, count);
    if (err == KDR_OK)
        err = push_node(b, &idx);
    if (err != KDR_OK) {
        b->err = err;
        return;
    }
    b->nodes[idx].u.first = (uint32_t)b->nrefs;
    b->nodes[idx].bits = ((uint32_t)count << 2) | KD_LEAF;
    for (size_t i = 0; i < ev->n[0]; i++)
        if (ev_type(ev->e[0][i]) != EV_END)
            b->refs[b->nrefs++] = ev_tri(ev->e[0][i]);
    b->leaves++;
    b->empty_leaves += count == 0;
    if ((uint64_t)depth > b->depth_seen)
        b->depth_seen = (uint64_t)depth;
    b->sah += b->o.isect_cost * (double)count * box_area(box) * b->inv_root_area;
}

static void build_node(builder *b, const kdr_bounds *box, const ev_list *ev,
                       int depth, int bad);

static void make_interior(builder *b, const kdr_bounds *box, const ev_list *ev,
                          const kd_split *s, int depth, int bad) {
    kdr_bounds cbox[2] = {*box, *box};
    cbox[0].max[s->axis] = cbox[1].min[s->axis] = s->pos;
    ev_list ch[2];
    size_t idx = 0;
    int err = split_events(b, ev, s, box, cbox, depth, ch);
    if (err == KDR_OK)
        err = push_node(b, &idx);
    if (err != KDR_OK) {
        b->err = err;
        return;
    }
    b->nodes[idx].u.split = s->pos;
    b->nodes[idx].bits = (uint32_t)s->axis;
    b->sah += b->o.trav_cost * box_area(box) * b->inv_root_area;
    build_node(b, &cbox[0], &ch[0], depth + 1, bad);
    b->nodes[idx].bits = ((uint32_t)b->nnodes << 2) | (uint32_t)s->axis;
    build_node(b, &cbox[1], &ch[1], depth + 1, bad);
}

static void build_node(builder *b, const kdr_bounds *box, const ev_list *ev,
                       int depth, int bad) {
    kd_split s;
    if (b->err)
        return;
    if (ev->ntri > (size_t)b->o.leaf_size && depth < b->max_depth &&
        find_split(b, box, ev, &s)) {
        const float leaf_cost = b->o.isect_cost * (float)ev->ntri;
        if (s.cost > leaf_cost)
            bad++;
        if (!((s.cost > 4.0f * leaf_cost && ev->ntri < KD_BAD_SMALL) ||
              bad >= KD_BAD_REFINES)) {
            make_interior(b, box, ev, &s, depth, bad);
            return;
        }
    }
    make_leaf(b, ev, box, depth);
}

/* ---- the public build -------------------------------------------------------- */

static double now_ms(void) {
    struct timespec ts;
    timespec_get(&ts, TIME_UTC);
    return (double)ts.tv_sec * 1e3 + (double)ts.tv_nsec * 1e-6;
}

static void logf_(kdr_log_fn log, void *user, const char *fmt, ...) {
    if (!log)
        return;
    char msg[256];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(msg, sizeof msg, fmt, ap);
    va_end(ap);
    log(user, msg);
}

static int check_opts(const kdr_build_opts *o) {
    if (!(o->isect_cost > 0.0f) || !(o->trav_cost >= 0.0f) ||
        !(o->empty_bonus >= 0.0f && o->empty_bonus < 1.0f) || o->leaf_size < 0)
        return KDR_EINVAL;
    return KDR_OK;
}

/* Bounds of the non-degenerate triangles; returns how many there are. */
static size_t scene_bounds(kdr_scene *s) {
    size_t nvalid = 0;
    kdr_bounds b = {{INFINITY, INFINITY, INFINITY}, {-INFINITY, -INFINITY, -INFINITY}};
    for (size_t i = 0; i < s->ntris; i++) {
        const float *t = s->tris + 9 * i;
        if (kd_tri_degenerate(t))
            continue;
        nvalid++;
        for (int v = 0; v < 3; v++)
            for (int k = 0; k < 3; k++) {
                b.min[k] = fminf(b.min[k], t[3 * v + k]);
                b.max[k] = fmaxf(b.max[k], t[3 * v + k]);
            }
    }
    if (nvalid == 0)
        memset(&b, 0, sizeof b);
    s->bounds = b;
    return nvalid;
}

/* The traversal box: bounds padded by a few ulps of the scene's largest
 * coordinate, so rays grazing the boundary (and triangles a rounding step
 * outside it in the watertight test) still enter. */
static void pad_root(kdr_scene *s) {
    float m = 0.0f;
    double d2 = 0.0;
    for (int k = 0; k < 3; k++) {
        m = fmaxf(m, fmaxf(fabsf(s->bounds.min[k]), fabsf(s->bounds.max[k])));
        double d = (double)s->bounds.max[k] - s->bounds.min[k];
        d2 += d * d;
    }
    const float pad = m * KD_ROOT_PAD + FLT_MIN;
    for (int k = 0; k < 3; k++) {
        s->root.min[k] = s->bounds.min[k] - pad;
        s->root.max[k] = s->bounds.max[k] + pad;
    }
    s->diagonal = (float)sqrt(d2);
}

static int root_events(const kdr_scene *s, size_t nvalid, ev_list *ev) {
    kd_event *tmp = malloc((2 * nvalid + 1) * sizeof *tmp);
    int err = tmp ? KDR_OK : KDR_ENOMEM;
    memset(ev, 0, sizeof *ev);
    for (int k = 0; k < 3 && err == KDR_OK; k++)
        if (!(ev->e[k] = malloc((2 * nvalid + 1) * sizeof(kd_event))))
            err = KDR_ENOMEM;
    for (size_t i = 0; i < s->ntris && err == KDR_OK; i++) {
        const float *t = s->tris + 9 * i;
        if (kd_tri_degenerate(t))
            continue;
        kdr_bounds bb;
        for (int k = 0; k < 3; k++) {
            bb.min[k] = min3(t[k], t[3 + k], t[6 + k]);
            bb.max[k] = max3(t[k], t[3 + k], t[6 + k]);
        }
        ev_add(ev->e, ev->n, &bb, (uint32_t)i);
    }
    for (int k = 0; k < 3 && err == KDR_OK; k++)
        radix_sort(ev->e[k], tmp, ev->n[k]);
    ev->ntri = nvalid;
    free(tmp);
    if (err != KDR_OK)
        ev_free(ev);
    return err;
}

static int max_depth_for(const kdr_build_opts *o, size_t n) {
    int d = o->max_depth > 0 ? o->max_depth
                             : (int)lround(KD_DEPTH_BASE +
                                           KD_DEPTH_PER_LOG2 *
                                               log2((double)(n ? n : 1)));
    return d < KD_MAX_DEPTH ? d : KD_MAX_DEPTH;
}

static int build_tree(kdr_scene *s, size_t nvalid, const kdr_build_opts *o,
                      kdr_log_fn log, void *user) {
    builder b;
    memset(&b, 0, sizeof b);
    b.tris = s->tris;
    b.o = *o;
    b.max_depth = max_depth_for(o, nvalid);
    double area = box_area(&s->bounds);
    b.inv_root_area = area > 0.0 ? 1.0 / area : 0.0;
    const int phases = nvalid > KD_LOG_PHASES;
    double t0 = now_ms();
    ev_list ev = {{NULL, NULL, NULL}, {0, 0, 0}, 0};
    b.side = malloc(s->ntris);
    int err = b.side ? root_events(s, nvalid, &ev) : KDR_ENOMEM;
    if (err == KDR_OK) {
        if (phases)
            logf_(log, user, "kd build: %zu events sorted in %.1f ms",
                  ev.n[0] + ev.n[1] + ev.n[2], now_ms() - t0);
        build_node(&b, &s->bounds, &ev, 0, 0);
        err = b.err;
        if (phases && err == KDR_OK)
            logf_(log, user, "kd build: %zu nodes, %zu refs after %.1f ms",
                  b.nnodes, b.nrefs, now_ms() - t0);
    }
    free(b.side);
    ev_free(&ev);
    for (int d = 0; d <= KD_MAX_DEPTH; d++)
        free(b.lvl[d]);
    free(b.both);
    free(b.add);
    if (err != KDR_OK) {
        free(b.nodes);
        free(b.refs);
        return err;
    }
    s->nodes = b.nodes;
    s->nnodes = b.nnodes;
    s->refs = b.refs;
    s->nrefs = b.nrefs;
    s->stats.nodes = b.nnodes;
    s->stats.leaves = b.leaves;
    s->stats.empty_leaves = b.empty_leaves;
    s->stats.max_depth = b.depth_seen;
    s->stats.refs = b.nrefs;
    s->stats.refs_per_leaf = b.leaves > b.empty_leaves
                                 ? (double)b.nrefs / (double)(b.leaves - b.empty_leaves)
                                 : 0.0;
    s->stats.sah_cost = b.sah;
    return KDR_OK;
}

#ifndef NDEBUG
/* Debug builds re-check the layout every traversal relies on: splits inside
 * their node's box, the above child after the below subtree, leaf lists in
 * range and free of degenerate triangles, every node reached once. */
static size_t check_subtree(const kdr_scene *s, uint32_t idx, kdr_bounds box,
                            int depth) {
    assert(idx < s->nnodes && depth <= KD_MAX_DEPTH);
    const kd_node *n = &s->nodes[idx];
    if (kd_is_leaf(n)) {
        assert((size_t)n->u.first + kd_count(n) <= s->nrefs);
        for (uint32_t i = 0; i < kd_count(n); i++) {
            assert(s->refs[n->u.first + i] < s->ntris);
            assert(!kd_tri_degenerate(s->tris + 9 * (size_t)s->refs[n->u.first + i]));
        }
        return 1;
    }
    const int k = kd_axis(n);
    assert(n->u.split > box.min[k] && n->u.split < box.max[k]);
    assert(kd_above(n) > idx + 1);
    kdr_bounds lb = box, rb = box;
    lb.max[k] = rb.min[k] = n->u.split;
    return 1 + check_subtree(s, idx + 1, lb, depth + 1) +
           check_subtree(s, kd_above(n), rb, depth + 1);
}
#endif

static int check_input(const float *tris, size_t ntris, kdr_scene **out) {
    if (!out)
        return KDR_EINVAL;
    *out = NULL;
    if (ntris > 0 && !tris)
        return KDR_EINVAL;
    if (ntris > KD_MAX_TRIS)
        return KDR_ERANGE;
    for (size_t i = 0; i < 9 * ntris; i++)
        if (!isfinite(tris[i]))
            return KDR_EINVAL;
    return KDR_OK;
}

int kdr_scene_build(const float *tris, size_t ntris, const kdr_build_opts *opts,
                    kdr_log_fn log, void *log_user, kdr_scene **out) {
    kdr_build_opts o;
    int err = check_input(tris, ntris, out);
    if (err != KDR_OK)
        return err;
    if (opts)
        o = *opts;
    else
        kdr_build_opts_default(&o);
    if ((err = check_opts(&o)) != KDR_OK)
        return err;
    const double t0 = now_ms();
    kdr_scene *s = calloc(1, sizeof *s);
    if (!s || !(s->tris = malloc(9 * ntris * sizeof(float) + 1))) {
        free(s);
        return KDR_ENOMEM;
    }
    if (ntris)
        memcpy(s->tris, tris, 9 * ntris * sizeof(float));
    s->ntris = ntris;
    const size_t nvalid = scene_bounds(s);
    pad_root(s);
    logf_(log, log_user, "kd build: %zu triangles (%zu degenerate)", ntris,
          ntris - nvalid);
    if (nvalid > 0 && (err = build_tree(s, nvalid, &o, log, log_user)) != KDR_OK) {
        kdr_scene_free(s);
        return err;
    }
    s->stats.build_ms = now_ms() - t0;
    s->stats.bytes = s->nnodes * sizeof(kd_node) + s->nrefs * sizeof(uint32_t) +
                     9 * ntris * sizeof(float);
    logf_(log, log_user,
          "kd build: done in %.1f ms: %llu nodes (%llu leaves, %llu empty), "
          "depth %llu, %.2f refs/leaf, SAH %.1f, %.1f MB",
          s->stats.build_ms, (unsigned long long)s->stats.nodes,
          (unsigned long long)s->stats.leaves,
          (unsigned long long)s->stats.empty_leaves,
          (unsigned long long)s->stats.max_depth, s->stats.refs_per_leaf,
          s->stats.sah_cost, (double)s->stats.bytes / 1e6);
    if ((err = kd_layout(s)) != KDR_OK) {
        kdr_scene_free(s);
        return err;
    }
#ifndef NDEBUG
    if (s->nodes) {
        size_t reached = check_subtree(s, 0, s->bounds, 0);
        assert(reached == s->nnodes);
        (void)reached;
    }
#endif
    *out = s;
    return KDR_OK;
}
