/*
 * kdr_base64.c — RFC 4648 base64 (standard alphabet, '=' padding), the
 * binary form of float arrays in JSON bodies. The decoder is strict so that
 * a corrupted body is an error naming the offset rather than a silently
 * different array of floats.
 *
 * Two implementations of one contract: a table-driven scalar loop (one
 * 4-character group at a time; the reference, the tail of every call, and
 * the whole job on CPUs without AVX2), and AVX2 loops that do 24 bytes <->
 * 32 characters per step, picked at run time. The vector decoder only ever
 * accepts blocks of 32 alphabet characters; a block holding anything else
 * ('=', whitespace, a bad byte) is handed to the scalar loop, which then
 * names the offset. So both give the same bytes and the same error offsets
 * (tests/test_codecs.c checks this against the pre-SIMD code).
 *
 * Hand-written because no Debian 12 package offers a vectorised base64
 * (libb64 and libbaseencode are scalar, about the speed of the scalar loop
 * here); the method is the well-known one of translating 6-bit values with
 * byte shuffles and packing them with multiply-adds.
 */
#include <immintrin.h>

#include "kdr_proto_internal.h"

#define KDR_AVX2 __attribute__((target("avx2")))

static const char b64_alphabet[64] =
    "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";

/* 0..63 for alphabet characters, 0xFF for everything else (incl. '='). */
#define X 0xFF
static const unsigned char b64_value[256] = {
    X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,
    X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,
    X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  62, X,  X,  X,  63,
    52, 53, 54, 55, 56, 57, 58, 59, 60, 61, X,  X,  X,  X,  X,  X,
    X,  0,  1,  2,  3,  4,  5,  6,  7,  8,  9,  10, 11, 12, 13, 14,
    15, 16, 17, 18, 19, 20, 21, 22, 23, 24, 25, X,  X,  X,  X,  X,
    X,  26, 27, 28, 29, 30, 31, 32, 33, 34, 35, 36, 37, 38, 39, 40,
    41, 42, 43, 44, 45, 46, 47, 48, 49, 50, 51, X,  X,  X,  X,  X,
    X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,
    X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,
    X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,
    X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,
    X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,
    X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,
    X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,
    X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,
};
#undef X

size_t kdr_base64_encoded_len(size_t n) { return (n + 2) / 3 * 4; }

size_t kdr_base64_decoded_max(size_t n) { return n / 4 * 3; }

static size_t encode_scalar(const unsigned char *s, size_t n, char *dst) {
    char *d = dst;
    size_t i = 0;
    for (; i + 3 <= n; i += 3, d += 4) {
        uint32_t v = (uint32_t)s[i] << 16 | (uint32_t)s[i + 1] << 8 | s[i + 2];
        d[0] = b64_alphabet[v >> 18];
        d[1] = b64_alphabet[(v >> 12) & 63];
        d[2] = b64_alphabet[(v >> 6) & 63];
        d[3] = b64_alphabet[v & 63];
    }
    if (i < n) {
        uint32_t v = (uint32_t)s[i] << 16;
        if (i + 1 < n)
            v |= (uint32_t)s[i + 1] << 8;
        d[0] = b64_alphabet[v >> 18];
        d[1] = b64_alphabet[(v >> 12) & 63];
        d[2] = i + 1 < n ? b64_alphabet[(v >> 6) & 63] : '=';
        d[3] = '=';
        d += 4;
    }
    return (size_t)(d - dst);
}

/* The first character of group g (4 chars at src) that is not valid there;
 * -1 if the group is a valid final group (padding allowed). */
static int bad_in_last_group(const unsigned char *g, size_t *nbytes) {
    unsigned char v[4];
    for (int k = 0; k < 4; k++)
        v[k] = b64_value[g[k]];
    if (v[0] == 0xFF) return 0;
    if (v[1] == 0xFF) return 1;
    if (g[2] == '=') {
        if (g[3] != '=') return 3;
        if (v[1] & 15) return 1; /* bits that no byte uses must be zero */
        *nbytes = 1;
        return -1;
    }
    if (v[2] == 0xFF) return 2;
    if (g[3] == '=') {
        if (v[2] & 3) return 2;
        *nbytes = 2;
        return -1;
    }
    if (v[3] == 0xFF) return 3;
    *nbytes = 3;
    return -1;
}

/* Scalar decode of s[i..n) into d (n a multiple of 4, i too): every group
 * but the last must be 4 alphabet characters. */
static int decode_scalar(const unsigned char *s, size_t i, size_t n, unsigned char *d,
                         unsigned char **d_end, size_t *err_offset) {
    size_t full = n ? n - 4 : 0; /* the last group may carry padding */
    for (; i < full; i += 4, d += 3) {
        uint32_t a = b64_value[s[i]], b = b64_value[s[i + 1]];
        uint32_t c = b64_value[s[i + 2]], e = b64_value[s[i + 3]];
        if ((a | b | c | e) & 0x80) {
            size_t k = a & 0x80 ? 0 : b & 0x80 ? 1 : c & 0x80 ? 2 : 3;
            *err_offset = i + k;
            return -1;
        }
        uint32_t v = a << 18 | b << 12 | c << 6 | e;
        d[0] = (unsigned char)(v >> 16);
        d[1] = (unsigned char)(v >> 8);
        d[2] = (unsigned char)v;
    }
    if (n) {
        size_t nbytes = 0;
        int bad = bad_in_last_group(s + i, &nbytes);
        if (bad >= 0) {
            *err_offset = i + (size_t)bad;
            return -1;
        }
        uint32_t v = (uint32_t)b64_value[s[i]] << 18 | (uint32_t)b64_value[s[i + 1]] << 12;
        if (nbytes > 1) v |= (uint32_t)b64_value[s[i + 2]] << 6;
        if (nbytes > 2) v |= b64_value[s[i + 3]];
        d[0] = (unsigned char)(v >> 16);
        if (nbytes > 1) d[1] = (unsigned char)(v >> 8);
        if (nbytes > 2) d[2] = (unsigned char)v;
        d += nbytes;
    }
    *d_end = d;
    return 0;
}

/* ---- AVX2 --------------------------------------------------------------------- */

/* 24 bytes -> 32 characters per step while 28 bytes can be read (the second
 * 16-byte load starts 12 bytes in). Returns the bytes consumed. */
KDR_AVX2 static size_t encode_avx2(const unsigned char *s, size_t n, char *d) {
    /* each 4-byte lane gets its 3 source bytes as b,a,c,b: the 16-bit
     * halves are then a:b and b:c, which hold the four 6-bit fields */
    const __m256i spread = _mm256_setr_epi8(1, 0, 2, 1, 4, 3, 5, 4, 7, 6, 8, 7, 10, 9, 11,
                                            10, 1, 0, 2, 1, 4, 3, 5, 4, 7, 6, 8, 7, 10, 9,
                                            11, 10);
    /* offsets from a 6-bit value to its character, by class (see below) */
    const __m256i offset = _mm256_setr_epi8(71, -4, -4, -4, -4, -4, -4, -4, -4, -4, -4,
                                            -19, -16, 65, 0, 0, 71, -4, -4, -4, -4, -4,
                                            -4, -4, -4, -4, -4, -19, -16, 65, 0, 0);
    size_t i = 0;
    for (; i + 28 <= n; i += 24, d += 32) {
        const __m128i lo = _mm_loadu_si128((const __m128i *)(s + i));
        const __m128i hi = _mm_loadu_si128((const __m128i *)(s + i + 12));
        const __m256i in = _mm256_shuffle_epi8(
            _mm256_inserti128_si256(_mm256_castsi128_si256(lo), hi, 1), spread);
        /* fields 0 and 2 to the low byte of each half (shift right 10, 6),
         * fields 1 and 3 to the high byte (shift left 4, 8) */
        const __m256i f02 = _mm256_mulhi_epu16(
            _mm256_and_si256(in, _mm256_set1_epi32(0x0fc0fc00)), _mm256_set1_epi32(0x04000040));
        const __m256i f13 = _mm256_mullo_epi16(
            _mm256_and_si256(in, _mm256_set1_epi32(0x003f03f0)), _mm256_set1_epi32(0x01000010));
        const __m256i v = _mm256_or_si256(f02, f13);
        /* class: 0 for 26..51, 1..12 for 52..63, 13 for 0..25 */
        __m256i cls = _mm256_subs_epu8(v, _mm256_set1_epi8(51));
        cls = _mm256_or_si256(cls, _mm256_and_si256(_mm256_cmpgt_epi8(_mm256_set1_epi8(26), v),
                                                    _mm256_set1_epi8(13)));
        const __m256i out = _mm256_add_epi8(v, _mm256_shuffle_epi8(offset, cls));
        _mm256_storeu_si256((__m256i *)d, out);
    }
    return i;
}

/* 32 characters -> 24 bytes per step over s[0..n), stopping before the
 * first block that is not 32 alphabet characters. Returns the characters
 * consumed (a multiple of 32). */
KDR_AVX2 static size_t decode_avx2(const unsigned char *s, size_t n, unsigned char *d) {
    /* Validity by nibbles: a character is valid iff lo_bits[low nibble] &
     * hi_bits[high nibble] == 0. High-nibble classes: 0x01 for 2 ('+','/'),
     * 0x02 for 3 (digits), 0x04 for 4 and 6 (letters from 1), 0x08 for 5
     * and 7 (letters up to 10), 0x10 for every other high nibble (never
     * valid, including bytes >= 0x80). */
    const __m256i lo_bits = _mm256_setr_epi8(
        0x15, 0x11, 0x11, 0x11, 0x11, 0x11, 0x11, 0x11, 0x11, 0x11, 0x13, 0x1a, 0x1b, 0x1b,
        0x1b, 0x1a, 0x15, 0x11, 0x11, 0x11, 0x11, 0x11, 0x11, 0x11, 0x11, 0x11, 0x13, 0x1a,
        0x1b, 0x1b, 0x1b, 0x1a);
    const __m256i hi_bits = _mm256_setr_epi8(
        0x10, 0x10, 0x01, 0x02, 0x04, 0x08, 0x04, 0x08, 0x10, 0x10, 0x10, 0x10, 0x10, 0x10,
        0x10, 0x10, 0x10, 0x10, 0x01, 0x02, 0x04, 0x08, 0x04, 0x08, 0x10, 0x10, 0x10, 0x10,
        0x10, 0x10, 0x10, 0x10);
    /* value = character + delta[high nibble], '/' taking slot 1 */
    const __m256i delta = _mm256_setr_epi8(0, 16, 19, 4, -65, -65, -71, -71, 0, 0, 0, 0, 0,
                                           0, 0, 0, 0, 16, 19, 4, -65, -65, -71, -71, 0, 0,
                                           0, 0, 0, 0, 0, 0);
    const __m256i pack = _mm256_setr_epi8(2, 1, 0, 6, 5, 4, 10, 9, 8, 14, 13, 12, -1, -1,
                                          -1, -1, 2, 1, 0, 6, 5, 4, 10, 9, 8, 14, 13, 12,
                                          -1, -1, -1, -1);
    const __m256i nib = _mm256_set1_epi8(0x0f);
    size_t i = 0;
    for (; i + 32 <= n; i += 32, d += 24) {
        const __m256i c = _mm256_loadu_si256((const __m256i *)(s + i));
        const __m256i hi = _mm256_and_si256(_mm256_srli_epi32(c, 4), nib);
        const __m256i lo = _mm256_and_si256(c, nib);
        if (!_mm256_testz_si256(_mm256_shuffle_epi8(lo_bits, lo),
                                _mm256_shuffle_epi8(hi_bits, hi)))
            break;
        const __m256i slash = _mm256_cmpeq_epi8(c, _mm256_set1_epi8('/'));
        const __m256i v =
            _mm256_add_epi8(c, _mm256_shuffle_epi8(delta, _mm256_add_epi8(hi, slash)));
        /* four 6-bit values per 32-bit lane -> one 24-bit value */
        const __m256i v12 = _mm256_maddubs_epi16(v, _mm256_set1_epi32(0x01400140));
        const __m256i v24 = _mm256_madd_epi16(v12, _mm256_set1_epi32(0x00011000));
        const __m256i bytes = _mm256_permutevar8x32_epi32(
            _mm256_shuffle_epi8(v24, pack), _mm256_setr_epi32(0, 1, 2, 4, 5, 6, 7, 7));
        _mm_storeu_si128((__m128i *)d, _mm256_castsi256_si128(bytes));
        _mm_storel_epi64((__m128i *)(d + 16), _mm256_extracti128_si256(bytes, 1));
    }
    return i;
}

static int have_avx2(void) { return __builtin_cpu_supports("avx2") ? 1 : 0; }

/* ---- API ----------------------------------------------------------------------- */

size_t kdr_base64_encode(const void *src, size_t n, char *dst) {
    const unsigned char *s = src;
    size_t done = n >= 28 && have_avx2() ? encode_avx2(s, n, dst) : 0;
    return done / 3 * 4 + encode_scalar(s + done, n - done, dst + done / 3 * 4);
}

int kdr_base64_decode(const char *src, size_t n, void *dst, size_t *out_len,
                      size_t *err_offset) {
    const unsigned char *s = (const unsigned char *)src;
    unsigned char *d = dst, *end = d;
    *out_len = 0;
    if (n % 4) {
        /* the input stops in the middle of a group: report its end */
        *err_offset = n;
        return -1;
    }
    /* the last group may carry padding: it is the scalar loop's */
    size_t done = n > 4 && have_avx2() ? decode_avx2(s, n - 4, d) : 0;
    if (decode_scalar(s, done, n, d + done / 4 * 3, &end, err_offset))
        return -1;
    *out_len = (size_t)(end - d);
    return 0;
}
