/*
 * kdr_exec_internal.h — what the scheduler (kdr_exec.c), a job's steps
 * (kdr_exec_job.c), its books (kdr_exec_admit.c) and the query kinds
 * (kdr_exec_kinds.c, kdr_exec_hits.c, kdr_exec_render.c) share: the
 * executor struct, the job that carries one query through it, and the table
 * of steps each kind implements. Not installed, not used outside exec/.
 */
#ifndef KDR_EXEC_INTERNAL_H
#define KDR_EXEC_INTERNAL_H

#include <pthread.h>
#include <stdatomic.h>

#include "kdr_exec.h"

/* A job's place in its life; changed under the executor's lock. */
typedef enum job_state {
    JOB_QUEUED,    /* waiting for a worker */
    JOB_PREPARING, /* one worker parses it and allocates the outputs */
    JOB_RUNNING,   /* chunks are claimed by any worker */
    JOB_FINISHING, /* one thread encodes the answer and settles the claim */
} job_state;

/* One query kind: parse the body and size the work, allocate the outputs,
 * trace a chunk, encode the answer, free everything the kind allocated.
 * parse and encode report errors through kdr_exec_fail(). core_error (may be
 * NULL) turns a core error that is really the client's into a problem
 * answer and returns 1; otherwise a core error is a 500 (our bug). */
typedef struct kdr_exec_kind_ops {
    int (*parse)(kdr_exec_job *j);
    int (*alloc)(kdr_exec_job *j);
    void (*chunk)(kdr_exec_job *j, size_t c);
    int (*encode)(kdr_exec_job *j);
    void (*release)(kdr_exec_job *j);
    int (*core_error)(kdr_exec_job *j, int rc);
} kdr_exec_kind_ops;

struct kdr_exec_job {
    kdr_exec *ex;
    kdr_exec_query *q;
    const kdr_exec_kind_ops *ops;

    /* scheduling (under ex->lock) */
    job_state state;
    unsigned users; /* workers inside the job */
    int picked;     /* a worker has taken it (it counts as running) */
    int inline_run; /* traced on the caller's thread (kdr_exec_try_inline) */
    kdr_exec_job *link;

    /* set by parse, read by every worker once the job runs */
    size_t nchunks;
    uint64_t work_rays;     /* worst-case rays: bundle N, frustum pixels,
                               cone-shadow points x lights x samples */
    size_t parsed_bytes;    /* the parsed request's arrays */
    size_t answer_estimate; /* result arrays + encoded answer */
    double deadline;        /* absolute (kdr_exec_now), 0 = none */
    double deadline_ms;     /* the one applied, for the message */

    atomic_size_t next;  /* next chunk to claim */
    atomic_size_t done;  /* chunks finished */
    atomic_int stop;     /* kdr_exec_stop, first reason wins */
    atomic_int cancel;   /* kdr_exec_cancel was called */
    atomic_int core_rc;  /* first core error of any chunk */
    atomic_llong cpu_ns; /* thread CPU time spent on it, summed */

    double t_submit, t_pick, t_trace0, t_trace1;

    /* streamed answers (q->stream; kdr_exec_stream.c) */
    atomic_uchar *chunk_done; /* nchunks flags, set once a chunk is traced */
    atomic_int stream_ready;  /* parsed, allocated, chunks open */
    size_t stream_prefix;     /* the caller's: chunks [0, prefix) are traced */
    /* bundle streams: chunk c is traced into slot c % window of the result
     * arrays, so no chunk may be claimed before the item window chunks
     * before it has been taken (encoded) by the caller; 0: no window */
    size_t window;
    atomic_size_t released; /* items the caller has taken */

    /* completion, for kdr_exec_wait */
    pthread_mutex_t m;
    pthread_cond_t cv;
    int finished;

    /* the kind's own state */
    union {
        struct {
            kdr_bundle_request req;
            kdr_hits hits;    /* closest, any */
            kdr_all_hits all; /* all: max_hits slots per ray; count: nhits */
            int32_t *offset;  /* all: n + 1, filled when encoding */
        } bundle;
        struct {
            kdr_frustum_request req;
            kdr_hits hits;
        } frustum;
        struct {
            kdr_shadow_request req;
            float *visibility;
            kdr_shadow_stats *stats; /* one per chunk, summed by encode */
            size_t per_chunk;        /* points */
        } shadow;
        struct {
            kdr_render_params p; /* framed */
            kdr_render_image img;
            kdr_render_stats *stats;    /* one per band, summed by encode */
            kdr_render_png_stream *png; /* fed by each band as it ends */
        } render;
        struct {
            kdr_closest_request req;
            kdr_closest *out; /* one per point */
        } closest;
        struct {
            kdr_occupancy_request req;
            uint8_t *inside; /* one per point */
        } occupancy;
    } k;
};

/* The executor: its job list, its threads and its books. */
struct kdr_exec {
    pthread_mutex_t lock;
    pthread_cond_t work; /* a job may be ready for a worker, or stop */
    kdr_exec_job *head, *tail;
    int stop;
    atomic_int shutting_down;
    kdr_exec_config cfg;
    size_t slots;
    /* books, under lock */
    size_t slots_used, queued, running, bytes_used;
    unsigned busy;
    uint64_t admitted, rejected_queue, rejected_memory, rejected_too_large;
    uint64_t completed, deadlines, cancelled, shutdown, out_of_memory;
    double mean_s;
    unsigned nthreads;
    pthread_t threads[];
};

/* Under ex->lock: returns c's queue slot if it still holds one. */
void kdr_exec_drop_slot(kdr_exec *ex, kdr_exec_claim *c);

/* The step table of a kind (kdr_exec_kinds.c). */
const kdr_exec_kind_ops *kdr_exec_ops_for(kdr_exec_kind kind);

/* Records a problem answer on the job's result (the first one wins). */
void kdr_exec_fail(kdr_exec_job *j, int status, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 3, 4)))
#endif
    ;
/* A protocol error: 500 (protocol/ runs out of memory) becomes 503. */
void kdr_exec_fail_proto(kdr_exec_job *j, const kdr_proto_error *err);
/* The render kind's step table (kdr_exec_render.c). */
const kdr_exec_kind_ops *kdr_exec_render_ops(void);
/* Notes a core error from a chunk (the first one wins). */
void kdr_exec_note_rc(kdr_exec_job *j, int rc);
/* Stream queries (kdr_exec_stream.c): a 406 problem when the query cannot
 * stream (0 when it can); the rays of a finished stream query. */
int kdr_exec_stream_check(kdr_exec_job *j);
void kdr_exec_stream_finish(kdr_exec_job *j);
/* Chunks a windowed stream may trace ahead of the items taken. */
#define KDR_EXEC_STREAM_WINDOW 16

/* What q's body holds (kdr_exec_query.body_held, at least its length). */
static inline size_t kdr_exec_body_held(const kdr_exec_query *q) {
    return q->body_held > q->len ? q->body_held : q->len;
}
/* What an answer encoded into an empty kdr_buf holds: the encoder reserves
 * the answer's bound at once, in a kdr_block_alloc block. */
static inline size_t kdr_exec_answer_block(size_t bound) { return kdr_block_size(bound); }
/* The one-shot CBOR answer of hits [first, first + count) (kdr_exec_hits.c). */
int kdr_exec_hits_slice(const kdr_exec_query *q, const kdr_hits *h, size_t first,
                        size_t count, kdr_query query, unsigned fields, kdr_buf *out);
/* ---- one job's steps (kdr_exec_job.c) ---- */
/* CPU time of the calling thread, ns. */
long long kdr_exec_thread_cpu_ns(void);
/* Records why j stops (the first reason wins). */
void kdr_exec_set_stop(kdr_exec_job *j, kdr_exec_stop why);
/* Checked before every chunk: cancelled, shutting down or past the deadline. */
kdr_exec_stop kdr_exec_check_stop(kdr_exec_job *j);
/* Sets j's deadline from the caller's and the request's (0: none). */
void kdr_exec_apply_deadline(kdr_exec_job *j, double request_ms);
/* The problem answer of a job stopped for why. */
void kdr_exec_stopped_result(kdr_exec_job *j, kdr_exec_stop why);
/* Parses the body, charges and allocates; sets nchunks (0 when the job
 * already has its answer: an error, or a stop before it began). */
void kdr_exec_prepare_work(kdr_exec *ex, kdr_exec_job *j);
/* ---- shared by the kinds (kdr_exec_kinds.c, kdr_exec_hits.c) ---- */
/* The encoding an answer is written in: CBOR when the answer media type
 * is CBOR, else the JSON or base64 text the request asked for. */
kdr_encoding kdr_exec_answer_encoding(const kdr_exec_job *j, kdr_encoding asked);
/* After an encoder (rc its result): records its failure or the answer's
 * Content-Type, and gives back what the answer's bound did not use. */
int kdr_exec_encoded(kdr_exec_job *j, int rc, kdr_encoding enc);
/* Chunks of per items that cover total items. */
static inline size_t kdr_exec_chunks_of(size_t total, size_t per) {
    return (total + per - 1) / per;
}
/* The step tables of bundle and frustum (kdr_exec_hits.c). */
const kdr_exec_kind_ops *kdr_exec_bundle_ops(void);
const kdr_exec_kind_ops *kdr_exec_frustum_ops(void);
/* First item and count of chunk c, for work of total items in chunks of per. */
void kdr_exec_chunk_range(size_t total, size_t per, size_t c, size_t *first,
                          size_t *count);

#endif
