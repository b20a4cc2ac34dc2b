/*
 * test_protocol_cbor.c — the binary body form (application/cbor): a CBOR
 * request and its JSON twin parse to the same query bit for bit for every
 * query kind and every array form; float32 typed arrays are used in place
 * when aligned and copied when not; CBOR answers, read back with libcbor's
 * own tree loader (cbor_load, a decoder independent of the streaming
 * reader under test), hold exactly the JSON answer's values for every
 * query kind and field choice. Malformed bodies: test_protocol_cbor_errors.c.
 * A plain C program: exits nonzero when a check fails.
 */
#include <float.h>

#include <cjson/cJSON.h>

#include "cbor_body.h"

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
                  x->offset == y->offset && x->offset == KDR_OFFSET_DIAGONAL &&
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
    if (failures) {
        fprintf(stderr, "test_protocol_cbor: %d checks failed\n", failures);
        return 1;
    }
    printf("test_protocol_cbor: all checks passed\n");
    return 0;
}
