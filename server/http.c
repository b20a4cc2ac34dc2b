/*
 * http.c — one request's life in libmicrohttpd's callbacks: its state from
 * the first callback (route, limits and, for a query, admission, before a
 * byte of the body is stored) through the body's arrival (http_body.c) and
 * the hand-off to the routes or the executor (http_query.c), to the answer
 * queued to libmicrohttpd and the clean-up once it has been sent, with the
 * access-log line. Nothing here knows what a scene or a ray is.
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
#include <netinet/in.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>

#include "http_internal.h"
#include "log.h"

enum MHD_Result kdr_http_queue(kdr_http *h, struct MHD_Connection *c, req_state *rs,
                               kdr_response *r) {
    struct MHD_Response *resp;
    size_t len = r->len;
    if (r->pieces) {
        /* the answer's arrays where the core wrote them: no copy; MHD
         * copies the vector and frees the pieces once it is done */
        kdr_exec_pieces *p = r->pieces;
        struct MHD_IoVec iov[KDR_HITS_PIECES_MAX];
        for (size_t i = 0; i < p->n; i++)
            iov[i] = (struct MHD_IoVec){p->v[i].data, p->v[i].len};
        resp = MHD_create_response_from_iovec(iov, (unsigned)p->n, kdr_exec_pieces_free, p);
        if (!resp) kdr_exec_pieces_free(p);
        r->pieces = NULL;
        free(r->body);
    } else if (r->len) {
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
    if (r->server_timing[0])
        MHD_add_response_header(resp, "Server-Timing", r->server_timing);
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

/* First callback: route and limits, before any body byte is read. */
static enum MHD_Result on_first(kdr_http *h, struct MHD_Connection *c,
                                const kdr_request *req, void **req_cls) {
    long long clen = kdr_http_content_length(c);
    req_state *rs = req_begin(h, c, req);
    if (!rs) return MHD_NO;
    *req_cls = rs;
    int refused = kdr_route_precheck(h->srv, req, clen, &rs->refusal);
    rs->ep = rs->refusal.ep;
    if (!refused && kdr_route_is_query(rs->ep))
        refused = kdr_http_admit(h, rs, clen, req->path);
    if (refused) {
        rs->refused = 1;
        rs->refusal.ep = rs->ep;
        if (kdr_http_answer_now(c, clen, h->srv->max_body))
            return kdr_http_queue(h, c, rs, &rs->refusal);
    }
    return MHD_YES;
}

enum MHD_Result kdr_http_on_request(void *cls, struct MHD_Connection *c, const char *url,
                                    const char *method, const char *version,
                                    const char *upload, size_t *upload_size,
                                    void **req_cls) {
    (void)version;
    kdr_http *h = cls;
    kdr_server *srv = h->srv;
    kdr_request req = {.method = method,
                       .path = url,
                       .content_type = MHD_lookup_connection_value(
                           c, MHD_HEADER_KIND, MHD_HTTP_HEADER_CONTENT_TYPE),
                       .accept = MHD_lookup_connection_value(c, MHD_HEADER_KIND,
                                                             MHD_HTTP_HEADER_ACCEPT)};
    req_state *rs = *req_cls;
    if (!rs) return on_first(h, c, &req, req_cls);
    if (rs->queued) { /* answered early; MHD may still hand us body bytes */
        *upload_size = 0;
        return MHD_YES;
    }
    if (rs->started == 1)
        return rs->stream ? kdr_http_stream_step(h, c, rs)
                          : kdr_http_finish_query(h, c, rs);
    if (*upload_size) {
        int ok = kdr_http_append(h, rs, upload, *upload_size) == 0;
        *upload_size = 0;
        return ok ? MHD_YES : MHD_NO;
    }
    if (rs->refused) return kdr_http_queue(h, c, rs, &rs->refusal);
    kdr_response resp = {0};
    if (rs->dropped) {
        char detail[128];
        snprintf(detail, sizeof detail, "body: over the limit of %zu bytes",
                 srv->max_body);
        kdr_route_problem(&resp, 413, detail);
    } else {
        req.body = rs->body;
        req.len = rs->len;
        req.held = rs->cap;
        req.start = rs->start;
        req.claim = &rs->claim;
        if (kdr_route_is_query(rs->ep)) return kdr_http_start_query(h, c, rs, &req);
        kdr_route_handle(srv, &req, &resp);
    }
    resp.ep = rs->ep;
    return kdr_http_queue(h, c, rs, &resp);
}

void kdr_http_on_completed(void *cls, struct MHD_Connection *c, void **req_cls,
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
        kdr_http_watch_remove(h, rs);
        kdr_exec_cancel(&rs->call.q);
        kdr_exec_wait(&rs->call.q, -1);
        if (rs->stream) kdr_stream_wait_done(rs->stream);
        kdr_query_finish(&rs->call, &dropped);
        free(dropped.body);
        kdr_exec_pieces_free(dropped.pieces);
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
