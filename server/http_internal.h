/*
 * http_internal.h — what the HTTP layer's files share (http.c, http_body.c,
 * http_query.c, http_daemon.c): the daemon handle and one request's state.
 *
 * Threads: a small pool of HTTP threads (--http-threads) reads requests and
 * writes answers; they never trace. A query's connection is suspended while
 * the executor runs it and resumed by the worker that finishes it, so the
 * HTTP threads stay free: health, ready and metrics are answered at once,
 * whatever the queries are doing. (One thread per connection was tried
 * first: on the shared 2-core box its thread start per new connection put a
 * probe's p99 at 8-18 ms against 2-3 ms for the pool.) While a connection
 * is suspended MHD does not look at its socket, so the watcher (watch.c)
 * does: a client that hung up cancels its query, and a queued query past
 * its deadline is answered even when every worker is busy.
 */
#ifndef KDR_SRV_HTTP_INTERNAL_H
#define KDR_SRV_HTTP_INTERNAL_H

#include <arpa/inet.h>
#include <microhttpd.h>
#include <stddef.h>
#include <stdint.h>

#include "server.h"
#include "stream.h"
#include "watch.h"

/* Bytes of the path kept for the access log. */
enum { LOG_PATH_MAX = 512, LOG_METHOD_MAX = 16 };

typedef struct req_state req_state;

struct kdr_http {
    struct MHD_Daemon *d;
    kdr_server *srv;
    unsigned port;
    MHD_socket quiesced;  /* the listen socket after MHD_quiesce_daemon */
    kdr_watcher *watcher; /* looks after suspended queries (watch.c) */
};

struct req_state {
    kdr_http *h;
    double start;
    kdr_endpoint ep;
    int refused;          /* answered before the body: the body is discarded */
    kdr_response refusal; /* that answer, until the body has been read */
    char *body;
    size_t len, cap;
    size_t dropped; /* bytes past the limit or of a refused body, discarded */
    int queued;     /* an answer was handed to MHD */
    kdr_exec_claim claim;
    struct MHD_Connection *conn;
    int fd; /* the client's socket, for the watcher */
    /* a query with the executor */
    int started, start_failed;
    kdr_query_call call;
    kdr_response early;       /* the answer when kdr_query_start refused */
    kdr_render_params render; /* render.png: the query string, parsed */
    char render_err[256];     /* the first bad parameter, "" if none */
    kdr_watch_entry watch;
    kdr_stream *stream; /* Accept: application/cbor-seq (stream.c) */
    /* for the access log */
    unsigned status;
    uint64_t rays;
    size_t bytes_out;
    char client[INET6_ADDRSTRLEN];
    char method[LOG_METHOD_MAX];
    char path[LOG_PATH_MAX];
};

/* http.c: queues an answer (r's body passes to MHD) and books it. */
enum MHD_Result kdr_http_queue(kdr_http *h, struct MHD_Connection *c, req_state *rs,
                               kdr_response *r);
/* http.c: libmicrohttpd's request and completion callbacks. */
enum MHD_Result kdr_http_on_request(void *cls, struct MHD_Connection *c, const char *url,
                                    const char *method, const char *version,
                                    const char *upload, size_t *upload_size,
                                    void **req_cls);
void kdr_http_on_completed(void *cls, struct MHD_Connection *c, void **req_cls,
                           enum MHD_RequestTerminationCode toe);

/* http_body.c */
long long kdr_http_content_length(struct MHD_Connection *c); /* -1: none or bad */
int kdr_http_answer_now(struct MHD_Connection *c, long long clen, size_t max_body);
int kdr_http_admit(kdr_http *h, req_state *rs, long long clen, const char *path);
int kdr_http_append(kdr_http *h, req_state *rs, const char *data, size_t n);

/* http_query.c */
enum MHD_Result kdr_http_start_query(kdr_http *h, struct MHD_Connection *c, req_state *rs,
                                     const kdr_request *req);
enum MHD_Result kdr_http_finish_query(kdr_http *h, struct MHD_Connection *c,
                                      req_state *rs);
enum MHD_Result kdr_http_stream_step(kdr_http *h, struct MHD_Connection *c,
                                     req_state *rs);
void kdr_http_watch_remove(kdr_http *h, req_state *rs);

#endif
