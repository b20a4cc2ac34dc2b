/*
 * kd_build_avx512.c — the AVX-512 kernels of the SAH build's split search
 * (kd_build.h): the same two passes as kd_build_sah.c's kd_group_events
 * and kd_eval_groups, 16 events or 16 groups at a time, with the same
 * results bit for bit (tests/test_core_build_simd.c compares them on
 * random lists). The build calls them when kd_cpu_has_avx512() said yes
 * (builder.avx512).
 *
 * The ISA's intrinsics live here, apart from the algorithm, rather than in
 * simd.h: simd.h is the traversal's lane layer (floats and lane masks),
 * these kernels are about 64-bit event keys, prefix counts and compress.
 *
 * Bit for bit: the SAH of a plane is computed with the same float
 * operations in the same order as sah_cost (no FMA: -ffp-contract=off and
 * explicit mul/add), counts are converted from int32 (exact below 2^24,
 * and rounded as the int64 conversion rounds above), and of equal costs
 * the first group wins, as in a sweep that replaces only on "<".
 */
#include <immintrin.h>
#include <math.h>
#include <string.h>

#include "kd_build.h"
#include "simd.h"

/* Events e[0..16) masked to the first n, as two 8-event halves. */
KD_AVX512 static inline void load16_raw(const kd_event *e, size_t n, __m512i *a,
                                        __m512i *b) {
    const __mmask8 m0 = (__mmask8)(n >= 8 ? 0xff : (1u << n) - 1);
    const __mmask8 m1 = (__mmask8)(n >= 16 ? 0xff : n > 8 ? (1u << (n - 8)) - 1 : 0);
    *a = _mm512_maskz_loadu_epi64(m0, e);
    *b = _mm512_maskz_loadu_epi64(m1, e + 8);
}

/* Lanes 0..15 of the keys (the events' high dwords, one two-source
 * permute) and types (bits 30-31 of the low dwords) of e[0..16), masked to
 * the first n lanes (zero beyond). */
KD_AVX512 static inline void load16(const kd_event *e, size_t n, __m512i *key,
                                    __m512i *type) {
    const __m512i hi = _mm512_setr_epi32(1, 3, 5, 7, 9, 11, 13, 15, 17, 19, 21, 23, 25,
                                         27, 29, 31);
    const __m512i lo = _mm512_setr_epi32(0, 2, 4, 6, 8, 10, 12, 14, 16, 18, 20, 22, 24,
                                         26, 28, 30);
    __m512i a, b;
    load16_raw(e, n, &a, &b);
    *key = _mm512_permutex2var_epi32(a, hi, b);
    *type = _mm512_srli_epi32(_mm512_permutex2var_epi32(a, lo, b), 30);
}

/* The keys alone. */
KD_AVX512 static inline __m512i load16_key(const kd_event *e, size_t n) {
    const __m512i hi = _mm512_setr_epi32(1, 3, 5, 7, 9, 11, 13, 15, 17, 19, 21, 23, 25,
                                         27, 29, 31);
    __m512i a, b;
    load16_raw(e, n, &a, &b);
    return _mm512_permutex2var_epi32(a, hi, b);
}

/* Inclusive prefix sum over the 16 lanes. */
KD_AVX512 static inline __m512i prefix16(__m512i x) {
    const __m512i z = _mm512_setzero_si512();
    x = _mm512_add_epi32(x, _mm512_alignr_epi32(x, z, 15));
    x = _mm512_add_epi32(x, _mm512_alignr_epi32(x, z, 14));
    x = _mm512_add_epi32(x, _mm512_alignr_epi32(x, z, 12));
    x = _mm512_add_epi32(x, _mm512_alignr_epi32(x, z, 8));
    return x;
}

KD_AVX512 size_t kd_group_events_avx512(const kd_event *e, size_t n,
                                        const kd_groups *g) {
    size_t ng = 0;
    uint32_t ends = 0, planars = 0;
    const __m512i lane = _mm512_setr_epi32(1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13,
                                           14, 15, 16);
    for (size_t i = 0; i < n; i += 16) {
        const size_t left = n - i;
        __m512i key, type;
        load16(e + i, left, &key, &type);
        /* the next event's key; the list's last event ends its group */
        const __m512i nkey = load16_key(e + i + 1, left - 1);
        const __mmask16 valid = (__mmask16)(left >= 16 ? 0xffff : (1u << left) - 1);
        const __mmask16 tail = (__mmask16)(left > 16 ? 0 : 1u << (left - 1));
        const __mmask16 last =
            (__mmask16)((_mm512_cmpneq_epi32_mask(key, nkey) | tail) & valid);
        const __mmask16 me = _mm512_mask_cmpeq_epi32_mask(valid, type, _mm512_set1_epi32(EV_END));
        const __mmask16 mp =
            _mm512_mask_cmpeq_epi32_mask(valid, type, _mm512_set1_epi32(EV_PLANAR));
        const __m512i ce = _mm512_add_epi32(
            prefix16(_mm512_maskz_set1_epi32(me, 1)), _mm512_set1_epi32((int)ends));
        const __m512i cp = _mm512_add_epi32(
            prefix16(_mm512_maskz_set1_epi32(mp, 1)), _mm512_set1_epi32((int)planars));
        const __m512i idx = _mm512_add_epi32(lane, _mm512_set1_epi32((int)i));
        _mm512_storeu_si512(g->key + ng, _mm512_maskz_compress_epi32(last, key));
        _mm512_storeu_si512(g->ends + ng, _mm512_maskz_compress_epi32(last, ce));
        _mm512_storeu_si512(g->planars + ng, _mm512_maskz_compress_epi32(last, cp));
        _mm512_storeu_si512(g->end + ng, _mm512_maskz_compress_epi32(last, idx));
        ng += (size_t)__builtin_popcount(last);
        ends += (uint32_t)__builtin_popcount(me);
        planars += (uint32_t)__builtin_popcount(mp);
    }
    return ng;
}

/* sah_cost for 16 planes: the same operations in the same order. */
KD_AVX512 static inline __m512 cost16(const sah_ctx *c, __m512 pl, __m512 pr,
                                      __m512i nl, __m512i nr) {
    const __mmask16 empty = _mm512_cmpeq_epi32_mask(nl, _mm512_setzero_si512()) |
                            _mm512_cmpeq_epi32_mask(nr, _mm512_setzero_si512());
    const __m512 eb = _mm512_mask_blend_ps(empty, _mm512_set1_ps(1.0f),
                                           _mm512_set1_ps(1.0f - c->bonus));
    const __m512 sum = _mm512_add_ps(_mm512_mul_ps(pl, _mm512_cvtepi32_ps(nl)),
                                     _mm512_mul_ps(pr, _mm512_cvtepi32_ps(nr)));
    return _mm512_add_ps(_mm512_set1_ps(c->trav),
                         _mm512_mul_ps(_mm512_mul_ps(_mm512_set1_ps(c->isect), eb), sum));
}

KD_AVX512 void kd_eval_groups_avx512(const sah_ctx *c, int k, const kd_groups *g,
                                     size_t ng, size_t ntri, kd_split *best) {
    const __m512 two = _mm512_set1_ps(2.0f), cap = _mm512_set1_ps(c->cap);
    const __m512 perim = _mm512_set1_ps(c->perim), inv = _mm512_set1_ps(c->inv_area);
    const __m512 lo = _mm512_set1_ps(c->min), hi = _mm512_set1_ps(c->max);
    const __m512i vntri = _mm512_set1_epi32((int)ntri);
    const __m512i sign = _mm512_set1_epi32((int)0x80000000u);
    const __m512i low31 = _mm512_set1_epi32(0x7fffffff);
    const __m512 inf = _mm512_set1_ps(INFINITY);
    for (size_t j = 0; j < ng; j += 16) {
        const size_t left = ng - j;
        const __mmask16 valid = (__mmask16)(left >= 16 ? 0xffff : (1u << left) - 1);
        const __m512i key = _mm512_maskz_loadu_epi32(valid, g->key + j);
        const __m512i ends = _mm512_maskz_loadu_epi32(valid, g->ends + j);
        const __m512i planars = _mm512_maskz_loadu_epi32(valid, g->planars + j);
        /* the previous group's entries (zero before the first) */
        __m512i pend, pplanar, pidx;
        if (j == 0) {
            const __mmask16 v1 = (__mmask16)(valid << 1);
            pend = _mm512_maskz_loadu_epi32(v1, g->ends - 1);
            pplanar = _mm512_maskz_loadu_epi32(v1, g->planars - 1);
            pidx = _mm512_maskz_loadu_epi32(v1, g->end - 1);
        } else {
            pend = _mm512_loadu_si512(g->ends + j - 1);
            pplanar = _mm512_loadu_si512(g->planars + j - 1);
            pidx = _mm512_loadu_si512(g->end + j - 1);
        }
        const __m512i nl = _mm512_sub_epi32(pidx, pend);
        const __m512i nr = _mm512_sub_epi32(_mm512_sub_epi32(vntri, ends), planars);
        const __m512i np = _mm512_sub_epi32(planars, pplanar);
        /* key_float: the order-preserving key back to the float's bits */
        const __mmask16 pos = _mm512_test_epi32_mask(key, sign);
        const __m512 p = _mm512_castsi512_ps(_mm512_mask_blend_epi32(
            pos, _mm512_andnot_si512(key, _mm512_set1_epi32(-1)),
            _mm512_and_si512(key, low31)));
        const __mmask16 inside = _mm512_mask_cmp_ps_mask(valid, p, lo, _CMP_GT_OQ) &
                                 _mm512_cmp_ps_mask(p, hi, _CMP_LT_OQ);
        if (!inside)
            continue;
        const __m512 pl = _mm512_mul_ps(
            _mm512_mul_ps(two, _mm512_add_ps(cap, _mm512_mul_ps(_mm512_sub_ps(p, lo), perim))),
            inv);
        const __m512 pr = _mm512_mul_ps(
            _mm512_mul_ps(two, _mm512_add_ps(cap, _mm512_mul_ps(_mm512_sub_ps(hi, p), perim))),
            inv);
        const __m512 cl = cost16(c, pl, pr, _mm512_add_epi32(nl, np), nr);
        const __m512 cr = cost16(c, pl, pr, nl, _mm512_add_epi32(nr, np));
        const __mmask16 left_wins = _mm512_cmp_ps_mask(cl, cr, _CMP_LE_OQ);
        __m512 cost = _mm512_mask_blend_ps(left_wins, cr, cl);
        cost = _mm512_mask_blend_ps(inside, inf, cost);
        const float m = _mm512_reduce_min_ps(cost);
        if (!(m < best->cost))
            continue;
        const __mmask16 at = _mm512_cmp_ps_mask(cost, _mm512_set1_ps(m), _CMP_EQ_OQ);
        const int l = __builtin_ctz((unsigned)at);
        float pv[16];
        _mm512_storeu_ps(pv, p);
        best->cost = m;
        best->axis = k;
        best->pos = pv[l];
        best->planar_left = (left_wins >> l) & 1u;
    }
}

/* ---- the straddlers' new events: rank sort ---------------------------------- */

KD_AVX512 void kd_rank_sort_avx512(kd_event *a, size_t n) {
    const __m512i top = _mm512_set1_epi64((long long)UINT64_MAX); /* never smaller */
    kd_event tmp[RANK_MAX];
    __m512i v[RANK_MAX / 8];
    for (size_t q = 0; q < RANK_MAX / 8; q++) {
        const size_t first = 8 * q;
        const __mmask8 m =
            (__mmask8)(n >= first + 8 ? 0xff : n > first ? (1u << (n - first)) - 1 : 0);
        v[q] = _mm512_mask_loadu_epi64(top, m, a + first);
        _mm512_storeu_si512(tmp + first, v[q]);
    }
    for (size_t i = 0; i < n; i++) {
        const __m512i x = _mm512_set1_epi64((long long)tmp[i]);
        uint32_t below = 0;
        for (size_t q = 0; q < RANK_MAX / 8; q++)
            below |= (uint32_t)_mm512_cmplt_epu64_mask(v[q], x) << (8 * q);
        a[__builtin_popcount(below)] = tmp[i];
    }
}

/* ---- a split's partition of a list into the children's ----------------------- */

/* kd_partition (kd_build.h), 8 events per step: the 8 triangles' side
 * bytes (read one by one: a gather was not wanted for 8 bytes) are packed
 * into one word, widened to 8 lanes, and each child's events of the step
 * are compressed to the front of a vector stored whole at its pointer,
 * which then advances by their number. A whole store writes at most 8
 * slots from a pointer that is at most i events past its start, so
 * nothing is written beyond n slots from where a list began (the scalar
 * loop's bound); the last n % 8 go through kd_partition itself. */
KD_AVX512 void kd_partition_avx512(const kd_event *in, size_t n, const uint8_t *side,
                                   kd_event *w[2]) {
    kd_event *w0 = w[0], *w1 = w[1];
    const __m512i left = _mm512_set1_epi64(SIDE_LEFT), right = _mm512_set1_epi64(SIDE_RIGHT);
    size_t i = 0;
    for (; i + 8 <= n; i += 8) {
        uint64_t packed = 0;
        for (unsigned j = 0; j < 8; j++)
            packed |= (uint64_t)side[ev_tri(in[i + j])] << (8 * j);
        const __m512i e = _mm512_loadu_si512(in + i);
        const __m512i sd = _mm512_cvtepu8_epi64(_mm_cvtsi64_si128((long long)packed));
        const __mmask8 m0 = _mm512_test_epi64_mask(sd, left);
        const __mmask8 m1 = _mm512_test_epi64_mask(sd, right);
        _mm512_storeu_si512(w0, _mm512_maskz_compress_epi64(m0, e));
        _mm512_storeu_si512(w1, _mm512_maskz_compress_epi64(m1, e));
        w0 += __builtin_popcount(m0);
        w1 += __builtin_popcount(m1);
    }
    w[0] = w0;
    w[1] = w1;
    kd_partition(in + i, n - i, side, w);
}

/* ---- the straddlers' new events: quicksort by compress ---------------------- */

/* kd_sort_events' quicksort step on AVX-512 CPUs for lists of up to
 * QS_MAX events: the same median-of-three pivot, but the partition is
 * without branches on the data: 8 keys per compare, those below the pivot
 * compressed to one scratch list, the others to another (each stored as a
 * whole vector, advanced by the count), then copied back, the lower ones
 * first. Keys are unique and the pivot is the median of three distinct
 * keys, so both parts are non-empty and smaller than the list. A sort's
 * result is unique, so the order is the scalar quicksort's. Longer lists
 * (only near the root) take kd_sort_events' scalar steps. */
#define QS_MAX 1024

KD_AVX512 static void qsort_compress(kd_event *a, size_t n, kd_event *lo, kd_event *hi) {
    while (n > RANK_MAX && n <= QS_MAX) {
        const kd_event x = a[0], y = a[n / 2], z = a[n - 1];
        const kd_event p =
            x < y ? (y < z ? y : (x < z ? z : x)) : (x < z ? x : (y < z ? z : y));
        const __m512i vp = _mm512_set1_epi64((long long)p);
        size_t nl = 0, nh = 0;
        for (size_t i = 0; i < n; i += 8) {
            const size_t left = n - i;
            const __mmask8 valid = (__mmask8)(left >= 8 ? 0xff : (1u << left) - 1);
            const __m512i v = _mm512_maskz_loadu_epi64(valid, a + i);
            const __mmask8 below = _mm512_mask_cmplt_epu64_mask(valid, v, vp);
            const __mmask8 above = (__mmask8)(valid & ~below);
            _mm512_storeu_si512(lo + nl, _mm512_maskz_compress_epi64(below, v));
            _mm512_storeu_si512(hi + nh, _mm512_maskz_compress_epi64(above, v));
            nl += (size_t)__builtin_popcount(below);
            nh += (size_t)__builtin_popcount(above);
        }
        memcpy(a, lo, nl * sizeof *a);
        memcpy(a + nl, hi, nh * sizeof *a);
        /* the smaller part by recursion, the larger one by the loop */
        if (nl <= nh) {
            qsort_compress(a, nl, lo, hi);
            a += nl;
            n = nh;
        } else {
            qsort_compress(a + nl, nh, lo, hi);
            n = nl;
        }
    }
    if (n > QS_MAX)
        kd_sort_events(a, n, 1);
    else
        kd_rank_sort_avx512(a, n);
}

/* (the two scratch lists are the caller's: one pair for the whole sort) */
KD_AVX512 void kd_sort_events_avx512(kd_event *a, size_t n) {
    kd_event lo[QS_MAX + 8], hi[QS_MAX + 8];
    qsort_compress(a, n, lo, hi);
}
