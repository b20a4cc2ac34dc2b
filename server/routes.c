/*
 * routes.c — which path is which endpoint, which method and content type
 * it takes, and the small GET answers (health, ready, metrics, scenes),
 * which run on the connection's own thread and never wait for a query. The
 * query endpoints are answered in query.c. Every error is problem+json,
 * encoded by protocol/; running out of memory is a 503 (retry later), never
 * a 500.
 */
#define _POSIX_C_SOURCE 200809L
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "kdr_protocol.h"
#include "server.h"

static const char *const CT_JSON = "application/json";
static const char *const CT_PROBLEM = "application/problem+json";
static const char *const CT_METRICS = "text/plain; version=0.0.4; charset=utf-8";
static const char *const ALLOW_GET = "GET, HEAD";
static const char *const ALLOW_POST = "POST";
static const char SCENES_PREFIX[] = "/v1/scenes/";

typedef struct route {
    kdr_endpoint ep;
    const char *scene; /* not NUL-terminated */
    size_t scene_len;
} route;

static int is_post_endpoint(kdr_endpoint ep) {
    return ep == KDR_EP_BUNDLE || ep == KDR_EP_CONE_SHADOW || ep == KDR_EP_FRUSTUM ||
           ep == KDR_EP_CLOSEST_POINT || ep == KDR_EP_OCCUPANCY;
}

/* A render is a GET, but a query all the same: admitted, run and charged
 * by the executor. */
int kdr_route_is_query(kdr_endpoint ep) {
    return is_post_endpoint(ep) || ep == KDR_EP_RENDER;
}

static route match(const char *path);

long kdr_route_scene(kdr_server *srv, const char *path) {
    route r = match(path);
    return r.scene ? kdr_registry_index(srv->registry, r.scene, r.scene_len) : -1;
}

static kdr_endpoint query_endpoint(const char *op) {
    if (!strcmp(op, "bundle")) return KDR_EP_BUNDLE;
    if (!strcmp(op, "cone-shadow")) return KDR_EP_CONE_SHADOW;
    if (!strcmp(op, "frustum")) return KDR_EP_FRUSTUM;
    if (!strcmp(op, "render.png")) return KDR_EP_RENDER;
    if (!strcmp(op, "closest-point")) return KDR_EP_CLOSEST_POINT;
    if (!strcmp(op, "occupancy")) return KDR_EP_OCCUPANCY;
    return KDR_EP_OTHER;
}

static route match(const char *path) {
    route r = {KDR_EP_OTHER, NULL, 0};
    if (!strcmp(path, "/") || !strcmp(path, "/index.html"))
        r.ep = KDR_EP_PAGE;
    else if (!strcmp(path, "/v1/health"))
        r.ep = KDR_EP_HEALTH;
    else if (!strcmp(path, "/v1/ready"))
        r.ep = KDR_EP_READY;
    else if (!strcmp(path, "/metrics"))
        r.ep = KDR_EP_METRICS;
    else if (!strcmp(path, "/v1/scenes"))
        r.ep = KDR_EP_SCENES;
    else if (!strncmp(path, SCENES_PREFIX, sizeof SCENES_PREFIX - 1)) {
        const char *name = path + sizeof SCENES_PREFIX - 1;
        const char *slash = strchr(name, '/');
        r.scene = name;
        r.scene_len = slash ? (size_t)(slash - name) : strlen(name);
        if (r.scene_len == 0)
            r.ep = KDR_EP_OTHER;
        else
            r.ep = slash ? query_endpoint(slash + 1) : KDR_EP_SCENE;
    }
    return r;
}

void kdr_route_problem(kdr_response *out, unsigned status, const char *detail) {
    kdr_proto_error err = {.status = (int)status};
    snprintf(err.detail, sizeof err.detail, "%s", detail);
    kdr_buf b;
    kdr_buf_init(&b);
    out->status = status;
    out->content_type = CT_PROBLEM;
    if (kdr_proto_encode_error(&err, &b) == 0) {
        out->body = b.data;
        out->len = b.len;
        return;
    }
    /* Out of memory (or no encoder): a fixed body that needs no escaping. */
    kdr_buf_free(&b);
    kdr_tb tb = {0};
    kdr_tb_printf(&tb, "{\"type\":\"about:blank\",\"title\":\"%s\",\"status\":%u}",
                  kdr_proto_status_title((int)status), status);
    out->body = kdr_tb_take(&tb, &out->len);
    if (!out->body) out->len = 0;
}

static void problemf(kdr_response *out, unsigned status, const char *fmt, const char *arg,
                     size_t arg_len) {
    char detail[256];
    char a[128];
    snprintf(a, sizeof a, "%.*s", (int)(arg_len < 100 ? arg_len : 100), arg);
    snprintf(detail, sizeof detail, fmt, a);
    kdr_route_problem(out, status, detail);
}

static int not_ready(kdr_server *srv, kdr_response *out) {
    if (atomic_load(&srv->stopping)) {
        kdr_route_problem(out, 503, "shutting down");
        return 1;
    }
    if (kdr_registry_ready(srv->registry)) return 0;
    char detail[96];
    snprintf(detail, sizeof detail, "starting: %zu of %zu scenes built",
             kdr_registry_built(srv->registry), kdr_registry_count(srv->registry));
    kdr_route_problem(out, 503, detail);
    return 1;
}

static int method_ok(kdr_endpoint ep, const char *method) {
    if (is_post_endpoint(ep)) return !strcmp(method, "POST");
    return !strcmp(method, "GET") || !strcmp(method, "HEAD");
}

int kdr_route_precheck(kdr_server *srv, const kdr_request *req, long long content_length,
                       kdr_response *out) {
    route r = match(req->path);
    out->ep = r.ep;
    if (r.ep == KDR_EP_OTHER) {
        problemf(out, 404, "%s: no such path", req->path, strlen(req->path));
        return 1;
    }
    if (!method_ok(r.ep, req->method)) {
        problemf(out, 405, "method %s not allowed here", req->method,
                 strlen(req->method));
        out->allow = is_post_endpoint(r.ep) ? ALLOW_POST : ALLOW_GET;
        return 1;
    }
    if (r.ep != KDR_EP_METRICS && r.ep != KDR_EP_PAGE && not_ready(srv, out)) return 1;
    if (r.scene && kdr_registry_index(srv->registry, r.scene, r.scene_len) < 0) {
        problemf(out, 404, "scene %s: no such scene", r.scene, r.scene_len);
        return 1;
    }
    if (is_post_endpoint(r.ep) &&
        kdr_proto_media_of(req->content_type) == KDR_MEDIA_OTHER) {
        const char *ct = req->content_type ? req->content_type : "(none)";
        problemf(out, 415,
                 "Content-Type %s: expected application/json or application/cbor", ct,
                 strlen(ct));
        return 1;
    }
    if (content_length >= 0 && (unsigned long long)content_length > srv->max_body) {
        char detail[128];
        snprintf(detail, sizeof detail,
                 "body: %lld bytes exceeds the limit of %zu bytes (--max-body-mb)",
                 content_length, srv->max_body);
        kdr_route_problem(out, 413, detail);
        return 1;
    }
    return 0;
}

/* "512 B", "12.5 KiB", "3.0 MiB": sizes in refusals, readable at any scale. */
static const char *size_text(size_t bytes, char *buf, size_t n) {
    if (bytes < 1024)
        snprintf(buf, n, "%zu B", bytes);
    else if (bytes < ((size_t)1 << 20))
        snprintf(buf, n, "%.1f KiB", (double)bytes / 1024.0);
    else
        snprintf(buf, n, "%.1f MiB", (double)bytes / 1048576.0);
    return buf;
}

void kdr_route_refusal(kdr_server *srv, kdr_admit why, size_t bytes, kdr_response *out) {
    char detail[192], a[24], b[24], c[24];
    kdr_exec_stats st;
    kdr_exec_get_stats(srv->exec, &st);
    switch (why) {
    case KDR_ADMIT_QUEUE_FULL:
        snprintf(detail, sizeof detail,
                 "queue full: %zu of %zu queries admitted (--threads + --max-queue)",
                 st.slots_used, st.slots);
        break;
    case KDR_ADMIT_TOO_LARGE:
        snprintf(
            detail, sizeof detail,
            "body: needs about %s in flight, over the limit of %s (--max-inflight-mb)",
            size_text(bytes, a, sizeof a), size_text(st.bytes_max, b, sizeof b));
        kdr_route_problem(out, 413, detail);
        return;
    case KDR_ADMIT_STOPPED:
        kdr_route_problem(out, 503, "shutting down");
        return;
    default:
        snprintf(detail, sizeof detail,
                 "memory: %s of %s in flight, no room for %s more (--max-inflight-mb)",
                 size_text(st.bytes_used, a, sizeof a),
                 size_text(st.bytes_max, b, sizeof b), size_text(bytes, c, sizeof c));
        break;
    }
    kdr_route_problem(out, 503, detail);
    out->retry_after = kdr_exec_retry_after(srv->exec);
}

void kdr_route_answer_buf(kdr_response *out, int rc, kdr_buf *b, const char *ct) {
    if (rc != 0) {
        kdr_buf_free(b);
        kdr_route_problem(out, 503, "out of memory while encoding the answer");
        out->retry_after = 1;
        return;
    }
    out->status = 200;
    out->content_type = ct;
    out->body = b->data;
    out->len = b->len;
}

/* The contract's SCENE object; meshes is scratch space owned by the caller. */
static int scene_info(const char *name, const kdr_scene_version *s,
                      kdr_proto_scene_info *info, kdr_proto_mesh_range **meshes) {
    *meshes = calloc(s->nranges ? s->nranges : 1, sizeof **meshes);
    if (!*meshes) return KDR_ENOMEM;
    for (size_t i = 0; i < s->nranges; i++)
        (*meshes)[i] = (kdr_proto_mesh_range){
            s->ranges[i].node, s->ranges[i].mesh, s->ranges[i].primitive,
            s->ranges[i].first_prim, s->ranges[i].count};
    *info = (kdr_proto_scene_info){.name = name,
                                   .triangles = kdr_scene_triangle_count(s->scene),
                                   .meshes = *meshes,
                                   .nmeshes = s->nranges};
    kdr_scene_bounds(s->scene, &info->bounds);
    kdr_scene_tree_stats(s->scene, &info->tree);
    info->tree.build_ms = s->build_ms; /* as the daemon measured it */
    return 0;
}

/* Each scene's current version is held only while its entry is encoded. */
static void answer_scenes(kdr_server *srv, const route *r, kdr_response *out) {
    size_t first =
        r->scene ? (size_t)kdr_registry_index(srv->registry, r->scene, r->scene_len) : 0;
    size_t n = r->scene ? 1 : kdr_registry_count(srv->registry);
    kdr_proto_scene_info *info = calloc(n ? n : 1, sizeof *info);
    kdr_proto_mesh_range **meshes = calloc(n ? n : 1, sizeof *meshes);
    kdr_scene_version **held = calloc(n ? n : 1, sizeof *held);
    int rc = info && meshes && held ? 0 : KDR_ENOMEM;
    for (size_t i = 0; i < n && rc == 0; i++) {
        held[i] = kdr_registry_acquire(srv->registry, first + i);
        rc = held[i] ? scene_info(kdr_registry_name(srv->registry, first + i), held[i],
                                  &info[i], &meshes[i])
                     : KDR_EINVAL;
    }
    kdr_buf b;
    kdr_buf_init(&b);
    if (rc == 0)
        rc = r->scene ? kdr_proto_encode_scene(&info[0], &b)
                      : kdr_proto_encode_scenes(info, n, &b);
    kdr_route_answer_buf(out, rc, &b, CT_JSON);
    for (size_t i = 0; held && i < n; i++)
        kdr_registry_release(held[i]);
    for (size_t i = 0; meshes && i < n; i++)
        free(meshes[i]);
    free(held);
    free(meshes);
    free(info);
}

/* /v1/ready: what a balancer or a Kubernetes readiness probe asks. 503 while
 * starting or stopping (the precheck), and while the executor is saturated,
 * so traffic goes to a replica with room; 200 otherwise. */
static void answer_ready(kdr_server *srv, kdr_response *out) {
    kdr_exec_stats st;
    kdr_exec_get_stats(srv->exec, &st);
    kdr_tb tb = {0};
    if (kdr_exec_saturated(&st)) {
        char detail[160];
        snprintf(detail, sizeof detail,
                 "saturated: %zu of %zu query slots taken, %.1f of %.1f MiB in flight",
                 st.slots_used, st.slots, (double)st.bytes_used / 1048576.0,
                 (double)st.bytes_max / 1048576.0);
        kdr_route_problem(out, 503, detail);
        out->retry_after = kdr_exec_retry_after(srv->exec);
        return;
    }
    kdr_tb_printf(
        &tb,
        "{\"status\":\"ready\",\"scenes\":%zu,\"workers\":%u,\"busy\":%u,"
        "\"queued\":%zu,\"slots\":%zu,\"slots_used\":%zu,\"inflight_bytes\":%zu,"
        "\"inflight_limit\":%zu}",
        kdr_registry_count(srv->registry), st.workers, st.busy, st.queued, st.slots,
        st.slots_used, st.bytes_used, st.bytes_max);
    out->body = kdr_tb_take(&tb, &out->len);
    if (!out->body) {
        kdr_route_problem(out, 503, "out of memory while answering");
        return;
    }
    out->status = 200;
    out->content_type = CT_JSON;
}

static void answer_metrics(kdr_server *srv, kdr_response *out) {
    kdr_tb tb = {0};
    kdr_exec_stats st;
    kdr_exec_get_stats(srv->exec, &st);
    kdr_metrics_render(&tb);
    kdr_metrics_render_exec(&tb, &st);
    kdr_registry_render_metrics(srv->registry, &tb);
    out->body = kdr_tb_take(&tb, &out->len);
    if (!out->body) {
        kdr_route_problem(out, 503, "out of memory while rendering metrics");
        return;
    }
    out->status = 200;
    out->content_type = CT_METRICS;
}

void kdr_route_handle(kdr_server *srv, const kdr_request *req, kdr_response *out) {
    route r = match(req->path);
    out->ep = r.ep; /* the precheck passed: scenes are built; a shutdown that
                       began since must still let this request finish */
    kdr_buf b;
    kdr_buf_init(&b);
    switch (r.ep) {
    case KDR_EP_HEALTH:
        kdr_route_answer_buf(
            out, kdr_proto_encode_health("ok", kdr_registry_count(srv->registry), &b), &b,
            CT_JSON);
        return;
    case KDR_EP_READY:
        answer_ready(srv, out);
        return;
    case KDR_EP_METRICS:
        answer_metrics(srv, out);
        return;
    case KDR_EP_SCENES:
    case KDR_EP_SCENE:
        answer_scenes(srv, &r, out);
        return;
    case KDR_EP_PAGE:
        kdr_page_answer(out);
        return;
    default: /* queries go through kdr_query_start (http_query.c) */
        kdr_route_problem(out, 404, "no such path");
        return;
    }
}
