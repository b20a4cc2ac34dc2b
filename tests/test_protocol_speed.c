/*
 * test_protocol_speed.c — throughput of protocol/ on large batches: the
 * building blocks (base64 both ways, float printing) against memcpy of the
 * same bytes, then parsing a bundle request of N rays (default 1M, per-ray
 * origins) in each body form (JSON numbers, base64, CBOR typed arrays read
 * in place or copied) and encoding a closest-hit answer of N rays in each
 * answer form. Prints MB/s and Mrays/s (process CPU time, so other load on
 * the machine matters less); each row is the best of a few repetitions.
 * Not a test: no assertions on time. With --targets it also prints the
 * targets of bench/protocol.cmake (ratios to memcpy measured in this run)
 * and whether each was met.
 * Usage: test_protocol_speed [rays] [--targets]
 */
#define _POSIX_C_SOURCE 200809L
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include <cbor.h>

#include "kdr_protocol.h"
#include "test_util.h"

#define REPEAT 3

/* MB/s of each row, for --targets */
static double memcpy_mbs, rate[16];
enum { R_B64_ENC, R_B64_DEC, R_PARSE_JSON, R_PARSE_B64, R_PARSE_CBOR, R_PARSE_CBOR_COPY,
       R_ENC_JSON, R_ENC_B64, R_ENC_CBOR, R_ENC_CBOR_ANY };

static double cpu_seconds(void) {
    struct timespec ts;
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

static uint64_t rng_state = 0x9e3779b97f4a7c15ull;
static float rnd(void) {
    return (float)(xorshift64(&rng_state) >> 40) * 0x1p-24f * 2.0f - 1.0f;
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

static void report_rate(int row, const char *what, size_t bytes, size_t rays, double s);
static void report(const char *what, size_t bytes, size_t rays, double s) {
    printf("%-30s %8.1f MB  %8.4f s  %8.1f MB/s", what, bytes / 1e6, s, bytes / 1e6 / s);
    if (rays)
        printf("  %7.2f Mrays/s", rays / 1e6 / s);
    printf("\n");
}

/* ---- building blocks -------------------------------------------------------- */

static void bench_blocks(const float *v, size_t nfloats) {
    const size_t bytes = 4 * nfloats, text = kdr_base64_encoded_len(bytes);
    char *b64 = xmalloc(text), *copy = xmalloc(text);
    float *back = xmalloc(bytes);
    char *digits = xmalloc(nfloats * KDR_FLOAT_CHARS);
    double best[4] = {1e30, 1e30, 1e30, 1e30};
    size_t got = 0, bad = 0, chars = 0;
    for (int r = 0; r < REPEAT; r++) {
        double t0 = cpu_seconds();
        memcpy(copy, v, bytes);
        double t1 = cpu_seconds();
        kdr_base64_encode(v, bytes, b64);
        double t2 = cpu_seconds();
        if (kdr_base64_decode(b64, text, back, &got, &bad) || memcmp(back, v, bytes))
            printf("base64 round trip FAILED\n");
        double t3 = cpu_seconds();
        char *p = digits;
        for (size_t i = 0; i < nfloats; i++)
            p += kdr_format_float(v[i], p);
        double t4 = cpu_seconds();
        chars = (size_t)(p - digits);
        const double dt[4] = {t1 - t0, t2 - t1, t3 - t2, t4 - t3};
        for (int k = 0; k < 4; k++)
            best[k] = dt[k] < best[k] ? dt[k] : best[k];
    }
    printf("%zu floats (%zu bytes); base64 rates are of the binary bytes\n", nfloats,
           bytes);
    report("memcpy (reference)", bytes, 0, best[0]);
    memcpy_mbs = bytes / 1e6 / best[0];
    report_rate(R_B64_ENC, "base64 encode", bytes, 0, best[1]);
    report_rate(R_B64_DEC, "base64 decode", bytes, 0, best[2]);
    report("float printing (text)", chars, 0, best[3]);
    printf("%-30s %8.1f Mfloats/s; base64 at %.2fx / %.2fx memcpy (enc/dec)\n",
           "float printing", nfloats / 1e6 / best[3], best[0] / best[1], best[0] / best[2]);
    free(b64), free(copy), free(back), free(digits);
}

static void report_rate(int row, const char *what, size_t bytes, size_t rays, double s) {
    rate[row] = bytes / 1e6 / s;
    report(what, bytes, rays, s);
}

/* ---- requests and answers ---------------------------------------------------- */

static size_t head_len(size_t v) {
    return v < 24 ? 1 : v < 256 ? 2 : v < 65536 ? 3 : v <= 0xffffffffu ? 5 : 9;
}

/* A padding member (pad_key: 0..3 characters of text) that puts the payload
 * of the typed-array member after it at an offset = misalign (mod 4), then
 * that member: key, tag 85, byte string of n float32. */
static void cbor_member(kdr_buf *b, const char *pad_key, const char *key, const float *v,
                        size_t n, int misalign) {
    unsigned char head[32];
    const size_t bare = b->len + 1 + strlen(pad_key) + 1 + head_len(strlen(key)) +
                        strlen(key) + 2 + head_len(4 * n);
    const size_t pad = (size_t)((4 + misalign) - (int)(bare % 4)) % 4;
    size_t k = cbor_encode_string_start(strlen(pad_key), head, sizeof head);
    kdr_buf_append(b, head, k);
    kdr_buf_append(b, pad_key, strlen(pad_key));
    k = cbor_encode_string_start(pad, head, sizeof head);
    kdr_buf_append(b, head, k);
    kdr_buf_append(b, "xxx", pad);
    k = cbor_encode_string_start(strlen(key), head, sizeof head);
    kdr_buf_append(b, head, k);
    kdr_buf_append(b, key, strlen(key));
    k = cbor_encode_tag(85, head, sizeof head);
    k += cbor_encode_bytestring_start(4 * n, head + k, sizeof head - k);
    kdr_buf_append(b, head, k);
    kdr_buf_append(b, v, 4 * n);
}

/* {"_a": pad, "origins": 85(...), "_b": pad, "directions": 85(...),
 * "tmax": 1e30} with both payloads at offsets = misalign (mod 4). */
static void cbor_body(kdr_buf *b, const float *org, const float *dir, size_t n,
                      int misalign) {
    kdr_buf_append(b, "\xa5", 1);
    cbor_member(b, "_a", "origins", org, 3 * n, misalign);
    cbor_member(b, "_b", "directions", dir, 3 * n, misalign);
    kdr_buf_append(b, "\x64tmax\xfb\x46\x29\xe0\x00\x00\x00\x00\x00", 14);
}

static void bench_parse_cbor(const float *org, const float *dir, size_t n, int misalign) {
    kdr_buf body;
    kdr_buf_init(&body);
    cbor_body(&body, org, dir, n, misalign);
    char *copy = xmalloc(body.len); /* malloc'd, as a server's body is */
    memcpy(copy, body.data, body.len);
    double best = 1e30;
    int in_place = 0;
    for (int r = 0; r < REPEAT; r++) {
        kdr_bundle_request req;
        kdr_proto_error err;
        double t0 = cpu_seconds();
        int st = kdr_proto_parse_bundle_as(KDR_MEDIA_CBOR, copy, body.len, n, &req, &err);
        double t1 = cpu_seconds();
        if (st || memcmp(req.batch.dir, dir, 12 * n) || memcmp(req.batch.org, org, 12 * n))
            printf("parse FAILED: %d %s\n", st, err.detail);
        in_place = !st && !req.owned[0] && !req.owned[1];
        kdr_bundle_request_free(&req);
        best = t1 - t0 < best ? t1 - t0 : best;
    }
    report_rate(misalign ? R_PARSE_CBOR_COPY : R_PARSE_CBOR,
                in_place ? "parse bundle (cbor, in place)" : "parse bundle (cbor, copied)",
                body.len, n, best);
    free(copy);
    kdr_buf_free(&body);
}

static void bench_parse(const float *org, const float *dir, size_t n, int b64) {
    kdr_buf body;
    kdr_buf_init(&body);
    kdr_buf_append(&body, "{", 1);
    put_floats(&body, "\"origins\":", org, 3 * n, b64);
    put_floats(&body, ",\"directions\":", dir, 3 * n, b64);
    kdr_buf_append(&body, ",\"tmax\":1e30}", 13);
    double best = 1e30;
    for (int r = 0; r < REPEAT; r++) {
        kdr_bundle_request req;
        kdr_proto_error err;
        double t0 = cpu_seconds();
        int st = kdr_proto_parse_bundle(body.data, body.len, n, &req, &err);
        double t1 = cpu_seconds();
        if (st || memcmp(req.batch.dir, dir, 12 * n) || memcmp(req.batch.org, org, 12 * n))
            printf("parse FAILED: %d %s\n", st, err.detail);
        kdr_bundle_request_free(&req);
        best = t1 - t0 < best ? t1 - t0 : best;
    }
    report_rate(b64 ? R_PARSE_B64 : R_PARSE_JSON,
                b64 ? "parse bundle (base64)" : "parse bundle (json)", body.len, n, best);
    kdr_buf_free(&body);
}

static void bench_encode(size_t n, kdr_encoding enc, kdr_query query) {
    float *t = xmalloc(4 * n), *u = xmalloc(4 * n), *v = xmalloc(4 * n);
    int32_t *prim = xmalloc(4 * n);
    for (size_t i = 0; i < n; i++) {
        t[i] = 10.0f * (rnd() + 1.0f);
        u[i] = 0.5f * (rnd() + 1.0f);
        v[i] = 0.5f * (1.0f - u[i]);
        prim[i] = i % 4 == 0 ? -1 : (int32_t)(i * 7919u % 1000000u);
    }
    uint8_t *hit = xmalloc(n);
    for (size_t i = 0; i < n; i++)
        hit[i] = prim[i] >= 0;
    kdr_hits h = {.t = t, .prim = prim, .u = u, .v = v, .hit = hit};
    double best = 1e30;
    size_t len = 0;
    for (int r = 0; r < REPEAT; r++) {
        kdr_buf out;
        kdr_buf_init(&out);
        double t0 = cpu_seconds();
        kdr_proto_encode_hits(&h, n, query, enc, &out);
        double t1 = cpu_seconds();
        len = out.len;
        kdr_buf_free(&out);
        best = t1 - t0 < best ? t1 - t0 : best;
    }
    static const char *const names[2][3] = {
        {"encode closest (json)", "encode closest (base64)", "encode closest (cbor)"},
        {"encode any (json)", "encode any (base64)", "encode any (cbor)"}};
    const int row = query == KDR_ANY ? R_ENC_CBOR_ANY
                    : enc == KDR_ENCODING_CBOR   ? R_ENC_CBOR
                    : enc == KDR_ENCODING_BASE64 ? R_ENC_B64
                                                 : R_ENC_JSON;
    report_rate(row, names[query == KDR_ANY][enc], len, n, best);
    free(t), free(u), free(v), free(prim), free(hit);
}

/* The targets of bench/protocol.cmake, as fractions of memcpy's MB/s in
 * this run: binary bodies and base64 at memory speed (the issue: "memcpy-
 * speed handling of 40 MB of raw arrays is about 10 ms"), JSON numbers as
 * fast as a shortest-round-trip printer allows. */
static int print_targets(void) {
    static const struct {
        int row;
        const char *what;
        double min_ratio;
    } targets[] = {
        {R_B64_ENC, "base64 encode", 0.25},
        {R_B64_DEC, "base64 decode", 0.25},
        {R_PARSE_B64, "parse bundle (base64)", 0.10},
        {R_PARSE_CBOR, "parse bundle (cbor, in place)", 0.25},
        {R_PARSE_CBOR_COPY, "parse bundle (cbor, copied)", 0.10},
        {R_ENC_B64, "encode closest (base64)", 0.07},
        {R_ENC_CBOR, "encode closest (cbor)", 0.10},
        {R_ENC_JSON, "encode closest (json)", 0.015},
    };
    int missed = 0;
    printf("\ntargets (MB/s as a fraction of memcpy's %.0f MB/s in this run):\n", memcpy_mbs);
    for (size_t i = 0; i < sizeof targets / sizeof targets[0]; i++) {
        const double ratio = rate[targets[i].row] / memcpy_mbs;
        const int met = ratio >= targets[i].min_ratio;
        missed += !met;
        printf("  %-30s %6.3fx  target >= %.3fx  %s\n", targets[i].what, ratio,
               targets[i].min_ratio, met ? "met" : "NOT MET");
    }
    return missed;
}

int main(int argc, char **argv) {
    size_t n = 1000000;
    int targets = 0;
    for (int i = 1; i < argc; i++) {
        if (!strcmp(argv[i], "--targets"))
            targets = 1;
        else
            n = strtoull(argv[i], NULL, 10);
    }
    float *org = xmalloc(12 * n), *dir = xmalloc(12 * n);
    for (size_t i = 0; i < 3 * n; i++) {
        org[i] = 100.0f * rnd();
        dir[i] = rnd();
    }
    for (size_t i = 0; i < n; i++)
        dir[3 * i] = 1.0f; /* never a zero direction */
    bench_blocks(org, 3 * n);
    printf("%zu rays, per-ray origins, random floats; best of %d\n", n, REPEAT);
    bench_parse(org, dir, n, 0);
    bench_parse(org, dir, n, 1);
    bench_parse_cbor(org, dir, n, 0);
    bench_parse_cbor(org, dir, n, 1);
    bench_encode(n, KDR_ENCODING_JSON, KDR_CLOSEST);
    bench_encode(n, KDR_ENCODING_BASE64, KDR_CLOSEST);
    bench_encode(n, KDR_ENCODING_CBOR, KDR_CLOSEST);
    bench_encode(n, KDR_ENCODING_CBOR, KDR_ANY);
    free(org), free(dir);
    return targets && print_targets() ? 1 : 0;
}
