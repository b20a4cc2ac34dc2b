/*
 * query.c — the three query endpoints, as thin as the executor lets them
 * be: hold the scene's current version, hand the body to the executor with
 * its media type (Content-Type) and the answer's (Accept; protocol/
 * decides both), and turn its result into the HTTP answer. The HTTP thread does not wait:
 * the executor calls back when the answer is ready (see http_query.c), and meanwhile a watcher
 * asks now and then whether the client is still there; a client that hung up cancels its
 * query, which stops at its next chunk and frees its worker.
 */
#include <stdio.h>
#include <string.h>

#include "kdr_protocol.h"
#include "log.h"
#include "server.h"

/* A query answered on the HTTP thread may hold it this long (estimated from
 * the scene's measured cost per ray for that kind of query); until a cost
 * is known, only queries of INLINE_RAYS_UNKNOWN rays or fewer. Bigger ones
 * go to the workers, which costs a hand-off: on the shared 2-core box a
 * 1024-ray base64 bundle took kdrayd 158-174 us of CPU answered inline and
 * 246-273 us through a worker (the data crosses cores), while 4096
 * incoherent rays on the 1.09M-triangle scene would hold a thread 11-19 ms. */
static const double INLINE_BUDGET_NS = 200e3;
static const size_t INLINE_RAYS_UNKNOWN = 256;
static const size_t INLINE_RAYS_MAX = 4096; /* one bundle chunk */
/* Weight of a new sample in the running cost (1/8). */
static const unsigned COST_SHIFT = 3;

static kdr_exec_kind kind_of(kdr_endpoint ep) {
    return ep == KDR_EP_FRUSTUM         ? KDR_EXEC_FRUSTUM
           : ep == KDR_EP_CONE_SHADOW   ? KDR_EXEC_CONE_SHADOW
           : ep == KDR_EP_RENDER        ? KDR_EXEC_RENDER
           : ep == KDR_EP_CLOSEST_POINT ? KDR_EXEC_CLOSEST_POINT
           : ep == KDR_EP_OCCUPANCY     ? KDR_EXEC_OCCUPANCY
                                        : KDR_EXEC_BUNDLE;
}

static size_t inline_rays(const kdr_scene_version *v, kdr_endpoint ep) {
    if (ep == KDR_EP_RENDER) return 0; /* a picture always goes to the workers */
    unsigned ns = atomic_load_explicit(&((kdr_scene_version *)v)->ns_per_ray[kind_of(ep)],
                                       memory_order_relaxed);
    if (ns == 0) return INLINE_RAYS_UNKNOWN;
    double r = INLINE_BUDGET_NS / ns;
    return r >= (double)INLINE_RAYS_MAX ? INLINE_RAYS_MAX : (size_t)r;
}

/* Folds an answered query's CPU time per ray (parse, chunks, encode:
 * thread CPU time, so a busy box's waiting is not counted) into the
 * scene's running mean. Racy by design: a lost update only delays the mean
 * a little. */
static void learn_cost(kdr_scene_version *v, kdr_endpoint ep, const kdr_exec_result *r) {
    if (r->status != 200 || r->work_rays == 0) return;
    double ns = r->cpu_s * 1e9 / (double)r->work_rays;
    unsigned sample = ns < 1 ? 1 : ns > 4e9 ? 4000000000u : (unsigned)ns;
    atomic_uint *slot = &v->ns_per_ray[kind_of(ep)];
    unsigned old = atomic_load_explicit(slot, memory_order_relaxed);
    unsigned next =
        old == 0 ? sample
                 : (unsigned)((long long)old +
                              (((long long)sample - (long long)old) >> COST_SHIFT));
    atomic_store_explicit(slot, next ? next : 1, memory_order_relaxed);
}

static kdr_ray_kind ray_kind_of(kdr_endpoint ep) {
    return ep == KDR_EP_FRUSTUM         ? KDR_RAYS_FRUSTUM
           : ep == KDR_EP_CONE_SHADOW   ? KDR_RAYS_SHADOW
           : ep == KDR_EP_RENDER        ? KDR_RAYS_RENDER
           : ep == KDR_EP_CLOSEST_POINT ? KDR_RAYS_POINTS
           : ep == KDR_EP_OCCUPANCY     ? KDR_RAYS_OCCUPANCY
                                        : KDR_RAYS_BUNDLE;
}

/* A picture's stage times (Server-Timing, milliseconds: primary, shadow,
 * shade and png are thread CPU time, the first three summed over the
 * workers that ran the bands, so on two idle workers their sum is about
 * twice the wall time; queue and total are the query's wall times) and its
 * statistics (X-Kdray-Render). */
static void render_headers(const kdr_query_call *call, const kdr_exec_result *r,
                           kdr_response *out) {
    const kdr_render_stats *s = &r->render;
    const double total = r->parse_s + r->trace_s + r->encode_s;
    snprintf(out->server_timing, sizeof out->server_timing,
             "primary;dur=%.2f, shadow;dur=%.2f, shade;dur=%.2f, png;dur=%.2f, "
             "queue;dur=%.2f, total;dur=%.2f",
             s->primary_s * 1e3, s->shadow_s * 1e3, s->shade_s * 1e3, r->png_s * 1e3,
             r->queued_s * 1e3, total * 1e3);
    /* one cone per hit point in the modes with a light */
    const int lit = call->render.mode == KDR_RENDER_SHADE || call->render.mode == KDR_RENDER_SHADOW;
    snprintf(out->render_stats, sizeof out->render_stats,
             "width=%u; height=%u; mode=%s; samples=%u; pixels=%llu; hits=%llu; "
             "primary_nodes_per_ray=%.2f; cones=%llu; cones_decided=%llu; "
             "shadow_rays=%llu; shadow_nodes=%llu; ao_rays=%llu",
             call->render.cam.width, call->render.cam.height,
             kdr_render_mode_name(call->render.mode), call->render.samples,
             (unsigned long long)s->pixels, (unsigned long long)s->hits,
             s->pixels ? (double)s->primary_nodes / (double)s->pixels : 0.0,
             (unsigned long long)(lit ? s->hits : 0),
             (unsigned long long)s->shadow.cones_decided,
             (unsigned long long)s->shadow.rays_traced,
             (unsigned long long)s->shadow.nodes_visited, (unsigned long long)s->ao_rays);
}

/* Holds the scene's current version and fills the executor query. */
static int setup(kdr_server *srv, kdr_query_call *call, size_t scene, kdr_endpoint ep,
                 const kdr_request *req, void (*on_done)(void *), void *ctx,
                 kdr_response *out) {
    memset(call, 0, sizeof *call);
    call->scene = kdr_registry_acquire(srv->registry, scene);
    if (!call->scene) {
        kdr_route_problem(out, 404, "no such scene");
        return -1;
    }
    call->ep = ep;
    call->path = req->path;
    if (req->render) call->render = *req->render;
    /* the precheck refused any other Content-Type (415) */
    const kdr_media media = kdr_proto_media_of(req->content_type);
    call->q = (kdr_exec_query){.kind = kind_of(ep),
                               .mode = KDR_EXEC_FAST,
                               .scene = call->scene->scene,
                               .meshes = call->scene->proto_ranges,
                               .nmeshes = call->scene->nranges,
                               .body = req->body,
                               .len = req->len,
                               .body_held = req->held,
                               .media = media,
                               .answer_media = kdr_proto_answer_media(req->accept, media),
                               .max_rays = srv->max_rays,
                               .start = req->start,
                               .deadline_ms = srv->deadline_ms,
                               .claim = req->claim,
                               .render = ep == KDR_EP_RENDER ? &call->render : NULL,
                               .on_done = on_done,
                               .done_ctx = ctx,
                               .pieces = 1};
    call->submitted = kdr_now();
    return 0;
}

static int not_started(kdr_query_call *call, kdr_response *out) {
    kdr_registry_release(call->scene);
    call->scene = NULL;
    kdr_route_problem(out, 503, "out of memory while queueing the query");
    out->retry_after = 1;
    return -1;
}

int kdr_query_start(kdr_server *srv, kdr_query_call *call, size_t scene, kdr_endpoint ep,
                    const kdr_request *req, void (*on_done)(void *), void *ctx,
                    kdr_response *out) {
    if (setup(srv, call, scene, ep, req, on_done, ctx, out) != 0) return -1;
    return kdr_exec_submit(srv->exec, &call->q) == 0 ? 0 : not_started(call, out);
}

int kdr_query_start_stream(kdr_server *srv, kdr_query_call *call, size_t scene,
                           kdr_endpoint ep, const kdr_request *req,
                           void (*on_progress)(void *), void (*on_done)(void *), void *ctx,
                           kdr_response *out) {
    if (setup(srv, call, scene, ep, req, on_done, ctx, out) != 0) return -1;
    call->q.stream = 1;
    call->q.on_progress = on_progress;
    return kdr_exec_submit(srv->exec, &call->q) == 0 ? 0 : not_started(call, out);
}

int kdr_query_try_inline(kdr_server *srv, kdr_query_call *call, size_t scene,
                         kdr_endpoint ep, const kdr_request *req, void (*on_done)(void *),
                         void *ctx, kdr_response *out) {
    if (setup(srv, call, scene, ep, req, on_done, ctx, out) != 0) return -1;
    int rc = kdr_exec_try_inline(srv->exec, &call->q, inline_rays(call->scene, ep));
    if (rc < 0) return not_started(call, out);
    if (rc == 1) kdr_query_finish(call, out);
    return rc;
}

void kdr_query_enqueue(kdr_server *srv, kdr_query_call *call) {
    kdr_exec_enqueue(srv->exec, &call->q);
}

void kdr_query_watch(kdr_query_call *call, int client_gone) {
    if (client_gone) kdr_exec_cancel(&call->q);
    kdr_exec_wait(&call->q, 0); /* finishes an idle query past its deadline */
}

void kdr_query_finish(kdr_query_call *call, kdr_response *out) {
    kdr_exec_result *r = &call->q.result;
    learn_cost(call->scene, call->ep, r);
    if (r->status == 200) {
        out->status = 200;
        out->content_type = r->content_type;
        out->body = r->body.data;
        out->len = r->body.len;
        if (r->pieces) {
            out->pieces = r->pieces;
            out->len = r->pieces->len;
        }
        out->rays = r->rays;
        r->body = (kdr_buf){0}; /* the response owns it now */
        r->pieces = NULL;
        if (call->ep == KDR_EP_RENDER) {
            render_headers(call, r, out);
        } else {
            /* Where the request's time went, in the standard Server-Timing
             * header (ms): the body's arrival (from the headers to the whole
             * body), the queue, parsing, tracing (first chunk to last, all
             * workers), encoding. Clients and the benchmarks read it. */
            snprintf(out->server_timing, sizeof out->server_timing,
                     "body;dur=%.3f, queue;dur=%.3f, parse;dur=%.3f, trace;dur=%.3f, "
                     "encode;dur=%.3f",
                     (call->submitted - call->q.start) * 1e3, r->queued_s * 1e3,
                     r->parse_s * 1e3, r->trace_s * 1e3, r->encode_s * 1e3);
        }
        kdr_metrics_rays(ray_kind_of(call->ep), out->rays);
    } else if (r->stopped == KDR_STOP_CANCELLED) {
        kdr_log_debug("%s: client hung up; query cancelled after %zu of %zu chunks",
                      call->path, r->chunks_done, r->chunks);
        out->no_answer = 1;
    } else {
        if (r->status >= 500 && r->status != 503)
            kdr_log_error("%s: %d %s", call->path, r->status, r->detail);
        else if (r->status == 503)
            kdr_log_debug("%s: 503 %s", call->path, r->detail);
        kdr_route_problem(out, (unsigned)r->status, r->detail);
        out->retry_after = r->retry_after;
    }
    kdr_exec_query_done(&call->q);
    kdr_registry_release(call->scene);
    call->scene = NULL;
}
