/*
 * kd_cone_packet.h — template of the packet code of kd_cone_packet.c,
 * instantiated once per lane count (the convention of simd_width.h). A
 * packet is up to KD_W shadow samples; every triangle test is
 * kd_tri_nray.h's, bit-identical to kd_tri_intersect,
 * so a lane's any-hit answer is exactly the scalar one.
 */
#include "kd_tri_nray.h"

typedef struct KD_WN(kc_packet) {
    KD_WN(kd_nray_pre) p;
    VF tmin, tmax;
    int all; /* mask of the used lanes */
} KD_WN(kc_packet);

KD_FN void KD_WN(kc_packet_init)(KD_WN(kc_packet) *pk, const kdr_ray *const *lanes,
                                 int n) {
    _Alignas(KD_VALIGN) float tmin[KD_W], tmax[KD_W];
    kd_ray_pre pre[KD_W];
    for (int j = 0; j < KD_W; j++) {
        const kdr_ray *r = lanes[j < n ? j : 0];
        kd_ray_precompute(r->org, r->dir, &pre[j]);
        tmin[j] = r->tmin;
        tmax[j] = r->tmax;
    }
    pk->all = (1 << n) - 1;
    KD_WN(kd_nray_pre_init)(&pk->p, pre, pk->all, 0);
    pk->tmin = V(load)(tmin);
    pk->tmax = V(load)(tmax);
}

/* Tests the active lanes against prims[0..count); returns the lanes still
 * unblocked. */
KD_FN int KD_WN(kc_packet_tris)(const KD_WN(kc_packet) *pk, const kdr_scene *scene,
                          const uint32_t *prims, size_t count, int act,
                          uint32_t *blocker) {
    for (size_t c = 0; c < count && act; c++) {
        VF t, u, v;
        const float *tri = scene->tris + 9 * (size_t)prims[c];
        const int hit = V(bits)(KD_WN(kd_nray_test)(&pk->p, tri, V(bitmask)(act),
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
KD_FN int KD_WN(kc_packet_walk)(const kdr_scene *scene, const kd_cone *c,
                          const kdr_ray *const *lanes, int n, uint64_t max_nodes,
                          uint32_t *blocker, uint64_t *visited, int *open) {
    KD_WN(kc_packet) pk;
    kd_cone_walk w;
    const kd_node *leaf;
    KD_WN(kc_packet_init)(&pk, lanes, n);
    int act = pk.all;
    *open = 0;
    kd_cone_walk_init(&w, scene, c);
    while (act && (leaf = kd_cone_walk_next(&w)) != NULL) {
        act = KD_WN(kc_packet_tris)(&pk, scene, scene->refs + leaf->u.first,
                              kd_count(leaf), act, blocker);
        if (act && w.visited > max_nodes) {
            *open = act;
            break;
        }
    }
    *visited += w.visited;
    return pk.all & ~act & ~*open;
}
