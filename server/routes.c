/*
 * routes.c — which path is which endpoint, which method and content type
 * it takes, and the small GET answers (health, metrics, scenes). The query
 * endpoints are answered in query.c. Every error is problem+json, encoded
 * by protocol/.
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
    return ep == KDR_EP_BUNDLE || ep == KDR_EP_CONE_SHADOW || ep == KDR_EP_FRUSTUM;
}

static kdr_endpoint query_endpoint(const char *op) {
    if (!strcmp(op, "bundle")) return KDR_EP_BUNDLE;
    if (!strcmp(op, "cone-shadow")) return KDR_EP_CONE_SHADOW;
    if (!strcmp(op, "frustum")) return KDR_EP_FRUSTUM;
    return KDR_EP_OTHER;
}

static route match(const char *path) {
    route r = {KDR_EP_OTHER, NULL, 0};
    if (!strcmp(path, "/v1/health"))
        r.ep = KDR_EP_HEALTH;
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
    if (r.ep != KDR_EP_METRICS && not_ready(srv, out)) return 1;
    if (r.scene && !kdr_registry_find(srv->registry, r.scene, r.scene_len)) {
        problemf(out, 404, "scene %s: no such scene", r.scene, r.scene_len);
        return 1;
    }
    if (is_post_endpoint(r.ep) && kdr_proto_media_of(req->content_type) == KDR_MEDIA_OTHER) {
        const char *ct = req->content_type ? req->content_type : "(none)";
        problemf(out, 415, "Content-Type %s: expected application/json or application/cbor",
                 ct, strlen(ct));
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

void kdr_route_answer_buf(kdr_response *out, int rc, kdr_buf *b, const char *ct) {
    if (rc != 0) {
        kdr_buf_free(b);
        kdr_route_problem(out, 500, "out of memory while encoding the answer");
        return;
    }
    out->status = 200;
    out->content_type = ct;
    out->body = b->data;
    out->len = b->len;
}

/* The contract's SCENE object; meshes is scratch space owned by the caller. */
static int scene_info(const kdr_served_scene *s, kdr_proto_scene_info *info,
                      kdr_proto_mesh_range **meshes) {
    *meshes = calloc(s->nranges ? s->nranges : 1, sizeof **meshes);
    if (!*meshes) return KDR_ENOMEM;
    for (size_t i = 0; i < s->nranges; i++)
        (*meshes)[i] = (kdr_proto_mesh_range){
            s->ranges[i].node, s->ranges[i].mesh, s->ranges[i].primitive,
            s->ranges[i].first_prim, s->ranges[i].count};
    *info = (kdr_proto_scene_info){.name = s->name,
                                   .triangles = kdr_scene_triangle_count(s->scene),
                                   .meshes = *meshes,
                                   .nmeshes = s->nranges};
    kdr_scene_bounds(s->scene, &info->bounds);
    kdr_scene_tree_stats(s->scene, &info->tree);
    info->tree.build_ms = s->build_ms; /* as the daemon measured it */
    return 0;
}

static void answer_scenes(kdr_server *srv, const route *r, kdr_response *out) {
    size_t n = r->scene ? 1 : kdr_registry_count(srv->registry);
    kdr_proto_scene_info *info = calloc(n, sizeof *info);
    kdr_proto_mesh_range **meshes = calloc(n, sizeof *meshes);
    int rc = info && meshes ? 0 : KDR_ENOMEM;
    for (size_t i = 0; i < n && rc == 0; i++) {
        const kdr_served_scene *s =
            r->scene ? kdr_registry_find(srv->registry, r->scene, r->scene_len)
                     : kdr_registry_at(srv->registry, i);
        rc = scene_info(s, &info[i], &meshes[i]);
    }
    kdr_buf b;
    kdr_buf_init(&b);
    if (rc == 0)
        rc = r->scene ? kdr_proto_encode_scene(&info[0], &b)
                      : kdr_proto_encode_scenes(info, n, &b);
    kdr_route_answer_buf(out, rc, &b, CT_JSON);
    for (size_t i = 0; meshes && i < n; i++)
        free(meshes[i]);
    free(meshes);
    free(info);
}

static void answer_metrics(kdr_server *srv, kdr_response *out) {
    kdr_tb tb = {0};
    kdr_metrics_render(&tb);
    kdr_registry_render_metrics(srv->registry, &tb);
    out->body = kdr_tb_take(&tb, &out->len);
    if (!out->body) {
        kdr_route_problem(out, 500, "out of memory while rendering metrics");
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
        kdr_route_answer_buf(out,
                   kdr_proto_encode_health("ok", kdr_registry_count(srv->registry), &b),
                   &b, CT_JSON);
        return;
    case KDR_EP_METRICS:
        answer_metrics(srv, out);
        return;
    case KDR_EP_SCENES:
    case KDR_EP_SCENE:
        answer_scenes(srv, &r, out);
        return;
    case KDR_EP_BUNDLE:
    case KDR_EP_CONE_SHADOW:
    case KDR_EP_FRUSTUM:
        kdr_query_answer(srv, kdr_registry_find(srv->registry, r.scene, r.scene_len),
                         r.ep, req, out);
        return;
    default:
        kdr_route_problem(out, 404, "no such path");
        return;
    }
}
