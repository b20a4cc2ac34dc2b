/*
 * exec_bodies.h — what tests/test_exec.c feeds the executor: the CHECK
 * macro, a seeded generator, a bumpy height-field scene, and request bodies
 * of every kind, as JSON text (printf-style) or as CBOR maps built by hand
 * (RFC 8949 heads, RFC 8746 float32 typed arrays placed at 4-byte offsets
 * so that the executor reads them in place). Header-only, one copy per
 * test program.
 */
#ifndef KDR_TEST_EXEC_BODIES_H
#define KDR_TEST_EXEC_BODIES_H

#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "kdr_exec.h"
#include "test_util.h"

static uint64_t rng_state = 0x9e3779b97f4a7c15ull;
static double frand(void) {
    rng_state ^= rng_state << 13;
    rng_state ^= rng_state >> 7;
    rng_state ^= rng_state << 17;
    return (double)(rng_state >> 11) * 0x1p-53;
}

/* ---- a scene and request bodies ------------------------------------------------ */

/* A bumpy 100 x 50 height field of 10,000 triangles in [-1,1]^2 x [0,0.3]. */
static kdr_scene *make_scene(void) {
    enum { NX = 100, NZ = 50 };
    float *t = malloc(NX * NZ * 2 * 9 * sizeof(float)), *p = t;
    for (int i = 0; i < NX; i++)
        for (int k = 0; k < NZ; k++) {
            float x0 = -1 + 2.0f * i / NX, x1 = -1 + 2.0f * (i + 1) / NX;
            float z0 = -1 + 2.0f * k / NZ, z1 = -1 + 2.0f * (k + 1) / NZ;
            float h[4];
            for (int c = 0; c < 4; c++)
                h[c] = 0.3f * (float)frand();
            const float q[4][3] = {
                {x0, h[0], z0}, {x1, h[1], z0}, {x1, h[2], z1}, {x0, h[3], z1}};
            const int tri[2][3] = {{0, 1, 2}, {0, 2, 3}};
            for (int a = 0; a < 2; a++)
                for (int v = 0; v < 3; v++)
                    for (int c = 0; c < 3; c++)
                        *p++ = q[tri[a][v]][c];
        }
    kdr_build_opts o;
    kdr_build_opts_default(&o);
    kdr_scene *s = NULL;
    int rc = kdr_scene_build(t, NX * NZ * 2, &o, NULL, NULL, &s);
    free(t);
    CHECK(rc == KDR_OK, "scene build: %s", kdr_strerror(rc));
    return s;
}

/* A request body, its media type and the answer's (zero: JSON both). */
typedef struct body {
    char *s;
    size_t len, cap;
    kdr_media media, answer;
} body;

static void put(body *b, const char *fmt, ...) {
    va_list ap;
    for (;;) {
        va_start(ap, fmt);
        int n = vsnprintf(b->s + b->len, b->cap - b->len, fmt, ap);
        va_end(ap);
        if ((size_t)n < b->cap - b->len) {
            b->len += (size_t)n;
            return;
        }
        b->cap = 2 * (b->cap + (size_t)n + 64);
        b->s = realloc(b->s, b->cap);
    }
}

/* n rays from above the field toward random points of it. */
static body bundle_body(size_t n, const char *query, const char *extra) {
    body b = {0};
    put(&b, "{\"query\":\"%s\",\"origins\":[0,2,0],\"directions\":[", query);
    for (size_t i = 0; i < n; i++)
        put(&b, "%s%.6f,%.6f,%.6f", i ? "," : "", 2 * frand() - 1, -2 + 0.2 * frand(),
            2 * frand() - 1);
    put(&b, "]%s}", extra);
    return b;
}

static body frustum_body(int w, int h, const char *query, const char *extra) {
    body b = {0};
    put(&b,
        "{\"camera\":{\"eye\":[0.3,1.2,2.5],\"target\":[0,0,0],\"fov_y_deg\":50,"
        "\"width\":%d,\"height\":%d},\"tile\":8,\"query\":\"%s\",\"encoding\":\"base64\"%"
        "s}",
        w, h, query, extra);
    return b;
}

static body shadow_body(size_t n, int samples, const char *extra) {
    body b = {0};
    put(&b,
        "{\"samples\":%d,\"stats\":true,\"lights\":[{\"center\":[0.5,2,0],"
        "\"radius\":0.4},{\"center\":[-2,1,0],\"radius\":0.2}],\"points\":[",
        samples);
    for (size_t i = 0; i < n; i++)
        put(&b, "%s%.5f,%.5f,%.5f", i ? "," : "", 2 * frand() - 1, 0.3 * frand(),
            2 * frand() - 1);
    put(&b, "]%s}", extra);
    return b;
}

/* ---- CBOR bodies (RFC 8949 heads, RFC 8746 float32 typed arrays) ---------------- */

static void raw(body *b, const void *p, size_t n) {
    if (b->len + n > b->cap) {
        b->cap = 2 * (b->cap + n + 64);
        b->s = realloc(b->s, b->cap);
    }
    memcpy(b->s + b->len, p, n);
    b->len += n;
}

static void head(body *b, unsigned major, uint64_t v) {
    unsigned char h[9];
    raw(b, h, cbor_head(h, major, v));
}

static void text(body *b, const char *t) {
    head(b, 3, strlen(t));
    raw(b, t, strlen(t));
}

/* "key": tag 85 (float32 LE) over v, preceded by a padding member when
 * needed so that the floats start at a multiple of 4 bytes into the body
 * (malloc'd bodies are aligned: the floats are then read in place). */
static void typed(body *b, const char *key, const float *v, size_t n) {
    size_t klen = 1 + strlen(key), hlen = 2 + (4 * n < 24      ? 1
                                               : 4 * n < 256   ? 2
                                               : 4 * n < 65536 ? 3
                                                               : 5);
    size_t at = b->len + klen + hlen;
    if (at % 4) {
        size_t pad =
            (4 - (at + 5 + 1) % 4) % 4; /* "_pad" is 5 bytes, its value 1 + pad */
        char x[4] = "xxx";
        x[pad] = '\0';
        text(b, "_pad");
        text(b, x);
    }
    text(b, key);
    raw(b, "\xd8\x55", 2);
    head(b, 2, 4 * n);
    raw(b, v, 4 * n);
}

/* The rays of bundle_body (same generator) as a CBOR map. */
static body cbor_bundle_body(size_t n, const char *query) {
    body b = {0};
    float *dir = malloc(3 * n * sizeof(float)), org[3] = {0, 2, 0};
    for (size_t i = 0; i < n; i++) {
        dir[3 * i] = (float)(2 * frand() - 1);
        dir[3 * i + 1] = (float)(-2 + 0.2 * frand());
        dir[3 * i + 2] = (float)(2 * frand() - 1);
    }
    raw(&b, "\xbf", 1); /* a map of indefinite length: padding members vary */
    text(&b, "query");
    text(&b, query);
    typed(&b, "origins", org, 3);
    typed(&b, "directions", dir, 3 * n);
    raw(&b, "\xff", 1);
    free(dir);
    b.media = KDR_MEDIA_CBOR;
    b.answer = KDR_MEDIA_CBOR;
    return b;
}

static body cbor_shadow_body(size_t n) {
    body b = {0};
    float *pts = malloc(3 * n * sizeof(float));
    for (size_t i = 0; i < n; i++) {
        pts[3 * i] = (float)(2 * frand() - 1);
        pts[3 * i + 1] = (float)(0.3 * frand());
        pts[3 * i + 2] = (float)(2 * frand() - 1);
    }
    static const unsigned char lights[] = {
        /* [{"center": [0.5, 2, 0], "radius": 0.4}]: floats as float32 items */
        0x81, 0xa2, 0x66, 'c',  'e',  'n',  't',  'e',  'r', 0x83,
        0xfa, 0x3f, 0x00, 0x00, 0x00, 0x02, 0x00, 0x66, 'r', 'a',
        'd',  'i',  'u',  's',  0xfa, 0x3e, 0xcc, 0xcc, 0xcd};
    raw(&b, "\xbf", 1);
    text(&b, "samples");
    head(&b, 0, 16);
    text(&b, "lights");
    raw(&b, lights, sizeof lights);
    typed(&b, "points", pts, 3 * n);
    raw(&b, "\xff", 1);
    free(pts);
    b.media = KDR_MEDIA_CBOR;
    b.answer = KDR_MEDIA_CBOR;
    return b;
}

#endif
