/*
 * test_protocol_fields.c — the answer-field choice ("fields") as parsed for
 * bundle and frustum requests (defaults, subsets, every error), and media
 * negotiation: Content-Type to JSON / CBOR / other, Accept q-values to the
 * answer's media type; and the answer size bounds (kdr_proto_*_answer_max)
 * that admission charges: every answer fits its bound, and encoding into
 * an empty buffer allocates the bound once and never grows it. A plain C
 * program.
 */
#include "cbor_body.h"

/* ---- field selection in JSON ----------------------------------------------------------
 */

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
        {"[\"normal\",\"mesh\"]", "closest", 0, KDR_FIELD_NORMAL | KDR_FIELD_MESH, ""},
        {"[\"mesh\"]", "any", 400, 0, "fields[0]: \"mesh\" needs \"query\": \"closest\""},
        {"[\"normals\"]", "closest", 400, 0,
         "fields[0]: unknown field \"normals\" (t, prim, u, v, hit, normal, mesh)"},
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

/* ---- streamed answer items (kdr_seq.c)
 * ----------------------------------------------------------------------- */

static void test_seq_items(void) {
    /* a chunk item is the slice's own answer map with "first" in front */
    float t[3] = {1.0f, 2.0f, 3.0f};
    int32_t prim[3] = {4, -1, 6};
    const kdr_hits h = {.t = t, .prim = prim, .u = t, .v = t};
    kdr_buf slice, item, want;
    kdr_buf_init(&slice);
    kdr_buf_init(&item);
    kdr_buf_init(&want);
    CHECK(kdr_proto_encode_hits_fields(&h, 3, KDR_CLOSEST, KDR_FIELD_T | KDR_FIELD_PRIM,
                                KDR_ENCODING_CBOR, &slice) == 0,
          "slice");
    CHECK(kdr_proto_seq_item(&item, 70000, &slice) == 0, "item");
    /* map(4) "first" 70000, then the slice's 3 members as they were */
    static const unsigned char head[] = {0xa4, 0x65, 'f', 'i', 'r',  's',
                                         't',  0x1a, 0,   1,   0x11, 0x70};
    CHECK(item.len == sizeof head + slice.len - 1 &&
              !memcmp(item.data, head, sizeof head) &&
              !memcmp(item.data + sizeof head, slice.data + 1, slice.len - 1),
          "item bytes");
    kdr_buf bad = {.data = (char *)"\x83\x01", .len = 2, .cap = 2};
    CHECK(kdr_proto_seq_item(&want, 0, &bad) == KDR_EINVAL, "not a map");
    kdr_buf_free(&item);
    CHECK(kdr_proto_seq_problem(&item, 503, "deadline") == 0 &&
              item.data[0] == (char)0xa4,
          "problem item");
    kdr_buf_free(&item);
    kdr_buf_free(&slice);
    kdr_buf_free(&want);
}

/* ---- media types
 * ----------------------------------------------------------------------- */

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
        {"application/problem+json, application/cbor;q=0.1", KDR_MEDIA_JSON,
         KDR_MEDIA_CBOR},
        /* a streamed answer is opt-in: named exactly, never via wildcards */
        {"application/cbor-seq", KDR_MEDIA_JSON, KDR_MEDIA_CBOR_SEQ},
        {"application/cbor-seq, application/cbor;q=0.5", KDR_MEDIA_CBOR,
         KDR_MEDIA_CBOR_SEQ},
        {"application/cbor, application/cbor-seq;q=0.5", KDR_MEDIA_JSON, KDR_MEDIA_CBOR},
        {"application/cbor-seq;q=0, application/cbor", KDR_MEDIA_JSON, KDR_MEDIA_CBOR},
        {"application/cbor-seqx", KDR_MEDIA_JSON, KDR_MEDIA_JSON},
    };
    for (size_t i = 0; i < sizeof acc / sizeof acc[0]; i++)
        CHECK(kdr_proto_answer_media(acc[i].accept, acc[i].req) == acc[i].want,
              "Accept %s (request %d)", acc[i].accept ? acc[i].accept : "(none)",
              acc[i].req);
    CHECK(kdr_proto_media_of("application/cbor-seq") == KDR_MEDIA_OTHER,
          "cbor-seq bodies are not read (415)");
    CHECK(!strcmp(kdr_proto_media_name(KDR_MEDIA_CBOR_SEQ), "application/cbor-seq"),
          "cbor-seq name");
    CHECK(!strcmp(kdr_proto_encoding_media(KDR_ENCODING_CBOR), "application/cbor") &&
              !strcmp(kdr_proto_encoding_media(KDR_ENCODING_BASE64), "application/json"),
          "answer media names");
}

/* ---- answer size bounds
 * ------------------------------------------------------------------ */

/* The longest values: a float printed in 16 characters, the largest
 * triangle index, every ray a hit (or, for misses, prim -1 and t -1). */
static void worst_hits(kdr_hits *h, size_t n, int misses) {
    for (size_t i = 0; i < n; i++) {
        const float f = i % 2 ? -1.23456875e-5f : -9.87654321e-38f; /* 16 / 15 chars */
        h->t[i] = h->u[i] = h->v[i] = f;
        h->prim[i] = misses && i % 3 == 0 ? -7 : 2147483647;
        h->hit[i] = 1;
    }
}

static void check_bound(kdr_buf *out, size_t bound, int rc, const char *what) {
    CHECK(rc == 0 && out->len <= bound && out->cap == bound,
          "%s: rc %d, %zu bytes, capacity %zu, bound %zu", what, rc, out->len, out->cap,
          bound);
}

static void test_answer_bounds(void) {
    static const size_t sizes[] = {1, 2, 3, 4, 3071, 3072, 3073, 10000};
    static const kdr_encoding encs[] = {KDR_ENCODING_JSON, KDR_ENCODING_BASE64,
                                        KDR_ENCODING_CBOR};
    char what[128];
    char tmp[KDR_FLOAT_CHARS];
    CHECK(kdr_format_float(-1.23456875e-5f, tmp) == KDR_FLOAT_MAX_LEN,
          "the 16-character float");
    for (size_t si = 0; si < sizeof sizes / sizeof sizes[0]; si++) {
        const size_t n = sizes[si];
        kdr_hits h = {xmalloc(4 * n), xmalloc(4 * n), xmalloc(4 * n), xmalloc(4 * n),
                      xmalloc(n)};
        for (int misses = 0; misses < 2; misses++) {
            worst_hits(&h, n, misses);
            for (int e = 0; e < 3; e++)
                for (int q = 0; q < 2; q++)
                    for (unsigned f = 1; f <= (KDR_FIELDS_CLOSEST | KDR_FIELDS_ANY);
                         f++) {
                        const kdr_query query = q ? KDR_ANY : KDR_CLOSEST;
                        if (query == KDR_ANY && (f & KDR_FIELDS_CLOSEST)) continue;
                        kdr_buf out;
                        kdr_buf_init(&out);
                        const size_t bound =
                            kdr_proto_hits_answer_max(n, query, f, encs[e]);
                        snprintf(what, sizeof what,
                                 "hits n=%zu enc %d query %d fields %u", n, e, q, f);
                        check_bound(
                            &out, bound,
                            kdr_proto_encode_hits_fields(&h, n, query, f, encs[e], &out),
                            what);
                        kdr_buf_free(&out);
                    }
            /* fewer fields, smaller bound; CBOR below base64 below JSON */
            const size_t all = kdr_proto_hits_answer_max(
                n, KDR_CLOSEST, KDR_FIELDS_CLOSEST, KDR_ENCODING_JSON);
            CHECK(kdr_proto_hits_answer_max(n, KDR_CLOSEST, KDR_FIELD_T,
                                            KDR_ENCODING_JSON) < all,
                  "t alone is smaller");
            CHECK(kdr_proto_hits_answer_max(n, KDR_CLOSEST, KDR_FIELDS_CLOSEST,
                                            KDR_ENCODING_CBOR) <
                      kdr_proto_hits_answer_max(n, KDR_CLOSEST, KDR_FIELDS_CLOSEST,
                                                KDR_ENCODING_BASE64),
                  "CBOR is smaller than base64");
        }
        /* cone-shadow: n points x 3 lights, with the largest stats */
        const kdr_shadow_stats st = {UINT64_MAX, UINT64_MAX, UINT64_MAX};
        for (int e = 0; e < 3; e++)
            for (int with = 0; with < 2; with++) {
                float *vis = xmalloc(3 * n * sizeof(float));
                for (size_t i = 0; i < 3 * n; i++)
                    vis[i] = i % 2 ? 0.000123456789f : 1.0f / 3.0f;
                kdr_buf out;
                kdr_buf_init(&out);
                const size_t bound = kdr_proto_shadow_answer_max(n, 3, with, encs[e]);
                snprintf(what, sizeof what, "shadow n=%zu enc %d stats %d", n, e, with);
                check_bound(
                    &out, bound,
                    kdr_proto_encode_shadow(vis, n, 3, with ? &st : NULL, encs[e], &out),
                    what);
                kdr_buf_free(&out);
                free(vis);
            }
        free(h.t), free(h.prim), free(h.u), free(h.v), free(h.hit);
    }
}

/* "all" and "count" answers (issue 15): n rays of 0..4 hits with the
 * longest values, every field set and encoding, stay within their bounds. */
static void test_all_bounds(void) {
    static const size_t sizes[] = {1, 2, 1000, 3073};
    static const kdr_encoding encs[] = {KDR_ENCODING_JSON, KDR_ENCODING_BASE64,
                                        KDR_ENCODING_CBOR};
    char what[128];
    for (size_t si = 0; si < sizeof sizes / sizeof sizes[0]; si++) {
        const size_t n = sizes[si];
        int32_t *nh = xmalloc(4 * n), *off = xmalloc(4 * (n + 1)),
                *prim = xmalloc(16 * n);
        uint32_t *cnt = xmalloc(4 * n);
        float *f = xmalloc(16 * n);
        off[0] = 0;
        for (size_t i = 0; i < n; i++) {
            nh[i] = (int32_t)(n == 1 ? 4 : i % 5);
            off[i + 1] = off[i] + nh[i];
            cnt[i] = 1u << 30;
        }
        for (size_t k = 0; k < 4 * n; k++) {
            f[k] = k % 2 ? -1.23456875e-5f : -9.87654321e-38f;
            prim[k] = 1073741823;
        }
        float *nrm = xmalloc(48 * n);
        int32_t *msh = xmalloc(48 * n);
        for (size_t k = 0; k < 12 * n; k++) {
            nrm[k] = k % 2 ? -1.23456875e-5f : -9.87654321e-38f;
            msh[k] = k % 3 ? -1 : 2147483647;
        }
        const kdr_all_answer a = {n, nh, off, f, f, f, prim, {nrm, msh}};
        const size_t maxh = n < 5 ? (size_t)nh[n - 1] : 4; /* the encoder's own bound */
        for (int e = 0; e < 3; e++) {
            for (unsigned fs = 1; fs <= (KDR_FIELDS_CLOSEST | KDR_FIELDS_ATTRS); fs++) {
                if (fs & KDR_FIELD_HIT) continue;
                kdr_buf out;
                kdr_buf_init(&out);
                snprintf(what, sizeof what, "all n=%zu enc %d fields %u", n, e, fs);
                check_bound(&out, kdr_proto_all_answer_max(n, maxh, fs, encs[e]),
                            kdr_proto_encode_all(&a, fs, encs[e], &out), what);
                kdr_buf_free(&out);
            }
            kdr_buf out;
            kdr_buf_init(&out);
            snprintf(what, sizeof what, "count n=%zu enc %d", n, e);
            check_bound(&out, kdr_proto_counts_answer_max(n, encs[e]),
                        kdr_proto_encode_counts(cnt, n, encs[e], &out), what);
            kdr_buf_free(&out);
        }
        kdr_buf out;
        kdr_buf_init(&out);
        CHECK(kdr_proto_encode_all(&a, KDR_FIELD_HIT, KDR_ENCODING_JSON, &out) ==
                  KDR_EINVAL,
              "all refuses the hit field");
        kdr_buf_free(&out);
        /* closest answers with normal and mesh (3 values per ray) */
        kdr_hits h = {f, prim, f, f, NULL};
        const kdr_hit_attrs at = {nrm, msh};
        for (int e = 0; e < 3; e++)
            for (unsigned fs = 1;
                 fs <= (KDR_FIELDS_CLOSEST | KDR_FIELDS_ANY | KDR_FIELDS_ATTRS); fs++) {
                if (!(fs & KDR_FIELDS_ATTRS)) continue;
                kdr_buf o2;
                kdr_buf_init(&o2);
                snprintf(what, sizeof what, "attrs n=%zu enc %d fields %u", n, e, fs);
                check_bound(&o2, kdr_proto_hits_answer_max(n, KDR_CLOSEST, fs, encs[e]),
                            kdr_proto_encode_hits_attrs(&h, &at, n, KDR_CLOSEST, fs,
                                                        encs[e], &o2),
                            what);
                kdr_buf_free(&o2);
            }
        kdr_buf o3;
        kdr_buf_init(&o3);
        CHECK(kdr_proto_encode_hits_fields(&h, n, KDR_CLOSEST, KDR_FIELD_NORMAL,
                                           KDR_ENCODING_JSON, &o3) == KDR_EINVAL,
              "normal without attributes is refused");
        kdr_buf_free(&o3);
        free(nh), free(off), free(prim), free(cnt), free(f), free(nrm), free(msh);
    }
    /* the JSON text of a small answer, exactly */
    const int32_t nh[2] = {2, 0}, off[3] = {0, 2, 2}, prim[2] = {5, 9};
    const float t[2] = {1.5f, 2.0f}, u[2] = {0.25f, 0.0f}, v[2] = {0.5f, 1.0f};
    const kdr_all_answer a = {2, nh, off, t, u, v, prim, {NULL, NULL}};
    kdr_buf out;
    kdr_buf_init(&out);
    CHECK(kdr_proto_encode_all(&a, KDR_FIELD_T | KDR_FIELD_PRIM, KDR_ENCODING_JSON,
                               &out) == 0 &&
              !strcmp(kdr_buf_cstr(&out),
                      "{\"count\":2,\"nhits\":[2,0],\"offset\":[0,2,2],"
                      "\"t\":[1.5,2],\"prim\":[5,9]}"),
          "all answer text: %s", out.data ? out.data : "(none)");
    kdr_buf_free(&out);
}

/* closest-point answers (issue 15) with the longest values stay within
 * their bound, in every encoding. */
static void test_closest_bounds(void) {
    static const size_t sizes[] = {1, 2, 1024, 3073};
    static const kdr_encoding encs[] = {KDR_ENCODING_JSON, KDR_ENCODING_BASE64,
                                        KDR_ENCODING_CBOR};
    char what[96];
    for (size_t si = 0; si < sizeof sizes / sizeof sizes[0]; si++) {
        const size_t n = sizes[si];
        kdr_closest *c = xmalloc(n * sizeof *c);
        for (size_t i = 0; i < n; i++) {
            const float f = i % 2 ? -1.23456875e-5f : -9.87654321e-38f;
            c[i] = (kdr_closest){{f, f, f}, f, f, f, i % 3 ? 1073741823 : -1};
        }
        for (int e = 0; e < 3; e++) {
            kdr_buf out;
            kdr_buf_init(&out);
            snprintf(what, sizeof what, "closest n=%zu enc %d", n, e);
            check_bound(&out, kdr_proto_closest_answer_max(n, encs[e]),
                        kdr_proto_encode_closest(c, n, encs[e], &out), what);
            kdr_buf_free(&out);
        }
        free(c);
    }
}

int main(void) {
    test_closest_bounds();
    test_fields_json();
    test_media();
    test_seq_items();
    test_answer_bounds();
    test_all_bounds();
    if (failures) {
        fprintf(stderr, "test_protocol_fields: %d checks failed\n", failures);
        return 1;
    }
    printf("test_protocol_fields: all checks passed\n");
    return 0;
}
