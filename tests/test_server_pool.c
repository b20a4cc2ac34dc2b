/*
 * test_server_pool.c — the server's job pool: every chunk runs exactly once,
 * with 0 to 3 workers, with 0, 1 and many chunks, and with several threads
 * submitting jobs at the same time (as concurrent HTTP requests do).
 */
#define _POSIX_C_SOURCE 200809L
#include <pthread.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>

#include "pool.h"

enum { MAX_CHUNKS = 5000, SUBMITTERS = 4, ROUNDS = 50 };

typedef struct counts {
    atomic_int hits[MAX_CHUNKS];
} counts;

static void count_chunk(void *ctx, size_t c) {
    atomic_fetch_add(&((counts *)ctx)->hits[c], 1);
}

static int run_and_check(kdr_pool *p, size_t nchunks) {
    counts *k = calloc(1, sizeof *k);
    if (!k) return 1;
    kdr_pool_run(p, nchunks, count_chunk, k);
    int bad = 0;
    for (size_t c = 0; c < MAX_CHUNKS; c++)
        if (atomic_load(&k->hits[c]) != (c < nchunks)) bad++;
    free(k);
    if (bad) fprintf(stderr, "%zu chunks: %d wrong counts\n", nchunks, bad);
    return bad != 0;
}

typedef struct submitter {
    kdr_pool *pool;
    int seed, failed;
} submitter;

static void *submit_main(void *arg) {
    submitter *s = arg;
    unsigned r = (unsigned)s->seed;
    for (int i = 0; i < ROUNDS; i++) {
        r = r * 1103515245u + 12345u;
        s->failed |= run_and_check(s->pool, (r >> 8) % 300);
    }
    return NULL;
}

static int concurrent(kdr_pool *p) {
    pthread_t th[SUBMITTERS];
    submitter s[SUBMITTERS];
    for (int i = 0; i < SUBMITTERS; i++) {
        s[i] = (submitter){p, i + 1, 0};
        pthread_create(&th[i], NULL, submit_main, &s[i]);
    }
    int failed = 0;
    for (int i = 0; i < SUBMITTERS; i++) {
        pthread_join(th[i], NULL);
        failed |= s[i].failed;
    }
    return failed;
}

int main(void) {
    int failed = 0;
    for (unsigned workers = 0; workers <= 3; workers++) {
        kdr_pool *p = kdr_pool_create(workers);
        if (!p) {
            fprintf(stderr, "kdr_pool_create(%u) failed\n", workers);
            return 1;
        }
        const size_t sizes[] = {0, 1, 2, 3, 17, 1000, MAX_CHUNKS};
        for (size_t i = 0; i < sizeof sizes / sizeof sizes[0]; i++)
            failed |= run_and_check(p, sizes[i]);
        failed |= concurrent(p);
        kdr_pool_destroy(p);
    }
    kdr_pool_destroy(NULL);
    printf("%s\n", failed ? "FAILED" : "ok");
    return failed;
}
