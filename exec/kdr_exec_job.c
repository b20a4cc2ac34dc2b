/*
 * kdr_exec_job.c — one job's own steps, apart from the scheduler that moves
 * it between threads (kdr_exec.c): the problem answer recorded on its
 * result (the first failure wins), the stop checked before every chunk
 * (cancelled, shutting down, past its deadline) and the deadline in force,
 * and its preparation by the worker that picks it: the parse, metered
 * against the query's claim and grown in steps, then the answer's charge
 * and the result arrays. Nothing here takes the executor's lock but the
 * claim's charges (kdr_exec_admit.c).
 */
#define _POSIX_C_SOURCE 200809L
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "kdr_exec_internal.h"

/* Smallest extra charge for a parse that outgrew its allowance. */
#define PARSE_STEP_MIN ((size_t)256 << 10)

double kdr_exec_now(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + (double)ts.tv_nsec * 1e-9;
}

/* CPU time of the calling thread, ns: what a step cost whatever the
 * scheduler did meanwhile (wall times on a shared box include waiting). */
long long kdr_exec_thread_cpu_ns(void) {
    struct timespec ts;
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
    return (long long)ts.tv_sec * 1000000000LL + ts.tv_nsec;
}

void kdr_exec_chunk_range(size_t total, size_t per, size_t c, size_t *first,
                          size_t *count) {
    *first = c * per;
    *count = total - *first < per ? total - *first : per;
}

/* ---- failures, recorded on the result --------------------------------------------- */

static void vfail(kdr_exec_job *j, int status, const char *fmt, va_list ap) {
    kdr_exec_result *r = &j->q->result;
    if (r->status != 0) return;
    r->status = status;
    vsnprintf(r->detail, sizeof r->detail, fmt, ap);
    if (status == 503) r->retry_after = kdr_exec_retry_after(j->ex);
}

void kdr_exec_fail(kdr_exec_job *j, int status, const char *fmt, ...) {
    va_list ap;
    va_start(ap, fmt);
    vfail(j, status, fmt, ap);
    va_end(ap);
}

/* protocol/ answers 500 when it runs out of memory: a 503, retried later. */
void kdr_exec_fail_proto(kdr_exec_job *j, const kdr_proto_error *err) {
    int oom = err->status == 500 && strstr(err->detail, "out of memory") != NULL;
    kdr_exec_fail(j, oom ? 503 : err->status, "%s", err->detail);
}

void kdr_exec_note_rc(kdr_exec_job *j, int rc) {
    int zero = KDR_OK;
    if (rc != KDR_OK) atomic_compare_exchange_strong(&j->core_rc, &zero, rc);
}

/* ---- stopping between chunks ------------------------------------------------------- */

void kdr_exec_set_stop(kdr_exec_job *j, kdr_exec_stop why) {
    int none = KDR_STOP_NONE;
    atomic_compare_exchange_strong(&j->stop, &none, (int)why);
}

/* Checked before every chunk: a few atomic loads and a vDSO clock read. */
kdr_exec_stop kdr_exec_check_stop(kdr_exec_job *j) {
    int s = atomic_load(&j->stop);
    if (s != KDR_STOP_NONE) return (kdr_exec_stop)s;
    if (atomic_load(&j->cancel))
        kdr_exec_set_stop(j, KDR_STOP_CANCELLED);
    else if (atomic_load(&j->ex->shutting_down))
        kdr_exec_set_stop(j, KDR_STOP_SHUTDOWN);
    else if (j->deadline > 0 && kdr_exec_now() >= j->deadline)
        kdr_exec_set_stop(j, KDR_STOP_DEADLINE);
    return (kdr_exec_stop)atomic_load(&j->stop);
}

/* The deadline in force: the caller's and the request's, whichever is
 * shorter (a request can only shorten the operator's limit). */
void kdr_exec_apply_deadline(kdr_exec_job *j, double request_ms) {
    double ms = j->q->deadline_ms;
    if (request_ms > 0 && (ms <= 0 || request_ms < ms)) ms = request_ms;
    j->deadline_ms = ms > 0 ? ms : 0;
    j->deadline = ms > 0 ? j->q->start + ms * 1e-3 : 0;
}

void kdr_exec_stopped_result(kdr_exec_job *j, kdr_exec_stop why) {
    kdr_exec_result *r = &j->q->result;
    size_t done = atomic_load(&j->done);
    switch (why) {
    case KDR_STOP_DEADLINE:
        kdr_exec_fail(
            j, 503, "deadline: %g ms exceeded after %.0f ms (%zu of %zu chunks traced)",
            j->deadline_ms, (kdr_exec_now() - j->q->start) * 1e3, done, j->nchunks);
        r->retry_after = 0; /* the same query would run out of time again */
        break;
    case KDR_STOP_CANCELLED:
        /* 499, as nginx logs it: the client closed the request */
        kdr_exec_fail(j, 499, "cancelled after %zu of %zu chunks", done, j->nchunks);
        break;
    case KDR_STOP_SHUTDOWN:
        kdr_exec_fail(j, 503, "shutting down: stopped after %zu of %zu chunks", done,
                      j->nchunks);
        r->retry_after = 0; /* go elsewhere */
        break;
    case KDR_STOP_NONE:
        break;
    }
}

/* ---- one job -------------------------------------------------------------------------
 */

/* More room for a parse that has used what its claim held for it
 * (protocol/'s meter asks before it allocates): charged to the claim in
 * steps of a quarter of the allowance or more, so that a big parse takes
 * the lock a few dozen times, not once per node. A refusal is the query's
 * answer: 413 when the parse alone would exceed the whole budget, else 503
 * with a retry hint (the protocol's "out of memory" that follows loses:
 * the first failure recorded wins). */
static int parse_grow(void *ctx, kdr_proto_meter *m, size_t need) {
    kdr_exec_job *j = ctx;
    kdr_exec *ex = j->ex;
    size_t step = need > PARSE_STEP_MIN ? need : PARSE_STEP_MIN;
    if (step < m->limit / 4) step = m->limit / 4;
    kdr_admit a = kdr_exec_charge(ex, j->q->claim, step);
    if (a != KDR_ADMIT_OK && step > need &&
        kdr_exec_charge(ex, j->q->claim, need) == KDR_ADMIT_OK) {
        a = KDR_ADMIT_OK;
        step = need;
    }
    if (a == KDR_ADMIT_OK) {
        m->limit += step;
        return 0;
    }
    if (a == KDR_ADMIT_TOO_LARGE)
        kdr_exec_fail(j, 413,
                      "body: parsing it takes more than the in-flight memory limit of "
                      "%.1f MiB (%.1f MiB so far for a %.1f MiB body; JSON the fast path "
                      "reads, flat number arrays or base64, or CBOR takes far less)",
                      (double)ex->cfg.max_bytes / 1048576.0, (double)m->used / 1048576.0,
                      (double)j->q->len / 1048576.0);
    else if (a == KDR_ADMIT_STOPPED)
        kdr_exec_fail(j, 503, "shutting down");
    else
        kdr_exec_fail(j, 503, "memory: no room to parse the body now (%.1f MiB so far)",
                      (double)m->used / 1048576.0);
    return -1;
}

/* The kind's parse, metered when the query has a claim: protocol/ counts
 * every block it (and cJSON) allocates before allocating it, first against
 * what the claim holds beyond the body (kdr_exec_body_charge's parse
 * share), then against more charged by parse_grow. */
static int metered_parse(kdr_exec_job *j) {
    kdr_exec_claim *c = j->q->claim;
    if (!c) return j->ops->parse(j);
    const size_t held = kdr_exec_body_held(j->q);
    kdr_proto_meter m = {.limit = c->bytes > held ? c->bytes - held : 0,
                         .grow = parse_grow,
                         .ctx = j};
    kdr_proto_meter *outer = kdr_proto_meter_set(&m);
    int rc = j->ops->parse(j);
    kdr_proto_meter_set(outer);
    return rc;
}

/* Parses the body, charges and allocates; sets nchunks (0 when the job
 * already has its answer: an error, or a stop before it began). */
void kdr_exec_prepare_work(kdr_exec *ex, kdr_exec_job *j) {
    kdr_exec_query *q = j->q;
    long long cpu0 = kdr_exec_thread_cpu_ns();
    j->t_pick = kdr_exec_now();
    kdr_exec_apply_deadline(j, 0);
    int ok = kdr_exec_check_stop(j) == KDR_STOP_NONE && metered_parse(j) == 0;
    if (ok) {
        kdr_exec_apply_deadline(j, j->deadline_ms);
        ok = kdr_exec_check_stop(j) == KDR_STOP_NONE;
    }
    /* before the charge: a stream's answer estimate is its own */
    if (ok && q->stream) ok = kdr_exec_stream_check(j) == 0;
    if (ok && q->claim) {
        kdr_exec_settle(ex, q->claim, kdr_exec_body_held(q) + j->parsed_bytes);
        kdr_admit a = kdr_exec_charge(ex, q->claim, j->answer_estimate);
        if (a == KDR_ADMIT_TOO_LARGE)
            kdr_exec_fail(j, 413,
                          "answer: about %.1f MiB with the request exceeds the in-flight "
                          "memory limit of %.1f MiB",
                          (double)(j->answer_estimate + q->claim->bytes) / 1048576.0,
                          (double)ex->cfg.max_bytes / 1048576.0);
        else if (a != KDR_ADMIT_OK)
            kdr_exec_fail(j, 503, "memory: no room for an answer of about %.1f MiB now",
                          (double)j->answer_estimate / 1048576.0);
        ok = a == KDR_ADMIT_OK;
    }
    if (ok && j->ops->alloc(j) != 0) {
        kdr_exec_fail(j, 503, "out of memory for the results");
        ok = 0;
    }
    if (ok && q->stream) {
        j->chunk_done = calloc(j->nchunks ? j->nchunks : 1, sizeof *j->chunk_done);
        if (!j->chunk_done) {
            kdr_exec_fail(j, 503, "out of memory for the results");
            ok = 0;
        }
    }
    if (!ok) j->nchunks = 0;
    /* the stream's head may go out from now on; the chunks open next */
    if (ok && q->stream) atomic_store(&j->stream_ready, 1);
    atomic_fetch_add(&j->cpu_ns, kdr_exec_thread_cpu_ns() - cpu0);
}
