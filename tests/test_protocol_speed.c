/*
 * test_protocol_speed.c — throughput of protocol/ on large bundles: parse a
 * request of N rays (default 1M) given as JSON numbers and as base64, and
 * encode a closest-hit response of N rays both ways. Prints MB/s and
 * Mrays/s (process CPU time, so other load on the machine matters less).
 * Not a test: no assertions on time. Usage: test_protocol_speed [rays]
 */
#define _POSIX_C_SOURCE 200809L
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "kdr_protocol.h"

static double cpu_seconds(void) {
    struct timespec ts;
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

static uint64_t rng_state = 0x9e3779b97f4a7c15ull;
static float rnd(void) {
    rng_state ^= rng_state << 13;
    rng_state ^= rng_state >> 7;
    rng_state ^= rng_state << 17;
    return (float)(rng_state >> 40) * 0x1p-24f * 2.0f - 1.0f;
}

static void put_floats(kdr_buf *b, const char *name, const float *v, size_t n, int b64) {
    char tmp[KDR_FLOAT_CHARS];
    kdr_buf_append(b, name, strlen(name));
    if (b64) {
        kdr_buf_reserve(b, kdr_base64_encoded_len(4 * n) + 16);
        kdr_buf_append(b, "{\"f32\":\"", 8);
        b->len += kdr_base64_encode(v, 4 * n, b->data + b->len);
        kdr_buf_append(b, "\"}", 2);
        return;
    }
    kdr_buf_append(b, "[", 1);
    for (size_t i = 0; i < n; i++) {
        if (i)
            kdr_buf_append(b, ",", 1);
        kdr_buf_append(b, tmp, kdr_format_float(v[i], tmp));
    }
    kdr_buf_append(b, "]", 1);
}

static void report(const char *what, size_t bytes, size_t rays, double s) {
    printf("%-28s %8.1f MB  %8.3f s  %8.1f MB/s  %7.2f Mrays/s\n", what, bytes / 1e6, s,
           bytes / 1e6 / s, rays / 1e6 / s);
}

static void bench_parse(const float *org, const float *dir, size_t n, int b64) {
    kdr_buf body;
    kdr_buf_init(&body);
    kdr_buf_append(&body, "{", 1);
    put_floats(&body, "\"origins\":", org, 3 * n, b64);
    put_floats(&body, ",\"directions\":", dir, 3 * n, b64);
    kdr_buf_append(&body, ",\"tmax\":1e30}", 13);
    kdr_bundle_request r;
    kdr_proto_error err;
    double t0 = cpu_seconds();
    int st = kdr_proto_parse_bundle(body.data, body.len, n, &r, &err);
    double t1 = cpu_seconds();
    if (st || memcmp(r.batch.dir, dir, 12 * n) || memcmp(r.batch.org, org, 12 * n))
        printf("parse FAILED: %d %s\n", st, err.detail);
    report(b64 ? "parse bundle (base64)" : "parse bundle (json)", body.len, n, t1 - t0);
    kdr_bundle_request_free(&r);
    kdr_buf_free(&body);
}

static void bench_encode(size_t n, kdr_encoding enc) {
    float *t = malloc(4 * n), *u = malloc(4 * n), *v = malloc(4 * n);
    int32_t *prim = malloc(4 * n);
    for (size_t i = 0; i < n; i++) {
        t[i] = 10.0f * (rnd() + 1.0f);
        u[i] = 0.5f * (rnd() + 1.0f);
        v[i] = 0.5f * (1.0f - u[i]);
        prim[i] = i % 4 == 0 ? -1 : (int32_t)(i * 7919u % 1000000u);
    }
    kdr_hits h = {.t = t, .prim = prim, .u = u, .v = v, .hit = NULL};
    kdr_buf out;
    kdr_buf_init(&out);
    double t0 = cpu_seconds();
    kdr_proto_encode_hits(&h, n, KDR_CLOSEST, enc, &out);
    double t1 = cpu_seconds();
    report(enc ? "encode closest (base64)" : "encode closest (json)", out.len, n, t1 - t0);
    kdr_buf_free(&out);
    free(t), free(u), free(v), free(prim);
}

int main(int argc, char **argv) {
    size_t n = argc > 1 ? strtoull(argv[1], NULL, 10) : 1000000;
    float *org = malloc(12 * n), *dir = malloc(12 * n);
    for (size_t i = 0; i < 3 * n; i++) {
        org[i] = 100.0f * rnd();
        dir[i] = rnd();
    }
    for (size_t i = 0; i < n; i++)
        dir[3 * i] = 1.0f; /* never a zero direction */
    printf("%zu rays, per-ray origins, random floats\n", n);
    bench_parse(org, dir, n, 0);
    bench_parse(org, dir, n, 1);
    bench_encode(n, KDR_ENCODING_JSON);
    bench_encode(n, KDR_ENCODING_BASE64);
    free(org), free(dir);
    return 0;
}
