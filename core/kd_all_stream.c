/*
 * kd_all_stream.c — all hits and counts of a batch's rays, interleaved:
 * KD_ALL_RAYS rays in flight in one thread, each with its own stack,
 * interval and sink (kd_all.h), advanced in turn by ONE node step or one
 * leaf test; a ray requests (prefetches) the node it visits next and
 * yields, so when its turn comes again the node is in the cache and the
 * chain of dependent node loads that bounds the one-ray walk (kd_all.c)
 * overlaps with the other rays' work. On large scenes (KD_STREAM_STAGE_MIN_
 * BYTES, as for closest hits), or when the caller asks (KD_ALL_STAGE:
 * kd_all.c does from KD_ALL_STAGE_MIN_BYTES), a ray reaching a leaf
 * requests its reference list, on its next turn its triangles, and tests
 * them on the turn after.
 * A finished ray writes its answer and its slot takes the batch's next ray.
 *
 * Exact: per ray this is kd_all.c's walk() step for step: the same set-up
 * (all_setup), the same node rule (written without branches, as the
 * closest-hit stream of kd_traverse_stream.c writes it: the same float
 * operations, so the same intervals and children), the same leaf test
 * (test_leaf) into the same kind of sink over the same [tmin, bound], the
 * same pop against kd_term_bound(bound). Only the order in which DIFFERENT
 * rays advance changes, and they share nothing but the read-only scene, so
 * every list, count and the work sums equal kdr_intersect_all1's /
 * kdr_count1's bit for bit (tests/test_all_stream.c checks it ray by ray).
 */
#include "kd_all.h"
#include "kd_stream.h" /* kd_cpu_has_avx512 */
#include "kd_tune.h"

/* One ray in flight. Slots never move (a count's sink points into its
 * slot's own local buffer); a list of live slot numbers is what shrinks. */
typedef struct ka_ray {
    const kd_node *n; /* the node of its next turn, already requested */
    float tn, tf;
    int sp;
    int pend; /* n is a leaf whose references (1) or triangles (2) were
               * requested on the last turn */
    float tmin;
    float org[3], inv[3], ss[3];
    uint32_t neg[3]; /* signbit(inv[k]): the near child is above */
    size_t id;
    kd_ray_pre pre;
    kd_ntri_pre4 pre4;
    all_sink s;
    uint32_t mb[KD_ALL_MBOX_SLOTS]; /* its mailbox, when c->mbox */
    uint32_t local[KD_COUNT_STACK];
    kd_todo stack[KD_MAX_DEPTH];
} ka_ray;

typedef struct ka_src {
    const kdr_scene *sc;
    const kdr_ray_batch *b;
    uint32_t max_hits; /* 0: counts */
    kdr_hit *buf;
    kdr_all_hits *out;
    uint32_t *counts;
    kdr_trav_stats *stats;
    int stage, avx2, mbox, rc;
} ka_src;

/* Writes slot k's answer and its stats. */
static void ka_finish(ka_src *c, ka_ray *r) {
    all_answer(&r->s, r->id, c->max_hits, c->out, c->counts, c->stats, &c->rc);
}

/* Takes ray id into slot k; returns 0 (answer written) when the ray cannot
 * be traced or misses the root box, as walk() answers it. */
static int ka_start(ka_src *c, ka_ray *r, int k, size_t id) {
    kdr_ray ray;
    all_batch_ray(c->b, id, &ray);
    r->id = id;
    if (c->max_hits)
        r->s = (all_sink){.hits = c->buf + (size_t)k * c->max_hits,
                          .cap = c->max_hits,
                          .bound = ray.tmax};
    else
        r->s = (all_sink){.prims = r->local, .pcap = KD_COUNT_STACK, .bound = ray.tmax};
    if (c->mbox) all_mbox_start(&r->s, r->mb);
    if (!all_setup(c->sc, &ray, r->inv, r->ss, &r->tn, &r->tf, &r->pre, &r->pre4)) {
        ka_finish(c, r);
        return 0;
    }
    for (int a = 0; a < 3; a++) {
        r->org[a] = ray.org[a];
        r->neg[a] = signbit(r->inv[a]) ? 1u : 0u;
    }
    r->tmin = ray.tmin;
    r->sp = 0;
    r->pend = 0;
    r->n = c->sc->nodes;
    __builtin_prefetch(r->n);
    return 1;
}

/* One turn of ray r: a node step, or (a stage of) a leaf and the pop after
 * it. Returns 1 while the ray goes on, 0 when it is done. */
static inline int ka_turn(const ka_src *c, ka_ray *r) {
    const kdr_scene *sc = c->sc;
    const kd_node *nodes = sc->nodes, *n = r->n;
    if (!kd_is_leaf(n)) {
        /* walk()'s node step, one node per turn, without its branches */
        r->s.nodes++;
        const kd_node *next = kd_step_nobranch(nodes, n, r->org, r->inv, r->ss, r->neg,
                                               &r->tn, &r->tf, r->stack, &r->sp);
        if (next) {
            __builtin_prefetch(next);
            r->n = next;
            return 1;
        }
    } else if (c->stage && r->pend < 2) {
        if (r->pend++ == 0)
            kd_prefetch_refs(sc, n);
        else
            kd_prefetch_tris(sc, sc->refs + n->u.first, kd_count(n));
        return 1;
    } else {
        r->pend = 0;
        r->s.nodes++;
        test_leaf(sc, n, &r->pre, &r->pre4, c->avx2, r->tmin, &r->s,
                  sc->prefetch_leaves && !c->stage);
        if (r->s.oom) return 0;
    }
    /* walk()'s pop */
    const float bound = kd_term_bound(r->s.bound);
    do {
        if (r->sp == 0) return 0;
        --r->sp;
    } while (!(r->stack[r->sp].tn <= bound));
    r->n = r->stack[r->sp].node;
    r->tn = r->stack[r->sp].tn;
    r->tf = r->stack[r->sp].tf;
    __builtin_prefetch(r->n);
    return 1;
}

int kd_all_stream(const kdr_scene *sc, const kdr_ray_batch *b, size_t first,
                  size_t count, uint32_t max_hits, kdr_hit *buf, kdr_all_hits *out,
                  uint32_t *counts, int flags, kdr_trav_stats *stats) {
    if (!(flags & KD_ALL_SCALAR) && kd_cpu_has_avx512())
        return kd_all_lanes16(sc, b, first, count, max_hits, buf, out, counts,
                              flags & (KD_ALL_STAGE | KD_ALL_MBOX), stats);
    ka_ray slot[KD_ALL_RAYS];
    int live_slot[KD_ALL_RAYS];
    ka_src c = {sc,
                b,
                max_hits,
                buf,
                out,
                counts,
                stats,
                (flags & KD_ALL_STAGE) || sc->stats.bytes >= KD_STREAM_STAGE_MIN_BYTES,
                __builtin_cpu_supports("avx2") ? 1 : 0,
                (flags & KD_ALL_MBOX) || all_use_mbox(sc, max_hits > 0),
                KDR_OK};
    size_t next = first;
    const size_t end = first + count;
    int live = 0;
    /* live_slot[0, live) are the slots holding rays in flight */
    for (int k = 0; k < KD_ALL_RAYS && next < end; k++) {
        while (next < end && !ka_start(&c, &slot[k], k, next))
            next++;
        if (next == end) break;
        next++;
        live_slot[live++] = k;
    }
    while (live > 0) {
        for (int j = 0; j < live; j++) {
            ka_ray *r = &slot[live_slot[j]];
            if (ka_turn(&c, r)) continue;
            ka_finish(&c, r);
            /* refill the slot from the batch, or drop it from the list */
            int filled = 0;
            while (!filled && next < end)
                filled = ka_start(&c, r, live_slot[j], next++);
            if (!filled) live_slot[j--] = live_slot[--live];
        }
    }
    return c.rc;
}
