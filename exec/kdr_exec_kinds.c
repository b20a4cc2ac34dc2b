/*
 * kdr_exec_kinds.c — the query kinds as the executor runs them: how a body
 * is parsed (protocol/), how much memory the parsed request and the answer
 * take (estimated before anything is allocated, so the claim can be charged
 * first), how one chunk is traced (core/, over a disjoint range of the
 * output) and how the answer is encoded: as JSON or base64 text (its
 * "encoding" member) or as CBOR when the answer media type is CBOR. Bodies
 * are parsed by their media type (JSON or CBOR). Fast and reference modes
 * differ only in the core mode a chunk asks for. Here: what every kind
 * shares, cone-shadow, closest-point, occupancy and the table of kinds; the
 * hit-set kinds (bundle, frustum) are in kdr_exec_hits.c, render in
 * kdr_exec_render.c.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "kdr_exec_internal.h"

/* The encoding an answer is written in: CBOR when the answer media type is
 * CBOR, else the JSON or base64 text the request asked for. */
kdr_encoding kdr_exec_answer_encoding(const kdr_exec_job *j, kdr_encoding asked) {
    const kdr_media m = j->q->answer_media;
    return m == KDR_MEDIA_CBOR || m == KDR_MEDIA_CBOR_SEQ ? KDR_ENCODING_CBOR : asked;
}

/* rc: the encoder's. The answer's Content-Type goes with it. The buffer
 * was allocated at the answer's bound; what the answer did not use goes
 * back to the allocator (a shrinking realloc stays in place), so the claim
 * is settled to what is really held. */
int kdr_exec_encoded(kdr_exec_job *j, int rc, kdr_encoding enc) {
    kdr_buf *b = &j->q->result.body;
    if (rc != 0) kdr_exec_fail(j, 503, "out of memory while encoding the answer");
    j->q->result.content_type = kdr_proto_encoding_media(enc);
    if (rc == 0 && b->len > 0 && b->len < b->cap) {
        char *p = realloc(b->data, b->len);
        if (p) {
            b->data = p;
            b->cap = b->len;
        }
    }
    return rc;
}

/* ---- cone-shadow ---------------------------------------------------------------- */

static int shadow_parse(kdr_exec_job *j) {
    kdr_proto_error err = {0};
    kdr_shadow_request *r = &j->k.shadow.req;
    if (kdr_proto_parse_shadow_as(j->q->media, j->q->body, j->q->len, j->q->max_rays, r,
                                  &err) != 0 ||
        kdr_proto_check_shadow_scene(r, kdr_scene_diagonal(j->q->scene), &err) != 0) {
        kdr_exec_fail_proto(j, &err);
        return -1;
    }
    const kdr_shadow_query *q = &r->query;
    size_t nvis = q->n * q->nlights;
    size_t per = KDR_EXEC_CHUNK_SHADOW_RAYS / (q->nlights * q->samples);
    j->k.shadow.per_chunk = per < 1                       ? 1
                            : per > KDR_EXEC_CHUNK_POINTS ? KDR_EXEC_CHUNK_POINTS
                                                          : per;
    j->nchunks = kdr_exec_chunks_of(q->n, j->k.shadow.per_chunk);
    j->work_rays = (uint64_t)q->n * q->nlights * q->samples;
    /* arrays the parser allocated (not CBOR typed arrays read in place) */
    j->parsed_bytes = (r->owned_points ? 3 * q->n * sizeof(float) : 0) +
                      (r->owned_normals ? 3 * q->n * sizeof(float) : 0) +
                      q->nlights * sizeof(kdr_sphere_light);
    j->answer_estimate =
        nvis * sizeof(float) + j->nchunks * sizeof(kdr_shadow_stats) +
        kdr_exec_answer_block(kdr_proto_shadow_answer_max(
            q->n, q->nlights, r->want_stats, kdr_exec_answer_encoding(j, r->encoding)));
    j->deadline_ms = r->deadline_ms;
    return 0;
}

static int shadow_alloc(kdr_exec_job *j) {
    const kdr_shadow_query *q = &j->k.shadow.req.query;
    size_t nvis = q->n * q->nlights;
    j->k.shadow.visibility = malloc((nvis ? nvis : 1) * sizeof(float));
    j->k.shadow.stats = calloc(j->nchunks ? j->nchunks : 1, sizeof(kdr_shadow_stats));
    return j->k.shadow.visibility && j->k.shadow.stats ? 0 : KDR_ENOMEM;
}

static void shadow_chunk(kdr_exec_job *j, size_t c) {
    const kdr_shadow_query *q = &j->k.shadow.req.query;
    size_t first, count;
    kdr_exec_chunk_range(q->n, j->k.shadow.per_chunk, c, &first, &count);
    kdr_shadow_mode mode =
        j->q->mode == KDR_EXEC_FAST ? KDR_SHADOW_CONE : KDR_SHADOW_RAYS;
    kdr_exec_note_rc(j, kdr_shadow_trace(j->q->scene, q, first, count, mode,
                                         j->k.shadow.visibility, &j->k.shadow.stats[c]));
}

/* The core refuses a point whose offset start lies inside a light (the
 * protocol checked the point itself, and kdr_proto_check_shadow_scene that
 * the offset is finite): name the first such point. */
static void shadow_name_invalid(kdr_exec_job *j) {
    const kdr_shadow_query *q = &j->k.shadow.req.query;
    kdr_ray ray;
    for (size_t i = 0; i < q->n; i++)
        for (size_t l = 0; l < q->nlights; l++)
            if (kdr_shadow_ray(j->q->scene, q, i, l, 0, &ray) == KDR_EINVAL) {
                kdr_exec_fail(j, 400,
                              "points[%zu]: inside lights[%zu] once offset (distance to "
                              "the center <= radius)",
                              i, l);
                return;
            }
}

static int shadow_encode(kdr_exec_job *j) {
    const kdr_shadow_request *r = &j->k.shadow.req;
    kdr_shadow_stats sum = {0, 0, 0};
    for (size_t c = 0; c < j->nchunks; c++) {
        sum.cones_decided += j->k.shadow.stats[c].cones_decided;
        sum.rays_traced += j->k.shadow.stats[c].rays_traced;
        sum.nodes_visited += j->k.shadow.stats[c].nodes_visited;
    }
    const kdr_encoding enc = kdr_exec_answer_encoding(j, r->encoding);
    j->q->result.rays = sum.rays_traced;
    return kdr_exec_encoded(
        j,
        kdr_proto_encode_shadow(j->k.shadow.visibility, r->query.n, r->query.nlights,
                                r->want_stats ? &sum : NULL, enc, &j->q->result.body),
        enc);
}

static void shadow_release(kdr_exec_job *j) {
    free(j->k.shadow.visibility);
    free(j->k.shadow.stats);
    j->k.shadow.visibility = NULL;
    j->k.shadow.stats = NULL;
    kdr_shadow_request_free(&j->k.shadow.req);
}

/* A cone-shadow chunk that failed with KDR_EINVAL hit a point the core
 * refuses: that is the client's 400, not our 500. */
static int shadow_core_error(kdr_exec_job *j, int rc) {
    if (rc != KDR_EINVAL) return 0;
    shadow_name_invalid(j);
    return j->q->result.status == 400;
}

/* ---- closest-point ------------------------------------------------------------------
 */

static int closest_parse(kdr_exec_job *j) {
    kdr_proto_error err = {0};
    kdr_closest_request *r = &j->k.closest.req;
    if (kdr_proto_parse_closest_as(j->q->media, j->q->body, j->q->len, j->q->max_rays, r,
                                   &err) != 0) {
        kdr_exec_fail_proto(j, &err);
        return -1;
    }
    j->parsed_bytes = r->owned_points ? 3 * r->n * sizeof(float) : 0;
    /* results, the encoder's per-member copy, the answer */
    j->answer_estimate =
        r->n * sizeof(kdr_closest) + 3 * r->n * sizeof(float) +
        kdr_exec_answer_block(
            kdr_proto_closest_answer_max(r->n, kdr_exec_answer_encoding(j, r->encoding)));
    j->nchunks = kdr_exec_chunks_of(r->n, KDR_EXEC_CHUNK_CLOSEST);
    j->work_rays = r->n * (r->is_signed ? 1 + (uint64_t)KDR_OCCUPANCY_RAYS : 1);
    j->deadline_ms = r->deadline_ms;
    return 0;
}

static int closest_alloc(kdr_exec_job *j) {
    const size_t n = j->k.closest.req.n;
    j->k.closest.out = malloc((n ? n : 1) * sizeof *j->k.closest.out);
    return j->k.closest.out ? 0 : KDR_ENOMEM;
}

/* One way to search: fast and reference modes are the same. */
static void closest_chunk(kdr_exec_job *j, size_t c) {
    const kdr_closest_request *r = &j->k.closest.req;
    size_t first, count;
    kdr_exec_chunk_range(r->n, KDR_EXEC_CHUNK_CLOSEST, c, &first, &count);
    kdr_exec_note_rc(j, kdr_closest_point_batch(j->q->scene, r->points, first, count,
                                                r->max_distance, j->k.closest.out, NULL));
    if (!r->is_signed) return;
    /* signed: negative inside the closed meshes (the occupancy vote) */
    for (size_t i = first; i < first + count; i++) {
        uint8_t inside = 0;
        const int rc =
            kdr_occupancy1(j->q->scene, r->points + 3 * i, &inside, NULL, NULL);
        if (rc != KDR_OK) {
            kdr_exec_note_rc(j, rc);
            return;
        }
        if (inside) j->k.closest.out[i].distance = -j->k.closest.out[i].distance;
    }
}

static int closest_encode(kdr_exec_job *j) {
    const kdr_closest_request *r = &j->k.closest.req;
    const kdr_encoding enc = kdr_exec_answer_encoding(j, r->encoding);
    j->q->result.rays = r->n;
    return kdr_exec_encoded(
        j, kdr_proto_encode_closest(j->k.closest.out, r->n, enc, &j->q->result.body),
        enc);
}

static void closest_release(kdr_exec_job *j) {
    free(j->k.closest.out);
    j->k.closest.out = NULL;
    kdr_closest_request_free(&j->k.closest.req);
}

/* ---- occupancy ------------------------------------------------------------------------
 */

static int occupancy_parse(kdr_exec_job *j) {
    kdr_proto_error err = {0};
    kdr_occupancy_request *r = &j->k.occupancy.req;
    if (kdr_proto_parse_occupancy_as(j->q->media, j->q->body, j->q->len, j->q->max_rays,
                                     r, &err) != 0) {
        kdr_exec_fail_proto(j, &err);
        return -1;
    }
    j->parsed_bytes = r->owned_points ? 3 * r->n * sizeof(float) : 0;
    j->answer_estimate = r->n + kdr_exec_answer_block(kdr_proto_occupancy_answer_max(
                                    r->n, kdr_exec_answer_encoding(j, r->encoding)));
    j->nchunks = kdr_exec_chunks_of(r->n, KDR_EXEC_CHUNK_OCCUPANCY);
    j->work_rays = r->n * (uint64_t)KDR_OCCUPANCY_RAYS;
    j->deadline_ms = r->deadline_ms;
    return 0;
}

static int occupancy_alloc(kdr_exec_job *j) {
    const size_t n = j->k.occupancy.req.n;
    j->k.occupancy.inside = malloc(n ? n : 1);
    return j->k.occupancy.inside ? 0 : KDR_ENOMEM;
}

static void occupancy_chunk(kdr_exec_job *j, size_t c) {
    const kdr_occupancy_request *r = &j->k.occupancy.req;
    size_t first, count;
    kdr_exec_chunk_range(r->n, KDR_EXEC_CHUNK_OCCUPANCY, c, &first, &count);
    kdr_exec_note_rc(j, kdr_occupancy_batch(j->q->scene, r->points, first, count,
                                            j->k.occupancy.inside, NULL));
}

static int occupancy_encode(kdr_exec_job *j) {
    const kdr_occupancy_request *r = &j->k.occupancy.req;
    const kdr_encoding enc = kdr_exec_answer_encoding(j, r->encoding);
    j->q->result.rays = r->n * (uint64_t)KDR_OCCUPANCY_RAYS;
    return kdr_exec_encoded(
        j,
        kdr_proto_encode_occupancy(j->k.occupancy.inside, r->n, enc, &j->q->result.body),
        enc);
}

static void occupancy_release(kdr_exec_job *j) {
    free(j->k.occupancy.inside);
    j->k.occupancy.inside = NULL;
    kdr_occupancy_request_free(&j->k.occupancy.req);
}

/* ---- the table -------------------------------------------------------------------- */

static const kdr_exec_kind_ops SHADOW = {shadow_parse,   shadow_alloc,
                                         shadow_chunk,   shadow_encode,
                                         shadow_release, shadow_core_error};

static const kdr_exec_kind_ops CLOSEST = {closest_parse,  closest_alloc,   closest_chunk,
                                          closest_encode, closest_release, NULL};

static const kdr_exec_kind_ops OCCUPANCY = {occupancy_parse,   occupancy_alloc,
                                            occupancy_chunk,   occupancy_encode,
                                            occupancy_release, NULL};

const kdr_exec_kind_ops *kdr_exec_ops_for(kdr_exec_kind kind) {
    switch (kind) {
    case KDR_EXEC_BUNDLE:
        return kdr_exec_bundle_ops();
    case KDR_EXEC_FRUSTUM:
        return kdr_exec_frustum_ops();
    case KDR_EXEC_CONE_SHADOW:
        return &SHADOW;
    case KDR_EXEC_RENDER:
        return kdr_exec_render_ops();
    case KDR_EXEC_CLOSEST_POINT:
        return &CLOSEST;
    case KDR_EXEC_OCCUPANCY:
        return &OCCUPANCY;
    }
    return NULL;
}
