/*
 * kd_batch.c — the batch API (kdr_trace_batch): checks the arguments, picks
 * the bundle width (AUTO: 16 lanes with AVX-512, 8 with AVX2, else 4; or
 * one ray at a time) and
 * owns the per-ray helpers the bundle drivers share: reading ray i of an
 * AoS batch with stride-0 sharing, tracing one ray alone (rays a bundle
 * cannot take), answering a chunk's rays that cannot be traced before it
 * is ordered (kd_batch_live), ordering a chunk for bundles, and telling
 * scattered chunks
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
#include "simd.h"

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

/* 0 when ray i fails the first test of kd_walk_setup (kd_walk.h), with the
 * same float operations: an inf or NaN in the origin or direction (x - x
 * is not 0), a zero direction, or !(tmin <= tmax), NaN included. */
static inline int ray_traceable(const kdr_ray_batch *b, size_t i) {
    const float *o = b->org + b->org_stride * i, *d = b->dir + 3 * i;
    const float tmin = b->tmin ? b->tmin[b->tmin_stride * i] : 0.0f;
    const float tmax = b->tmax ? b->tmax[b->tmax_stride * i] : INFINITY;
    int ok = tmin <= tmax;
    ok &= (d[0] != 0.0f) | (d[1] != 0.0f) | (d[2] != 0.0f);
    for (int k = 0; k < 3; k++)
        ok &= (o[k] - o[k] == 0.0f) & (d[k] - d[k] == 0.0f);
    return ok;
}

/* Three floats per ray (rays i..i+3 from p): 1 when all twelve are finite
 * (x - x == 0, as ray_traceable) and, with dir != 0, no ray's three are
 * all zero. */
static inline int four_ok(const float *p, int dir) {
    const f4 z = f4_set1(0.0f);
    const f4 a = f4_loadu(p), b = f4_loadu(p + 4), c = f4_loadu(p + 8);
    const f4 fin = f4_and(f4_and(f4_eq(f4_sub(a, a), z), f4_eq(f4_sub(b, b), z)),
                          f4_eq(f4_sub(c, c), z));
    if (f4_bits(fin) != 15)
        return 0;
    if (!dir)
        return 1;
    /* bit 3r + k: component k of ray r is 0; a ray is flat when its
     * three bits are set */
    const int zm = f4_bits(f4_eq(a, z)) | f4_bits(f4_eq(b, z)) << 4 |
                   f4_bits(f4_eq(c, z)) << 8;
    return (zm & zm >> 1 & zm >> 2 & 0x249) == 0;
}

/* 1 when the n floats from p are all finite (x - x == 0). */
static int floats_finite(const float *p, size_t n) {
    const f4 z = f4_set1(0.0f);
    f4 fin = f4_eq(z, z);
    size_t j = 0;
    for (; j + 4 <= n; j += 4) {
        const f4 v = f4_loadu(p + j);
        fin = f4_and(fin, f4_eq(f4_sub(v, v), z));
    }
    int fine = f4_bits(fin) == 15;
    for (; j < n; j++)
        fine &= p[j] - p[j] == 0.0f;
    return fine;
}

/* 1 when the count directions from d (3 floats each) are all finite and
 * none is 0 in all three components: four rays (three vectors) at a time,
 * bit 3r + k of zm telling that component k of ray r is 0. */
static int dirs_fine(const float *d, size_t count) {
    const f4 z = f4_set1(0.0f);
    f4 fin = f4_eq(z, z);
    int flat = 0;
    size_t i = 0;
    for (; i + 4 <= count; i += 4) {
        const float *p = d + 3 * i;
        const f4 a = f4_loadu(p), b = f4_loadu(p + 4), c = f4_loadu(p + 8);
        fin = f4_and(fin, f4_and(f4_and(f4_eq(f4_sub(a, a), z), f4_eq(f4_sub(b, b), z)),
                                 f4_eq(f4_sub(c, c), z)));
        const int zm = f4_bits(f4_eq(a, z)) | f4_bits(f4_eq(b, z)) << 4 |
                       f4_bits(f4_eq(c, z)) << 8;
        flat |= zm & zm >> 1 & zm >> 2 & 0x249;
    }
    int fine = f4_bits(fin) == 15 && !flat;
    for (; i < count; i++) {
        const float *p = d + 3 * i;
        fine &= (p[0] - p[0] == 0.0f) & (p[1] - p[1] == 0.0f) & (p[2] - p[2] == 0.0f);
        fine &= (p[0] != 0.0f) | (p[1] != 0.0f) | (p[2] != 0.0f);
    }
    return fine;
}

/* 1 when every ray of [first, first+count) passes ray_traceable (the usual
 * chunk: tested a vector at a time, a few instructions per ray); 0 means
 * some ray may fail. */
static int chunk_traceable(const kdr_ray_batch *b, size_t first, size_t count) {
    if (!dirs_fine(b->dir + 3 * first, count))
        return 0;
    const size_t no = b->org_stride ? 3 * count : 3;
    if (!floats_finite(b->org + b->org_stride * first, no))
        return 0;
    const int vmin = b->tmin && b->tmin_stride, vmax = b->tmax && b->tmax_stride;
    const float lo0 = b->tmin ? b->tmin[vmin ? first : 0] : 0.0f;
    const float hi0 = b->tmax ? b->tmax[vmax ? first : 0] : INFINITY;
    if (!vmin && !vmax)
        return lo0 <= hi0;
    f4 ok = f4_eq(f4_set1(0.0f), f4_set1(0.0f));
    size_t i = first;
    for (; i + 4 <= first + count; i += 4) {
        const f4 lo = vmin ? f4_loadu(b->tmin + i) : f4_set1(lo0);
        const f4 hi = vmax ? f4_loadu(b->tmax + i) : f4_set1(hi0);
        ok = f4_and(ok, f4_le(lo, hi));
    }
    int fine = f4_bits(ok) == 15;
    for (; i < first + count; i++)
        fine &= (vmin ? b->tmin[i] : lo0) <= (vmax ? b->tmax[i] : hi0);
    return fine;
}

size_t kd_batch_live(const kdr_ray_batch *b, size_t first, size_t count, kdr_query q,
                     kdr_hits *out, kdr_trav_stats *stats, size_t *ids) {
    if (chunk_traceable(b, first, count)) {
        for (size_t i = 0; i < count; i++)
            ids[i] = first + i;
        return count;
    }
    /* groups of four rays are tested at once (the usual case: all fine);
     * a group with a doubtful ray, and the last few rays, ray by ray */
    int org_ok = 1; /* a shared origin: tested once */
    if (b->org_stride == 0)
        for (int k = 0; k < 3; k++)
            org_ok &= b->org[k] - b->org[k] == 0.0f;
    const float t_lo = b->tmin ? b->tmin[0] : 0.0f;
    const float t_hi = b->tmax ? b->tmax[0] : INFINITY;
    const int tmin_v = b->tmin && b->tmin_stride, tmax_v = b->tmax && b->tmax_stride;
    size_t m = 0, i = first;
    for (; i + 4 <= first + count; i += 4) {
        int ok = four_ok(b->dir + 3 * i, 1);
        ok &= b->org_stride == 0 ? org_ok : four_ok(b->org + 3 * i, 0);
        const f4 lo = tmin_v ? f4_loadu(b->tmin + i) : f4_set1(t_lo);
        const f4 hi = tmax_v ? f4_loadu(b->tmax + i) : f4_set1(t_hi);
        ok &= f4_bits(f4_le(lo, hi)) == 15;
        if (ok) {
            for (size_t k = 0; k < 4; k++)
                ids[m + k] = i + k;
            m += 4;
            continue;
        }
        for (size_t k = i; k < i + 4; k++) {
            ids[m] = k;
            m += (size_t)ray_traceable(b, k);
        }
    }
    for (; i < first + count; i++) {
        ids[m] = i;
        m += (size_t)ray_traceable(b, i);
    }
    if (m == count)
        return m;
    for (size_t k = first, j = 0; k < first + count; k++) {
        if (j < m && ids[j] == k) {
            j++;
            continue;
        }
        if (q == KDR_ANY) {
            out->hit[k] = 0;
        } else {
            out->t[k] = -1.0f;
            out->prim[k] = -1;
            out->u[k] = out->v[k] = 0.0f;
        }
    }
    if (stats)
        stats->rays += count - m; /* kdr_intersect1 counts them, with no node */
    return m;
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

/* One stable counting-sort pass of positions (indices of key) by bits
 * [shift, shift+KEY_PASS). */
static void sort_pass(const uint32_t *key, const size_t *in, size_t *out,
                      size_t n, int shift) {
    size_t count[1u << KEY_PASS] = {0};
    const uint32_t mask = (1u << KEY_PASS) - 1;
    for (size_t i = 0; i < n; i++)
        count[(key[in[i]] >> shift) & mask]++;
    size_t sum = 0;
    for (uint32_t k = 0; k <= mask; k++) {
        size_t c = count[k];
        count[k] = sum;
        sum += c;
    }
    for (size_t i = 0; i < n; i++)
        out[count[(key[in[i]] >> shift) & mask]++] = in[i];
}

/* Mean spread of the L1-normalised directions over consecutive groups of 8
 * rays (sum over axes of max - min): ~0 for camera tiles, ~2 for random
 * hemisphere or sphere directions. */
/* Rays ids[0..count), or (ids NULL) [first, first+count). */
static float order_spread(const kdr_ray_batch *b, const size_t *ids, size_t first,
                          size_t count) {
    float total = 0.0f;
    size_t groups = 0;
    for (size_t g = 0; g + 8 <= count; g += 8, groups++) {
        float lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
        for (size_t i = g; i < g + 8; i++) {
            const float *d = b->dir + 3 * (ids ? ids[i] : first + i);
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

void kd_batch_order(const kdr_ray_batch *b, size_t count, int sort, size_t *ids) {
    if (!sort || count <= 8 || order_spread(b, ids, 0, count) < KB_SORT_SPREAD)
        return;
    /* rays never leave their run of equal origins (hemisphere rays of one
     * surface point stay one shared-origin group); the direction orders
     * them within it */
    uint32_t key[KB_CHUNK], run = 0;
    size_t pos[KB_CHUNK], tmp[KB_CHUNK];
    for (size_t i = 0; i < count; i++) {
        const float *o = b->org + b->org_stride * ids[i];
        const float *prev = b->org + b->org_stride * ids[i > 0 ? i - 1 : 0];
        if (memcmp(o, prev, 3 * sizeof(float)) != 0)
            run++;
        key[i] = (run > 255 ? 255 : run) << 11 | dir_key(b->dir + 3 * ids[i]);
        pos[i] = i;
    }
    /* sorted are positions in ids (the keys' index), mapped back at the end */
    sort_pass(key, pos, tmp, count, 0);
    sort_pass(key, tmp, pos, count, KEY_PASS);
    sort_pass(key, pos, tmp, count, 2 * KEY_PASS);
    for (size_t i = 0; i < count; i++)
        pos[i] = ids[tmp[i]];
    memcpy(ids, pos, count * sizeof *ids);
}

/* kd_batch_order's run field holds 255 runs: a chunk of at most 256 rays
 * never merges two origins there, so it never moves a ray out of its run
 * (what kd_batch_runs_fit relies on) */
_Static_assert(KB_CHUNK <= 256, "kd_batch_order's run key would merge origins");

int kd_batch_runs_fit(const kdr_ray_batch *b, const size_t *ids, size_t count, size_t w) {
    /* one origin for the whole batch is one run across every bundle */
    if (b->org_stride == 0)
        return 0;
    for (size_t p = w; p < count; p += w)
        if (memcmp(b->org + 3 * ids[p], b->org + 3 * ids[p - 1], 3 * sizeof(float)) == 0)
            return 0;
    return 1;
}

/* kd_batch_scattered with runs of shared origins sent to the walk from
 * scenes of runs_min bytes */
static int scattered(const kdr_scene *s, const kdr_ray_batch *b, size_t first,
                     size_t count, size_t runs_min) {
    if (b->org_stride == 0 || count <= 8)
        return 0;
    size_t runs = 1;
    for (size_t i = first + 1; i < first + count; i++)
        runs += memcmp(b->org + 3 * i, b->org + 3 * (i - 1), 3 * sizeof(float)) != 0;
    /* one origin for the whole chunk (a cone's samples of one point) is
     * the shared-origin case whatever the stride says: bundles */
    if (runs * KD_STREAM_MAX_RUN < count &&
        (runs == 1 || s->stats.bytes < runs_min))
        return 0;
    return order_spread(b, NULL, first, count) >= KB_SORT_SPREAD;
}

int kd_batch_scattered(const kdr_scene *s, const kdr_ray_batch *b, size_t first,
                       size_t count) {
    return scattered(s, b, first, count, KD_STREAM_RUNS_MIN_BYTES);
}

_Static_assert(KD_FAR_RUNS_MIN_BYTES <= KD_STREAM_RUNS_MIN_BYTES,
               "AO runs walked far end first would leave the walk on mid-sized scenes");

int kd_batch_scattered_any(const kdr_scene *s, const kdr_ray_batch *b, size_t first,
                           size_t count) {
    size_t runs_min = KD_STREAM_RUNS_MIN_BYTES;
    if (s->stats.bytes >= KD_FAR_RUNS_MIN_BYTES && s->stats.bytes < runs_min &&
        kd_batch_far_first(s, b, NULL, first, count) == KB_ENDS_SPREAD)
        runs_min = KD_FAR_RUNS_MIN_BYTES;
    return scattered(s, b, first, count, runs_min);
}

#define FAR_SAMPLE 32

int kd_batch_far_first(const kdr_scene *s, const kdr_ray_batch *b, const size_t *ids,
                       size_t first, size_t count) {
    if (b->org_stride == 0 || !b->tmax || count == 0)
        return KB_ENDS_NONE;
    float olo[3], ohi[3], elo[3], ehi[3], len2 = 0.0f;
    for (int k = 0; k < 3; k++)
        olo[k] = elo[k] = INFINITY, ohi[k] = ehi[k] = -INFINITY;
    /* FAR_SAMPLE rays spread over the chunk tell the boxes well enough
     * (every ray cost 2 % of a 4-spp cone query's instructions) */
    const size_t step = count > FAR_SAMPLE ? count / FAR_SAMPLE : 1;
    for (size_t j = 0; j < count; j += step) {
        const size_t i = ids ? ids[j] : first + j;
        const float *o = b->org + 3 * i, *d = b->dir + 3 * i;
        const float tmax = b->tmax[b->tmax_stride * i];
        float l2 = 0.0f;
        for (int k = 0; k < 3; k++) {
            const float e = o[k] + tmax * d[k];
            l2 += (tmax * d[k]) * (tmax * d[k]);
            if (!(e - e == 0.0f)) /* no finite end (tmax = inf, NaN) */
                return KB_ENDS_NONE;
            olo[k] = o[k] < olo[k] ? o[k] : olo[k];
            ohi[k] = o[k] > ohi[k] ? o[k] : ohi[k];
            elo[k] = e < elo[k] ? e : elo[k];
            ehi[k] = e > ehi[k] ? e : ehi[k];
        }
        len2 = l2 > len2 ? l2 : len2;
    }
    float ow = 0.0f, ew = 0.0f;
    for (int k = 0; k < 3; k++) {
        ow = ohi[k] - olo[k] > ow ? ohi[k] - olo[k] : ow;
        ew = ehi[k] - elo[k] > ew ? ehi[k] - elo[k] : ew;
    }
    /* one origin over the sample (a point's samples in stride 3): its
     * path replay stays, as with stride 0 */
    if (ow == 0.0f)
        return KB_ENDS_NONE;
    if (ew < KD_FAR_END_SPREAD * ow)
        return KB_ENDS_CLUSTER;
    /* spread ends: short rays (AO) are KB_ENDS_SPREAD, longer ones (toward
     * a large light) KB_ENDS_LONG: far end first unstaged */
    const float lim = KD_FAR_SPREAD_MAX_LEN * s->diagonal;
    return len2 <= lim * lim ? KB_ENDS_SPREAD : KB_ENDS_LONG;
}

void kd_batch_bundles(const kdr_scene *s, const kdr_ray_batch *b, size_t first,
                      size_t count, kdr_query q, int flags, int max_width,
                      kdr_hits *out, kdr_trav_stats *stats) {
    if (!s->nodes)
        for (size_t i = first; i < first + count; i++)
            kd_batch_single(s, b, i, q, out, stats);
    else if (max_width >= 16 && kd_cpu_has_avx512())
        kd_bundle16_trace(s, b, first, count, q, flags, out, stats);
    else if (max_width >= 8 && kdr_cpu_has_avx2())
        kd_bundle8_trace(s, b, first, count, q, flags, out, stats);
    else
        kd_bundle4_trace(s, b, first, count, q, flags, out, stats);
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
    if (mode == KDR_TRAV_SINGLE) {
        for (size_t i = first; i < first + count; i++)
            kd_batch_single(scene, batch, i, query, out, stats);
        return KDR_OK;
    }
    /* AUTO: 16-wide bundles with AVX-512 (docs/TRAVERSAL.md, Bundles) */
    const int width = mode == KDR_TRAV_AUTO ? 16 : mode == KDR_TRAV_BUNDLE8 ? 8 : 4;
    kd_batch_bundles(scene, batch, first, count, query,
                     KB_FALLBACK | KB_SORT | KB_LIVE | KB_FAR_AUTO, width, out, stats);
    return KDR_OK;
}
