/*
 * test_protocol_fields.c — the answer-field choice ("fields") as parsed for
 * bundle and frustum requests (defaults, subsets, every error), and media
 * negotiation: Content-Type to JSON / CBOR / other, Accept q-values to the
 * answer's media type. A plain C program.
 */
#include "cbor_body.h"

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
    test_fields_json();
    test_media();
    if (failures) {
        fprintf(stderr, "test_protocol_fields: %d checks failed\n", failures);
        return 1;
    }
    printf("test_protocol_fields: all checks passed\n");
    return 0;
}
