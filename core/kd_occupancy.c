/*
 * kd_occupancy.c — inside or outside the scene's closed meshes, by voting.
 *
 * A point is inside when a ray from it crosses the surface an odd number
 * of times (parity, as Open3D's compute_occupancy defines it; a point
 * inside two overlapping closed meshes is outside by this rule, as it is by
 * the winding number taken mod 2). One ray can be wrong: through a shared
 * edge or vertex the watertight test reports every triangle that meets
 * there (kd_all.c: two or more hits where the surface is crossed once), and
 * a ray grazing a silhouette may count a touch as a crossing. So
 * KDR_OCCUPANCY_RAYS rays in fixed directions, well spread over the sphere
 * (a spherical Fibonacci set, tilted off the axes: at least 62 degrees
 * apart), each give a parity, and the majority decides. A wrong answer
 * needs most rays to be degenerate at once, which near no point farther
 * from the surface than the stated band (docs/API.md) was seen to happen
 * (tests/test_occupancy.c).
 */
#include <math.h>

#include "kd_internal.h"

static const float DIRS[KDR_OCCUPANCY_RAYS][3] = {
    {0.395710951f, -0.116878263f, 0.910907413f},
    {-0.728428273f, -0.101750836f, 0.677524183f},
    {0.517309466f, -0.844263595f, 0.140035346f},
    {0.122516908f, 0.814878645f, 0.566535437f},
    {-0.762792972f, -0.600105662f, -0.240873570f},
    {0.974275246f, 0.047991369f, -0.220192128f},
    {-0.636788056f, 0.750267215f, -0.177764108f},
    {0.036569630f, -0.442549262f, -0.895998222f},
    {0.292510991f, 0.658317290f, -0.693581766f},
};

int kdr_occupancy1(const kdr_scene *scene, const float point[3], uint8_t *inside,
                   uint8_t *votes, kdr_trav_stats *stats) {
    if (inside) *inside = 0;
    if (!scene || !point || !inside) return KDR_EINVAL;
    if (!isfinite(point[0]) || !isfinite(point[1]) || !isfinite(point[2]))
        return KDR_EINVAL;
    unsigned odd = 0;
    for (int r = 0; r < KDR_OCCUPANCY_RAYS; r++) {
        kdr_ray ray = {{point[0], point[1], point[2]},
                       {DIRS[r][0], DIRS[r][1], DIRS[r][2]},
                       0.0f,
                       INFINITY};
        uint32_t n = 0;
        const int rc = kdr_count1(scene, &ray, &n, stats);
        if (rc != KDR_OK) return rc;
        odd += n & 1u;
    }
    if (votes) *votes = (uint8_t)odd;
    *inside = 2 * odd > KDR_OCCUPANCY_RAYS;
    return KDR_OK;
}

int kdr_occupancy_batch(const kdr_scene *scene, const float *points, size_t first,
                        size_t count, uint8_t *inside, kdr_trav_stats *stats) {
    if (!scene || !points || !inside) return KDR_EINVAL;
    for (size_t i = first; i < first + count; i++) {
        const int rc = kdr_occupancy1(scene, points + 3 * i, &inside[i], NULL, stats);
        if (rc != KDR_OK) return rc;
    }
    return KDR_OK;
}

void kdr_occupancy_direction(int r, float dir[3]) {
    for (int k = 0; k < 3; k++)
        dir[k] = r >= 0 && r < KDR_OCCUPANCY_RAYS ? DIRS[r][k] : 0.0f;
}
