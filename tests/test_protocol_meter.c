/*
 * test_protocol_meter.c — what a parse allocates is counted before it is
 * allocated (kdr_proto_meter), cJSON's nodes included, and an allocation
 * that fails inside cJSON is "out of memory" (500), not "malformed JSON"
 * (400). Prints the meter's count per body byte for the body forms the
 * docs quote (the executor charges 2 bytes per body byte up front and
 * grows the charge through the meter beyond that).
 */
#include "cbor_body.h"

/* A body of about n bytes: `head` (which opens an array), then the digit
 * 1 as its elements, a multiple of 3 of them, then `tail`. */
static kdr_buf digits(const char *head, size_t n, const char *tail) {
    kdr_buf b;
    kdr_buf_init(&b);
    kdr_buf_append(&b, head, strlen(head));
    for (size_t k = 0; b.len < n || k % 3; k++)
        kdr_buf_append(&b, ",1" + (k == 0), k == 0 ? 1 : 2);
    kdr_buf_append(&b, tail, strlen(tail));
    return b;
}

/* A bundle of n rays with directions as decimals of ~9 characters. */
static kdr_buf usual(size_t n) {
    kdr_buf b;
    kdr_buf_init(&b);
    kdr_buf_append(&b, "{\"origins\":[0,3,5],\"directions\":[", 33);
    char tmp[KDR_FLOAT_CHARS];
    for (size_t i = 0; i < 3 * n; i++) {
        if (i) kdr_buf_append(&b, ",", 1);
        float v = i % 3 == 1 ? -1.0f : frand(-0.5f, 0.5f);
        kdr_buf_append(&b, tmp, kdr_format_float(v, tmp));
    }
    kdr_buf_append(&b, "]}", 2);
    return b;
}

typedef struct grant {
    size_t calls, granted;
} grant;

static int grant_all(void *ctx, kdr_proto_meter *m, size_t need) {
    grant *g = ctx;
    g->calls++;
    g->granted += need;
    m->limit += need;
    return 0;
}

/* Parses a bundle body under a meter that grants everything; returns the
 * count (an upper bound of the peak) and checks it never passed the limit. */
static size_t metered(kdr_media media, const char *body, size_t len, int *status,
                      char *detail) {
    grant g = {0, 0};
    kdr_proto_meter m = {.limit = 0, .grow = grant_all, .ctx = &g};
    kdr_proto_meter *outer = kdr_proto_meter_set(&m);
    kdr_bundle_request r;
    kdr_proto_error err = {0};
    *status = kdr_proto_parse_bundle_as(media, body, len, 0, &r, &err);
    kdr_proto_meter_set(outer);
    if (detail) snprintf(detail, 256, "%s", err.detail);
    kdr_bundle_request_free(&r);
    CHECK(m.used <= m.limit && !m.refused, "used %zu limit %zu", m.used, m.limit);
    return m.limit; /* every byte ever granted: the most that was live at once */
}

static void test_counts(void) {
    struct {
        const char *what;
        kdr_buf b;
        double at_most; /* bytes counted per body byte: measured + ~10% */
    } cases[] = {
        {"usual JSON (9-character decimals)", usual(100000), 1.4},
        {"JSON single digits in directions",
         digits("{\"origins\":[0,3,5],\"directions\":[", 600000, "]}"), 6.0},
        {"JSON single digits in an unknown member (cJSON)",
         digits("{\"origins\":[0,3,5],\"directions\":[0,0,-1],\"x\":[", 600000, "]}"),
         44},
        {"JSON single digits, escaped key (all cJSON)",
         digits("{\"origins\":[0,3,5],\"direction\\u0073\":[", 600000, "]}"), 46},
    };
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        int st;
        char detail[256];
        size_t used =
            metered(KDR_MEDIA_JSON, cases[i].b.data, cases[i].b.len, &st, detail);
        double per = (double)used / (double)cases[i].b.len;
        printf("%-52s %8zu bytes: %6.2f counted per body byte (status %d)\n",
               cases[i].what, cases[i].b.len, per, st);
        CHECK(st == 0, "%s: %d %s", cases[i].what, st, detail);
        CHECK(per <= cases[i].at_most, "%s: %.2f > %.2f", cases[i].what, per,
              cases[i].at_most);
        kdr_buf_free(&cases[i].b);
    }
    /* CBOR: typed arrays are read in place, one-byte integers cost 4 */
    body c = {0};
    const size_t n = 100000;
    float *dir = xmalloc(3 * n * sizeof(float));
    for (size_t i = 0; i < 3 * n; i++)
        dir[i] = i % 3 == 1 ? -1.0f : (float)(i % 2);
    for (int form = 0; form < 2; form++) {
        c.clen = 0;
        c_head(&c, cbor_encode_map_start, form ? 2 : 3);
        c_text(&c, "origins");
        c_floats(&c, (const float[]){0, 3, 5}, 3);
        if (form == 0) { /* a padding member puts the floats at a multiple of 4 */
            c_text(&c, "_p");
            const size_t k = (4 - (c.clen + 1 + 11 + 2 + 5) % 4) % 4;
            c_text(&c, "xxx" + 3 - k);
            c_text(&c, "directions");
            c_typed(&c, dir, 3 * n);
        } else {
            c_text(&c, "directions"); /* small integers: one byte each */
            c_head(&c, cbor_encode_array_start, 3 * n);
            for (size_t i = 0; i < 3 * n; i++)
                c_uint(&c, 1);
        }
        char *body = exact(c.c, c.clen);
        int st;
        char detail[256];
        size_t used = metered(KDR_MEDIA_CBOR, body, c.clen, &st, detail);
        double per = (double)used / (double)c.clen;
        printf("%-52s %8zu bytes: %6.2f counted per body byte (status %d)\n",
               form ? "CBOR one-byte integers" : "CBOR typed array", c.clen, per, st);
        CHECK(st == 0, "CBOR form %d: %d %s", form, st, detail);
        CHECK(form ? per <= 8.8 : per < 0.1, "CBOR form %d: %.2f per byte", form, per);
        free(body);
    }
    free(dir);
    body_free(&c);
}

/* A meter that refuses: the parse fails as out of memory, before the
 * block that would not fit exists, whichever path was allocating. */
static void test_refusal(void) {
    kdr_buf odd =
        digits("{\"origins\":[0,3,5],\"directions\":[0,0,-1],\"x\":[", 200000, "]}");
    kdr_buf esc = digits("{\"origins\":[0,3,5],\"direction\\u0073\":[", 200000, "]}");
    kdr_buf ok = usual(20000);
    const kdr_buf *bodies[] = {&odd, &esc, &ok};
    const char *names[] = {"unknown member", "escaped key", "usual"};
    for (int i = 0; i < 3; i++)
        for (size_t limit = 0; limit <= 200000; limit = limit ? 4 * limit : 64) {
            kdr_proto_meter m = {.limit = limit};
            kdr_proto_meter *outer = kdr_proto_meter_set(&m);
            kdr_bundle_request r;
            kdr_proto_error err = {0};
            int st = kdr_proto_parse_bundle(bodies[i]->data, bodies[i]->len, 0, &r, &err);
            kdr_proto_meter_set(outer);
            kdr_bundle_request_free(&r);
            CHECK(m.used <= limit, "%s: used %zu > limit %zu", names[i], m.used, limit);
            CHECK(st == 500 && strstr(err.detail, "out of memory") && m.refused,
                  "%s, limit %zu: %d %s", names[i], limit, st, err.detail);
        }
    /* unlimited: the same bodies parse; malformed JSON stays a 400 */
    for (int i = 0; i < 3; i++) {
        kdr_bundle_request r;
        kdr_proto_error err = {0};
        CHECK(kdr_proto_parse_bundle(bodies[i]->data, bodies[i]->len, 0, &r, &err) == 0,
              "%s: %s", names[i], err.detail);
        kdr_bundle_request_free(&r);
    }
    odd.data[odd.len - 2] = ',';
    kdr_proto_meter m = {.limit = (size_t)1 << 30};
    kdr_proto_meter *outer = kdr_proto_meter_set(&m);
    kdr_bundle_request r;
    kdr_proto_error err = {0};
    int st = kdr_proto_parse_bundle(odd.data, odd.len, 0, &r, &err);
    kdr_proto_meter_set(outer);
    CHECK(st == 400 && strstr(err.detail, "malformed JSON") && !m.refused, "%d %s", st,
          err.detail);
    kdr_buf_free(&odd);
    kdr_buf_free(&esc);
    kdr_buf_free(&ok);
}

/* A CBOR body whose small members go to cJSON is metered too. */
static void test_cbor_refusal(void) {
    body c = {0};
    c_head(&c, cbor_encode_map_start, 3);
    c_text(&c, "origins");
    c_floats(&c, (const float[]){0, 3, 5}, 3);
    c_text(&c, "directions");
    c_floats(&c, (const float[]){0, 0, -1}, 3);
    c_text(&c, "x");
    c_head(&c, cbor_encode_array_start, 60000);
    for (int i = 0; i < 60000; i++)
        c_uint(&c, 0);
    char *b = exact(c.c, c.clen);
    kdr_proto_meter m = {.limit = 100000};
    kdr_proto_meter *outer = kdr_proto_meter_set(&m);
    kdr_bundle_request r;
    kdr_proto_error err = {0};
    int st = kdr_proto_parse_bundle_as(KDR_MEDIA_CBOR, b, c.clen, 0, &r, &err);
    kdr_proto_meter_set(outer);
    kdr_bundle_request_free(&r);
    CHECK(st == 500 && strstr(err.detail, "out of memory") && m.used <= m.limit,
          "CBOR: %d %s, used %zu", st, err.detail, m.used);
    free(b);
    body_free(&c);
}

int main(void) {
    test_counts();
    test_refusal();
    test_cbor_refusal();
    printf("%s\n", failures ? "FAILED" : "ok");
    return failures != 0;
}
