/*
 * http_query.c — a complete query request handed to the executor and its
 * answer handed back: answered at once on the HTTP thread when small
 * (query.c decides), else the connection is suspended while a worker runs
 * it and resumed by the worker that finishes it; a streamed answer
 * (Accept: application/cbor-seq) goes through stream.c. While a query is
 * with the executor its socket is on the watcher's list (watch.c), since a
 * suspended connection's socket is not looked at by libmicrohttpd.
 */
#define _POSIX_C_SOURCE 200809L
#include <stdlib.h>

#include "http_internal.h"

/* A body this small is parsed on the HTTP thread (tens of microseconds),
 * and answered there too when its work should take under 0.2 ms (query.c
 * decides from the scene's measured cost per ray): no hand-off to a worker
 * and back. A 1-ray query's round trip (wrk, 1 connection, median) went
 * from 94-107 us through a (niced) worker to 20-22 us, as with the old
 * thread-pool daemon (20-21 us). */
static const size_t INLINE_BODY_MAX = 64 * 1024;

static void watch_add(kdr_http *h, req_state *rs) {
    rs->watch.fd = rs->fd;
    rs->watch.call = &rs->call;
    kdr_watcher_add(h->watcher, &rs->watch);
}

void kdr_http_watch_remove(kdr_http *h, req_state *rs) {
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
    if (kdr_render_param(&rs->render, key, value, rs->render_err,
                         sizeof rs->render_err) == 0)
        rs->render_err[0] = '\0';
    return MHD_YES;
}

/* stream.c's end of a streamed answer: its final item is encoded, so the
 * query is finished here (the watcher lets go of it first). */
static void stream_end(void *ctx, unsigned status) {
    req_state *rs = ctx;
    kdr_response fin = {0};
    kdr_http_watch_remove(rs->h, rs);
    kdr_query_finish(&rs->call, &fin);
    free(fin.body);
    kdr_exec_pieces_free(fin.pieces); /* none: a stream has no one-shot answer */
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
        return kdr_http_queue(h, c, rs, &now);
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

/* The body is complete. A small one may be answered here at once;
 * otherwise the connection is suspended before the query reaches the
 * workers, so that their resume can never overtake the suspension. */
enum MHD_Result kdr_http_start_query(kdr_http *h, struct MHD_Connection *c, req_state *rs,
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
    return kdr_http_queue(h, c, rs, &now);
}

/* Called again after the resume: the query's answer. */
enum MHD_Result kdr_http_finish_query(kdr_http *h, struct MHD_Connection *c,
                                      req_state *rs) {
    kdr_response resp = {0};
    kdr_http_watch_remove(h, rs);
    if (rs->start_failed) {
        resp = rs->early;
        rs->early.body = NULL;
    } else {
        kdr_query_finish(&rs->call, &resp);
    }
    rs->started = 2; /* finished: nothing of the query is left to free */
    if (resp.no_answer) return MHD_NO; /* the client left: close, log 499 */
    resp.ep = rs->ep;
    return kdr_http_queue(h, c, rs, &resp);
}

enum MHD_Result kdr_http_stream_step(kdr_http *h, struct MHD_Connection *c,
                                     req_state *rs) {
    if (rs->start_failed) return kdr_http_finish_query(h, c, rs);
    const int s = kdr_stream_poll(rs->stream);
    if (s < 0) return MHD_YES; /* asleep again */
    if (s == 0) return kdr_http_finish_query(h, c, rs);
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
