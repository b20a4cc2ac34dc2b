/*
 * kdr_exec_stream.c — streamed answers (see kdr_exec.h): which queries can
 * stream, what their items are, when an item is ready, and its encoding.
 *
 * An item is a contiguous range of the answer's rays, so that a client
 * appends items to get the one-shot arrays: a bundle or cone-shadow item
 * is one chunk; a frustum item is one row of tiles (tiles are traced in
 * row-major order by chunks of 16, and a row of tiles is whole rows of
 * pixels, which is how the answer's arrays are laid out). Readiness is
 * read from the per-chunk flags the workers set (acquire, pairing with
 * their release), so the caller reads each item's output only after every
 * chunk that wrote it is done. No one-shot answer is encoded (for hits it
 * is as large as the result arrays). A bundle stream's result arrays are a
 * window of chunk slots (chunk c in slot c % window): the scheduler opens
 * chunk c only once item c - window has been taken (release_slot), so a
 * reader that stops stalls the query instead of growing its memory.
 * Frustum and cone-shadow streams keep the batch's arrays: the core writes
 * frustum pixels by image index, and visibilities are small.
 */
#include <stdlib.h>
#include <string.h>

#include "kdr_exec_internal.h"

/* Pixels of one frustum item: a row of tiles. */
static size_t frustum_item_rows(const kdr_frustum_request *r) { return r->tile; }

static size_t frustum_tiles_x(const kdr_frustum_request *r) {
    return (r->camera.width + r->tile - 1) / r->tile;
}

int kdr_exec_stream_check(kdr_exec_job *j) {
    const kdr_exec_query *q = j->q;
    /* the result arrays (a bundle's: its window of slots) plus one item's
     * bound, the only encoded bytes held at a time */
    switch (q->kind) {
    case KDR_EXEC_BUNDLE: {
        const kdr_bundle_request *r = &j->k.bundle.req;
        if (r->query != KDR_CLOSEST && r->query != KDR_ANY) break;
        /* a window of chunk slots, not the batch's arrays */
        j->window =
            j->nchunks < KDR_EXEC_STREAM_WINDOW ? j->nchunks : KDR_EXEC_STREAM_WINDOW;
        const size_t n = j->window * KDR_EXEC_CHUNK_RAYS, per = KDR_EXEC_CHUNK_RAYS;
        j->answer_estimate =
            (r->query == KDR_ANY ? n : 16 * n) + per * 24 +
            kdr_exec_answer_block(
                kdr_proto_hits_answer_max(per, r->query, r->fields, KDR_ENCODING_CBOR)) +
            64;
        return 0;
    }
    case KDR_EXEC_FRUSTUM: {
        const kdr_frustum_request *r = &j->k.frustum.req;
        const size_t n = r->rays, per = frustum_item_rows(r) * r->camera.width;
        j->answer_estimate =
            (r->query == KDR_ANY ? n : 16 * n) + per * 24 +
            kdr_exec_answer_block(
                kdr_proto_hits_answer_max(per, r->query, r->fields, KDR_ENCODING_CBOR)) +
            64;
        return 0;
    }
    case KDR_EXEC_CONE_SHADOW: {
        const kdr_shadow_query *s = &j->k.shadow.req.query;
        j->answer_estimate =
            s->n * s->nlights * sizeof(float) + j->nchunks * sizeof(kdr_shadow_stats) +
            kdr_exec_answer_block(kdr_proto_shadow_answer_max(j->k.shadow.per_chunk,
                                                              s->nlights, 0,
                                                              KDR_ENCODING_CBOR)) +
            64;
        return 0;
    }
    default:
        break;
    }
    kdr_exec_fail(j, 406,
                  "Accept: application/cbor-seq streams bundle (closest, any), "
                  "cone-shadow and frustum answers only; ask application/cbor");
    return -1;
}

void kdr_exec_stream_finish(kdr_exec_job *j) {
    kdr_exec_result *r = &j->q->result;
    switch (j->q->kind) {
    case KDR_EXEC_BUNDLE:
        r->rays = j->k.bundle.req.batch.n;
        break;
    case KDR_EXEC_FRUSTUM:
        r->rays = j->k.frustum.req.rays;
        break;
    case KDR_EXEC_CONE_SHADOW:
        r->rays = 0;
        for (size_t c = 0; c < j->nchunks; c++)
            r->rays += j->k.shadow.stats[c].rays_traced;
        break;
    default:
        break;
    }
}

int kdr_exec_stream_ready(const kdr_exec_query *q) {
    return q->job && atomic_load(&q->job->stream_ready);
}

size_t kdr_exec_stream_items(const kdr_exec_query *q) {
    const kdr_exec_job *j = q->job;
    if (!kdr_exec_stream_ready(q)) return 0;
    if (q->kind == KDR_EXEC_FRUSTUM) {
        const kdr_frustum_request *r = &j->k.frustum.req;
        const size_t rows = frustum_item_rows(r);
        return (r->camera.height + rows - 1) / rows;
    }
    return j->nchunks;
}

/* The last chunk item i needs. */
static size_t last_chunk(const kdr_exec_job *j, size_t i) {
    if (j->q->kind != KDR_EXEC_FRUSTUM) return i;
    const size_t tx = frustum_tiles_x(&j->k.frustum.req);
    return ((i + 1) * tx - 1) / KDR_EXEC_CHUNK_TILES;
}

int kdr_exec_stream_item_ready(kdr_exec_query *q, size_t i) {
    kdr_exec_job *j = q->job;
    if (!kdr_exec_stream_ready(q) || i >= kdr_exec_stream_items(q)) return 0;
    const size_t need = last_chunk(j, i) + 1;
    while (j->stream_prefix < need &&
           atomic_load_explicit(&j->chunk_done[j->stream_prefix], memory_order_acquire))
        j->stream_prefix++;
    return j->stream_prefix >= need;
}

static const char *kind_name(kdr_exec_kind k) {
    return k == KDR_EXEC_FRUSTUM       ? "frustum"
           : k == KDR_EXEC_CONE_SHADOW ? "cone-shadow"
                                       : "bundle";
}

int kdr_exec_stream_head(const kdr_exec_query *q, kdr_buf *out) {
    const kdr_exec_job *j = q->job;
    size_t count = 0;
    if (q->kind == KDR_EXEC_BUNDLE) count = j->k.bundle.req.batch.n;
    if (q->kind == KDR_EXEC_FRUSTUM) count = j->k.frustum.req.rays;
    if (q->kind == KDR_EXEC_CONE_SHADOW) count = j->k.shadow.req.query.n;
    return kdr_proto_seq_head(out, kind_name(q->kind), count, kdr_exec_stream_items(q));
}

/* Item i - 1 is encoded: its slot may take chunk i - 1 + window. Workers
 * idle for want of a claimable chunk are woken (the executor's lock is
 * taken for that only: once per item). */
static void release_slot(kdr_exec_job *j, size_t taken) {
    atomic_store(&j->released, taken);
    if (taken + j->window > j->nchunks) return; /* no chunk left to open */
    pthread_mutex_lock(&j->ex->lock);
    pthread_cond_broadcast(&j->ex->work);
    pthread_mutex_unlock(&j->ex->lock);
}

int kdr_exec_stream_item(const kdr_exec_query *q, size_t i, kdr_buf *out) {
    const kdr_exec_job *j = q->job;
    kdr_buf slice;
    kdr_buf_init(&slice);
    size_t first = 0, count = 0;
    int rc;
    if (q->kind == KDR_EXEC_BUNDLE) {
        const kdr_bundle_request *r = &j->k.bundle.req;
        kdr_exec_chunk_range(r->batch.n, KDR_EXEC_CHUNK_RAYS, i, &first, &count);
        const size_t at = j->window ? (i % j->window) * KDR_EXEC_CHUNK_RAYS : first;
        rc = kdr_exec_hits_slice(q, &j->k.bundle.hits, at, count, r->query, r->fields,
                                 &slice);
    } else if (q->kind == KDR_EXEC_FRUSTUM) {
        const kdr_frustum_request *r = &j->k.frustum.req;
        const size_t w = r->camera.width;
        kdr_exec_chunk_range(r->camera.height, frustum_item_rows(r), i, &first, &count);
        first *= w;
        count *= w;
        rc = kdr_exec_hits_slice(q, &j->k.frustum.hits, first, count, r->query, r->fields,
                                 &slice);
    } else {
        const kdr_shadow_query *s = &j->k.shadow.req.query;
        kdr_exec_chunk_range(s->n, j->k.shadow.per_chunk, i, &first, &count);
        rc = kdr_proto_encode_shadow(j->k.shadow.visibility + first * s->nlights, count,
                                     s->nlights, NULL, KDR_ENCODING_CBOR, &slice);
    }
    if (rc == 0) rc = kdr_proto_seq_item(out, first, &slice);
    kdr_buf_free(&slice);
    if (j->window && rc == 0) release_slot(q->job, i + 1);
    return rc;
}

int kdr_exec_stream_end(const kdr_exec_query *q, size_t items_sent, kdr_buf *out) {
    const kdr_exec_result *r = &q->result;
    if (r->status != 200) return kdr_proto_seq_problem(out, r->status, r->detail);
    kdr_shadow_stats sum = {0, 0, 0};
    const kdr_shadow_stats *stats = NULL;
    const kdr_exec_job *j = q->job;
    if (q->kind == KDR_EXEC_CONE_SHADOW && j->k.shadow.req.want_stats) {
        for (size_t c = 0; c < j->nchunks; c++) {
            sum.cones_decided += j->k.shadow.stats[c].cones_decided;
            sum.rays_traced += j->k.shadow.stats[c].rays_traced;
            sum.nodes_visited += j->k.shadow.stats[c].nodes_visited;
        }
        stats = &sum;
    }
    const double s[3] = {r->queued_s, r->parse_s, r->trace_s};
    uint64_t us[3];
    for (int k = 0; k < 3; k++)
        us[k] = s[k] > 0 ? (uint64_t)(s[k] * 1e6 + 0.5) : 0;
    return kdr_proto_seq_end(out, r->rays, items_sent, us, stats);
}
