/*
 * kd_internal.h — the built scene as every traversal sees it: the 8-byte
 * node layout, the leaf reference lists and the triangle copy. Shared by
 * the kd_build*.c files and the kd_traverse_*.c files; not part of the
 * public API.
 *
 * Node layout (8 bytes, as in pbrt-v3 / Wald's thesis):
 *   interior: u.split = split position, bits = (above_child << 2) | axis,
 *             axis in 0..2; the below child is always the next node
 *             (depth-first order), the above child is nodes[above_child].
 *   leaf:     u.first = index of its first reference in scene->refs,
 *             bits = (count << 2) | 3; refs[first .. first+count) are
 *             triangle numbers (prims).
 * A triangle lying exactly in a split plane goes to one side only; a
 * triangle touching the plane from one side is referenced on that side.
 * Zero-area triangles are never inserted.
 */
#ifndef KD_INTERNAL_H
#define KD_INTERNAL_H

#include <float.h>
#include <math.h>
#include <stdint.h>

#include "kd_tune.h"
#include "kdray.h"

typedef struct kd_node {
    union {
        float split;
        uint32_t first;
    } u;
    uint32_t bits;
} kd_node;

#define KD_LEAF 3u

static inline int kd_is_leaf(const kd_node *n) { return (n->bits & 3u) == KD_LEAF; }
static inline int kd_axis(const kd_node *n) { return (int)(n->bits & 3u); }
static inline uint32_t kd_above(const kd_node *n) { return n->bits >> 2; }
static inline uint32_t kd_count(const kd_node *n) { return n->bits >> 2; }

/* Hard depth limit of the build; traversal stacks are this deep. */
#define KD_MAX_DEPTH 64

struct kdr_scene {
    size_t ntris;
    float *tris;          /* 9 * ntris, the caller's triangles, prim order */
    kd_node *nodes;       /* nodes[0] is the root; NULL when no triangle */
    size_t nnodes;
    uint32_t *refs;       /* leaf reference lists */
    size_t nrefs;
    kdr_bounds bounds;    /* of all non-degenerate triangles */
    kdr_bounds root;      /* bounds padded outward by a few ulps: the box
                             traversals clip rays against */
    float diagonal;
    kdr_tree_stats stats;
};

/*
 * Termination bound: a subtree entered at distance t_near can be skipped
 * once t_near > kd_term_bound(best_t). The slack (2^-18 relative) covers
 * rounding in split distances so that a triangle hit at exactly best_t in
 * a neighbouring leaf is still found, which keeps the smallest-prim tie rule
 * identical across single, bundle and frustum traversal.
 */
static inline float kd_term_bound(float best_t) {
    return best_t + fabsf(best_t) * 0x1p-18f + FLT_MIN;
}

/* Tie rule for closest hits: smaller t, then smaller prim. */
static inline int kd_hit_better(float t, int32_t prim, float best_t,
                                int32_t best_prim) {
    return t < best_t || (t == best_t && (uint32_t)prim < (uint32_t)best_prim);
}

#endif /* KD_INTERNAL_H */
