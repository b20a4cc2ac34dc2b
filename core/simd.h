/*
 * simd.h — the lane layer shared by bundle, cone and frustum traversal:
 * 4-wide helpers (f4_*, SSE2, the x86-64 baseline) and 8-wide helpers
 * (f8_*, AVX2). The build has no -mavx2 flag, so every 8-wide helper carries
 * KD_AVX2 (a target attribute); call them only from functions that carry
 * KD_AVX2 too, and only after kdr_cpu_has_avx2() said yes.
 *
 * Masks are float vectors whose lanes are all-ones or all-zeros, as the
 * compare instructions produce them; f*_sel(m, a, b) picks a where m is set.
 * min/max keep the hardware rule that matters to traversal: when either
 * operand is NaN the SECOND operand is returned, so f4_min(d, t_far) with a
 * NaN d yields t_far.
 *
 * The interleaved walk of incoherent batches (kd_traverse_stream_lanes.h)
 * holds one ray per lane at 8 (AVX2: f8_, i8_) or 16 lanes (AVX-512 F/DQ/
 * BW/VL: f16_, i16_, KD_AVX512); its helpers take lane masks as plain bits.
 * Call 16-lane helpers only from KD_AVX512 functions after
 * kd_cpu_has_avx512() said yes.
 *
 * Only plain IEEE operations here (no FMA, no approximate reciprocals), so
 * that SIMD code can reproduce scalar results bit for bit. Every intrinsic
 * of core/ lives in this file; code written once for both widths uses the
 * template convention of simd_width.h (VF, V(op), KD_WN, KD_FN).
 */
#ifndef KD_SIMD_H
#define KD_SIMD_H

#include <immintrin.h>
#include <stdint.h>

#define KD_AVX2 __attribute__((target("avx2")))
#define KD_AVX512 __attribute__((target("avx2,avx512f,avx512dq,avx512bw,avx512vl")))

/* ---- 4 lanes (SSE2) ------------------------------------------------------ */

typedef __m128 f4;

static inline f4 f4_set1(float x) { return _mm_set1_ps(x); }
static inline f4 f4_load(const float *p) { return _mm_load_ps(p); }
static inline f4 f4_loadu(const float *p) { return _mm_loadu_ps(p); }
static inline void f4_store(float *p, f4 a) { _mm_store_ps(p, a); }
static inline f4 f4_add(f4 a, f4 b) { return _mm_add_ps(a, b); }
static inline f4 f4_sub(f4 a, f4 b) { return _mm_sub_ps(a, b); }
static inline f4 f4_mul(f4 a, f4 b) { return _mm_mul_ps(a, b); }
static inline f4 f4_div(f4 a, f4 b) { return _mm_div_ps(a, b); }
static inline f4 f4_min(f4 a, f4 b) { return _mm_min_ps(a, b); }
static inline f4 f4_max(f4 a, f4 b) { return _mm_max_ps(a, b); }
static inline f4 f4_lt(f4 a, f4 b) { return _mm_cmplt_ps(a, b); }
static inline f4 f4_le(f4 a, f4 b) { return _mm_cmple_ps(a, b); }
static inline f4 f4_gt(f4 a, f4 b) { return _mm_cmpgt_ps(a, b); }
static inline f4 f4_eq(f4 a, f4 b) { return _mm_cmpeq_ps(a, b); }
static inline f4 f4_ord(f4 a, f4 b) { return _mm_cmpord_ps(a, b); }
static inline f4 f4_and(f4 a, f4 b) { return _mm_and_ps(a, b); }
static inline f4 f4_or(f4 a, f4 b) { return _mm_or_ps(a, b); }
static inline f4 f4_andnot(f4 m, f4 a) { return _mm_andnot_ps(m, a); }
static inline f4 f4_xor(f4 a, f4 b) { return _mm_xor_ps(a, b); }
static inline f4 f4_sel(f4 m, f4 a, f4 b) {
    return _mm_or_ps(_mm_and_ps(m, a), _mm_andnot_ps(m, b));
}
static inline int f4_bits(f4 m) { return _mm_movemask_ps(m); }
/* all-ones in lanes whose sign bit is set (including -0.0 and -NaN) */
static inline f4 f4_signmask(f4 a) {
    return _mm_castsi128_ps(_mm_srai_epi32(_mm_castps_si128(a), 31));
}
static inline f4 f4_bitmask(int bits) {
    const __m128i lane = _mm_setr_epi32(1, 2, 4, 8);
    __m128i b = _mm_and_si128(_mm_set1_epi32(bits), lane);
    return _mm_castsi128_ps(_mm_cmpeq_epi32(b, lane));
}
/* int32 lanes carried in a float vector (selects are bitwise) */
static inline f4 f4_seti(int32_t x) { return _mm_castsi128_ps(_mm_set1_epi32(x)); }
/* Per-lane counters: +1 in the lanes of mask m (all-ones is -1 as int32). */
static inline f4 f4_count(f4 acc, f4 m) {
    return _mm_castsi128_ps(_mm_sub_epi32(_mm_castps_si128(acc), _mm_castps_si128(m)));
}
/* Sum of the int32 lanes of a counter. */
static inline uint64_t f4_count_sum(f4 acc) {
    _Alignas(16) int32_t v[4];
    _mm_store_si128((__m128i *)v, _mm_castps_si128(acc));
    return (uint64_t)v[0] + (uint64_t)v[1] + (uint64_t)v[2] + (uint64_t)v[3];
}

/* a == b and a < b on int32 lanes carried in float vectors */
static inline f4 f4_ieq(f4 a, f4 b) {
    return _mm_castsi128_ps(_mm_cmpeq_epi32(_mm_castps_si128(a), _mm_castps_si128(b)));
}
static inline f4 f4_ilt(f4 a, f4 b) {
    return _mm_castsi128_ps(_mm_cmplt_epi32(_mm_castps_si128(a), _mm_castps_si128(b)));
}
/* Lanes [0, 2) to lo[0..1], lanes [2, 4) to hi[0..1] (unaligned). */
static inline void f4_store_halves(float *lo, float *hi, f4 a) {
    _mm_storel_pi((__m64 *)(void *)lo, a);
    _mm_storeh_pi((__m64 *)(void *)hi, a);
}
/* Floats off..off+3 of rows r[0..3], transposed: lane j of c[i] is
 * r[j][off + i] (unaligned rows). */
static inline void f4_rows4(const float *const r[4], int off, f4 c[4]) {
    f4 a = _mm_loadu_ps(r[0] + off), b = _mm_loadu_ps(r[1] + off),
       d = _mm_loadu_ps(r[2] + off), e = _mm_loadu_ps(r[3] + off);
    _MM_TRANSPOSE4_PS(a, b, d, e);
    c[0] = a, c[1] = b, c[2] = d, c[3] = e;
}

/* The transpose of c[0..3] to rows: r[j][off + i] = lane j of c[i]
 * (unaligned rows); f4_rows4's inverse. */
static inline void f4_to_rows4(const f4 c[4], float *const r[4], int off) {
    f4 a = c[0], b = c[1], d = c[2], e = c[3];
    _MM_TRANSPOSE4_PS(a, b, d, e);
    _mm_storeu_ps(r[0] + off, a);
    _mm_storeu_ps(r[1] + off, b);
    _mm_storeu_ps(r[2] + off, d);
    _mm_storeu_ps(r[3] + off, e);
}

/* The largest / smallest lane (no NaN lanes). */
static inline float f4_hmax(f4 a) {
    const f4 b = _mm_max_ps(a, _mm_movehl_ps(a, a));
    return _mm_cvtss_f32(_mm_max_ss(b, _mm_shuffle_ps(b, b, 1)));
}
static inline float f4_hmin(f4 a) {
    const f4 b = _mm_min_ps(a, _mm_movehl_ps(a, a));
    return _mm_cvtss_f32(_mm_min_ss(b, _mm_shuffle_ps(b, b, 1)));
}
/* (x + y) + z of lanes 0..2, in that order (the scalar sum's rounding). */
static inline float f4_sum3(f4 a) {
    const f4 xy = _mm_add_ss(a, _mm_shuffle_ps(a, a, 1));
    return _mm_cvtss_f32(_mm_add_ss(xy, _mm_movehl_ps(a, a)));
}
/* Lane 3 replaced by x (lanes 0..2 of a ray's 3-vectors, loaded as 4). */
static inline f4 f4_lane3(f4 a, float x) {
    const f4 m = _mm_castsi128_ps(_mm_setr_epi32(-1, -1, -1, 0));
    return f4_sel(m, a, _mm_set1_ps(x));
}

/* (x, y, z, 0): a point or box corner as one vector. */
static inline f4 f4_xyz0(float x, float y, float z) { return _mm_setr_ps(x, y, z, 0.0f); }
/* Four 32-bit words (16-byte aligned) as a float vector: a constant mask. */
static inline f4 f4_load_words(const int32_t *p) {
    return _mm_castsi128_ps(_mm_load_si128((const __m128i *)p));
}

/* Number of set bits in a lane mask (<= 8 lanes). A table, because the
 * baseline build has no popcnt instruction and __builtin_popcount would be
 * a library call. */
static inline int kd_lane_count(int bits) {
    static const unsigned char nib[16] = {0, 1, 1, 2, 1, 2, 2, 3,
                                          1, 2, 2, 3, 2, 3, 3, 4};
    return nib[bits & 15] + nib[(bits >> 4) & 15];
}

/* ---- 4 double lanes (AVX2): exact point-triangle tests (kd_closest.c) --- */

typedef __m256d d4;

KD_AVX2 static inline d4 d4_set1(double x) { return _mm256_set1_pd(x); }
KD_AVX2 static inline d4 d4_zero(void) { return _mm256_setzero_pd(); }
/* the four floats of a, widened (exactly) */
KD_AVX2 static inline d4 d4_from_f4(f4 a) { return _mm256_cvtps_pd(a); }
KD_AVX2 static inline void d4_store(double *p, d4 a) { _mm256_store_pd(p, a); }
KD_AVX2 static inline d4 d4_add(d4 a, d4 b) { return _mm256_add_pd(a, b); }
KD_AVX2 static inline d4 d4_sub(d4 a, d4 b) { return _mm256_sub_pd(a, b); }
KD_AVX2 static inline d4 d4_mul(d4 a, d4 b) { return _mm256_mul_pd(a, b); }
KD_AVX2 static inline d4 d4_div(d4 a, d4 b) { return _mm256_div_pd(a, b); }
KD_AVX2 static inline d4 d4_le(d4 a, d4 b) { return _mm256_cmp_pd(a, b, _CMP_LE_OQ); }
KD_AVX2 static inline d4 d4_ge(d4 a, d4 b) { return _mm256_cmp_pd(a, b, _CMP_GE_OQ); }
KD_AVX2 static inline d4 d4_and(d4 a, d4 b) { return _mm256_and_pd(a, b); }
/* lanes of m: a, others b */
KD_AVX2 static inline d4 d4_sel(d4 m, d4 a, d4 b) { return _mm256_blendv_pd(b, a, m); }
KD_AVX2 static inline d4 d4_load(const double *p) { return _mm256_load_pd(p); }
KD_AVX2 static inline d4 d4_sqrt(d4 a) { return _mm256_sqrt_pd(a); }
KD_AVX2 static inline d4 d4_gt(d4 a, d4 b) { return _mm256_cmp_pd(a, b, _CMP_GT_OQ); }
/* per lane a > b ? a : b, and b where either is NaN (as maxpd) */
KD_AVX2 static inline d4 d4_max(d4 a, d4 b) { return _mm256_max_pd(a, b); }
/* the four doubles rounded to float as a C cast does (to nearest) */
KD_AVX2 static inline f4 d4_to_f4(d4 a) { return _mm256_cvtpd_ps(a); }

/* ---- 8 lanes (AVX2) ------------------------------------------------------ */

typedef __m256 f8;

KD_AVX2 static inline f8 f8_set1(float x) { return _mm256_set1_ps(x); }
KD_AVX2 static inline f8 f8_load(const float *p) { return _mm256_load_ps(p); }
KD_AVX2 static inline void f8_store(float *p, f8 a) { _mm256_store_ps(p, a); }
KD_AVX2 static inline f8 f8_add(f8 a, f8 b) { return _mm256_add_ps(a, b); }
KD_AVX2 static inline f8 f8_sub(f8 a, f8 b) { return _mm256_sub_ps(a, b); }
KD_AVX2 static inline f8 f8_mul(f8 a, f8 b) { return _mm256_mul_ps(a, b); }
KD_AVX2 static inline f8 f8_div(f8 a, f8 b) { return _mm256_div_ps(a, b); }
KD_AVX2 static inline f8 f8_min(f8 a, f8 b) { return _mm256_min_ps(a, b); }
KD_AVX2 static inline f8 f8_max(f8 a, f8 b) { return _mm256_max_ps(a, b); }
KD_AVX2 static inline f8 f8_lt(f8 a, f8 b) { return _mm256_cmp_ps(a, b, _CMP_LT_OQ); }
KD_AVX2 static inline f8 f8_le(f8 a, f8 b) { return _mm256_cmp_ps(a, b, _CMP_LE_OQ); }
KD_AVX2 static inline f8 f8_gt(f8 a, f8 b) { return _mm256_cmp_ps(a, b, _CMP_GT_OQ); }
KD_AVX2 static inline f8 f8_eq(f8 a, f8 b) { return _mm256_cmp_ps(a, b, _CMP_EQ_OQ); }
KD_AVX2 static inline f8 f8_ord(f8 a, f8 b) { return _mm256_cmp_ps(a, b, _CMP_ORD_Q); }
KD_AVX2 static inline f8 f8_and(f8 a, f8 b) { return _mm256_and_ps(a, b); }
KD_AVX2 static inline f8 f8_or(f8 a, f8 b) { return _mm256_or_ps(a, b); }
KD_AVX2 static inline f8 f8_andnot(f8 m, f8 a) { return _mm256_andnot_ps(m, a); }
KD_AVX2 static inline f8 f8_xor(f8 a, f8 b) { return _mm256_xor_ps(a, b); }
KD_AVX2 static inline f8 f8_sel(f8 m, f8 a, f8 b) { return _mm256_blendv_ps(b, a, m); }
KD_AVX2 static inline int f8_bits(f8 m) { return _mm256_movemask_ps(m); }
KD_AVX2 static inline float f8_first(f8 a) { return _mm256_cvtss_f32(a); }
KD_AVX2 static inline f8 f8_signmask(f8 a) {
    return _mm256_castsi256_ps(_mm256_srai_epi32(_mm256_castps_si256(a), 31));
}
KD_AVX2 static inline f8 f8_bitmask(int bits) {
    const __m256i lane = _mm256_setr_epi32(1, 2, 4, 8, 16, 32, 64, 128);
    __m256i b = _mm256_and_si256(_mm256_set1_epi32(bits), lane);
    return _mm256_castsi256_ps(_mm256_cmpeq_epi32(b, lane));
}
KD_AVX2 static inline f8 f8_seti(int32_t x) {
    return _mm256_castsi256_ps(_mm256_set1_epi32(x));
}
KD_AVX2 static inline f8 f8_count(f8 acc, f8 m) {
    return _mm256_castsi256_ps(
        _mm256_sub_epi32(_mm256_castps_si256(acc), _mm256_castps_si256(m)));
}
KD_AVX2 static inline uint64_t f8_count_sum(f8 acc) {
    _Alignas(32) int32_t v[8];
    _mm256_store_si256((__m256i *)v, _mm256_castps_si256(acc));
    uint64_t sum = 0;
    for (int j = 0; j < 8; j++)
        sum += (uint64_t)v[j];
    return sum;
}
KD_AVX2 static inline f8 f8_loadu(const float *p) { return _mm256_loadu_ps(p); }
/* Lane j gets v[idx[j]]; idx holds int32 lane indices (0..7) as bits. */
KD_AVX2 static inline f8 f8_permute(f8 v, f8 idx) {
    return _mm256_permutevar8x32_ps(v, _mm256_castps_si256(idx));
}

KD_AVX2 static inline f8 f8_ieq(f8 a, f8 b) {
    return _mm256_castsi256_ps(
        _mm256_cmpeq_epi32(_mm256_castps_si256(a), _mm256_castps_si256(b)));
}
KD_AVX2 static inline f8 f8_ilt(f8 a, f8 b) {
    return _mm256_castsi256_ps(
        _mm256_cmpgt_epi32(_mm256_castps_si256(b), _mm256_castps_si256(a)));
}
/* Lanes [0, 4) to lo[0..3], lanes [4, 8) to hi[0..3] (unaligned). */
KD_AVX2 static inline void f8_store_halves(float *lo, float *hi, f8 a) {
    _mm_storeu_ps(lo, _mm256_castps256_ps128(a));
    _mm_storeu_ps(hi, _mm256_extractf128_ps(a, 1));
}
/* Floats 0..8 of rows r[0..7], transposed: lane j of c[i] is r[j][i]
 * (unaligned rows of at least 9 floats). */
KD_AVX2 static inline void f8_rows9(const float *const r[8], f8 c[9]) {
    f8 v[8], t[8], u[8];
    for (int j = 0; j < 8; j++)
        v[j] = _mm256_loadu_ps(r[j]);
    for (int j = 0; j < 8; j += 2) {
        t[j] = _mm256_unpacklo_ps(v[j], v[j + 1]);
        t[j + 1] = _mm256_unpackhi_ps(v[j], v[j + 1]);
    }
    for (int h = 0; h < 8; h += 4) { /* rows h..h+3 */
        u[h + 0] = _mm256_shuffle_ps(t[h], t[h + 2], 0x44);
        u[h + 1] = _mm256_shuffle_ps(t[h], t[h + 2], 0xEE);
        u[h + 2] = _mm256_shuffle_ps(t[h + 1], t[h + 3], 0x44);
        u[h + 3] = _mm256_shuffle_ps(t[h + 1], t[h + 3], 0xEE);
    }
    for (int i = 0; i < 4; i++) {
        c[i] = _mm256_permute2f128_ps(u[i], u[4 + i], 0x20);
        c[4 + i] = _mm256_permute2f128_ps(u[i], u[4 + i], 0x31);
    }
    c[8] = _mm256_setr_ps(r[0][8], r[1][8], r[2][8], r[3][8], r[4][8], r[5][8],
                          r[6][8], r[7][8]);
}

/* ---- one ray per lane: 8 (AVX2) and 16 (AVX-512) ------------------------
 * The interleaved walk (kd_traverse_stream_lanes.h) keeps a different ray
 * at a different node in every lane: node words are gathered per lane,
 * stack entries written per lane, and masks are plain lane bits (unsigned,
 * bit j = lane j), which AVX-512 compares give directly and AVX2 compares
 * give through movemask. Same names at both widths (f8_/i8_, f16_/i16_),
 * so the template is written once. */

typedef __m256i i8;

/* lanes of bit mask m: a, others b */
KD_AVX2 static inline f8 f8_selm(unsigned m, f8 a, f8 b) {
    return _mm256_blendv_ps(b, a, f8_bitmask((int)m));
}
/* lanes of m where !(a < b) / !(a > b), so a NaN lane is set */
KD_AVX2 static inline unsigned f8_nlt(unsigned m, f8 a, f8 b) {
    return m & (unsigned)_mm256_movemask_ps(_mm256_cmp_ps(a, b, _CMP_NLT_UQ));
}
KD_AVX2 static inline unsigned f8_ngt(unsigned m, f8 a, f8 b) {
    return m & (unsigned)_mm256_movemask_ps(_mm256_cmp_ps(a, b, _CMP_NGT_UQ));
}
/* lanes whose sign bit is set (-0.0 and -inf included) */
KD_AVX2 static inline unsigned f8_signs(f8 a) { return (unsigned)_mm256_movemask_ps(a); }
/* the lanes of m set to x */
KD_AVX2 static inline f8 f8_put(f8 v, unsigned m, float x) {
    return f8_selm(m, _mm256_set1_ps(x), v);
}
/* the float at byte offset 8 * idx of base in the lanes of m (others: src) */
KD_AVX2 static inline f8 f8_gather8(f8 src, unsigned m, i8 idx, const void *base) {
    return _mm256_mask_i32gather_ps(src, (const float *)base, idx, f8_bitmask((int)m), 8);
}
/* base[idx] = a in the lanes of m (AVX2 has no scatter: lane by lane) */
KD_AVX2 static inline void f8_scatter(float *base, unsigned m, i8 idx, f8 a) {
    _Alignas(32) int32_t iv[8];
    _Alignas(32) float av[8];
    _mm256_store_si256((__m256i *)iv, idx);
    _mm256_store_ps(av, a);
    for (; m; m &= m - 1)
        base[iv[__builtin_ctz(m)]] = av[__builtin_ctz(m)];
}

KD_AVX2 static inline i8 i8_set1(int32_t x) { return _mm256_set1_epi32(x); }
KD_AVX2 static inline i8 i8_iota(void) { return _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7); }
KD_AVX2 static inline i8 i8_add(i8 a, i8 b) { return _mm256_add_epi32(a, b); }
/* a + b in the lanes of m, a elsewhere */
KD_AVX2 static inline i8 i8_add_in(unsigned m, i8 a, i8 b) {
    return _mm256_add_epi32(a, _mm256_and_si256(b, _mm256_castps_si256(f8_bitmask((int)m))));
}
KD_AVX2 static inline i8 i8_and(i8 a, i8 b) { return _mm256_and_si256(a, b); }
KD_AVX2 static inline i8 i8_srl(i8 a, int n) { return _mm256_srli_epi32(a, n); }
KD_AVX2 static inline i8 i8_sll(i8 a, int n) { return _mm256_slli_epi32(a, n); }
KD_AVX2 static inline i8 i8_selm(unsigned m, i8 a, i8 b) {
    return _mm256_castps_si256(
        f8_selm(m, _mm256_castsi256_ps(a), _mm256_castsi256_ps(b)));
}
/* lanes of m where a == b / where a & b != 0 */
KD_AVX2 static inline unsigned i8_eq(unsigned m, i8 a, i8 b) {
    return m & (unsigned)_mm256_movemask_ps(_mm256_castsi256_ps(_mm256_cmpeq_epi32(a, b)));
}
KD_AVX2 static inline unsigned i8_test(i8 a, i8 b) {
    const __m256i z = _mm256_cmpeq_epi32(_mm256_and_si256(a, b), _mm256_setzero_si256());
    return ~(unsigned)_mm256_movemask_ps(_mm256_castsi256_ps(z)) & 0xFFu;
}
KD_AVX2 static inline i8 i8_put(i8 v, unsigned m, int32_t x) {
    return i8_selm(m, _mm256_set1_epi32(x), v);
}
KD_AVX2 static inline void i8_store(int32_t *p, i8 a) { _mm256_store_si256((__m256i *)p, a); }
KD_AVX2 static inline i8 i8_gather8(i8 src, unsigned m, i8 idx, const void *base) {
    return _mm256_mask_i32gather_epi32(src, (const int *)base, idx,
                                       _mm256_castps_si256(f8_bitmask((int)m)), 8);
}
KD_AVX2 static inline void i8_scatter(int32_t *base, unsigned m, i8 idx, i8 a) {
    _Alignas(32) int32_t iv[8], av[8];
    _mm256_store_si256((__m256i *)iv, idx);
    _mm256_store_si256((__m256i *)av, a);
    for (; m; m &= m - 1)
        base[iv[__builtin_ctz(m)]] = av[__builtin_ctz(m)];
}

typedef __m512 f16;
typedef __m512i i16;

KD_AVX512 static inline f16 f16_set1(float x) { return _mm512_set1_ps(x); }
KD_AVX512 static inline f16 f16_add(f16 a, f16 b) { return _mm512_add_ps(a, b); }
KD_AVX512 static inline f16 f16_sub(f16 a, f16 b) { return _mm512_sub_ps(a, b); }
KD_AVX512 static inline f16 f16_mul(f16 a, f16 b) { return _mm512_mul_ps(a, b); }
/* a > b ? a : b and a < b ? a : b, as the scalar ternaries (NaN: b) */
KD_AVX512 static inline f16 f16_max(f16 a, f16 b) { return _mm512_max_ps(a, b); }
KD_AVX512 static inline f16 f16_min(f16 a, f16 b) { return _mm512_min_ps(a, b); }
KD_AVX512 static inline f16 f16_selm(unsigned m, f16 a, f16 b) {
    return _mm512_mask_blend_ps((__mmask16)m, b, a);
}
KD_AVX512 static inline unsigned f16_nlt(unsigned m, f16 a, f16 b) {
    return _mm512_mask_cmp_ps_mask((__mmask16)m, a, b, _CMP_NLT_UQ);
}
KD_AVX512 static inline unsigned f16_ngt(unsigned m, f16 a, f16 b) {
    return _mm512_mask_cmp_ps_mask((__mmask16)m, a, b, _CMP_NGT_UQ);
}
/* lanes of m where a is not a NaN */
KD_AVX512 static inline unsigned f16_ord(unsigned m, f16 a) {
    return _mm512_mask_cmp_ps_mask((__mmask16)m, a, a, _CMP_ORD_Q);
}
KD_AVX512 static inline unsigned f16_signs(f16 a) {
    return _mm512_movepi32_mask(_mm512_castps_si512(a));
}
KD_AVX512 static inline f16 f16_put(f16 v, unsigned m, float x) {
    return _mm512_mask_broadcastss_ps(v, (__mmask16)m, _mm_set_ss(x));
}
KD_AVX512 static inline void f16_store(float *p, f16 a) { _mm512_store_ps(p, a); }
KD_AVX512 static inline f16 f16_loadu(const float *p) { return _mm512_loadu_ps(p); }
/* lane j takes v's lane j - s; lanes below s take fill's (a scan's shift) */
KD_AVX512 static inline f16 f16_up(f16 v, f16 fill, unsigned s) {
    const __m512i idx = _mm512_sub_epi32(
        _mm512_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15),
        _mm512_set1_epi32((int)s));
    return _mm512_mask_permutexvar_ps(fill, (__mmask16)(0xffffu << s), idx, v);
}
KD_AVX512 static inline f16 f16_gather8(f16 src, unsigned m, i16 idx, const void *base) {
    return _mm512_mask_i32gather_ps(src, (__mmask16)m, idx, base, 8);
}
KD_AVX512 static inline void f16_scatter(float *base, unsigned m, i16 idx, f16 a) {
    _mm512_mask_i32scatter_ps(base, (__mmask16)m, idx, a, 4);
}

KD_AVX512 static inline i16 i16_set1(int32_t x) { return _mm512_set1_epi32(x); }
KD_AVX512 static inline i16 i16_iota(void) {
    return _mm512_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
}
KD_AVX512 static inline i16 i16_add(i16 a, i16 b) { return _mm512_add_epi32(a, b); }
KD_AVX512 static inline i16 i16_add_in(unsigned m, i16 a, i16 b) {
    return _mm512_mask_add_epi32(a, (__mmask16)m, a, b);
}
KD_AVX512 static inline i16 i16_and(i16 a, i16 b) { return _mm512_and_si512(a, b); }
KD_AVX512 static inline i16 i16_srl(i16 a, unsigned n) { return _mm512_srli_epi32(a, n); }
KD_AVX512 static inline i16 i16_sll(i16 a, unsigned n) { return _mm512_slli_epi32(a, n); }
KD_AVX512 static inline i16 i16_selm(unsigned m, i16 a, i16 b) {
    return _mm512_mask_blend_epi32((__mmask16)m, b, a);
}
KD_AVX512 static inline unsigned i16_eq(unsigned m, i16 a, i16 b) {
    return _mm512_mask_cmpeq_epi32_mask((__mmask16)m, a, b);
}
KD_AVX512 static inline unsigned i16_test(i16 a, i16 b) {
    return _mm512_test_epi32_mask(a, b);
}
KD_AVX512 static inline i16 i16_put(i16 v, unsigned m, int32_t x) {
    return _mm512_mask_set1_epi32(v, (__mmask16)m, x);
}
KD_AVX512 static inline void i16_store(int32_t *p, i16 a) { _mm512_store_si512(p, a); }
KD_AVX512 static inline i16 i16_gather8(i16 src, unsigned m, i16 idx, const void *base) {
    return _mm512_mask_i32gather_epi32(src, (__mmask16)m, idx, base, 8);
}
KD_AVX512 static inline void i16_scatter(int32_t *base, unsigned m, i16 idx, i16 a) {
    _mm512_mask_i32scatter_epi32(base, (__mmask16)m, idx, a, 4);
}

/* ---- 16 lanes as whole-vector masks (the bundle template) ---------------
 * The bundle traversal (kd_traverse_bundle.h) and the N-rays triangle test
 * (kd_tri_nray.h) are written for masks held in float vectors (all-ones or
 * all-zero lanes, the SSE/AVX compare results). These give the 16-lane
 * instance the same helpers: a compare's k-mask becomes a vector with
 * vpmovm2d and a vector mask a k-mask with vpmovd2m (one cheap
 * instruction each), so the template needs no second mask convention. */
KD_AVX512 static inline f16 f16_load(const float *p) { return _mm512_load_ps(p); }
KD_AVX512 static inline f16 f16_div(f16 a, f16 b) { return _mm512_div_ps(a, b); }
KD_AVX512 static inline f16 f16_kmask(__mmask16 k) {
    return _mm512_castsi512_ps(_mm512_movm_epi32(k));
}
KD_AVX512 static inline __mmask16 f16_kbits(f16 m) {
    return _mm512_movepi32_mask(_mm512_castps_si512(m));
}
KD_AVX512 static inline f16 f16_lt(f16 a, f16 b) {
    return f16_kmask(_mm512_cmp_ps_mask(a, b, _CMP_LT_OQ));
}
KD_AVX512 static inline f16 f16_le(f16 a, f16 b) {
    return f16_kmask(_mm512_cmp_ps_mask(a, b, _CMP_LE_OQ));
}
KD_AVX512 static inline f16 f16_gt(f16 a, f16 b) {
    return f16_kmask(_mm512_cmp_ps_mask(a, b, _CMP_GT_OQ));
}
KD_AVX512 static inline f16 f16_eq(f16 a, f16 b) {
    return f16_kmask(_mm512_cmp_ps_mask(a, b, _CMP_EQ_OQ));
}
KD_AVX512 static inline f16 f16_and(f16 a, f16 b) { return _mm512_and_ps(a, b); }
KD_AVX512 static inline f16 f16_or(f16 a, f16 b) { return _mm512_or_ps(a, b); }
KD_AVX512 static inline f16 f16_andnot(f16 m, f16 a) { return _mm512_andnot_ps(m, a); }
KD_AVX512 static inline f16 f16_xor(f16 a, f16 b) { return _mm512_xor_ps(a, b); }
/* lanes of vector mask m: a, others b */
KD_AVX512 static inline f16 f16_sel(f16 m, f16 a, f16 b) {
    return _mm512_mask_blend_ps(f16_kbits(m), b, a);
}
KD_AVX512 static inline int f16_bits(f16 m) { return (int)f16_kbits(m); }
KD_AVX512 static inline f16 f16_signmask(f16 a) {
    return _mm512_castsi512_ps(_mm512_srai_epi32(_mm512_castps_si512(a), 31));
}
KD_AVX512 static inline f16 f16_bitmask(int bits) { return f16_kmask((__mmask16)bits); }
KD_AVX512 static inline f16 f16_seti(int32_t x) {
    return _mm512_castsi512_ps(_mm512_set1_epi32(x));
}
/* per-lane counters: acc - m adds 1 where m is all-ones (-1) */
KD_AVX512 static inline f16 f16_count(f16 acc, f16 m) {
    return _mm512_castsi512_ps(
        _mm512_sub_epi32(_mm512_castps_si512(acc), _mm512_castps_si512(m)));
}
KD_AVX512 static inline uint64_t f16_count_sum(f16 acc) {
    _Alignas(64) int32_t v[16];
    _mm512_store_si512(v, _mm512_castps_si512(acc));
    uint64_t sum = 0;
    for (int j = 0; j < 16; j++)
        sum += (uint64_t)v[j];
    return sum;
}
/* Lane j gets v[idx[j]] (idx: int32 lane indices 0..15 as bits). */
KD_AVX512 static inline f16 f16_permute(f16 v, f16 idx) {
    return _mm512_permutexvar_ps(_mm512_castps_si512(idx), v);
}
/* Floats p[0..7] in lanes 0..7, the upper lanes undefined (for
 * f16_permute with indices below 8: reads no more than the 8-wide load). */
KD_AVX512 static inline f16 f16_load8u(const float *p) {
    return _mm512_castps256_ps512(_mm256_loadu_ps(p));
}
/* Sixteen 3-float records from p (48 floats, AoS) into their x, y and z
 * lanes (SoA): three loads and six two-source permutes, where a lane-by-
 * lane copy stores 48 floats and reloads them as vectors (the bundle
 * driver's gather of 16 consecutive rays). */
KD_AVX512 static inline void f16_load3x16(const float *p, f16 out[3]) {
    const f16 a = _mm512_loadu_ps(p), b = _mm512_loadu_ps(p + 16),
              c = _mm512_loadu_ps(p + 32);
    /* record j's component k is float 3j + k: lanes whose float lies in
     * a|b (index < 32) take it from there, the others then from c (16 +
     * index - 32 in the second permute, which keeps lane j otherwise) */
    const __m512i lo0 = _mm512_setr_epi32(0, 3, 6, 9, 12, 15, 18, 21, 24, 27, 30, 0, 0, 0, 0, 0);
    const __m512i hi0 = _mm512_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 17, 20, 23, 26, 29);
    const __m512i lo1 = _mm512_setr_epi32(1, 4, 7, 10, 13, 16, 19, 22, 25, 28, 31, 0, 0, 0, 0, 0);
    const __m512i hi1 = _mm512_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 18, 21, 24, 27, 30);
    const __m512i lo2 = _mm512_setr_epi32(2, 5, 8, 11, 14, 17, 20, 23, 26, 29, 0, 0, 0, 0, 0, 0);
    const __m512i hi2 = _mm512_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 16, 19, 22, 25, 28, 31);
    out[0] = _mm512_permutex2var_ps(_mm512_permutex2var_ps(a, lo0, b), hi0, c);
    out[1] = _mm512_permutex2var_ps(_mm512_permutex2var_ps(a, lo1, b), hi1, c);
    out[2] = _mm512_permutex2var_ps(_mm512_permutex2var_ps(a, lo2, b), hi2, c);
}

#endif /* KD_SIMD_H */
