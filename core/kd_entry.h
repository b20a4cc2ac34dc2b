/*
 * kd_entry.h — entry points for rays that share an origin (AO rays of one
 * surface point, shadow samples of one point). The path from the root to
 * the origin's leaf, which all of them descend, is built once per origin
 * (kd_entry_path_init); each ray then replays the single walk along it
 * (kd_entry_descend) with the walk's own node rule, float operations,
 * interval updates and pushes, for as long as the walk stays on the path.
 * Where it would leave it (the path's child not needed, or its near
 * sibling needed first) the ray's ordinary walk starts, at that node, with
 * that interval and the entries pushed so far: the state the full walk
 * reaches there. So the answer, the leaves visited and their order, and
 * the work (nodes, triangle tests) are the single walk's exactly, for
 * closest and any hit alike; only the replayed steps are cheaper (levels
 * held in a small array, 16 per AVX-512 operation, no near/far branch).
 * Used by the interleaved walk's refill (kd_entry_for); bundles whose lanes
 * share an origin replay the same path with their own step (kb_replay in
 * kd_traverse_bundle.h). Internal to core/.
 */
#ifndef KD_ENTRY_H
#define KD_ENTRY_H

#include <stddef.h>
#include <stdint.h>

#include "kd_internal.h"
#include "kd_traverse.h"

/* The origin's path from the root: node[i + 1] is the child of node[i]
 * holding the origin (above[i] says which), i < depth; node[depth] is a
 * leaf, or the node where the path stopped (origin in its split plane, or
 * its child there flagged empty). Each level keeps the split, the axis, the
 * empty flags and the other child, the only fields the replay reads. */
typedef struct kd_entry_path {
    int depth;
    const kd_node *node[KD_MAX_DEPTH + 1];
    const kd_node *sib[KD_MAX_DEPTH]; /* node[i]'s other child */
    struct kd_entry_level {
        float split;
        uint8_t axis, above; /* above: the origin's child is the above one */
        uint8_t empty;       /* bit 0: below child empty, bit 1: above */
    } lv[KD_MAX_DEPTH];
    /* The same levels for kd_entry_descend16 (16 levels per AVX-512
     * operation): a[i] = split - org[axis] (the walk's first operation,
     * shared by every ray of the origin), padded for unaligned loads, and
     * bit i of each mask: axis 1, axis 2, origin above, below child empty,
     * above child empty. */
    float a[KD_MAX_DEPTH + 16];
    uint64_t ax1, ax2, above_m, below_empty_m, above_empty_m;
    int wide; /* kd_cpu_has_avx512() */
} kd_entry_path;

/* Fills p for origin org (scene with a tree). */
void kd_entry_path_init(const kdr_scene *s, const float org[3], kd_entry_path *p);

/*
 * The single walk's descent along the path for a ray with the path's
 * origin after kd_walk_setup (inv, ss, neg, interval *tn, *tf), descend()'s
 * cases in kd_step_nobranch's form: at level i the crossings t_lo, t_hi;
 * the walk needs the near child unless t_hi < tn and the far child unless
 * t_lo > tf, minus an empty child. Where the path's child is the near one
 * and needed, the walk takes it, first pushing the sibling (the far child)
 * with [max(t_lo, tn), tf] when that is needed too, and clips tf to
 * min(t_hi, tf); where the path's child is the far one, needed, and the
 * near child is not, it takes it with tn = max(t_lo, tn). Anywhere else
 * (the path's child not needed, or the near sibling needed first) the walk
 * leaves the path: the replay stops there. Returns that node (the origin's
 * leaf when the ray follows the whole path), its level in *level and the
 * walk's state at it: interval *tn, *tf and the sp entries it pushed on
 * the way, in stack[0..*sp), in the walk's order.
 */
static inline const kd_node *
kd_entry_descend_scalar(const kd_entry_path *p, const float org[3], const float inv[3],
                        const float ss[3], const unsigned neg[3], float *tn, float *tf,
                        int *level, kd_todo *stack, int *sp) {
    float n0 = *tn, f0 = *tf;
    int i = 0, k = 0;
    for (; i < p->depth; i++) {
        const struct kd_entry_level *l = &p->lv[i];
        const int axis = l->axis;
        const float a = l->split - org[axis];
        const float t_lo = (a - ss[axis]) * inv[axis];
        const float t_hi = (a + ss[axis]) * inv[axis];
        const unsigned ng = neg[axis];
        /* near is the above child when the direction is negative */
        const unsigned near_empty = ((unsigned)l->empty >> ng) & 1u;
        const unsigned far_empty = ((unsigned)l->empty >> (ng ^ 1u)) & 1u;
        const unsigned go_near = (unsigned)!(t_hi < n0) & ~near_empty & 1u;
        const unsigned go_far = (unsigned)!(t_lo > f0) & ~far_empty & 1u;
        if ((unsigned)l->above == ng) { /* the path's child is the near one */
            if (!go_near) break;
            if (go_far) {
                stack[k].node = p->sib[i];
                stack[k].tn = t_lo > n0 ? t_lo : n0;
                stack[k].tf = f0;
                k++;
            }
            f0 = t_hi < f0 ? t_hi : f0;
        } else {
            if (go_near || !go_far) break;
            n0 = t_lo > n0 ? t_lo : n0;
        }
    }
    *tn = n0;
    *tf = f0;
    *level = i;
    *sp = k;
    return p->node[i];
}

/* kd_entry_descend_scalar's answer, 16 levels at a time with AVX-512
 * (kd_entry.c); bit for bit the same node, level, interval and stack
 * (tested by test_entry). */
const kd_node *kd_entry_descend16(const kd_entry_path *p, const float inv[3],
                                  const float ss[3], float *tn, float *tf, int *level,
                                  kd_todo *stack, int *sp);

/* The replay: kd_entry_descend16 on AVX-512 CPUs, else the scalar one. */
static inline const kd_node *kd_entry_descend(const kd_entry_path *p, const float org[3],
                                              const float inv[3], const float ss[3],
                                              const unsigned neg[3], float *tn, float *tf,
                                              int *level, kd_todo *stack, int *sp) {
    if (p->wide) return kd_entry_descend16(p, inv, ss, tn, tf, level, stack, sp);
    return kd_entry_descend_scalar(p, org, inv, ss, neg, tn, tf, level, stack, sp);
}

/* One ray with the path's origin through the single walk from its entry
 * (kd_traverse_single.c): the answer of kdr_occluded1 (any != 0) or
 * kdr_intersect1, bit for bit, and the same stats (the replayed levels
 * count as the nodes the single walk enters there). */
int kd_entry_occluded1(const kdr_scene *s, const kd_entry_path *p, const kdr_ray *r,
                       kdr_trav_stats *stats);
int kd_entry_intersect1(const kdr_scene *s, const kd_entry_path *p, const kdr_ray *r,
                        kdr_hit *hit, kdr_trav_stats *stats);

/* A walk over a batch that starts its rays one by one (the interleaved
 * walk's refill) keeps one path: rays whose origin is the path's start
 * from their entry; a ray with the previous ray's origin (a run begins)
 * builds the path for that origin first; any other ray starts at the root,
 * so scattered origins pay a compare, not a path. */
typedef struct kd_entry_cache {
    kd_entry_path path;
    float path_org[3], prev_org[3];
    int have_path, have_prev;
} kd_entry_cache;

/* The start of a ray with origin org after kd_walk_setup (inv, ss, neg,
 * interval *tn, *tf): its entry node, interval and stack
 * (kd_entry_descend), or the root, the interval as it is and no stack; *level is the
 * number of interior nodes the single walk steps through above the start (the stats count
 * them as visited, so work sums equal the single walk's). Cache zeroed before the first
 * ray. */
const kd_node *kd_entry_for(const kdr_scene *s, kd_entry_cache *ec, const float org[3],
                            const float inv[3], const float ss[3], const unsigned neg[3],
                            float *tn, float *tf, int *level, kd_todo *stack, int *sp);

#endif /* KD_ENTRY_H */
