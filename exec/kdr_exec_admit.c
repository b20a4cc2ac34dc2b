/*
 * kdr_exec_admit.c — the executor's books: admission of claims (a queue
 * slot and bytes) against the limits, the Retry-After estimate, and the
 * statistics behind /metrics and /v1/ready. Every count here changes under
 * the executor's one mutex (kdr_exec_internal.h), held for a few additions.
 */
#define _POSIX_C_SOURCE 200809L
#include <math.h>

#include "kdr_exec_internal.h"

static const unsigned RETRY_MIN_S = 1, RETRY_MAX_S = 60;
/* Saturated when less than 1/SATURATED_FREE_PART of the byte budget is free. */
static const size_t SATURATED_FREE_PART = 10;

/* ---- admission ------------------------------------------------------------------- */

size_t kdr_exec_body_charge(size_t len) {
    const size_t k = 1 + KDR_EXEC_PARSE_BYTES_PER_BODY_BYTE;
    return len > SIZE_MAX / k ? SIZE_MAX : len * k;
}

/* Under lock: does `more` fit in the budget on top of what is charged? */
static int fits(const kdr_exec *ex, size_t more) {
    const size_t max = ex->cfg.max_bytes;
    return max == 0 || (more <= max && ex->bytes_used <= max - more);
}

static int too_large(const kdr_exec *ex, size_t total) {
    return ex->cfg.max_bytes != 0 && total > ex->cfg.max_bytes;
}

kdr_admit kdr_exec_admit(kdr_exec *ex, kdr_exec_claim *c, size_t bytes) {
    kdr_admit a = KDR_ADMIT_OK;
    pthread_mutex_lock(&ex->lock);
    if (atomic_load(&ex->shutting_down)) {
        a = KDR_ADMIT_STOPPED;
    } else if (too_large(ex, bytes)) {
        a = KDR_ADMIT_TOO_LARGE;
        ex->rejected_too_large++;
    } else if (ex->slots_used >= ex->slots) {
        a = KDR_ADMIT_QUEUE_FULL;
        ex->rejected_queue++;
    } else if (!fits(ex, bytes)) {
        a = KDR_ADMIT_MEMORY_FULL;
        ex->rejected_memory++;
    } else {
        ex->slots_used++;
        ex->bytes_used += bytes;
        ex->admitted++;
        c->slot = 1;
        c->bytes = bytes;
    }
    pthread_mutex_unlock(&ex->lock);
    return a;
}

kdr_admit kdr_exec_charge(kdr_exec *ex, kdr_exec_claim *c, size_t more) {
    kdr_admit a = KDR_ADMIT_OK;
    pthread_mutex_lock(&ex->lock);
    if (more > SIZE_MAX - c->bytes || too_large(ex, c->bytes + more)) {
        a = KDR_ADMIT_TOO_LARGE;
        ex->rejected_too_large++;
    } else if (!fits(ex, more)) {
        a = KDR_ADMIT_MEMORY_FULL;
        ex->rejected_memory++;
    } else {
        ex->bytes_used += more;
        c->bytes += more;
    }
    pthread_mutex_unlock(&ex->lock);
    return a;
}

void kdr_exec_settle(kdr_exec *ex, kdr_exec_claim *c, size_t bytes) {
    pthread_mutex_lock(&ex->lock);
    ex->bytes_used = ex->bytes_used - c->bytes + bytes;
    c->bytes = bytes;
    pthread_mutex_unlock(&ex->lock);
}

/* Under lock. */
void kdr_exec_drop_slot(kdr_exec *ex, kdr_exec_claim *c) {
    if (c && c->slot) {
        ex->slots_used--;
        c->slot = 0;
    }
}

void kdr_exec_release(kdr_exec *ex, kdr_exec_claim *c) {
    if (!ex || !c) return;
    pthread_mutex_lock(&ex->lock);
    kdr_exec_drop_slot(ex, c);
    ex->bytes_used -= c->bytes;
    c->bytes = 0;
    pthread_mutex_unlock(&ex->lock);
}

unsigned kdr_exec_retry_after(kdr_exec *ex) {
    pthread_mutex_lock(&ex->lock);
    size_t ahead = ex->queued + ex->running;
    double s = ex->mean_s * (double)(ahead ? ahead : 1) / ex->cfg.workers;
    pthread_mutex_unlock(&ex->lock);
    s = ceil(s);
    return s < RETRY_MIN_S ? RETRY_MIN_S : s > RETRY_MAX_S ? RETRY_MAX_S : (unsigned)s;
}

void kdr_exec_get_stats(kdr_exec *ex, kdr_exec_stats *s) {
    pthread_mutex_lock(&ex->lock);
    *s = (kdr_exec_stats){.workers = ex->cfg.workers,
                          .busy = ex->busy,
                          .slots = ex->slots,
                          .slots_used = ex->slots_used,
                          .queued = ex->queued,
                          .running = ex->running,
                          .bytes_max = ex->cfg.max_bytes,
                          .bytes_used = ex->bytes_used,
                          .admitted = ex->admitted,
                          .rejected_queue = ex->rejected_queue,
                          .rejected_memory = ex->rejected_memory,
                          .rejected_too_large = ex->rejected_too_large,
                          .completed = ex->completed,
                          .deadlines = ex->deadlines,
                          .cancelled = ex->cancelled,
                          .shutdown = ex->shutdown,
                          .out_of_memory = ex->out_of_memory,
                          .mean_query_s = ex->mean_s};
    pthread_mutex_unlock(&ex->lock);
}

int kdr_exec_saturated(const kdr_exec_stats *s) {
    if (s->slots_used >= s->slots) return 1;
    if (s->bytes_max == 0) return 0;
    size_t free_bytes = s->bytes_used < s->bytes_max ? s->bytes_max - s->bytes_used : 0;
    return free_bytes < s->bytes_max / SATURATED_FREE_PART;
}
