/*
 * kd_cone.c — the cone-shadow query (kdr_shadow_trace): visibility of
 * spherical lights from points, as the fraction of kdr_shadow_ray samples
 * that reach the light.
 *
 * First version: both modes trace every sample through the kd-tree with
 * kdr_occluded1; the cone traversal replaces KDR_SHADOW_CONE next.
 */
#include <stddef.h>

#include "kd_cone.h"
#include "kd_internal.h"

#define SHADOW_MAX_SAMPLES 4096u

static int query_valid(const kdr_scene *scene, const kdr_shadow_query *q,
                       size_t first, size_t count, const float *visibility) {
    if (!scene || !q || !visibility || !q->points || !q->lights)
        return 0;
    if (q->nlights < 1 || q->samples < 1 || q->samples > SHADOW_MAX_SAMPLES)
        return 0;
    return first <= q->n && count <= q->n - first;
}

/* Fraction of the frame's samples that reach the light, each sample traced
 * through the whole kd-tree. */
static float visibility_by_rays(const kdr_scene *scene,
                                const kd_shadow_frame *f, uint32_t nsamples,
                                kdr_shadow_stats *stats) {
    kdr_trav_stats ts = {0};
    uint32_t lit = 0;
    for (uint32_t s = 0; s < nsamples; s++) {
        kdr_ray r;
        kd_shadow_frame_ray(f, s, nsamples, &r);
        lit += kdr_occluded1(scene, &r, &ts) ? 0u : 1u;
    }
    if (stats) {
        stats->rays_traced += nsamples;
        stats->nodes_visited += ts.nodes_visited;
    }
    return (float)lit / (float)nsamples;
}

int kdr_shadow_trace(const kdr_scene *scene, const kdr_shadow_query *q,
                     size_t first, size_t count, kdr_shadow_mode mode,
                     float *visibility, kdr_shadow_stats *stats) {
    (void)mode;
    if (!query_valid(scene, q, first, count, visibility))
        return KDR_EINVAL;
    for (size_t i = first; i < first + count; i++) {
        for (size_t l = 0; l < q->nlights; l++) {
            kd_shadow_frame f;
            int rc = kd_shadow_frame_init(scene, q, i, l, &f);
            if (rc != KDR_OK)
                return rc;
            visibility[i * q->nlights + l] =
                visibility_by_rays(scene, &f, q->samples, stats);
        }
    }
    return KDR_OK;
}
