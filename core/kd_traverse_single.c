/*
 * kd_traverse_single.c — one ray at a time through the kd-tree, closest hit
 * and any hit: pbrt's front-to-back walk with a fixed to-do stack of
 * {node, tnear, tfar}, using the split convention of kd_traverse.h.
 *
 * Leaves test every reference over [tmin, best_t], not over the leaf's own
 * interval: a triangle hit just outside the leaf (rounding, or a triangle
 * that spans several leaves) is still accepted, and the tie rule (smaller t,
 * then smaller prim) then makes the answer independent of visiting order.
 * The walk ends when no pending subtree starts at or before
 * kd_term_bound(best_t).
 *
 * Speed (measured with tests/test_core_perf): node fetches are latency-bound
 * for incoherent rays, so each interior step prefetches the above child;
 * rays that start on surfaces (AO, shadows) spend most of their time in
 * leaves of clustered small triangles, so leaves of 3+ references are tested
 * 4 (SSE2) or 8 (AVX2) triangles at a time, bit-identical to kd_tri.h.
 *
 * kdr_occluded1 walks a ray with a finite tmax back to front (far child
 * first, kd_occluded1_far's order; KD_FAR1_FINITE): AO and shadow rays
 * from surfaces mostly meet their blockers nearer their end than the
 * crowded leaves around their origin. The answer does not depend on the
 * order; kd_occluded1_fwd keeps the front-to-back walk whose steps
 * kd_entry_occluded1 and the interleaved walk take.
 */
#include "kd_entry.h"
#include "kd_walk.h"

/* Descends from n to a non-empty leaf, pushing far children (rev: near
 * children, entering the far one: the far end first, same intervals);
 * returns the leaf, or NULL when the rest of this subtree is empty for the
 * ray (a child flagged empty is never entered). */
static inline const kd_node *descend(const kd_node *nodes, const kd_node *n,
                                     const float org[3], const float inv[3],
                                     const float ss[3], const unsigned neg[3],
                                     kd_todo *stack, int *sp, float *tn, float *tf,
                                     uint64_t *visited, const int rev) {
    while (!kd_is_leaf(n)) {
        ++*visited;
        const int axis = kd_axis(n);
        const float a = n->u.split - org[axis];
        const float t_lo = (a - ss[axis]) * inv[axis];
        const float t_hi = (a + ss[axis]) * inv[axis];
        const kd_node *below = n + 1, *above = nodes + kd_above(n);
        __builtin_prefetch(above);
        const kd_node *nearc = neg[axis] ? above : below;
        const kd_node *farc = neg[axis] ? below : above;
        const int near_empty = neg[axis] ? kd_above_empty(n) : kd_below_empty(n);
        const int far_empty = neg[axis] ? kd_below_empty(n) : kd_above_empty(n);
        if (t_lo > *tf) {
            if (near_empty)
                return NULL;
            n = nearc;
        } else if (t_hi < *tn) {
            if (far_empty)
                return NULL;
            n = farc;
        } else if (far_empty) { /* both, and also a NaN (ray in the plane) */
            n = nearc;
            *tf = t_hi < *tf ? t_hi : *tf;
        } else if (near_empty) {
            n = farc;
            *tn = t_lo > *tn ? t_lo : *tn;
        } else if (rev) { /* the same two intervals, far child first */
            stack[*sp].node = nearc;
            stack[*sp].tn = *tn;
            stack[*sp].tf = t_hi < *tf ? t_hi : *tf;
            ++*sp;
            n = farc;
            *tn = t_lo > *tn ? t_lo : *tn;
        } else {
            stack[*sp].node = farc;
            stack[*sp].tn = t_lo > *tn ? t_lo : *tn;
            stack[*sp].tf = *tf;
            ++*sp;
            n = nearc;
            *tf = t_hi < *tf ? t_hi : *tf;
        }
    }
    ++*visited;
    return n;
}

/* The walk from node n over [tn, tf] with stack[0..sp) pending (the root,
 * the root-clipped interval and nothing, or an entry point of kd_entry.h
 * and the entries pushed above it); any != 0 stops at the first hit; rev
 * != 0 (any hit only) visits the cells back to front. */
static inline int walk_from(const kdr_scene *s, const kdr_ray *r, const int any,
                            const int rev,
                            const kd_node *n, float tn, float tf, const float inv[3],
                            const float ss[3], const unsigned neg[3], kd_todo *stack,
                            int sp, kd_walk_out *o) {
    kd_ray_pre pre;
    kd_ray_precompute(r->org, r->dir, &pre);
    kd_ntri_pre4 pre4;
    kd_ntri_pre_init4(&pre, &pre4);
    const int avx2 = __builtin_cpu_supports("avx2") ? 1 : 0;
    const kd_node *nodes = s->nodes;
    for (;;) {
        n = descend(nodes, n, r->org, inv, ss, neg, stack, &sp, &tn, &tf, &o->nodes,
                    rev);
        if (n && kd_walk_leaf(s, n, &pre, &pre4, r->tmin, any, avx2, o))
            return 1;
        const float bound = kd_term_bound(o->t);
        do {
            if (sp == 0)
                return o->prim >= 0;
            --sp;
        } while (!(stack[sp].tn <= bound));
        n = stack[sp].node;
        tn = stack[sp].tn;
        tf = stack[sp].tf;
    }
}

/* Whether kdr_occluded1 walks r far end first (KD_FAR1_FINITE, core/
 * kd_tune.h): when its interval has an end to start from. */
static inline int far1_pick(const kdr_ray *r) {
    return KD_FAR1_FINITE && r->tmax < INFINITY;
}

/* The walk shared by both queries; any != 0 stops at the first hit, rev
 * != 0 walks back to front (any hit only), rev < 0 (any hit) as
 * far1_pick says. */
static inline int walk(const kdr_scene *s, const kdr_ray *r, const int any,
                       const int rev, kd_walk_out *o) {
    float inv[3], ss[3], tn, tf;
    unsigned neg[3];
    if (!s || !s->nodes || !kd_walk_setup(s, r, inv, ss, neg, &tn, &tf))
        return 0;
    kd_todo stack[KD_MAX_DEPTH];
    if (rev < 0 && far1_pick(r))
        return walk_from(s, r, 1, 1, s->nodes, tn, tf, inv, ss, neg, stack, 0, o);
    return walk_from(s, r, any, rev > 0, s->nodes, tn, tf, inv, ss, neg, stack, 0, o);
}

/* The same from the ray's entry on the path of its origin (kd_entry.h). */
static inline int walk_entry(const kdr_scene *s, const kd_entry_path *p,
                             const kdr_ray *r, const int any, kd_walk_out *o) {
    float inv[3], ss[3], tn, tf;
    unsigned neg[3];
    if (!s || !s->nodes || !kd_walk_setup(s, r, inv, ss, neg, &tn, &tf))
        return 0;
    kd_todo stack[KD_MAX_DEPTH];
    int level, sp;
    const kd_node *n =
        kd_entry_descend(p, r->org, inv, ss, neg, &tn, &tf, &level, stack, &sp);
    o->nodes += (uint64_t)level; /* the single walk steps through them */
    return walk_from(s, r, any, 0, n, tn, tf, inv, ss, neg, stack, sp, o);
}

static void add_stats(kdr_trav_stats *st, const kd_walk_out *o) {
    if (!st)
        return;
    st->rays++;
    st->nodes_visited += o->nodes;
    st->tri_tests += o->tests;
}

int kdr_intersect1(const kdr_scene *scene, const kdr_ray *ray, kdr_hit *hit,
                   kdr_trav_stats *stats) {
    kd_walk_out o = {ray ? ray->tmax : 0.0f, 0.0f, 0.0f, -1, 0, 0};
    const int found = ray ? walk(scene, ray, 0, 0, &o) : 0;
    add_stats(stats, &o);
    if (hit) {
        hit->t = found ? o.t : -1.0f;
        hit->u = found ? o.u : 0.0f;
        hit->v = found ? o.v : 0.0f;
        hit->prim = found ? o.prim : -1;
    }
    return found;
}

/* An any-hit walk in walk()'s order (0 front to back, 1 far end first, -1
 * the rule of KD_FAR1_FINITE). */
static int occluded(const kdr_scene *scene, const kdr_ray *ray, int order,
                    kdr_trav_stats *stats) {
    kd_walk_out o = {ray ? ray->tmax : 0.0f, 0.0f, 0.0f, -1, 0, 0};
    const int found = ray ? walk(scene, ray, 1, order, &o) : 0;
    add_stats(stats, &o);
    return found;
}

int kdr_occluded1(const kdr_scene *scene, const kdr_ray *ray, kdr_trav_stats *stats) {
    return occluded(scene, ray, -1, stats);
}

int kd_occluded1_fwd(const kdr_scene *scene, const kdr_ray *ray, kdr_trav_stats *stats) {
    return occluded(scene, ray, 0, stats);
}

int kd_occluded1_far(const kdr_scene *scene, const kdr_ray *ray, kdr_trav_stats *stats) {
    return occluded(scene, ray, 1, stats);
}

int kd_entry_occluded1(const kdr_scene *s, const kd_entry_path *p, const kdr_ray *r,
                       kdr_trav_stats *stats) {
    kd_walk_out o = {r->tmax, 0.0f, 0.0f, -1, 0, 0};
    const int found = walk_entry(s, p, r, 1, &o);
    add_stats(stats, &o);
    return found;
}

int kd_entry_intersect1(const kdr_scene *s, const kd_entry_path *p, const kdr_ray *r,
                        kdr_hit *hit, kdr_trav_stats *stats) {
    kd_walk_out o = {r->tmax, 0.0f, 0.0f, -1, 0, 0};
    const int found = walk_entry(s, p, r, 0, &o);
    add_stats(stats, &o);
    hit->t = found ? o.t : -1.0f;
    hit->u = found ? o.u : 0.0f;
    hit->v = found ? o.v : 0.0f;
    hit->prim = found ? o.prim : -1;
    return found;
}
