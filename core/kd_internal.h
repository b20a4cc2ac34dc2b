/*
 * kd_internal.h — the built scene as every traversal sees it: the 8-byte
 * node layout, the leaf reference lists and the triangle copy. Shared by
 * the kd_build*.c files and the kd_traverse_*.c files; not part of the
 * public API.
 *
 * Node layout (8 bytes, as in pbrt-v3 / Wald's thesis), as every traversal
 * sees it after kd_layout() (core/kd_layout.c):
 *   interior: u.split = split position,
 *             bits = (above_child << 4) | (above_empty << 3) |
 *                    (below_empty << 2) | axis,
 *             axis in 0..2; the below child is always the next node
 *             (depth-first order), the above child is nodes[above_child];
 *             *_empty flags a child that is a leaf without references, so
 *             a walk can skip it without loading it.
 *   leaf:     u.first = index of its first reference in scene->refs,
 *             bits = (count << 4) | (flat << 2) | 3; refs[first ..
 *             first+count) are triangle numbers (prims); flat (set by
 *             the build: kd_flat_of) is 1 + k when every vertex of every referenced
 *             triangle has the same coordinate on axis k (a leaf of an
 *             axis-aligned floor or wall), else 0 (kd_leaf_behind).
 * The build (kd_build.c) writes interior bits as (above_child << 2) | axis;
 * kd_layout() rewrites them once the tree is complete.
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
static inline uint32_t kd_above(const kd_node *n) { return n->bits >> 4; }
static inline int kd_below_empty(const kd_node *n) { return (int)(n->bits >> 2) & 1; }
static inline int kd_above_empty(const kd_node *n) { return (int)(n->bits >> 3) & 1; }
static inline uint32_t kd_count(const kd_node *n) { return n->bits >> 4; }
/* 1 + the axis on which leaf n is flat, or 0 (kd_layout_flat). */
static inline int kd_leaf_flat(const kd_node *n) { return (int)(n->bits >> 2) & 3; }

/* A leaf holds fewer references than this (its count has 28 bits). */
#define KD_LEAF_MAX_REFS ((size_t)1 << 28)

/* Interior nodes keep 28 bits for the above child's index. */
#define KD_LAYOUT_MAX_NODES ((size_t)1 << 28)

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
    float root_mag;       /* largest |coordinate| of root (kd_layout) */
    int prefetch_leaves;  /* scene larger than a core's caches: walks
                             request a leaf's triangles before testing them
                             (kd_layout, KD_PREFETCH_MIN_BYTES) */
    kdr_tree_stats stats;
    int borrowed;         /* tris, nodes and refs point into a caller's
                             tree image (kd_image.c): kdr_scene_free leaves
                             them alone */
};

/* sizeof(struct kdr_scene) on LP64 as core/kd_image.c knows it. Whoever adds
 * a field to the struct above must carry it in the tree image (write and
 * open in kd_image.c, or derive it there as kd_layout_derive does), bump
 * KD_IMAGE_FORMAT if the image changes, and then update this constant;
 * kd_image.c refuses to compile until they do. */
#define KD_SCENE_STRUCT_SIZE 192

/* A scene's large read-mostly array (core/kd_mem.c): at least
 * KD_HUGE_MIN_BYTES gets a mapping of its own, 2 MiB-aligned and advised
 * with MADV_HUGEPAGE on Linux, the rest malloc (never NULL for 0 bytes
 * unless out of memory). Freed only with kd_mem_free (NULL is a no-op). */
void *kd_mem_alloc(size_t bytes);
void kd_mem_free(void *p);

/* Requests the rows of triangles refs[0..count) (two lines may hold a
 * 36-byte row); walks call it at a leaf when scene->prefetch_leaves. Kept
 * out of line so that leaf loops of small scenes keep their shape. */
__attribute__((noinline)) void kd_prefetch_tris(const kdr_scene *s,
                                                const uint32_t *refs,
                                                uint32_t count);

/* Requests the reference list of leaf n (one or two lines). */
static inline void kd_prefetch_refs(const kdr_scene *s, const kd_node *n) {
    const uint32_t count = kd_count(n);
    if (count == 0)
        return;
    __builtin_prefetch(s->refs + n->u.first);
    __builtin_prefetch(s->refs + n->u.first + count - 1);
}

/* The post-build pass: rewrites the built tree into the traversal layout
 * above (core/kd_layout.c). KDR_ERANGE when the tree has KD_LAYOUT_MAX_NODES
 * nodes or more. */
int kd_layout(kdr_scene *s);
/* The part of kd_layout() that is derived from the finished tree and not
 * stored in it (root_mag, prefetch_leaves); kd_image.c calls it too. */
void kd_layout_derive(kdr_scene *s);
/* The flat field of a leaf with references ref[0..count) into tris: 1 +
 * the first axis on which every vertex of every referenced triangle has
 * one coordinate, 0 when there is none or no reference. The build sets it
 * as it writes each leaf (kd_build.c); kd_layout_flat recomputes it for a
 * leaf of a finished scene (0 for an interior node), which kd_image.c
 * checks a stored tree against. */
int kd_flat_of(const float *tris, const uint32_t *ref, uint32_t count);
int kd_layout_flat(const kdr_scene *s, const kd_node *n);

/*
 * Whether every triangle of flat leaf n lies behind a ray's origin along
 * the ray's dominant axis kz, so that the watertight test (kd_tri.h) can
 * find none of them at t >= 0: the leaf's plane is flat on axis kz
 * (kd_leaf_flat), and az = sz * (c - org[kz]), computed as the test
 * computes each vertex's scaled z (c is every vertex's coordinate there:
 * the first reference's first vertex), is at most -2^-120. Then every
 * vertex has that az, T = U az + V bz + W cz has the sign of -det with
 * |T| >= |det| / 3 * 2^-120 (U, V, W share a sign; the largest is at
 * least det / 3; a product that underflows sends t to kd_tri_t_exact,
 * whose double T keeps the sign), so t = T / det <= -2^-122: below any
 * tmin >= 0. Callers skip the leaf's tests when tmin >= 0; the answer and
 * the order of everything else are unchanged, so every traversal kind may
 * use it or not and still return the single walk's bits.
 */
static inline int kd_leaf_behind(const kdr_scene *s, const kd_node *n, int kz,
                                 float org_kz, float sz) {
    if (kd_leaf_flat(n) != kz + 1)
        return 0;
    const float c = s->tris[9 * (size_t)s->refs[n->u.first] + (size_t)kz];
    return sz * (c - org_kz) <= -0x1p-120f;
}

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
