/*
 * kd_traverse_stream.c — the interleaved walk of a batch's incoherent rays
 * without SIMD lanes (kd_traverse_stream16.c and kd_traverse_stream8.c are
 * the AVX-512 and AVX2 forms, with an _any.c each for any-hit rays; this
 * file also dispatches between the three: 16 lanes, else 8, else this one,
 * and between the lanes' two query kinds): KD_STREAM_RAYS rays are in flight in one
 * thread, each with its own stack, interval and best hit; in turn each
 * ray takes ONE node step or tests one leaf, requests (prefetches) the
 * node it visits next and yields to the next ray. When its turn comes
 * again its node is in the cache, so the chain of dependent node loads
 * that bounds the single walk overlaps with the other rays' work; and the
 * node step is written without branches (masks select near/far and the
 * stack push), which costs the single walk (the next address then waits
 * for the compare) but not an interleaved walk, where another ray's work
 * fills that wait, so the near/far mispredicts go too.
 *
 * Exact: per ray this is kd_traverse_single.c's walk operation for
 * operation (kd_walk.h holds the shared set-up and leaf test; ks_turn's
 * node step is descend()'s five cases as masks, its pop is walk()'s): the
 * same leaves in the same order with the same [tmin, best t], so the same
 * t, u, v and prim bit for bit. Only the order in which DIFFERENT rays
 * advance changes, and rays share nothing but the read-only scene.
 */
#include "kd_stream.h"

#include <string.h>

#include "kd_traverse_bundle.h"
#include "kd_walk.h"

/* One ray in flight. */
typedef struct ks_ray {
    const kd_node *n; /* the node of its next turn, already requested */
    float tn, tf;
    int sp;
    int pend; /* n is a leaf whose references (1) or triangles (2) were
               * requested last turn */
    float org[3], inv[3], ss[3];
    unsigned neg[3];
    float tmin;
    size_t id;
    kd_walk_out o;
    kd_ray_pre pre;
    kd_ntri_pre4 pre4;
    kd_todo stack[KD_MAX_DEPTH];
} ks_ray;

/* Takes ray `id` into slot r; returns 0 (result written) when the ray
 * cannot be traced or misses the root box, as kdr_intersect1 answers it. */
static int ks_start(const kdr_scene *s, const kdr_ray_batch *b, size_t id, ks_ray *r) {
    kdr_ray ray;
    kd_batch_read(b, id, &ray);
    r->id = id;
    r->o = (kd_walk_out){ray.tmax, 0.0f, 0.0f, -1, 0, 0};
    if (!kd_walk_setup(s, &ray, r->inv, r->ss, r->neg, &r->tn, &r->tf)) return 0;
    for (int k = 0; k < 3; k++)
        r->org[k] = ray.org[k];
    r->tmin = ray.tmin;
    kd_ray_precompute(ray.org, ray.dir, &r->pre);
    kd_ntri_pre_init4(&r->pre, &r->pre4);
    r->sp = 0;
    r->pend = 0;
    r->n = s->nodes;
    return 1;
}

/* Writes ray r's answer (found: a hit; any-hit: the flag) and its stats. */
static void ks_finish(const ks_ray *r, int found, kdr_query q, kdr_hits *out,
                      kdr_trav_stats *st) {
    const size_t i = r->id;
    if (st) {
        st->rays++;
        st->nodes_visited += r->o.nodes;
        st->tri_tests += r->o.tests;
    }
    if (q == KDR_ANY) {
        out->hit[i] = (uint8_t)found;
        return;
    }
    out->t[i] = found ? r->o.t : -1.0f;
    out->prim[i] = found ? r->o.prim : -1;
    out->u[i] = found ? r->o.u : 0.0f;
    out->v[i] = found ? r->o.v : 0.0f;
}

/* One turn of ray r: a node step, or a leaf and the pop after it (on
 * large scenes (stage != 0) a leaf's reference list is requested on the
 * turn that reaches it, its triangles on the next, the test on the one
 * after). Returns 1 while the ray goes
 * on; 0 when it is done, with *found its answer. */
static inline int ks_turn(const kdr_scene *s, ks_ray *r, const int any, const int avx2,
                          const int stage, int *found) {
    const kd_node *n = r->n;
    r->o.nodes += (uint64_t)(r->pend == 0);
    if (!kd_is_leaf(n)) {
        /* descend()'s step, one node per turn, without its branches */
        const kd_node *next = kd_step_nobranch(s->nodes, n, r->org, r->inv, r->ss,
                                               r->neg, &r->tn, &r->tf, r->stack, &r->sp);
        if (next) {
            __builtin_prefetch(next);
            r->n = next;
            return 1;
        }
    } else if (stage && r->pend < 2) {
        /* staged: the reference list, next turn the triangles, then the test */
        if (r->pend++ == 0)
            kd_prefetch_refs(s, n);
        else
            kd_prefetch_tris(s, s->refs + n->u.first, kd_count(n));
        return 1;
    } else if (r->pend = 0,
               kd_walk_leaf(s, n, &r->pre, &r->pre4, r->tmin, any, avx2, &r->o)) {
        *found = 1;
        return 0;
    }
    /* walk()'s pop */
    const float bound = kd_term_bound(r->o.t);
    do {
        if (r->sp == 0) {
            *found = r->o.prim >= 0;
            return 0;
        }
        --r->sp;
    } while (!(r->stack[r->sp].tn <= bound));
    r->n = r->stack[r->sp].node;
    r->tn = r->stack[r->sp].tn;
    r->tf = r->stack[r->sp].tf;
    __builtin_prefetch(r->n);
    return 1;
}

void kd_stream_scalar_trace(const kdr_scene *s, const kdr_ray_batch *b, const size_t *ids,
                            size_t first, size_t m, kdr_query q, int flags, kdr_hits *out,
                            kdr_trav_stats *stats) {
    ks_ray slot[KD_STREAM_RAYS];
    const int any = q == KDR_ANY;
    const int avx2 = kdr_cpu_has_avx2();
    const int stage =
        (flags & KD_STREAM_STAGE) || s->stats.bytes >= KD_STREAM_STAGE_MIN_BYTES;
    size_t next = 0;
    int live = 0;
    /* slots [0, live) hold rays in flight */
    while (live < KD_STREAM_RAYS && next < m) {
        if (ks_start(s, b, ids ? ids[next] : first + next, &slot[live]))
            __builtin_prefetch(slot[live++].n);
        else
            ks_finish(&slot[live], 0, q, out, stats);
        next++;
    }
    while (live > 0) {
        for (int k = 0; k < live; k++) {
            int found;
            if (ks_turn(s, &slot[k], any, avx2, stage, &found)) continue;
            ks_finish(&slot[k], found, q, out, stats);
            /* refill the slot from the batch, or close the gap */
            int filled = 0;
            while (!filled && next < m) {
                filled = ks_start(s, b, ids ? ids[next] : first + next, &slot[k]);
                next++;
                if (!filled) ks_finish(&slot[k], 0, q, out, stats);
            }
            if (filled)
                __builtin_prefetch(slot[k].n);
            else if (k < --live)
                slot[k--] = slot[live];
        }
    }
}

int kd_cpu_has_avx512(void) {
    return __builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512dq") &&
           __builtin_cpu_supports("avx512bw") && __builtin_cpu_supports("avx512vl");
}

void kd_stream_trace8(const kdr_scene *s, const kdr_ray_batch *b, const size_t *ids,
                      size_t first, size_t m, kdr_query q, int flags, kdr_hits *out,
                      kdr_trav_stats *stats) {
    if (q == KDR_ANY)
        kd_stream_any8(s, b, ids, first, m, flags, out, stats);
    else
        kd_stream_hit8(s, b, ids, first, m, flags, out, stats);
}

void kd_stream_trace16(const kdr_scene *s, const kdr_ray_batch *b, const size_t *ids,
                       size_t first, size_t m, kdr_query q, int flags, kdr_hits *out,
                       kdr_trav_stats *stats) {
    if (q == KDR_ANY)
        kd_stream_any16(s, b, ids, first, m, flags, out, stats);
    else
        kd_stream_hit16(s, b, ids, first, m, flags, out, stats);
}

static void stream_trace(const kdr_scene *s, const kdr_ray_batch *b, const size_t *ids,
                         size_t first, size_t m, kdr_query q, int flags, kdr_hits *out,
                         kdr_trav_stats *stats) {
    if (kd_cpu_has_avx512())
        kd_stream_trace16(s, b, ids, first, m, q, flags, out, stats);
    else if (kdr_cpu_has_avx2())
        kd_stream_trace8(s, b, ids, first, m, q, flags, out, stats);
    else
        kd_stream_scalar_trace(s, b, ids, first, m, q, 0, out, stats);
}

void kd_stream_trace(const kdr_scene *s, const kdr_ray_batch *b, const size_t *ids,
                     size_t first, size_t m, kdr_query q, kdr_hits *out,
                     kdr_trav_stats *stats) {
    stream_trace(s, b, ids, first, m, q, 0, out, stats);
}

void kd_stream_trace_far(const kdr_scene *s, const kdr_ray_batch *b, const size_t *ids,
                         size_t first, size_t m, kdr_query q, int flags, kdr_hits *out,
                         kdr_trav_stats *stats) {
    stream_trace(s, b, ids, first, m, q, KD_STREAM_FAR | (flags & KD_STREAM_STAGE), out,
                 stats);
}
