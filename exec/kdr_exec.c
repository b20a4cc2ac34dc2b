/*
 * kdr_exec.c — the executor's scheduler and its books (see kdr_exec.h).
 *
 * One mutex guards the job list, the admission counters and the statistics
 * (the books themselves are kept in kdr_exec_admit.c);
 * it is held for a few pointer moves at a time, never while a body is
 * parsed, a chunk traced or an answer encoded, so a metrics scrape or an
 * admission never waits behind a query. Jobs sit in one FIFO list from
 * submission until a thread starts finishing them. A free worker takes the
 * first job that has work for it: a queued job (the worker parses it, alone,
 * through kdr_exec_job.c) or a running job with chunks left to claim. Chunk
 * indices are claimed with an atomic increment. A job is finished (encoded,
 * settled, signalled) by whichever thread sees it last: the worker that
 * leaves it with no chunk left, or a canceller that finds it idle.
 */
#define _POSIX_C_SOURCE 200809L
#include <errno.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "kdr_exec_internal.h"

/* Weight of the newest query in the running mean behind Retry-After. */
static const double MEAN_WEIGHT = 0.2;

/* A worker's first step on a queued job: prepare it, then open its chunks
 * to every worker. */
static void prepare_job(kdr_exec *ex, kdr_exec_job *j) {
    kdr_exec_prepare_work(ex, j);
    /* Before the chunks open: another worker may trace them all and
     * finish the job (reading t_trace0) before this one gets the lock back. */
    j->t_trace0 = kdr_exec_now();
    pthread_mutex_lock(&ex->lock);
    j->state = JOB_RUNNING;
    if (j->nchunks > 1) pthread_cond_broadcast(&ex->work);
    pthread_mutex_unlock(&ex->lock);
    /* this worker is still inside the job, so it cannot finish meanwhile */
    if (j->q->on_progress && atomic_load(&j->stream_ready))
        j->q->on_progress(j->q->done_ctx);
}

/* Chunks below this may be claimed: all of them, or for a windowed stream
 * those whose slot the caller has emptied (kdr_exec_stream.c). */
static size_t claim_limit(kdr_exec_job *j) {
    if (!j->window) return j->nchunks;
    const size_t lim = atomic_load(&j->released) + j->window;
    return lim < j->nchunks ? lim : j->nchunks;
}

/* Claims the next chunk; SIZE_MAX when none may be claimed now. */
static size_t claim(kdr_exec_job *j) {
    size_t c = atomic_load(&j->next);
    do {
        if (c >= claim_limit(j)) return SIZE_MAX;
    } while (!atomic_compare_exchange_weak(&j->next, &c, c + 1));
    return c;
}

static void drain(kdr_exec_job *j) {
    long long cpu0 = kdr_exec_thread_cpu_ns();
    for (;;) {
        if (kdr_exec_check_stop(j) != KDR_STOP_NONE) break;
        size_t c = claim(j);
        if (c == SIZE_MAX) break;
        j->ops->chunk(j, c);
        atomic_fetch_add(&j->done, 1);
        if (j->chunk_done) {
            /* release: the caller that sees the flag sees the chunk's output */
            atomic_store_explicit(&j->chunk_done[c], 1, memory_order_release);
            if (j->q->on_progress) j->q->on_progress(j->q->done_ctx);
        }
    }
    atomic_fetch_add(&j->cpu_ns, kdr_exec_thread_cpu_ns() - cpu0);
}

/* Under lock: unlinks j from the list. */
static void unlink_job(kdr_exec *ex, kdr_exec_job *j) {
    kdr_exec_job **pp = &ex->head, *prev = NULL;
    while (*pp && *pp != j) {
        prev = *pp;
        pp = &(*pp)->link;
    }
    if (!*pp) return;
    *pp = j->link;
    if (ex->tail == j) ex->tail = prev;
    j->link = NULL;
}

static int out_of_memory(const kdr_exec_result *r) {
    return r->status == 503 && r->stopped == KDR_STOP_NONE &&
           (strstr(r->detail, "out of memory") || strstr(r->detail, "memory:"));
}

/* Encodes (or records why not), frees the kind's arrays, settles the claim,
 * updates the books and wakes the waiter. j is in state FINISHING, off the
 * list, with no worker inside. */
static void finish_job(kdr_exec_job *j) {
    kdr_exec *ex = j->ex;
    kdr_exec_query *q = j->q;
    kdr_exec_result *r = &q->result;
    double t_end = kdr_exec_now();
    long long cpu0 = kdr_exec_thread_cpu_ns();
    kdr_exec_stop stop = (kdr_exec_stop)atomic_load(&j->stop);
    int rc = atomic_load(&j->core_rc);
    r->chunks = j->nchunks;
    r->chunks_done = atomic_load(&j->done);
    if (r->status == 0) {
        if (stop != KDR_STOP_NONE)
            kdr_exec_stopped_result(j, stop);
        else if (rc != KDR_OK) {
            if (!j->ops->core_error || !j->ops->core_error(j, rc))
                kdr_exec_fail(j, 500, "core error: %s", kdr_strerror(rc));
        } else if (q->stream) {
            kdr_exec_stream_finish(j); /* the caller encodes, item by item */
            r->status = 200;
        } else if (j->ops->encode(j) == 0)
            r->status = 200;
    }
    if (r->status != 200) {
        kdr_buf_free(&r->body);
        kdr_exec_pieces_free(r->pieces);
        r->pieces = NULL;
        r->rays = 0;
    }
    double t_done = kdr_exec_now();
    r->cpu_s = (double)(atomic_load(&j->cpu_ns) + kdr_exec_thread_cpu_ns() - cpu0) * 1e-9;
    /* A stream's caller may still be encoding an item from the result
     * arrays: they are freed (and their charge kept) until
     * kdr_exec_query_done. */
    if (!q->stream) {
        j->ops->release(j);
        if (q->claim)
            kdr_exec_settle(ex, q->claim,
                            kdr_exec_body_held(q) + r->body.cap +
                                (r->pieces ? r->pieces->held : 0));
    }
    r->stopped = stop;
    r->deadline_ms = j->deadline_ms;
    r->work_rays = j->work_rays;
    r->queued_s = (j->picked ? j->t_pick : t_end) - j->t_submit;
    r->parse_s = j->picked ? j->t_trace0 - j->t_pick : 0;
    r->trace_s = j->picked ? t_end - j->t_trace0 : 0;
    r->encode_s = t_done - t_end;

    pthread_mutex_lock(&ex->lock);
    if (j->picked) {
        ex->running--;
        double dt = t_done - j->t_pick;
        ex->mean_s =
            ex->mean_s > 0 ? (1 - MEAN_WEIGHT) * ex->mean_s + MEAN_WEIGHT * dt : dt;
    } else {
        ex->queued--;
    }
    kdr_exec_drop_slot(ex, q->claim);
    ex->completed++;
    ex->deadlines += stop == KDR_STOP_DEADLINE;
    ex->cancelled += stop == KDR_STOP_CANCELLED;
    ex->shutdown += stop == KDR_STOP_SHUTDOWN;
    ex->out_of_memory += out_of_memory(r);
    pthread_mutex_unlock(&ex->lock);

    /* q may be gone once finished; an inline run's caller needs no call */
    void (*on_done)(void *) = j->inline_run ? NULL : q->on_done;
    void *done_ctx = q->done_ctx;
    pthread_mutex_lock(&j->m);
    j->finished = 1;
    pthread_cond_broadcast(&j->cv);
    pthread_mutex_unlock(&j->m);
    if (on_done) on_done(done_ctx);
}

/* Under lock: the first job with work for a free worker. */
static kdr_exec_job *pick(kdr_exec *ex, int *prepare) {
    for (kdr_exec_job *j = ex->head; j; j = j->link) {
        if (j->state == JOB_QUEUED) {
            j->state = JOB_PREPARING;
            j->picked = 1;
            ex->queued--;
            ex->running++;
            *prepare = 1;
            return j;
        }
        if (j->state == JOB_RUNNING && atomic_load(&j->next) < claim_limit(j) &&
            atomic_load(&j->stop) == KDR_STOP_NONE) {
            *prepare = 0;
            return j;
        }
    }
    return NULL;
}

static int exhausted(kdr_exec_job *j) {
    return atomic_load(&j->next) >= j->nchunks || atomic_load(&j->stop) != KDR_STOP_NONE;
}

static void *worker_main(void *arg) {
    kdr_exec *ex = arg;
    if (ex->cfg.on_worker_start) ex->cfg.on_worker_start(ex->cfg.worker_ctx);
    pthread_mutex_lock(&ex->lock);
    for (;;) {
        int prepare = 0;
        kdr_exec_job *j = NULL;
        while (!ex->stop && !(j = pick(ex, &prepare)))
            pthread_cond_wait(&ex->work, &ex->lock);
        if (ex->stop) break;
        j->users++;
        ex->busy++;
        pthread_mutex_unlock(&ex->lock);
        if (prepare) prepare_job(ex, j);
        drain(j);
        pthread_mutex_lock(&ex->lock);
        ex->busy--;
        j->users--;
        if (j->state == JOB_RUNNING && j->users == 0 && exhausted(j)) {
            j->state = JOB_FINISHING;
            unlink_job(ex, j);
            pthread_mutex_unlock(&ex->lock);
            finish_job(j);
            pthread_mutex_lock(&ex->lock);
        }
    }
    pthread_mutex_unlock(&ex->lock);
    return NULL;
}

/* ---- the caller's side ------------------------------------------------------------- */

static kdr_exec_job *job_new(kdr_exec_query *q, kdr_exec *ex, int *rc) {
    const kdr_exec_kind_ops *ops = kdr_exec_ops_for(q->kind);
    *rc = KDR_EINVAL;
    if (!ops || !q->scene || (!q->body && q->len)) return NULL;
    *rc = KDR_ENOMEM;
    kdr_exec_job *j = calloc(1, sizeof *j);
    if (!j) return NULL;
    pthread_condattr_t ca;
    pthread_condattr_init(&ca);
    pthread_condattr_setclock(&ca, CLOCK_MONOTONIC);
    int bad = pthread_cond_init(&j->cv, &ca) != 0;
    pthread_condattr_destroy(&ca);
    if (bad || pthread_mutex_init(&j->m, NULL) != 0) {
        if (!bad) pthread_cond_destroy(&j->cv);
        free(j);
        return NULL;
    }
    j->ex = ex;
    j->q = q;
    j->ops = ops;
    j->state = JOB_QUEUED;
    atomic_init(&j->next, 0);
    atomic_init(&j->done, 0);
    atomic_init(&j->stop, KDR_STOP_NONE);
    atomic_init(&j->cancel, 0);
    atomic_init(&j->core_rc, KDR_OK);
    atomic_init(&j->cpu_ns, 0);
    atomic_init(&j->stream_ready, 0);
    atomic_init(&j->released, 0);
    memset(&q->result, 0, sizeof q->result);
    q->job = j;
    j->t_submit = kdr_exec_now();
    *rc = 0;
    return j;
}

/* Under lock: appends j to the list. */
static void link_job(kdr_exec *ex, kdr_exec_job *j) {
    if (ex->tail)
        ex->tail->link = j;
    else
        ex->head = j;
    ex->tail = j;
}

int kdr_exec_submit(kdr_exec *ex, kdr_exec_query *q) {
    int rc;
    kdr_exec_job *j = job_new(q, ex, &rc);
    if (!j) return rc;
    pthread_mutex_lock(&ex->lock);
    link_job(ex, j);
    ex->queued++;
    pthread_cond_signal(&ex->work);
    pthread_mutex_unlock(&ex->lock);
    return 0;
}

int kdr_exec_try_inline(kdr_exec *ex, kdr_exec_query *q, size_t inline_rays) {
    int rc;
    kdr_exec_job *j = job_new(q, ex, &rc);
    if (!j) return rc;
    pthread_mutex_lock(&ex->lock);
    j->state = JOB_PREPARING; /* not on the list: no worker sees it */
    j->picked = 1;
    ex->running++;
    pthread_mutex_unlock(&ex->lock);
    kdr_exec_prepare_work(ex, j);
    if (j->nchunks > 1 || (j->nchunks == 1 && j->work_rays > inline_rays)) return 0;
    j->inline_run = 1;
    j->t_trace0 = kdr_exec_now();
    drain(j);
    j->state = JOB_FINISHING;
    finish_job(j);
    return 1;
}

void kdr_exec_enqueue(kdr_exec *ex, kdr_exec_query *q) {
    kdr_exec_job *j = q->job;
    j->t_trace0 = kdr_exec_now();
    pthread_mutex_lock(&ex->lock);
    j->state = JOB_RUNNING; /* parsed: any worker may claim its chunks */
    link_job(ex, j);
    pthread_cond_broadcast(&ex->work);
    pthread_mutex_unlock(&ex->lock);
}

/* Takes j to finish it here if no worker is inside it (queued, or running
 * between chunks with every worker elsewhere), stopping it for why. */
static int take_idle(kdr_exec_job *j, kdr_exec_stop why) {
    kdr_exec *ex = j->ex;
    int took = 0;
    pthread_mutex_lock(&ex->lock);
    if (j->state == JOB_QUEUED || (j->state == JOB_RUNNING && j->users == 0)) {
        if (j->state == JOB_QUEUED) kdr_exec_apply_deadline(j, 0); /* for the message */
        kdr_exec_set_stop(j, why);
        j->state = JOB_FINISHING;
        unlink_job(ex, j);
        took = 1;
    }
    pthread_mutex_unlock(&ex->lock);
    if (took) finish_job(j);
    return took;
}

void kdr_exec_cancel(kdr_exec_query *q) {
    atomic_store(&q->job->cancel, 1);
    take_idle(q->job, KDR_STOP_CANCELLED);
}

/* A job whose deadline passed, or which the shutdown stopped, is finished
 * by its waiter when no worker is inside it: none may be free to notice.
 * A queued job has only the caller's deadline; a running one the deadline
 * its parse settled (read under the lock, after the parse published it). */
static void expire_idle(kdr_exec_job *j) {
    const kdr_exec_query *q = j->q;
    if (atomic_load(&j->ex->shutting_down)) {
        take_idle(j, KDR_STOP_SHUTDOWN);
        return;
    }
    double now = kdr_exec_now(), deadline = 0;
    pthread_mutex_lock(&j->ex->lock);
    if (j->state == JOB_QUEUED && q->deadline_ms > 0)
        deadline = q->start + q->deadline_ms * 1e-3;
    else if (j->state == JOB_RUNNING && j->users == 0)
        deadline = j->deadline;
    pthread_mutex_unlock(&j->ex->lock);
    if (deadline > 0 && now >= deadline) take_idle(j, KDR_STOP_DEADLINE);
}

int kdr_exec_wait(kdr_exec_query *q, double timeout_s) {
    kdr_exec_job *j = q->job;
    pthread_mutex_lock(&j->m);
    if (timeout_s < 0) {
        while (!j->finished)
            pthread_cond_wait(&j->cv, &j->m);
    } else if (!j->finished) {
        double t = kdr_exec_now() + timeout_s;
        struct timespec ts = {(time_t)t, (long)((t - floor(t)) * 1e9)};
        while (!j->finished && pthread_cond_timedwait(&j->cv, &j->m, &ts) != ETIMEDOUT) {
        }
    }
    int done = j->finished;
    pthread_mutex_unlock(&j->m);
    if (!done) {
        expire_idle(j);
        pthread_mutex_lock(&j->m);
        done = j->finished;
        pthread_mutex_unlock(&j->m);
    }
    return done;
}

void kdr_exec_query_done(kdr_exec_query *q) {
    kdr_exec_job *j = q->job;
    if (j) {
        if (q->stream) j->ops->release(j);
        free(j->chunk_done);
        pthread_cond_destroy(&j->cv);
        pthread_mutex_destroy(&j->m);
        free(j);
    }
    q->job = NULL;
    kdr_buf_free(&q->result.body);
    kdr_exec_pieces_free(q->result.pieces);
    q->result.pieces = NULL;
}

void kdr_exec_shutdown(kdr_exec *ex) {
    atomic_store(&ex->shutting_down, 1);
    pthread_mutex_lock(&ex->lock);
    pthread_cond_broadcast(&ex->work); /* queued jobs: picked and stopped */
    pthread_mutex_unlock(&ex->lock);
}

/* ---- life and statistics ------------------------------------------------------------
 */

kdr_exec *kdr_exec_create(const kdr_exec_config *cfg) {
    if (!cfg || cfg->workers < 1) {
        errno = EINVAL;
        return NULL;
    }
    kdr_exec *ex = calloc(1, sizeof *ex + cfg->workers * sizeof(pthread_t));
    if (!ex) return NULL;
    ex->cfg = *cfg;
    ex->slots = cfg->max_queue > SIZE_MAX - cfg->workers ? SIZE_MAX
                                                         : cfg->workers + cfg->max_queue;
    atomic_init(&ex->shutting_down, 0);
    pthread_mutex_init(&ex->lock, NULL);
    pthread_cond_init(&ex->work, NULL);
    for (; ex->nthreads < cfg->workers; ex->nthreads++) {
        int rc = pthread_create(&ex->threads[ex->nthreads], NULL, worker_main, ex);
        if (rc) {
            kdr_exec_destroy(ex);
            errno = rc;
            return NULL;
        }
    }
    return ex;
}

void kdr_exec_destroy(kdr_exec *ex) {
    if (!ex) return;
    pthread_mutex_lock(&ex->lock);
    ex->stop = 1;
    pthread_cond_broadcast(&ex->work);
    pthread_mutex_unlock(&ex->lock);
    for (unsigned i = 0; i < ex->nthreads; i++)
        pthread_join(ex->threads[i], NULL);
    pthread_cond_destroy(&ex->work);
    pthread_mutex_destroy(&ex->lock);
    free(ex);
}
