/*
 * stream.h — a query's answer streamed as application/cbor-seq over
 * chunked transfer encoding (stream.c): libmicrohttpd pulls the items
 * through a content reader while later chunks still trace, and the
 * connection sleeps (suspended) whenever the next item is not traced yet.
 */
#ifndef KDR_SRV_STREAM_H
#define KDR_SRV_STREAM_H

#include <microhttpd.h>

#include "server.h"

typedef struct kdr_stream kdr_stream;

/* The stream of call's query on connection c; on_end(ctx, status) is called
 * once the final item is encoded (status: 200 or the problem's), from the
 * thread that encoded it, before the item is sent. NULL when out of memory. */
kdr_stream *kdr_stream_new(struct MHD_Connection *c, kdr_query_call *call,
                           void (*on_end)(void *ctx, unsigned status), void *ctx);
/* The executor's on_progress and on_done (ctx: the stream): resume the
 * connection if it sleeps, else remember that something happened. */
void kdr_stream_progress(void *st);
void kdr_stream_done(void *st);
/* Suspends c until the next wake; from the access handler (c is not
 * suspended and the query not started yet). */
void kdr_stream_sleep(kdr_stream *st);
/* From the access handler after a wake: 1 when the answer streams (queue
 * kdr_stream_response with status 200), 0 when the query finished without
 * streaming (an ordinary problem answer: kdr_query_finish), -1 when
 * nothing is decided yet (the connection sleeps again). */
int kdr_stream_poll(kdr_stream *st);
/* The chunked response (status 200, application/cbor-seq); NULL on ENOMEM. */
struct MHD_Response *kdr_stream_response(kdr_stream *st);
/* Bytes handed to libmicrohttpd so far. */
size_t kdr_stream_sent(const kdr_stream *st);
/* Waits until the executor's on_done has been called (after kdr_exec_wait
 * returned 1 it is microseconds away): the stream may then be freed. */
void kdr_stream_wait_done(kdr_stream *st);
/* After the request completed (the reader is never called again). */
void kdr_stream_free(kdr_stream *st);

#endif
