/*
 * test_exec.c — the query executor (exec/): answers equal a single-threaded
 * parse + core call + encode byte for byte for every kind and mode with 1 to
 * 3 workers and several submitting threads; admission refuses by slots, by
 * bytes and by size, and its books return to zero; deadlines, cancellation
 * and shutdown stop a query between chunks with the right status; a parse
 * error is a 400 whose claim is settled. Bodies are JSON or CBOR, answers
 * JSON, base64 or CBOR with the fields asked for, each equal to protocol/'s
 * own parse + encode of the same body. A plain C program: exits nonzero
 * when a check fails.
 */
#define _POSIX_C_SOURCE 200809L
#include <math.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "exec_bodies.h"

/* ---- the single-threaded answer: parse, one core call, encode --------------- */

static kdr_buf direct_answer(const kdr_scene *s, kdr_exec_kind kind, kdr_exec_mode mode,
                             const body *b) {
    kdr_buf out;
    kdr_buf_init(&out);
    kdr_proto_error err;
    int fast = mode == KDR_EXEC_FAST;
    const int cbor = b->answer == KDR_MEDIA_CBOR;
    if (kind == KDR_EXEC_BUNDLE) {
        kdr_bundle_request r;
        CHECK(kdr_proto_parse_bundle_as(b->media, b->s, b->len, 0, &r, &err) == 0, "%s",
              err.detail);
        size_t n = r.batch.n;
        kdr_hits h = {malloc(4 * n), malloc(4 * n), malloc(4 * n), malloc(4 * n),
                      malloc(n)};
        kdr_trace_batch(s, &r.batch, 0, n, r.query,
                        fast ? KDR_TRAV_AUTO : KDR_TRAV_SINGLE, &h, NULL);
        kdr_proto_encode_hits_fields(&h, n, r.query, r.fields,
                                     cbor ? KDR_ENCODING_CBOR : r.encoding, &out);
        free(h.t), free(h.prim), free(h.u), free(h.v), free(h.hit);
        kdr_bundle_request_free(&r);
    } else if (kind == KDR_EXEC_FRUSTUM) {
        kdr_frustum_request r;
        CHECK(kdr_proto_parse_frustum_as(b->media, b->s, b->len, 0, &r, &err) == 0, "%s",
              err.detail);
        size_t n = r.rays;
        kdr_hits h = {malloc(4 * n), malloc(4 * n), malloc(4 * n), malloc(4 * n),
                      malloc(n)};
        kdr_frustum_trace(s, &r.camera, r.tile, 0,
                          kdr_frustum_tile_count(&r.camera, r.tile), r.query,
                          fast ? KDR_FRUSTUM_MULTI4 : KDR_FRUSTUM_RAYS, &h, NULL);
        kdr_proto_encode_hits_fields(&h, n, r.query, r.fields,
                                     cbor ? KDR_ENCODING_CBOR : r.encoding, &out);
        free(h.t), free(h.prim), free(h.u), free(h.v), free(h.hit);
    } else {
        kdr_shadow_request r;
        CHECK(kdr_proto_parse_shadow_as(b->media, b->s, b->len, 0, &r, &err) == 0, "%s",
              err.detail);
        float *vis = malloc(r.query.n * r.query.nlights * sizeof(float));
        kdr_shadow_stats st = {0, 0, 0};
        kdr_shadow_trace(s, &r.query, 0, r.query.n,
                         fast ? KDR_SHADOW_CONE : KDR_SHADOW_RAYS, vis, &st);
        kdr_proto_encode_shadow(vis, r.query.n, r.query.nlights,
                                r.want_stats ? &st : NULL,
                                cbor ? KDR_ENCODING_CBOR : r.encoding, &out);
        free(vis);
        kdr_shadow_request_free(&r);
    }
    return out;
}

static void run_query(kdr_exec *ex, kdr_exec_query *q) {
    CHECK(kdr_exec_submit(ex, q) == 0, "submit");
    kdr_exec_wait(q, -1);
}

static kdr_exec_query query_of(const kdr_scene *s, kdr_exec_kind kind, kdr_exec_mode mode,
                               const body *b) {
    kdr_exec_query q = {.kind = kind,
                        .mode = mode,
                        .scene = s,
                        .body = b->s,
                        .len = b->len,
                        .media = b->media,
                        .answer_media = b->answer,
                        .start = kdr_exec_now()};
    return q;
}

/* ---- answers ------------------------------------------------------------------- */

enum { NCASES = 12 };
typedef struct cases {
    const kdr_scene *scene;
    body bodies[NCASES];
    kdr_exec_kind kinds[NCASES];
    kdr_buf want[2][NCASES]; /* [mode][case] */
} cases;

static void make_cases(cases *c, const kdr_scene *s) {
    c->scene = s;
    const kdr_exec_kind k[NCASES] = {
        KDR_EXEC_BUNDLE,  KDR_EXEC_BUNDLE,      KDR_EXEC_BUNDLE,      KDR_EXEC_FRUSTUM,
        KDR_EXEC_FRUSTUM, KDR_EXEC_CONE_SHADOW, KDR_EXEC_CONE_SHADOW, KDR_EXEC_BUNDLE,
        KDR_EXEC_BUNDLE,  KDR_EXEC_BUNDLE,      KDR_EXEC_CONE_SHADOW, KDR_EXEC_FRUSTUM};
    memcpy(c->kinds, k, sizeof k);
    c->bodies[0] = bundle_body(10000, "closest", ""); /* 3 chunks */
    c->bodies[1] = bundle_body(9000, "any", ",\"encoding\":\"base64\"");
    c->bodies[2] = bundle_body(1, "closest", "");
    /* 13 x 8 tiles: 7 chunks; base64 (frustum_body's encoding) of the
     * core's arrays as they lie (kdr_proto_encode_hits_wire), misses
     * included, against the normalising encoder */
    c->bodies[3] = frustum_body(97, 61, "closest", "");
    c->bodies[4] = frustum_body(40, 30, "any", "");
    c->bodies[5] = shadow_body(150, 16, ""); /* 3 chunks */
    c->bodies[6] = shadow_body(1, 64, ",\"encoding\":\"base64\"");
    /* CBOR in and out (float32 typed arrays read in place), CBOR in and
     * JSON out (Accept), JSON in and CBOR out, and "fields" */
    c->bodies[7] = cbor_bundle_body(10000, "closest");
    c->bodies[8] = cbor_bundle_body(5000, "any");
    c->bodies[8].answer = KDR_MEDIA_JSON;
    c->bodies[9] = bundle_body(5000, "closest", ",\"fields\":[\"t\",\"hit\"]");
    c->bodies[9].answer = KDR_MEDIA_CBOR;
    c->bodies[10] = cbor_shadow_body(100);
    c->bodies[11] = frustum_body(40, 30, "closest", ",\"fields\":[\"prim\"]");
    /* the CBOR bodies' arrays are used where they lie in the body (which the
     * executor must keep until the answer is encoded; ASan would see it) */
    kdr_bundle_request r;
    kdr_proto_error err;
    CHECK(kdr_proto_parse_bundle_as(KDR_MEDIA_CBOR, c->bodies[7].s, c->bodies[7].len, 0,
                                    &r, &err) == 0 &&
              !r.owned[0] && !r.owned[1] &&
              r.batch.dir >= (const float *)c->bodies[7].s &&
              r.batch.dir < (const float *)(c->bodies[7].s + c->bodies[7].len),
          "CBOR directions read in place");
    kdr_bundle_request_free(&r);
    for (int m = 0; m < 2; m++)
        for (int i = 0; i < NCASES; i++)
            c->want[m][i] =
                direct_answer(s, c->kinds[i], (kdr_exec_mode)m, &c->bodies[i]);
}

static void free_cases(cases *c) {
    for (int i = 0; i < NCASES; i++) {
        free(c->bodies[i].s);
        kdr_buf_free(&c->want[0][i]);
        kdr_buf_free(&c->want[1][i]);
    }
}

static int same_answer(const kdr_exec_query *q, const kdr_buf *want) {
    const char *ct =
        q->answer_media == KDR_MEDIA_CBOR ? "application/cbor" : "application/json";
    return q->result.status == 200 && q->result.body.len == want->len &&
           !memcmp(q->result.body.data, want->data, want->len) &&
           q->result.content_type && !strcmp(q->result.content_type, ct);
}

static void count_done(void *ctx) { atomic_fetch_add((atomic_int *)ctx, 1); }

static void check_case(kdr_exec *ex, cases *c, int i, int mode, const char *what) {
    kdr_exec_query q =
        query_of(c->scene, c->kinds[i], (kdr_exec_mode)mode, &c->bodies[i]);
    atomic_int done;
    atomic_init(&done, 0);
    q.on_done = count_done;
    q.done_ctx = &done;
    run_query(ex, &q);
    for (int k = 0; k < 100000 && atomic_load(&done) == 0; k++)
        nanosleep(&(struct timespec){0, 10000}, NULL);
    CHECK(atomic_load(&done) == 1, "on_done called %d times", atomic_load(&done));
    CHECK(same_answer(&q, &c->want[mode][i]), "%s: case %d mode %d: status %d %s", what,
          i, mode, q.result.status, q.result.detail);
    CHECK(q.result.chunks == q.result.chunks_done && q.result.chunks >= 1,
          "chunks %zu/%zu", q.result.chunks_done, q.result.chunks);
    kdr_exec_query_done(&q);
}

typedef struct submitter {
    kdr_exec *ex;
    cases *c;
    int seed;
} submitter;

static void *submit_main(void *arg) {
    submitter *s = arg;
    for (int r = 0; r < 12; r++)
        check_case(s->ex, s->c, (s->seed * 5 + r * 3) % NCASES, (s->seed + r) % 2,
                   "concurrent");
    return NULL;
}

static void test_answers(cases *c) {
    for (unsigned workers = 1; workers <= 3; workers++) {
        kdr_exec_config cfg = {workers, 64, 0, NULL, NULL};
        kdr_exec *ex = kdr_exec_create(&cfg);
        for (int m = 0; m < 2; m++)
            for (int i = 0; i < NCASES; i++)
                check_case(ex, c, i, m, "serial");
        pthread_t th[4];
        submitter sub[4];
        for (int k = 0; k < 4; k++) {
            sub[k] = (submitter){ex, c, k};
            pthread_create(&th[k], NULL, submit_main, &sub[k]);
        }
        for (int k = 0; k < 4; k++)
            pthread_join(th[k], NULL);
        kdr_exec_stats st;
        kdr_exec_get_stats(ex, &st);
        CHECK(st.queued == 0 && st.running == 0 && st.busy == 0 && st.slots_used == 0,
              "idle books: %zu %zu %u %zu", st.queued, st.running, st.busy,
              st.slots_used);
        CHECK(st.completed == 2 * NCASES + 48, "completed %llu",
              (unsigned long long)st.completed);
        kdr_exec_destroy(ex);
    }
}

/* Small work is answered on the caller's thread; larger work is parsed
 * there and handed over; both give the answers of the workers. */
static void test_inline(cases *c) {
    kdr_exec_config cfg = {2, 8, 0, NULL, NULL};
    kdr_exec *ex = kdr_exec_create(&cfg);
    for (int i = 0; i < NCASES; i++) {
        kdr_exec_query q = query_of(c->scene, c->kinds[i], KDR_EXEC_FAST, &c->bodies[i]);
        atomic_int done;
        atomic_init(&done, 0);
        q.on_done = count_done;
        q.done_ctx = &done;
        int rc = kdr_exec_try_inline(ex, &q, 4096);
        int small = i == 2 || i == 6; /* 1 ray; 1 point x 2 lights x 64 samples */
        CHECK(rc == small, "case %d: try_inline %d", i, rc);
        if (rc == 0) {
            kdr_exec_enqueue(ex, &q);
            kdr_exec_wait(&q, -1);
            for (int k = 0; k < 100000 && atomic_load(&done) == 0; k++)
                nanosleep(&(struct timespec){0, 10000}, NULL);
        }
        CHECK(atomic_load(&done) == !small, "case %d: on_done %d", i, atomic_load(&done));
        CHECK(same_answer(&q, &c->want[KDR_EXEC_FAST][i]), "case %d inline: %d %s", i,
              q.result.status, q.result.detail);
        kdr_exec_query_done(&q);
    }
    body bad = {0};
    put(&bad, "{\"origins\": [0,0,0]}");
    kdr_exec_query q = query_of(c->scene, KDR_EXEC_BUNDLE, KDR_EXEC_FAST, &bad);
    CHECK(kdr_exec_try_inline(ex, &q, 4096) == 1 && q.result.status == 400,
          "a bad body is answered inline: %d", q.result.status);
    kdr_exec_query_done(&q);
    free(bad.s);
    kdr_exec_stats st;
    kdr_exec_get_stats(ex, &st);
    CHECK(st.running == 0 && st.queued == 0 && st.completed == NCASES + 1,
          "inline books");
    kdr_exec_destroy(ex);
}

/* ---- answers in pieces (kdr_exec_query.pieces) ------------------------------------ */

/* The pieces, one after another. */
static kdr_buf join_pieces(const kdr_exec_pieces *p) {
    kdr_buf b;
    kdr_buf_init(&b);
    for (size_t i = 0; i < p->n; i++)
        CHECK(kdr_buf_append(&b, p->v[i].data, p->v[i].len) == 0, "append");
    return b;
}

/* A large CBOR answer of hits comes in pieces, byte for byte the one-buffer
 * answer (misses included: the frusta see past the scene), with the
 * arrays where the core wrote them; its claim settles to the body and the
 * blocks the pieces hold. A small one, a JSON one and a cone-shadow one
 * come in one buffer. */
static void test_pieces(const kdr_scene *s) {
    enum { NP = 7 };
    body b[NP];
    kdr_exec_kind kinds[NP] = {KDR_EXEC_FRUSTUM, KDR_EXEC_FRUSTUM,    KDR_EXEC_BUNDLE,
                               KDR_EXEC_BUNDLE,  KDR_EXEC_BUNDLE,     KDR_EXEC_FRUSTUM,
                               KDR_EXEC_CONE_SHADOW};
    const int want_pieces[NP] = {1, 1, 1, 1, 0, 0, 0};
    b[0] = frustum_body(320, 240, "closest", "");
    b[0].answer = KDR_MEDIA_CBOR;
    b[1] = frustum_body(1024, 1024, "any", "");
    b[1].answer = KDR_MEDIA_CBOR;
    b[2] = bundle_body(
        30000, "closest",
        ",\"fields\":[\"mesh\",\"hit\",\"v\",\"normal\",\"t\",\"prim\",\"u\"]");
    b[2].answer = KDR_MEDIA_CBOR;
    b[3] = cbor_bundle_body(70000, "closest");
    b[4] = cbor_bundle_body(65000, "closest"); /* 1040000 B of arrays: one buffer */
    b[5] = frustum_body(320, 240, "closest", ""); /* base64: one buffer */
    b[6] = cbor_shadow_body(3000);
    kdr_exec_config cfg = {2, 8, 0, NULL, NULL};
    kdr_exec *ex = kdr_exec_create(&cfg);
    for (int i = 0; i < NP; i++) {
        kdr_exec_query one = query_of(s, kinds[i], KDR_EXEC_FAST, &b[i]);
        run_query(ex, &one);
        CHECK(one.result.status == 200 && !one.result.pieces && one.result.body.len > 0,
              "pieces case %d, one buffer: %d %s", i, one.result.status,
              one.result.detail);
        kdr_exec_claim cl = {0};
        CHECK(kdr_exec_admit(ex, &cl, kdr_exec_body_charge(b[i].len)) == KDR_ADMIT_OK,
              "admit");
        kdr_exec_query q = query_of(s, kinds[i], KDR_EXEC_FAST, &b[i]);
        q.pieces = 1;
        q.claim = &cl;
        run_query(ex, &q);
        CHECK(q.result.status == 200, "pieces case %d: %d %s", i, q.result.status,
              q.result.detail);
        CHECK(!strcmp(q.result.content_type, one.result.content_type), "content type");
        const kdr_exec_pieces *p = q.result.pieces;
        CHECK(!!p == want_pieces[i], "case %d: pieces %d", i, !!p);
        if (p) {
            kdr_buf got = join_pieces(p);
            CHECK(q.result.body.len == 0 && p->len == got.len && got.len == one.result.body.len &&
                      !memcmp(got.data, one.result.body.data, got.len),
                  "case %d: pieces differ from the one-buffer answer (%zu vs %zu bytes)", i,
                  got.len, one.result.body.len);
            kdr_buf_free(&got);
            /* the arrays go out where they are: the biggest pieces are
             * not in the head */
            size_t arrays = 0;
            for (size_t k = 0; k < p->n; k++)
                if (p->v[k].len >= 4096) {
                    arrays++;
                    CHECK((const char *)p->v[k].data < p->head.data ||
                              (const char *)p->v[k].data >= p->head.data + p->head.cap,
                          "case %d: an array in the head", i);
                }
            CHECK(arrays >= 1, "case %d: no array piece", i);
            if (i == 0) { /* pieces: head, t, head, prim, head, u, head, v */
                const int32_t *prim = p->v[3].data;
                size_t misses = 0, n = p->v[3].len / 4;
                for (size_t k = 0; k < n; k++)
                    misses += prim[k] == -1;
                CHECK(p->n == 8 && n == 320 * 240 && misses > 0 && misses < n,
                      "case 0: %zu pieces, %zu of %zu rays missed", p->n, misses, n);
            }
            CHECK(cl.bytes == b[i].len + p->held && p->held >= p->len - 200,
                  "case %d: claim %zu, pieces hold %zu for %zu bytes", i, cl.bytes,
                  p->held, p->len);
        } else {
            CHECK(q.result.body.len == one.result.body.len &&
                      !memcmp(q.result.body.data, one.result.body.data,
                              one.result.body.len),
                  "case %d: one buffer differs", i);
        }
        kdr_exec_query_done(&q);
        CHECK(!q.result.pieces, "query_done frees the pieces");
        kdr_exec_release(ex, &cl);
        kdr_exec_query_done(&one);
        free(b[i].s);
    }
    kdr_exec_stats st;
    kdr_exec_get_stats(ex, &st);
    CHECK(st.bytes_used == 0 && st.slots_used == 0, "books back to zero");
    kdr_exec_destroy(ex);
}

/* ---- admission ---------------------------------------------------------------- */

static void test_admission(void) {
    kdr_exec_config cfg = {1, 1, 1000, NULL, NULL};
    kdr_exec *ex = kdr_exec_create(&cfg);
    kdr_exec_claim a = {0}, b = {0}, c = {0};
    CHECK(kdr_exec_admit(ex, &a, 600) == KDR_ADMIT_OK && a.slot && a.bytes == 600, "a");
    CHECK(kdr_exec_admit(ex, &b, 500) == KDR_ADMIT_MEMORY_FULL && !b.slot && !b.bytes,
          "b");
    CHECK(kdr_exec_admit(ex, &b, 1001) == KDR_ADMIT_TOO_LARGE, "too large");
    CHECK(kdr_exec_admit(ex, &b, 400) == KDR_ADMIT_OK, "b fits");
    CHECK(kdr_exec_admit(ex, &c, 0) == KDR_ADMIT_QUEUE_FULL, "2 slots (1 worker + 1)");
    CHECK(kdr_exec_charge(ex, &a, 1) == KDR_ADMIT_MEMORY_FULL && a.bytes == 600,
          "charge");
    kdr_exec_stats st;
    kdr_exec_get_stats(ex, &st);
    CHECK(kdr_exec_saturated(&st), "full slots are saturation");
    CHECK(st.rejected_queue == 1 && st.rejected_memory == 2 &&
              st.rejected_too_large == 1 && st.admitted == 2 && st.bytes_used == 1000,
          "books %llu %llu %llu %zu", (unsigned long long)st.rejected_queue,
          (unsigned long long)st.rejected_memory,
          (unsigned long long)st.rejected_too_large, st.bytes_used);
    kdr_exec_settle(ex, &a, 100);
    CHECK(kdr_exec_charge(ex, &a, 400) == KDR_ADMIT_OK && a.bytes == 500,
          "charge after settle");
    kdr_exec_release(ex, &b);
    CHECK(kdr_exec_admit(ex, &c, 10) == KDR_ADMIT_OK, "slot freed by release");
    kdr_exec_release(ex, &a);
    kdr_exec_release(ex, &c);
    kdr_exec_get_stats(ex, &st);
    CHECK(st.bytes_used == 0 && st.slots_used == 0 && !kdr_exec_saturated(&st),
          "all back");
    CHECK(kdr_exec_retry_after(ex) >= 1, "retry after at least 1 s");
    kdr_exec_destroy(ex);
}

/* The answer's estimate is charged before its arrays exist. */
static void test_answer_charge(const kdr_scene *s) {
    kdr_exec_config cfg = {2, 4, 1 << 20, NULL, NULL};
    kdr_exec *ex = kdr_exec_create(&cfg);
    body big = frustum_body(1000, 1000, "closest", ""); /* ~16 MB of hits alone */
    kdr_exec_claim cl = {0};
    CHECK(kdr_exec_admit(ex, &cl, kdr_exec_body_charge(big.len)) == KDR_ADMIT_OK,
          "admit");
    kdr_exec_query q = query_of(s, KDR_EXEC_FRUSTUM, KDR_EXEC_FAST, &big);
    q.claim = &cl;
    run_query(ex, &q);
    CHECK(q.result.status == 413 && strstr(q.result.detail, "in-flight memory limit"),
          "%d %s", q.result.status, q.result.detail);
    CHECK(cl.bytes == big.len && !cl.slot, "settled to the body, slot returned: %zu",
          cl.bytes);
    kdr_exec_query_done(&q);
    kdr_exec_release(ex, &cl);
    /* fits alone, but not next to a hog: 503 with a retry hint */
    body mid = frustum_body(100, 100, "closest", "");
    kdr_exec_claim hog = {0};
    CHECK(kdr_exec_admit(ex, &hog, (1 << 20) - 300000) == KDR_ADMIT_OK, "hog");
    CHECK(kdr_exec_admit(ex, &cl, mid.len) == KDR_ADMIT_OK, "mid");
    q = query_of(s, KDR_EXEC_FRUSTUM, KDR_EXEC_FAST, &mid);
    q.claim = &cl;
    run_query(ex, &q);
    CHECK(q.result.status == 503 && q.result.retry_after >= 1 &&
              strstr(q.result.detail, "memory"),
          "%d %s", q.result.status, q.result.detail);
    kdr_exec_query_done(&q);
    kdr_exec_release(ex, &cl);
    kdr_exec_release(ex, &hog);
    /* a parse error: 400, claim settled to the body */
    body bad = {0};
    put(&bad, "{\"camera\": 5}");
    CHECK(kdr_exec_admit(ex, &cl, kdr_exec_body_charge(bad.len)) == KDR_ADMIT_OK, "bad");
    q = query_of(s, KDR_EXEC_FRUSTUM, KDR_EXEC_FAST, &bad);
    q.claim = &cl;
    run_query(ex, &q);
    CHECK(q.result.status == 400 &&
              !strcmp(q.result.detail, "camera: expected an object") &&
              cl.bytes == bad.len && q.result.body.len == 0,
          "%d %s", q.result.status, q.result.detail);
    kdr_exec_query_done(&q);
    kdr_exec_release(ex, &cl);
    kdr_exec_stats st;
    kdr_exec_get_stats(ex, &st);
    CHECK(st.bytes_used == 0 && st.slots_used == 0, "books back to zero");
    free(big.s), free(mid.s), free(bad.s);
    kdr_exec_destroy(ex);
}

/* Admission charges what is allocated, not the lengths (issue 16, svc9): a
 * body read into a kdr_block_alloc block is held at its whole 2 MiB pages
 * (kdr_exec_query.body_held), and an answer at the block the encoder
 * reserves for its bound (kdr_block_size of it). A budget one byte short of
 * that refuses the answer (the exact lengths fit it: the old charge ran
 * it); the exact budget runs it, and the claim settles to the held body
 * plus the answer's capacity. */
static void test_block_charge(const kdr_scene *s) {
    const size_t n = 200000; /* 2.4 MB of directions, a 3.2 MB answer */
    body b = cbor_bundle_body(n, "closest");
    size_t held = 0;
    char *blk = kdr_block_alloc(b.len, &held);
    CHECK(blk && held > b.len && held == kdr_block_size(b.len),
          "a body of %zu bytes in a block of %zu", b.len, held);
    memcpy(blk, b.s, b.len);
    const size_t bound =
        kdr_proto_hits_answer_max(n, KDR_CLOSEST, KDR_FIELDS_CLOSEST, KDR_ENCODING_CBOR);
    CHECK(kdr_block_size(bound) > bound, "the answer's bound %zu is a block", bound);
    /* after the parse (typed arrays read in place, a few floats of
     * defaults allocated: within SLACK): body, hit arrays, answer block */
    const size_t need = held + n * 16 + kdr_block_size(bound), SLACK = 64;
    for (int fits = 0; fits < 2; fits++) {
        kdr_exec_config cfg = {1, 4, fits ? need + SLACK : need - 1, NULL, NULL};
        kdr_exec *ex = kdr_exec_create(&cfg);
        kdr_exec_claim cl = {0};
        CHECK(kdr_exec_admit(ex, &cl, kdr_exec_body_charge(b.len) + (held - b.len)) ==
                  KDR_ADMIT_OK,
              "admit");
        kdr_exec_query q = query_of(s, KDR_EXEC_BUNDLE, KDR_EXEC_FAST, &b);
        q.body = blk;
        q.body_held = held;
        q.claim = &cl;
        run_query(ex, &q);
        if (fits)
            CHECK(q.result.status == 200 && cl.bytes == held + q.result.body.cap &&
                      q.result.body.cap >= q.result.body.len,
                  "budget that fits: %d %s, settled to %zu (held %zu + answer %zu)",
                  q.result.status, q.result.detail, cl.bytes, held, q.result.body.cap);
        else
            CHECK(q.result.status == 413 && strstr(q.result.detail, "answer:") &&
                      cl.bytes == held,
                  "a byte short: %d %s, settled to %zu", q.result.status,
                  q.result.detail, cl.bytes);
        kdr_exec_stats st;
        kdr_exec_get_stats(ex, &st);
        CHECK(st.bytes_used == cl.bytes, "books %zu", st.bytes_used);
        kdr_exec_query_done(&q);
        kdr_exec_release(ex, &cl);
        kdr_exec_destroy(ex);
    }
    free(blk);
    free(b.s);
}

/* A body that goes to cJSON (an unknown member of single digits: ~40
 * bytes of nodes per body byte) is charged as its parse allocates: 413 past
 * the whole budget, 503 when others hold the room, 200 when it fits; its
 * claim ends settled to the body and the answer either way. */
static void test_parse_charge(const kdr_scene *s) {
    body odd = {0};
    put(&odd, "{\"origins\":[0,2,0],\"directions\":[0,-1,0],\"x\":[0");
    while (odd.len < 100000)
        put(&odd, ",0");
    put(&odd, "]}");
    const size_t need = 40 * odd.len; /* about: cJSON's nodes */
    struct {
        size_t budget, hog;
        int status;
        const char *says;
    } runs[] = {
        {need / 2, 0, 413, "parsing it takes more than the in-flight memory limit"},
        {2 * need, need + need / 2, 503, "memory: no room to parse the body now"},
        {2 * need, 0, 200, NULL},
    };
    for (int i = 0; i < 3; i++) {
        kdr_exec_config cfg = {1, 4, runs[i].budget, NULL, NULL};
        kdr_exec *ex = kdr_exec_create(&cfg);
        kdr_exec_claim hog = {0}, cl = {0};
        if (runs[i].hog)
            CHECK(kdr_exec_admit(ex, &hog, runs[i].hog) == KDR_ADMIT_OK, "hog");
        CHECK(kdr_exec_admit(ex, &cl, kdr_exec_body_charge(odd.len)) == KDR_ADMIT_OK,
              "admit");
        kdr_exec_query q = query_of(s, KDR_EXEC_BUNDLE, KDR_EXEC_FAST, &odd);
        q.claim = &cl;
        run_query(ex, &q);
        CHECK(q.result.status == runs[i].status &&
                  (!runs[i].says || strstr(q.result.detail, runs[i].says)),
              "run %d: %d %s", i, q.result.status, q.result.detail);
        CHECK(runs[i].status != 503 || q.result.retry_after >= 1, "retry hint");
        CHECK(cl.bytes == odd.len + q.result.body.len, "run %d: settled to %zu", i,
              cl.bytes);
        kdr_exec_stats st;
        kdr_exec_get_stats(ex, &st);
        CHECK(st.bytes_used == cl.bytes + hog.bytes, "run %d: books", i);
        kdr_exec_query_done(&q);
        kdr_exec_release(ex, &cl);
        kdr_exec_release(ex, &hog);
        kdr_exec_destroy(ex);
    }
    free(odd.s);
}

/* ---- stopping ------------------------------------------------------------------ */

static void wait_running(kdr_exec *ex, unsigned busy) {
    kdr_exec_stats st;
    for (int i = 0; i < 20000; i++) {
        kdr_exec_get_stats(ex, &st);
        if (st.busy >= busy) return;
        nanosleep(&(struct timespec){0, 100000}, NULL);
    }
    CHECK(0, "never %u busy workers", busy);
}

static void test_stops(const kdr_scene *s) {
    atomic_int started;
    atomic_init(&started, 0);
    kdr_exec_config cfg = {1, 8, 0, count_done, &started};
    kdr_exec *ex = kdr_exec_create(&cfg);
    for (int k = 0; k < 100000 && atomic_load(&started) == 0; k++)
        nanosleep(&(struct timespec){0, 10000}, NULL);
    CHECK(atomic_load(&started) == 1, "on_worker_start ran once per worker: %d",
          atomic_load(&started));
    /* about 0.4 s of work on this machine (2040 of 3907 chunks in 200 ms
     * at load 4): 2000x2000 per-pixel rays */
    body longb = frustum_body(2000, 2000, "closest", "");
    /* 100 ms, not less: the deadline runs from submission, and on a loaded
     * machine a shorter one ran out before the worker had cut the query
     * into chunks (0 of 0 traced), which is not the stop between chunks
     * this case is about */
    body shortdl = frustum_body(2000, 2000, "closest", ",\"deadline_ms\":100");

    /* Under a load spike (load 7 in one run) the worker may still not have
     * cut the query into chunks when the 100 ms run out: that answer is a
     * right one too (503, deadline, 0 of 0 chunks) but not the case this is
     * about, so such a try is repeated, up to 5 times; every try must stop
     * by its deadline, and one must have stopped between chunks. */
    kdr_exec_query q;
    int between = 0;
    for (int attempt = 0; attempt < 5 && !between; attempt++) {
        q = query_of(s, KDR_EXEC_FRUSTUM, KDR_EXEC_REFERENCE, &shortdl);
        run_query(ex, &q);
        CHECK(q.result.status == 503 && q.result.stopped == KDR_STOP_DEADLINE &&
                  strstr(q.result.detail, "deadline: 100 ms exceeded") &&
                  q.result.retry_after == 0,
              "request deadline: %d %s", q.result.status, q.result.detail);
        if (q.result.chunks > 0) {
            CHECK(q.result.chunks_done < q.result.chunks,
                  "request deadline stops between chunks: %s", q.result.detail);
            between = 1;
        }
        kdr_exec_query_done(&q);
    }
    CHECK(between, "request deadline: no try got as far as its chunks in 5");

    q = query_of(s, KDR_EXEC_FRUSTUM, KDR_EXEC_REFERENCE, &longb);
    q.deadline_ms = 20; /* the operator's */
    run_query(ex, &q);
    CHECK(q.result.stopped == KDR_STOP_DEADLINE && strstr(q.result.detail, "20 ms"),
          "caller deadline: %s", q.result.detail);
    kdr_exec_query_done(&q);

    /* cancel a running query, and a queued one behind it */
    kdr_exec_query a = query_of(s, KDR_EXEC_FRUSTUM, KDR_EXEC_REFERENCE, &longb);
    kdr_exec_query b = query_of(s, KDR_EXEC_FRUSTUM, KDR_EXEC_REFERENCE, &longb);
    CHECK(kdr_exec_submit(ex, &a) == 0 && kdr_exec_submit(ex, &b) == 0, "submit");
    wait_running(ex, 1);
    CHECK(kdr_exec_wait(&a, 0.01) == 0, "a long query is not done in 10 ms");
    kdr_exec_cancel(&b);
    CHECK(kdr_exec_wait(&b, 0) == 1 && b.result.stopped == KDR_STOP_CANCELLED &&
              b.result.chunks_done == 0 && b.result.status == 499,
          "queued cancel: %d %s", b.result.status, b.result.detail);
    double t0 = kdr_exec_now();
    kdr_exec_cancel(&a);
    kdr_exec_wait(&a, -1);
    CHECK(a.result.stopped == KDR_STOP_CANCELLED &&
              a.result.chunks_done < a.result.chunks,
          "running cancel: %zu of %zu", a.result.chunks_done, a.result.chunks);
    CHECK(kdr_exec_now() - t0 < 2.0, "a cancel stops within a chunk");
    kdr_exec_query_done(&a);
    kdr_exec_query_done(&b);

    /* a queued query whose caller deadline passes is answered by its waiter */
    a = query_of(s, KDR_EXEC_FRUSTUM, KDR_EXEC_REFERENCE, &longb);
    b = query_of(s, KDR_EXEC_FRUSTUM, KDR_EXEC_REFERENCE, &longb);
    b.deadline_ms = 50;
    kdr_exec_submit(ex, &a);
    wait_running(ex, 1);
    kdr_exec_submit(ex, &b);
    while (!kdr_exec_wait(&b, 0.01)) {
    }
    CHECK(b.result.stopped == KDR_STOP_DEADLINE && b.result.chunks_done == 0 &&
              kdr_exec_wait(&a, 0) == 0,
          "queued deadline: %s", b.result.detail);

    /* shutdown stops the running one; admissions are refused */
    kdr_exec_shutdown(ex);
    kdr_exec_wait(&a, -1);
    CHECK(a.result.status == 503 && a.result.stopped == KDR_STOP_SHUTDOWN &&
              strstr(a.result.detail, "shutting down"),
          "shutdown: %d %s", a.result.status, a.result.detail);
    kdr_exec_claim cl = {0};
    CHECK(kdr_exec_admit(ex, &cl, 1) == KDR_ADMIT_STOPPED, "no admission after shutdown");
    kdr_exec_stats st;
    kdr_exec_get_stats(ex, &st);
    CHECK(st.deadlines == 3 && st.cancelled == 2 && st.shutdown == 1,
          "stop counters %llu %llu %llu", (unsigned long long)st.deadlines,
          (unsigned long long)st.cancelled, (unsigned long long)st.shutdown);
    kdr_exec_query_done(&a);
    kdr_exec_query_done(&b);
    free(longb.s), free(shortdl.s);
    kdr_exec_destroy(ex);
}

int main(void) {
    kdr_scene *s = make_scene();
    if (!s) return 1;
    cases c;
    make_cases(&c, s);
    test_answers(&c);
    test_inline(&c);
    test_pieces(s);
    test_admission();
    test_answer_charge(s);
    test_parse_charge(s);
    test_block_charge(s);
    test_stops(s);
    free_cases(&c);
    kdr_scene_free(s);
    printf("%s\n", failures ? "FAILED" : "ok");
    return failures != 0;
}
