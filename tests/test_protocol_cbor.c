/*
 * test_protocol_cbor.c — the binary body form (application/cbor) and the
 * answer-field choice: a CBOR request and its JSON twin parse to the same
 * query bit for bit for every query kind and every array form; float32
 * typed arrays are used in place when aligned and copied when not; CBOR
 * answers, read back with libcbor's own tree loader (cbor_load, a decoder
 * independent of the streaming reader under test), hold exactly the JSON
 * answer's values for every query kind and field choice; malformed bodies
 * (every truncation of a valid body, wrong types, wrong lengths, huge
 * declared lengths, nesting bombs, item floods) give 400 naming the field;
 * Content-Type and Accept negotiation. A plain C program: exits nonzero
 * when a check fails.
 */
#include <cbor.h>
#include <float.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <cjson/cJSON.h>

#include "kdr_protocol.h"

static int failures;

#define CHECK(cond, ...)                                                             \
    do {                                                                             \
        if (!(cond) && ++failures <= 40) {                                           \
            fprintf(stderr, "%s:%d: CHECK(%s) failed: ", __FILE__, __LINE__, #cond); \
            fprintf(stderr, __VA_ARGS__);                                            \
            fputc('\n', stderr);                                                     \
        }                                                                            \
    } while (0)

static uint64_t rng_state = 0x510e527fade682d1ull;
static uint64_t rng(void) {
    rng_state ^= rng_state << 13;
    rng_state ^= rng_state >> 7;
    rng_state ^= rng_state << 17;
    return rng_state;
}
static float frand(float lo, float hi) {
    return lo + (hi - lo) * (float)(rng() >> 40) * 0x1p-24f;
}

static void *xmalloc(size_t n) {
    void *p = malloc(n ? n : 1);
    if (!p) {
        fprintf(stderr, "test_protocol_cbor: out of memory\n");
        exit(2);
    }
    return p;
}

/* ---- building bodies -------------------------------------------------------------- */

/* A CBOR body (built with libcbor's encoders) and its JSON twin side by side. */
typedef struct body {
    unsigned char *c;
    size_t clen, ccap;
    kdr_buf j;
} body;

static void c_raw(body *b, const void *p, size_t n) {
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
static void c_head(body *b, head_fn fn, size_t v) {
    unsigned char tmp[9];
    c_raw(b, tmp, fn(v, tmp, sizeof tmp));
}
/* Bytes of a head with argument v (preferred serialization). */
static size_t head_len(size_t v) {
    return v < 24 ? 1 : v < 256 ? 2 : v < 65536 ? 3 : v <= 0xffffffffu ? 5 : 9;
}
static void c_text(body *b, const char *s) {
    c_head(b, cbor_encode_string_start, strlen(s));
    c_raw(b, s, strlen(s));
}
static void c_uint(body *b, uint64_t v) {
    unsigned char tmp[9];
    c_raw(b, tmp, cbor_encode_uint(v, tmp, sizeof tmp));
}
static void c_tag(body *b, uint64_t v) {
    unsigned char tmp[9];
    c_raw(b, tmp, cbor_encode_tag(v, tmp, sizeof tmp));
}
static void c_double(body *b, double d) {
    unsigned char tmp[9];
    c_raw(b, tmp, cbor_encode_double(d, tmp, sizeof tmp));
}
static void c_typed(body *b, const float *v, size_t n) {
    c_tag(b, 85);
    c_head(b, cbor_encode_bytestring_start, 4 * n);
    c_raw(b, v, 4 * n);
}
/* Floats as a CBOR array: alternately single, double and (when exact)
 * integer items, so every number form is read. */
static void c_floats(body *b, const float *v, size_t n) {
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

static void j_lit(body *b, const char *s) { kdr_buf_append(&b->j, s, strlen(s)); }
static void j_floats(body *b, const float *v, size_t n) {
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
static void both_array(body *b, const char *key, const float *v, size_t n, int form) {
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

static void body_free(body *b) {
    free(b->c);
    kdr_buf_free(&b->j);
}

/* An exact-size, 16-byte aligned copy of the CBOR body (as a server's
 * malloc'd body would be) so ASan sees any read past it. */
static char *exact(const void *p, size_t n) {
    char *c = xmalloc(n);
    memcpy(c, p, n);
    return c;
}

/* ---- requests: CBOR and JSON parse to the same query ------------------------------ */

static int same_floats(const float *a, const float *b, size_t n) {
    return n == 0 || memcmp(a, b, 4 * n) == 0;
}

static int points_into(const void *p, const char *base, size_t len) {
    return (const char *)p >= base && (const char *)p < base + len;
}

static void test_bundle_twins(size_t n, int form, int shared_origin, int per_ray_t) {
    float *org = xmalloc(12 * n), *dir = xmalloc(12 * n), *tmin = xmalloc(4 * n),
          *tmax = xmalloc(4 * n);
    for (size_t i = 0; i < 3 * n; i++) {
        org[i] = frand(-100, 100);
        dir[i] = i % 3 == 0 ? 1.0f : frand(-1, 1);
    }
    for (size_t i = 0; i < n; i++) {
        tmin[i] = frand(0, 1);
        tmax[i] = i % 7 ? frand(1, 1000) : 3.0e38f;
    }
    const size_t norg = shared_origin ? 3 : 3 * n;
    body b = {0};
    kdr_buf_init(&b.j);
    j_lit(&b, "{");
    c_head(&b, cbor_encode_map_start,
           4 + (per_ray_t ? 2 : 0) + (form == 2 ? 1 + (per_ray_t ? 1 : 0) : 0));
    both_array(&b, "origins", org, norg, form == 2 ? 0 : form);
    both_array(&b, "directions", dir, 3 * n, form);
    if (per_ray_t) {
        both_array(&b, "tmin", tmin, n, form);
        both_array(&b, "tmax", tmax, n, form == 2 ? 0 : form);
    }
    c_text(&b, "query");
    c_text(&b, "any");
    c_text(&b, "fields");
    c_head(&b, cbor_encode_array_start, 1);
    c_text(&b, "hit");
    j_lit(&b, ",\"query\":\"any\",\"fields\":[\"hit\"]}");
    char *cb = exact(b.c, b.clen), *jb = exact(b.j.data, b.j.len);
    kdr_bundle_request rc, rj;
    kdr_proto_error ec, ej;
    const int sc = kdr_proto_parse_bundle_as(KDR_MEDIA_CBOR, cb, b.clen, 0, &rc, &ec);
    const int sj = kdr_proto_parse_bundle(jb, b.j.len, 0, &rj, &ej);
    CHECK(sc == 0 && sj == 0, "form %d: cbor %d %s / json %d %s", form, sc, ec.detail, sj,
          ej.detail);
    if (sc == 0 && sj == 0) {
        const kdr_ray_batch *x = &rc.batch, *y = &rj.batch;
        CHECK(x->n == n && y->n == n && x->org_stride == y->org_stride, "shape");
        CHECK(same_floats(x->org, y->org, norg) && same_floats(x->dir, y->dir, 3 * n),
              "form %d: origins/directions differ", form);
        CHECK(x->tmin_stride == y->tmin_stride && x->tmax_stride == y->tmax_stride, "t");
        CHECK(same_floats(x->tmin, y->tmin, x->tmin_stride ? n : 1) &&
                  same_floats(x->tmax, y->tmax, x->tmax_stride ? n : 1),
              "form %d: tmin/tmax differ", form);
        CHECK(rc.query == KDR_ANY && rc.fields == KDR_FIELD_HIT && rj.fields == rc.fields,
              "query and fields");
        /* typed arrays are read in place when aligned, else copied */
        if (points_into(x->dir, cb, b.clen))
            CHECK(form == 0 && (uintptr_t)x->dir % 4 == 0 && !rc.owned[1], "in place");
        else
            CHECK(rc.owned[1] == x->dir, "form %d: a copy", form);
        if (form == 2)
            CHECK(!points_into(x->dir, cb, b.clen), "misaligned directions are copied");
        if (form == 1)
            CHECK(!points_into(x->org, cb, b.clen), "CBOR number arrays are converted");
    }
    kdr_bundle_request_free(&rc);
    kdr_bundle_request_free(&rj);
    free(cb), free(jb), free(org), free(dir), free(tmin), free(tmax);
    body_free(&b);
}

/* The typed-array payload offset of "directions" decides in-place use:
 * shift it through all four residues with a padding member. */
static void test_in_place(void) {
    float dir[12] = {1, 0, 0, 0, 1, 0, 0, 0, 1, 1, 1, 1};
    int in_place = 0, copied = 0;
    for (int pad = 0; pad < 4; pad++) {
        body b = {0};
        kdr_buf_init(&b.j);
        c_head(&b, cbor_encode_map_start, 3);
        c_text(&b, "_");
        c_text(&b, "abc" + (3 - pad));
        c_text(&b, "origins");
        c_typed(&b, dir, 3);
        c_text(&b, "directions");
        c_typed(&b, dir, 12);
        char *cb = exact(b.c, b.clen);
        kdr_bundle_request r;
        kdr_proto_error e;
        CHECK(kdr_proto_parse_bundle_as(KDR_MEDIA_CBOR, cb, b.clen, 0, &r, &e) == 0, "%s",
              e.detail);
        const size_t off = b.clen - 48; /* the directions payload */
        if (off % 4 == 0) {
            in_place++;
            CHECK(r.batch.dir == (const float *)(const void *)(cb + off) && !r.owned[1],
                  "aligned typed array read in place");
        } else {
            copied++;
            CHECK(!points_into(r.batch.dir, cb, b.clen) && r.owned[1] == r.batch.dir,
                  "misaligned typed array copied");
        }
        CHECK(same_floats(r.batch.dir, dir, 12), "values");
        kdr_bundle_request_free(&r);
        free(cb);
        body_free(&b);
    }
    CHECK(in_place == 1 && copied == 3, "in place %d copied %d", in_place, copied);
}

static void test_shadow_twins(int form) {
    enum { N = 97 };
    float pts[3 * N], nrm[3 * N], ctr[3] = {0, 50, 0};
    for (size_t i = 0; i < 3 * N; i++) {
        pts[i] = frand(-10, 10);
        nrm[i] = frand(-1, 1);
    }
    body b = {0};
    kdr_buf_init(&b.j);
    j_lit(&b, "{");
    c_head(&b, cbor_encode_map_start, form == 2 ? 9 : 7);
    both_array(&b, "points", pts, 3 * N, form);
    both_array(&b, "normals", nrm, 3 * N, form);
    c_text(&b, "lights");
    c_head(&b, cbor_encode_array_start, 2);
    for (int l = 0; l < 2; l++) {
        c_head(&b, cbor_encode_map_start, 2);
        c_text(&b, "center");
        if (l)
            c_typed(&b, ctr, 3);
        else
            c_floats(&b, ctr, 3);
        c_text(&b, "radius");
        c_double(&b, 2.5 + l);
    }
    c_text(&b, "samples");
    c_uint(&b, 33);
    c_text(&b, "seed");
    c_uint(&b, 1ull << 40);
    c_text(&b, "epsilon");
    c_double(&b, 0.001);
    c_text(&b, "stats");
    c_raw(&b, "\xf5", 1);
    j_lit(&b, ",\"lights\":[{\"center\":[0,50,0],\"radius\":2.5},{\"center\":[0,50,0],"
              "\"radius\":3.5}],\"samples\":33,\"seed\":1099511627776,\"epsilon\":0.001,"
              "\"stats\":true}");
    char *cb = exact(b.c, b.clen), *jb = exact(b.j.data, b.j.len);
    kdr_shadow_request rc, rj;
    kdr_proto_error ec, ej;
    const int sc = kdr_proto_parse_shadow_as(KDR_MEDIA_CBOR, cb, b.clen, 0, &rc, &ec);
    const int sj = kdr_proto_parse_shadow(jb, b.j.len, 0, &rj, &ej);
    CHECK(sc == 0 && sj == 0, "shadow form %d: %s / %s", form, ec.detail, ej.detail);
    if (!sc && !sj) {
        const kdr_shadow_query *x = &rc.query, *y = &rj.query;
        CHECK(x->n == N && y->n == N && same_floats(x->points, y->points, 3 * N) &&
                  same_floats(x->normals, y->normals, 3 * N),
              "points/normals");
        CHECK(x->nlights == 2 && !memcmp(x->lights, y->lights, 2 * sizeof *x->lights),
              "lights");
        CHECK(x->samples == 33 && x->seed == 1ull << 40 && x->epsilon == y->epsilon &&
                  rc.want_stats && rj.want_stats,
              "options");
    }
    kdr_shadow_request_free(&rc);
    kdr_shadow_request_free(&rj);
    free(cb), free(jb);
    body_free(&b);
}

static void test_frustum_twins(void) {
    body b = {0};
    kdr_buf_init(&b.j);
    const float eye[3] = {1, 2, 30}, target[3] = {0, 0.5f, 0};
    c_head(&b, cbor_encode_map_start, 4);
    c_text(&b, "camera");
    c_head(&b, cbor_encode_map_start, 5);
    c_text(&b, "eye");
    c_typed(&b, eye, 3);
    c_text(&b, "target");
    c_floats(&b, target, 3);
    c_text(&b, "fov_y_deg");
    c_double(&b, 45);
    c_text(&b, "width");
    c_uint(&b, 64);
    c_text(&b, "height");
    c_uint(&b, 48);
    c_text(&b, "tile");
    c_uint(&b, 16);
    c_text(&b, "fields");
    c_head(&b, cbor_encode_array_start, 2);
    c_text(&b, "prim");
    c_text(&b, "t");
    c_text(&b, "encoding");
    c_text(&b, "base64");
    j_lit(&b, "{\"camera\":{\"eye\":[1,2,30],\"target\":[0,0.5,0],\"fov_y_deg\":45,"
              "\"width\":64,\"height\":48},\"tile\":16,\"fields\":[\"prim\",\"t\"],"
              "\"encoding\":\"base64\"}");
    char *cb = exact(b.c, b.clen);
    kdr_frustum_request rc, rj;
    kdr_proto_error ec, ej;
    const int sc = kdr_proto_parse_frustum_as(KDR_MEDIA_CBOR, cb, b.clen, 0, &rc, &ec);
    const int sj = kdr_proto_parse_frustum(b.j.data, b.j.len, 0, &rj, &ej);
    CHECK(sc == 0 && sj == 0, "frustum: %s / %s", ec.detail, ej.detail);
    CHECK(!memcmp(&rc, &rj, sizeof rc), "frustum requests differ");
    CHECK(rc.fields == (KDR_FIELD_T | KDR_FIELD_PRIM) && rc.encoding == KDR_ENCODING_BASE64,
          "fields %u encoding %d", rc.fields, rc.encoding);
    free(cb);
    body_free(&b);
}

/* ---- answers: CBOR holds exactly the JSON answer's values -------------------------- */

/* The value of key in a libcbor map item, or NULL. */
static cbor_item_t *map_get(cbor_item_t *map, const char *key) {
    struct cbor_pair *pairs = cbor_map_handle(map);
    for (size_t i = 0; i < cbor_map_size(map); i++)
        if (cbor_isa_string(pairs[i].key) &&
            cbor_string_length(pairs[i].key) == strlen(key) &&
            !memcmp(cbor_string_handle(pairs[i].key), key, strlen(key)))
            return pairs[i].value;
    return NULL;
}

/* A typed array member: its tag and payload. */
static const unsigned char *typed(cbor_item_t *map, const char *key, uint64_t *tag,
                                  size_t *len) {
    cbor_item_t *v = map_get(map, key);
    if (!v || !cbor_isa_tag(v))
        return NULL;
    *tag = cbor_tag_value(v);
    cbor_item_t *bs = cbor_tag_item(v);
    const unsigned char *p = NULL;
    if (cbor_isa_bytestring(bs) && cbor_bytestring_is_definite(bs)) {
        p = cbor_bytestring_handle(bs);
        *len = cbor_bytestring_length(bs);
    }
    cbor_decref(&bs);
    return p;
}

/* The JSON answer's array key as 4-byte words (floats as float32 bits,
 * integers as int32), or 0 if absent. */
static size_t json_words(cJSON *doc, const char *key, int as_int, uint32_t *out) {
    const cJSON *a = cJSON_GetObjectItemCaseSensitive(doc, key);
    size_t n = 0;
    for (const cJSON *c = a ? a->child : NULL; c; c = c->next, n++) {
        if (as_int) {
            int32_t i = (int32_t)c->valuedouble;
            memcpy(&out[n], &i, 4);
        } else {
            float f = (float)c->valuedouble;
            memcpy(&out[n], &f, 4);
        }
    }
    return a ? n : 0;
}

static void compare_answer(const kdr_buf *cb, const kdr_buf *jb, size_t n) {
    struct cbor_load_result res;
    cbor_item_t *root = cbor_load((const unsigned char *)cb->data, cb->len, &res);
    cJSON *doc = cJSON_ParseWithLength(jb->data, jb->len);
    CHECK(root && res.read == cb->len && cbor_isa_map(root) && doc, "answer parses");
    if (!root || !doc || !cbor_isa_map(root)) {
        if (root)
            cbor_decref(&root);
        cJSON_Delete(doc);
        return;
    }
    CHECK(cbor_map_size(root) == (size_t)cJSON_GetArraySize(doc), "same members");
    cbor_item_t *count = map_get(root, "count");
    CHECK(count && cbor_isa_uint(count) && cbor_get_int(count) == n, "count");
    size_t most = 1;
    for (const cJSON *m = doc->child; m; m = m->next)
        if (cJSON_IsArray(m) && (size_t)cJSON_GetArraySize(m) > most)
            most = (size_t)cJSON_GetArraySize(m);
    uint32_t *want = xmalloc(4 * most);
    static const struct {
        const char *key;
        uint64_t tag;
        int as_int;
    } arrays[] = {{"t", 85, 0},   {"prim", 78, 1}, {"u", 85, 0},
                  {"v", 85, 0},   {"hit", 64, 1},  {"visibility", 85, 0}};
    for (size_t k = 0; k < sizeof arrays / sizeof arrays[0]; k++) {
        const size_t nw = json_words(doc, arrays[k].key, arrays[k].as_int, want);
        uint64_t tag = 0;
        size_t len = 0;
        const unsigned char *p = typed(root, arrays[k].key, &tag, &len);
        CHECK(!p == !cJSON_GetObjectItemCaseSensitive(doc, arrays[k].key), "%s presence",
              arrays[k].key);
        if (!p)
            continue;
        CHECK(tag == arrays[k].tag, "%s tag %llu", arrays[k].key, (unsigned long long)tag);
        if (tag == 64) {
            CHECK(len == nw, "hit length");
            for (size_t i = 0; i < nw && i < len; i++)
                CHECK(p[i] == (unsigned char)want[i], "hit[%zu]", i);
        } else {
            CHECK(len == 4 * nw && !memcmp(p, want, len), "%s values", arrays[k].key);
        }
    }
    cbor_item_t *stats = map_get(root, "stats");
    const cJSON *js = cJSON_GetObjectItemCaseSensitive(doc, "stats");
    CHECK(!stats == !js, "stats presence");
    if (stats && js) {
        cbor_item_t *rt = map_get(stats, "rays_traced");
        CHECK(rt && cbor_get_int(rt) ==
                        (uint64_t)cJSON_GetObjectItem(js, "rays_traced")->valuedouble,
              "stats.rays_traced");
    }
    free(want);
    cbor_decref(&root);
    cJSON_Delete(doc);
}

static void test_answers(size_t n) {
    float *t = xmalloc(4 * n), *u = xmalloc(4 * n), *v = xmalloc(4 * n);
    int32_t *prim = xmalloc(4 * n);
    uint8_t *hit = xmalloc(n);
    for (size_t i = 0; i < n; i++) {
        t[i] = frand(0, 100);
        u[i] = frand(0, 1);
        v[i] = frand(0, 1) * (1 - u[i]);
        prim[i] = i % 4 == 1 ? -1 : (int32_t)(rng() % 1000000);
        hit[i] = (uint8_t)(rng() & 1);
    }
    const kdr_hits h = {.t = t, .prim = prim, .u = u, .v = v, .hit = hit};
    for (unsigned fields = 1; fields < 32; fields++)
        for (int q = 0; q < 2; q++) {
            const kdr_query query = q ? KDR_ANY : KDR_CLOSEST;
            kdr_buf cb, jb;
            kdr_buf_init(&cb);
            kdr_buf_init(&jb);
            const int sc =
                kdr_proto_encode_hits_fields(&h, n, query, fields, KDR_ENCODING_CBOR, &cb);
            const int sj =
                kdr_proto_encode_hits_fields(&h, n, query, fields, KDR_ENCODING_JSON, &jb);
            const int valid = query == KDR_CLOSEST || fields == KDR_FIELD_HIT;
            CHECK(sc == sj && (sc == 0) == valid, "fields %u query %d: %d %d", fields, q, sc,
                  sj);
            if (valid && sc == 0)
                compare_answer(&cb, &jb, n);
            kdr_buf_free(&cb);
            kdr_buf_free(&jb);
        }
    /* the default fields are those of kdr_proto_encode_hits */
    for (int q = 0; q < 2; q++) {
        kdr_buf a, b;
        kdr_buf_init(&a);
        kdr_buf_init(&b);
        kdr_proto_encode_hits(&h, n, q ? KDR_ANY : KDR_CLOSEST, KDR_ENCODING_CBOR, &a);
        kdr_proto_encode_hits_fields(&h, n, q ? KDR_ANY : KDR_CLOSEST,
                                     q ? KDR_FIELDS_ANY : KDR_FIELDS_CLOSEST,
                                     KDR_ENCODING_CBOR, &b);
        CHECK(a.len == b.len && !memcmp(a.data, b.data, a.len), "default fields");
        kdr_buf_free(&a);
        kdr_buf_free(&b);
    }
    /* closest "hit" is prim >= 0 */
    kdr_buf jb;
    kdr_buf_init(&jb);
    kdr_proto_encode_hits_fields(&h, n, KDR_CLOSEST, KDR_FIELD_HIT, KDR_ENCODING_JSON, &jb);
    cJSON *doc = cJSON_ParseWithLength(jb.data, jb.len);
    const cJSON *c = cJSON_GetObjectItem(doc, "hit")->child;
    for (size_t i = 0; i < n; i++, c = c->next)
        CHECK(c && c->valuedouble == (prim[i] >= 0), "closest hit[%zu]", i);
    cJSON_Delete(doc);
    kdr_buf_free(&jb);
    /* visibility, with and without stats */
    const kdr_shadow_stats st = {.cones_decided = 7, .rays_traced = 1ull << 35,
                                 .nodes_visited = 99};
    for (int s = 0; s < 2; s++) {
        kdr_buf cb, jb2;
        kdr_buf_init(&cb);
        kdr_buf_init(&jb2);
        kdr_proto_encode_shadow(u, n / 2, 2, s ? &st : NULL, KDR_ENCODING_CBOR, &cb);
        kdr_proto_encode_shadow(u, n / 2, 2, s ? &st : NULL, KDR_ENCODING_JSON, &jb2);
        compare_answer(&cb, &jb2, n / 2);
        kdr_buf_free(&cb);
        kdr_buf_free(&jb2);
    }
    free(t), free(u), free(v), free(prim), free(hit);
}

/* ---- malformed bodies ---------------------------------------------------------------- */

static int parse_kind(int kind, const void *p, size_t len, kdr_proto_error *e) {
    char *c = exact(p, len ? len : 1);
    int st;
    if (kind == 0) {
        kdr_bundle_request r;
        st = kdr_proto_parse_bundle_as(KDR_MEDIA_CBOR, c, len, 1000000, &r, e);
        kdr_bundle_request_free(&r);
    } else if (kind == 1) {
        kdr_shadow_request r;
        st = kdr_proto_parse_shadow_as(KDR_MEDIA_CBOR, c, len, 1000000, &r, e);
        kdr_shadow_request_free(&r);
    } else {
        kdr_frustum_request r;
        st = kdr_proto_parse_frustum_as(KDR_MEDIA_CBOR, c, len, 1000000, &r, e);
    }
    free(c);
    return st;
}

static void expect(int kind, const body *b, int status, const char *detail) {
    kdr_proto_error e = {0, ""};
    const int st = parse_kind(kind, b->c, b->clen, &e);
    CHECK(st == status && !strcmp(e.detail, detail), "\n    got %d \"%s\"\n    want %d \"%s\"",
          st, e.detail, status, detail);
}

/* A valid bundle body, then each of its prefixes: every one a clean 400. */
static void test_truncations(void) {
    const float org[3] = {0, 0, 5}, dir[6] = {0, 0, -1, 0.5f, 0, -1};
    body b = {0};
    kdr_buf_init(&b.j);
    c_head(&b, cbor_encode_map_start, 4);
    c_text(&b, "origins");
    c_typed(&b, org, 3);
    c_text(&b, "directions");
    c_floats(&b, dir, 6);
    c_text(&b, "tmax");
    c_double(&b, 1e30);
    c_text(&b, "lights");
    c_raw(&b, "\x9f\xff", 2); /* an indefinite-length empty array */
    kdr_proto_error e;
    CHECK(parse_kind(0, b.c, b.clen, &e) == 0, "whole body: %s", e.detail);
    for (size_t cut = 0; cut < b.clen; cut++) {
        e.detail[0] = '\0';
        const int st = parse_kind(0, b.c, cut, &e);
        CHECK(st == 400 && e.detail[0], "prefix of %zu bytes: %d %s", cut, st, e.detail);
    }
    body_free(&b);
}

static void test_malformed(void) {
    const float three[3] = {1, 2, 3};
    body b = {0};
#define RESET() (free(b.c), b.c = NULL, b.clen = b.ccap = 0)
    kdr_buf_init(&b.j);
    c_uint(&b, 7);
    expect(0, &b, 400, "body: expected a CBOR map (CBOR offset 0)");
    RESET();
    c_raw(&b, "\xa1\x01\x02", 3);
    expect(0, &b, 400, "body: map keys must be text strings (CBOR offset 1)");
    RESET();
    c_raw(&b, "\xa0\x00", 2);
    expect(0, &b, 400, "body: data after the CBOR map (CBOR offset 1)");
    RESET();
    c_raw(&b, "\xa0", 1);
    expect(0, &b, 400, "directions: required");
    RESET();
    c_raw(&b, "\xa1\x61" "a\xfc", 4);
    expect(0, &b, 400,
           "a: malformed CBOR: reserved or unsupported initial byte (CBOR offset 3)");
    RESET();
    c_raw(&b, "\xa1\x61" "a\x7f\xff", 5);
    expect(0, &b, 400, "a: indefinite-length strings are not supported (CBOR offset 3)");
    /* wrong types and lengths, named by field */
    RESET();
    c_head(&b, cbor_encode_map_start, 1);
    c_text(&b, "directions");
    c_text(&b, "abc");
    expect(0, &b, 400,
           "directions: expected a float32 typed array (tag 85) or an array of numbers");
    RESET();
    c_head(&b, cbor_encode_map_start, 1);
    c_text(&b, "directions");
    c_head(&b, cbor_encode_bytestring_start, 12);
    c_raw(&b, three, 12);
    expect(0, &b, 400,
           "directions: a byte string needs a typed-array tag (float32: 85) (CBOR offset 12)");
    RESET();
    c_head(&b, cbor_encode_map_start, 1);
    c_text(&b, "directions");
    c_tag(&b, 85);
    c_head(&b, cbor_encode_bytestring_start, 10);
    c_raw(&b, three, 10);
    expect(0, &b, 400,
           "directions: typed array length is not a multiple of 4 bytes (CBOR offset 14)");
    RESET();
    c_head(&b, cbor_encode_map_start, 1);
    c_text(&b, "directions");
    c_tag(&b, 86); /* float64 LE */
    c_head(&b, cbor_encode_bytestring_start, 8);
    c_raw(&b, three, 8);
    expect(0, &b, 400,
           "directions: only float32 little-endian typed arrays (tag 85) are read (CBOR "
           "offset 12)");
    RESET();
    c_head(&b, cbor_encode_map_start, 2);
    c_text(&b, "origins");
    c_typed(&b, three, 3);
    c_text(&b, "directions");
    c_typed(&b, three, 2);
    expect(0, &b, 400, "directions: length 2 is not 3*N with N >= 1");
    RESET();
    {
        const float bad[6] = {1, 0, 0, 0, NAN, 0};
        c_head(&b, cbor_encode_map_start, 2);
        c_text(&b, "origins");
        c_typed(&b, three, 3);
        c_text(&b, "directions");
        c_typed(&b, bad, 6);
        expect(0, &b, 400, "directions[4]: not a finite number");
        RESET();
        c_head(&b, cbor_encode_map_start, 2);
        c_text(&b, "origins");
        c_typed(&b, three, 3);
        c_text(&b, "directions");
        c_floats(&b, bad, 6);
        expect(0, &b, 400, "directions[4]: not a number");
    }
    RESET();
    c_head(&b, cbor_encode_map_start, 2);
    c_text(&b, "origins");
    c_typed(&b, three, 3);
    c_text(&b, "directions");
    c_head(&b, cbor_encode_array_start, 3);
    c_uint(&b, 1);
    c_raw(&b, "\xf5", 1); /* true */
    c_uint(&b, 1);
    expect(0, &b, 400, "directions[1]: not a number");
    RESET();
    c_head(&b, cbor_encode_map_start, 3);
    c_text(&b, "origins");
    c_typed(&b, three, 3);
    c_text(&b, "directions");
    c_typed(&b, three, 3);
    c_text(&b, "tmax");
    c_double(&b, NAN);
    expect(0, &b, 400, "tmax: not a number");
    RESET();
    c_head(&b, cbor_encode_map_start, 4);
    c_text(&b, "origins");
    c_typed(&b, three, 3);
    c_text(&b, "directions");
    c_typed(&b, three, 3);
    c_text(&b, "query");
    c_text(&b, "any");
    c_text(&b, "fields");
    c_head(&b, cbor_encode_array_start, 1);
    c_text(&b, "t");
    expect(0, &b, 400, "fields[0]: \"t\" needs \"query\": \"closest\"");
    /* huge declared lengths: clean truncation errors, no allocation */
    RESET();
    c_raw(&b, "\xa1\x6a" "directions\x9b\x7f\xff\xff\xff\xff\xff\xff\xff\x01", 22);
    expect(0, &b, 400, "directions: truncated CBOR (CBOR offset 22)");
    RESET();
    c_raw(&b, "\xa1\x6a" "directions\xd8\x55\x5b\xff\xff\xff\xff\xff\xff\xff\xf0", 23);
    expect(0, &b, 400,
           "directions: truncated CBOR: an item needs more bytes than the body has (CBOR "
           "offset 14)");
    RESET();
    c_raw(&b, "\xbb\xff\xff\xff\xff\xff\xff\xff\xff", 9);
    expect(0, &b, 400, "body: truncated CBOR (CBOR offset 9)");
    /* nesting bombs: in an unknown member, in a known one, in a float array */
    for (int where = 0; where < 3; where++) {
        static const char *const keys[] = {"zzz", "lights", "points"};
        RESET();
        c_head(&b, cbor_encode_map_start, 1);
        c_text(&b, keys[where]);
        for (int d = 0; d < 100000; d++)
            c_raw(&b, "\x81", 1);
        c_uint(&b, 0);
        kdr_proto_error e = {0, ""};
        const int st = parse_kind(1, b.c, b.clen, &e);
        CHECK(st == 400 && strstr(e.detail, "nested too deeply") &&
                  !strncmp(e.detail, keys[where], strlen(keys[where])),
              "bomb in %s: %d %s", keys[where], st, e.detail);
    }
    /* an item flood: a small body declaring 10^6 one-byte items */
    RESET();
    c_head(&b, cbor_encode_map_start, 1);
    c_text(&b, "lights");
    c_head(&b, cbor_encode_array_start, 1000000);
    for (int i = 0; i < 1000000; i++)
        c_raw(&b, "\xf6", 1);
    expect(1, &b, 400, "lights[65535]: more than 65536 items (CBOR offset 65548)");
    RESET();
    /* unknown members are read (and must be well formed) but ignored */
    c_head(&b, cbor_encode_map_start, 4);
    c_text(&b, "x-extra");
    c_tag(&b, 85);
    c_head(&b, cbor_encode_bytestring_start, 4);
    c_raw(&b, three, 4);
    c_text(&b, "origins");
    c_typed(&b, three, 3);
    c_text(&b, "directions");
    c_typed(&b, three, 3);
    c_text(&b, "directions");
    c_text(&b, "second one is ignored, as in JSON");
    expect(0, &b, 0, "");
#undef RESET
    body_free(&b);
}

/* ---- field selection in JSON ---------------------------------------------------------- */

static void test_fields_json(void) {
    static const struct {
        const char *fields, *query;
        int status;
        unsigned bits;
        const char *detail;
    } cases[] = {
        {NULL, "closest", 0, KDR_FIELDS_CLOSEST, ""},
        {NULL, "any", 0, KDR_FIELDS_ANY, ""},
        {"[\"t\"]", "closest", 0, KDR_FIELD_T, ""},
        {"[\"v\",\"t\",\"t\"]", "closest", 0, KDR_FIELD_T | KDR_FIELD_V, ""},
        {"[\"hit\",\"prim\"]", "closest", 0, KDR_FIELD_HIT | KDR_FIELD_PRIM, ""},
        {"[\"hit\"]", "any", 0, KDR_FIELD_HIT, ""},
        {"[\"u\"]", "any", 400, 0, "fields[0]: \"u\" needs \"query\": \"closest\""},
        {"[]", "closest", 400, 0, "fields: expected a non-empty array of field names"},
        {"\"t\"", "closest", 400, 0, "fields: expected a non-empty array of field names"},
        {"[\"t\",1]", "closest", 400, 0, "fields[1]: expected a field name"},
        {"[\"normal\"]", "closest", 400, 0,
         "fields[0]: unknown field \"normal\" (t, prim, u, v, hit)"},
    };
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        char json[256];
        snprintf(json, sizeof json,
                 "{\"origins\":[0,0,0],\"directions\":[1,0,0],\"query\":\"%s\"%s%s}",
                 cases[i].query, cases[i].fields ? ",\"fields\":" : "",
                 cases[i].fields ? cases[i].fields : "");
        kdr_bundle_request r;
        kdr_proto_error e = {0, ""};
        const int st = kdr_proto_parse_bundle(json, strlen(json), 0, &r, &e);
        CHECK(st == cases[i].status && !strcmp(e.detail, cases[i].detail) &&
                  (st || r.fields == cases[i].bits),
              "%s: %d \"%s\" fields %u", json, st, e.detail, st ? 0 : r.fields);
        kdr_bundle_request_free(&r);
        /* the frustum takes the same member */
        snprintf(json, sizeof json,
                 "{\"camera\":{\"eye\":[0,0,5],\"target\":[0,0,0],\"fov_y_deg\":60,"
                 "\"width\":4,\"height\":3},\"query\":\"%s\"%s%s}",
                 cases[i].query, cases[i].fields ? ",\"fields\":" : "",
                 cases[i].fields ? cases[i].fields : "");
        kdr_frustum_request f;
        const int sf = kdr_proto_parse_frustum(json, strlen(json), 0, &f, &e);
        CHECK(sf == cases[i].status && (sf || f.fields == cases[i].bits), "frustum %s",
              json);
    }
}

/* ---- media types ----------------------------------------------------------------------- */

static void test_media(void) {
    static const struct {
        const char *ct;
        kdr_media m;
    } types[] = {
        {"application/json", KDR_MEDIA_JSON},
        {"Application/JSON; charset=utf-8", KDR_MEDIA_JSON},
        {"application/json;charset=latin1", KDR_MEDIA_OTHER},
        {"application/cbor", KDR_MEDIA_CBOR},
        {" application/CBOR ; x=y", KDR_MEDIA_CBOR},
        {"application/cborx", KDR_MEDIA_OTHER},
        {"application/jsonx", KDR_MEDIA_OTHER},
        {"text/plain", KDR_MEDIA_OTHER},
        {NULL, KDR_MEDIA_OTHER},
    };
    for (size_t i = 0; i < sizeof types / sizeof types[0]; i++)
        CHECK(kdr_proto_media_of(types[i].ct) == types[i].m, "Content-Type %s",
              types[i].ct ? types[i].ct : "(none)");
    static const struct {
        const char *accept;
        kdr_media req, want;
    } acc[] = {
        {NULL, KDR_MEDIA_CBOR, KDR_MEDIA_CBOR},
        {NULL, KDR_MEDIA_JSON, KDR_MEDIA_JSON},
        {"*/*", KDR_MEDIA_CBOR, KDR_MEDIA_CBOR},
        {"application/cbor", KDR_MEDIA_JSON, KDR_MEDIA_CBOR},
        {"application/json", KDR_MEDIA_CBOR, KDR_MEDIA_JSON},
        {"application/json;q=0.5, application/cbor", KDR_MEDIA_JSON, KDR_MEDIA_CBOR},
        {"application/cbor;q=0.4,application/json;q=0.9", KDR_MEDIA_JSON, KDR_MEDIA_JSON},
        {"application/*;q=0.3, application/cbor", KDR_MEDIA_JSON, KDR_MEDIA_CBOR},
        {"application/cbor;q=0, */*", KDR_MEDIA_CBOR, KDR_MEDIA_JSON},
        {"text/html", KDR_MEDIA_CBOR, KDR_MEDIA_CBOR},
        {"application/cbor; q=1.5", KDR_MEDIA_JSON, KDR_MEDIA_JSON},
        {"application/problem+json, application/cbor;q=0.1", KDR_MEDIA_JSON, KDR_MEDIA_CBOR},
    };
    for (size_t i = 0; i < sizeof acc / sizeof acc[0]; i++)
        CHECK(kdr_proto_answer_media(acc[i].accept, acc[i].req) == acc[i].want,
              "Accept %s (request %d)", acc[i].accept ? acc[i].accept : "(none)", acc[i].req);
    CHECK(!strcmp(kdr_proto_encoding_media(KDR_ENCODING_CBOR), "application/cbor") &&
              !strcmp(kdr_proto_encoding_media(KDR_ENCODING_BASE64), "application/json"),
          "answer media names");
}

int main(void) {
    for (int form = 0; form < 3; form++)
        for (int shared = 0; shared < 2; shared++) {
            test_bundle_twins(1, form, shared, form != 1);
            test_bundle_twins(1000, form, shared, 1);
            test_bundle_twins(777, form, shared, 0);
        }
    test_in_place();
    for (int form = 0; form < 3; form++)
        test_shadow_twins(form);
    test_frustum_twins();
    test_answers(1);
    test_answers(5000);
    test_truncations();
    test_malformed();
    test_fields_json();
    test_media();
    if (failures) {
        fprintf(stderr, "test_protocol_cbor: %d checks failed\n", failures);
        return 1;
    }
    printf("test_protocol_cbor: all checks passed\n");
    return 0;
}
