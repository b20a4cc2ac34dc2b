/*
 * test_protocol.c — protocol/ request parsing: every request error path
 * with its exact detail (the err_cases table), the fast top-level walk
 * against the all-cJSON path on those bodies and on number edge cases,
 * and successful bundle, shadow and frustum requests, with both
 * float-array forms (JSON numbers and base64) parsing to the same bits.
 * Codecs and answers are test_protocol_encode.c's. A plain C program:
 * exits nonzero when any check fails.
 */
#include <float.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "kdr_protocol.h"
#include "test_protocol_util.h"

static size_t put_str(char *dst, const char *s) {
    size_t n = strlen(s);
    memcpy(dst, s, n);
    return n;
}

/* ---- request errors: every path, exact detail ---------------------------------- */

enum { BUNDLE, SHADOW, FRUSTUM };

/* Runs one parser; returns the status and frees whatever it parsed. */
static int parse_any(int kind, const char *body, size_t len, size_t max_rays,
                     kdr_proto_error *err) {
    int st;
    if (kind == BUNDLE) {
        kdr_bundle_request r;
        st = kdr_proto_parse_bundle(body, len, max_rays, &r, err);
        kdr_bundle_request_free(&r);
    } else if (kind == SHADOW) {
        kdr_shadow_request r;
        st = kdr_proto_parse_shadow(body, len, max_rays, &r, err);
        kdr_shadow_request_free(&r);
    } else {
        kdr_frustum_request r;
        st = kdr_proto_parse_frustum(body, len, max_rays, &r, err);
    }
    return st;
}

static void expect_error(int kind, const char *body, size_t max_rays, int status,
                         const char *detail) {
    kdr_proto_error err = {0, ""};
    /* bodies are not NUL-terminated: parse from an exact-size copy */
    size_t len = strlen(body);
    char *copy = xmalloc(len ? len : 1);
    memcpy(copy, body, len);
    int st = parse_any(kind, copy, len, max_rays, &err);
    free(copy);
    CHECK(st == status && err.status == status && !strcmp(err.detail, detail),
          "%s\n    got %d \"%s\"\n    want %d \"%s\"", body, st, err.detail, status,
          detail);
}

#define LIGHT "\"lights\":[{\"center\":[0,10,0],\"radius\":1}]"
#define CAM(extra) "{\"camera\":{\"eye\":[0,0,5],\"target\":[0,0,0]," extra "}}"
#define CAMOK "\"fov_y_deg\":60,\"width\":4,\"height\":3"

static const struct err_case {
    int kind;
    const char *body;
    size_t max_rays;
    int status;
    const char *detail;
} err_cases[] = {
    {BUNDLE, "", 0, 400, "body: empty"},
    {BUNDLE, "{\"a\":1} x", 0, 400, "body: malformed JSON at offset 8 (data after the value)"},
    {BUNDLE, "[1,2]", 0, 400, "body: expected a JSON object"},
    {BUNDLE, "{}", 0, 400, "directions: required"},
    {BUNDLE, "{\"directions\":\"abc\"}", 0, 400,
     "directions: expected an array of numbers or {\"f32\": base64}"},
    {BUNDLE, "{\"directions\":{\"x\":1}}", 0, 400,
     "directions: expected an array of numbers or {\"f32\": base64}"},
    {BUNDLE, "{\"directions\":{\"f32\":5}}", 0, 400, "directions.f32: expected a base64 string"},
    {BUNDLE, "{\"directions\":[1,0]}", 0, 400, "directions: length 2 is not 3*N with N >= 1"},
    {BUNDLE, "{\"directions\":[]}", 0, 400, "directions: length 0 is not 3*N with N >= 1"},
    {BUNDLE, "{\"directions\":[1,0,0]}", 0, 400, "origins: required"},
    {BUNDLE, "{\"directions\":[1,0,0,0,1,0,0,0,1,1,1,1],\"origins\":[0,0,0,1,1,1,2]}", 0, 400,
     "origins: length 7 is not 3 or 3*N (N=4)"},
    {BUNDLE, "{\"origins\":[0,0,0],\"directions\":[1,0,\"x\"]}", 0, 400,
     "directions[2]: not a number"},
    {BUNDLE, "{\"origins\":[0,0,0],\"directions\":[1,0,1e39]}", 0, 400,
     "directions[2]: out of float32 range"},
    {BUNDLE, "{\"origins\":[0,0,0],\"directions\":[1,0,1e999]}", 0, 400,
     "directions[2]: not a finite number"},
    {BUNDLE, "{\"origins\":[0,0,0],\"directions\":[1,0,0,0,0,0]}", 0, 400,
     "directions[1]: zero direction"},
    {BUNDLE, "{\"origins\":[0,0,0],\"directions\":{\"f32\":\"AAAAAAAA\"}}", 0, 400,
     "directions.f32: 6 bytes is not a multiple of 4"},
    {BUNDLE, "{\"origins\":[0,0,0],\"directions\":{\"f32\":\"AAAAAAAAAAA*AAAA\"}}", 0, 400,
     "directions.f32: invalid base64 at offset 11"},
    {BUNDLE, "{\"origins\":[0,0,0],\"directions\":{\"f32\":\"AAAAAAAAAA\"}}", 0, 400,
     "directions.f32: invalid base64 at offset 10"},
    {BUNDLE, "{\"origins\":[0,0,0],\"directions\":{\"f32\":\"AAAAAAAAAAAAAAAA\"}}", 0, 400,
     "directions[0]: zero direction"},
    {BUNDLE, "{\"origins\":{\"f32\":\"!AAAAAAAAAAAAAAA\"},\"directions\":[1,0,0]}", 0, 400,
     "origins.f32: invalid base64 at offset 0"},
    {BUNDLE, "{\"origins\":[0,0,0],\"directions\":[1,0,0],\"tmin\":\"x\"}", 0, 400,
     "tmin: expected a number, an array of N numbers or {\"f32\": base64}"},
    {BUNDLE, "{\"origins\":[0,0,0],\"directions\":[1,0,0],\"tmax\":[1,2]}", 0, 400,
     "tmax: length 2 is not N=1"},
    {BUNDLE, "{\"origins\":[0,0,0],\"directions\":[1,0,0,0,1,0],\"tmax\":[1,\"a\"]}", 0, 400,
     "tmax[1]: not a number"},
    {BUNDLE, "{\"origins\":[0,0,0],\"directions\":[1,0,0],\"query\":\"nearest\"}", 0, 400,
     "query: must be \"closest\", \"any\", \"all\" or \"count\""},
    {BUNDLE, "{\"origins\":[0,0,0],\"directions\":[1,0,0],\"encoding\":5}", 0, 400,
     "encoding: must be \"json\" or \"base64\""},
    {BUNDLE, "{\"origins\":[0,0,0],\"directions\":[1,0,0,0,1,0,0,0,1]}", 2, 413,
     "batch of 3 rays exceeds the limit of 2"},
    {BUNDLE, "{\"origins\":[0,0,0],\"directions\":[1,0,0],\"deadline_ms\":0}", 0, 400, "deadline_ms: must be a number of milliseconds in (0, 86400000]"},
    {BUNDLE, "{\"origins\":[0,0,0],\"directions\":[1,0,0],\"deadline_ms\":-5}", 0, 400, "deadline_ms: must be a number of milliseconds in (0, 86400000]"},
    {BUNDLE, "{\"origins\":[0,0,0],\"directions\":[1,0,0],\"deadline_ms\":\"9\"}", 0, 400,
     "deadline_ms: must be a number of milliseconds in (0, 86400000]"},
    {BUNDLE, "{\"origins\":[0,0,0],\"directions\":[1,0,0],\"deadline_ms\":86400001}", 0,
     400, "deadline_ms: must be a number of milliseconds in (0, 86400000]"},

    {SHADOW, "{}", 0, 400, "lights: required"},
    {SHADOW, "{\"lights\":[]}", 0, 400, "lights: expected an array of 1..64 lights"},
    {SHADOW, "{\"lights\":{}}", 0, 400, "lights: expected an array of 1..64 lights"},
    {SHADOW, "{\"lights\":[5]}", 0, 400, "lights[0]: expected an object"},
    {SHADOW, "{\"lights\":[{\"radius\":1}]}", 0, 400, "lights[0].center: required"},
    {SHADOW, "{\"lights\":[{\"center\":[0,0],\"radius\":1}]}", 0, 400,
     "lights[0].center: expected 3 numbers, got 2"},
    {SHADOW, "{\"lights\":[{\"center\":[0,9,0]}]}", 0, 400, "lights[0].radius: required"},
    {SHADOW, "{\"lights\":[{\"center\":[0,9,0],\"radius\":1},{\"center\":[0,9,0],\"radius\":0}]}",
     0, 400, "lights[1].radius: must be > 0"},
    {SHADOW, "{\"lights\":[{\"center\":[0,9,0],\"radius\":-2}]}", 0, 400,
     "lights[0].radius: must be > 0"},
    {SHADOW, "{\"lights\":[{\"center\":[0,9,0],\"radius\":\"a\"}]}", 0, 400,
     "lights[0].radius: not a number"},
    {SHADOW, "{" LIGHT ",\"samples\":0}", 0, 400, "samples: must be an integer in 1..4096"},
    {SHADOW, "{" LIGHT ",\"samples\":4097}", 0, 400, "samples: must be an integer in 1..4096"},
    {SHADOW, "{" LIGHT ",\"samples\":1.5}", 0, 400, "samples: must be an integer in 1..4096"},
    {SHADOW, "{" LIGHT ",\"samples\":\"64\"}", 0, 400, "samples: must be an integer in 1..4096"},
    {SHADOW, "{" LIGHT ",\"seed\":-1}", 0, 400, "seed: must be an integer in 0..2^53"},
    {SHADOW, "{" LIGHT ",\"seed\":9007199254740994}", 0, 400,
     "seed: must be an integer in 0..2^53"},
    {SHADOW, "{" LIGHT ",\"epsilon\":-1}", 0, 400,
     "epsilon: must be \"auto\" or a finite number >= 0"},
    {SHADOW, "{" LIGHT ",\"epsilon\":\"x\"}", 0, 400,
     "epsilon: must be \"auto\" or a finite number >= 0"},
    {SHADOW, "{" LIGHT ",\"epsilon\":\"AUTO\"}", 0, 400,
     "epsilon: must be \"auto\" or a finite number >= 0"},
    {SHADOW, "{" LIGHT ",\"epsilon\":null}", 0, 400,
     "epsilon: must be \"auto\" or a finite number >= 0"},
    {SHADOW, "{" LIGHT ",\"epsilon\":1e39}", 0, 400,
     "epsilon: must be \"auto\" or a finite number >= 0"},
    {SHADOW, "{" LIGHT ",\"stats\":1}", 0, 400, "stats: must be true or false"},
    {SHADOW, "{" LIGHT ",\"encoding\":\"hex\"}", 0, 400,
     "encoding: must be \"json\" or \"base64\""},
    {SHADOW, "{" LIGHT "}", 0, 400, "points: required"},
    {SHADOW, "{" LIGHT ",\"points\":[0,0,0],\"deadline_ms\":null}", 0, 400, "deadline_ms: must be a number of milliseconds in (0, 86400000]"},
    {SHADOW, "{" LIGHT ",\"points\":[0,0]}", 0, 400,
     "points: length 2 is not 3*N with N >= 1"},
    {SHADOW, "{" LIGHT ",\"points\":[0,0,0],\"normals\":[0,0,1,0]}", 0, 400,
     "normals: length 4 is not 3*N (N=1)"},
    {SHADOW, "{" LIGHT ",\"points\":[0,0,0],\"normals\":[0,0,\"z\"]}", 0, 400,
     "normals[2]: not a number"},
    {SHADOW, "{" LIGHT ",\"points\":[0,0,0,5,5,5,0,9.5,0]}", 0, 400,
     "points[2]: inside lights[0]"},
    {SHADOW, "{" LIGHT ",\"points\":[0,9,0]}", 0, 400, "points[0]: inside lights[0]"},
    {SHADOW, "{\"lights\":[{\"center\":[0,10,0],\"radius\":1},{\"center\":[5,0,0],"
             "\"radius\":0.5}],\"points\":[0,0,0,5,0.25,0]}",
     0, 400, "points[1]: inside lights[1]"},
    {SHADOW, "{" LIGHT ",\"points\":[0,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0]}",
     100, 413, "batch of 640 rays (points*lights*samples) exceeds the limit of 100"},

    {FRUSTUM, "{}", 0, 400, "camera: required"},
    {FRUSTUM, "{\"camera\":5}", 0, 400, "camera: expected an object"},
    {FRUSTUM, "{\"camera\":{}}", 0, 400, "camera.eye: required"},
    {FRUSTUM, "{\"camera\":{\"eye\":[0,0]}}", 0, 400, "camera.eye: expected 3 numbers, got 2"},
    {FRUSTUM, "{\"camera\":{\"eye\":[0,0,0]}}", 0, 400, "camera.target: required"},
    {FRUSTUM, CAM("\"width\":4"), 0, 400, "camera.fov_y_deg: required"},
    {FRUSTUM, CAM("\"fov_y_deg\":180"), 0, 400, "camera.fov_y_deg: must be a number in (0, 180)"},
    {FRUSTUM, CAM("\"fov_y_deg\":0"), 0, 400, "camera.fov_y_deg: must be a number in (0, 180)"},
    {FRUSTUM, CAM("\"fov_y_deg\":\"60\""), 0, 400,
     "camera.fov_y_deg: must be a number in (0, 180)"},
    {FRUSTUM, CAM("\"fov_y_deg\":60"), 0, 400, "camera.width: required"},
    {FRUSTUM, CAM("\"fov_y_deg\":60,\"width\":0"), 0, 400,
     "camera.width: must be an integer in 1..16384"},
    {FRUSTUM, CAM("\"fov_y_deg\":60,\"width\":16385"), 0, 400,
     "camera.width: must be an integer in 1..16384"},
    {FRUSTUM, CAM("\"fov_y_deg\":60,\"width\":10.5"), 0, 400,
     "camera.width: must be an integer in 1..16384"},
    {FRUSTUM, CAM("\"fov_y_deg\":60,\"width\":4"), 0, 400, "camera.height: required"},
    {FRUSTUM, CAM("\"fov_y_deg\":60,\"width\":4,\"height\":-3"), 0, 400,
     "camera.height: must be an integer in 1..16384"},
    {FRUSTUM, "{\"camera\":{\"eye\":[1,2,3],\"target\":[1,2,3]," CAMOK "}}", 0, 400,
     "camera: eye and target coincide"},
    {FRUSTUM, "{\"camera\":{\"eye\":[0,0,0],\"target\":[0,5,0]," CAMOK "}}", 0, 400,
     "camera.up: parallel to the view direction"},
    {FRUSTUM, CAM(CAMOK ",\"up\":[0,0,0]"), 0, 400, "camera.up: zero vector"},
    {FRUSTUM, CAM(CAMOK ",\"up\":[0,1]"), 0, 400, "camera.up: expected 3 numbers, got 2"},
    {FRUSTUM, "{\"camera\":{\"eye\":[0,0,5],\"target\":[0,0,0]," CAMOK "},\"tile\":3}", 0, 400,
     "tile: must be an integer in 4..64"},
    {FRUSTUM, "{\"camera\":{\"eye\":[0,0,5],\"target\":[0,0,0]," CAMOK "},\"tile\":65}", 0, 400,
     "tile: must be an integer in 4..64"},
    {FRUSTUM, "{\"camera\":{\"eye\":[0,0,5],\"target\":[0,0,0]," CAMOK "},\"tile\":8.5}", 0,
     400, "tile: must be an integer in 4..64"},
    {FRUSTUM, "{\"camera\":{\"eye\":[0,0,5],\"target\":[0,0,0]," CAMOK "},\"query\":\"all\"}", 0,
     400, "query: must be \"closest\" or \"any\""},
    {FRUSTUM, "{\"camera\":{\"eye\":[0,0,5],\"target\":[0,0,0]," CAMOK "},\"encoding\":null}",
     0, 400, "encoding: must be \"json\" or \"base64\""},
    {FRUSTUM, "{\"camera\":{\"eye\":[0,0,5],\"target\":[0,0,0]," CAMOK "},\"deadline_ms\":1e99}",
     0, 400, "deadline_ms: must be a number of milliseconds in (0, 86400000]"},
    {FRUSTUM, "{\"camera\":{\"eye\":[0,0,5],\"target\":[0,0,0],\"fov_y_deg\":60,\"width\":100,"
              "\"height\":100}}",
     9999, 413, "batch of 10000 rays exceeds the limit of 9999"},
};

/* Errors inside base64 arrays: NaN / Inf elements are named. */
static void test_base64_element_errors(void) {
    float dir[6] = {1, 0, 0, 0, NAN, 0}, tmax[4] = {1, INFINITY, 2, NAN};
    char body[512], *b1 = b64_of(dir, sizeof dir), *b2 = b64_of(tmax, sizeof tmax);
    snprintf(body, sizeof body, "{\"origins\":[0,0,0],\"directions\":{\"f32\":\"%s\"}}", b1);
    expect_error(BUNDLE, body, 0, 400, "directions[4]: not a finite number");
    dir[4] = -INFINITY;
    free(b1);
    b1 = b64_of(dir, sizeof dir);
    snprintf(body, sizeof body, "{\"origins\":[0,0,0],\"directions\":{\"f32\":\"%s\"}}", b1);
    expect_error(BUNDLE, body, 0, 400, "directions[4]: not a finite number");
    snprintf(body, sizeof body,
             "{\"origins\":[0,0,0],\"directions\":[1,0,0,0,1,0,0,0,1,1,1,1],"
             "\"tmax\":{\"f32\":\"%s\"}}",
             b2);
    expect_error(BUNDLE, body, 0, 400, "tmax[3]: not a number");
    free(b1);
    free(b2);
}

static void test_errors(void) {
    for (size_t i = 0; i < sizeof err_cases / sizeof err_cases[0]; i++)
        expect_error(err_cases[i].kind, err_cases[i].body, err_cases[i].max_rays,
                     err_cases[i].status, err_cases[i].detail);
    /* malformed JSON names an offset; truncated bodies of a valid request
     * are all errors, never a crash */
    const char *good = "{\"origins\":[0,0,0],\"directions\":[1,0,0]}";
    for (size_t len = 0; len < strlen(good); len++) {
        kdr_proto_error err;
        char *copy = xmalloc(len ? len : 1);
        memcpy(copy, good, len);
        int st = parse_any(BUNDLE, copy, len, 0, &err);
        free(copy);
        CHECK(st == 400 && (len == 0 || !strncmp(err.detail, "body: malformed JSON at offset ",
                                                 31)),
              "prefix %zu: %d %s", len, st, err.detail);
    }
    test_base64_element_errors();
}

/* ---- successful requests ------------------------------------------------------------ */

static int parse_bundle_str(const char *body, kdr_bundle_request *r) {
    kdr_proto_error err;
    int st = kdr_proto_parse_bundle(body, strlen(body), 0, r, &err);
    CHECK(st == 0, "%s: %d %s", body, st, err.detail);
    return st;
}

static void test_bundle_ok(void) {
    kdr_bundle_request r;
    /* shared origin, defaults: tmin 0, tmax +inf, closest, json */
    if (!parse_bundle_str("{\"origins\":[1,2,3],\"directions\":[1,0,0,0,-0.5,1e-45],"
                          "\"unknown\":{\"x\":[1]}}",
                          &r)) {
        const kdr_ray_batch *b = &r.batch;
        CHECK(b->n == 2 && b->org_stride == 0 && b->tmin_stride == 0 && b->tmax_stride == 0,
              "shape");
        CHECK(b->org[0] == 1 && b->org[1] == 2 && b->org[2] == 3, "origin");
        CHECK(b->dir[4] == -0.5f && same_bits(b->dir[5], 1e-45f) && b->dir[0] == 1, "dirs");
        CHECK(b->tmin[0] == 0.0f && isinf(b->tmax[0]) && b->tmax[0] > 0, "defaults");
        CHECK(r.query == KDR_CLOSEST && r.encoding == KDR_ENCODING_JSON, "enums");
        CHECK(r.deadline_ms == 0.0, "no deadline by default");
        kdr_bundle_request_free(&r);
    }
    /* per-ray arrays, tmax 1e30 and 1e300 (saturates), any, base64 */
    if (!parse_bundle_str("{\"origins\":[0,0,0,1,1,1],\"directions\":[1,0,0,0,1,0],"
                          "\"tmin\":[0.5,-1e300],\"tmax\":[1e30,1e300],\"query\":\"any\","
                          "\"encoding\":\"base64\",\"deadline_ms\":86400000}",
                          &r)) {
        const kdr_ray_batch *b = &r.batch;
        CHECK(b->org_stride == 3 && b->tmin_stride == 1 && b->tmax_stride == 1, "strides");
        CHECK(b->org[3] == 1 && b->tmin[0] == 0.5f && isinf(b->tmin[1]) && b->tmin[1] < 0,
              "tmin");
        CHECK(b->tmax[0] == 1e30f && isinf(b->tmax[1]), "tmax");
        CHECK(r.query == KDR_ANY && r.encoding == KDR_ENCODING_BASE64, "enums");
        CHECK(r.deadline_ms == 86400000.0, "deadline_ms at its maximum");
        kdr_bundle_request_free(&r);
    }
    /* scalar tmin/tmax numbers */
    if (!parse_bundle_str("{\"origins\":[0,0,0],\"directions\":[0,0,2],\"tmin\":0.25,"
                          "\"tmax\":1e30}",
                          &r)) {
        CHECK(r.batch.tmin[0] == 0.25f && r.batch.tmax[0] == 1e30f, "scalars");
        kdr_bundle_request_free(&r);
    }
}

/* The same rays as JSON numbers and as base64 parse to identical bits. */
static void test_both_forms(size_t n) {
    float *org = xmalloc(12 * n), *dir = xmalloc(12 * n), *tmax = xmalloc(4 * n);
    for (size_t i = 0; i < 3 * n; i++) {
        uint32_t bits = (uint32_t)rng() & 0xbfffffffu; /* finite: exponent < 255 */
        memcpy(&org[i], &bits, 4);
        dir[i] = (float)((int)(rng() % 2001) - 1000) / 7.0f;
    }
    for (size_t i = 0; i < n; i++) {
        dir[3 * i] = 1.0f + (float)i; /* never zero */
        tmax[i] = (float)(rng() % 1000) * 0.37f;
    }
    char *b_org = b64_of(org, 12 * n), *b_dir = b64_of(dir, 12 * n), *b_tmax = b64_of(tmax, 4 * n);
    size_t cap = 64 * n + 3 * (16 * n) + 256;
    char *body_json = xmalloc(cap * 2), *body_b64 = xmalloc(cap);
    size_t len = put_str(body_json, "{\"origins\":[");
    for (size_t i = 0; i < 3 * n; i++) {
        len += put_str(body_json + len, i ? "," : "");
        len += kdr_format_float(org[i], body_json + len);
    }
    len += put_str(body_json + len, "],\"directions\":[");
    for (size_t i = 0; i < 3 * n; i++) {
        len += put_str(body_json + len, i ? "," : "");
        len += kdr_format_float(dir[i], body_json + len);
    }
    len += put_str(body_json + len, "],\"tmax\":[");
    for (size_t i = 0; i < n; i++) {
        len += put_str(body_json + len, i ? "," : "");
        len += kdr_format_float(tmax[i], body_json + len);
    }
    len += put_str(body_json + len, "]}");
    size_t len2 = (size_t)sprintf(body_b64,
                                  "{\"origins\":{\"f32\":\"%s\"},\"directions\":{\"f32\":\"%s\"},"
                                  "\"tmax\":{\"f32\":\"%s\"}}",
                                  b_org, b_dir, b_tmax);
    kdr_bundle_request a, b;
    kdr_proto_error err;
    int sa = kdr_proto_parse_bundle(body_json, len, 0, &a, &err);
    CHECK(sa == 0, "json form: %s", err.detail);
    int sb = kdr_proto_parse_bundle(body_b64, len2, 0, &b, &err);
    CHECK(sb == 0, "base64 form: %s", err.detail);
    if (!sa && !sb) {
        CHECK(a.batch.n == n && b.batch.n == n, "n");
        CHECK(!memcmp(a.batch.org, org, 12 * n) && !memcmp(b.batch.org, org, 12 * n), "org");
        CHECK(!memcmp(a.batch.dir, dir, 12 * n) && !memcmp(b.batch.dir, dir, 12 * n), "dir");
        CHECK(!memcmp(a.batch.tmax, tmax, 4 * n) && !memcmp(b.batch.tmax, tmax, 4 * n),
              "tmax");
    }
    kdr_bundle_request_free(&a);
    kdr_bundle_request_free(&b);
    free(org), free(dir), free(tmax), free(b_org), free(b_dir), free(b_tmax);
    free(body_json), free(body_b64);
}

static void test_shadow_ok(void) {
    kdr_shadow_request r;
    kdr_proto_error err;
    const char *body = "{\"points\":[0,0,0,1,1,1],\"lights\":[{\"center\":[0,10,0],"
                       "\"radius\":0.5},{\"center\":{\"f32\":\"AAAAAAAAIEEAAAAA\"},"
                       "\"radius\":2}]}";
    int st = kdr_proto_parse_shadow(body, strlen(body), 0, &r, &err);
    CHECK(st == 0, "%s", err.detail);
    if (!st) {
        const kdr_shadow_query *q = &r.query;
        CHECK(q->n == 2 && q->nlights == 2 && q->normals == NULL, "shape");
        CHECK(q->samples == KDR_PROTO_DEFAULT_SAMPLES && q->seed == 1 &&
                  q->offset == KDR_OFFSET_AUTO && !r.want_stats,
              "defaults (API v1.1: epsilon \"auto\")");
        CHECK(q->lights[1].center[1] == 10.0f && q->lights[1].radius == 2.0f, "light 1");
        CHECK(q->points[3] == 1.0f, "points");
    }
    kdr_shadow_request_free(&r);
    body = "{\"points\":[0,0,0],\"normals\":[0,0,0],\"lights\":[{\"center\":[0,10,0],"
           "\"radius\":0.5}],\"samples\":4096,\"seed\":9007199254740992,\"epsilon\":0,"
           "\"stats\":true,\"encoding\":\"base64\",\"deadline_ms\":0.5}";
    st = kdr_proto_parse_shadow(body, strlen(body), 0, &r, &err);
    CHECK(st == 0, "%s", err.detail);
    if (!st) {
        const kdr_shadow_query *q = &r.query;
        CHECK(q->normals && q->samples == 4096 && q->seed == 9007199254740992ull &&
                  q->offset == KDR_OFFSET_DIAGONAL && q->epsilon == 0.0f &&
                  r.want_stats && r.encoding == KDR_ENCODING_BASE64 && r.deadline_ms == 0.5,
              "options");
    }
    kdr_shadow_request_free(&r);
    /* "auto" spelled out; then the scene checks: a numeric epsilon whose
     * offset epsilon * diagonal overflows float is a 400 naming epsilon (v1
     * blamed points[0] through the core's refusal) */
    body = "{\"points\":[0,0,0],\"lights\":[{\"center\":[0,10,0],\"radius\":0.5}],"
           "\"epsilon\":\"auto\"}";
    st = kdr_proto_parse_shadow(body, strlen(body), 0, &r, &err);
    CHECK(st == 0 && r.query.offset == KDR_OFFSET_AUTO, "epsilon auto: %s", err.detail);
    CHECK(st || kdr_proto_check_shadow_scene(&r, 3e38f, &err) == 0,
          "auto never overflows: %s", err.detail);
    kdr_shadow_request_free(&r);
    body = "{\"points\":[0,0,0],\"lights\":[{\"center\":[0,10,0],\"radius\":0.5}],"
           "\"epsilon\":1e30}";
    st = kdr_proto_parse_shadow(body, strlen(body), 0, &r, &err);
    CHECK(st == 0 && r.query.offset == KDR_OFFSET_DIAGONAL, "epsilon 1e30: %s", err.detail);
    if (!st) {
        CHECK(kdr_proto_check_shadow_scene(&r, 100.0f, &err) == 0, "1e30 * 100 is finite");
        const int cs = kdr_proto_check_shadow_scene(&r, 1e9f, &err);
        CHECK(cs == 400 && !strncmp(err.detail, "epsilon: ", 9) &&
                  strstr(err.detail, "not a finite offset"),
              "overflowing offset: %d \"%s\"", cs, err.detail);
    }
    kdr_shadow_request_free(&r);
}

static void test_frustum_ok(void) {
    kdr_frustum_request r;
    kdr_proto_error err;
    const char *body = "{\"camera\":{\"eye\":[0,1,5],\"target\":[0,1,0],\"fov_y_deg\":60,"
                       "\"width\":640,\"height\":480},\"encoding\":\"base64\"}";
    int st = kdr_proto_parse_frustum(body, strlen(body), 0, &r, &err);
    CHECK(st == 0, "%s", err.detail);
    CHECK(r.tile == 8 && r.rays == 640 * 480 && r.query == KDR_CLOSEST &&
              r.encoding == KDR_ENCODING_BASE64 && r.camera.up[1] == 1.0f &&
              r.camera.fov_y_deg == 60.0f && r.camera.eye[2] == 5.0f,
          "frustum fields");
    body = "{\"camera\":{\"eye\":[0,0,0],\"target\":[0,5,0],\"up\":[0,0,1],\"fov_y_deg\":"
           "179.9,\"width\":16384,\"height\":1},\"tile\":64,\"query\":\"any\","
           "\"deadline_ms\":250}";
    st = kdr_proto_parse_frustum(body, strlen(body), 0, &r, &err);
    CHECK(st == 0 && r.tile == 64 && r.query == KDR_ANY && r.camera.width == 16384 &&
              r.deadline_ms == 250.0,
          "%s", err.detail);
}

/* ---- responses, parsed back ------------------------------------------------------- */

/* The same body with a member whose escaped name makes the parser take the
 * all-cJSON path; NULL when body is not an object. */
static char *force_cjson(const char *body) {
    size_t len = strlen(body);
    if (len < 2 || body[0] != '{')
        return NULL;
    const char *rest = body + 1;
    while (*rest == ' ')
        rest++;
    char *out = xmalloc(len + 32);
    snprintf(out, len + 32, "{\"\\u0078\":0%s%s", *rest == '}' ? "" : ",", body + 1);
    return out;
}

static void same_result(int kind, const char *body) {
    char *other = force_cjson(body);
    if (!other)
        return;
    kdr_proto_error e1 = {0, ""}, e2 = {0, ""};
    int s1 = parse_any(kind, body, strlen(body), 0, &e1);
    int s2 = parse_any(kind, other, strlen(other), 0, &e2);
    CHECK(s1 == s2 && (!strncmp(e1.detail, "body:", 5) || !strcmp(e1.detail, e2.detail)),
          "%s: fast %d \"%s\", cJSON %d \"%s\"", body, s1, e1.detail, s2, e2.detail);
    kdr_bundle_request a, b;
    memset(&a, 0, sizeof a);
    memset(&b, 0, sizeof b);
    if (kind == BUNDLE && !kdr_proto_parse_bundle(body, strlen(body), 0, &a, &e1)) {
        if (!kdr_proto_parse_bundle(other, strlen(other), 0, &b, &e2)) {
            const kdr_ray_batch *x = &a.batch, *y = &b.batch;
            CHECK(x->n == y->n && x->org_stride == y->org_stride &&
                      !memcmp(x->dir, y->dir, 12 * x->n) && !memcmp(x->org, y->org, 12) &&
                      !memcmp(x->tmax, y->tmax, 4) && !memcmp(x->tmin, y->tmin, 4),
                  "%s: arrays differ between paths", body);
        }
        kdr_bundle_request_free(&b);
    }
    kdr_bundle_request_free(&a);
    free(other);
}

/* One number as directions[0], both paths: (float)strtod, or the error. */
static void check_number(const char *num) {
    char body[256];
    snprintf(body, sizeof body, "{\"origins\":[0,0,0],\"directions\":[%s,1,1]}", num);
    char *other = force_cjson(body);
    const double d = strtod(num, NULL);
    for (int path = 0; path < 2; path++) {
        const char *b = path ? other : body;
        kdr_bundle_request r;
        kdr_proto_error err = {0, ""};
        int st = kdr_proto_parse_bundle(b, strlen(b), 0, &r, &err);
        if (isinf(d))
            CHECK(st == 400 && !strcmp(err.detail, "directions[0]: not a finite number"),
                  "%s path %d: %s", num, path, err.detail);
        else if (fabs(d) >= 0x1.ffffffp127)
            CHECK(st == 400 && !strcmp(err.detail, "directions[0]: out of float32 range"),
                  "%s path %d: %s", num, path, err.detail);
        else
            CHECK(st == 0 && same_bits(r.batch.dir[0], (float)d), "%s path %d: %s %a", num,
                  path, err.detail, st ? 0.0 : (double)r.batch.dir[0]);
        kdr_bundle_request_free(&r);
    }
    free(other);
}

static void test_fast_walk(void) {
    static const char *nums[] = {
        "0", "-0", "1", "-1", "0.1", "1e-45", "-1.4e-45", "7e-46", "1.5e-7", "2.5E-3", "1E+2",
        "123456789012345678", "0.000000000000000000000000000001", "1e22", "1e23", "9e15",
        "3.4028235e38", "3.40282356e38", "3.4028236e38", "1e39", "-1e39", "1e999", "-1e999",
        "16777217", "0.30000000000000004", "100000000000000000000000000000000000000",
        "4.9406564584124654e-324", "1.00000005960464477539062500000001"};
    for (size_t i = 0; i < sizeof nums / sizeof nums[0]; i++)
        check_number(nums[i]);
    for (int i = 0; i < 2000; i++) { /* random short decimals */
        char num[48];
        snprintf(num, sizeof num, "%s%llu.%llue%d", rng() & 1 ? "-" : "",
                 (unsigned long long)(rng() % 100000), (unsigned long long)(rng() % 10000000),
                 (int)(rng() % 90) - 45);
        check_number(num);
    }
    for (size_t i = 0; i < sizeof err_cases / sizeof err_cases[0]; i++)
        if (err_cases[i].max_rays == 0)
            same_result(err_cases[i].kind, err_cases[i].body);
    static const char *bodies[] = {
        "{\"directions\":[1,0,0],\"directions\":\"x\",\"origins\":[0,0,0]}",
        "{\"directions\":\"x\",\"directions\":[1,0,0],\"origins\":[0,0,0]}",
        "{ \"origins\" : [ 0 , 0 , 0 ] , \"directions\" : [ 1 , 0 , 0 ] }",
        "{\"origins\":[0,0,0],\"directions\":[1,0,0,]}",
        "{\"origins\":[0,0,0],\"directions\":[1,0,[0]]}",
        "{\"origins\":[0,0,0],\"directions\":[1,0,01]}",
        "{\"origins\":[0,0,0],\"directions\":[1,0,1.]}",
        "{\"origins\":[0,0,0],\"directions\":[1,0,.5]}",
        "{\"origins\":[0,0,0],\"directions\":[1,0,+5]}",
        "{\"origins\":[0,0,0],\"directions\":[1,0,1.5.3]}",
        "{\"origins\":[0,0,0],\"directions\":[1,0,null]}",
        "{\"origins\":[0,0,0],\"directions\":[1,0,1]",
        "{\"origins\":[0,0,0],\"directions\":[1,0,1]}}",
        "{\"origins\":[0,0,0] \"directions\":[1,0,1]}",
        "{\"samples\":[1,2],\"points\":[0,0,0]," LIGHT "}",
        "{\"lights\":[],\"points\":[0,0,0]}",
        "{\"tmax\":[],\"origins\":[0,0,0],\"directions\":[1,0,1]}",
        "{\"tmax\":[5],\"origins\":[0,0,0],\"directions\":[1,0,1]}",
        "{\"tmin\":[1e999],\"origins\":[0,0,0],\"directions\":[1,0,1]}",
        "{\"origins\":[0,0,0],\"directions\":[1,0,1],\"tmax\":[-1e39]}",
        "{\"origins\":{\"f32\":\"AAAAAAAAAAAAAAAA\"},\"directions\":{\"f32\":\"AACAPwAAAAAAAAAA\"}}",
        "{\"origins\":{ \"f32\" : \"AAAAAAAAAAAAAAAA\" },\"directions\":{\"f32\":\"AACAPwAAAAAAAAAA\"}}",
        "{\"origins\":{\"f32\":\"AAAAAAAAAAAAAAAA\",\"x\":1},\"directions\":[1,1,1]}",
        "{\"origins\":{\"f32\":\"AAAAAAAAAAAAAAAA\",\"f32\":\"\"},\"directions\":[1,1,1]}",
        "{\"origins\":{\"f32\":\"AAAAAAAAAAAA\\/AAA\"},\"directions\":[1,1,1]}",
        "{\"origins\":{\"f32\":\"AAAAAAAAAAAA/AAA\"},\"directions\":[1,1,1]}",
        "{\"origins\":{\"f\\u0033\\u0032\":\"AAAAAAAAAAAAAAAA\"},\"directions\":[1,1,1]}",
        "{\"origins\":{\"f32\":5},\"directions\":[1,1,1]}",
        "{\"origins\":{\"F32\":\"AAAA\"},\"directions\":[1,1,1]}",
        "{\"origins\":{\"f32\":\"\"},\"directions\":[1,1,1]}",
        "{\"origins\":{\"f32\":\"AAAAAAAAAAA*AAAA\"},\"directions\":[1,1,1]}",
        "{\"origins\":{\"f32\":\"AAAAAAAAAAAAAAAA\"}, \"directions\":{\"f32\":\"AACAPwAAAAAAAAAA\"} ,"
        "\"tmax\":{\"f32\":\"AACAfw==\"}}",
        "{\"points\":{\"f32\":\"AAAAAAAAAAAAAAAA\"},\"normals\":{\"f32\":\"AACAPwAAAAAAAAAA\"},"
        LIGHT "}",
    };
    for (size_t i = 0; i < sizeof bodies / sizeof bodies[0]; i++) {
        same_result(BUNDLE, bodies[i]);
        same_result(SHADOW, bodies[i]);
    }
}

int main(void) {
    test_errors();
    test_fast_walk();
    test_bundle_ok();
    test_both_forms(1);
    test_both_forms(50000);
    test_shadow_ok();
    test_frustum_ok();
    return check_exit("test_protocol");
}
