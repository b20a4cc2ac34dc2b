/*
 * pool.c — a FIFO of jobs guarded by one mutex, with chunk indices claimed
 * by atomic increments so the lock is taken per job, not per chunk. A job
 * lives on its submitter's stack: workers register as its users under the
 * lock, and the submitter returns only when all chunks are done and no
 * worker still holds a pointer to it.
 */
#define _POSIX_C_SOURCE 200809L
#include "pool.h"

#include <errno.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdlib.h>

typedef struct job {
    kdr_pool_fn fn;
    void *ctx;
    size_t nchunks;
    atomic_size_t next; /* next chunk to claim */
    atomic_size_t done; /* chunks finished */
    unsigned users;     /* workers inside the job (under the pool lock) */
    struct job *link;
} job;

struct kdr_pool {
    pthread_mutex_t lock;
    pthread_cond_t work; /* a job was queued, or stop */
    pthread_cond_t idle; /* a job's users or chunks dropped */
    job *head, *tail;
    int stop;
    unsigned nthreads;
    pthread_t threads[];
};

/* Runs chunks until none is left to claim. */
static void job_drain(job *j) {
    for (;;) {
        size_t c = atomic_fetch_add(&j->next, 1);
        if (c >= j->nchunks) return;
        j->fn(j->ctx, c);
        atomic_fetch_add(&j->done, 1);
    }
}

/* Under the lock: unlinks j if it is still queued. */
static void job_unlink(kdr_pool *p, job *j) {
    job **pp = &p->head, *prev = NULL;
    while (*pp && *pp != j) {
        prev = *pp;
        pp = &(*pp)->link;
    }
    if (!*pp) return;
    *pp = j->link;
    if (p->tail == j) p->tail = prev;
}

static void *worker_main(void *arg) {
    kdr_pool *p = arg;
    pthread_mutex_lock(&p->lock);
    for (;;) {
        while (!p->head && !p->stop)
            pthread_cond_wait(&p->work, &p->lock);
        if (p->stop) break;
        job *j = p->head;
        if (atomic_load(&j->next) >= j->nchunks) {
            job_unlink(p, j); /* fully claimed: nothing left for anyone */
            continue;
        }
        j->users++;
        pthread_mutex_unlock(&p->lock);
        job_drain(j);
        pthread_mutex_lock(&p->lock);
        job_unlink(p, j);
        j->users--;
        pthread_cond_broadcast(&p->idle);
    }
    pthread_mutex_unlock(&p->lock);
    return NULL;
}

kdr_pool *kdr_pool_create(unsigned workers) {
    kdr_pool *p = calloc(1, sizeof *p + workers * sizeof(pthread_t));
    if (!p) return NULL;
    pthread_mutex_init(&p->lock, NULL);
    pthread_cond_init(&p->work, NULL);
    pthread_cond_init(&p->idle, NULL);
    for (; p->nthreads < workers; p->nthreads++) {
        int rc = pthread_create(&p->threads[p->nthreads], NULL, worker_main, p);
        if (rc) {
            kdr_pool_destroy(p);
            errno = rc;
            return NULL;
        }
    }
    return p;
}

void kdr_pool_run(kdr_pool *p, size_t nchunks, kdr_pool_fn fn, void *ctx) {
    job j = {.fn = fn, .ctx = ctx, .nchunks = nchunks};
    atomic_init(&j.next, 0);
    atomic_init(&j.done, 0);
    if (nchunks > 1 && p->nthreads > 0) {
        pthread_mutex_lock(&p->lock);
        if (p->tail)
            p->tail->link = &j;
        else
            p->head = &j;
        p->tail = &j;
        pthread_cond_broadcast(&p->work);
        pthread_mutex_unlock(&p->lock);
    }
    job_drain(&j);
    if (nchunks <= 1 || p->nthreads == 0) return;
    pthread_mutex_lock(&p->lock);
    job_unlink(p, &j);
    while (j.users > 0 || atomic_load(&j.done) < nchunks)
        pthread_cond_wait(&p->idle, &p->lock);
    pthread_mutex_unlock(&p->lock);
}

void kdr_pool_destroy(kdr_pool *p) {
    if (!p) return;
    pthread_mutex_lock(&p->lock);
    p->stop = 1;
    pthread_cond_broadcast(&p->work);
    pthread_mutex_unlock(&p->lock);
    for (unsigned i = 0; i < p->nthreads; i++)
        pthread_join(p->threads[i], NULL);
    pthread_cond_destroy(&p->idle);
    pthread_cond_destroy(&p->work);
    pthread_mutex_destroy(&p->lock);
    free(p);
}
