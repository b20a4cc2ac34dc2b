/*
 * kd_build.c — SAH kd-tree construction: the recursion, and the public
 * kdr_scene_build. The stages it calls live in kd_build_events.c (sorted
 * event lists and their partition), kd_build_clip.c (perfect splits),
 * kd_build_sah.c (the split searches), kd_build_bin.c (the binned top) and
 * kd_build_par.c (threads, and the final node and reference arrays);
 * kd_build.h says what they share.
 *
 * A node with more than opts.exact_max triangles is binned: its triangles
 * are a plain array with their bounds, its plane comes from min-max bins
 * (Mitsuba 0.6's scheme). Smaller nodes use the exact O(N log N) sweep of
 * Wald and Havran, "On building fast kd-trees for ray tracing, and on doing
 * that in O(N log N)" (2006): three sorted event lists per node, made once
 * where the node turned exact (or at the root). A node becomes a leaf when
 * it is small, deep, or when pbrt's bad-refine rule says its best split
 * does not pay; otherwise both children are built depth-first, below child
 * first, so the below child is always the node right after its parent. A
 * triangle lying in the split plane goes to one side only; a triangle
 * touching the plane from one side goes to that side only.
 *
 * With threads, a child subtree big enough (builder.spawn_min) is handed
 * to another worker instead of being built in place; the decisions never
 * depend on where a subtree is built, so neither does the tree.
 */
#include <assert.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "kd_build.h"
#include "kd_stream.h"
#include "kd_traverse.h"

#define KD_LOG_PHASES 1000000 /* log each phase above this size */
#define KD_MAX_THREADS 1024   /* kdr_build_opts.threads beyond this: 1024 */
#define KD_ROOT_PAD 0x1p-20f  /* root padding, relative (~8 ulps) */

/* ---- fragments: where a task writes ------------------------------------------- */

static int push_node(builder *b, size_t *idx) {
    kd_frag *f = b->frag;
    if (f->nnodes >= KD_MAX_NODES)
        return KDR_ERANGE;
    if (f->nnodes == f->cap_nodes) {
        size_t cap = f->cap_nodes ? 2 * f->cap_nodes : 1024;
        kd_node *n = realloc(f->nodes, cap * sizeof *n);
        if (!n)
            return KDR_ENOMEM;
        f->nodes = n;
        f->cap_nodes = cap;
    }
    *idx = f->nnodes++;
    return KDR_OK;
}

static int reserve_refs(builder *b, size_t more) {
    kd_frag *f = b->frag;
    if (f->nrefs + more > UINT32_MAX)
        return KDR_ERANGE;
    if (f->nrefs + more <= f->cap_refs)
        return KDR_OK;
    size_t cap = f->cap_refs ? f->cap_refs : 1024;
    while (cap < f->nrefs + more)
        cap *= 2;
    uint32_t *r = realloc(f->refs, cap * sizeof *r);
    if (!r)
        return KDR_ENOMEM;
    f->refs = r;
    f->cap_refs = cap;
    return KDR_OK;
}

/* A new leaf of count references; returns where they go, NULL on error. */
static uint32_t *push_leaf(builder *b, size_t count) {
    size_t idx;
    int err = count >= KD_LEAF_MAX_REFS ? KDR_ERANGE : reserve_refs(b, count);
    if (err == KDR_OK)
        err = push_node(b, &idx);
    if (err != KDR_OK) {
        b->err = err;
        return NULL;
    }
    kd_frag *f = b->frag;
    f->nodes[idx].u.first = (uint32_t)f->nrefs;
    f->nodes[idx].bits = ((uint32_t)count << 4) | KD_LEAF; /* flat: set_flat */
    f->nrefs += count;
    return f->refs + f->nrefs - count;
}

/* The placeholder of a subtree another worker builds into fragment id. */
static void push_link(builder *b, uint32_t id) {
    size_t idx;
    int err = push_node(b, &idx);
    if (err != KDR_OK) {
        b->err = err;
        return;
    }
    b->frag->nodes[idx].u.first = KD_LINK;
    b->frag->nodes[idx].bits = (id << 4) | KD_LEAF;
    b->frag->links++;
}

/* An interior node at split s; its above child is set by set_above. */
static int push_interior(builder *b, const kd_split *s, size_t *idx) {
    int err = push_node(b, idx);
    if (err != KDR_OK) {
        b->err = err;
        return err;
    }
    b->frag->nodes[*idx].u.split = s->pos;
    b->frag->nodes[*idx].bits = (uint32_t)s->axis;
    return KDR_OK;
}

static void set_above(builder *b, size_t idx, int axis) {
    b->frag->nodes[idx].bits = ((uint32_t)b->frag->nnodes << 2) | (uint32_t)axis;
}

static int stopped(builder *b) { return b->err || kd_build_failed(b); }

/* pbrt's termination: is splitting a node of n triangles at s worth it?
 * Updates the count of bad refines on the path. */
static int split_pays(size_t n, const kd_split *s, const builder *b, int *bad) {
    const float leaf_cost = b->o.isect_cost * (float)n;
    if (s->cost > leaf_cost)
        ++*bad;
    return !((s->cost > 4.0f * leaf_cost && n < KD_BAD_SMALL) ||
             *bad >= KD_BAD_REFINES);
}

/* ---- the exact sweep (event lists) --------------------------------------------- */

static void build_exact(builder *b, const kdr_bounds *box, const ev_list *ev,
                        int depth, int bad);

/* The flat field (kd_internal.h) of the leaf push_leaf just wrote, its
 * references filled in: the fragment's last node. */
static void set_flat(builder *b) {
    kd_node *n = &b->frag->nodes[b->frag->nnodes - 1];
    n->bits |= (uint32_t)kd_flat_of(b->tris, b->frag->refs + n->u.first, kd_count(n)) << 2;
}

static void make_leaf(builder *b, const ev_list *ev) {
    uint32_t *r = push_leaf(b, ev->ntri);
    if (!r)
        return;
    for (size_t i = 0; i < ev->n[0]; i++)
        if (ev_type(ev->e[0][i]) != EV_END)
            *r++ = ev_tri(ev->e[0][i]);
    set_flat(b);
}

/* Hands the above child's lists (copied out of this worker's scratch) to
 * another worker; 0 if it must be built here. */
static int spawn_exact(builder *b, const kdr_bounds *cbox, const ev_list *ch,
                       int depth, int bad, uint32_t *id) {
    if (!b->pool || ch->ntri < b->spawn_min)
        return 0;
    kd_task t;
    memset(&t, 0, sizeof t);
    t.kind = KD_TASK_EXACT;
    t.box = *cbox;
    t.depth = depth;
    t.bad = bad;
    t.block = malloc((ch->n[0] + ch->n[1] + ch->n[2] + 1) * sizeof(kd_event));
    if (!t.block)
        return 0;
    kd_event *w = t.block;
    for (int k = 0; k < 3; k++) {
        memcpy(w, ch->e[k], ch->n[k] * sizeof *w);
        t.ev.e[k] = w;
        t.ev.n[k] = ch->n[k];
        w += ch->n[k];
    }
    t.ev.ntri = ch->ntri;
    if (kd_spawn(b, &t, id) != KDR_OK) {
        free(t.block);
        return 0;
    }
    return 1;
}

static void make_interior(builder *b, const kdr_bounds *box, const ev_list *ev,
                          const kd_split *s, int depth, int bad) {
    kdr_bounds cbox[2] = {*box, *box};
    cbox[0].max[s->axis] = cbox[1].min[s->axis] = s->pos;
    ev_list ch[2];
    size_t idx = 0;
    kd_event *own = NULL;
    const size_t mark = b->stack_top;
    int err = kd_split_events(b, ev, s, box, cbox, ch, &own);
    if (err != KDR_OK) {
        b->err = err;
        return;
    }
    if (push_interior(b, s, &idx) == KDR_OK) {
        uint32_t id;
        const int spawned = spawn_exact(b, &cbox[1], &ch[1], depth + 1, bad, &id);
        build_exact(b, &cbox[0], &ch[0], depth + 1, bad);
        set_above(b, idx, s->axis);
        if (spawned)
            push_link(b, id);
        else
            build_exact(b, &cbox[1], &ch[1], depth + 1, bad);
    }
    b->stack_top = mark; /* the children's lists are dead */
    free(own);
}

static void build_exact(builder *b, const kdr_bounds *box, const ev_list *ev,
                        int depth, int bad) {
    kd_split s;
    if (stopped(b))
        return;
    if (ev->ntri > (size_t)b->o.leaf_size && depth < b->max_depth &&
        kd_find_split(b, box, ev, &s) && split_pays(ev->ntri, &s, b, &bad)) {
        make_interior(b, box, ev, &s, depth, bad);
        return;
    }
    if (!b->err) /* kd_find_split may have run out of memory */
        make_leaf(b, ev);
}

/* ---- the binned top (prim arrays) ------------------------------------------------ */

static void build_binned(builder *b, const kdr_bounds *box, kd_prims *p,
                         int depth, int bad);

/* The subtree of a node small enough for the exact sweep. */
static void binned_to_exact(builder *b, const kdr_bounds *box, kd_prims *p,
                            int depth, int bad) {
    ev_list ev;
    kd_event *block;
    int err = kd_prims_to_events(p, &ev, &block, b->avx512);
    free(p->p);
    p->p = NULL;
    if (err == KDR_OK && !b->side && !(b->side = calloc(b->ntris, 1)))
        err = KDR_ENOMEM;
    if (err == KDR_OK)
        build_exact(b, box, &ev, depth, bad);
    else
        b->err = err;
    free(block);
}

static int spawn_binned(builder *b, const kdr_bounds *cbox, kd_prims *ch,
                        int depth, int bad, uint32_t *id) {
    if (!b->pool || ch->n < b->spawn_min)
        return 0;
    kd_task t;
    memset(&t, 0, sizeof t);
    t.kind = KD_TASK_BINNED;
    t.box = *cbox;
    t.depth = depth;
    t.bad = bad;
    t.prims = *ch;
    if (kd_spawn(b, &t, id) != KDR_OK)
        return 0;
    ch->p = NULL; /* the task owns it now */
    return 1;
}

static void make_interior_binned(builder *b, const kdr_bounds *box, kd_prims *p,
                                 const kd_split *s, int depth, int bad) {
    kdr_bounds cbox[2] = {*box, *box};
    cbox[0].max[s->axis] = cbox[1].min[s->axis] = s->pos;
    kd_prims ch[2];
    size_t idx;
    int err = kd_bin_partition(b, box, s, cbox, p, ch);
    free(p->p);
    p->p = NULL;
    if (err != KDR_OK) {
        b->err = err;
        return;
    }
    if (push_interior(b, s, &idx) != KDR_OK) {
        free(ch[0].p);
        free(ch[1].p);
        return;
    }
    uint32_t id;
    const int spawned = spawn_binned(b, &cbox[1], &ch[1], depth + 1, bad, &id);
    build_binned(b, &cbox[0], &ch[0], depth + 1, bad);
    set_above(b, idx, s->axis);
    if (spawned)
        push_link(b, id);
    else
        build_binned(b, &cbox[1], &ch[1], depth + 1, bad);
}

/* Builds the subtree of a binned node; frees p->p. */
static void build_binned(builder *b, const kdr_bounds *box, kd_prims *p,
                         int depth, int bad) {
    kd_split s;
    if (stopped(b)) {
        free(p->p);
        p->p = NULL;
        return;
    }
    if (p->n <= (size_t)b->o.exact_max) {
        binned_to_exact(b, box, p, depth, bad);
        return;
    }
    if (p->n > (size_t)b->o.leaf_size && depth < b->max_depth &&
        kd_bin_split(b, box, p, &s) && split_pays(p->n, &s, b, &bad)) {
        make_interior_binned(b, box, p, &s, depth, bad);
        return;
    }
    uint32_t *r = push_leaf(b, p->n);
    for (size_t i = 0; r && i < p->n; i++)
        r[i] = p->p[i].tri;
    if (r)
        set_flat(b);
    free(p->p);
    p->p = NULL;
}

/* The root's events on axis k, in triangle order (ev_add's, one axis):
 * each root SORT task makes its own axis, so with threads the three are
 * made in parallel. Returns their count. */
static size_t root_axis_events(const builder *b, int k, int skip_degenerate,
                               kd_event *out) {
    size_t n = 0;
    for (size_t i = 0; i < b->ntris; i++) {
        const float *t = b->tris + 9 * i;
        if (skip_degenerate && kd_tri_degenerate(t))
            continue;
        const float lo = min3(t[k], t[3 + k], t[6 + k]);
        const float hi = max3(t[k], t[3 + k], t[6 + k]);
        if (lo == hi) {
            out[n++] = ev_make(lo, EV_PLANAR, (uint32_t)i);
        } else {
            out[n++] = ev_make(lo, EV_START, (uint32_t)i);
            out[n++] = ev_make(hi, EV_END, (uint32_t)i);
        }
    }
    return n;
}

void kd_run_task(builder *b, kd_task *t) {
    switch (t->kind) {
    case KD_TASK_SORT:
        if (t->n_out) {
            const size_t n = root_axis_events(b, t->axis, t->skip_degenerate, t->ev.e[0]);
            kd_radix_sort_into(t->ev.e[0], t->ev.e[1], n);
            *t->n_out = n;
        } else {
            kd_radix_sort(t->ev.e[0], t->ev.e[1], t->ev.n[0]);
        }
        break;
    case KD_TASK_EXACT:
        b->frag = t->frag;
        if (!b->side && !(b->side = calloc(b->ntris, 1)))
            b->err = KDR_ENOMEM;
        else
            build_exact(b, &t->box, &t->ev, t->depth, t->bad);
        break;
    case KD_TASK_BINNED:
        b->frag = t->frag;
        build_binned(b, &t->box, &t->prims, t->depth, t->bad);
        break;
    }
    free(t->block);
    t->block = NULL;
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
        !(o->empty_bonus >= 0.0f && o->empty_bonus < 1.0f) || o->leaf_size < 0 ||
        o->threads < 0 || o->exact_max < 0)
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
                /* fminf/fmaxf are library calls (18 per triangle, serial
                 * before the parallel build); these are minss/maxss, the
                 * same choice x86-64 glibc's make for finite inputs */
                const float x = t[3 * v + k];
                b.min[k] = b.min[k] < x ? b.min[k] : x;
                b.max[k] = b.max[k] > x ? b.max[k] : x;
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

/* The root's sorted event lists (exact build from the root): three SORT
 * tasks, each making one axis' events in triangle order and radix-sorting
 * them (in parallel when there are threads). The block holds, per axis,
 * the unsorted events and then the sorted ones (the sort's output, the
 * lists of the root task), and is the root task's, freed when it is done:
 * one allocation, in huge pages (kd_scratch_alloc, kd_mem.c), instead of
 * six fresh ones. */
static int root_events(const kdr_scene *s, size_t nvalid, ev_list *ev,
                       kd_event **block, kd_task sort[3]) {
    const size_t per = 2 * nvalid + 1;
    memset(ev, 0, sizeof *ev);
    memset(sort, 0, 3 * sizeof *sort);
    kd_event *m = kd_scratch_alloc(6 * per * sizeof *m);
    *block = m;
    if (!m)
        return KDR_ENOMEM;
    ev->ntri = nvalid;
    for (int k = 0; k < 3; k++) {
        ev->e[k] = m + (size_t)(3 + k) * per;
        sort[k].kind = KD_TASK_SORT;
        sort[k].axis = k;
        sort[k].skip_degenerate = nvalid < s->ntris;
        sort[k].n_out = &ev->n[k];
        sort[k].ev.e[0] = m + (size_t)k * per;
        sort[k].ev.e[1] = ev->e[k];
    }
    return KDR_OK;
}

static int max_depth_for(const kdr_build_opts *o, size_t n) {
    int d = o->max_depth > 0 ? o->max_depth
                             : (int)lround(KD_DEPTH_BASE +
                                           KD_DEPTH_PER_LOG2 *
                                               log2((double)(n ? n : 1)));
    return d < KD_MAX_DEPTH ? d : KD_MAX_DEPTH;
}

/* Subtrees worth a task: big enough to repay the hand-over, few enough
 * (KD_TASKS_PER_THREAD per thread) to keep the copies of exact lists cheap.
 * Only where the work is cut depends on the thread count, never the tree. */
static size_t spawn_min_for(size_t nvalid, int threads) {
    const size_t per = nvalid / ((size_t)KD_TASKS_PER_THREAD * (size_t)threads);
    return per > KD_SPAWN_MIN ? per : KD_SPAWN_MIN;
}

static int build_tree(kdr_scene *s, size_t nvalid, const kdr_build_opts *o,
                      kdr_log_fn log, void *user) {
    /* No more threads than tasks of KD_SPAWN_MIN triangles could keep busy
     * (below two, the caller alone), nor than KD_MAX_THREADS: extra ones
     * would only be started and joined. */
    const size_t useful = nvalid / KD_SPAWN_MIN;
    size_t t = o->threads > 1 ? (size_t)o->threads : 1;
    t = t < useful ? t : useful;
    t = t < KD_MAX_THREADS ? t : KD_MAX_THREADS;
    const int threads = t > 1 ? (int)t : 1;
    builder proto;
    memset(&proto, 0, sizeof proto);
    proto.tris = s->tris;
    proto.ntris = s->ntris;
    proto.o = *o;
    proto.max_depth = max_depth_for(o, nvalid);
    proto.spawn_min = spawn_min_for(nvalid, threads);
    proto.avx512 = kd_cpu_has_avx512();
    /* Huge-page scratch won where the whole tree is exact (haus, clearcoat:
     * 0.88-0.93x CPU at 1 and 2 threads) and lost on binned tops at 2
     * threads (engine, engine3: 1.09-1.18x median, single rounds up to
     * 2.7x): bench/ab_build, docs/BUILD.md round 4. */
    proto.huge = nvalid <= (size_t)o->exact_max;
    const int phases = nvalid > KD_LOG_PHASES;
    double t0 = now_ms();
    kd_task root, sort[3];
    memset(&root, 0, sizeof root);
    root.box = s->bounds;
    int err, nsort = 0;
    if (nvalid > (size_t)o->exact_max) {
        root.kind = KD_TASK_BINNED;
        err = kd_root_prims(s->tris, s->ntris, nvalid, &root.prims);
    } else {
        root.kind = KD_TASK_EXACT;
        err = root_events(s, nvalid, &root.ev, &root.block, sort);
        nsort = 3;
    }
    kd_frag **frags = NULL;
    size_t nfrags = 0;
    double cpu_ms[2] = {0.0, 0.0};
    if (err == KDR_OK)
        err = kd_build_run(&proto, threads, sort, nsort, &root, &frags, &nfrags, cpu_ms);
    else {
        free(root.prims.p);
        free(root.block);
    }
    if (err == KDR_OK) {
        /* the busiest thread's CPU time bounds the wall time an idle
         * machine would take for this phase */
        if (phases || threads > 1)
            logf_(log, user,
                  "kd build: %zu pieces on %d thread%s after %.1f ms (CPU: busiest "
                  "thread %.1f ms, all %.1f ms)",
                  nfrags, threads, threads == 1 ? "" : "s", now_ms() - t0, cpu_ms[0],
                  cpu_ms[1]);
        err = kd_stitch(frags, nfrags, o, s);
    }
    kd_frags_free(frags, nfrags);
    return err;
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
    if (!s || !(s->tris = kd_mem_alloc(9 * ntris * sizeof(float) + 1))) {
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
