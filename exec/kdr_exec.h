/*
 * kdr_exec.h — the query executor: admission against a memory budget and a
 * queue bound, a FIFO of queries and a fixed pool of worker threads that
 * parse, trace and encode them. kdrayd and kdray-trace both run every
 * bundle, cone-shadow and frustum query through it; nothing here knows HTTP.
 *
 * Unit of work. A query is parsed by one worker (protocol/), then cut into
 * chunks (4096 rays, 16 frustum tiles or 64 shadow points) that any idle
 * worker claims; chunks write disjoint slices of one output, so the answer
 * is the single-threaded answer whatever the thread count. The worker that
 * finishes the last chunk encodes the answer. Between two chunks a worker
 * checks the query's deadline and whether it was cancelled, so a query
 * stops within one chunk of either. A front end that wants to trace while
 * the body still arrives, or to send each chunk's answer as it is ready,
 * plugs in here: the chunk is the unit both would use.
 *
 * Admission. A caller claims a queue slot and bytes (kdr_exec_admit) before
 * it allocates anything for a request, and grows the claim as it learns
 * more (body bytes of a chunked upload, kdr_exec_charge). The executor then
 * charges the query's own memory to the same claim before it is allocated:
 * the parse (protocol/'s meter counts every block, cJSON's included, and
 * asks for more of the claim when the body's parse share is used up), then
 * the arrays the parse kept, the result arrays and the answer's bound for
 * its encoding and fields. A claim that does not fit is refused (the
 * caller answers 503 with Retry-After), or KDR_ADMIT_TOO_LARGE (413) when
 * it would not fit even in an empty executor. Slots count queries from admission until
 * their answer is encoded; bytes stay charged until the caller releases the claim (after
 * the answer has been sent).
 *
 * Threads. Every function may be called from any thread. A query struct is
 * owned by its caller and must stay alive (with its body and scene) until
 * kdr_exec_wait has returned 1, or its on_done callback has been called. A
 * caller either blocks in kdr_exec_wait (kdray-trace) or goes on with other
 * work and is called back (kdrayd's HTTP threads), polling now and then
 * (kdr_exec_wait with timeout 0) so that a queued query past its deadline is
 * answered even while every worker is busy.
 */
#ifndef KDR_EXEC_H
#define KDR_EXEC_H

#include <stddef.h>
#include <stdint.h>

#include "kdr_protocol.h"
#include "kdr_render.h"
#include "kdray.h"

#ifdef __cplusplus
extern "C" {
#endif

/* Rays, tiles and points per chunk. A frustum chunk is a multiple of 4
 * tiles so that the four frusta traversed together are never split. A
 * cone-shadow chunk has at most CHUNK_POINTS points and, when there are
 * many lights and samples, only as many as keep its worst case near
 * CHUNK_SHADOW_RAYS shadow rays (at least one point), so that a deadline
 * or a cancel is noticed within tens of milliseconds there too. */
#define KDR_EXEC_CHUNK_RAYS 4096
#define KDR_EXEC_CHUNK_TILES 16
#define KDR_EXEC_CHUNK_POINTS 64
/* Arrays of an answer in pieces (kdr_exec_query.pieces): at least 1 MiB
 * (64K closest hits, 1M any hits). A smaller answer is copied into one
 * buffer as before (its copy takes at most ~0.1-0.2 ms; one buffer lets
 * libmicrohttpd send headers and body in one write, and answers of one
 * chunk, which kdrayd may answer on its HTTP thread, keep the path they
 * were measured on). Not measured at the boundary: the round "answers
 * without copies" in docs/BENCHMARKS.md measured 1M rays (the copy of a
 * 16 MB answer: 4-8 ms of encode). */
#define KDR_EXEC_PIECES_MIN ((size_t)1 << 20)
#define KDR_EXEC_CHUNK_SHADOW_RAYS 65536
/* closest-point: points per chunk (a few microseconds each) */
#define KDR_EXEC_CHUNK_CLOSEST 2048
/* occupancy: points per chunk (9 hit counts each) */
#define KDR_EXEC_CHUNK_OCCUPANCY 512
/* Bytes charged per body byte for parsing it, up front: what a JSON body of
 * usual decimals takes (1.3 per byte while its float arrays grow; CBOR
 * typed arrays take none). A parse that needs more is charged more as it
 * allocates (kdr_exec_job.c, metered_parse). The body itself is charged on
 * top. */
#define KDR_EXEC_PARSE_BYTES_PER_BODY_BYTE 2

typedef struct kdr_exec kdr_exec;

typedef struct kdr_exec_config {
    unsigned workers; /* threads that parse, trace and encode; >= 1 */
    size_t max_queue; /* queries admitted beyond one per worker */
    size_t max_bytes; /* bytes in flight over all claims; 0 = no limit */
    /* optional: run first on every worker thread (kdrayd lowers their
     * scheduling priority there, so its HTTP threads answer at once) */
    void (*on_worker_start)(void *ctx);
    void *worker_ctx;
} kdr_exec_config;

/* NULL on failure (errno set). */
kdr_exec *kdr_exec_create(const kdr_exec_config *cfg);
/* Joins the workers. Every query must be done and every claim released. */
void kdr_exec_destroy(kdr_exec *ex);

/* ---- admission ------------------------------------------------------------- */

typedef enum kdr_admit {
    KDR_ADMIT_OK = 0,
    KDR_ADMIT_QUEUE_FULL,  /* every slot is taken: retry later */
    KDR_ADMIT_MEMORY_FULL, /* the budget has no room now: retry later */
    KDR_ADMIT_TOO_LARGE,   /* more than the whole budget: never fits */
    KDR_ADMIT_STOPPED,     /* the executor is shutting down */
} kdr_admit;

/* One request's share of the executor. Zero-initialise; release once. */
typedef struct kdr_exec_claim {
    size_t bytes; /* charged now */
    int slot;     /* holds a queue slot */
} kdr_exec_claim;

/* Takes a queue slot and charges bytes. Nothing is taken on refusal. */
kdr_admit kdr_exec_admit(kdr_exec *ex, kdr_exec_claim *c, size_t bytes);
/* Charges more bytes to an admitted claim (the slot is not re-checked). */
kdr_admit kdr_exec_charge(kdr_exec *ex, kdr_exec_claim *c, size_t more);
/* Sets the claim's charge to bytes without a check: for measured sizes that
 * replace an estimate (an answer is never larger than its estimate by more
 * than the estimate's error). */
void kdr_exec_settle(kdr_exec *ex, kdr_exec_claim *c, size_t bytes);
/* Returns the slot (if still held) and every byte. NULL-safe. */
void kdr_exec_release(kdr_exec *ex, kdr_exec_claim *c);
/* Seconds a refused client should wait: the recent mean query time times
 * the queries ahead, over the workers; 1..60. */
unsigned kdr_exec_retry_after(kdr_exec *ex);
/* Bytes a body of len bytes is charged at admission (body + parse). */
size_t kdr_exec_body_charge(size_t len);

/* ---- queries ----------------------------------------------------------------- */

typedef enum kdr_exec_kind {
    KDR_EXEC_BUNDLE,
    KDR_EXEC_CONE_SHADOW,
    KDR_EXEC_FRUSTUM,
    KDR_EXEC_RENDER, /* a picture (render/): q->render, no body; PNG answer */
    KDR_EXEC_CLOSEST_POINT, /* issue 15: nearest triangle of each point */
    KDR_EXEC_OCCUPANCY,     /* issue 15: inside/outside by voting */
} kdr_exec_kind;

typedef enum kdr_exec_mode {
    KDR_EXEC_FAST,      /* what kdrayd serves: bundles, 4 frusta, cones */
    KDR_EXEC_REFERENCE, /* single rays, per-pixel rays, per-sample rays */
} kdr_exec_mode;

typedef enum kdr_exec_stop {
    KDR_STOP_NONE,
    KDR_STOP_DEADLINE,  /* the deadline passed: 503 */
    KDR_STOP_CANCELLED, /* kdr_exec_cancel: the caller no longer wants it */
    KDR_STOP_SHUTDOWN,  /* kdr_exec_shutdown: 503 */
} kdr_exec_stop;

/* A 200 answer in pieces (kdr_exec_query.pieces): sent one after another
 * (writev), pieces v[0..n) are the answer's len bytes, the same bytes the
 * one-buffer answer has. The struct owns the blocks they lie in (the
 * result arrays the core wrote, the attribute arrays, the CBOR heads), so
 * the arrays go out where they are, with no copy; held is what those
 * blocks take (charged to the query's claim until the caller releases it).
 * kdr_exec_pieces_free frees all of it (its type fits libmicrohttpd's free
 * callback). */
#define KDR_EXEC_PIECES_BLOCKS 8
typedef struct kdr_exec_pieces {
    size_t n, len, held;
    kdr_piece v[KDR_HITS_PIECES_MAX];
    kdr_buf head;
    void *blocks[KDR_EXEC_PIECES_BLOCKS];
    size_t nblocks;
} kdr_exec_pieces;
void kdr_exec_pieces_free(void *pieces);

typedef struct kdr_exec_result {
    int status;               /* 200, or the problem's status */
    char detail[256];         /* problem detail when status != 200 */
    kdr_buf body;             /* the 200 answer (unless pieces is set) */
    kdr_exec_pieces *pieces;  /* or the 200 answer in pieces (query.pieces) */
    const char *content_type; /* of a 200 answer: application/json or
                                 application/cbor (a static string) */
    unsigned retry_after;     /* > 0 on a 503 that a later retry may cure */
    kdr_exec_stop stopped;
    uint64_t rays;      /* bundle rays, frustum pixels, shadow rays traced */
    uint64_t work_rays; /* the worst case the request asked for: bundle
                           rays, frustum pixels, points x lights x samples */
    size_t chunks, chunks_done;
    double queued_s, parse_s, trace_s, encode_s; /* wall times */
    double cpu_s;       /* thread CPU time of parsing, every chunk and encoding */
    double deadline_ms; /* the deadline applied, 0: none */
    /* KDR_EXEC_RENDER: statistics and stage times summed over the bands
     * (primary_s, shadow_s, shade_s: thread CPU time summed over the
     * workers), and the PNG encoder's thread CPU time */
    kdr_render_stats render;
    double png_s;
} kdr_exec_result;

typedef struct kdr_exec_job kdr_exec_job;

typedef struct kdr_exec_query {
    /* filled by the caller */
    kdr_exec_kind kind;
    kdr_exec_mode mode;
    const kdr_scene *scene;
    /* the scene's glTF (node, mesh, primitive) ranges, for the "mesh"
     * answer field; NULL / 0: every hit's mesh is -1,-1,-1 */
    const kdr_proto_mesh_range *meshes;
    size_t nmeshes;
    const char *body; /* not NUL-terminated; a CBOR body's float arrays
                         are read in place, so it must outlive q (above) */
    size_t len;
    /* bytes the body's buffer really holds, charged while the query lives:
     * a kdr_block_alloc block's kdr_block_size(len), a grown buffer's
     * capacity; 0 (or less than len) means len */
    size_t body_held;
    kdr_media media;        /* the body's type (Content-Type); JSON is 0 */
    kdr_media answer_media; /* the answer's (Accept, kdr_proto_answer_media):
                               CBOR, or JSON for the JSON or base64 text the
                               request's "encoding" member asks for */
    size_t max_rays;        /* protocol limit (0: the protocol default) */
    double start;           /* kdr_exec_now() when the request began */
    double deadline_ms;     /* the caller's deadline from start, 0 = none; a
                               request's "deadline_ms" can only shorten it */
    kdr_exec_claim *claim;  /* charged as the query grows; NULL: unlimited */
    /* KDR_EXEC_RENDER: the parameters as given (copied, then framed by the
     * executor, so the caller's copy need not outlive submission) */
    const kdr_render_params *render;
    /* optional: called once, by the thread that finished q, after the
     * result is filled (kdr_exec_wait already returns 1). It must not block;
     * q may be freed by another thread as soon as it is called. */
    void (*on_done)(void *ctx);
    void *done_ctx;
    /* A streamed answer (kdrayd, Accept: application/cbor-seq; bundle
     * closest/any, cone-shadow and frustum only, else a 406): no one-shot
     * answer is encoded; the caller takes the answer item by item
     * (kdr_exec_stream_*) while later chunks trace. The result arrays stay
     * allocated (and charged) until kdr_exec_query_done. */
    int stream;
    /* The caller can send an answer in pieces (kdrayd): a one-shot CBOR
     * answer of closest or any hits (bundle, frustum) of at least
     * KDR_EXEC_PIECES_MIN bytes of arrays comes in result.pieces, its
     * arrays where the core wrote them, instead of being copied into
     * result.body. 0: always result.body (kdray-trace). */
    int pieces;
    /* optional, stream only: called (with done_ctx) once the parse
     * succeeded and the chunks opened, and after every chunk traced, by the
     * worker; it must not block. Never called after on_done. */
    void (*on_progress)(void *ctx);
    /* filled by the executor once kdr_exec_wait returns 1 */
    kdr_exec_result result;
    kdr_exec_job *job; /* private */
} kdr_exec_query;

/* Queues q. 0, or KDR_ENOMEM / KDR_EINVAL (q untouched, nothing queued). */
int kdr_exec_submit(kdr_exec *ex, kdr_exec_query *q);
/* The short way for small requests, on the caller's own thread: parses q
 * there and, when its whole work is one chunk of at most inline_rays
 * worst-case rays (or it already has its answer, e.g. a 400), traces and
 * encodes it there too and returns 1 with q->result filled (on_done is not
 * called). Otherwise returns 0: q is parsed, charged and allocated but not
 * yet with the workers; hand it over with kdr_exec_enqueue (a caller that
 * must get ready for on_done first, such as suspending a connection, does
 * that in between). < 0: KDR_ENOMEM / KDR_EINVAL, nothing started. For
 * kdrayd a 1-ray query then costs no thread hand-off (wrk, 1 connection,
 * shared 2-core box: median 20-22 us, against 94-107 us through a worker). */
int kdr_exec_try_inline(kdr_exec *ex, kdr_exec_query *q, size_t inline_rays);
void kdr_exec_enqueue(kdr_exec *ex, kdr_exec_query *q);
/* Waits up to timeout_s seconds (< 0: no limit). 1 when q is done and
 * q->result is filled, 0 on timeout. */
int kdr_exec_wait(kdr_exec_query *q, double timeout_s);
/* Asks q to stop at its next chunk (a queued q is finished at once). The
 * caller still waits for it; the result is then KDR_STOP_CANCELLED. */
void kdr_exec_cancel(kdr_exec_query *q);
/* After kdr_exec_wait returned 1: frees the job and the result body or
 * pieces (unless the caller took them: set q->result.body to {0},
 * q->result.pieces to NULL). */
void kdr_exec_query_done(kdr_exec_query *q);
/* ---- streamed answers (kdr_exec_stream.c) ----------------------------------------
 * One caller thread at a time takes a stream query's items, in order:
 * the head, items 0..kdr_exec_stream_items-1 as each is ready, then the
 * final item once kdr_exec_wait returned 1. Item i is ready once every
 * chunk it covers is traced (a bundle or cone-shadow item is one chunk, a
 * frustum item one row of tiles, whole rows of pixels). Each function
 * appends to out and returns 0, or KDR_ENOMEM. */

/* 1 once the query was parsed, its arrays allocated and its chunks opened:
 * the answer will stream. 0 before, and for a query that failed first (its
 * result is then an ordinary problem). */
int kdr_exec_stream_ready(const kdr_exec_query *q);
size_t kdr_exec_stream_items(const kdr_exec_query *q);
int kdr_exec_stream_item_ready(kdr_exec_query *q, size_t i);
int kdr_exec_stream_head(const kdr_exec_query *q, kdr_buf *out);
int kdr_exec_stream_item(const kdr_exec_query *q, size_t i, kdr_buf *out);
/* After kdr_exec_wait returned 1: {"status": 200, ...} when the query
 * succeeded, else its problem (q->result.status, detail). */
int kdr_exec_stream_end(const kdr_exec_query *q, size_t items_sent, kdr_buf *out);

/* Refuses new admissions and stops every query in flight at its next
 * chunk with a 503 "shutting down". */
void kdr_exec_shutdown(kdr_exec *ex);

/* Monotonic clock, seconds. */
double kdr_exec_now(void);

/* ---- statistics -------------------------------------------------------------- */

typedef struct kdr_exec_stats {
    unsigned workers, busy;   /* busy: workers inside a query */
    size_t slots, slots_used; /* slots = workers + max_queue */
    size_t queued, running;   /* submitted, waiting / started */
    size_t bytes_max, bytes_used;
    uint64_t admitted, rejected_queue, rejected_memory, rejected_too_large;
    uint64_t completed, deadlines, cancelled, shutdown, out_of_memory;
    double mean_query_s; /* recent mean, first pick-up to done */
} kdr_exec_stats;

void kdr_exec_get_stats(kdr_exec *ex, kdr_exec_stats *out);
/* 1 when a new query would be refused for lack of a slot, or less than a
 * tenth of the byte budget is free. */
int kdr_exec_saturated(const kdr_exec_stats *s);

#ifdef __cplusplus
}
#endif
#endif /* KDR_EXEC_H */
