/*
 * kd_cone_packet.h — template of the packet code of kd_cone_packet.c,
 * instantiated once per lane count (define KB_W, VF, V(op), KB(x), KB_FN as
 * for kd_tri_simd.h, then include). A packet is up to KB_W shadow samples;
 * every triangle test is kd_tri_simd.h's, bit-identical to kd_tri_intersect,
 * so a lane's any-hit answer is exactly the scalar one.
 */
#include "kd_tri_simd.h"

typedef struct KB(packet) {
    KB(tri_pre) p;
    VF tmin, tmax;
    int all; /* mask of the used lanes */
} KB(packet);

KB_FN void KB(packet_init)(KB(packet) *pk, const kdr_ray *const *lanes, int n) {
    _Alignas(32) float tmin[KB_W], tmax[KB_W];
    kd_ray_pre pre[KB_W];
    for (int j = 0; j < KB_W; j++) {
        const kdr_ray *r = lanes[j < n ? j : 0];
        kd_ray_precompute(r->org, r->dir, &pre[j]);
        tmin[j] = r->tmin;
        tmax[j] = r->tmax;
    }
    pk->all = (1 << n) - 1;
    KB(tri_pre_init)(&pk->p, pre, pk->all, 0);
    pk->tmin = V(load)(tmin);
    pk->tmax = V(load)(tmax);
}

/* Tests the active lanes against prims[0..count); returns the lanes still
 * unblocked. */
KB_FN int KB(packet_tris)(const KB(packet) *pk, const kdr_scene *scene,
                          const uint32_t *prims, size_t count, int act,
                          uint32_t *blocker) {
    for (size_t c = 0; c < count && act; c++) {
        VF t, u, v;
        const float *tri = scene->tris + 9 * (size_t)prims[c];
        const int hit = V(bits)(KB(tri_test)(&pk->p, tri, V(bitmask)(act),
                                             pk->tmin, pk->tmax, &t, &u, &v));
        if (hit) {
            act &= ~hit;
            *blocker = prims[c];
        }
    }
    return act;
}

/* The packet walks its cone front to back and tests each leaf's triangles
 * as it goes, until every lane is blocked, the cone is exhausted, or
 * max_nodes nodes were entered (the still-active lanes are then left
 * undecided in *open). Returns the mask of blocked lanes. */
KB_FN int KB(packet_walk)(const kdr_scene *scene, const kd_cone *c,
                          const kdr_ray *const *lanes, int n, uint64_t max_nodes,
                          uint32_t *blocker, uint64_t *visited, int *open) {
    KB(packet) pk;
    kd_cone_walk w;
    const kd_node *leaf;
    KB(packet_init)(&pk, lanes, n);
    int act = pk.all;
    *open = 0;
    kd_cone_walk_init(&w, scene, c);
    while (act && (leaf = kd_cone_walk_next(&w)) != NULL) {
        act = KB(packet_tris)(&pk, scene, scene->refs + leaf->u.first,
                              kd_count(leaf), act, blocker);
        if (act && w.visited > max_nodes) {
            *open = act;
            break;
        }
    }
    *visited += w.visited;
    return pk.all & ~act & ~*open;
}
