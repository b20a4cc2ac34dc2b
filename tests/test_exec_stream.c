/*
 * test_exec_stream.c — the executor's streamed answers (exec/kdr_exec_stream.c)
 * without HTTP: the items taken in order (head, chunk items, final item)
 * hold the one-shot CBOR answer's typed arrays byte for byte, for bundle
 * closest/any (with fields), frustum and cone-shadow, with 1 and 2
 * workers; a bundle stream of more chunks than its window reuses its slots;
 * a consumer that stops taking items leaves the query running with no
 * worker inside; a deadline or a cancel ends a stalled stream. Items are
 * decoded with libcbor. A plain C program: exits nonzero when a check
 * fails.
 */
#define _POSIX_C_SOURCE 200809L
#include <cbor.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "exec_bodies.h"

/* The members of one CBOR map item: typed arrays (tag + byte string) as
 * their bytes appended to arrays[k] (k by name), and the uint "first",
 * "count" and "status". */
enum { NAMES = 8 };
static const char *const NAME[NAMES] = {"t",   "prim",       "u",      "v",
                                        "hit", "visibility", "normal", "mesh"};
typedef struct decoded {
    kdr_buf arrays[NAMES];
    long long first, count, status;
} decoded;

static void decode_into(const kdr_buf *item, decoded *d) {
    struct cbor_load_result res;
    cbor_item_t *it = cbor_load((const unsigned char *)item->data, item->len, &res);
    CHECK(it && res.error.code == CBOR_ERR_NONE && res.read == item->len &&
              cbor_isa_map(it),
          "one map item (%zu of %zu bytes read)", res.read, item->len);
    if (!it) return;
    d->first = d->count = d->status = -1;
    struct cbor_pair *p = cbor_map_handle(it);
    for (size_t i = 0; i < cbor_map_size(it); i++) {
        char key[32] = "";
        if (cbor_isa_string(p[i].key) && cbor_string_length(p[i].key) < sizeof key)
            memcpy(key, cbor_string_handle(p[i].key), cbor_string_length(p[i].key));
        if (cbor_isa_uint(p[i].value)) {
            long long v = (long long)cbor_get_int(p[i].value);
            if (!strcmp(key, "first")) d->first = v;
            if (!strcmp(key, "count")) d->count = v;
            if (!strcmp(key, "status")) d->status = v;
        }
        if (!cbor_isa_tag(p[i].value)) continue;
        cbor_item_t *bytes = cbor_tag_item(p[i].value);
        for (int k = 0; k < NAMES; k++)
            if (!strcmp(key, NAME[k]))
                kdr_buf_append(&d->arrays[k], cbor_bytestring_handle(bytes),
                               cbor_bytestring_length(bytes));
        cbor_decref(&bytes);
    }
    cbor_decref(&it);
}

static void decoded_free(decoded *d) {
    for (int k = 0; k < NAMES; k++)
        kdr_buf_free(&d->arrays[k]);
}

static kdr_exec_query query_of(const kdr_scene *s, kdr_exec_kind kind, const body *b) {
    kdr_exec_query q = {.kind = kind,
                        .mode = KDR_EXEC_FAST,
                        .scene = s,
                        .body = b->s,
                        .len = b->len,
                        .media = b->media,
                        .answer_media = KDR_MEDIA_CBOR,
                        .start = kdr_exec_now()};
    return q;
}

static void pause_us(long us) { nanosleep(&(struct timespec){0, us * 1000L}, NULL); }

/* Waits until q is ready to stream; 0 if it finished without (a problem). */
static int wait_ready(kdr_exec_query *q) {
    while (!kdr_exec_stream_ready(q))
        if (kdr_exec_wait(q, 0.001)) return kdr_exec_stream_ready(q);
    return 1;
}

/* Takes every item of a ready stream into d; the final item's status. */
static long long take_all(kdr_exec_query *q, decoded *d, long slow_us) {
    kdr_buf item;
    kdr_buf_init(&item);
    CHECK(kdr_exec_stream_head(q, &item) == 0, "head");
    kdr_buf_free(&item);
    const size_t items = kdr_exec_stream_items(q);
    long long next_first = 0;
    size_t i = 0;
    for (; i < items; i++) {
        while (!kdr_exec_stream_item_ready(q, i))
            if (kdr_exec_wait(q, 0.0005) && q->result.status != 200 &&
                !kdr_exec_stream_item_ready(q, i))
                break;
        if (!kdr_exec_stream_item_ready(q, i)) break; /* stopped */
        CHECK(kdr_exec_stream_item(q, i, &item) == 0, "item %zu", i);
        decoded one = {0};
        decode_into(&item, &one);
        kdr_buf_free(&item);
        CHECK(one.first == next_first && one.count > 0, "item %zu: first %lld, want %lld",
              i, one.first, next_first);
        next_first += one.count;
        for (int k = 0; k < NAMES; k++)
            kdr_buf_append(&d->arrays[k], one.arrays[k].data, one.arrays[k].len);
        decoded_free(&one);
        if (slow_us) pause_us(slow_us);
    }
    kdr_exec_wait(q, -1);
    CHECK(kdr_exec_stream_end(q, i, &item) == 0, "final item");
    decoded fin = {0};
    decode_into(&item, &fin);
    kdr_buf_free(&item);
    decoded_free(&fin);
    return fin.status;
}

/* One body streamed equals its one-shot CBOR answer, array by array. */
static void check_stream(kdr_exec *ex, const kdr_scene *s, kdr_exec_kind kind,
                         const body *b, const char *what, long slow_us) {
    kdr_exec_query one = query_of(s, kind, b);
    CHECK(kdr_exec_submit(ex, &one) == 0, "submit");
    kdr_exec_wait(&one, -1);
    CHECK(one.result.status == 200, "%s: one-shot %d %s", what, one.result.status,
          one.result.detail);
    decoded want = {0}, got = {0};
    decode_into(&one.result.body, &want);
    kdr_exec_query_done(&one);

    kdr_exec_query q = query_of(s, kind, b);
    q.stream = 1;
    CHECK(kdr_exec_submit(ex, &q) == 0, "submit");
    CHECK(wait_ready(&q), "%s: ready: %d %s", what, q.result.status, q.result.detail);
    const long long status = take_all(&q, &got, slow_us);
    CHECK(status == 200, "%s: final status %lld (%s)", what, status, q.result.detail);
    for (int k = 0; k < NAMES; k++)
        CHECK(got.arrays[k].len == want.arrays[k].len &&
                  (!want.arrays[k].len ||
                   !memcmp(got.arrays[k].data, want.arrays[k].data, want.arrays[k].len)),
              "%s: %s: %zu bytes streamed, %zu in one piece (or different)", what,
              NAME[k], got.arrays[k].len, want.arrays[k].len);
    kdr_exec_query_done(&q);
    decoded_free(&want);
    decoded_free(&got);
}

static void test_equal(const kdr_scene *s) {
    body b[9];
    b[0] = bundle_body(10000, "closest", "");
    b[1] = bundle_body(100000, "closest", ""); /* 25 chunks: the window wraps */
    b[2] = bundle_body(70000, "any", ",\"fields\":[\"hit\"]");
    b[3] = cbor_bundle_body(30000, "closest");
    b[4] = bundle_body(5000, "closest", ",\"fields\":[\"t\",\"normal\",\"mesh\"]");
    b[5] = frustum_body(97, 61, "closest", "");
    b[6] = frustum_body(40, 30, "any", "");
    b[7] = shadow_body(300, 16, ""); /* with stats */
    b[8] = cbor_shadow_body(100);
    const kdr_exec_kind k[9] = {
        KDR_EXEC_BUNDLE,  KDR_EXEC_BUNDLE,      KDR_EXEC_BUNDLE,
        KDR_EXEC_BUNDLE,  KDR_EXEC_BUNDLE,      KDR_EXEC_FRUSTUM,
        KDR_EXEC_FRUSTUM, KDR_EXEC_CONE_SHADOW, KDR_EXEC_CONE_SHADOW};
    for (unsigned workers = 1; workers <= 2; workers++) {
        kdr_exec_config cfg = {workers, 8, 0, NULL, NULL};
        kdr_exec *ex = kdr_exec_create(&cfg);
        for (int i = 0; i < 9; i++) {
            char what[64];
            snprintf(what, sizeof what, "case %d, %u workers", i, workers);
            check_stream(ex, s, k[i], &b[i], what, 0);
        }
        /* a slow consumer: the window fills and drains many times */
        check_stream(ex, s, KDR_EXEC_BUNDLE, &b[1], "slow consumer", 2000);
        kdr_exec_stats st;
        kdr_exec_get_stats(ex, &st);
        CHECK(st.queued == 0 && st.running == 0 && st.busy == 0 && st.slots_used == 0,
              "idle books");
        kdr_exec_destroy(ex);
    }
    for (int i = 0; i < 9; i++)
        free(b[i].s);
}

/* A consumer that takes nothing: once the window is traced the query runs
 * with no worker inside; then a deadline (or a cancel) ends it, and the
 * items traced before it are still there. */
static void test_stall(const kdr_scene *s) {
    body b = bundle_body(200000, "closest", "");
    kdr_exec_config cfg = {2, 8, 0, NULL, NULL};
    kdr_exec *ex = kdr_exec_create(&cfg);
    for (int cancel = 0; cancel < 2; cancel++) {
        kdr_exec_query q = query_of(s, KDR_EXEC_BUNDLE, &b);
        q.stream = 1;
        q.deadline_ms = cancel ? 0 : 1500;
        CHECK(kdr_exec_submit(ex, &q) == 0, "submit");
        CHECK(wait_ready(&q), "ready");
        kdr_exec_stats st = {0};
        int stalled = 0;
        for (int k = 0; k < 20000 && !stalled; k++) {
            kdr_exec_get_stats(ex, &st);
            stalled =
                st.running == 1 && st.busy == 0 && kdr_exec_stream_item_ready(&q, 15);
            if (!stalled) pause_us(500);
        }
        CHECK(stalled, "stalled with the window full: running %zu, busy %u", st.running,
              st.busy);
        CHECK(!kdr_exec_stream_item_ready(&q, 16), "chunk 16 waits for item 0");
        if (cancel) {
            kdr_exec_cancel(&q);
        } else {
            while (!kdr_exec_wait(&q, 0.01)) {
            } /* the waiter finishes an idle query past its deadline */
        }
        decoded got = {0};
        const long long status = take_all(&q, &got, 0);
        CHECK(status == (cancel ? 499 : 503), "stalled stream ends %lld: %s", status,
              q.result.detail);
        CHECK(got.arrays[0].len == 16 * 4096 * sizeof(float),
              "the 16 traced items are still taken: %zu bytes of t", got.arrays[0].len);
        kdr_exec_query_done(&q);
        decoded_free(&got);
    }
    kdr_exec_destroy(ex);
    free(b.s);
}

/* A query that cannot stream is a 406 before anything streams. */
static void test_refused(const kdr_scene *s) {
    body b = bundle_body(100, "count", "");
    kdr_exec_config cfg = {1, 8, 0, NULL, NULL};
    kdr_exec *ex = kdr_exec_create(&cfg);
    kdr_exec_query q = query_of(s, KDR_EXEC_BUNDLE, &b);
    q.stream = 1;
    CHECK(kdr_exec_submit(ex, &q) == 0, "submit");
    CHECK(!wait_ready(&q) && q.result.status == 406, "count: %d", q.result.status);
    kdr_exec_query_done(&q);
    kdr_exec_destroy(ex);
    free(b.s);
}

int main(void) {
    kdr_scene *s = make_scene();
    if (!s) return 1;
    test_equal(s);
    test_stall(s);
    test_refused(s);
    kdr_scene_free(s);
    printf("%s\n", failures ? "FAILED" : "ok");
    return failures != 0;
}
