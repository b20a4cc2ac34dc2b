/*
 * fuzz_request.c — libFuzzer entry point for protocol/: arbitrary bytes go
 * to all three request parsers, as a JSON body and as a CBOR body (not
 * NUL-terminated), and to the strict base64 decoder. Any accepted request
 * must satisfy what the core relies on: the invariants are asserted here,
 * so a parser that lets a bad query through is a crash, not a silent wrong
 * answer. An accepted CBOR bundle is also written out as its JSON twin,
 * which must parse to the same rays bit for bit, and answers of the
 * request's shape are encoded in every encoding. Each body is parsed once
 * more under a parse meter whose limit comes from the input, so that an
 * allocation fails at an arbitrary point: the parse must then end in a 500
 * "out of memory" (never a 400, never a crash or a leak), must never pass
 * the limit, and freeing the request must count back every byte.
 */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "kdr_protocol.h"

/* Small limit so that huge batches exercise the 413 path cheaply. */
#define FUZZ_MAX_RAYS 100000

static void check(int ok) {
    if (!ok) abort();
}

static int finite_n(const float *v, size_t n) {
    for (size_t i = 0; i < n; i++)
        if (!isfinite(v[i])) return 0;
    return 1;
}

static void put_float(kdr_buf *b, float f) {
    char tmp[KDR_FLOAT_CHARS];
    if (isinf(f))
        kdr_buf_append(b, f > 0 ? "1e999" : "-1e999", f > 0 ? 5 : 6);
    else
        kdr_buf_append(b, tmp, kdr_format_float(f, tmp));
}

static void put_floats(kdr_buf *b, const char *key, const float *v, size_t n, int list) {
    kdr_buf_append(b, key, strlen(key));
    if (list) kdr_buf_append(b, "[", 1);
    for (size_t i = 0; i < n; i++) {
        if (i) kdr_buf_append(b, ",", 1);
        put_float(b, v[i]);
    }
    if (list) kdr_buf_append(b, "]", 1);
}

/* An accepted CBOR bundle as JSON parses to the same batch. */
static void json_twin(const kdr_bundle_request *r) {
    const kdr_ray_batch *x = &r->batch;
    kdr_buf j;
    kdr_buf_init(&j);
    put_floats(&j, "{\"origins\":", x->org, x->org_stride ? 3 * x->n : 3, 1);
    put_floats(&j, ",\"directions\":", x->dir, 3 * x->n, 1);
    put_floats(&j, ",\"tmin\":", x->tmin, x->tmin_stride ? x->n : 1, x->tmin_stride);
    put_floats(&j, ",\"tmax\":", x->tmax, x->tmax_stride ? x->n : 1, x->tmax_stride);
    static const char *const q[] = {"closest", "any", "all", "count"};
    char tail[64];
    const int tl =
        r->query == KDR_ALL
            ? snprintf(tail, sizeof tail, ",\"query\":\"all\",\"max_hits\":%u}",
                       (unsigned)r->max_hits)
            : snprintf(tail, sizeof tail, ",\"query\":\"%s\"}", q[r->query]);
    kdr_buf_append(&j, tail, (size_t)tl);
    kdr_bundle_request t;
    kdr_proto_error err;
    check(kdr_proto_parse_bundle(j.data, j.len, FUZZ_MAX_RAYS, &t, &err) == 0);
    const kdr_ray_batch *y = &t.batch;
    check(x->n == y->n && x->org_stride == y->org_stride && t.query == r->query &&
          t.max_hits == r->max_hits);
    check(!memcmp(x->dir, y->dir, 12 * x->n));
    check(!memcmp(x->org, y->org, x->org_stride ? 12 * x->n : 12));
    check(!memcmp(x->tmin, y->tmin, x->tmin_stride ? 4 * x->n : 4));
    check(!memcmp(x->tmax, y->tmax, x->tmax_stride ? 4 * x->n : 4));
    kdr_bundle_request_free(&t);
    kdr_buf_free(&j);
}

static void fuzz_bundle(kdr_media media, const char *body, size_t len) {
    kdr_bundle_request r;
    kdr_proto_error err;
    int st = kdr_proto_parse_bundle_as(media, body, len, FUZZ_MAX_RAYS, &r, &err);
    check(st == err.status || st == 0);
    if (st == 0) {
        const kdr_ray_batch *b = &r.batch;
        check(b->n >= 1 && b->n <= FUZZ_MAX_RAYS);
        check(finite_n(b->org, b->org_stride ? 3 * b->n : 3) &&
              finite_n(b->dir, 3 * b->n));
        for (size_t i = 0; i < b->n; i++)
            check(b->dir[3 * i] != 0 || b->dir[3 * i + 1] != 0 || b->dir[3 * i + 2] != 0);
        for (size_t i = 0; i < (b->tmax_stride ? b->n : 1); i++)
            check(!isnan(b->tmax[i]));
        check(r.fields != 0 || r.query == KDR_COUNT);
        check(r.query == KDR_ALL ? r.max_hits >= 1 && r.max_hits <= KDR_MAX_HITS_LIMIT &&
                                       (uint64_t)b->n * r.max_hits <= FUZZ_MAX_RAYS
                                 : r.max_hits == 0);
        if (media == KDR_MEDIA_CBOR) json_twin(&r);
        /* encode a fake result of the right size every way */
        float *t = calloc(b->n, 4);
        int32_t *prim = calloc(b->n, 4);
        uint8_t *hit = calloc(b->n, 1);
        kdr_hits h = {.t = t, .prim = prim, .u = t, .v = t, .hit = hit};
        check(t && prim && hit);
        int32_t *off = calloc(b->n + 1, 4);
        check(off != NULL);
        float *n3 = calloc(3 * b->n, 4);
        int32_t *m3 = calloc(3 * b->n, 4);
        check(n3 && m3);
        const kdr_all_answer all = {b->n, prim, off, t, t, t, prim, {n3, m3}};
        const kdr_hit_attrs attrs = {n3, m3};
        for (int enc = 0; enc < 3; enc++) {
            kdr_buf out;
            kdr_buf_init(&out);
            const kdr_encoding e = enc ? (kdr_encoding)enc : r.encoding;
            if (r.query == KDR_ALL)
                check(kdr_proto_encode_all(&all, r.fields, e, &out) == 0);
            else if (r.query == KDR_COUNT)
                check(kdr_proto_encode_counts((const uint32_t *)prim, b->n, e, &out) ==
                      0);
            else
                check(kdr_proto_encode_hits_attrs(&h, &attrs, b->n, r.query, r.fields, e,
                                                  &out) == 0);
            kdr_buf_free(&out);
        }
        free(t), free(prim), free(hit), free(off), free(n3), free(m3);
    } else {
        check(st == 400 || st == 413);
        check(memchr(err.detail, '\0', sizeof err.detail) != NULL && err.detail[0]);
    }
    kdr_bundle_request_free(&r);
}

static void fuzz_shadow(kdr_media media, const char *body, size_t len) {
    kdr_shadow_request r;
    kdr_proto_error err;
    int st = kdr_proto_parse_shadow_as(media, body, len, FUZZ_MAX_RAYS, &r, &err);
    if (st == 0) {
        const kdr_shadow_query *q = &r.query;
        check(q->n >= 1 && q->nlights >= 1 && q->nlights <= KDR_PROTO_MAX_LIGHTS);
        check(q->samples >= 1 && q->samples <= KDR_PROTO_MAX_SAMPLES);
        check((uint64_t)q->n * q->nlights * q->samples <= FUZZ_MAX_RAYS);
        check(finite_n(q->points, 3 * q->n) && isfinite(q->epsilon) && q->epsilon >= 0 &&
              (q->offset == KDR_OFFSET_AUTO || q->offset == KDR_OFFSET_DIAGONAL));
        check(!q->normals || finite_n(q->normals, 3 * q->n));
        for (size_t l = 0; l < q->nlights; l++)
            check(q->lights[l].radius > 0 && finite_n(q->lights[l].center, 3));
    } else {
        check(st == 400 || st == 413);
    }
    kdr_shadow_request_free(&r);
}

static void fuzz_frustum(kdr_media media, const char *body, size_t len) {
    kdr_frustum_request r;
    kdr_proto_error err;
    int st = kdr_proto_parse_frustum_as(media, body, len, FUZZ_MAX_RAYS, &r, &err);
    if (st == 0) {
        check(kdr_camera_validate(&r.camera) == KDR_OK && r.fields != 0);
        check(r.tile >= 4 && r.tile <= 64 && r.rays <= FUZZ_MAX_RAYS);
    } else {
        check(st == 400 || st == 413);
    }
}

/* closest-point and occupancy (issue 15): points finite, N within the
 * limit, max_distance >= 0 (not with signed). */
static void fuzz_points(kdr_media media, const char *body, size_t len) {
    kdr_closest_request c;
    kdr_proto_error err;
    int st = kdr_proto_parse_closest_as(media, body, len, FUZZ_MAX_RAYS, &c, &err);
    if (st == 0) {
        check(c.n >= 1 && c.n <= FUZZ_MAX_RAYS && finite_n(c.points, 3 * c.n));
        check(c.max_distance >= 0 && (!c.is_signed || isinf(c.max_distance)));
    } else {
        check(st == 400 || st == 413);
    }
    kdr_closest_request_free(&c);
    kdr_occupancy_request o;
    st = kdr_proto_parse_occupancy_as(media, body, len, FUZZ_MAX_RAYS, &o, &err);
    if (st == 0)
        check(o.n >= 1 && o.n <= FUZZ_MAX_RAYS && finite_n(o.points, 3 * o.n));
    else
        check(st == 400 || st == 413);
    kdr_occupancy_request_free(&o);
}

static void fuzz_base64(const char *s, size_t len) {
    unsigned char *dst = malloc(kdr_base64_decoded_max(len) + 1);
    size_t got = 0, bad = 0;
    check(dst != NULL);
    if (kdr_base64_decode(s, len, dst, &got, &bad) == 0) {
        /* a valid input is canonical: re-encoding gives it back */
        char *enc = malloc(kdr_base64_encoded_len(got) + 1);
        check(enc && kdr_base64_encode(dst, got, enc) == len && !memcmp(enc, s, len));
        free(enc);
    } else {
        check(bad <= len);
    }
    free(dst);
}

/* The parser walks the top level itself and falls back to cJSON for the
 * whole body on anything unusual (here: an escaped member name). Both paths
 * must agree on the status, the detail (offsets of malformed JSON aside)
 * and every float. */
static void fuzz_paths_agree(const char *body, size_t len) {
    static const char extra[] = "{\"\\u0078\":0,";
    if (len < 2 || body[0] != '{') return;
    size_t k = 1;
    while (k < len && (unsigned char)body[k] <= ' ') /* cJSON's whitespace */
        k++;
    const int empty = k < len && body[k] == '}';
    char *other = malloc(len + sizeof extra);
    if (!other) return;
    size_t n = sizeof extra - 1 - (size_t)empty;
    memcpy(other, extra, n);
    memcpy(other + n, body + 1, len - 1);
    kdr_bundle_request a, b;
    kdr_proto_error ea, eb;
    int sa = kdr_proto_parse_bundle(body, len, FUZZ_MAX_RAYS, &a, &ea);
    int sb = kdr_proto_parse_bundle(other, n + len - 1, FUZZ_MAX_RAYS, &b, &eb);
    check(sa == sb);
    if (sa && strncmp(ea.detail, "body:", 5)) check(!strcmp(ea.detail, eb.detail));
    if (!sa) {
        const kdr_ray_batch *x = &a.batch, *y = &b.batch;
        check(x->n == y->n && x->org_stride == y->org_stride);
        check(!memcmp(x->dir, y->dir, 12 * x->n));
        check(!memcmp(x->org, y->org, x->org_stride ? 12 * x->n : 12));
        check(!memcmp(x->tmax, y->tmax, x->tmax_stride ? 4 * x->n : 4));
        check(!memcmp(x->tmin, y->tmin, x->tmin_stride ? 4 * x->n : 4));
    }
    kdr_bundle_request_free(&a);
    kdr_bundle_request_free(&b);
    free(other);
}

/* The parsers under a meter of limit bytes, in both media types. */
static void fuzz_metered(const char *body, size_t len, size_t limit) {
    for (int m = 0; m < 2; m++) {
        const kdr_media media = m ? KDR_MEDIA_CBOR : KDR_MEDIA_JSON;
        for (int kind = 0; kind < 5; kind++) {
            kdr_proto_meter meter = {.limit = limit};
            kdr_proto_meter *outer = kdr_proto_meter_set(&meter);
            kdr_proto_error err;
            int st;
            if (kind == 0) {
                kdr_bundle_request r;
                st = kdr_proto_parse_bundle_as(media, body, len, FUZZ_MAX_RAYS, &r, &err);
                kdr_bundle_request_free(&r);
            } else if (kind == 1) {
                kdr_shadow_request r;
                st = kdr_proto_parse_shadow_as(media, body, len, FUZZ_MAX_RAYS, &r, &err);
                kdr_shadow_request_free(&r);
            } else if (kind == 2) {
                kdr_frustum_request r;
                st =
                    kdr_proto_parse_frustum_as(media, body, len, FUZZ_MAX_RAYS, &r, &err);
            } else if (kind == 3) {
                kdr_closest_request r;
                st =
                    kdr_proto_parse_closest_as(media, body, len, FUZZ_MAX_RAYS, &r, &err);
                kdr_closest_request_free(&r);
            } else {
                kdr_occupancy_request r;
                st = kdr_proto_parse_occupancy_as(media, body, len, FUZZ_MAX_RAYS, &r,
                                                  &err);
                kdr_occupancy_request_free(&r);
            }
            kdr_proto_meter_set(outer);
            check(meter.used == 0); /* every block counted back */
            check((st == 500) == (meter.refused != 0));
            check(st != 500 || strstr(err.detail, "out of memory") != NULL);
        }
    }
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
    /* an exact-size copy, so ASan catches any read past the body */
    char *body = malloc(size ? size : 1);
    if (!body) return 0;
    memcpy(body, data, size);
    for (int m = 0; m < 2; m++) {
        const kdr_media media = m ? KDR_MEDIA_CBOR : KDR_MEDIA_JSON;
        fuzz_bundle(media, body, size);
        fuzz_shadow(media, body, size);
        fuzz_frustum(media, body, size);
        fuzz_points(media, body, size);
    }
    fuzz_base64(body, size);
    fuzz_paths_agree(body, size);
    if (size) fuzz_metered(body, size, (size_t)data[size - 1] * 48);
    free(body);
    return 0;
}
