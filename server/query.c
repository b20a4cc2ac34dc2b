/*
 * query.c — the three query endpoints: protocol/ parses the body (JSON or
 * CBOR, by Content-Type), the job pool splits the work into chunks over
 * disjoint ranges of the core's range-taking calls, protocol/ encodes the
 * answer (the fields the request chose, in the media type Accept chose).
 * Chunks write disjoint slices of one output, so the answer is the
 * single-threaded answer.
 */
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "kdr_protocol.h"
#include "log.h"
#include "server.h"

/* Chunk sizes: KDR_CHUNK_* in pool.h (kdray-trace splits alike). */

/* The body's media type (the precheck refused any other) and the answer's
 * encoding: CBOR when Accept (or, without one, the request) asks for it,
 * else what the body's "encoding" member said. */
static kdr_media body_media(const kdr_request *req) {
    return kdr_proto_media_of(req->content_type);
}

static kdr_encoding answer_encoding(const kdr_request *req, kdr_encoding asked) {
    return kdr_proto_answer_media(req->accept, body_media(req)) == KDR_MEDIA_CBOR
               ? KDR_ENCODING_CBOR
               : asked;
}

/* What every chunk needs, plus the first core error any chunk saw. */
typedef struct query_job {
    const kdr_scene *scene;
    size_t total, per_chunk;
    kdr_query query;
    kdr_hits hits;
    const kdr_ray_batch *batch;       /* bundle */
    const kdr_frustum_request *frust; /* frustum */
    const kdr_shadow_query *shadow;   /* cone-shadow */
    float *visibility;
    kdr_shadow_stats *shadow_stats; /* one per chunk, summed afterwards */
    atomic_int rc;
} query_job;

static size_t chunk_count(size_t total, size_t per) { return (total + per - 1) / per; }

static void chunk_range(const query_job *j, size_t c, size_t *first, size_t *count) {
    *first = c * j->per_chunk;
    *count = j->total - *first < j->per_chunk ? j->total - *first : j->per_chunk;
}

static void note_rc(query_job *j, int rc) {
    int zero = 0;
    if (rc != KDR_OK) atomic_compare_exchange_strong(&j->rc, &zero, rc);
}

static void bundle_chunk(void *ctx, size_t c) {
    query_job *j = ctx;
    size_t first, count;
    chunk_range(j, c, &first, &count);
    note_rc(j, kdr_trace_batch(j->scene, j->batch, first, count, j->query, KDR_TRAV_AUTO,
                               &j->hits, NULL));
}

static void frustum_chunk(void *ctx, size_t c) {
    query_job *j = ctx;
    size_t first, count;
    chunk_range(j, c, &first, &count);
    note_rc(j, kdr_frustum_trace(j->scene, &j->frust->camera, j->frust->tile, first,
                                 count, j->query, KDR_FRUSTUM_MULTI4, &j->hits, NULL));
}

static void shadow_chunk(void *ctx, size_t c) {
    query_job *j = ctx;
    size_t first, count;
    chunk_range(j, c, &first, &count);
    note_rc(j, kdr_shadow_trace(j->scene, j->shadow, first, count, KDR_SHADOW_CONE,
                                j->visibility, &j->shadow_stats[c]));
}

static void problem_from(kdr_response *out, const kdr_proto_error *err) {
    kdr_route_problem(out, (unsigned)err->status, err->detail);
}

/* A core error after the protocol accepted the request is our bug. */
static void core_failed(kdr_response *out, const char *what, int rc) {
    char detail[160];
    snprintf(detail, sizeof detail, "%s: core error: %s", what, kdr_strerror(rc));
    kdr_log("error: %s", detail);
    kdr_route_problem(out, 500, detail);
}

/* Output arrays for n rays; NULL members on failure. */
static int hits_alloc(kdr_hits *h, size_t n, kdr_query q) {
    memset(h, 0, sizeof *h);
    size_t m = n ? n : 1;
    if (q == KDR_ANY) return (h->hit = malloc(m)) ? 0 : KDR_ENOMEM;
    h->t = malloc(m * sizeof *h->t);
    h->prim = malloc(m * sizeof *h->prim);
    h->u = malloc(m * sizeof *h->u);
    h->v = malloc(m * sizeof *h->v);
    return h->t && h->prim && h->u && h->v ? 0 : KDR_ENOMEM;
}

static void hits_free(kdr_hits *h) {
    free(h->t);
    free(h->prim);
    free(h->u);
    free(h->v);
    free(h->hit);
}

/* Runs j over all chunks and encodes the chosen fields of hits for n rays. */
static void run_hits(kdr_server *srv, query_job *j, kdr_pool_fn fn, size_t n,
                     unsigned fields, kdr_encoding enc, const char *what,
                     kdr_response *out) {
    if (hits_alloc(&j->hits, n, j->query) != 0) {
        hits_free(&j->hits);
        kdr_route_problem(out, 500, "out of memory for the results");
        return;
    }
    kdr_pool_run(srv->pool, chunk_count(j->total, j->per_chunk), fn, j);
    int rc = atomic_load(&j->rc);
    if (rc != KDR_OK) {
        core_failed(out, what, rc);
    } else {
        kdr_buf b;
        kdr_buf_init(&b);
        kdr_route_answer_buf(
            out, kdr_proto_encode_hits_fields(&j->hits, n, j->query, fields, enc, &b), &b,
            kdr_proto_encoding_media(enc));
    }
    hits_free(&j->hits);
}

static void answer_bundle(kdr_server *srv, const kdr_served_scene *s,
                          const kdr_request *req, kdr_response *out) {
    kdr_bundle_request br;
    kdr_proto_error err = {0};
    if (kdr_proto_parse_bundle_as(body_media(req), req->body, req->len, srv->max_rays, &br,
                                  &err) != 0) {
        kdr_bundle_request_free(&br);
        problem_from(out, &err);
        return;
    }
    query_job j = {.scene = s->scene,
                   .total = br.batch.n,
                   .per_chunk = KDR_CHUNK_RAYS,
                   .query = br.query,
                   .batch = &br.batch};
    atomic_init(&j.rc, KDR_OK);
    run_hits(srv, &j, bundle_chunk, br.batch.n, br.fields,
             answer_encoding(req, br.encoding), "bundle", out);
    if (out->status == 200) kdr_metrics_rays(KDR_RAYS_BUNDLE, br.batch.n);
    kdr_bundle_request_free(&br);
}

static void answer_frustum(kdr_server *srv, const kdr_served_scene *s,
                           const kdr_request *req, kdr_response *out) {
    kdr_frustum_request fr;
    kdr_proto_error err = {0};
    if (kdr_proto_parse_frustum_as(body_media(req), req->body, req->len, srv->max_rays, &fr,
                                   &err) != 0) {
        problem_from(out, &err);
        return;
    }
    query_job j = {.scene = s->scene,
                   .total = kdr_frustum_tile_count(&fr.camera, fr.tile),
                   .per_chunk = KDR_CHUNK_TILES,
                   .query = fr.query,
                   .frust = &fr};
    atomic_init(&j.rc, KDR_OK);
    run_hits(srv, &j, frustum_chunk, fr.rays, fr.fields, answer_encoding(req, fr.encoding),
             "frustum", out);
    if (out->status == 200) kdr_metrics_rays(KDR_RAYS_FRUSTUM, fr.rays);
}

/* kdr_shadow_trace refuses a point whose offset start lies inside a light
 * (kdr_proto_check_shadow_scene has already refused an offset that is not
 * finite); name the first one. */
static void shadow_invalid(const kdr_scene *scene, const kdr_shadow_query *q,
                           kdr_response *out) {
    kdr_ray ray;
    for (size_t i = 0; i < q->n; i++)
        for (size_t l = 0; l < q->nlights; l++)
            if (kdr_shadow_ray(scene, q, i, l, 0, &ray) == KDR_EINVAL) {
                char detail[128];
                snprintf(detail, sizeof detail,
                         "points[%zu]: inside lights[%zu] once offset (distance to "
                         "the center <= radius)",
                         i, l);
                kdr_route_problem(out, 400, detail);
                return;
            }
    core_failed(out, "cone-shadow", KDR_EINVAL);
}

static void shadow_stats_sum(const kdr_shadow_stats *per, size_t n,
                             kdr_shadow_stats *sum) {
    memset(sum, 0, sizeof *sum);
    for (size_t c = 0; c < n; c++) {
        sum->cones_decided += per[c].cones_decided;
        sum->rays_traced += per[c].rays_traced;
        sum->nodes_visited += per[c].nodes_visited;
    }
}

static void run_shadow(kdr_server *srv, const kdr_served_scene *s,
                       const kdr_shadow_request *sr, kdr_encoding enc, kdr_response *out) {
    const kdr_shadow_query *q = &sr->query;
    size_t nchunks = chunk_count(q->n, KDR_CHUNK_POINTS);
    size_t nvis = q->n * q->nlights;
    query_job j = {.scene = s->scene,
                   .total = q->n,
                   .per_chunk = KDR_CHUNK_POINTS,
                   .shadow = q,
                   .visibility = malloc((nvis ? nvis : 1) * sizeof(float)),
                   .shadow_stats =
                       calloc(nchunks ? nchunks : 1, sizeof(kdr_shadow_stats))};
    atomic_init(&j.rc, KDR_OK);
    if (!j.visibility || !j.shadow_stats) {
        kdr_route_problem(out, 500, "out of memory for the results");
    } else {
        kdr_pool_run(srv->pool, nchunks, shadow_chunk, &j);
        int rc = atomic_load(&j.rc);
        kdr_shadow_stats sum;
        shadow_stats_sum(j.shadow_stats, nchunks, &sum);
        if (rc == KDR_EINVAL)
            shadow_invalid(s->scene, q, out);
        else if (rc != KDR_OK)
            core_failed(out, "cone-shadow", rc);
        else {
            kdr_buf b;
            kdr_buf_init(&b);
            kdr_route_answer_buf(out,
                       kdr_proto_encode_shadow(j.visibility, q->n, q->nlights,
                                               sr->want_stats ? &sum : NULL, enc, &b),
                       &b, kdr_proto_encoding_media(enc));
            kdr_metrics_rays(KDR_RAYS_SHADOW, sum.rays_traced);
        }
    }
    free(j.visibility);
    free(j.shadow_stats);
}

static void answer_shadow(kdr_server *srv, const kdr_served_scene *s,
                          const kdr_request *req, kdr_response *out) {
    kdr_shadow_request sr;
    kdr_proto_error err = {0};
    if (kdr_proto_parse_shadow_as(body_media(req), req->body, req->len, srv->max_rays, &sr,
                                  &err) != 0 ||
        kdr_proto_check_shadow_scene(&sr, kdr_scene_diagonal(s->scene), &err) != 0) {
        kdr_shadow_request_free(&sr);
        problem_from(out, &err);
        return;
    }
    run_shadow(srv, s, &sr, answer_encoding(req, sr.encoding), out);
    kdr_shadow_request_free(&sr);
}

void kdr_query_answer(kdr_server *srv, const kdr_served_scene *scene, kdr_endpoint ep,
                      const kdr_request *req, kdr_response *out) {
    if (!scene) {
        kdr_route_problem(out, 404, "no such scene");
        return;
    }
    switch (ep) {
    case KDR_EP_BUNDLE:
        answer_bundle(srv, scene, req, out);
        return;
    case KDR_EP_FRUSTUM:
        answer_frustum(srv, scene, req, out);
        return;
    case KDR_EP_CONE_SHADOW:
        answer_shadow(srv, scene, req, out);
        return;
    default:
        kdr_route_problem(out, 404, "no such query");
        return;
    }
}
