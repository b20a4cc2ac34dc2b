/*
 * kd_build_par.c — the SAH build on several threads (kd_build.h), and the
 * pass that turns the pieces into the scene's node and reference arrays.
 *
 * Work is a FIFO of tasks under one mutex: the caller and threads-1 helper
 * threads (POSIX threads, started and joined by each build) pop the oldest
 * task and run it. A task builds one subtree depth-first into its own
 * fragment; where a child subtree is big enough (builder.spawn_min) it is
 * queued as a new task and the parent's fragment gets a link node in its
 * place. Tasks are few and coarse (a subtree of thousands of triangles),
 * so one lock is no bottleneck. POSIX threads rather than C11 <threads.h>:
 * clang 14's ThreadSanitizer does not intercept thrd_create (a TSan build
 * crashes at the first thread), and the parallel build must stay testable.
 *
 * Every split decision depends only on the node's own triangles, never on
 * which thread made it or when; kd_stitch walks the fragments depth-first
 * from the root and writes exactly the node order a single-threaded build
 * writes (below child right after its parent, then the above child), so
 * the tree, its statistics included, is the same for every thread count.
 */
#define _POSIX_C_SOURCE 200809L
#include <pthread.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "kd_build.h"

struct kd_pool {
    pthread_mutex_t lock;
    pthread_cond_t cond; /* a task was queued, all work is done, or stop */
    kd_task *queue;      /* FIFO: [head, tail) */
    size_t head, tail, cap;
    size_t running; /* tasks being run */
    int stop;
    atomic_int failed; /* first error of any worker, KDR_OK until then */
    kd_frag **frags;   /* frags[0] is the root's */
    size_t nfrags, cap_frags;
};

/* ---- the task queue ---------------------------------------------------------- */

static int push_locked(kd_pool *p, const kd_task *t) {
    if (p->tail == p->cap) {
        const size_t cap = p->cap ? 2 * p->cap : 64;
        kd_task *q = realloc(p->queue, cap * sizeof *q);
        if (!q)
            return KDR_ENOMEM;
        p->queue = q;
        p->cap = cap;
    }
    p->queue[p->tail++] = *t;
    pthread_cond_broadcast(&p->cond);
    return KDR_OK;
}

int kd_spawn(builder *b, const kd_task *t, uint32_t *frag) {
    kd_pool *p = b->pool;
    kd_frag *f = calloc(1, sizeof *f);
    if (!f)
        return KDR_ENOMEM;
    int err = KDR_OK;
    pthread_mutex_lock(&p->lock);
    if (p->nfrags == p->cap_frags) {
        const size_t cap = p->cap_frags ? 2 * p->cap_frags : 64;
        kd_frag **v = realloc(p->frags, cap * sizeof *v);
        if (v) {
            p->frags = v;
            p->cap_frags = cap;
        } else {
            err = KDR_ENOMEM;
        }
    }
    if (err == KDR_OK && p->nfrags >= KD_MAX_NODES)
        err = KDR_ERANGE;
    kd_task c = *t;
    c.frag = f;
    if (err == KDR_OK && (err = push_locked(p, &c)) == KDR_OK) {
        *frag = (uint32_t)p->nfrags;
        p->frags[p->nfrags++] = f;
    }
    pthread_mutex_unlock(&p->lock);
    if (err != KDR_OK)
        free(f);
    return err;
}

int kd_build_failed(const builder *b) {
    return b->pool ? atomic_load_explicit(&b->pool->failed, memory_order_relaxed) : 0;
}

/* With the lock held: runs the oldest task without it. */
static void run_one(kd_pool *p, builder *b) {
    kd_task t = p->queue[p->head++];
    if (p->head == p->tail)
        p->head = p->tail = 0;
    p->running++;
    pthread_mutex_unlock(&p->lock);
    kd_run_task(b, &t);
    if (b->err != KDR_OK) {
        int expected = KDR_OK;
        atomic_compare_exchange_strong(&p->failed, &expected, b->err);
    }
    pthread_mutex_lock(&p->lock);
    p->running--;
    if (p->running == 0 && p->head == p->tail)
        pthread_cond_broadcast(&p->cond);
}

static double thread_cpu_ms(void) {
    struct timespec ts;
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
    return (double)ts.tv_sec * 1e3 + (double)ts.tv_nsec * 1e-6;
}

static void *worker_main(void *arg) {
    builder *b = arg;
    kd_pool *p = b->pool;
    const double c0 = thread_cpu_ms();
    pthread_mutex_lock(&p->lock);
    for (;;) {
        if (p->head < p->tail)
            run_one(p, b);
        else if (p->stop)
            break;
        else
            pthread_cond_wait(&p->cond, &p->lock);
    }
    pthread_mutex_unlock(&p->lock);
    b->cpu_ms = thread_cpu_ms() - c0;
    return NULL;
}

/* The caller's share: runs tasks until none is queued or running. */
static void drain(kd_pool *p, builder *b) {
    pthread_mutex_lock(&p->lock);
    for (;;) {
        if (p->head < p->tail)
            run_one(p, b);
        else if (p->running == 0)
            break;
        else
            pthread_cond_wait(&p->cond, &p->lock);
    }
    pthread_mutex_unlock(&p->lock);
}

/* Queues the tasks and works until all of them (and what they spawn) are
 * done. */
static int run_phase(kd_pool *p, builder *b, kd_task *t, int n) {
    int err = KDR_OK;
    pthread_mutex_lock(&p->lock);
    for (int i = 0; i < n && err == KDR_OK; i++) {
        if ((err = push_locked(p, &t[i])) == KDR_OK) {
            t[i].block = NULL; /* the queued copy owns them now */
            t[i].prims.p = NULL;
        }
    }
    pthread_mutex_unlock(&p->lock);
    drain(p, b);
    return err;
}

static void discard(kd_task *t) {
    free(t->block);
    free(t->prims.p);
    t->block = NULL;
    t->prims.p = NULL;
}

static void free_scratch(builder *b) {
    free(b->side);
    free(b->stack);
    free(b->both);
    free(b->add);
    free(b->old);
    free(b->groups);
}

int kd_build_run(const builder *proto, int threads, kd_task *sort, int nsort,
                 kd_task *root, kd_frag ***frags, size_t *nfrags, double cpu_ms[2]) {
    const double c0 = thread_cpu_ms();
    kd_pool p;
    memset(&p, 0, sizeof p);
    atomic_init(&p.failed, KDR_OK);
    builder *w = calloc((size_t)threads, sizeof *w);
    pthread_t *th = calloc((size_t)threads, sizeof *th);
    p.frags = malloc(64 * sizeof *p.frags);
    p.cap_frags = 64;
    kd_frag *rf = calloc(1, sizeof *rf);
    if (!w || !th || !p.frags || !rf) {
        free(w);
        free(th);
        free(p.frags);
        free(rf);
        for (int i = 0; i < nsort; i++)
            discard(&sort[i]);
        discard(root);
        return KDR_ENOMEM;
    }
    p.frags[p.nfrags++] = rf;
    root->frag = rf;
    pthread_mutex_init(&p.lock, NULL);
    pthread_cond_init(&p.cond, NULL);
    for (int i = 0; i < threads; i++) {
        w[i] = *proto;
        w[i].pool = threads > 1 ? &p : NULL;
    }
    int started = 1;
    for (; started < threads; started++)
        if (pthread_create(&th[started], NULL, worker_main, &w[started]) != 0)
            break; /* fewer helpers: slower, same tree */
    int err = KDR_OK;
    if (threads > 1) {
        err = run_phase(&p, &w[0], sort, nsort);
        if (err == KDR_OK)
            err = run_phase(&p, &w[0], root, 1);
    } else {
        for (int i = 0; i < nsort; i++)
            kd_run_task(&w[0], &sort[i]);
        kd_run_task(&w[0], root);
    }
    for (int i = 0; i < nsort; i++)
        discard(&sort[i]);
    discard(root);
    pthread_mutex_lock(&p.lock);
    p.stop = 1;
    pthread_cond_broadcast(&p.cond);
    pthread_mutex_unlock(&p.lock);
    w[0].cpu_ms = thread_cpu_ms() - c0;
    for (int i = 1; i < started; i++)
        pthread_join(th[i], NULL);
    cpu_ms[0] = cpu_ms[1] = 0.0;
    for (int i = 0; i < started; i++) {
        cpu_ms[0] = w[i].cpu_ms > cpu_ms[0] ? w[i].cpu_ms : cpu_ms[0];
        cpu_ms[1] += w[i].cpu_ms;
    }
    if (err == KDR_OK)
        err = w[0].err != KDR_OK ? w[0].err : atomic_load(&p.failed);
    for (int i = 0; i < threads; i++)
        free_scratch(&w[i]);
    free(w);
    free(th);
    free(p.queue);
    pthread_cond_destroy(&p.cond);
    pthread_mutex_destroy(&p.lock);
    *frags = p.frags;
    *nfrags = p.nfrags;
    return err;
}

void kd_frags_free(kd_frag **frags, size_t nfrags) {
    for (size_t i = 0; i < nfrags; i++) {
        if (frags[i]) {
            free(frags[i]->nodes);
            free(frags[i]->refs);
            free(frags[i]);
        }
    }
    free(frags);
}

/* ---- putting the pieces together ------------------------------------------------ */

typedef struct stitcher {
    kd_frag **frags;
    kd_node *nodes;
    size_t nn;
    uint32_t *refs;
    size_t nr;
    float isect, trav;
    double inv_root_area, sah;
    uint64_t leaves, empty, depth;
} stitcher;

/* Copies the subtree at f->nodes[i] (box at depth) depth-first, following
 * links into other fragments; the statistics add up in the same order as
 * the single-threaded recursion visits nodes. */
static void walk(stitcher *st, const kd_frag *f, size_t i, kdr_bounds box,
                 int depth) {
    const kd_node *n = &f->nodes[i];
    if (kd_is_leaf(n) && n->u.first == KD_LINK) {
        walk(st, st->frags[kd_count(n)], 0, box, depth);
        return;
    }
    kd_node *o = &st->nodes[st->nn++];
    if (kd_is_leaf(n)) {
        const uint32_t count = kd_count(n);
        o->u.first = (uint32_t)st->nr;
        o->bits = n->bits;
        if (count) /* an empty fragment's refs may be NULL */
            memcpy(st->refs + st->nr, f->refs + n->u.first, count * sizeof *st->refs);
        st->nr += count;
        st->leaves++;
        st->empty += count == 0;
        if ((uint64_t)depth > st->depth)
            st->depth = (uint64_t)depth;
        st->sah += st->isect * (double)count * box_area(&box) * st->inv_root_area;
        return;
    }
    const int k = kd_axis(n);
    const size_t at = (size_t)(o - st->nodes);
    o->u.split = n->u.split;
    st->sah += st->trav * box_area(&box) * st->inv_root_area;
    kdr_bounds lb = box, rb = box;
    lb.max[k] = rb.min[k] = n->u.split;
    walk(st, f, i + 1, lb, depth + 1);
    st->nodes[at].bits = ((uint32_t)st->nn << 2) | (uint32_t)k;
    walk(st, f, kd_build_above(n), rb, depth + 1);
}

int kd_stitch(kd_frag **frags, size_t nfrags, const kdr_build_opts *o,
              kdr_scene *s) {
    size_t nn = 0, nr = 0;
    for (size_t i = 0; i < nfrags; i++) {
        nn += frags[i]->nnodes - frags[i]->links;
        nr += frags[i]->nrefs;
    }
    if (nn > KD_MAX_NODES || nr > UINT32_MAX)
        return KDR_ERANGE;
    stitcher st;
    memset(&st, 0, sizeof st);
    st.frags = frags;
    st.nodes = kd_mem_alloc(nn * sizeof *st.nodes);
    st.refs = kd_mem_alloc(nr * sizeof *st.refs);
    if (!st.nodes || !st.refs) {
        kd_mem_free(st.nodes);
        kd_mem_free(st.refs);
        return KDR_ENOMEM;
    }
    const double area = box_area(&s->bounds);
    st.inv_root_area = area > 0.0 ? 1.0 / area : 0.0;
    st.isect = o->isect_cost;
    st.trav = o->trav_cost;
    walk(&st, frags[0], 0, s->bounds, 0);
    s->nodes = st.nodes;
    s->nnodes = st.nn;
    s->refs = st.refs;
    s->nrefs = st.nr;
    s->stats.nodes = st.nn;
    s->stats.leaves = st.leaves;
    s->stats.empty_leaves = st.empty;
    s->stats.max_depth = st.depth;
    s->stats.refs = st.nr;
    s->stats.refs_per_leaf =
        st.leaves > st.empty ? (double)st.nr / (double)(st.leaves - st.empty) : 0.0;
    s->stats.sah_cost = st.sah;
    return KDR_OK;
}
