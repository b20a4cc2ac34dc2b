/*
 * kd_batch.c — the batch API (kdr_trace_batch): checks the arguments, picks
 * the bundle width (8 lanes with AVX2, else 4, or one ray at a time) and
 * owns the per-ray helpers the bundle drivers share: reading ray i of an
 * AoS batch with stride-0 sharing, and tracing one ray alone (rays a bundle
 * cannot take, and incoherent stretches).
 */
#include <stddef.h>

#include "kd_internal.h"
#include "kd_traverse.h"
#include "kd_traverse_bundle.h"

int kdr_cpu_has_avx2(void) {
    __builtin_cpu_init();
    return __builtin_cpu_supports("avx2") ? 1 : 0;
}

/* Ray i with stride-0 fields shared; absent tmin/tmax mean 0 / +inf. */
static void batch_read(const kdr_ray_batch *b, size_t i, kdr_ray *r) {
    const float *o = b->org + b->org_stride * i;
    const float *d = b->dir + 3 * i;
    for (int k = 0; k < 3; k++) {
        r->org[k] = o[k];
        r->dir[k] = d[k];
    }
    r->tmin = b->tmin ? b->tmin[b->tmin_stride * i] : 0.0f;
    r->tmax = b->tmax ? b->tmax[b->tmax_stride * i] : INFINITY;
}

/* Bundles assume t >= 0 (the paper's "negative distance is +inf" would be
 * wrong behind the origin), so a negative tmin goes alone as well. */
int kd_batch_ray(const kdr_ray_batch *b, size_t i, kdr_ray *r) {
    batch_read(b, i, r);
    return kd_ray_valid(r->org, r->dir, r->tmin, r->tmax) && r->tmin >= 0.0f;
}

void kd_batch_single(const kdr_scene *s, const kdr_ray_batch *b, size_t i,
                     kdr_query q, kdr_hits *out, kdr_trav_stats *stats) {
    kdr_ray r;
    batch_read(b, i, &r);
    if (q == KDR_ANY) {
        out->hit[i] = (uint8_t)kdr_occluded1(s, &r, stats);
        return;
    }
    kdr_hit h;
    kdr_intersect1(s, &r, &h, stats);
    out->t[i] = h.t;
    out->prim[i] = h.prim;
    out->u[i] = h.u;
    out->v[i] = h.v;
}

static int batch_args_ok(const kdr_ray_batch *b, size_t first, size_t count,
                         kdr_query q, const kdr_hits *out) {
    if (!b || !out || !b->org || !b->dir)
        return 0;
    if (b->org_stride != 0 && b->org_stride != 3)
        return 0;
    if ((b->tmin && b->tmin_stride > 1) || (b->tmax && b->tmax_stride > 1))
        return 0;
    if (first > b->n || count > b->n - first)
        return 0;
    if (q == KDR_ANY)
        return out->hit != NULL;
    return q == KDR_CLOSEST && out->t && out->prim && out->u && out->v;
}

int kdr_trace_batch(const kdr_scene *scene, const kdr_ray_batch *batch,
                    size_t first, size_t count, kdr_query query,
                    kdr_trav_mode mode, kdr_hits *out, kdr_trav_stats *stats) {
    if (!scene || !batch_args_ok(batch, first, count, query, out))
        return KDR_EINVAL;
    if (mode < KDR_TRAV_AUTO || mode > KDR_TRAV_BUNDLE8)
        return KDR_EINVAL;
    if (mode == KDR_TRAV_AUTO || mode == KDR_TRAV_BUNDLE8)
        mode = kdr_cpu_has_avx2() ? KDR_TRAV_BUNDLE8 : KDR_TRAV_BUNDLE4;
    if (!scene->nodes)
        mode = KDR_TRAV_SINGLE; /* nothing to bundle over */
    switch (mode) {
    case KDR_TRAV_BUNDLE8:
        kd_bundle8_trace(scene, batch, first, count, query, 1, out, stats);
        break;
    case KDR_TRAV_BUNDLE4:
        kd_bundle4_trace(scene, batch, first, count, query, 1, out, stats);
        break;
    default:
        for (size_t i = first; i < first + count; i++)
            kd_batch_single(scene, batch, i, query, out, stats);
    }
    return KDR_OK;
}
