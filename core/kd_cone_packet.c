/*
 * kd_cone_packet.c — shadow samples 4, 8 or 16 at a time (SSE2 / AVX2 /
 * AVX-512): against a short candidate list, or walking a group's cone
 * through the kd-tree and testing each leaf's triangles on the way
 * (kd_cone_packet.h, instantiated here per width). One SIMD test replaces
 * 4, 8 or 16 scalar ones, and a packet stops as soon as every lane is
 * blocked. Lists take 16 lanes (a penumbra cell's samples, 64 at 64 spp,
 * go 16 at a time: half the triangle tests of 8-wide packets); walks stay
 * at 8 (lit_busy sizes a packet's cone by its width).
 */
#include "kd_cone.h"
#include "kd_internal.h"

#define KD_W 4
#include "simd_width.h"
#include "kd_cone_packet.h"
#undef KD_W
#define KD_W 8
#include "simd_width.h"
#include "kd_cone_packet.h"
#undef KD_W
#define KD_W 16
#include "simd_width.h"
#include "kd_cone_packet.h"

KD_AVX512 static int list16(const kdr_scene *scene, const kdr_ray *const *lanes,
                            int n, const uint32_t *cands, size_t ncand,
                            uint32_t *blocker) {
    kc_packet16 pk;
    kc_packet_init16(&pk, lanes, n);
    return pk.all & ~kc_packet_tris16(&pk, scene, cands, ncand, pk.all, blocker);
}

KD_AVX2 static int list8(const kdr_scene *scene, const kdr_ray *const *lanes,
                         int n, const uint32_t *cands, size_t ncand,
                         uint32_t *blocker) {
    kc_packet8 pk;
    kc_packet_init8(&pk, lanes, n);
    return pk.all & ~kc_packet_tris8(&pk, scene, cands, ncand, pk.all, blocker);
}

static int list4(const kdr_scene *scene, const kdr_ray *const *lanes, int n,
                 const uint32_t *cands, size_t ncand, uint32_t *blocker) {
    kc_packet4 pk;
    kc_packet_init4(&pk, lanes, n);
    return pk.all & ~kc_packet_tris4(&pk, scene, cands, ncand, pk.all, blocker);
}

int kd_cone_packet_blocked(const kdr_scene *scene, const kdr_ray *const *lanes,
                           int n, const uint32_t *cands, size_t ncand,
                           uint32_t *blocker, int width) {
    if (width == 16)
        return list16(scene, lanes, n, cands, ncand, blocker);
    if (width == 8)
        return list8(scene, lanes, n, cands, ncand, blocker);
    int mask = list4(scene, lanes, n < 4 ? n : 4, cands, ncand, blocker);
    if (n > 4)
        mask |= list4(scene, lanes + 4, n - 4, cands, ncand, blocker) << 4;
    return mask;
}

KD_AVX2 static int walk8(const kdr_scene *scene, const kd_cone *c,
                         const kdr_ray *const *lanes, int n, uint64_t max_nodes,
                         uint32_t *blocker, uint64_t *visited, int *open) {
    return kc_packet_walk8(scene, c, lanes, n, max_nodes, blocker, visited, open);
}

int kd_cone_packet_walk(const kdr_scene *scene, const kd_cone *c,
                        const kdr_ray *const *lanes, int n, uint64_t max_nodes,
                        uint32_t *blocker, uint64_t *visited, int *open,
                        int wide) {
    if (wide)
        return walk8(scene, c, lanes, n, max_nodes, blocker, visited, open);
    return kc_packet_walk4(scene, c, lanes, n, max_nodes, blocker, visited, open);
}
