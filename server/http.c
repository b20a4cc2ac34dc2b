/*
 * http.c — libmicrohttpd glue: listening socket, per-request body
 * accumulation under the size limit, and handing complete requests to the
 * routes. Nothing here knows what a scene or a ray is.
 *
 * A request's state lives in *req_cls from its first callback until
 * MHD_OPTION_NOTIFY_COMPLETED; the in-flight gauge counts exactly those
 * lifetimes, which is what a graceful shutdown waits on.
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

/* MHD per-connection memory: bigger reads mean fewer callbacks per body. */
static const size_t CONNECTION_MEMORY = 256 * 1024;
/* Seconds an idle connection is kept. */
static const unsigned CONNECTION_TIMEOUT_S = 60;
/* A chunked body past the limit is drained (so the client reads our 413)
 * for at most this many extra bytes, then the connection is dropped. */
static const size_t DRAIN_MAX = 16u << 20;
/* Initial body buffer when the length is not announced. */
static const size_t BODY_MIN_CAP = 64 * 1024;

struct kdr_http {
    struct MHD_Daemon *d;
    kdr_server *srv;
    unsigned port;
};

typedef struct req_state {
    double start;
    kdr_endpoint ep;
    int refused;          /* answered by the precheck: body is discarded */
    kdr_response refusal; /* that answer, until the body has been read */
    char *body;
    size_t len, cap;
    size_t dropped; /* bytes past the limit, discarded */
    int queued;     /* an answer was handed to MHD */
} req_state;

static void log_mhd(void *cls, const char *fmt, va_list ap) {
    (void)cls;
    char msg[512];
    vsnprintf(msg, sizeof msg, fmt, ap);
    size_t n = strlen(msg);
    while (n && (msg[n - 1] == '\n' || msg[n - 1] == '\r'))
        msg[--n] = '\0';
    kdr_log("http: %s", msg);
}

static enum MHD_Result queue(kdr_http *h, struct MHD_Connection *c, req_state *rs,
                             kdr_response *r) {
    struct MHD_Response *resp;
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
    if (atomic_load(&h->srv->stopping))
        MHD_add_response_header(resp, MHD_HTTP_HEADER_CONNECTION, "close");
    enum MHD_Result ok = MHD_queue_response(c, r->status, resp);
    MHD_destroy_response(resp);
    rs->queued = 1;
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

/* Appends a chunk, or counts it as dropped once the limit is passed. */
static int append(req_state *rs, size_t max, const char *data, size_t n) {
    if (rs->dropped || rs->len + n > max) {
        rs->dropped += n;
        return rs->dropped <= DRAIN_MAX;
    }
    if (rs->len + n > rs->cap) {
        size_t cap = rs->cap ? rs->cap : BODY_MIN_CAP;
        while (cap < rs->len + n)
            cap *= 2;
        if (cap > max) cap = max;
        char *p = realloc(rs->body, cap);
        if (!p) return 0;
        rs->body = p;
        rs->cap = cap;
    }
    memcpy(rs->body + rs->len, data, n);
    rs->len += n;
    return 1;
}

static req_state *req_begin(void) {
    req_state *rs = calloc(1, sizeof *rs);
    if (!rs) return NULL;
    rs->start = kdr_now();
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

/* First callback: route and limits, before any body byte is read. */
static enum MHD_Result on_first(kdr_http *h, struct MHD_Connection *c,
                                const kdr_request *req, void **req_cls) {
    long long clen = content_length(c);
    req_state *rs = req_begin();
    if (!rs) return MHD_NO;
    *req_cls = rs;
    if (kdr_route_precheck(h->srv, req, clen, &rs->refusal)) {
        rs->refused = 1;
        if (answer_now(c, clen, h->srv->max_body)) return queue(h, c, rs, &rs->refusal);
        return MHD_YES;
    }
    rs->ep = rs->refusal.ep;
    if (clen > 0 && (size_t)clen <= h->srv->max_body) {
        rs->body = malloc((size_t)clen);
        rs->cap = rs->body ? (size_t)clen : 0;
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
    if (*upload_size) {
        int ok = rs->refused ? (rs->dropped += *upload_size) <= DRAIN_MAX
                             : append(rs, srv->max_body, upload, *upload_size);
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
        kdr_route_handle(srv, &req, &resp);
    }
    resp.ep = rs->ep;
    return queue(h, c, rs, &resp);
}

static void on_completed(void *cls, struct MHD_Connection *c, void **req_cls,
                         enum MHD_RequestTerminationCode toe) {
    (void)cls;
    (void)c;
    (void)toe;
    req_state *rs = *req_cls;
    if (!rs) return;
    free(rs->body);
    free(rs->refusal.body); /* set when the client left before our answer */
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
        kdr_log("error: --listen %s: expected ADDR:PORT (IPv4, localhost or [IPv6])",
                addr);
        return NULL;
    }
    kdr_http *h = calloc(1, sizeof *h);
    if (!h) return NULL;
    h->srv = srv;
    /* poll(), not epoll: with MHD 0.9.75's epoll mode a client that hangs up
     * in the middle of a body is noticed only at the connection timeout
     * (measured: 7 of 10 hang-ups), so it counts as in flight for a minute. */
    unsigned flags = MHD_USE_POLL | MHD_USE_INTERNAL_POLLING_THREAD | MHD_USE_ITC |
                     MHD_USE_ERROR_LOG | (v6 ? MHD_USE_IPv6 : 0);
    /* The logger goes first so that MHD reports option errors through it. */
    /* clang-format off */
    h->d = MHD_start_daemon(flags, 0, NULL, NULL, on_request, h,
        MHD_OPTION_EXTERNAL_LOGGER, log_mhd, (void *)NULL,
        MHD_OPTION_SOCK_ADDR, (const struct sockaddr *)&ss,
        MHD_OPTION_THREAD_POOL_SIZE, (unsigned)srv->threads,
        MHD_OPTION_NOTIFY_COMPLETED, on_completed, (void *)h,
        MHD_OPTION_CONNECTION_MEMORY_LIMIT, CONNECTION_MEMORY,
        MHD_OPTION_CONNECTION_TIMEOUT, CONNECTION_TIMEOUT_S,
        MHD_OPTION_END);
    /* clang-format on */
    if (!h->d) {
        kdr_log("error: cannot listen on %s: %s", addr, strerror(errno));
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

void kdr_http_stop(kdr_http *h, double grace_s) {
    if (!h) return;
    atomic_store(&h->srv->stopping, 1);
    MHD_socket ls = MHD_quiesce_daemon(h->d);
    double t0 = kdr_now();
    long left;
    while ((left = kdr_metrics_inflight_now()) > 0 && kdr_now() - t0 < grace_s)
        sleep_ms(10);
    if (left > 0)
        kdr_log("shutdown: %ld requests still in flight after %.0f s, closing", left,
                grace_s);
    MHD_stop_daemon(h->d);
    if (ls != MHD_INVALID_SOCKET) close(ls);
    free(h);
}
