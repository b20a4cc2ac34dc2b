/*
 * test_codecs.c — the codecs against the code they replaced: the AVX2
 * base64 against the pre-SIMD scalar base64, and the Dragonbox float
 * printer against the pre-Dragonbox printer (tests/support/old_codecs.c,
 * the protocol's code at commit 9466b74) and strtof.
 *
 * Property tests, seeded: every length up to 700 bytes and random lengths
 * up to 200 KB encode to the same text; every single-character corruption
 * (all 256 byte values, every position of the first blocks, random
 * positions after) decodes to the same status, error offset and bytes;
 * ~2.3M floats (a stride through all bit patterns, random patterns, and
 * the edges: subnormals, powers of two and ten, FLT_MAX) print as text that
 * strtof and strtod-then-float read back bit for bit, never longer than the old printer's and
 * equal to it except where two shortest decimals are equally near (then
 * the new one ends in the even digit, the old one in the lower). The exhaustive round trip
 * over all 2^32 patterns is tests/float_exhaustive.c (by hand, minutes).
 */
#include <float.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "kdr_protocol.h"
#include "old_codecs.h"
#define CHECK_PRINT_MAX 30
#include "check.h"
#include "test_util.h"

static uint64_t rng_state = 0x3c6ef372fe94f82bull;
static uint64_t rng(void) { return xorshift64(&rng_state); }

/* ---- base64 --------------------------------------------------------------------- */

/* Decodes text[0..n) with both decoders into exactly sized buffers (so
 * ASan sees any write past the decoded size) and compares everything. */
static void same_decode(const char *text, size_t n, const char *what) {
    const size_t cap = kdr_base64_decoded_max(n);
    unsigned char *a = xmalloc(cap), *b = xmalloc(cap);
    memset(a, 0xAA, cap ? cap : 1);
    memset(b, 0xAA, cap ? cap : 1);
    size_t la = 0, lb = 0, ea = 0, eb = 0;
    const int ra = kdr_base64_decode(text, n, a, &la, &ea);
    const int rb = old_base64_decode(text, n, b, &lb, &eb);
    CHECK(ra == rb, "%s: status %d, old %d", what, ra, rb);
    if (ra == 0 && rb == 0) {
        CHECK(la == lb && !memcmp(a, b, la), "%s: decoded bytes differ (n=%zu)", what, n);
    } else if (ra && rb) {
        CHECK(ea == eb, "%s: error offset %zu, old %zu", what, ea, eb);
    }
    free(a);
    free(b);
}

static void encode_both(const unsigned char *src, size_t n, char **out) {
    const size_t len = kdr_base64_encoded_len(n);
    char *a = xmalloc(len), *b = xmalloc(len);
    const size_t la = kdr_base64_encode(src, n, a), lb = old_base64_encode(src, n, b);
    CHECK(la == len && lb == len && !memcmp(a, b, len), "encode of %zu bytes differs", n);
    free(b);
    *out = a;
}

static void test_base64_lengths(void) {
    enum { MAXN = 200000 };
    unsigned char *src = xmalloc(MAXN);
    for (size_t i = 0; i < MAXN; i++)
        src[i] = (unsigned char)rng();
    for (size_t trial = 0; trial < 760; trial++) {
        const size_t n = trial < 700 ? trial : rng() % MAXN;
        char *text;
        encode_both(src + trial % 7, n, &text);
        same_decode(text, kdr_base64_encoded_len(n), "valid text");
        free(text);
    }
    free(src);
}

/* Every byte value at every position of the first two 32-character blocks,
 * in the padding group and at random positions; also cut lengths. */
static void test_base64_corruption(void) {
    enum { N = 3000 };
    unsigned char src[N];
    for (size_t i = 0; i < N; i++)
        src[i] = (unsigned char)rng();
    const size_t sizes[] = {23, 24, 25, 47, 48, 49, 96, 100, N - 1, N};
    for (size_t s = 0; s < sizeof sizes / sizeof sizes[0]; s++) {
        char *text;
        encode_both(src, sizes[s], &text);
        const size_t len = kdr_base64_encoded_len(sizes[s]);
        char *bad = xmalloc(len);
        for (size_t pos = 0; pos < len; pos++) {
            const int near_edge = pos < 72 || pos + 8 >= len;
            if (!near_edge && rng() % 8)
                continue;
            for (int v = 0; v < 256; v++) {
                memcpy(bad, text, len);
                bad[pos] = (char)v;
                same_decode(bad, len, "one byte changed");
            }
        }
        for (size_t cut = 0; cut <= len && cut < 80; cut++)
            same_decode(text, len - cut, "shortened text");
        free(bad);
        free(text);
    }
}

/* ---- float printing ----------------------------------------------------------- */

static size_t float_checked, float_shorter, float_ties;

/* a and b differ only in a last digit that is one apart, a's even: two
 * shortest decimals equally near the float (Dragonbox breaks the tie to
 * even, the old printer to the lower one). */
static int tie_to_even(const char *a, const char *b) {
    const size_t n = strlen(a);
    if (n != strlen(b) || n == 0 || memcmp(a, b, n - 1))
        return 0;
    const int da = a[n - 1] - '0', db = b[n - 1] - '0';
    return da % 2 == 0 && (da - db == 1 || db - da == 1);
}

static void check_float(uint32_t bits) {
    float f;
    memcpy(&f, &bits, 4);
    char a[KDR_FLOAT_CHARS + 1], b[KDR_FLOAT_CHARS + 1];
    const size_t la = kdr_format_float(f, a), lb = old_format_float(f, b);
    a[la] = b[lb] = '\0';
    float_checked++;
    if (!isfinite(f)) {
        CHECK(!strcmp(a, "null"), "%08x: %s, want null", (unsigned)bits, a);
        return;
    }
    const float back = strtof(a, NULL), via_double = (float)strtod(a, NULL);
    CHECK(!memcmp(&back, &f, 4), "%08x: %s reads back as %a", (unsigned)bits, a,
          (double)back);
    CHECK(!memcmp(&via_double, &f, 4), "%08x: %s reads back through a double as %a",
          (unsigned)bits, a, (double)via_double);
    CHECK(la <= lb, "%08x: %s longer than the old %s", (unsigned)bits, a, b);
    if (la < lb) {
        float_shorter++;
    } else if (strcmp(a, b)) {
        float_ties++;
        CHECK(tie_to_even(a, b), "%08x: %s, old printer %s", (unsigned)bits, a, b);
    }
}

static void test_float_printing(void) {
    for (uint64_t bits = 0; bits < 0x100000000ull; bits += 4099)
        check_float((uint32_t)bits);
    for (int i = 0; i < 1000000; i++)
        check_float((uint32_t)rng());
    for (uint32_t m = 0; m < 4096; m++) { /* subnormals, and next to FLT_MAX */
        check_float(m);
        check_float(0x7f7fffffu - m);
        check_float(0x00800000u + m);
    }
    for (int e = 0; e < 256; e++) /* powers of two and their neighbours */
        for (int d = -2; d <= 2; d++)
            check_float(((uint32_t)e << 23) + (uint32_t)d);
    for (int k = -45; k <= 38; k++) { /* powers of ten and their neighbours */
        float p = strtof("1", NULL) * (float)pow(10.0, k);
        uint32_t bits;
        memcpy(&bits, &p, 4);
        for (int d = -2; d <= 2; d++)
            check_float(bits + (uint32_t)d);
    }
    printf("float printing: %zu floats; %zu shorter than the old printer, %zu ties "
           "broken to even\n",
           float_checked, float_shorter, float_ties);
}

int main(void) {
    test_base64_lengths();
    test_base64_corruption();
    test_float_printing();
    if (failures) {
        fprintf(stderr, "test_codecs: %d checks failed\n", failures);
        return 1;
    }
    printf("test_codecs: all checks passed\n");
    return 0;
}
