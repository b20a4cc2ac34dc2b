/*
 * kd_layout.c — the post-build pass between kd_build.c and every traversal:
 * the build writes pbrt's depth-first nodes (interior bits = above << 2 |
 * axis); this pass rewrites each interior node into the traversal layout of
 * kd_internal.h, which also flags children that are empty leaves. A walk
 * then decides at the parent that an empty child needs no visit: a ray
 * crossing empty space cut off by the SAH's empty bonus costs no node step,
 * no stack entry and no leaf exit (bench/ab: see docs/TRAVERSAL.md).
 * Leaves whose triangles all lie in one axis-aligned plane (a floor, a
 * wall) carry a flat field, which the build sets as it writes each leaf
 * (kd_flat_of, on the build's threads) so that walks can skip such a leaf
 * for rays that start in front of its plane and move away from it along
 * their dominant axis (kd_leaf_behind in kd_internal.h).
 * The pass changes no triangle, split or reference, so every answer is the
 * same.
 */
#include "kd_internal.h"

static int empty_leaf(const kd_node *n) {
    return kd_is_leaf(n) && kd_count(n) == 0;
}

void kd_layout_derive(kdr_scene *s) {
    /* kd_ray_slack's scene part, once per scene instead of once per ray */
    float m = 0.0f;
    for (int k = 0; k < 3; k++) {
        m = -s->root.min[k] > m ? -s->root.min[k] : m;
        m = s->root.max[k] > m ? s->root.max[k] : m;
    }
    s->root_mag = m;
    const size_t bytes = s->nnodes * sizeof(kd_node) + s->nrefs * sizeof(uint32_t) +
                         9 * s->ntris * sizeof(float);
    s->prefetch_leaves = bytes >= KD_PREFETCH_MIN_BYTES;
}

int kd_flat_of(const float *tris, const uint32_t *ref, uint32_t count) {
    if (count == 0)
        return 0;
    const float *first = tris + 9 * (size_t)ref[0];
    for (int k = 0; k < 3; k++) {
        const float c = first[k];
        int flat = 1;
        for (uint32_t r = 0; r < count && flat; r++) {
            const float *t = tris + 9 * (size_t)ref[r];
            flat = t[k] == c && t[3 + k] == c && t[6 + k] == c;
        }
        if (flat)
            return k + 1;
    }
    return 0;
}

int kd_layout_flat(const kdr_scene *s, const kd_node *n) {
    return kd_is_leaf(n) ? kd_flat_of(s->tris, s->refs + n->u.first, kd_count(n)) : 0;
}

int kd_layout(kdr_scene *s) {
    if (!s->nodes)
        return KDR_OK;
    if (s->nnodes >= KD_LAYOUT_MAX_NODES)
        return KDR_ERANGE;
    kd_layout_derive(s);
    /* a child's emptiness reads only leaf bits, which are never rewritten */
    for (size_t i = 0; i < s->nnodes; i++) {
        kd_node *n = &s->nodes[i];
        if (kd_is_leaf(n))
            continue;
        const uint32_t above = n->bits >> 2, axis = n->bits & 3u;
        const uint32_t eb = (uint32_t)empty_leaf(&s->nodes[i + 1]);
        const uint32_t ea = (uint32_t)empty_leaf(&s->nodes[above]);
        n->bits = above << 4 | ea << 3 | eb << 2 | axis;
    }
    return KDR_OK;
}

void kd_prefetch_tris(const kdr_scene *s, const uint32_t *refs, uint32_t count) {
    for (uint32_t r = 0; r < count; r++) {
        const float *tri = s->tris + 9 * (size_t)refs[r];
        __builtin_prefetch(tri);
        __builtin_prefetch(tri + 8);
    }
}
