/*
 * kdr_exec_hits.c — the two query kinds whose answer is a set of hits, one
 * per ray: bundle (closest, any, all, count) and frustum (closest or any
 * per pixel). Their result arrays are sized and charged before they are
 * allocated, each chunk traces a disjoint range of them (core/), and the
 * answer encodes only the fields the request chose (t, hit, prim, normal,
 * mesh), with per-hit attributes looked up from the scene's mesh ranges. A
 * streamed answer encodes a slice of the same arrays per item
 * (kdr_exec_hits_slice, for kdr_exec_stream.c).
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "kdr_exec_internal.h"

/* Result arrays plus the encoded answer's bound (protocol/ knows it exactly
 * for every encoding and field set, and allocates no more): only the
 * fields asked for are encoded, though the core fills every result array
 * of the query. */
static size_t hits_estimate(size_t n, kdr_query q, unsigned fields, kdr_encoding enc) {
    size_t arrays = q == KDR_ANY ? n : n * (3 * sizeof(float) + sizeof(int32_t));
    return arrays + kdr_exec_answer_block(kdr_proto_hits_answer_max(n, q, fields, enc));
}

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
    memset(h, 0, sizeof *h);
}

/* ---- per-hit attributes ("normal", "mesh") ------------------------------------------
 */

/* Bytes of the attribute arrays for entries hits (3 floats + 3 int32). */
static size_t attrs_bytes(unsigned fields, size_t entries) {
    return fields & KDR_FIELDS_ATTRS ? entries * 24 : 0;
}

/* The range holding prim (they tile [0, ntris) in order), or NULL. */
static const kdr_proto_mesh_range *range_of(const kdr_exec_query *q, int32_t prim) {
    size_t lo = 0, hi = q->nmeshes;
    while (lo < hi) {
        const size_t mid = lo + (hi - lo) / 2;
        if ((uint64_t)prim < q->meshes[mid].first_prim)
            hi = mid;
        else if ((uint64_t)prim >= q->meshes[mid].first_prim + q->meshes[mid].count)
            lo = mid + 1;
        else
            return &q->meshes[mid];
    }
    return NULL;
}

/* Fills normal / mesh (3 per entry) for prims[0..n): the unit normal of
 * (p1-p0) x (p2-p0) computed in double, and the glTF indices; a miss (prim
 * < 0) gets 0,0,0 and -1,-1,-1. Allocates both arrays (freed by the
 * caller); KDR_ENOMEM. */
static int attrs_fill(const kdr_exec_query *q, const int32_t *prims, size_t n,
                      float **normal, int32_t **mesh) {
    *normal = malloc((n ? 3 * n : 1) * sizeof **normal);
    *mesh = malloc((n ? 3 * n : 1) * sizeof **mesh);
    if (!*normal || !*mesh) return KDR_ENOMEM;
    for (size_t i = 0; i < n; i++) {
        float *nv = *normal + 3 * i;
        int32_t *mv = *mesh + 3 * i;
        nv[0] = nv[1] = nv[2] = 0.0f;
        mv[0] = mv[1] = mv[2] = -1;
        const float *t =
            prims[i] >= 0 ? kdr_scene_triangle(q->scene, (size_t)prims[i]) : NULL;
        if (!t) continue;
        double e1[3], e2[3];
        for (int k = 0; k < 3; k++) {
            e1[k] = (double)t[3 + k] - t[k];
            e2[k] = (double)t[6 + k] - t[k];
        }
        const double c[3] = {e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2],
                             e1[0] * e2[1] - e1[1] * e2[0]};
        const double len = sqrt(c[0] * c[0] + c[1] * c[1] + c[2] * c[2]);
        for (int k = 0; k < 3; k++)
            nv[k] = len > 0 ? (float)(c[k] / len) : 0.0f;
        const kdr_proto_mesh_range *r = range_of(q, prims[i]);
        if (r) {
            mv[0] = (int32_t)r->node;
            mv[1] = (int32_t)r->mesh;
            mv[2] = (int32_t)r->primitive;
        }
    }
    return 0;
}

/* Bytes of the arrays of a hits answer with these fields (its size less
 * the CBOR heads). */
static size_t hits_array_bytes(size_t n, kdr_query query, unsigned fields) {
    size_t b = 0;
    if (fields & KDR_FIELD_HIT) b += n;
    if (query == KDR_ANY) return b;
    for (unsigned bit = KDR_FIELD_T; bit <= KDR_FIELD_V; bit <<= 1)
        if (fields & bit) b += 4 * n;
    return b + (fields & KDR_FIELD_NORMAL ? 12 * n : 0) + (fields & KDR_FIELD_MESH ? 12 * n : 0);
}

/* Moves block (bytes long) into p, or frees it when no piece uses it. */
static void pieces_take(kdr_exec_pieces *p, void *block, size_t bytes, int used) {
    if (!block) return;
    if (!used) {
        free(block);
        return;
    }
    p->blocks[p->nblocks++] = block;
    p->held += bytes;
}

void kdr_exec_pieces_free(void *pieces) {
    kdr_exec_pieces *p = pieces;
    if (!p) return;
    for (size_t i = 0; i < p->nblocks; i++)
        free(p->blocks[i]);
    kdr_buf_free(&p->head);
    free(p);
}

/* The answer in pieces (kdr_exec_query.pieces): the heads are written, the
 * arrays stay where the core wrote them and move, with the attribute
 * arrays, from the job (h is emptied) to the result's pieces. */
static int pieces_hits(kdr_exec_job *j, kdr_hits *h, size_t n, kdr_query query,
                       unsigned fields, float *normal, int32_t *mesh) {
    kdr_exec_pieces *p = calloc(1, sizeof *p);
    uint8_t *hit_bytes = NULL;
    const kdr_hit_attrs attrs = {normal, mesh};
    int rc = p ? kdr_proto_hits_pieces(h, &attrs, n, query, fields, &p->head, &hit_bytes,
                                       p->v, &p->n)
               : KDR_ENOMEM;
    if (rc != 0) {
        free(hit_bytes);
        free(normal);
        free(mesh);
        kdr_exec_pieces_free(p);
        return rc;
    }
    for (size_t i = 0; i < p->n; i++)
        p->len += p->v[i].len;
    p->held = p->head.cap;
    const size_t f4 = 4 * n;
    pieces_take(p, h->t, f4, (fields & KDR_FIELD_T) != 0);
    pieces_take(p, h->prim, f4, (fields & KDR_FIELD_PRIM) != 0);
    pieces_take(p, h->u, f4, (fields & KDR_FIELD_U) != 0);
    pieces_take(p, h->v, f4, (fields & KDR_FIELD_V) != 0);
    pieces_take(p, h->hit, n, (fields & KDR_FIELD_HIT) != 0);
    pieces_take(p, hit_bytes, n, 1);
    pieces_take(p, normal, 3 * f4, 1);
    pieces_take(p, mesh, 3 * f4, 1);
    memset(h, 0, sizeof *h);
    j->q->result.pieces = p;
    return 0;
}

/* Encodes closest / any hits with the attributes the fields ask for: in
 * pieces when the caller takes them and the answer is large CBOR, else
 * into one buffer. */
static int encode_hits(kdr_exec_job *j, kdr_hits *h, size_t n, kdr_query query,
                       unsigned fields, kdr_encoding enc) {
    float *normal = NULL;
    int32_t *mesh = NULL;
    int rc = 0;
    if (fields & KDR_FIELDS_ATTRS) rc = attrs_fill(j->q, h->prim, n, &normal, &mesh);
    if (rc == 0 && j->q->pieces && enc == KDR_ENCODING_CBOR &&
        hits_array_bytes(n, query, fields) >= KDR_EXEC_PIECES_MIN) {
        rc = pieces_hits(j, h, n, query, fields, normal, mesh);
        /* normal and mesh now belong to the pieces (or were freed) */
        j->q->result.content_type = kdr_proto_encoding_media(enc);
        if (rc != 0) kdr_exec_fail(j, 503, "out of memory while encoding the answer");
        return rc;
    }
    const kdr_hit_attrs attrs = {normal, mesh};
    if (rc == 0) /* the core's arrays: misses are in wire form already */
        rc = kdr_proto_encode_hits_wire(h, &attrs, n, query, fields, enc,
                                        &j->q->result.body);
    free(normal);
    free(mesh);
    return kdr_exec_encoded(j, rc, enc);
}

/* The view of h's arrays from ray `at` on: hit for any-hit queries,
 * t, prim, u, v for closest ones (the others stay NULL). */
static kdr_hits hits_from(const kdr_hits *h, size_t at, kdr_query query) {
    kdr_hits s = {0};
    if (query == KDR_ANY) {
        s.hit = h->hit + at;
    } else {
        s.t = h->t + at;
        s.prim = h->prim + at;
        s.u = h->u + at;
        s.v = h->v + at;
    }
    return s;
}

/* One streamed item's slice of hits [first, first + count): its one-shot
 * CBOR answer, attributes included (kdr_exec_stream.c puts "first" in). */
int kdr_exec_hits_slice(const kdr_exec_query *q, const kdr_hits *h, size_t first,
                        size_t count, kdr_query query, unsigned fields, kdr_buf *out) {
    kdr_hits s = hits_from(h, first, query);
    float *normal = NULL;
    int32_t *mesh = NULL;
    int rc = 0;
    if (fields & KDR_FIELDS_ATTRS) rc = attrs_fill(q, s.prim, count, &normal, &mesh);
    const kdr_hit_attrs attrs = {normal, mesh};
    if (rc == 0)
        rc = kdr_proto_encode_hits_attrs(&s, &attrs, count, query, fields,
                                         KDR_ENCODING_CBOR, out);
    free(normal);
    free(mesh);
    return rc;
}

/* ---- bundle ------------------------------------------------------------------ */

static int bundle_parse(kdr_exec_job *j) {
    kdr_proto_error err = {0};
    kdr_bundle_request *r = &j->k.bundle.req;
    if (kdr_proto_parse_bundle_as(j->q->media, j->q->body, j->q->len, j->q->max_rays, r,
                                  &err) != 0) {
        kdr_exec_fail_proto(j, &err);
        return -1;
    }
    const kdr_ray_batch *b = &r->batch;
    /* arrays the parser allocated; a CBOR typed array read in place
     * (owned[i] NULL) lives in the body, which is charged already */
    const size_t floats[4] = {b->org_stride ? 3 * b->n : 3, 3 * b->n,
                              b->tmin_stride ? b->n : 1, b->tmax_stride ? b->n : 1};
    j->parsed_bytes = 0;
    for (int i = 0; i < 4; i++)
        if (r->owned[i]) j->parsed_bytes += floats[i] * sizeof(float);
    const kdr_encoding enc = kdr_exec_answer_encoding(j, r->encoding);
    if (r->query == KDR_ALL) /* slots, offsets, attributes, answer */
        j->answer_estimate = b->n * (size_t)r->max_hits * 16 + (2 * b->n + 1) * 4 +
                             attrs_bytes(r->fields, b->n * (size_t)r->max_hits) +
                             kdr_exec_answer_block(kdr_proto_all_answer_max(
                                 b->n, r->max_hits, r->fields, enc));
    else if (r->query == KDR_COUNT)
        j->answer_estimate =
            b->n * 4 + kdr_exec_answer_block(kdr_proto_counts_answer_max(b->n, enc));
    else
        j->answer_estimate =
            hits_estimate(b->n, r->query, r->fields, enc) + attrs_bytes(r->fields, b->n);
    j->nchunks = kdr_exec_chunks_of(b->n, KDR_EXEC_CHUNK_RAYS);
    j->work_rays = b->n;
    j->deadline_ms = r->deadline_ms;
    return 0;
}

static int bundle_alloc(kdr_exec_job *j) {
    const kdr_bundle_request *r = &j->k.bundle.req;
    kdr_all_hits *a = &j->k.bundle.all;
    memset(a, 0, sizeof *a);
    j->k.bundle.offset = NULL;
    memset(&j->k.bundle.hits, 0, sizeof j->k.bundle.hits);
    const size_t n = r->batch.n ? r->batch.n : 1;
    if (r->query == KDR_COUNT)
        return (a->nhits = malloc(n * sizeof *a->nhits)) ? 0 : KDR_ENOMEM;
    if (j->window) /* a stream's slots (kdr_exec_stream.c) */
        return hits_alloc(&j->k.bundle.hits, j->window * KDR_EXEC_CHUNK_RAYS, r->query);
    if (r->query != KDR_ALL) return hits_alloc(&j->k.bundle.hits, r->batch.n, r->query);
    const size_t slots = n * r->max_hits;
    a->nhits = malloc(n * sizeof *a->nhits);
    a->t = malloc(slots * sizeof *a->t);
    a->u = malloc(slots * sizeof *a->u);
    a->v = malloc(slots * sizeof *a->v);
    a->prim = malloc(slots * sizeof *a->prim);
    j->k.bundle.offset = malloc((n + 1) * sizeof *j->k.bundle.offset);
    return a->nhits && a->t && a->u && a->v && a->prim && j->k.bundle.offset ? 0
                                                                             : KDR_ENOMEM;
}

/* p + k, NULL staying NULL (no arithmetic on a null pointer). */
static const float *from(const float *p, size_t k) { return p ? p + k : p; }

static void bundle_chunk(kdr_exec_job *j, size_t c) {
    const kdr_bundle_request *r = &j->k.bundle.req;
    size_t first, count;
    kdr_exec_chunk_range(r->batch.n, KDR_EXEC_CHUNK_RAYS, c, &first, &count);
    if (r->query == KDR_ALL) { /* one way to walk: both modes are the same */
        kdr_exec_note_rc(j, kdr_all_batch(j->q->scene, &r->batch, first, count,
                                          r->max_hits, &j->k.bundle.all, NULL));
        return;
    }
    if (r->query == KDR_COUNT) {
        kdr_exec_note_rc(j, kdr_count_batch(j->q->scene, &r->batch, first, count,
                                            j->k.bundle.all.nhits, NULL));
        return;
    }
    kdr_trav_mode mode = j->q->mode == KDR_EXEC_FAST ? KDR_TRAV_AUTO : KDR_TRAV_SINGLE;
    if (j->window) {
        /* a stream's chunk: rays [first, first + count) as a batch of their
         * own into slot c % window (answers are per ray, so the same) */
        const kdr_ray_batch *b = &r->batch;
        const kdr_ray_batch view = {count,
                                    from(b->org, b->org_stride * first),
                                    b->org_stride,
                                    from(b->dir, 3 * first),
                                    from(b->tmin, b->tmin_stride * first),
                                    b->tmin_stride,
                                    from(b->tmax, b->tmax_stride * first),
                                    b->tmax_stride};
        const kdr_hits *h = &j->k.bundle.hits;
        const size_t at = (c % j->window) * KDR_EXEC_CHUNK_RAYS;
        kdr_hits slot = hits_from(h, at, r->query);
        kdr_exec_note_rc(j, kdr_trace_batch(j->q->scene, &view, 0, count, r->query, mode,
                                            &slot, NULL));
        return;
    }
    kdr_exec_note_rc(j, kdr_trace_batch(j->q->scene, &r->batch, first, count, r->query,
                                        mode, &j->k.bundle.hits, NULL));
}

/* The all answer's flat arrays: each ray's hits moved down from its slots
 * (ray i's slots start at i * max_hits >= its flat offset, so moving in
 * ray order never overwrites what is still to be moved). */
static void all_compact(kdr_exec_job *j) {
    const kdr_bundle_request *r = &j->k.bundle.req;
    kdr_all_hits *a = &j->k.bundle.all;
    int32_t *off = j->k.bundle.offset;
    size_t at = 0;
    for (size_t i = 0; i < r->batch.n; i++) {
        off[i] = (int32_t)at;
        const size_t from = i * (size_t)r->max_hits, m = a->nhits[i];
        if (from != at) {
            memmove(a->t + at, a->t + from, m * sizeof *a->t);
            memmove(a->u + at, a->u + from, m * sizeof *a->u);
            memmove(a->v + at, a->v + from, m * sizeof *a->v);
            memmove(a->prim + at, a->prim + from, m * sizeof *a->prim);
        }
        at += m;
    }
    off[r->batch.n] = (int32_t)at;
}

static int bundle_encode(kdr_exec_job *j) {
    const kdr_bundle_request *r = &j->k.bundle.req;
    const kdr_encoding enc = kdr_exec_answer_encoding(j, r->encoding);
    j->q->result.rays = r->batch.n;
    if (r->query == KDR_COUNT)
        return kdr_exec_encoded(j,
                                kdr_proto_encode_counts(j->k.bundle.all.nhits, r->batch.n,
                                                        enc, &j->q->result.body),
                                enc);
    if (r->query == KDR_ALL) {
        all_compact(j);
        const kdr_all_hits *a = &j->k.bundle.all;
        float *normal = NULL;
        int32_t *mesh = NULL;
        int rc = 0;
        if (r->fields & KDR_FIELDS_ATTRS)
            rc = attrs_fill(j->q, a->prim, (size_t)j->k.bundle.offset[r->batch.n],
                            &normal, &mesh);
        const kdr_all_answer ans = {r->batch.n,
                                    (const int32_t *)(const void *)a->nhits,
                                    j->k.bundle.offset,
                                    a->t,
                                    a->u,
                                    a->v,
                                    a->prim,
                                    {normal, mesh}};
        if (rc == 0) rc = kdr_proto_encode_all(&ans, r->fields, enc, &j->q->result.body);
        free(normal);
        free(mesh);
        return kdr_exec_encoded(j, rc, enc);
    }
    return encode_hits(j, &j->k.bundle.hits, r->batch.n, r->query, r->fields, enc);
}

static void bundle_release(kdr_exec_job *j) {
    hits_free(&j->k.bundle.hits);
    kdr_all_hits *a = &j->k.bundle.all;
    free(a->nhits);
    free(a->t);
    free(a->u);
    free(a->v);
    free(a->prim);
    memset(a, 0, sizeof *a);
    free(j->k.bundle.offset);
    j->k.bundle.offset = NULL;
    kdr_bundle_request_free(&j->k.bundle.req);
}

/* ---- frustum ------------------------------------------------------------------ */

static int frustum_parse(kdr_exec_job *j) {
    kdr_proto_error err = {0};
    kdr_frustum_request *r = &j->k.frustum.req;
    if (kdr_proto_parse_frustum_as(j->q->media, j->q->body, j->q->len, j->q->max_rays, r,
                                   &err) != 0) {
        kdr_exec_fail_proto(j, &err);
        return -1;
    }
    j->parsed_bytes = 0; /* a camera: nothing beyond the job itself */
    j->answer_estimate = hits_estimate(r->rays, r->query, r->fields,
                                       kdr_exec_answer_encoding(j, r->encoding)) +
                         attrs_bytes(r->fields, r->rays);
    j->nchunks = kdr_exec_chunks_of(kdr_frustum_tile_count(&r->camera, r->tile),
                                    KDR_EXEC_CHUNK_TILES);
    j->work_rays = r->rays;
    j->deadline_ms = r->deadline_ms;
    return 0;
}

static int frustum_alloc(kdr_exec_job *j) {
    return hits_alloc(&j->k.frustum.hits, j->k.frustum.req.rays, j->k.frustum.req.query);
}

static void frustum_chunk(kdr_exec_job *j, size_t c) {
    const kdr_frustum_request *r = &j->k.frustum.req;
    size_t first, count;
    kdr_exec_chunk_range(kdr_frustum_tile_count(&r->camera, r->tile),
                         KDR_EXEC_CHUNK_TILES, c, &first, &count);
    kdr_frustum_mode mode =
        j->q->mode == KDR_EXEC_FAST ? KDR_FRUSTUM_MULTI4 : KDR_FRUSTUM_RAYS;
    kdr_exec_note_rc(j, kdr_frustum_trace(j->q->scene, &r->camera, r->tile, first, count,
                                          r->query, mode, &j->k.frustum.hits, NULL));
}

static int frustum_encode(kdr_exec_job *j) {
    const kdr_frustum_request *r = &j->k.frustum.req;
    const kdr_encoding enc = kdr_exec_answer_encoding(j, r->encoding);
    j->q->result.rays = r->rays;
    return encode_hits(j, &j->k.frustum.hits, r->rays, r->query, r->fields, enc);
}

static void frustum_release(kdr_exec_job *j) { hits_free(&j->k.frustum.hits); }

/* ---- their steps -------------------------------------------------------------- */

static const kdr_exec_kind_ops BUNDLE = {bundle_parse,  bundle_alloc,   bundle_chunk,
                                         bundle_encode, bundle_release, NULL};
static const kdr_exec_kind_ops FRUSTUM = {frustum_parse,  frustum_alloc,   frustum_chunk,
                                          frustum_encode, frustum_release, NULL};

const kdr_exec_kind_ops *kdr_exec_bundle_ops(void) { return &BUNDLE; }

const kdr_exec_kind_ops *kdr_exec_frustum_ops(void) { return &FRUSTUM; }
