/*
 * test_protocol_encode.c — protocol/ encodings: base64 against an
 * independent bit-by-bit reference, the float formatter against strtof
 * (exact read-back, shortest form), and every response encoder (hits,
 * shadow visibility, scene list, problem+json errors, health) parsed back
 * with cJSON and compared bit for bit. Requests are test_protocol.c's.
 * A plain C program: exits nonzero when any check fails.
 */
#include <float.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <cjson/cJSON.h>

#include "kdr_protocol.h"
#include "test_protocol_util.h"

/* ---- base64: an independent reference, one bit at a time ------------------ */

static size_t ref_b64(const unsigned char *s, size_t n, char *out) {
    static const char a[] =
        "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    size_t bits = 8 * n, k = 0;
    for (size_t pos = 0; pos < bits; pos += 6) {
        int v = 0;
        for (size_t b = pos; b < pos + 6; b++)
            v = v << 1 | (b < bits ? (s[b / 8] >> (7 - b % 8)) & 1 : 0);
        out[k++] = a[v];
    }
    while (k % 4)
        out[k++] = '=';
    return k;
}

static void test_base64(void) {
    unsigned char src[300] = {0}, back[300];
    char enc[512], ref[512];
    for (size_t n = 0; n < 300; n++) {
        for (size_t i = 0; i < n; i++)
            src[i] = (unsigned char)rng();
        size_t len = kdr_base64_encode(src, n, enc);
        size_t rlen = ref_b64(src, n, ref);
        CHECK(len == rlen && len == kdr_base64_encoded_len(n) && !memcmp(enc, ref, len),
              "encode n=%zu", n);
        size_t got = 99, bad = 99;
        CHECK(kdr_base64_decode(enc, len, back, &got, &bad) == 0 && got == n &&
                  !memcmp(src, back, n),
              "decode n=%zu", n);
    }
    static const struct {
        const char *in;
        int ok;
        size_t offset_or_len;
    } cases[] = {
        {"", 1, 0},        {"QQ==", 1, 1},    {"QUI=", 1, 2},     {"QUJD", 1, 3},
        {"QR==", 0, 1},    {"QUJ=", 0, 2},    {"Q===", 0, 1},     {"QQ=A", 0, 3},
        {"QQ", 0, 2},      {"QUJDR", 0, 5},   {"QU JD", 0, 5},    {"QUJD\nQUJD", 0, 9},
        {"QU*D", 0, 2},    {"QQ==QUJD", 0, 2}, {"QUJDQUJ-", 0, 7}, {"QUJD QUJ", 0, 4},
        {"=QUJ", 0, 0},
    };
    for (size_t c = 0; c < sizeof cases / sizeof cases[0]; c++) {
        size_t got = 0, bad = 0;
        int rc = kdr_base64_decode(cases[c].in, strlen(cases[c].in), back, &got, &bad);
        if (cases[c].ok)
            CHECK(rc == 0 && got == cases[c].offset_or_len, "'%s' -> %zu bytes",
                  cases[c].in, got);
        else
            CHECK(rc == -1 && bad == cases[c].offset_or_len, "'%s' rc %d offset %zu",
                  cases[c].in, rc, bad);
    }
}

/* ---- float formatting ------------------------------------------------------------ */

static int sig_digits(const char *s) {
    char d[32];
    int n = 0;
    for (; *s && *s != 'e'; s++)
        if (*s >= '0' && *s <= '9' && (n || *s != '0'))
            d[n++] = *s;
    while (n && d[n - 1] == '0')
        n--;
    return n;
}

/* Checks exact read-back; returns 1 when a shorter %.Ng would also do. */
static int check_float_text(float f) {
    char buf[KDR_FLOAT_CHARS + 1];
    size_t n = kdr_format_float(f, buf);
    buf[n] = '\0';
    CHECK(n <= KDR_FLOAT_CHARS, "%a: %zu chars", (double)f, n);
    CHECK(!strpbrk(buf, "ni"), "%a printed as %s", (double)f, buf);
    CHECK(same_bits(strtof(buf, NULL), f), "%a -> %s", (double)f, buf);
    CHECK(same_bits((float)strtod(buf, NULL), f), "%a -> %s via double", (double)f, buf);
    char t[40];
    for (int p = 1; p <= 9; p++) {
        snprintf(t, sizeof t, "%.*g", p, (double)f);
        if (same_bits(strtof(t, NULL), f))
            return sig_digits(buf) > p;
    }
    return 0;
}

static void expect_text(float f, const char *want) {
    char buf[KDR_FLOAT_CHARS + 1];
    buf[kdr_format_float(f, buf)] = '\0';
    CHECK(!strcmp(buf, want), "%a -> %s, want %s", (double)f, buf, want);
}

static void test_float_format(void) {
    expect_text(0.0f, "0");
    expect_text(-0.0f, "-0");
    expect_text(1.0f, "1");
    expect_text(-1.0f, "-1");
    expect_text(0.1f, "0.1");
    expect_text(1e-45f, "1e-45");
    expect_text(FLT_MAX, "3.4028235e38");
    expect_text(FLT_MIN, "1.1754944e-38");
    expect_text(16777216.0f, "16777216");
    expect_text(0.001f, "0.001");
    expect_text(123456.7f, "123456.7");
    expect_text(NAN, "null");
    expect_text(INFINITY, "null");
    int longer = 0, total = 0;
    for (uint32_t b = 0; b < 2000; b++) { /* denormals, then the top end */
        float f, g;
        uint32_t hi = 0x7f7fffffu - b;
        memcpy(&f, &b, 4);
        memcpy(&g, &hi, 4);
        longer += check_float_text(f) + check_float_text(g);
        total += 2;
    }
    for (int e = -149; e <= 127; e++) {
        longer += check_float_text(ldexpf(1.0f, e));
        longer += check_float_text(nextafterf(ldexpf(1.0f, e), 0.0f));
        total += 2;
    }
    for (int i = 0; i < 200000; i++) {
        uint32_t b = (uint32_t)rng();
        float f;
        memcpy(&f, &b, 4);
        if (isfinite(f)) {
            longer += check_float_text(f);
            total++;
        }
    }
    /* shortest up to exact decimal ties the safety margin declines */
    CHECK(longer * 10000 <= total, "%d of %d not shortest", longer, total);
}

static cJSON *parse_buf(kdr_buf *b) {
    cJSON *doc = cJSON_ParseWithLength(b->data, b->len);
    CHECK(doc != NULL, "response is not JSON: %.*s", (int)(b->len < 200 ? b->len : 200),
          b->data ? b->data : "");
    return doc;
}

/* Reads field name of doc as n floats (JSON or {"f32"}) or n int32s. */
static int read_back(const cJSON *doc, const char *name, int is_int, size_t n, void *dst) {
    const cJSON *it = cJSON_GetObjectItemCaseSensitive(doc, name);
    if (cJSON_IsArray(it)) {
        size_t i = 0;
        for (const cJSON *c = it->child; c; c = c->next, i++) {
            if (i >= n || !cJSON_IsNumber(c))
                return -1;
            if (is_int)
                ((int32_t *)dst)[i] = (int32_t)c->valuedouble;
            else
                ((float *)dst)[i] = (float)c->valuedouble;
        }
        return i == n ? 0 : -1;
    }
    const cJSON *s = cJSON_GetObjectItemCaseSensitive(it, is_int ? "i32" : "f32");
    if (!cJSON_IsString(s))
        return -1;
    size_t len = strlen(s->valuestring), got, bad;
    if (kdr_base64_decoded_max(len) > 4 * n + 2)
        return -1;
    unsigned char *tmp = xmalloc(kdr_base64_decoded_max(len) + 1);
    int rc = kdr_base64_decode(s->valuestring, len, tmp, &got, &bad);
    if (!rc && got == 4 * n)
        memcpy(dst, tmp, 4 * n);
    free(tmp);
    return !rc && got == 4 * n ? 0 : -1;
}

static void test_hits_response(size_t n, kdr_encoding enc) {
    float *t = xmalloc(4 * n), *u = xmalloc(4 * n), *v = xmalloc(4 * n), *f = xmalloc(4 * n);
    int32_t *prim = xmalloc(4 * n), *ib = xmalloc(4 * n);
    uint8_t *hit = xmalloc(n);
    static const float special[] = {0.0f, -0.0f, 1e-45f, FLT_MAX, FLT_MIN, 0.1f, 1e30f};
    for (size_t i = 0; i < n; i++) {
        uint32_t bits = (uint32_t)rng() & 0xbfffffffu;
        memcpy(&t[i], &bits, 4);
        if (i < sizeof special / sizeof special[0])
            t[i] = special[i];
        u[i] = (float)(rng() % 100000) / 99991.0f;
        v[i] = -u[i];
        prim[i] = i % 5 == 3 ? -1 : (int32_t)(rng() % 2147483647u);
        /* any nonzero byte is a hit (the core writes 1) */
        hit[i] = rng() & 1 ? (uint8_t)(1 + rng() % 255) : 0;
    }
    kdr_hits h = {.t = t, .prim = prim, .u = u, .v = v, .hit = hit};
    kdr_buf b;
    kdr_buf_init(&b);
    CHECK(kdr_proto_encode_hits(&h, n, KDR_CLOSEST, enc, &b) == 0, "encode");
    cJSON *doc = parse_buf(&b);
    const cJSON *cnt = cJSON_GetObjectItemCaseSensitive(doc, "count");
    CHECK(cJSON_IsNumber(cnt) && cnt->valuedouble == (double)n, "count");
    CHECK(read_back(doc, "t", 0, n, f) == 0, "t array");
    for (size_t i = 0; i < n; i++)
        CHECK(same_bits(f[i], prim[i] < 0 ? -1.0f : t[i]), "t[%zu]", i);
    CHECK(read_back(doc, "prim", 1, n, ib) == 0, "prim array");
    CHECK(!memcmp(ib, prim, 4 * n), "prim values");
    CHECK(read_back(doc, "u", 0, n, f) == 0, "u array");
    for (size_t i = 0; i < n; i++)
        CHECK(same_bits(f[i], prim[i] < 0 ? 0.0f : u[i]), "u[%zu]", i);
    CHECK(read_back(doc, "v", 0, n, f) == 0, "v array");
    for (size_t i = 0; i < n; i++)
        CHECK(same_bits(f[i], prim[i] < 0 ? 0.0f : v[i]), "v[%zu]", i);
    cJSON_Delete(doc);
    b.len = 0;
    CHECK(kdr_proto_encode_hits(&h, n, KDR_ANY, enc, &b) == 0, "encode any");
    doc = parse_buf(&b);
    CHECK(read_back(doc, "hit", 1, n, ib) == 0, "hit array");
    for (size_t i = 0; i < n; i++)
        CHECK(ib[i] == (hit[i] != 0), "hit[%zu]", i);
    CHECK(!cJSON_GetObjectItemCaseSensitive(doc, "t"), "any has no t");
    cJSON_Delete(doc);
    /* "hit" of a closest query: prim >= 0 */
    b.len = 0;
    CHECK(kdr_proto_encode_hits_fields(&h, n, KDR_CLOSEST, KDR_FIELD_HIT, enc, &b) == 0,
          "encode closest hit");
    doc = parse_buf(&b);
    CHECK(read_back(doc, "hit", 1, n, ib) == 0, "closest hit array");
    for (size_t i = 0; i < n; i++)
        CHECK(ib[i] == (prim[i] >= 0), "closest hit[%zu]", i);
    cJSON_Delete(doc);
    /* arrays in wire form (misses as the core writes them): the wire
     * encoder gives the normalising encoder's bytes */
    for (size_t i = 0; i < n; i++) {
        if (prim[i] < 0) t[i] = -1.0f, u[i] = 0.0f, v[i] = 0.0f;
        hit[i] = hit[i] != 0;
    }
    kdr_buf w;
    kdr_buf_init(&w);
    for (int q = 0; q < 2; q++) {
        const kdr_query query = q ? KDR_ANY : KDR_CLOSEST;
        const unsigned fields = q ? KDR_FIELDS_ANY : KDR_FIELDS_CLOSEST | KDR_FIELD_HIT;
        b.len = w.len = 0;
        CHECK(kdr_proto_encode_hits_fields(&h, n, query, fields, enc, &b) == 0 &&
                  kdr_proto_encode_hits_wire(&h, NULL, n, query, fields, enc, &w) == 0 &&
                  b.len == w.len && !memcmp(b.data, w.data, b.len),
              "wire encoder, query %d", q);
    }
    kdr_buf_free(&w);
    kdr_buf_free(&b);
    free(t), free(u), free(v), free(f), free(prim), free(ib), free(hit);
}

static void test_shadow_response(void) {
    float vis[6] = {1, 0, 0.5f, 0.25f, 1e-45f, 0.999f}, back[6];
    kdr_shadow_stats st = {7, 123456789012ull, 42};
    for (int enc = 0; enc < 2; enc++) {
        kdr_buf b;
        kdr_buf_init(&b);
        CHECK(kdr_proto_encode_shadow(vis, 3, 2, enc ? NULL : &st, (kdr_encoding)enc, &b) == 0,
              "encode");
        cJSON *doc = parse_buf(&b);
        CHECK(cJSON_GetObjectItemCaseSensitive(doc, "count")->valuedouble == 3, "count");
        CHECK(read_back(doc, "visibility", 0, 6, back) == 0 && !memcmp(back, vis, sizeof vis),
              "visibility");
        const cJSON *s = cJSON_GetObjectItemCaseSensitive(doc, "stats");
        if (enc)
            CHECK(s == NULL, "no stats unless asked");
        else
            CHECK(cJSON_GetObjectItemCaseSensitive(s, "rays_traced")->valuedouble ==
                          123456789012.0 &&
                      cJSON_GetObjectItemCaseSensitive(s, "cones_decided")->valuedouble == 7 &&
                      cJSON_GetObjectItemCaseSensitive(s, "nodes_visited")->valuedouble == 42,
                  "stats");
        cJSON_Delete(doc);
        kdr_buf_free(&b);
    }
}

static void test_scene_and_errors(void) {
    kdr_proto_mesh_range m[2] = {{0, 0, 0, 0, 12}, {3, 1, 2, 12, 30}};
    kdr_proto_scene_info s[2];
    memset(s, 0, sizeof s);
    s[0].name = "default \"quoted\"\n";
    s[0].triangles = 42;
    s[0].bounds = (kdr_bounds){{-1, -2.5f, 0}, {1, 2, 1e-45f}};
    s[0].tree.nodes = 9;
    s[0].tree.leaves = 5;
    s[0].tree.empty_leaves = 1;
    s[0].tree.max_depth = 4;
    s[0].tree.refs_per_leaf = 0.1;
    s[0].tree.sah_cost = 12.75;
    s[0].tree.build_ms = 1.0 / 3.0;
    s[0].meshes = m;
    s[0].nmeshes = 2;
    s[1].name = "empty";
    kdr_buf b;
    kdr_buf_init(&b);
    CHECK(kdr_proto_encode_scenes(s, 2, &b) == 0, "scenes");
    cJSON *doc = parse_buf(&b);
    const cJSON *arr = cJSON_GetObjectItemCaseSensitive(doc, "scenes");
    CHECK(cJSON_GetArraySize(arr) == 2, "two scenes");
    const cJSON *s0 = cJSON_GetArrayItem(arr, 0);
    CHECK(!strcmp(cJSON_GetObjectItemCaseSensitive(s0, "name")->valuestring, s[0].name), "name");
    CHECK(cJSON_GetObjectItemCaseSensitive(s0, "triangles")->valuedouble == 42, "triangles");
    const cJSON *bmin = cJSON_GetObjectItemCaseSensitive(
        cJSON_GetObjectItemCaseSensitive(s0, "bounds"), "min");
    CHECK((float)cJSON_GetArrayItem(bmin, 1)->valuedouble == -2.5f, "bounds");
    const cJSON *kd = cJSON_GetObjectItemCaseSensitive(s0, "kdtree");
    CHECK(cJSON_GetObjectItemCaseSensitive(kd, "build_ms")->valuedouble == 1.0 / 3.0 &&
              cJSON_GetObjectItemCaseSensitive(kd, "refs_per_leaf")->valuedouble == 0.1 &&
              cJSON_GetObjectItemCaseSensitive(kd, "empty_leaves")->valuedouble == 1,
          "kdtree");
    const cJSON *m1 = cJSON_GetArrayItem(cJSON_GetObjectItemCaseSensitive(s0, "meshes"), 1);
    CHECK(cJSON_GetObjectItemCaseSensitive(m1, "node")->valuedouble == 3 &&
              cJSON_GetObjectItemCaseSensitive(m1, "primitive")->valuedouble == 2 &&
              cJSON_GetObjectItemCaseSensitive(m1, "first_prim")->valuedouble == 12 &&
              cJSON_GetObjectItemCaseSensitive(m1, "count")->valuedouble == 30,
          "mesh range");
    cJSON_Delete(doc);
    b.len = 0;
    kdr_proto_error e;
    kdr_proto_error_set(&e, 413, "batch of %d rays exceeds the limit of %d", 5, 4);
    CHECK(kdr_proto_encode_error(&e, &b) == 0, "error body");
    CHECK(b.len && !strcmp(kdr_buf_cstr(&b),
                           "{\"type\":\"about:blank\",\"title\":\"Content Too Large\","
                           "\"status\":413,\"detail\":\"batch of 5 rays exceeds the limit of 4\"}"),
          "%s", b.data);
    static const int codes[] = {400, 404, 405, 413, 415, 500, 503};
    for (size_t i = 0; i < sizeof codes / sizeof codes[0]; i++)
        CHECK(strcmp(kdr_proto_status_title(codes[i]), "Error") != 0, "title %d", codes[i]);
    b.len = 0;
    CHECK(kdr_proto_encode_health("ok", 3, &b) == 0 &&
              !strcmp(kdr_buf_cstr(&b), "{\"status\":\"ok\",\"scenes\":3}"),
          "health");
    kdr_buf_free(&b);
}

/* ---- the fast top-level walk versus the all-cJSON path --------------------- */

int main(void) {
    test_base64();
    test_float_format();
    test_hits_response(1, KDR_ENCODING_JSON);
    test_hits_response(3, KDR_ENCODING_BASE64);
    test_hits_response(40000, KDR_ENCODING_JSON);
    test_hits_response(40001, KDR_ENCODING_BASE64);
    test_shadow_response();
    test_scene_and_errors();
    return check_exit("test_protocol_encode");
}
