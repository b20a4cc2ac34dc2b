/*
 * http.c — libmicrohttpd glue: listening socket, admission of query bodies
 * before a byte of them is stored, body accumulation under the size limit,
 * and handing complete requests to the routes or the executor. Nothing here
 * knows what a scene or a ray is.
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
 *
 * A request's state lives in *req_cls from its first callback until
 * MHD_OPTION_NOTIFY_COMPLETED; the in-flight gauge counts exactly those
 * lifetimes, which is what a graceful shutdown waits on. A query's claim on
 * the executor (slot and bytes) is taken in the first callback, from
 * Content-Length (or grown as a chunked body arrives), and returned there
 * too, after the answer has been sent.
 */
#define _POSIX_C_SOURCE 200809L
#include <arpa/inet.h>
#include <errno.h>
#include <limits.h>
#include <microhttpd.h>
#include <netinet/in.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <sys/socket.h>
#include <time.h>
#include <unistd.h>

#include "log.h"
#include "server.h"
#include "stream.h"
#include "watch.h"

/* MHD per-connection memory. libmicrohttpd 0.9.75 mmaps a pool above 32 KiB
 * (malloc at or below), and after every request zeroes the whole pool: at
 * 256 KiB each new connection faulted in 64 fresh pages and unmapped them
 * at close, 196 us of daemon CPU per GET /v1/health on a new connection
 * against 38 us at 32 KiB (perf stat, 3000 probes), and the idle probe's
 * p90 2.8 -> 0.6 ms, keep-alive p99 3.9 -> 0.28 ms (bench/health_probe.py).
 * Bodies arrive in smaller reads; a 60 MB upload cost the same daemon CPU
 * (128 vs 130 ms) and an 8 MB one 10.5 vs 11.0 ms. */
static const size_t CONNECTION_MEMORY = 32 * 1024;
/* A body this small is parsed on the HTTP thread (tens of microseconds),
 * and answered there too when its work should take under 0.2 ms (query.c
 * decides from the scene's measured cost per ray): no hand-off to a worker
 * and back. A 1-ray query's round trip (wrk, 1 connection, median) went
 * from 94-107 us through a (niced) worker to 20-22 us, as with the old
 * thread-pool daemon (20-21 us). */
static const size_t INLINE_BODY_MAX = 64 * 1024;
/* A body past the limit, or refused, is drained (so the client reads our
 * answer) for at most this many bytes, then the connection is dropped. */
static const size_t DRAIN_MAX = 16u << 20;
/* Initial body buffer when the length is not announced. */
static const size_t BODY_MIN_CAP = 64 * 1024;
/* After the grace period, how long a shutdown waits for stopped queries. */
static const double STOP_WAIT_S = 10.0;
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
    kdr_response early; /* the answer when kdr_query_start refused */
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

static void log_mhd(void *cls, const char *fmt, va_list ap) {
    (void)cls;
    char msg[512];
    vsnprintf(msg, sizeof msg, fmt, ap);
    size_t n = strlen(msg);
    while (n && (msg[n - 1] == '\n' || msg[n - 1] == '\r'))
        msg[--n] = '\0';
    kdr_log_warn("http: %s", msg);
}

static enum MHD_Result queue(kdr_http *h, struct MHD_Connection *c, req_state *rs,
                             kdr_response *r) {
    struct MHD_Response *resp;
    size_t len = r->len;
    if (r->len) {
        resp = MHD_create_response_from_buffer_with_free_callback(r->len, r->body, free);
        if (!resp) free(r->body);
    } else {
        free(r->body);
        resp = MHD_create_response_from_buffer(0, (void *)"", MHD_RESPMEM_PERSISTENT);
    }
    r->body = NULL; /* MHD owns it now (or it is gone) */
    if (!resp) return MHD_NO;
    if (r->content_type)
        MHD_add_response_header(resp, MHD_HTTP_HEADER_CONTENT_TYPE, r->content_type);
    if (r->allow) MHD_add_response_header(resp, MHD_HTTP_HEADER_ALLOW, r->allow);
    if (r->retry_after) {
        char secs[16];
        snprintf(secs, sizeof secs, "%u", r->retry_after);
        MHD_add_response_header(resp, MHD_HTTP_HEADER_RETRY_AFTER, secs);
    }
    if (atomic_load(&h->srv->stopping))
        MHD_add_response_header(resp, MHD_HTTP_HEADER_CONNECTION, "close");
    if (r->server_timing[0]) MHD_add_response_header(resp, "Server-Timing", r->server_timing);
    if (r->render_stats[0]) {
        MHD_add_response_header(resp, "X-Kdray-Render", r->render_stats);
        MHD_add_response_header(resp, MHD_HTTP_HEADER_CACHE_CONTROL, "no-store");
    }
    enum MHD_Result ok = MHD_queue_response(c, r->status, resp);
    MHD_destroy_response(resp);
    rs->queued = 1;
    rs->status = r->status;
    rs->rays = r->rays;
    rs->bytes_out = len;
    kdr_metrics_request(r->ep, r->status, kdr_now() - rs->start);
    return ok;
}

static long long content_length(struct MHD_Connection *c) {
    const char *v =
        MHD_lookup_connection_value(c, MHD_HEADER_KIND, MHD_HTTP_HEADER_CONTENT_LENGTH);
    if (!v || !*v) return -1;
    char *end;
    errno = 0;
    unsigned long long n = strtoull(v, &end, 10);
    if (errno || *end || n > (unsigned long long)LLONG_MAX) return -1;
    return (long long)n;
}

/* From now on the body is read and thrown away, and `answer` follows it. */
static void refuse(kdr_http *h, req_state *rs, kdr_response *answer) {
    rs->refusal = *answer;
    rs->refused = 1;
    free(rs->body);
    rs->body = NULL;
    rs->cap = 0;
    rs->dropped += rs->len;
    rs->len = 0;
    kdr_exec_release(h->srv->exec, &rs->claim); /* a drain needs no slot */
}

/* Grows the body buffer for n more bytes of a body of unknown length,
 * charging the claim before allocating. 0, or -1 after refuse(). */
static int grow(kdr_http *h, req_state *rs, size_t n) {
    size_t max = h->srv->max_body, cap = rs->cap ? rs->cap : BODY_MIN_CAP;
    while (cap < rs->len + n)
        cap *= 2;
    if (cap > max) cap = max;
    kdr_response no = {0};
    size_t more = kdr_exec_body_charge(cap) - kdr_exec_body_charge(rs->cap);
    kdr_admit a = kdr_exec_charge(h->srv->exec, &rs->claim, more);
    if (a != KDR_ADMIT_OK) {
        kdr_route_refusal(h->srv, a, more, &no);
    } else {
        char *p = realloc(rs->body, cap);
        if (p) {
            rs->body = p;
            rs->cap = cap;
            return 0;
        }
        kdr_route_problem(&no, 503, "out of memory for the request body");
        no.retry_after = 1;
    }
    no.ep = rs->ep;
    refuse(h, rs, &no);
    return -1;
}

/* Appends a piece of the body, or counts it as discarded once the body is
 * over the limit or refused. 0 to go on, -1 to drop the connection. */
static int append(kdr_http *h, req_state *rs, const char *data, size_t n) {
    if (rs->refused || rs->dropped || rs->len + n > h->srv->max_body) {
        rs->dropped += n;
        return rs->dropped <= DRAIN_MAX ? 0 : -1;
    }
    if (rs->len + n > rs->cap && grow(h, rs, n) != 0) {
        rs->dropped += n;
        return rs->dropped <= DRAIN_MAX ? 0 : -1;
    }
    memcpy(rs->body + rs->len, data, n);
    rs->len += n;
    return 0;
}

static void client_address(struct MHD_Connection *c, char *out, size_t n) {
    const union MHD_ConnectionInfo *ci =
        MHD_get_connection_info(c, MHD_CONNECTION_INFO_CLIENT_ADDRESS);
    out[0] = '\0';
    if (!ci || !ci->client_addr) return;
    const struct sockaddr *sa = ci->client_addr;
    if (sa->sa_family == AF_INET)
        inet_ntop(AF_INET, &((const struct sockaddr_in *)(const void *)sa)->sin_addr, out,
                  (socklen_t)n);
    else if (sa->sa_family == AF_INET6)
        inet_ntop(AF_INET6, &((const struct sockaddr_in6 *)(const void *)sa)->sin6_addr,
                  out, (socklen_t)n);
}

static void watch_add(kdr_http *h, req_state *rs) {
    rs->watch.fd = rs->fd;
    rs->watch.call = &rs->call;
    kdr_watcher_add(h->watcher, &rs->watch);
}

static void watch_remove(kdr_http *h, req_state *rs) {
    kdr_watcher_remove(h->watcher, &rs->watch);
}

/* From the worker that finished the query: let MHD call us back. */
static void on_query_done(void *ctx) {
    req_state *rs = ctx;
    MHD_resume_connection(rs->conn);
}

/* One query-string argument of render.png; the first bad one is kept. */
static enum MHD_Result render_arg(void *cls, enum MHD_ValueKind kind, const char *key,
                                  const char *value) {
    (void)kind;
    req_state *rs = cls;
    if (rs->render_err[0]) return MHD_YES;
    if (kdr_render_param(&rs->render, key, value, rs->render_err, sizeof rs->render_err) ==
        0)
        rs->render_err[0] = '\0';
    return MHD_YES;
}

/* stream.c's end of a streamed answer: its final item is encoded, so the
 * query is finished here (the watcher lets go of it first). */
static void stream_end(void *ctx, unsigned status) {
    req_state *rs = ctx;
    kdr_response fin = {0};
    watch_remove(rs->h, rs);
    kdr_query_finish(&rs->call, &fin);
    free(fin.body);
    rs->started = 2;
    rs->status = fin.no_answer ? 499 : status;
    rs->rays = fin.rays;
    kdr_metrics_request(rs->ep, rs->status, kdr_now() - rs->start);
}

/* A streamed answer for the three ray queries when Accept asks for it;
 * the other queries (and render.png) are refused by the executor (406). */
static int wants_stream(const req_state *rs, const kdr_request *req) {
    return rs->ep != KDR_EP_RENDER &&
           kdr_proto_answer_media(req->accept, kdr_proto_media_of(req->content_type)) ==
               KDR_MEDIA_CBOR_SEQ;
}

/* Starts a streamed query; the connection sleeps until the executor has
 * parsed it (or refused it). */
static enum MHD_Result start_stream(kdr_http *h, struct MHD_Connection *c, req_state *rs,
                                    const kdr_request *req, size_t scene) {
    rs->stream = kdr_stream_new(c, &rs->call, stream_end, rs);
    if (!rs->stream) {
        kdr_response now = {0};
        kdr_route_problem(&now, 503, "out of memory for the answer's stream");
        now.retry_after = 1;
        now.ep = rs->ep;
        return queue(h, c, rs, &now);
    }
    kdr_stream_sleep(rs->stream);
    rs->started = 1;
    if (kdr_query_start_stream(h->srv, &rs->call, scene, rs->ep, req, kdr_stream_progress,
                               kdr_stream_done, rs->stream, &rs->early) == 0) {
        watch_add(h, rs);
        return MHD_YES;
    }
    rs->start_failed = 1;
    kdr_stream_done(rs->stream); /* wakes the connection: rs->early follows */
    return MHD_YES;
}

/* Called again after a wake of a streamed query: start the chunked answer
 * once the query is parsed, or answer its problem like any query. */
static enum MHD_Result stream_step(kdr_http *h, struct MHD_Connection *c, req_state *rs);

/* The body is complete. A small one may be answered here at once;
 * otherwise the connection is suspended before the query reaches the
 * workers, so that their resume can never overtake the suspension. */
static enum MHD_Result start_query(kdr_http *h, struct MHD_Connection *c, req_state *rs,
                                   const kdr_request *req) {
    long scene = kdr_route_scene(h->srv, req->path);
    kdr_response now = {0};
    int rc = -1;
    kdr_request with_args = *req;
    if (rs->ep == KDR_EP_RENDER) {
        kdr_render_params_init(&rs->render);
        rs->render_err[0] = '\0';
        MHD_get_connection_values(c, MHD_GET_ARGUMENT_KIND, render_arg, rs);
        with_args.render = &rs->render;
        req = &with_args;
    }
    if (scene < 0) {
        kdr_route_problem(&now, 404, "no such scene");
    } else if (rs->render_err[0]) {
        kdr_route_problem(&now, 400, rs->render_err);
    } else if (wants_stream(rs, req)) {
        return start_stream(h, c, rs, req, (size_t)scene);
    } else if (req->len <= INLINE_BODY_MAX) {
        rc = kdr_query_try_inline(h->srv, &rs->call, (size_t)scene, rs->ep, req,
                                  on_query_done, rs, &now);
        if (rc == 0) {
            MHD_suspend_connection(c);
            rs->started = 1;
            kdr_query_enqueue(h->srv, &rs->call);
            watch_add(h, rs);
            return MHD_YES;
        }
    } else {
        MHD_suspend_connection(c);
        rs->started = 1;
        rc = kdr_query_start(h->srv, &rs->call, (size_t)scene, rs->ep, req, on_query_done,
                             rs, &rs->early);
        if (rc == 0) {
            watch_add(h, rs);
            return MHD_YES;
        }
        rs->start_failed = 1;
        MHD_resume_connection(c);
        return MHD_YES;
    }
    /* answered here: inline, or refused before anything started */
    if (now.no_answer) return MHD_NO;
    now.ep = rs->ep;
    return queue(h, c, rs, &now);
}

/* Called again after the resume: the query's answer. */
static enum MHD_Result finish_query(kdr_http *h, struct MHD_Connection *c,
                                    req_state *rs) {
    kdr_response resp = {0};
    watch_remove(h, rs);
    if (rs->start_failed) {
        resp = rs->early;
        rs->early.body = NULL;
    } else {
        kdr_query_finish(&rs->call, &resp);
    }
    rs->started = 2; /* finished: nothing of the query is left to free */
    if (resp.no_answer) return MHD_NO; /* the client left: close, log 499 */
    resp.ep = rs->ep;
    return queue(h, c, rs, &resp);
}

static enum MHD_Result stream_step(kdr_http *h, struct MHD_Connection *c, req_state *rs) {
    if (rs->start_failed) return finish_query(h, c, rs);
    const int s = kdr_stream_poll(rs->stream);
    if (s < 0) return MHD_YES; /* asleep again */
    if (s == 0) return finish_query(h, c, rs);
    struct MHD_Response *resp = kdr_stream_response(rs->stream);
    if (!resp) return MHD_NO; /* closed: on_completed cancels the query */
    if (atomic_load(&h->srv->stopping))
        MHD_add_response_header(resp, MHD_HTTP_HEADER_CONNECTION, "close");
    enum MHD_Result ok = MHD_queue_response(c, 200, resp);
    MHD_destroy_response(resp);
    rs->queued = 1;
    rs->status = 200;
    return ok;
}

static req_state *req_begin(kdr_http *h, struct MHD_Connection *c,
                            const kdr_request *req) {
    req_state *rs = calloc(1, sizeof *rs);
    if (!rs) return NULL;
    rs->h = h;
    rs->start = kdr_now();
    rs->conn = c;
    const union MHD_ConnectionInfo *fd =
        MHD_get_connection_info(c, MHD_CONNECTION_INFO_CONNECTION_FD);
    rs->fd = fd ? fd->connect_fd : -1;
    if (h->srv->access_log.fd >= 0) {
        client_address(c, rs->client, sizeof rs->client);
        snprintf(rs->method, sizeof rs->method, "%s", req->method);
        snprintf(rs->path, sizeof rs->path, "%s", req->path);
    }
    kdr_metrics_inflight(+1);
    return rs;
}

/* An early answer is sent at once only when the client will not push a
 * body at us first (none announced, or Expect: 100-continue) or the body is
 * too big to drain; otherwise we read and discard the body and answer after
 * it, because MHD closes a connection whose body it has not read and a
 * client still writing would see a broken pipe instead of our answer. */
static int answer_now(struct MHD_Connection *c, long long clen, size_t max_body) {
    const char *te = MHD_lookup_connection_value(c, MHD_HEADER_KIND,
                                                 MHD_HTTP_HEADER_TRANSFER_ENCODING);
    const char *ex =
        MHD_lookup_connection_value(c, MHD_HEADER_KIND, MHD_HTTP_HEADER_EXPECT);
    if (ex && !strcasecmp(ex, "100-continue")) return 1;
    if (te) return 0; /* chunked: length unknown, drain up to the cap */
    return clen <= 0 || (unsigned long long)clen > max_body + DRAIN_MAX;
}

/* A query body's admission: a slot and the bytes of its announced length,
 * before anything is allocated for it. 0, or 1 with rs->refusal set. */
static int admit(kdr_http *h, req_state *rs, long long clen, const char *path) {
    size_t need = clen > 0 ? kdr_exec_body_charge((size_t)clen) : 0;
    kdr_admit a = kdr_exec_admit(h->srv->exec, &rs->claim, need);
    if (a != KDR_ADMIT_OK) {
        kdr_route_refusal(h->srv, a, need, &rs->refusal);
        kdr_log_debug("%s: %u %s", path, rs->refusal.status,
                      a == KDR_ADMIT_QUEUE_FULL  ? "queue full"
                      : a == KDR_ADMIT_TOO_LARGE ? "over the whole in-flight budget"
                      : a == KDR_ADMIT_STOPPED   ? "shutting down"
                                                 : "memory full");
        return 1;
    }
    if (clen > 0) {
        rs->body = malloc((size_t)clen);
        rs->cap = rs->body ? (size_t)clen : 0;
        if (!rs->body) {
            kdr_exec_release(h->srv->exec, &rs->claim);
            kdr_route_problem(&rs->refusal, 503, "out of memory for the request body");
            rs->refusal.retry_after = 1;
            return 1;
        }
    }
    return 0;
}

/* First callback: route and limits, before any body byte is read. */
static enum MHD_Result on_first(kdr_http *h, struct MHD_Connection *c,
                                const kdr_request *req, void **req_cls) {
    long long clen = content_length(c);
    req_state *rs = req_begin(h, c, req);
    if (!rs) return MHD_NO;
    *req_cls = rs;
    int refused = kdr_route_precheck(h->srv, req, clen, &rs->refusal);
    rs->ep = rs->refusal.ep;
    if (!refused && kdr_route_is_query(rs->ep)) refused = admit(h, rs, clen, req->path);
    if (refused) {
        rs->refused = 1;
        rs->refusal.ep = rs->ep;
        if (answer_now(c, clen, h->srv->max_body)) return queue(h, c, rs, &rs->refusal);
    }
    return MHD_YES;
}

static enum MHD_Result on_request(void *cls, struct MHD_Connection *c, const char *url,
                                  const char *method, const char *version,
                                  const char *upload, size_t *upload_size,
                                  void **req_cls) {
    (void)version;
    kdr_http *h = cls;
    kdr_server *srv = h->srv;
    kdr_request req = {
        .method = method,
        .path = url,
        .content_type =
            MHD_lookup_connection_value(c, MHD_HEADER_KIND, MHD_HTTP_HEADER_CONTENT_TYPE),
        .accept = MHD_lookup_connection_value(c, MHD_HEADER_KIND, MHD_HTTP_HEADER_ACCEPT)};
    req_state *rs = *req_cls;
    if (!rs) return on_first(h, c, &req, req_cls);
    if (rs->queued) { /* answered early; MHD may still hand us body bytes */
        *upload_size = 0;
        return MHD_YES;
    }
    if (rs->started == 1)
        return rs->stream ? stream_step(h, c, rs) : finish_query(h, c, rs);
    if (*upload_size) {
        int ok = append(h, rs, upload, *upload_size) == 0;
        *upload_size = 0;
        return ok ? MHD_YES : MHD_NO;
    }
    if (rs->refused) return queue(h, c, rs, &rs->refusal);
    kdr_response resp = {0};
    if (rs->dropped) {
        char detail[128];
        snprintf(detail, sizeof detail, "body: over the limit of %zu bytes",
                 srv->max_body);
        kdr_route_problem(&resp, 413, detail);
    } else {
        req.body = rs->body;
        req.len = rs->len;
        req.start = rs->start;
        req.claim = &rs->claim;
        if (kdr_route_is_query(rs->ep)) return start_query(h, c, rs, &req);
        kdr_route_handle(srv, &req, &resp);
    }
    resp.ep = rs->ep;
    return queue(h, c, rs, &resp);
}

static void on_completed(void *cls, struct MHD_Connection *c, void **req_cls,
                         enum MHD_RequestTerminationCode toe) {
    kdr_http *h = cls;
    (void)c;
    (void)toe;
    req_state *rs = *req_cls;
    if (!rs) return;
    if (rs->stream) rs->bytes_out = kdr_stream_sent(rs->stream);
    if (h->srv->access_log.fd >= 0) {
        kdr_access_entry e = {rs->client,    rs->method,
                              rs->path,      rs->queued ? rs->status : 499,
                              rs->rays,      rs->len + rs->dropped,
                              rs->bytes_out, (kdr_now() - rs->start) * 1e3};
        kdr_access_log_write(&h->srv->access_log, &e);
    }
    if (rs->started == 1 && !rs->start_failed) {
        /* Resumed, then closed by MHD before our handler saw the answer (the
         * client had gone). MHD never closes a suspended connection, so the
         * query is finished; the cancel and wait only make sure of it. */
        kdr_response dropped = {0};
        watch_remove(h, rs);
        kdr_exec_cancel(&rs->call.q);
        kdr_exec_wait(&rs->call.q, -1);
        if (rs->stream) kdr_stream_wait_done(rs->stream);
        kdr_query_finish(&rs->call, &dropped);
        free(dropped.body);
    }
    kdr_stream_free(rs->stream);
    kdr_exec_release(h->srv->exec, &rs->claim);
    free(rs->body);
    free(rs->refusal.body); /* set when the client left before our answer */
    free(rs->early.body);
    free(rs);
    *req_cls = NULL;
    kdr_metrics_inflight(-1);
}

/* Parses "HOST:PORT" / "[V6]:PORT" into a socket address. */
static int parse_addr(const char *addr, struct sockaddr_storage *ss, int *v6) {
    char host[256];
    const char *colon = strrchr(addr, ':');
    if (!colon || colon == addr || (size_t)(colon - addr) >= sizeof host) return -1;
    char *end;
    errno = 0;
    unsigned long port = strtoul(colon + 1, &end, 10);
    if (errno || end == colon + 1 || *end || port > 65535) return -1;
    memcpy(host, addr, (size_t)(colon - addr));
    host[colon - addr] = '\0';
    memset(ss, 0, sizeof *ss);
    size_t hl = strlen(host);
    if (host[0] == '[' && hl > 2 && host[hl - 1] == ']') {
        struct sockaddr_in6 *s6 = (struct sockaddr_in6 *)ss;
        host[hl - 1] = '\0';
        s6->sin6_family = AF_INET6;
        s6->sin6_port = htons((uint16_t)port);
        *v6 = 1;
        return inet_pton(AF_INET6, host + 1, &s6->sin6_addr) == 1 ? 0 : -1;
    }
    struct sockaddr_in *s4 = (struct sockaddr_in *)ss;
    s4->sin_family = AF_INET;
    s4->sin_port = htons((uint16_t)port);
    *v6 = 0;
    if (!strcmp(host, "localhost")) strcpy(host, "127.0.0.1");
    return inet_pton(AF_INET, host, &s4->sin_addr) == 1 ? 0 : -1;
}

int kdr_http_addr_ok(const char *addr) {
    struct sockaddr_storage ss;
    int v6;
    return parse_addr(addr, &ss, &v6) == 0;
}

kdr_http *kdr_http_start(kdr_server *srv, const char *addr) {
    struct sockaddr_storage ss;
    int v6 = 0;
    if (parse_addr(addr, &ss, &v6) != 0) {
        kdr_log_error("--listen %s: expected ADDR:PORT (IPv4, localhost or [IPv6])",
                      addr);
        return NULL;
    }
    kdr_http *h = calloc(1, sizeof *h);
    if (!h) return NULL;
    h->srv = srv;
    h->quiesced = MHD_INVALID_SOCKET;
    /* poll(), not epoll: with MHD 0.9.75's epoll mode a client that hangs up
     * in the middle of a body is noticed only at the connection timeout
     * (measured: 7 of 10 hang-ups), so it counts as in flight for a minute. */
    unsigned flags = MHD_USE_INTERNAL_POLLING_THREAD | MHD_USE_POLL | MHD_USE_ITC |
                     MHD_ALLOW_SUSPEND_RESUME | MHD_USE_ERROR_LOG |
                     (v6 ? MHD_USE_IPv6 : 0);
    h->watcher = kdr_watcher_start();
    if (!h->watcher) {
        kdr_log_error("cannot start the connection watcher: %s", strerror(errno));
        free(h);
        return NULL;
    }
    /* The logger goes first so that MHD reports option errors through it. */
    /* clang-format off */
    h->d = MHD_start_daemon(flags, 0, NULL, NULL, on_request, h,
        MHD_OPTION_EXTERNAL_LOGGER, log_mhd, (void *)NULL,
        MHD_OPTION_SOCK_ADDR, (const struct sockaddr *)&ss,
        MHD_OPTION_THREAD_POOL_SIZE, (unsigned)srv->http_threads,
        MHD_OPTION_CONNECTION_LIMIT, (unsigned)srv->max_connections,
        MHD_OPTION_NOTIFY_COMPLETED, on_completed, (void *)h,
        MHD_OPTION_CONNECTION_MEMORY_LIMIT, CONNECTION_MEMORY,
        MHD_OPTION_CONNECTION_TIMEOUT, srv->connection_timeout_s,
        MHD_OPTION_END);
    /* clang-format on */
    if (!h->d) {
        kdr_log_error("cannot listen on %s: %s", addr, strerror(errno));
        kdr_watcher_stop(h->watcher);
        free(h);
        return NULL;
    }
    const union MHD_DaemonInfo *info =
        MHD_get_daemon_info(h->d, MHD_DAEMON_INFO_BIND_PORT);
    h->port = info ? info->port : 0;
    return h;
}

unsigned kdr_http_port(const kdr_http *h) { return h->port; }

static void sleep_ms(long ms) {
    struct timespec ts = {ms / 1000, (ms % 1000) * 1000000L};
    nanosleep(&ts, NULL);
}

void kdr_http_quiesce(kdr_http *h) {
    if (!h || h->quiesced != MHD_INVALID_SOCKET) return;
    atomic_store(&h->srv->stopping, 1);
    h->quiesced = MHD_quiesce_daemon(h->d);
}

/* Waits until nothing is in flight or `seconds` pass; what is left. */
static long wait_idle(double seconds) {
    double t0 = kdr_now();
    long left;
    while ((left = kdr_metrics_inflight_now()) > 0 && kdr_now() - t0 < seconds)
        sleep_ms(10);
    return left;
}

/* Waits until the executor holds no query: every stopped query has been
 * finished and its connection resumed. Chunks are bounded, so this ends. */
static void wait_executor(kdr_exec *ex) {
    kdr_exec_stats st;
    for (long ms = 0;; ms += 10) {
        kdr_exec_get_stats(ex, &st);
        if (st.queued + st.running == 0) return;
        if (ms && ms % 10000 == 0)
            kdr_log_warn("shutdown: waiting for %zu quer%s to reach a chunk boundary",
                         st.queued + st.running,
                         st.queued + st.running == 1 ? "y" : "ies");
        sleep_ms(10);
    }
}

void kdr_http_stop(kdr_http *h, double grace_s) {
    if (!h) return;
    kdr_http_quiesce(h);
    long left = wait_idle(grace_s);
    if (left > 0) {
        kdr_log_warn(
            "shutdown: %ld request%s still in flight after %.0f s: stopping their "
            "queries",
            left, left == 1 ? "" : "s", grace_s);
        kdr_exec_shutdown(h->srv->exec);
        wait_executor(h->srv->exec);
        left = wait_idle(STOP_WAIT_S);
        if (left > 0)
            kdr_log_warn("shutdown: closing %ld connection%s", left,
                         left == 1 ? "" : "s");
    }
    /* No query is suspended now (they all finished above), so MHD never has
     * to resume a connection behind the executor's back. */
    MHD_stop_daemon(h->d);
    if (h->quiesced != MHD_INVALID_SOCKET) close(h->quiesced);
    kdr_watcher_stop(h->watcher);
    free(h);
}
