/*
 * kd_batch.c — the batch API (kdr_trace_batch): checks the arguments, picks
 * the bundle width (8 lanes with AVX2, else 4, or one ray at a time) and
 * owns the per-ray helpers the bundle drivers share: reading ray i of an
 * AoS batch with stride-0 sharing, tracing one ray alone (rays a bundle
 * cannot take), ordering a chunk for bundles, and telling scattered chunks
 * (incoherent rays with their own origins), which go to the interleaved
 * walk of kd_stream.h instead.
 */
#include <math.h>
#include <stddef.h>
#include <string.h>

#include "kd_internal.h"
#include "kd_stream.h"
#include "kd_traverse.h"
#include "kd_traverse_bundle.h"

/* libgcc's constructor has run the CPU detection before main; calling
 * __builtin_cpu_init here again would race between threads. */
int kdr_cpu_has_avx2(void) { return __builtin_cpu_supports("avx2") ? 1 : 0; }

void kd_batch_read(const kdr_ray_batch *b, size_t i, kdr_ray *r) {
    const float *o = b->org + b->org_stride * i;
    const float *d = b->dir + 3 * i;
    for (int k = 0; k < 3; k++) {
        r->org[k] = o[k];
        r->dir[k] = d[k];
    }
    r->tmin = b->tmin ? b->tmin[b->tmin_stride * i] : 0.0f;
    r->tmax = b->tmax ? b->tmax[b->tmax_stride * i] : INFINITY;
}

void kd_batch_single(const kdr_scene *s, const kdr_ray_batch *b, size_t i,
                     kdr_query q, kdr_hits *out, kdr_trav_stats *stats) {
    kdr_ray r;
    kd_batch_read(b, i, &r);
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

/* Direction key: octant (3 bits) above a 4+4-bit Morton code of the
 * direction's L1-normalised |x| and |y| (its position within the octant). */
static uint32_t dir_key(const float *d) {
    const float ax = fabsf(d[0]), ay = fabsf(d[1]), az = fabsf(d[2]);
    const float l1 = ax + ay + az;
    float a = ax / l1, b = ay / l1; /* NaN for bad rays: any key will do */
    uint32_t qa = a >= 0.0f && a <= 1.0f ? (uint32_t)(a * 15.99f) : 0;
    uint32_t qb = b >= 0.0f && b <= 1.0f ? (uint32_t)(b * 15.99f) : 0;
    uint32_t m = 0;
    for (int i = 0; i < 4; i++)
        m |= ((qa >> i) & 1u) << (2 * i + 1) | ((qb >> i) & 1u) << (2 * i);
    const uint32_t oct = (uint32_t)(signbit(d[0]) != 0) << 2 |
                         (uint32_t)(signbit(d[1]) != 0) << 1 |
                         (uint32_t)(signbit(d[2]) != 0);
    return oct << 8 | m;
}

/* Keys: origin run (8 bits) above the direction key (11 bits): three
 * counting-sort passes of 7 bits. */
#define KEY_PASS 7

/* One stable counting-sort pass of ids by bits [shift, shift+KEY_PASS). */
static void sort_pass(const uint32_t *key, const size_t *in, size_t *out,
                      size_t n, size_t first, int shift) {
    size_t count[1u << KEY_PASS] = {0};
    const uint32_t mask = (1u << KEY_PASS) - 1;
    for (size_t i = 0; i < n; i++)
        count[(key[in[i] - first] >> shift) & mask]++;
    size_t sum = 0;
    for (uint32_t k = 0; k <= mask; k++) {
        size_t c = count[k];
        count[k] = sum;
        sum += c;
    }
    for (size_t i = 0; i < n; i++)
        out[count[(key[in[i] - first] >> shift) & mask]++] = in[i];
}

/* Mean spread of the L1-normalised directions over consecutive groups of 8
 * rays (sum over axes of max - min): ~0 for camera tiles, ~2 for random
 * hemisphere or sphere directions. */
static float order_spread(const kdr_ray_batch *b, size_t first, size_t count) {
    float total = 0.0f;
    size_t groups = 0;
    for (size_t g = 0; g + 8 <= count; g += 8, groups++) {
        float lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
        for (size_t i = g; i < g + 8; i++) {
            const float *d = b->dir + 3 * (first + i);
            const float r1 = 1.0f / (fabsf(d[0]) + fabsf(d[1]) + fabsf(d[2]));
            for (int k = 0; k < 3; k++) {
                const float x = d[k] * r1;
                lo[k] = x < lo[k] ? x : lo[k]; /* NaN (bad ray) ignored */
                hi[k] = x > hi[k] ? x : hi[k];
            }
        }
        for (int k = 0; k < 3; k++)
            total += hi[k] > lo[k] ? hi[k] - lo[k] : 0.0f;
    }
    return groups ? total / (float)groups : 0.0f;
}

void kd_batch_order(const kdr_ray_batch *b, size_t first, size_t count,
                    int sort, size_t *ids) {
    for (size_t i = 0; i < count; i++)
        ids[i] = first + i;
    if (!sort || count <= 8 || order_spread(b, first, count) < KB_SORT_SPREAD)
        return;
    /* rays never leave their run of equal origins (hemisphere rays of one
     * surface point stay one shared-origin group); the direction orders
     * them within it */
    uint32_t key[KB_CHUNK], run = 0;
    size_t tmp[KB_CHUNK];
    for (size_t i = 0; i < count; i++) {
        const float *o = b->org + b->org_stride * (first + i);
        if (i > 0 && memcmp(o, o - b->org_stride, 3 * sizeof(float)) != 0)
            run++;
        key[i] = (run > 255 ? 255 : run) << 11 | dir_key(b->dir + 3 * (first + i));
    }
    sort_pass(key, ids, tmp, count, first, 0);
    sort_pass(key, tmp, ids, count, first, KEY_PASS);
    sort_pass(key, ids, tmp, count, first, 2 * KEY_PASS);
    memcpy(ids, tmp, count * sizeof *ids);
}

int kd_batch_scattered(const kdr_scene *s, const kdr_ray_batch *b, size_t first,
                       size_t count) {
    if (b->org_stride == 0 || count <= 8)
        return 0;
    size_t runs = 1;
    for (size_t i = first + 1; i < first + count; i++)
        runs += memcmp(b->org + 3 * i, b->org + 3 * (i - 1), 3 * sizeof(float)) != 0;
    /* one origin for the whole chunk (a cone's samples of one point) is
     * the shared-origin case whatever the stride says: bundles */
    if (runs * KD_STREAM_MAX_RUN < count &&
        (runs == 1 || s->stats.bytes < KD_STREAM_RUNS_MIN_BYTES))
        return 0;
    return order_spread(b, first, count) >= KB_SORT_SPREAD;
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
        kd_bundle8_trace(scene, batch, first, count, query, KB_FALLBACK | KB_SORT,
                         out, stats);
        break;
    case KDR_TRAV_BUNDLE4:
        kd_bundle4_trace(scene, batch, first, count, query, KB_FALLBACK | KB_SORT,
                         out, stats);
        break;
    default:
        for (size_t i = first; i < first + count; i++)
            kd_batch_single(scene, batch, i, query, out, stats);
    }
    return KDR_OK;
}
