/*
 * server.h — what the HTTP layer and the route handlers share: the scene
 * registry, the query executor, the limits from the command line, the
 * access log and the shutdown flag. Built by main.c; read-only afterwards
 * except `stopping`.
 */
#ifndef KDR_SRV_SERVER_H
#define KDR_SRV_SERVER_H

#include <stdatomic.h>
#include <stddef.h>
#include <stdint.h>

#include "access_log.h"
#include "kdr_exec.h"
#include "metrics.h"
#include "registry.h"

typedef struct kdr_server {
    kdr_registry *registry;
    kdr_exec *exec;
    size_t max_body;          /* bytes */
    size_t max_rays;          /* rays (or pixels, or shadow rays) per request */
    size_t max_inflight;      /* bytes, the executor's budget */
    unsigned threads;         /* executor workers */
    unsigned http_threads;    /* libmicrohttpd's thread pool */
    unsigned max_connections; /* HTTP connections at once */
    unsigned connection_timeout_s; /* --connection-timeout-s */
    double deadline_ms;       /* --deadline-ms, 0 = none */
    int worker_nice;          /* --worker-nice */
    kdr_access_log access_log;
    atomic_int stopping;
} kdr_server;

/* An HTTP request as the routes see it: the body is complete and not
 * NUL-terminated. */
typedef struct kdr_request {
    const char *method;
    const char *path;
    const char *content_type; /* NULL if absent */
    const char *accept;       /* NULL if absent */
    const char *body;
    size_t len;
    size_t held;           /* bytes body's buffer holds (>= len; 0: len) */
    double start;          /* kdr_now() when its headers arrived */
    kdr_exec_claim *claim; /* query endpoints: the admitted claim */
    const kdr_render_params *render; /* render.png: its parsed parameters */
} kdr_request;

/* An answer: body is malloc'd (or NULL when len is 0) and owned by whoever
 * holds the response; content_type and allow are static strings. */
typedef struct kdr_response {
    unsigned status;
    const char *content_type;
    const char *allow;    /* for 405 */
    unsigned retry_after; /* seconds, sent as Retry-After when > 0 */
    char *body;
    size_t len;
    /* or a query's answer in pieces (exec/: its arrays where the core wrote
     * them), len bytes in all, sent with writev; body is NULL then */
    struct kdr_exec_pieces *pieces;
    kdr_endpoint ep;
    uint64_t rays; /* traced for this answer, for the access log */
    int no_answer; /* the client left: close without answering */
    /* Server-Timing (a query's stages, or render.png's) and X-Kdray-Render
     * header values ("" none) */
    char server_timing[192];
    char render_stats[256];
} kdr_response;

/* Routing before the body is read: decides 404/405/415/503 and 413 from
 * Content-Length (content_length < 0: unknown). Returns 1 with *out filled
 * if the request is already answered, else 0 with out->ep set. */
int kdr_route_precheck(kdr_server *srv, const kdr_request *req, long long content_length,
                       kdr_response *out);
/* 1 for the endpoints whose body is a query (admitted by the executor). */
int kdr_route_is_query(kdr_endpoint ep);
/* Answers a request whose body has fully arrived. */
void kdr_route_handle(kdr_server *srv, const kdr_request *req, kdr_response *out);
/* A problem+json answer (RFC 7807). */
void kdr_route_problem(kdr_response *out, unsigned status, const char *detail);
/* The answer to a refused admission: 503 with Retry-After, or 413 for a
 * request larger than the whole in-flight budget. */
void kdr_route_refusal(kdr_server *srv, kdr_admit why, size_t bytes, kdr_response *out);
/* A 200 answer carrying b (content type ct), or a 503 when encoding it ran
 * out of memory (rc != 0; b is freed then). */
struct kdr_buf;
void kdr_route_answer_buf(kdr_response *out, int rc, struct kdr_buf *b, const char *ct);

/* The page at / (page.c: HTML embedded at build time). */
void kdr_page_answer(kdr_response *out);

/* The scene index of a query endpoint's path (the precheck found it), or -1. */
long kdr_route_scene(kdr_server *srv, const char *path);

/* A bundle / cone-shadow / frustum request on its way through the executor
 * (query.c). The HTTP thread starts it and goes back to serving other
 * connections; a worker calls on_done when the answer is ready; the HTTP
 * thread then finishes it. Between the two, a watcher calls
 * kdr_query_watch every few milliseconds. */
typedef struct kdr_query_call {
    kdr_exec_query q;
    kdr_scene_version *scene; /* held until finished: a reload swaps, never frees it */
    kdr_endpoint ep;
    const char *path;
    kdr_render_params render; /* render.png's parameters, as parsed */
    double submitted;         /* kdr_now() when the whole body was handed over */
} kdr_query_call;

/* 0: started (on_done(ctx) will be called exactly once); -1: nothing
 * started, *out holds the answer. req's body must live until finished. */
int kdr_query_start(kdr_server *srv, kdr_query_call *call, size_t scene, kdr_endpoint ep,
                    const kdr_request *req, void (*on_done)(void *), void *ctx,
                    kdr_response *out);
/* As kdr_query_start, for an answer streamed item by item (Accept:
 * application/cbor-seq; stream.c): on_progress(ctx) after the parse and
 * after every chunk, on_done(ctx) once. */
int kdr_query_start_stream(kdr_server *srv, kdr_query_call *call, size_t scene,
                           kdr_endpoint ep, const kdr_request *req,
                           void (*on_progress)(void *), void (*on_done)(void *), void *ctx,
                           kdr_response *out);
/* The short way for a small body, on the HTTP thread: parses it and, if
 * its work should take under 0.2 ms there (the scene's measured cost per
 * ray for this kind of query; 256 rays until one is known), or it is an
 * error, answers it right away: 1 with *out filled. 0: parsed, waiting for
 * kdr_query_enqueue (on_done follows as for kdr_query_start). -1: nothing
 * started, *out holds the answer. */
int kdr_query_try_inline(kdr_server *srv, kdr_query_call *call, size_t scene,
                         kdr_endpoint ep, const kdr_request *req, void (*on_done)(void *),
                         void *ctx, kdr_response *out);
void kdr_query_enqueue(kdr_server *srv, kdr_query_call *call);
/* Cancels the query if its client has gone, and lets the executor stop a
 * query past its deadline that no worker is looking at. Any thread. */
void kdr_query_watch(kdr_query_call *call, int client_gone);
/* After on_done: the answer in *out (out->no_answer when the client left);
 * releases everything the call held. */
void kdr_query_finish(kdr_query_call *call, kdr_response *out);

/* HTTP daemon (http_daemon.c; requests in http.c, http_body.c, http_query.c). */
typedef struct kdr_http kdr_http;
/* addr is "HOST:PORT" (IPv4 literal, "localhost", or "[IPv6]:PORT"); port 0
 * picks a free port. NULL after logging the reason. */
kdr_http *kdr_http_start(kdr_server *srv, const char *addr);
/* 1 if addr is a listen address kdr_http_start accepts. */
int kdr_http_addr_ok(const char *addr);
unsigned kdr_http_port(const kdr_http *h);
/* Stops accepting at once (new connections are refused). */
void kdr_http_quiesce(kdr_http *h);
/* Waits up to grace_s for requests in flight, stops the queries still
 * running after that (503), then stops the daemon. */
void kdr_http_stop(kdr_http *h, double grace_s);

#endif
