/*
 * kd_all_lanes.c — the interleaved walk of all hits and counts with its
 * node steps in the 16 lanes of AVX-512 registers (kd_all_lanes16): 16
 * rays of a batch, each in its own lane at its own node with its own stack,
 * interval and sink (kd_all.h), never waiting for each other. One turn
 * advances every lane: the lanes at interior nodes take the node step as
 * mask operations (the closest-hit walk's lanes, kd_traverse_stream_lanes.h,
 * without its best-t), the lanes at leaves test them one by one with
 * kd_all.h's test_leaf, and lanes after a leaf or with no child to enter
 * pop their stack; a finished lane writes its answer and takes the batch's
 * next ray. kd_all_stream.c's scalar form spent about half its time in its
 * per-ray node step (docs/TRAVERSAL.md, "All hits and counts"); here one
 * vector step serves 16 rays.
 *
 * Exact: per lane it is kd_all.c's walk() step for step: the same set-up
 * (all_setup), the same float operations of the node step in its order
 * (a = split - org, t_lo = (a - ss) * inv, t_hi = (a + ss) * inv; max and
 * min with the scalar ternaries' operand order), the same leaves in the
 * same order into the same sink over the same [tmin, bound], the same pop
 * against kd_term_bound(bound); nodes are counted once per interior step
 * and once per leaf as walk() counts them. So every list, count and work
 * sum equals kdr_intersect_all1's / kdr_count1's bit for bit
 * (tests/test_all_stream.c). Run only after kd_cpu_has_avx512() said yes.
 */
#include "kd_all.h"
#include "kd_stream.h"
#include "simd.h"

#define KL_W 16
#define KL_ALL 0xFFFFu
/* lane j's list is buf + j * max_hits: the caller's scratch holds
 * KD_ALL_RAYS lists */
_Static_assert(KL_W <= KD_ALL_RAYS, "kd_all_lanes16 needs KD_ALL_RAYS lists of scratch");

/* What the scalar parts (leaf tests, answers) keep per lane. */
typedef struct kl_lane {
    size_t id;
    float tmin;
    kd_ray_pre pre;
    kd_ntri_pre4 pre4;
    all_sink s;
    uint32_t mb[KD_ALL_MBOX_SLOTS];  /* its mailbox, when c->mbox */
    uint32_t local[KD_COUNT_STACK]; /* a count's first prims */
} kl_lane;

/* The lanes: vectors, and stacks of {node, tn, tf} in lane columns
 * (entry d of lane j is [d][j]). */
typedef struct kl_lanes {
    i16 node, sp, visits;
    f16 tn, tf, org[3], inv[3], ss[3];
    unsigned act;  /* lanes holding a ray */
    unsigned refs; /* lanes whose leaf's references were requested last turn */
    unsigned tris; /* lanes whose leaf's triangles were requested last turn */
    _Alignas(64) int32_t stk_node[KD_MAX_DEPTH][KL_W];
    _Alignas(64) float stk_tn[KD_MAX_DEPTH][KL_W];
    _Alignas(64) float stk_tf[KD_MAX_DEPTH][KL_W];
    kl_lane lane[KL_W];
} kl_lanes;

typedef struct kl_src {
    const kdr_scene *sc;
    const kdr_ray_batch *b;
    size_t next, end;
    uint32_t max_hits; /* 0: counts */
    kdr_hit *buf;
    kdr_all_hits *out;
    uint32_t *counts;
    kdr_trav_stats *stats;
    unsigned stage; /* every lane when leaves are staged */
    int avx2, mbox, rc;
} kl_src;

/* Writes lane l's answer and its stats. */
static void kl_finish(kl_src *c, kl_lane *l) {
    all_answer(&l->s, l->id, c->max_hits, c->out, c->counts, c->stats, &c->rc);
}

/* Puts the batch's next traceable ray into lane j (rays that cannot be
 * traced or miss the root box are answered on the way, as walk() answers
 * them); returns 0 when the batch is exhausted. */
KD_AVX512 __attribute__((noinline)) static int kl_fill(kl_src *c, kl_lanes *w, int j) {
    const unsigned bit = 1u << j;
    kl_lane *l = &w->lane[j];
    while (c->next < c->end) {
        kdr_ray ray;
        l->id = c->next++;
        all_batch_ray(c->b, l->id, &ray);
        if (c->max_hits)
            l->s = (all_sink){.hits = c->buf + (size_t)j * c->max_hits,
                              .cap = c->max_hits,
                              .bound = ray.tmax};
        else
            l->s = (all_sink){.prims = l->local, .pcap = KD_COUNT_STACK, .bound = ray.tmax};
        if (c->mbox) all_mbox_start(&l->s, l->mb);
        float inv[3], ss[3], tn, tf;
        if (!all_setup(c->sc, &ray, inv, ss, &tn, &tf, &l->pre, &l->pre4)) {
            kl_finish(c, l);
            continue;
        }
        l->tmin = ray.tmin;
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
        if (c->stage) __builtin_prefetch(c->sc->nodes);
        return 1;
    }
    return 0;
}

/* Lane j's pop (walk()'s): returns 0 when its stack holds nothing that
 * starts at or before kd_term_bound(bound), i.e. the ray is done. */
KD_AVX512 static inline int kl_pop(kl_lanes *w, int j, const int32_t *spv) {
    const unsigned bit = 1u << j;
    const int sp =
        kd_lane_pop_depth(&w->stk_tn[0][0], KL_W, j, spv[j], kd_term_bound(w->lane[j].s.bound));
    if (sp < 0) return 0;
    w->node = i16_put(w->node, bit, w->stk_node[sp][j]);
    w->tn = f16_put(w->tn, bit, w->stk_tn[sp][j]);
    w->tf = f16_put(w->tf, bit, w->stk_tf[sp][j]);
    w->sp = i16_put(w->sp, bit, sp);
    return 1;
}

/* The lanes' leaves and pops; finished lanes answer and refill. */
KD_AVX512 __attribute__((noinline)) static void kl_settle(kl_src *c, kl_lanes *w,
                                                          unsigned leaf, unsigned pop) {
    const kdr_scene *sc = c->sc;
    _Alignas(64) int32_t nv[KL_W], spv[KL_W], vis[KL_W];
    i16_store(nv, w->node);
    i16_store(spv, w->sp);
    unsigned done = 0;
    for (unsigned mm = leaf; mm; mm &= mm - 1) {
        const int j = __builtin_ctz(mm);
        kl_lane *l = &w->lane[j];
        test_leaf(sc, sc->nodes + nv[j], &l->pre, &l->pre4, c->avx2, l->tmin, &l->s,
                  sc->prefetch_leaves && !c->stage);
        if (l->s.oom)
            done |= 1u << j; /* walk() returns at once */
        else
            pop |= 1u << j;
    }
    for (unsigned mm = pop; mm; mm &= mm - 1) {
        const int j = __builtin_ctz(mm);
        if (!kl_pop(w, j, spv)) done |= 1u << j;
    }
    if (!done) return;
    i16_store(vis, w->visits);
    for (unsigned mm = done; mm; mm &= mm - 1) {
        const int j = __builtin_ctz(mm);
        w->lane[j].s.nodes = (uint64_t)vis[j];
        kl_finish(c, &w->lane[j]);
        if (!kl_fill(c, w, j)) w->act &= ~(1u << j);
    }
}

/* One turn: every active lane takes one step. */
KD_AVX512 static inline void kl_turn(kl_src *c, kl_lanes *w) {
    const kdr_scene *sc = c->sc;
    const i16 one = i16_set1(1), three = i16_set1(3);
    const unsigned act = w->act;
    const i16 node = w->node;
    const f16 tn = w->tn, tf = w->tf;
    /* the node: split (word 0) and bits (word 1) of kd_node[node] */
    const i16 bits = i16_gather8(three, act, node, (const int32_t *)sc->nodes + 1);
    const f16 split = f16_gather8(f16_set1(0.0f), act, node, sc->nodes);
    /* a leaf counts once, on the turn that reaches it */
    w->visits = i16_add_in(act & ~w->refs & ~w->tris, w->visits, one);
    const i16 axis = i16_and(bits, three);
    const unsigned at_leaf = i16_eq(act, axis, three);
    /* staged leaves: references requested on the turn that reaches the
     * leaf, triangles on the next, the test on the one after */
    const unsigned get_refs = at_leaf & ~w->refs & ~w->tris & c->stage;
    const unsigned get_tris = at_leaf & w->refs;
    const unsigned leaf = at_leaf & ~get_refs & ~get_tris;
    w->refs = get_refs;
    w->tris = get_tris;
    const unsigned inner = act & ~at_leaf;
    const unsigned ax1 = i16_eq(KL_ALL, axis, one), ax2 = i16_eq(KL_ALL, axis, i16_set1(2));
    const f16 o = f16_selm(ax2, w->org[2], f16_selm(ax1, w->org[1], w->org[0]));
    const f16 iv = f16_selm(ax2, w->inv[2], f16_selm(ax1, w->inv[1], w->inv[0]));
    const f16 ss = f16_selm(ax2, w->ss[2], f16_selm(ax1, w->ss[1], w->ss[0]));
    const f16 a = f16_sub(split, o);
    const f16 t_lo = f16_mul(f16_sub(a, ss), iv);
    const f16 t_hi = f16_mul(f16_add(a, ss), iv);
    const unsigned neg = f16_signs(iv); /* the near child is above */
    const i16 below = i16_add(node, one), above = i16_srl(bits, 4);
    const i16 nearc = i16_selm(neg, above, below), farc = i16_selm(neg, below, above);
    const unsigned below_empty = i16_test(bits, i16_set1(4));
    const unsigned above_empty = i16_test(bits, i16_set1(8));
    const unsigned near_empty = (neg & above_empty) | (~neg & below_empty);
    const unsigned far_empty = (neg & below_empty) | (~neg & above_empty);
    /* kd_step_nobranch's two flags: near unless t_hi < tn, far unless
     * t_lo > tf, minus an empty child */
    const unsigned go_near = f16_nlt(inner & ~near_empty, t_hi, tn);
    const unsigned go_far = f16_ngt(inner & ~far_empty, t_lo, tf);
    const unsigned push = go_near & go_far;
    /* walk()'s t_lo > tn ? t_lo : tn and t_hi < tf ? t_hi : tf */
    const f16 far_tn = f16_max(t_lo, tn), near_tf = f16_min(t_hi, tf);
    if (push) {
        const i16 slot = i16_add(i16_sll(w->sp, 4), i16_iota());
        i16_scatter(&w->stk_node[0][0], push, slot, farc);
        f16_scatter(&w->stk_tn[0][0], push, slot, far_tn);
        f16_scatter(&w->stk_tf[0][0], push, slot, tf);
        w->sp = i16_add_in(push, w->sp, one);
    }
    const unsigned moved = go_near | go_far;
    w->node = i16_selm(moved, i16_selm(go_near, nearc, farc), node);
    w->tn = f16_selm(go_far & ~go_near, far_tn, tn);
    w->tf = f16_selm(go_near, near_tf, tf);
    if (c->stage) {
        _Alignas(64) int32_t nv[KL_W];
        i16_store(nv, w->node);
        for (unsigned mm = moved; mm; mm &= mm - 1)
            __builtin_prefetch(sc->nodes + nv[__builtin_ctz(mm)]);
        for (unsigned mm = get_refs; mm; mm &= mm - 1)
            kd_prefetch_refs(sc, sc->nodes + nv[__builtin_ctz(mm)]);
        for (unsigned mm = get_tris; mm; mm &= mm - 1) {
            const kd_node *n = sc->nodes + nv[__builtin_ctz(mm)];
            kd_prefetch_tris(sc, sc->refs + n->u.first, kd_count(n));
        }
    }
    const unsigned pop = inner & ~moved;
    if (leaf | pop) kl_settle(c, w, leaf, pop);
}

KD_AVX512 int kd_all_lanes16(const kdr_scene *sc, const kdr_ray_batch *b, size_t first,
                             size_t count, uint32_t max_hits, kdr_hit *buf,
                             kdr_all_hits *out, uint32_t *counts, int flags,
                             kdr_trav_stats *stats) {
    const int stage = (flags & KD_ALL_STAGE) || sc->stats.bytes >= KD_STREAM_STAGE_MIN_BYTES;
    kl_src c = {sc,
                b,
                first,
                first + count,
                max_hits,
                buf,
                out,
                counts,
                stats,
                stage ? KL_ALL : 0u,
                __builtin_cpu_supports("avx2") ? 1 : 0,
                (flags & KD_ALL_MBOX) || all_use_mbox(sc, max_hits > 0),
                KDR_OK};
    kl_lanes w;
    w.node = w.sp = w.visits = i16_set1(0);
    w.tn = w.tf = f16_set1(0.0f);
    for (int k = 0; k < 3; k++)
        w.org[k] = w.inv[k] = w.ss[k] = f16_set1(0.0f);
    w.act = w.refs = w.tris = 0;
    for (int j = 0; j < KL_W; j++)
        if (kl_fill(&c, &w, j)) w.act |= 1u << j;
    while (w.act)
        kl_turn(&c, &w);
    return c.rc;
}
