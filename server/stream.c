/*
 * stream.c — streamed answers (see stream.h and docs/API.md, "Streamed
 * answers"): the content reader that libmicrohttpd calls for the next bytes
 * of a chunked answer, and the sleep/wake handshake with the executor.
 *
 * The reader hands out, in order, the head item, each chunk item once the
 * executor has traced every chunk it covers (exec/kdr_exec_stream.c) and,
 * once the query is done, the final item: {"status": 200, ...} or the
 * problem that stopped it (deadline, shutdown, out of memory). Nothing
 * ready yet: it suspends the connection and returns 0, as libmicrohttpd
 * allows from a content reader, and the next on_progress or on_done of the
 * executor resumes it. The HTTP thread never waits for a worker.
 *
 * Sleep and wake race: a worker may finish a chunk between the reader's
 * look and its suspend. So the reader clears `pending` before it looks,
 * and suspends only if no wake came meanwhile (under the mutex); a wake
 * resumes the connection if it sleeps, else sets `pending`. Every resume
 * thus follows a suspend, as libmicrohttpd requires, and no wake is lost.
 * While the connection sleeps its socket is not read by libmicrohttpd, so
 * the query stays on the watcher's list until the final item (http_query.c): a
 * client that hangs up mid-stream cancels the query as before.
 */
#define _POSIX_C_SOURCE 200809L
#include "stream.h"

#include <pthread.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "log.h"

/* Bytes libmicrohttpd may ask for per call; it asks for less, since its
 * buffer comes out of the connection's memory pool (32 KiB, http_daemon.c). */
static const size_t BLOCK = 64 * 1024;

struct kdr_stream {
    struct MHD_Connection *conn;
    kdr_query_call *call;
    void (*on_end)(void *ctx, unsigned status);
    void *end_ctx;
    pthread_mutex_t m;
    int suspended; /* the connection sleeps (under m) */
    int pending;   /* a wake came while it did not (under m) */
    int done;      /* the executor's on_done was called (under m) */
    /* the reader's own (one connection: one thread at a time) */
    kdr_buf item; /* the item being sent */
    size_t off;   /* bytes of it already handed out */
    int head_sent, ended;
    size_t next, items;
    size_t sent;
};

kdr_stream *kdr_stream_new(struct MHD_Connection *c, kdr_query_call *call,
                           void (*on_end)(void *ctx, unsigned status), void *ctx) {
    kdr_stream *st = calloc(1, sizeof *st);
    if (!st) return NULL;
    if (pthread_mutex_init(&st->m, NULL) != 0) {
        free(st);
        return NULL;
    }
    st->conn = c;
    st->call = call;
    st->on_end = on_end;
    st->end_ctx = ctx;
    kdr_buf_init(&st->item);
    return st;
}

void kdr_stream_free(kdr_stream *st) {
    if (!st) return;
    /* a worker's wake may still hold the mutex: let it leave first */
    pthread_mutex_lock(&st->m);
    pthread_mutex_unlock(&st->m);
    kdr_buf_free(&st->item);
    pthread_mutex_destroy(&st->m);
    free(st);
}

/* The executor's on_done may still be running in a worker when the query
 * already reads as finished; the query (and this stream) are let go only
 * once it has passed here: `done`, set under the mutex it holds. */
static void wake(kdr_stream *st, int done) {
    pthread_mutex_lock(&st->m);
    if (done) st->done = 1;
    if (st->suspended) {
        st->suspended = 0;
        MHD_resume_connection(st->conn);
    } else {
        st->pending = 1;
    }
    pthread_mutex_unlock(&st->m);
}

void kdr_stream_progress(void *st) { wake(st, 0); }

void kdr_stream_done(void *st) { wake(st, 1); }

/* 1 once on_done has come (the query is finished and may be freed). */
static int finished(kdr_stream *st) {
    kdr_exec_wait(&st->call->q, 0); /* stops an idle query past its deadline */
    pthread_mutex_lock(&st->m);
    const int done = st->done;
    pthread_mutex_unlock(&st->m);
    return done;
}

void kdr_stream_wait_done(kdr_stream *st) {
    const struct timespec tick = {0, 100000};
    for (;;) {
        pthread_mutex_lock(&st->m);
        const int done = st->done;
        pthread_mutex_unlock(&st->m);
        if (done) return;
        nanosleep(&tick, NULL);
    }
}

void kdr_stream_sleep(kdr_stream *st) {
    pthread_mutex_lock(&st->m);
    st->suspended = 1;
    MHD_suspend_connection(st->conn);
    pthread_mutex_unlock(&st->m);
}

static void clear_pending(kdr_stream *st) {
    pthread_mutex_lock(&st->m);
    st->pending = 0;
    pthread_mutex_unlock(&st->m);
}

/* Suspends unless a wake came since clear_pending: 1 asleep, 0 look again. */
static int sleep_unless_woken(kdr_stream *st) {
    pthread_mutex_lock(&st->m);
    const int woken = st->pending;
    if (!woken) {
        st->suspended = 1;
        MHD_suspend_connection(st->conn);
    }
    pthread_mutex_unlock(&st->m);
    return !woken;
}

int kdr_stream_poll(kdr_stream *st) {
    kdr_exec_query *q = &st->call->q;
    for (;;) {
        clear_pending(st);
        if (kdr_exec_stream_ready(q)) return 1;
        /* not ready: done (a problem) or still parsing; kdr_exec_wait with
         * no time also finishes a query past its deadline that no worker
         * holds (its on_done wakes us: pending) */
        if (finished(st)) return kdr_exec_stream_ready(q) ? 1 : 0;
        if (sleep_unless_woken(st)) return -1;
    }
}

/* The next item into st->item: 1 one is there, 0 nothing yet (the
 * connection sleeps), -1 out of memory. */
static int next_item(kdr_stream *st) {
    kdr_exec_query *q = &st->call->q;
    st->item.len = 0;
    st->off = 0;
    for (;;) {
        clear_pending(st);
        if (!st->head_sent) {
            st->items = kdr_exec_stream_items(q);
            st->head_sent = 1;
            return kdr_exec_stream_head(q, &st->item) == 0 ? 1 : -1;
        }
        if (st->next < st->items && kdr_exec_stream_item_ready(q, st->next))
            return kdr_exec_stream_item(q, st->next++, &st->item) == 0 ? 1 : -1;
        if (finished(st)) {
            /* a 200 has traced every chunk: its items are all ready above */
            if (q->result.status == 200 && st->next < st->items) continue;
            const int rc = kdr_exec_stream_end(q, st->next, &st->item);
            st->ended = 1;
            const unsigned status = (unsigned)q->result.status;
            if (status != 200)
                kdr_log_debug("%s: stream stopped after %zu of %zu items: %u %s",
                              st->call->path, st->next, st->items, status,
                              q->result.detail);
            st->on_end(st->end_ctx, status); /* q is finished and freed there */
            return rc == 0 ? 1 : -1;
        }
        if (sleep_unless_woken(st)) return 0;
    }
}

static ssize_t reader(void *cls, uint64_t pos, char *buf, size_t max) {
    kdr_stream *st = cls;
    (void)pos;
    while (st->off >= st->item.len) {
        if (st->ended) return MHD_CONTENT_READER_END_OF_STREAM;
        const int got = next_item(st);
        if (got == 0) return 0; /* asleep until the next wake */
        if (got < 0) {
            /* the client sees a cut chunked body: a failed answer */
            kdr_log_warn("%s: out of memory while streaming the answer; closing",
                         st->call->path);
            return MHD_CONTENT_READER_END_WITH_ERROR;
        }
    }
    size_t n = st->item.len - st->off;
    if (n > max) n = max;
    memcpy(buf, st->item.data + st->off, n);
    st->off += n;
    st->sent += n;
    return (ssize_t)n;
}

struct MHD_Response *kdr_stream_response(kdr_stream *st) {
    struct MHD_Response *r =
        MHD_create_response_from_callback(MHD_SIZE_UNKNOWN, BLOCK, reader, st, NULL);
    if (r)
        MHD_add_response_header(r, MHD_HTTP_HEADER_CONTENT_TYPE,
                                kdr_proto_media_name(KDR_MEDIA_CBOR_SEQ));
    return r;
}

size_t kdr_stream_sent(const kdr_stream *st) { return st->sent; }
