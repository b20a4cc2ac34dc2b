/*
 * kd_traverse_stream16.c — the interleaved walk on AVX-512: 16 rays of a
 * batch in the 16 lanes of the registers, each lane ITS OWN ray at ITS OWN
 * node with its own stack and interval (not a bundle: lanes never wait for
 * each other). One turn of the loop advances every lane by one step:
 *
 *   gather   each lane's node (split and bits: two 16-way gathers);
 *   step     the lanes at interior nodes take kd_traverse_single.c's node
 *            step as mask operations (near/far, the empty-child flags, the
 *            far entry scattered to the lane's stack when both are taken);
 *   leaves   the lanes at leaves test their leaf one by one, with the
 *            single walk's leaf test (kd_walk_leaf: one ray against 1, 4
 *            or 8 triangles at a time);
 *   pops     lanes after a leaf or with no child to enter pop their stack
 *            (walk()'s pop: entries starting after kd_term_bound(best t)
 *            are dropped);
 *   refill   a finished lane writes its answer and takes the batch's next
 *            ray, so the lanes stay full until the batch runs dry.
 *
 * Exact: per lane every float operation is the single walk's, in its
 * order (a = split - org, t_lo = (a - ss) * inv, t_hi = (a + ss) * inv,
 * max/min with the scalar ternaries' operand order, kd_term_bound's sum),
 * the same leaves are tested in the same order with the same [tmin, best
 * t], so t, u, v and prim are the single walk's bit for bit.
 *
 * On scenes of KD_STREAM_STAGE_MIN_BYTES and more (trees and triangles
 * that do not stay in the caches) a lane that reaches a leaf requests its
 * reference list, on its next turn the triangles, and tests them on the
 * turn after; and every lane's next node is requested as soon as it is
 * known.
 */
#include "kd_stream.h"
#include "kd_traverse_bundle.h"
#include "kd_walk.h"

/* Per-lane data the scalar parts use (leaf tests, answers). */
typedef struct ks_lane {
    size_t id;
    float tmin;
    kd_walk_out o;
    kd_ray_pre pre;
    kd_ntri_pre4 pre4;
} ks_lane;

/* The lanes' state: in registers (the vectors) and in memory (stacks of
 * {node, tn, tf} in lane columns: entry d of lane j is [d][j]). */
typedef struct ks16 {
    i16 node, sp, visits;
    f16 tn, tf, org[3], inv[3], ss[3];
    m16 act;  /* lanes holding a ray */
    m16 refs; /* lanes whose leaf's reference list was requested last turn */
    m16 tris; /* lanes whose leaf's triangles were requested last turn */
    _Alignas(64) int32_t stk_node[KD_MAX_DEPTH][16];
    _Alignas(64) float stk_tn[KD_MAX_DEPTH][16];
    _Alignas(64) float stk_tf[KD_MAX_DEPTH][16];
    ks_lane lane[16];
} ks16;

/* The batch being traced. */
typedef struct ks_src {
    const kdr_scene *s;
    const kdr_ray_batch *b;
    const size_t *ids; /* NULL: rays first, first + 1, ... */
    size_t first, m, next;
    kdr_query q;
    kdr_hits *out;
    kdr_trav_stats *stats;
    m16 stage; /* all lanes when leaves are staged (large scenes) */
} ks_src;

/* Writes lane l's answer and adds its stats. */
static void ks16_finish(const ks_lane *l, int found, const ks_src *c) {
    const size_t i = l->id;
    if (c->stats) {
        c->stats->rays++;
        c->stats->nodes_visited += l->o.nodes;
        c->stats->tri_tests += l->o.tests;
    }
    if (c->q == KDR_ANY) {
        c->out->hit[i] = (uint8_t)found;
        return;
    }
    c->out->t[i] = found ? l->o.t : -1.0f;
    c->out->prim[i] = found ? l->o.prim : -1;
    c->out->u[i] = found ? l->o.u : 0.0f;
    c->out->v[i] = found ? l->o.v : 0.0f;
}

/* Puts the batch's next traceable ray into lane j (rays that cannot be
 * traced or miss the root box are answered on the way, as kdr_intersect1
 * answers them); returns 0 when the batch is exhausted. */
KD_AVX512 __attribute__((noinline)) static int ks16_fill(ks_src *c, ks16 *w, int j) {
    const m16 bit = (m16)(1u << j);
    ks_lane *l = &w->lane[j];
    while (c->next < c->m) {
        kdr_ray ray;
        l->id = c->ids ? c->ids[c->next] : c->first + c->next;
        c->next++;
        kd_batch_read(c->b, l->id, &ray);
        l->o = (kd_walk_out){ray.tmax, 0.0f, 0.0f, -1, 0, 0};
        float inv[3], ss[3], tn, tf;
        unsigned neg[3];
        if (!kd_walk_setup(c->s, &ray, inv, ss, neg, &tn, &tf)) {
            ks16_finish(l, 0, c);
            continue;
        }
        l->tmin = ray.tmin;
        kd_ray_precompute(ray.org, ray.dir, &l->pre);
        kd_ntri_pre_init4(&l->pre, &l->pre4);
        w->node = i16_put(w->node, bit, 0);
        w->sp = i16_put(w->sp, bit, 0);
        w->visits = i16_put(w->visits, bit, 0);
        w->tn = f16_put(w->tn, bit, tn);
        w->tf = f16_put(w->tf, bit, tf);
        for (int k = 0; k < 3; k++) {
            w->org[k] = f16_put(w->org[k], bit, ray.org[k]);
            w->inv[k] = f16_put(w->inv[k], bit, inv[k]);
            w->ss[k] = f16_put(w->ss[k], bit, ss[k]);
        }
        return 1;
    }
    return 0;
}

/* Lane j's pop (walk()'s): returns 0 when its stack holds nothing that
 * starts at or before kd_term_bound(best t), i.e. the ray is done. */
KD_AVX512 static inline int ks16_pop(ks16 *w, int j, const int32_t *spv) {
    const m16 bit = (m16)(1u << j);
    const float bound = kd_term_bound(w->lane[j].o.t);
    int sp = spv[j];
    do {
        if (sp == 0) return 0;
        --sp;
    } while (!(w->stk_tn[sp][j] <= bound));
    w->node = i16_put(w->node, bit, w->stk_node[sp][j]);
    w->tn = f16_put(w->tn, bit, w->stk_tn[sp][j]);
    w->tf = f16_put(w->tf, bit, w->stk_tf[sp][j]);
    w->sp = i16_put(w->sp, bit, sp);
    return 1;
}

/* The lanes' leaves and pops; finished lanes answer and refill. */
KD_AVX512 static inline void ks16_settle(ks_src *c, ks16 *w, m16 leaf, m16 pop) {
    const kdr_scene *s = c->s;
    _Alignas(64) int32_t nv[16], spv[16], vis[16];
    i16_store(nv, w->node);
    i16_store(spv, w->sp);
    m16 done = 0, found = 0;
    for (unsigned mm = leaf; mm; mm &= mm - 1) {
        const int j = __builtin_ctz(mm);
        ks_lane *l = &w->lane[j];
        if (kd_walk_leaf(s, s->nodes + nv[j], &l->pre, &l->pre4, l->tmin, c->q == KDR_ANY,
                         1, &l->o)) {
            done |= (m16)(1u << j);
            found |= (m16)(1u << j);
        } else {
            pop |= (m16)(1u << j);
        }
    }
    for (unsigned mm = pop; mm; mm &= mm - 1) {
        const int j = __builtin_ctz(mm);
        if (!ks16_pop(w, j, spv)) {
            done |= (m16)(1u << j);
            found |= (m16)((w->lane[j].o.prim >= 0) << j);
        }
    }
    if (!done) return;
    i16_store(vis, w->visits);
    for (unsigned mm = done; mm; mm &= mm - 1) {
        const int j = __builtin_ctz(mm);
        w->lane[j].o.nodes = (uint64_t)vis[j];
        ks16_finish(&w->lane[j], (found >> j) & 1, c);
        if (!ks16_fill(c, w, j)) w->act &= (m16) ~(1u << j);
    }
}

/* One turn: every active lane takes one step. */
KD_AVX512 static inline void ks16_turn(ks_src *c, ks16 *w) {
    const kdr_scene *s = c->s;
    const i16 one = i16_set1(1), three = i16_set1(3);
    const m16 act = w->act;
    const i16 node = w->node;
    const f16 tn = w->tn, tf = w->tf;
    /* the node: split (word 0) and bits (word 1) of kd_node[node] */
    const i16 bits = i16_gather8(three, act, node, (const int32_t *)s->nodes + 1);
    const f16 split = f16_gather8(f16_set1(0.0f), act, node, s->nodes);
    w->visits = i16_add_in(act & ~w->refs & ~w->tris, w->visits, one);
    const i16 axis = i16_and(bits, three);
    const m16 at_leaf = i16_eq(act, axis, three);
    /* staged leaves: references requested on the turn that reaches the
     * leaf, triangles on the next (the references are then in the cache,
     * so the requests cost no miss), the test on the one after */
    const m16 get_refs = at_leaf & ~w->refs & ~w->tris & c->stage;
    const m16 get_tris = at_leaf & w->refs;
    const m16 leaf = at_leaf & ~get_refs & ~get_tris;
    w->refs = get_refs;
    w->tris = get_tris;
    const m16 inner = act & ~at_leaf;
    /* descend()'s step, lane by lane as masks */
    const m16 ax1 = i16_eq(0xFFFF, axis, one), ax2 = i16_eq(0xFFFF, axis, i16_set1(2));
    const f16 o = f16_sel(ax2, w->org[2], f16_sel(ax1, w->org[1], w->org[0]));
    const f16 iv = f16_sel(ax2, w->inv[2], f16_sel(ax1, w->inv[1], w->inv[0]));
    const f16 ss = f16_sel(ax2, w->ss[2], f16_sel(ax1, w->ss[1], w->ss[0]));
    const f16 a = f16_sub(split, o);
    const f16 t_lo = f16_mul(f16_sub(a, ss), iv);
    const f16 t_hi = f16_mul(f16_add(a, ss), iv);
    const m16 neg = f16_signs(iv); /* the near child is above */
    const i16 below = i16_add(node, one), above = i16_srl(bits, 4);
    const i16 nearc = i16_sel(neg, above, below), farc = i16_sel(neg, below, above);
    const m16 below_empty = i16_test(bits, i16_set1(4));
    const m16 above_empty = i16_test(bits, i16_set1(8));
    const m16 near_empty = (neg & above_empty) | (~neg & below_empty);
    const m16 far_empty = (neg & below_empty) | (~neg & above_empty);
    /* kd_traverse_stream.c's branch-free form of the five cases */
    const m16 go_near = f16_nlt(inner & ~near_empty, t_hi, tn);
    const m16 go_far = f16_ngt(inner & ~far_empty, t_lo, tf);
    const m16 push = go_near & go_far;
    const f16 far_tn = f16_max(t_lo, tn), near_tf = f16_min(t_hi, tf);
    if (push) {
        const i16 slot = i16_add(i16_sll(w->sp, 4), i16_iota());
        i16_scatter(&w->stk_node[0][0], push, slot, farc);
        f16_scatter(&w->stk_tn[0][0], push, slot, far_tn);
        f16_scatter(&w->stk_tf[0][0], push, slot, tf);
        w->sp = i16_add_in(push, w->sp, one);
    }
    const m16 moved = go_near | go_far;
    w->node = i16_sel(moved, i16_sel(go_near, nearc, farc), node);
    w->tn = f16_sel(go_far & ~go_near, far_tn, tn);
    w->tf = f16_sel(go_near, near_tf, tf);
    if (c->stage) {
        _Alignas(64) int32_t nv[16];
        i16_store(nv, w->node);
        for (unsigned mm = moved; mm; mm &= mm - 1)
            __builtin_prefetch(s->nodes + nv[__builtin_ctz(mm)]);
        for (unsigned mm = get_refs; mm; mm &= mm - 1) {
            const kd_node *n = s->nodes + nv[__builtin_ctz(mm)];
            kd_prefetch_refs(s, n);
        }
        for (unsigned mm = get_tris; mm; mm &= mm - 1) {
            const kd_node *n = s->nodes + nv[__builtin_ctz(mm)];
            kd_prefetch_tris(s, s->refs + n->u.first, kd_count(n));
        }
    }
    const m16 pop = inner & ~moved;
    if (leaf | pop) ks16_settle(c, w, leaf, pop);
}

KD_AVX512 void kd_stream16_trace(const kdr_scene *s, const kdr_ray_batch *b,
                                 const size_t *ids, size_t first, size_t m, kdr_query q,
                                 int flags, kdr_hits *out, kdr_trav_stats *stats) {
    const int stage =
        (flags & KD_STREAM_STAGE) || s->stats.bytes >= KD_STREAM_STAGE_MIN_BYTES;
    ks_src c = {s, b, ids, first, m, 0, q, out, stats, stage ? (m16)0xFFFF : 0};
    ks16 w;
    w.node = w.sp = w.visits = i16_set1(0);
    w.tn = w.tf = f16_set1(0.0f);
    for (int k = 0; k < 3; k++)
        w.org[k] = w.inv[k] = w.ss[k] = f16_set1(0.0f);
    w.act = w.refs = w.tris = 0;
    for (int j = 0; j < 16; j++)
        if (ks16_fill(&c, &w, j)) w.act |= (m16)(1u << j);
    while (w.act)
        ks16_turn(&c, &w);
}
