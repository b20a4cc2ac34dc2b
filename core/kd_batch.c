/*
 * kd_batch.c — the batch API (kdr_trace_batch): reads AoS ray triples with
 * optional shared origin / interval, groups consecutive rays into bundles and
 * writes SoA results indexed by absolute ray number.
 *
 * First version: every mode traces ray by ray, so that everybody links while
 * the SIMD bundle traversal is being written.
 */
#include <stddef.h>

#include "kd_internal.h"

int kdr_cpu_has_avx2(void) {
    __builtin_cpu_init();
    return __builtin_cpu_supports("avx2") ? 1 : 0;
}

/* Ray i of the batch, with stride-0 fields shared. */
static void batch_ray(const kdr_ray_batch *b, size_t i, kdr_ray *r) {
    const float *o = b->org + b->org_stride * i;
    const float *d = b->dir + 3 * i;
    for (int k = 0; k < 3; k++) {
        r->org[k] = o[k];
        r->dir[k] = d[k];
    }
    r->tmin = b->tmin ? b->tmin[b->tmin_stride * i] : 0.0f;
    r->tmax = b->tmax ? b->tmax[b->tmax_stride * i] : INFINITY;
}

int kdr_trace_batch(const kdr_scene *scene, const kdr_ray_batch *batch,
                    size_t first, size_t count, kdr_query query,
                    kdr_trav_mode mode, kdr_hits *out, kdr_trav_stats *stats) {
    (void)mode;
    if (!scene || !batch || !out || !batch->org || !batch->dir)
        return KDR_EINVAL;
    if (first > batch->n || count > batch->n - first)
        return KDR_EINVAL;
    for (size_t i = first; i < first + count; i++) {
        kdr_ray r;
        batch_ray(batch, i, &r);
        if (query == KDR_ANY) {
            out->hit[i] = (uint8_t)kdr_occluded1(scene, &r, stats);
        } else {
            kdr_hit h;
            kdr_intersect1(scene, &r, &h, stats);
            out->t[i] = h.t;
            out->prim[i] = h.prim;
            out->u[i] = h.u;
            out->v[i] = h.v;
        }
    }
    return KDR_OK;
}
