/*
 * test_protocol_cbor_errors.c — malformed CBOR bodies: every truncation of
 * a valid body, wrong types and lengths, NaN, unsupported tags, huge
 * declared lengths, nesting bombs (in unknown, known and float-array
 * members) and an item flood each give a clean 400 whose detail names the
 * member (and the CBOR offset), never a crash; unknown and duplicate
 * members are read and ignored as in JSON. A plain C program.
 */
#include <float.h>

#include "cbor_body.h"

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
    {
        /* the finite check runs four or more floats at a time: the largest
         * finite values and subnormals pass, a non-finite one in the
         * vector part or in the scalar tail is found and named */
        float big[33];
        for (int i = 0; i < 33; i++)
            big[i] = i % 3 == 2 ? -FLT_MAX : i % 2 ? FLT_MAX : 1e-40f;
        for (int k = 0; k < 3; k++) {
            if (k == 1) big[32] = INFINITY;
            if (k == 2) {
                big[32] = FLT_MAX;
                big[17] = -INFINITY;
            }
            RESET();
            c_head(&b, cbor_encode_map_start, 2);
            c_text(&b, "origins");
            c_typed(&b, three, 3);
            c_text(&b, "directions");
            c_typed(&b, big, 33);
            expect(0, &b, k ? 400 : 0,
                   k == 0 ? "" : k == 1 ? "directions[32]: not a finite number"
                                        : "directions[17]: not a finite number");
        }
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

int main(void) {
    test_truncations();
    test_malformed();
    if (failures) {
        fprintf(stderr, "test_protocol_cbor_errors: %d checks failed\n", failures);
        return 1;
    }
    printf("test_protocol_cbor_errors: all checks passed\n");
    return 0;
}
