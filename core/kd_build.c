/*
 * kd_build.c — SAH kd-tree construction in O(N log N), after Wald and
 * Havran, "On building fast kd-trees for ray tracing, and on doing that in
 * O(N log N)" (2006): the recursion, the node and reference arrays it
 * fills, and the public kdr_scene_build. The stages it calls live in
 * kd_build_events.c (sorted event lists and their partition),
 * kd_build_clip.c (perfect splits) and kd_build_sah.c (the split search);
 * kd_build.h says what they share.
 *
 * Every node has three sorted event lists, one per axis, sorted once at
 * the root. A node becomes a leaf when it is small, deep, or when pbrt's
 * bad-refine rule says its best split does not pay; otherwise its lists
 * are split and both children are built depth-first, below child first,
 * so the below child is always the node right after its parent. A
 * triangle lying in the split plane goes to the cheaper side; a triangle
 * touching the plane from one side goes to that side only.
 */
#include <assert.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "kd_build.h"
#include "kd_traverse.h"

#define KD_MAX_NODES ((size_t)1 << 30) /* above-child index fits 30 bits */
#define KD_LOG_PHASES 1000000          /* log each phase above this size */
#define KD_ROOT_PAD 0x1p-20f           /* root padding, relative (~8 ulps) */

static double box_area(const kdr_bounds *b) {
    double dx = (double)b->max[0] - b->min[0];
    double dy = (double)b->max[1] - b->min[1];
    double dz = (double)b->max[2] - b->min[2];
    return 2.0 * (dx * dy + dy * dz + dz * dx);
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
    int err = kd_split_events(b, ev, s, box, cbox, depth, ch);
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
        kd_find_split(b, box, ev, &s)) {
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
        kd_radix_sort(ev->e[k], tmp, ev->n[k]);
    ev->ntri = nvalid;
    free(tmp);
    if (err != KDR_OK)
        kd_ev_free(ev);
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
    kd_ev_free(&ev);
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
