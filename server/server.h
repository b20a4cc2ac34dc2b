/*
 * server.h — what the HTTP layer and the route handlers share: the scene
 * registry, the job pool, the limits from the command line and the
 * shutdown flag. Built by main.c; read-only afterwards except `stopping`.
 */
#ifndef KDR_SRV_SERVER_H
#define KDR_SRV_SERVER_H

#include <stdatomic.h>
#include <stddef.h>

#include "metrics.h"
#include "pool.h"
#include "registry.h"

typedef struct kdr_server {
    kdr_registry *registry;
    kdr_pool *pool;
    size_t max_body;  /* bytes */
    size_t max_rays;  /* rays (or pixels, or shadow rays) per request */
    unsigned threads; /* HTTP threads = workers + 1 */
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
} kdr_request;

/* An answer: body is malloc'd (or NULL when len is 0) and owned by whoever
 * holds the response; content_type and allow are static strings. */
typedef struct kdr_response {
    unsigned status;
    const char *content_type;
    const char *allow; /* for 405 */
    char *body;
    size_t len;
    kdr_endpoint ep;
} kdr_response;

/* Routing before the body is read: decides 404/405/415/503 and 413 from
 * Content-Length (content_length < 0: unknown). Returns 1 with *out filled
 * if the request is already answered, else 0 with out->ep set. */
int kdr_route_precheck(kdr_server *srv, const kdr_request *req, long long content_length,
                       kdr_response *out);
/* Answers a request whose body has fully arrived. */
void kdr_route_handle(kdr_server *srv, const kdr_request *req, kdr_response *out);
/* A problem+json answer (RFC 7807). */
void kdr_route_problem(kdr_response *out, unsigned status, const char *detail);
/* A 200 answer carrying b (content type ct), or a 500 when encoding it
 * failed (rc != 0; b is freed then). */
struct kdr_buf;
void kdr_route_answer_buf(kdr_response *out, int rc, struct kdr_buf *b, const char *ct);

/* Answers a bundle / cone-shadow / frustum request on scene (query.c). */
void kdr_query_answer(kdr_server *srv, const kdr_served_scene *scene, kdr_endpoint ep,
                      const kdr_request *req, kdr_response *out);

/* HTTP daemon (http.c). */
typedef struct kdr_http kdr_http;
/* addr is "HOST:PORT" (IPv4 literal, "localhost", or "[IPv6]:PORT"); port 0
 * picks a free port. NULL after logging the reason. */
kdr_http *kdr_http_start(kdr_server *srv, const char *addr);
/* 1 if addr is a listen address kdr_http_start accepts. */
int kdr_http_addr_ok(const char *addr);
unsigned kdr_http_port(const kdr_http *h);
/* Stops accepting, waits up to grace_s for requests in flight, stops. */
void kdr_http_stop(kdr_http *h, double grace_s);

#endif
