/*
 * cbor_body.h — shared by the CBOR protocol tests: the CHECK macro, a
 * seeded generator, and a builder that writes a CBOR request body (with
 * libcbor's encoders) and its JSON twin side by side. Header-only (static
 * inline), one copy per test program.
 */
#ifndef KDR_TEST_CBOR_BODY_H
#define KDR_TEST_CBOR_BODY_H

#include <cbor.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "kdr_protocol.h"
#define CHECK_PRINT_MAX 40
#include "check.h"
#include "test_util.h"

static uint64_t rng_state = 0x510e527fade682d1ull;
static inline uint64_t rng(void) { return xorshift64(&rng_state); }
static inline float frand(float lo, float hi) {
    return lo + (hi - lo) * (float)(rng() >> 40) * 0x1p-24f;
}

/* ---- building bodies -------------------------------------------------------------- */

/* A CBOR body (built with libcbor's encoders) and its JSON twin side by side. */
typedef struct body {
    unsigned char *c;
    size_t clen, ccap;
    kdr_buf j;
} body;

static inline void c_raw(body *b, const void *p, size_t n) {
    if (b->clen + n > b->ccap) { /* doubling: bombs are a million bytes */
        b->ccap = 2 * (b->clen + n);
        b->c = realloc(b->c, b->ccap);
        if (!b->c)
            exit(2);
    }
    memcpy(b->c + b->clen, p, n);
    b->clen += n;
}
typedef size_t (*head_fn)(size_t, unsigned char *, size_t);
static inline void c_head(body *b, head_fn fn, size_t v) {
    unsigned char tmp[9];
    c_raw(b, tmp, fn(v, tmp, sizeof tmp));
}
/* Bytes of a head with argument v (preferred serialization). */
static inline size_t head_len(size_t v) {
    return v < 24 ? 1 : v < 256 ? 2 : v < 65536 ? 3 : v <= 0xffffffffu ? 5 : 9;
}
static inline void c_text(body *b, const char *s) {
    c_head(b, cbor_encode_string_start, strlen(s));
    c_raw(b, s, strlen(s));
}
static inline void c_uint(body *b, uint64_t v) {
    unsigned char tmp[9];
    c_raw(b, tmp, cbor_encode_uint(v, tmp, sizeof tmp));
}
static inline void c_tag(body *b, uint64_t v) {
    unsigned char tmp[9];
    c_raw(b, tmp, cbor_encode_tag(v, tmp, sizeof tmp));
}
static inline void c_double(body *b, double d) {
    unsigned char tmp[9];
    c_raw(b, tmp, cbor_encode_double(d, tmp, sizeof tmp));
}
static inline void c_typed(body *b, const float *v, size_t n) {
    c_tag(b, 85);
    c_head(b, cbor_encode_bytestring_start, 4 * n);
    c_raw(b, v, 4 * n);
}
/* Floats as a CBOR array: alternately single, double and (when exact)
 * integer items, so every number form is read. */
static inline void c_floats(body *b, const float *v, size_t n) {
    unsigned char tmp[9];
    c_head(b, cbor_encode_array_start, n);
    for (size_t i = 0; i < n; i++) {
        if (i % 3 == 0 && v[i] == floorf(v[i]) && fabsf(v[i]) < 1e6f && v[i] >= 0)
            c_uint(b, (uint64_t)v[i]);
        else if (i % 3 == 1)
            c_raw(b, tmp, cbor_encode_double(v[i], tmp, sizeof tmp));
        else
            c_raw(b, tmp, cbor_encode_single(v[i], tmp, sizeof tmp));
    }
}

static inline void j_lit(body *b, const char *s) { kdr_buf_append(&b->j, s, strlen(s)); }
static inline void j_floats(body *b, const float *v, size_t n) {
    char tmp[KDR_FLOAT_CHARS];
    j_lit(b, "[");
    for (size_t i = 0; i < n; i++) {
        if (i)
            j_lit(b, ",");
        kdr_buf_append(&b->j, tmp, kdr_format_float(v[i], tmp));
    }
    j_lit(b, "]");
}

/* A float-array member in form 0 (typed array), 1 (CBOR array) or 2
 * (typed array preceded by a padding member that misaligns it). */
static inline void both_array(body *b, const char *key, const float *v, size_t n, int form) {
    if (form == 2) { /* a padding member whose text puts the payload off 4 */
        char pad[40];
        snprintf(pad, sizeof pad, "_pad_%s", key);
        c_text(b, pad);
        const size_t after = b->clen + head_len(strlen(key)) + strlen(key) + 2 +
                             head_len(4 * n); /* + pad value */
        c_text(b, (after + 2) % 4 ? "x" : "xy");
    }
    c_text(b, key);
    if (form == 1)
        c_floats(b, v, n);
    else
        c_typed(b, v, n);
    j_lit(b, b->j.len > 1 ? ",\"" : "\"");
    j_lit(b, key);
    j_lit(b, "\":");
    j_floats(b, v, n);
}

static inline void body_free(body *b) {
    free(b->c);
    kdr_buf_free(&b->j);
}

/* An exact-size, 16-byte aligned copy of the CBOR body (as a server's
 * malloc'd body would be) so ASan sees any read past it. */
static inline char *exact(const void *p, size_t n) {
    char *c = xmalloc(n);
    memcpy(c, p, n);
    return c;
}

#endif
