/*
 * kd_traverse_bundle.h — omni-directional ray bundle traversal (technique 1
 * of Tsakok, Bishop and Kennings), written once for any lane count.
 *
 * The first part declares the per-width entry points that kd_batch.c
 * dispatches to. The second part is a template (the convention of
 * simd_width.h) for one bundle's trip through the tree (its lanes' state,
 * root clipping, the node steps, the leaf test); the batch driver that
 * fills bundles from a ray batch, stores their answers and falls back to
 * the interleaved walk on incoherent rays is kd_traverse_bundle_run.h.
 * kd_traverse_bundle4.c, kd_traverse_bundle8.c and kd_traverse_bundle16.c
 * define KD_W, include simd_width.h, then this file once more and
 * kd_traverse_bundle_run.h to instantiate each (kb_run4, kb_run8, ...).
 *
 * The paper's two changes to packet traversal are what let rays of any
 * direction signs share a bundle:
 *  1. each lane visits the child on its ORIGIN's side of the split plane
 *     first (front) and the other second (back), whatever its direction;
 *  2. a negative plane distance (the ray moves away from the plane; -0.0
 *     from an underflow counts as negative) becomes +infinity for the
 *     front child, which then keeps the whole interval.
 * The crossing distances t_lo/t_hi = (split - org -/+ signed slack) * inv_dir
 * are those of kd_traverse.h, so every lane sees exactly the child
 * intervals of the single-ray walk (front [t_near, min(t_hi, t_far)], back
 * [max(t_lo, t_near), t_far]; moving away, the front keeps [t_near, t_far]
 * and the back only reaches t_hi): same leaves, same triangle tests, same
 * answer. See kb_spans for the rule in one place.
 * A lane whose origin is ON the plane (split - org == 0) has no side of its
 * own: its front is the child its direction leaves (the single walk's near
 * child). A lane lying in the plane (direction component +-0) gets
 * infinite or NaN crossings, and the min/max operand order (NaN yields the
 * second operand) gives it both children over its whole interval.
 *
 * Origins: lanes may have different origins. When every lane has the same
 * origin (a camera, hemisphere rays from a surface point) and it is off the
 * plane, one scalar distance decides front and back for the whole bundle:
 * the paper's listing (kb_step_shared). Otherwise every lane computes its
 * below/above intervals from its own origin side, so each lane's intervals
 * stay exact; the bundle enters first the child that is front for most
 * active lanes and stacks the other (kb_step_general). Lanes whose origins
 * lie on different sides of a plane therefore never need a split bundle;
 * the minority lanes see their back child first, which costs pruning but
 * not correctness.
 *
 * Entry: bundles of one origin all descend the top of the tree along the
 * origin's path (kd_entry.h). Once a second bundle in a row has the origin,
 * the path is built and each bundle replays kb_step_shared along it
 * (kb_replay) to the point where the loop's walk leaves it, with the
 * loop's cursor, stack and counts there: same walk, fewer loads and
 * branches (docs/TRAVERSAL.md, "Bundles from the origin's path").
 *
 * Lanes are active while t_near <= t_far and t_near <= kd_term_bound(best_t)
 * (any-hit lanes leave once they hit); a bundle pops when no lane is active.
 * Rays a bundle cannot take (NaN/inf input, zero direction, a subnormal
 * direction component, tmin < 0 where "negative means behind" breaks,
 * tmax < tmin) are traced alone.
 */
#ifndef KD_TRAVERSE_BUNDLE_DECL
#define KD_TRAVERSE_BUNDLE_DECL

#include "kd_internal.h"
#include "kd_stream.h"
#include "kd_traverse.h"

/* Batch drivers: same contract as kdr_trace_batch (arguments checked by the
 * caller); flags are KB_FALLBACK | KB_SORT | KB_LIVE | KB_FAR_AUTO below. With flags == 0
 * every bundle is traced as a bundle in the caller's ray order (tests use this to
 * put every adversarial ray through the SIMD path). kd_bundle8_trace needs
 * AVX2. */
void kd_bundle4_trace(const kdr_scene *s, const kdr_ray_batch *b, size_t first,
                      size_t count, kdr_query q, int flags, kdr_hits *out,
                      kdr_trav_stats *stats);
void kd_bundle8_trace(const kdr_scene *s, const kdr_ray_batch *b, size_t first,
                      size_t count, kdr_query q, int flags, kdr_hits *out,
                      kdr_trav_stats *stats);
/* The 16-lane instance (kd_traverse_bundle16.c); needs AVX-512
 * (kd_cpu_has_avx512). */
void kd_bundle16_trace(const kdr_scene *s, const kdr_ray_batch *b, size_t first,
                       size_t count, kdr_query q, int flags, kdr_hits *out,
                       kdr_trav_stats *stats);

/* The batch driver of the widest bundles the CPU runs up to max_width
 * lanes (16 with AVX-512, 8 with AVX2, else 4), with the caller's flags
 * (kd_batch.c); a scene without a tree traces each ray alone. */
void kd_batch_bundles(const kdr_scene *s, const kdr_ray_batch *b, size_t first,
                      size_t count, kdr_query q, int flags, int max_width,
                      kdr_hits *out, kdr_trav_stats *stats);

/* Ray i of the batch, stride-0 fields shared; absent tmin/tmax mean 0 /
 * +inf (kd_batch.c). */
void kd_batch_read(const kdr_ray_batch *b, size_t i, kdr_ray *r);

/* Traces ray i alone and writes its result (kd_batch.c). */
void kd_batch_single(const kdr_scene *s, const kdr_ray_batch *b, size_t i,
                     kdr_query q, kdr_hits *out, kdr_trav_stats *stats);

/* 1 when rays [first, first+count) have their own origins (stride 3) and
 * incoherent directions (mean spread per 8 rays over KB_SORT_SPREAD), and
 * either their origins change at least every KD_STREAM_MAX_RUN rays on
 * average (no bundle would hold its lanes) or the scene takes at least
 * KD_STREAM_RUNS_MIN_BYTES and the chunk holds more than one origin (runs
 * of a shared origin, AO rays of many points: there the interleaved walk's
 * hidden memory latency beats the bundles' shared descent; one origin in
 * the whole chunk, a cone's samples of one point, stays with bundles). The
 * drivers send such chunks straight to the interleaved walk (kd_batch.c). */
int kd_batch_scattered(const kdr_scene *s, const kdr_ray_batch *b, size_t first,
                       size_t count);

/* Answers the rays of [first, first+count) that kd_walk_setup rejects
 * before its root clip (tmin > tmax, NaN or inf input, zero direction) as
 * kdr_intersect1 / kdr_occluded1 answer them (a miss; stats: a ray with no
 * node), and lists the others in ids, in order; returns how many it listed
 * (kd_batch.c). Rays that only miss the scene's box stay listed: telling
 * them costs a division per ray, paid again by every live ray. */
size_t kd_batch_live(const kdr_ray_batch *b, size_t first, size_t count, kdr_query q,
                     kdr_hits *out, kdr_trav_stats *stats, size_t *ids);

/* Orders rays ids[0..count) (count <= KB_CHUNK) in place for bundling:
 * when consecutive rays are incoherent (mean direction spread per 8 rays
 * over KB_SORT_SPREAD) and sort != 0, by direction octant, then by a
 * coarse Morton code of the direction, stable, never across a run of
 * equal origins (kd_batch.c); else unchanged. */
void kd_batch_order(const kdr_ray_batch *b, size_t count, int sort, size_t *ids);

/* 1 when no run of equal origins (bitwise) among rays ids[0..count)
 * crosses a multiple of w: every bundle of w consecutive rays then holds
 * whole runs (16 shadow rays of one point, 16 AO rays of one point, rays
 * with their own origins), so kd_batch_order, which moves rays only within
 * their run, would permute lanes inside bundles and change nothing else
 * (kd_batch.c). 0 for a batch with one shared origin (org_stride 0). */
int kd_batch_runs_fit(const kdr_ray_batch *b, const size_t *ids, size_t count, size_t w);

/* Driver flags (the `flags` argument of kd_bundle*_trace). */
#define KB_FALLBACK 1 /* incoherent stretches go through kd_stream_trace */
#define KB_SORT 2     /* regroup each chunk of rays by direction */
#define KB_LIVE 4     /* answer rays that cannot hit first (kd_batch_live) */
#define KB_ROOT 8     /* every bundle walks from the root: no kb_replay (tests, A/B) */
#define KB_FAR_AUTO 16 /* any hit: chunks kd_batch_far_first picks walk far end first */
#define KB_FAR 32     /* any hit: every chunk walks far end first (tests, A/B) */

/* Where the ends o + tmax d of the rays ids[0..count) (ids NULL: [first,
 * first + count)) lie, sampled over 32 rays spread evenly over the list,
 * for the any-hit order (kd_batch.c):
 *   KB_ENDS_CLUSTER  own origins, every end finite, the ends' box narrower
 *                    than KD_FAR_END_SPREAD times the origins' box on its
 *                    widest axis (shadow rays of many points toward one
 *                    light: the walk from each end meets the blockers near
 *                    the light and shares its top path with the chunk's
 *                    other rays): far end first where the call's probe
 *                    measures it cheaper;
 *   KB_ENDS_SPREAD   own origins, every end finite, not clustered, and
 *                    every sampled ray no longer than KD_FAR_SPREAD_MAX_LEN
 *                    times the scene's diagonal (AO rays: short, ends
 *                    around their origins): far end first in the
 *                    interleaved walk, runs there from
 *                    KD_FAR_RUNS_MIN_BYTES, leaves staged from
 *                    KD_FAR_STAGE_MIN_BYTES;
 *   KB_ENDS_LONG     the same with some sampled ray longer (shadow rays
 *                    toward a large light): far end first in the
 *                    interleaved walk, its usual routes and staging;
 *   KB_ENDS_NONE     one origin (stride 0, or one over the sample: its
 *                    path replay stays), no tmax array or some end not
 *                    finite: front to back. */
#define KB_ENDS_NONE 0
#define KB_ENDS_CLUSTER 1
#define KB_ENDS_SPREAD 2
#define KB_ENDS_LONG 3
int kd_batch_far_first(const kdr_scene *s, const kdr_ray_batch *b, const size_t *ids,
                       size_t first, size_t count);

/* kd_batch_scattered for an any-hit call that offers the far order
 * (KB_FAR_AUTO): chunks whose ends spread (KB_ENDS_SPREAD) with runs of
 * shared origins go to the interleaved walk from scenes of
 * KD_FAR_RUNS_MIN_BYTES, where they walk far end first. */
int kd_batch_scattered_any(const kdr_scene *s, const kdr_ray_batch *b, size_t first,
                           size_t count);

/* Which order a batch call's clustered-end chunks take (kd_batch_far_first
 * says the ends cluster; whether the far end finds the blockers sooner
 * depends on where they are: shadow rays from points inside an object's
 * cavities meet its shell near the light, points a camera sees often have
 * their blocker near them). The driver measures: the first bundles (or
 * interleaved-walk runs) alternate the orders until each has traced
 * KD_FAR_PROBE_RAYS rays; then the call takes the far order while its
 * work per ray (node steps + triangle tests) is under KD_FAR_GAIN times
 * the front-to-back order's. work and rays per order: [0] front to back,
 * [1] far end first. */
typedef struct kd_far_probe {
    double work[2], rays[2];
} kd_far_probe;

/* 1: far end first for the next rays (the order still short of its probe,
 * far first; then the cheaper one by the rule above). */
static inline int kd_far_pick(const kd_far_probe *p) {
    if (p->rays[0] < KD_FAR_PROBE_RAYS || p->rays[1] < KD_FAR_PROBE_RAYS)
        return p->rays[1] <= p->rays[0];
    return p->work[1] * p->rays[0] < KD_FAR_GAIN * p->work[0] * p->rays[1];
}

/* 1 while some order is short of its probe. */
static inline int kd_far_probing(const kd_far_probe *p) {
    return p->rays[0] < KD_FAR_PROBE_RAYS || p->rays[1] < KD_FAR_PROBE_RAYS;
}

/* The order argument of the drivers' helpers: front to back, far end
 * first, or chosen by the call's kd_far_probe. */
#define KB_ORDER_NEAR 0
#define KB_ORDER_FAR 1
#define KB_ORDER_PROBE 2
/* far end first for rays whose ends spread (KB_ENDS_SPREAD: AO), only in
 * the interleaved walk, whose leaves are then staged from
 * KD_FAR_STAGE_MIN_BYTES */
#define KB_ORDER_FAR_SPREAD 3
/* The incoherence probe's knobs (KB_OCC_MIN, KB_PROBE, KB_FALLBACK_CHUNKS)
 * are in kd_tune.h with KB_CHUNK. */

#endif /* KD_TRAVERSE_BUNDLE_DECL */

#ifdef KD_W
#include <string.h>

#include "kd_entry.h"
#include "kd_tri_nray.h"

/* One bundle: the lanes' rays in SoA and their best hits. */
typedef struct KD_WN(kb_bundle) {
    _Alignas(KD_VALIGN) float org[3][KD_W], dir[3][KD_W], tmin[KD_W];
    _Alignas(KD_VALIGN) float best_t[KD_W], best_u[KD_W], best_v[KD_W];
    _Alignas(KD_VALIGN) int32_t best_prim[KD_W];
    float scene_mag;  /* largest root-box coordinate magnitude */
    int lanes;        /* lanes traced by the bundle */
    int hit;          /* any-hit: lanes that hit */
    uint64_t steps;   /* node steps of the bundle */
    uint64_t lane_steps;
    uint64_t tri_tests;
} KD_WN(kb_bundle);

typedef struct KD_WN(kb_entry) {
    VF t_near, t_far;
    uint32_t node;
} KD_WN(kb_entry);

/* Live traversal state of one bundle. */
typedef struct KD_WN(kb_state) {
    KD_WN(kd_nray_pre) tp;
    VF org[3], inv_dir[3], tmin;
    VF ss[3];  /* the ray's slack signed like inv_dir (kd_signed_slack) */
    VF sgn[3]; /* lanes with inv_dir < 0 (sign bit): above is near */
    VF best_t, best_u, best_v, best_prim;
    float sorg[3]; /* the origin, when every lane has the same one */
    int shared;
    VF live;   /* lanes still searching (any-hit lanes leave on a hit) */
    VF tmin_ok; /* lanes with tmin >= 0 (kd_leaf_behind's condition) */
    VF lane_steps, tri_tests; /* per-lane counters (V(count)) */
    VF limit;  /* kd_term_bound(best_t) on live lanes, -inf elsewhere */
    int any;
    int far;   /* any hit, far end first: at a split the child the lanes'
                  directions lead into (where their ends lie) is entered first */
} KD_WN(kb_state);

/* kd_term_bound, per lane, exactly as the scalar inline computes it. */
KD_FN void KD_WN(kb_update_limit)(KD_WN(kb_state) *st) {
    const VF absmask = V(seti)(0x7fffffff);
    VF slack = V(mul)(V(and)(st->best_t, absmask), V(set1)(0x1p-18f));
    VF bound = V(add)(V(add)(st->best_t, slack), V(set1)(FLT_MIN));
    st->limit = V(sel)(st->live, bound, V(set1)(-INFINITY));
}

/* Lanes of an interval that still need visiting. */
KD_FN VF KD_WN(kb_active)(const KD_WN(kb_state) *st, VF t_near, VF t_far) {
    return V(and)(V(le)(t_near, t_far), V(le)(t_near, st->limit));
}

/* Smallest-prim tie rule for lanes whose hit t equals best_t exactly. */
KD_FN VF KD_WN(kb_ties)(const KD_WN(kb_state) *st, VF eq, int32_t prim) {
    _Alignas(KD_VALIGN) int32_t best[KD_W];
    V(store)((float *)best, st->best_prim);
    int bits = V(bits)(eq), win = 0;
    for (int j = 0; j < KD_W; j++)
        if (((bits >> j) & 1) && (uint32_t)prim < (uint32_t)best[j])
            win |= 1 << j;
    return V(bitmask)(win);
}

/* Tests the leaf's triangles against the active lanes. */
KD_FN void KD_WN(kb_leaf)(const kdr_scene *s, const kd_node *n, KD_WN(kb_state) *st,
                    VF act) {
    const uint32_t *refs = s->refs + n->u.first;
    const uint32_t cnt = kd_count(n);
    const int flat = kd_leaf_flat(n);
    if (flat) { /* kd_leaf_behind per lane: lanes with tmin >= 0 whose
                   dominant axis is the plane's and whose origin is in
                   front of it, moving away, have nothing to find here */
        const VF c = V(set1)(s->tris[9 * (size_t)refs[0] + (size_t)(flat - 1)]);
        const VF on_axis = flat == 1   ? st->tp.kz0
                           : flat == 2 ? st->tp.kz1
                                       : V(andnot)(V(or)(st->tp.kz0, st->tp.kz1),
                                                   V(seti)(-1));
        const VF behind = V(le)(V(mul)(st->tp.sz, V(sub)(c, st->tp.oz)),
                                V(set1)(-0x1p-120f));
        act = V(andnot)(V(and)(V(and)(on_axis, behind), st->tmin_ok), act);
        if (!V(bits)(act)) {
            KD_WN(kb_update_limit)(st);
            return;
        }
    }
    /* request every triangle of the leaf at once: the tests then find
     * their rows arriving in parallel instead of one miss after another */
    if (s->prefetch_leaves)
        kd_prefetch_tris(s, refs, cnt);
    for (uint32_t r = 0; r < cnt; r++) {
        const int32_t prim = (int32_t)refs[r];
        VF t, Vv, W, det;
        st->tri_tests = V(count)(st->tri_tests, act);
        VF hit = KD_WN(kd_nray_test_raw)(&st->tp, s->tris + 9 * (size_t)prim, act,
                                  st->tmin, st->best_t, &t, &Vv, &W, &det);
        if (!V(bits)(hit))
            continue;
        if (st->any) {
            st->live = V(andnot)(hit, st->live);
            act = V(andnot)(hit, act);
            if (!V(bits)(act))
                break;
            continue;
        }
        VF better = V(lt)(t, st->best_t);
        VF eq = V(and)(hit, V(eq)(t, st->best_t));
        if (V(bits)(eq))
            better = V(or)(better, KD_WN(kb_ties)(st, eq, prim));
        better = V(and)(better, hit);
        st->best_t = V(sel)(better, t, st->best_t);
        st->best_u = V(sel)(better, V(div)(Vv, det), st->best_u);
        st->best_v = V(sel)(better, V(div)(W, det), st->best_v);
        st->best_prim = V(sel)(better, V(seti)(prim), st->best_prim);
    }
    KD_WN(kb_update_limit)(st);
}

/* Where a bundle is: a node, the lanes' interval there, the active lanes. */
typedef struct KD_WN(kb_cursor) {
    VF t_near, t_far, act;
    uint32_t node;
} KD_WN(kb_cursor);

KD_FN void KD_WN(kb_push)(KD_WN(kb_entry) *stack, int *sp, uint32_t node, VF t_near,
                    VF t_far) {
    KD_WN(kb_entry) *e = &stack[(*sp)++];
    e->node = node, e->t_near = t_near, e->t_far = t_far;
}

/* A child's interval per lane: [t_near, t_far]. */
typedef struct KD_WN(kb_span) {
    VF t_near, t_far;
} KD_WN(kb_span);

/*
 * The front and back intervals of every lane at a split plane. t_lo and
 * t_hi are where the ray crosses split -/+ its slack, computed exactly as
 * the single-ray walk does (kd_traverse.h); `away` flags lanes moving away
 * from the plane (the paper's negative distance). Then
 *   front [t_near, min(t_hi, t_far)]     away: [t_near, t_far] (d as +inf)
 *   back  [max(t_lo, t_near), t_far]     away: up to min(t_hi, t_far)
 * which are the single walk's near/far intervals: a lane leaving a plane
 * closer than its slack still looks at the other side, as the single walk
 * does. min/max take t_lo/t_hi first: a NaN (a lane in the plane) yields the
 * lane's own t_far / t_near, i.e. both children over the whole interval.
 */
KD_FN void KD_WN(kb_spans)(VF t_lo, VF t_hi, VF away, VF t_near, VF t_far,
                     KD_WN(kb_span) *f, KD_WN(kb_span) *b) {
    const VF inf = V(set1)(INFINITY);
    f->t_near = t_near;
    f->t_far = V(min)(V(sel)(away, inf, t_hi), t_far);
    b->t_near = V(max)(t_lo, t_near);
    b->t_far = V(min)(V(sel)(away, t_hi, inf), t_far);
}

/*
 * What both shared-origin steps below decide at an interior node whose
 * split the shared origin lies strictly off: the front (origin's side) and
 * back children, their per-lane spans, which lanes need each, and each
 * child's lane bits (0 for an empty child: kd_layout's flags say it needs
 * no visit). A lane moves away from the plane when its direction points
 * from the plane to the origin's side.
 */
typedef struct KD_WN(kb_choice) {
    KD_WN(kb_span) f, b;
    VF f_act, b_act;
    uint32_t front, back;
    int fb, bb;
} KD_WN(kb_choice);

KD_FN void KD_WN(kb_shared_choice)(const KD_WN(kb_state) *st, const kd_node *n, float a,
                                   const KD_WN(kb_cursor) *c, KD_WN(kb_choice) *ch) {
    const int axis = kd_axis(n);
    const VF av = V(set1)(a), inv = st->inv_dir[axis];
    const VF t_lo = V(mul)(V(sub)(av, st->ss[axis]), inv);
    const VF t_hi = V(mul)(V(add)(av, st->ss[axis]), inv);
    const VF away = a < 0.0f ? V(andnot)(st->sgn[axis], V(seti)(-1)) : st->sgn[axis];
    KD_WN(kb_spans)(t_lo, t_hi, away, c->t_near, c->t_far, &ch->f, &ch->b);
    ch->f_act = V(and)(c->act, V(le)(ch->f.t_near, ch->f.t_far));
    ch->b_act = V(and)(c->act, KD_WN(kb_active)(st, ch->b.t_near, ch->b.t_far));
    ch->front = a < 0.0f ? kd_above(n) : c->node + 1;
    ch->back = a < 0.0f ? c->node + 1 : kd_above(n);
    const int f_empty = a < 0.0f ? kd_above_empty(n) : kd_below_empty(n);
    const int b_empty = a < 0.0f ? kd_below_empty(n) : kd_above_empty(n);
    ch->fb = f_empty ? 0 : V(bits)(ch->f_act);
    ch->bb = b_empty ? 0 : V(bits)(ch->b_act);
}

/*
 * Interior node, shared origin strictly off the plane: one front child for
 * every lane, the paper's listing. Returns 0 when no lane enters either
 * child.
 */
KD_FN int KD_WN(kb_step_shared)(const KD_WN(kb_state) *st, const kd_node *n, float a,
                          KD_WN(kb_cursor) *c, KD_WN(kb_entry) *stack, int *sp) {
    KD_WN(kb_choice) ch;
    KD_WN(kb_shared_choice)(st, n, a, c, &ch);
    if (ch.fb && ch.bb)
        KD_WN(kb_push)(stack, sp, ch.back, ch.b.t_near, ch.b.t_far);
    if (ch.fb) {
        c->node = ch.front, c->t_far = ch.f.t_far, c->act = ch.f_act;
        return 1;
    }
    if (ch.bb) {
        c->node = ch.back, c->t_near = ch.b.t_near, c->t_far = ch.b.t_far, c->act = ch.b_act;
        return 1;
    }
    return 0;
}

/*
 * kb_step_shared for any-hit bundles, with the lanes' choice made by
 * selects instead of branches: the back entry is written always and kept
 * (the stack pointer moved) only when both children are needed, and the
 * cursor takes the front child's fields when some lane needs it, else the
 * back child's. The same values as kb_step_shared's branches pick, so the
 * same walk. Shadow and AO lanes turn at random where camera tiles do not:
 * their branches mispredict (camera tiles lost with this form: see
 * docs/TRAVERSAL.md, so closest-hit bundles keep the branches).
 */
KD_FN int KD_WN(kb_step_shared_nb)(const KD_WN(kb_state) *st, const kd_node *n, float a,
                                   KD_WN(kb_cursor) *c, KD_WN(kb_entry) *stack,
                                   int *sp) {
    KD_WN(kb_choice) ch;
    KD_WN(kb_shared_choice)(st, n, a, c, &ch);
    KD_WN(kb_entry) *e = &stack[*sp];
    e->node = ch.back, e->t_near = ch.b.t_near, e->t_far = ch.b.t_far;
    *sp += (ch.fb != 0) & (ch.bb != 0);
    const VF go_front = V(bitmask)(ch.fb ? -1 : 0);
    c->node = ch.fb ? ch.front : ch.back;
    c->t_near = V(sel)(go_front, c->t_near, ch.b.t_near);
    c->t_far = V(sel)(go_front, ch.f.t_far, ch.b.t_far);
    c->act = V(sel)(go_front, ch.f_act, ch.b_act);
    return (ch.fb | ch.bb) != 0;
}

/*
 * kb_step_shared_nb's far end first form (any hit): the back child (beyond
 * the plane from the shared origin, where the lanes moving toward the
 * plane end) is entered first when some lane needs it, the front child
 * stacked when both are needed; the same spans and lane sets, so the same
 * leaves are tested over the same intervals, only in the other order.
 */
KD_FN int KD_WN(kb_step_shared_far)(const KD_WN(kb_state) *st, const kd_node *n, float a,
                                    KD_WN(kb_cursor) *c, KD_WN(kb_entry) *stack,
                                    int *sp) {
    KD_WN(kb_choice) ch;
    KD_WN(kb_shared_choice)(st, n, a, c, &ch);
    KD_WN(kb_entry) *e = &stack[*sp];
    e->node = ch.front, e->t_near = ch.f.t_near, e->t_far = ch.f.t_far;
    *sp += (ch.fb != 0) & (ch.bb != 0);
    const VF go_back = V(bitmask)(ch.bb ? -1 : 0);
    c->node = ch.bb ? ch.back : ch.front;
    c->t_near = V(sel)(go_back, ch.b.t_near, c->t_near);
    c->t_far = V(sel)(go_back, ch.b.t_far, ch.f.t_far);
    c->act = V(sel)(go_back, ch.b_act, ch.f_act);
    return (ch.fb | ch.bb) != 0;
}

/*
 * Interior node, general case: per-lane origins, or a shared origin on the
 * plane. Each lane's below/above intervals come from its own front/back; an
 * origin ON the plane takes as front the child its direction leaves (the
 * single walk's near child). The child that is front for most active lanes
 * is entered first.
 */
KD_FN int KD_WN(kb_step_general)(const KD_WN(kb_state) *st, const kd_node *n,
                           KD_WN(kb_cursor) *c, KD_WN(kb_entry) *stack, int *sp,
                           const int far) {
    const int axis = kd_axis(n);
    const VF zero = V(set1)(0.0f), inv = st->inv_dir[axis];
    const VF a = V(sub)(V(set1)(n->u.split), st->org[axis]);
    const VF t_lo = V(mul)(V(sub)(a, st->ss[axis]), inv);
    const VF t_hi = V(mul)(V(add)(a, st->ss[axis]), inv);
    const VF on_plane = V(eq)(a, zero), below = V(lt)(a, zero);
    const VF away = V(andnot)(on_plane, V(xor)(below, st->sgn[axis]));
    const VF above_front = V(or)(below, V(and)(on_plane, st->sgn[axis]));
    KD_WN(kb_span) f, b;
    KD_WN(kb_spans)(t_lo, t_hi, away, c->t_near, c->t_far, &f, &b);
    const KD_WN(kb_span) lo = {V(sel)(above_front, b.t_near, f.t_near),
                         V(sel)(above_front, b.t_far, f.t_far)};
    const KD_WN(kb_span) hi = {V(sel)(above_front, f.t_near, b.t_near),
                         V(sel)(above_front, f.t_far, b.t_far)};
    const VF lo_act = V(and)(c->act, KD_WN(kb_active)(st, lo.t_near, lo.t_far));
    const VF hi_act = V(and)(c->act, KD_WN(kb_active)(st, hi.t_near, hi.t_far));
    /* an empty child (kd_layout's flags) needs no visit */
    const int lb = kd_below_empty(n) ? 0 : V(bits)(lo_act);
    const int hb = kd_above_empty(n) ? 0 : V(bits)(hi_act);
    if (!lb && !hb)
        return 0;
    int go_above = !lb;
    if (lb && hb) {
        /* far end first: the child most lanes' directions lead into */
        const VF first_above = far ? V(andnot)(st->sgn[axis], V(seti)(-1)) : above_front;
        const int votes = kd_lane_count(V(bits)(V(and)(c->act, first_above)));
        go_above = 2 * votes > kd_lane_count(V(bits)(c->act));
        if (go_above)
            KD_WN(kb_push)(stack, sp, c->node + 1, lo.t_near, lo.t_far);
        else
            KD_WN(kb_push)(stack, sp, kd_above(n), hi.t_near, hi.t_far);
    }
    c->node = go_above ? kd_above(n) : c->node + 1;
    c->t_near = go_above ? hi.t_near : lo.t_near;
    c->t_far = go_above ? hi.t_far : lo.t_far;
    c->act = go_above ? hi_act : lo_act;
    return 1;
}

/*
 * The shared-origin steps of the walk along the origin's path (kd_entry.h),
 * from the root: at each level kb_step_shared's own operations on the
 * path's copy of the node (a = split - org as the walk computes it, the
 * axis, the back child's empty flag and index), for as long as the walk
 * takes the front child, which is the path's child (the origin's side).
 * The back child is pushed with its per-lane interval when a lane needs
 * it, as kb_step_shared pushes it (the write is unconditional, the stack
 * pointer moves only then). At the first level where no lane needs the
 * front child the replay stops without counting that node: the loop then
 * steps it as usual. So the cursor, the stack (entries, order, intervals)
 * and the step counts are those the loop reaches there; only the node
 * loads, the leaf and origin tests and the branches of the loop are saved.
 * The path never holds a node whose split the origin lies on, nor a step
 * into an empty front child (kd_entry_path_init stops there).
 */
KD_FN void KD_WN(kb_replay)(const kdr_scene *s, const kd_entry_path *p,
                            KD_WN(kb_state) *st, KD_WN(kb_cursor) *c,
                            KD_WN(kb_entry) *stack, int *sp, uint64_t *steps) {
    const VF ones = V(seti)(-1);
    const VF t_near = c->t_near;
    VF t_far = c->t_far, act = c->act, lane_steps = st->lane_steps;
    int i = 0, k = *sp;
    for (; i < p->depth; i++) {
        const struct kd_entry_level *l = &p->lv[i];
        const int axis = l->axis;
        const float a = p->a[i];
        if (a == 0.0f) /* flushed to zero (FTZ): the loop's general step */
            break;
        const VF av = V(set1)(a), inv = st->inv_dir[axis];
        const VF t_lo = V(mul)(V(sub)(av, st->ss[axis]), inv);
        const VF t_hi = V(mul)(V(add)(av, st->ss[axis]), inv);
        const VF away = a < 0.0f ? V(andnot)(st->sgn[axis], ones) : st->sgn[axis];
        KD_WN(kb_span) f, b;
        KD_WN(kb_spans)(t_lo, t_hi, away, t_near, t_far, &f, &b);
        const VF f_act = V(and)(act, V(le)(f.t_near, f.t_far));
        if (!V(bits)(f_act))
            break;
        const VF b_act = V(and)(act, KD_WN(kb_active)(st, b.t_near, b.t_far));
        const int b_empty = l->above ? (l->empty & 1) : (l->empty >> 1) & 1;
        lane_steps = V(count)(lane_steps, act);
        KD_WN(kb_entry) *e = &stack[k];
        e->node = (uint32_t)(p->sib[i] - s->nodes);
        e->t_near = b.t_near, e->t_far = b.t_far;
        k += !b_empty && V(bits)(b_act);
        t_far = f.t_far, act = f_act;
    }
    *steps += (uint64_t)i;
    st->lane_steps = lane_steps;
    c->node = (uint32_t)(p->node[i] - s->nodes);
    c->t_far = t_far, c->act = act;
    *sp = k;
}

/* The node loop: from the root interval (or, given the path of the
 * bundle's shared origin, from where kb_replay leaves it) to an empty
 * stack. far (a constant: kb_trace instantiates the loop once for each
 * order, so the front-to-back loop is compiled as it was before the far
 * order existed) takes the far end first steps. */
KD_FN __attribute__((always_inline)) void
KD_WN(kb_walk)(const kdr_scene *s, KD_WN(kb_state) *st, VF t_near, VF t_far,
               const kd_entry_path *path, KD_WN(kb_bundle) *b, const int far) {
    KD_WN(kb_entry) stack[KD_MAX_DEPTH + 1];
    int sp = 0;
    KD_WN(kb_cursor) c = {t_near, t_far, KD_WN(kb_active)(st, t_near, t_far), 0};
    uint64_t steps = 0;
    if (path)
        KD_WN(kb_replay)(s, path, st, &c, stack, &sp, &steps);
    for (;;) {
        const kd_node *n = &s->nodes[c.node];
        steps++;
        st->lane_steps = V(count)(st->lane_steps, c.act);
        if (!kd_is_leaf(n)) {
            const float a = n->u.split - st->sorg[kd_axis(n)];
            if (st->shared && a != 0.0f
                    ? (far       ? KD_WN(kb_step_shared_far)(st, n, a, &c, stack, &sp)
                       : st->any ? KD_WN(kb_step_shared_nb)(st, n, a, &c, stack, &sp)
                                 : KD_WN(kb_step_shared)(st, n, a, &c, stack, &sp))
                    : KD_WN(kb_step_general)(st, n, &c, stack, &sp, far))
                continue;
        } else {
            KD_WN(kb_leaf)(s, n, st, c.act);
        }
        /* pop the nearest entry that still has an active lane */
        for (;;) {
            if (sp == 0) {
                b->steps = steps;
                return;
            }
            const KD_WN(kb_entry) *e = &stack[--sp];
            c.act = KD_WN(kb_active)(st, e->t_near, e->t_far);
            if (V(bits)(c.act)) {
                c.node = e->node, c.t_near = e->t_near, c.t_far = e->t_far;
                break;
            }
        }
    }
}

/* kd_ray_slack's scene part (a max, so its order does not matter). */
static inline float KD_WN(kb_scene_mag)(const kdr_scene *s) {
    float m = 0.0f;
    for (int k = 0; k < 3; k++) {
        const float a = -s->root.min[k], c = s->root.max[k];
        m = a > m ? a : m;
        m = c > m ? c : m;
    }
    return m;
}

/*
 * kd_ray_slack, kd_signed_slack and kd_clip_root_slack for all lanes at
 * once (the same float operations and comparisons, so the same bits). Lanes
 * that miss the root box leave b->lanes; the others get their interval.
 */
KD_FN void KD_WN(kb_clip)(const kdr_scene *s, KD_WN(kb_bundle) *b, KD_WN(kb_state) *st,
                    const VF dir[3], VF *t_near, VF *t_far) {
    const VF absm = V(seti)(0x7fffffff), zero = V(set1)(0.0f);
    VF m = V(set1)(b->scene_mag);
    for (int k = 0; k < 3; k++)
        m = V(max)(V(and)(st->org[k], absm), m);
    const VF slack = V(mul)(m, V(set1)(KD_SLACK_REL));
    VF tn = st->tmin, tf = V(load)(b->best_t), ok = V(bitmask)(b->lanes);
    for (int k = 0; k < 3; k++) {
        const VF flat = V(eq)(dir[k], zero), o = st->org[k];
        st->sgn[k] = V(signmask)(st->inv_dir[k]);
        st->ss[k] = V(xor)(slack, V(and)(st->sgn[k], V(set1)(-0.0f)));
        const VF lo_b = V(sub)(V(set1)(s->root.min[k]), slack);
        const VF hi_b = V(add)(V(set1)(s->root.max[k]), slack);
        const VF t0 = V(mul)(V(sub)(lo_b, o), st->inv_dir[k]);
        const VF t1 = V(mul)(V(sub)(hi_b, o), st->inv_dir[k]);
        const VF sw = V(gt)(t0, t1);
        const VF lo = V(sel)(sw, t1, t0), hi = V(sel)(sw, t0, t1);
        tn = V(sel)(V(andnot)(flat, V(gt)(lo, tn)), lo, tn);
        tf = V(sel)(V(andnot)(flat, V(lt)(hi, tf)), hi, tf);
        /* a flat axis only rejects origins outside the (grown) slab */
        ok = V(andnot)(V(and)(flat, V(or)(V(lt)(o, lo_b), V(gt)(o, hi_b))), ok);
    }
    ok = V(and)(ok, V(le)(tn, tf));
    b->lanes = V(bits)(ok);
    *t_near = V(sel)(ok, tn, V(set1)(INFINITY));
    *t_far = V(sel)(ok, tf, V(set1)(-INFINITY));
}

/* Vector set-up of the traversal state from the gathered lanes. */
KD_FN void KD_WN(kb_setup)(const kdr_scene *s, KD_WN(kb_bundle) *b, KD_WN(kb_state) *st,
                     VF *t_near, VF *t_far) {
    VF dir[3];
    for (int k = 0; k < 3; k++) {
        st->org[k] = V(load)(b->org[k]);
        dir[k] = V(load)(b->dir[k]);
        st->inv_dir[k] = V(div)(V(set1)(1.0f), dir[k]);
    }
    st->tmin = V(load)(b->tmin);
    KD_WN(kb_clip)(s, b, st, dir, t_near, t_far);
    if (!b->lanes)
        return;
    KD_WN(kd_nray_setup)(&st->tp, st->org, dir, b->lanes);
    const int ref = __builtin_ctz((unsigned)b->lanes);
    st->shared = 1;
    for (int k = 0; k < 3; k++) {
        st->sorg[k] = b->org[k][ref];
        VF same = V(eq)(st->org[k], V(set1)(st->sorg[k]));
        st->shared &= (V(bits)(same) & b->lanes) == b->lanes;
    }
}

/* The origin's path for a bundle whose lanes share an origin, from the
 * chunk's cache (a kd_entry_cache: the last path and the previous bundle's
 * origin), or NULL: the path is built when a second bundle in a row has
 * the origin (a run of bundles; one bundle alone would pay the path's
 * 25-level walk to save about as much), reused while bundles keep it. */
KD_FN const kd_entry_path *KD_WN(kb_path)(const kdr_scene *s, const KD_WN(kb_state) *st,
                                          kd_entry_cache *ec) {
    if (!ec || !st->shared)
        return NULL;
    const size_t sz = 3 * sizeof(float);
    if (ec->have_path && memcmp(st->sorg, ec->path_org, sz) == 0)
        return &ec->path;
    const int run = ec->have_prev && memcmp(st->sorg, ec->prev_org, sz) == 0;
    memcpy(ec->prev_org, st->sorg, sz);
    ec->have_prev = 1;
    if (!run)
        return NULL;
    kd_entry_path_init(s, st->sorg, &ec->path);
    memcpy(ec->path_org, st->sorg, sz);
    ec->have_path = 1;
    return &ec->path;
}

/* Traces the gathered lanes of a bundle; ec (NULL: every walk starts at
 * the root) caches the path of a shared origin (kb_path); far (any hit
 * only) walks the lanes far end first. */
KD_FN void KD_WN(kb_trace)(const kdr_scene *s, KD_WN(kb_bundle) *b, int any, int far,
                           kd_entry_cache *ec) {
    KD_WN(kb_state) st;
    VF t_near, t_far;
    b->hit = 0;
    b->steps = b->lane_steps = b->tri_tests = 0;
    if (!b->lanes)
        return;
    KD_WN(kb_setup)(s, b, &st, &t_near, &t_far);
    if (!b->lanes)
        return;
    st.best_t = V(load)(b->best_t);
    st.best_u = st.best_v = V(set1)(0.0f);
    st.best_prim = V(seti)(-1);
    st.live = V(bitmask)(b->lanes);
    st.lane_steps = st.tri_tests = V(seti)(0);
    st.any = any;
    st.tmin_ok = V(le)(V(set1)(0.0f), st.tmin);
    st.far = any && far;
    KD_WN(kb_update_limit)(&st);
    if (st.far) /* from the root: the origin's path leads to the near end */
        KD_WN(kb_walk)(s, &st, t_near, t_far, NULL, b, 1);
    else
        KD_WN(kb_walk)(s, &st, t_near, t_far, KD_WN(kb_path)(s, &st, ec), b, 0);
    b->lane_steps = V(count_sum)(st.lane_steps);
    b->tri_tests = V(count_sum)(st.tri_tests);
    V(store)(b->best_t, st.best_t);
    V(store)(b->best_u, st.best_u);
    V(store)(b->best_v, st.best_v);
    V(store)((float *)b->best_prim, st.best_prim);
    b->hit = b->lanes & ~V(bits)(st.live);
}
#endif /* KD_W */
